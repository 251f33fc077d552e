"""The HTML and JUnit reports: self-contained, escaped, complete, and honest about aborts."""

from __future__ import annotations

import base64
import dataclasses
import hashlib
import re
import xml.etree.ElementTree as ET
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

import bench.report.html as report_html
from bench.report import write_html, write_junit
from bench.report.html import fmt
from bench.report.junit import split_nodeid, xml_safe
from bench.report.plots import MAX_POINTS, Plotter, decimate
from bench.results.model import CaseResult, Plot, RunResult, Series, Step, Table

SCRIPT = "<script>alert(1)</script>"
IMG = '<img src=x onerror="window.__pwned=1">'
QUOTE = '" onerror="x'


def make_run(mcap: str = f"logs/run {QUOTE}.mcap") -> RunResult:
    """Three cases (passed with hostile names everywhere, failed, skipped) and a run table."""
    t = np.linspace(0.0, 5.0, 5000)
    time_plot = Plot(
        title=f"steer {SCRIPT}", xlabel=f"t [s] {IMG}", ylabel=f"angle {QUOTE}",
        series=[Series(f"SAS_Angle {SCRIPT}", list(t), list(np.sin(t))),
                Series(f"_raw {IMG}", list(t), list(np.cos(t))),
                Series("cost $\\alpha_{x", [0.0, 1.0], [1.0, 2.0])],  # broken mathtext
    )
    xy_plot = Plot(title="top view", xlabel="x [m]", ylabel="y [m]", kind="xy",
                   series=[Series("path", list(10 * np.cos(t)), list(5 * np.sin(t)))])
    passed = CaseResult(
        nodeid=f"testcases/test_steer.py::test_ramp[{SCRIPT}]", name=f"test_ramp[{SCRIPT}]",
        outcome="passed", wall_time=1.25, sim_start=0.0, sim_time=5.0,
        steps=[Step(f"angle {SCRIPT}", 1.23456789, 1.2, "±0.05", "pass", 1.5, "deg", IMG),
               Step("mode", "ON", "ON", "equal", "pass", 2.0)],
        plots=[time_plot, xy_plot],
        tables=[Table(f"figures {SCRIPT}", ["what", IMG], [["a", SCRIPT], [QUOTE, "2"]])],
        notes=[f"note {IMG}"],
    )
    failed = CaseResult(
        nodeid="testcases/test_abs.py::TestAbs::test_brake[mu=0.2]", name="test_brake[mu=0.2]",
        outcome="failed", wall_time=2.0, sim_start=5.0, sim_time=3.0,
        steps=[Step("stop distance", 41.5, 38.0, "±2", "fail", 7.9, "m"),
               Step("wheel lock", None, 0.0, "== 0", "pass", 8.0)],
        plots=[Plot("empty", "t", "v", [])],
        message=f"assert 41.5 <= 40\nECU said \x00\x1b[31m{IMG}",
    )
    skipped = CaseResult(nodeid="testcases/test_abs.py::test_split_mu", name="test_split_mu",
                         outcome="skipped", message="needs a real ECU")
    return RunResult(
        started="2025-03-01T10:00:00+01:00", interface="embedded", channel=f"vcan0 {SCRIPT}",
        time_mode="virtual", external=[f"ECU {IMG}"], cases=[passed, failed, skipped],
        mcap_path=mcap, wall_time=3.5, sim_time=8.0, frames=12000,
        invalid_frames=3, tables=[Table("run figures", ["k", "v"], [["frames", "12000"]])],
    )


class _Collector(HTMLParser):
    """All tags with attributes, all ids, and the cell texts of table#summary."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.summary: list[list[str]] = []
        self._in_summary = self._in_cell = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        self.tags.append((tag, a))
        if tag == "table" and a.get("id") == "summary":
            self._in_summary = True
        elif self._in_summary and tag == "tr":
            self.summary.append([])
        elif self._in_summary and tag in ("td", "th"):
            self._in_cell = True
            self.summary[-1].append("")

    def handle_endtag(self, tag: str) -> None:
        if tag == "table":
            self._in_summary = False
        if tag in ("td", "th"):
            self._in_cell = False

    def handle_data(self, data: str) -> None:
        if self._in_summary and self._in_cell:
            self.summary[-1][-1] += data


def _parse(html: str) -> _Collector:
    parser = _Collector()
    parser.feed(html)
    parser.close()
    return parser


@pytest.fixture()
def report(tmp_path: Path) -> tuple[str, Path]:
    run = make_run(mcap=str(tmp_path / "logs" / f"run {QUOTE}.mcap"))
    path = write_html(run, tmp_path / "out" / "sub" / "report.html")
    return path.read_text(encoding="utf-8"), path


def test_html_is_self_contained(report: tuple[str, Path]) -> None:
    html, _ = report
    low = html.lower()
    assert "<link" not in low and "<iframe" not in low
    assert 'src="http' not in low and "@import" not in low and "url(http" not in low
    # one script: the page's own filter script, inline, allowed by its hash and nothing else
    assert low.count("<script") == 1 and f"<script>{report_html.SCRIPT}</script>" in html
    digest = base64.b64encode(hashlib.sha256(report_html.SCRIPT.encode()).digest()).decode()
    csp = re.search(r'http-equiv="Content-Security-Policy" content="([^"]*)"', html).group(1)  # type: ignore[union-attr]
    assert f"script-src 'sha256-{digest}'" in csp and "unsafe-inline'; script" in csp and "default-src 'none'" in csp
    assert "fetch(" not in report_html.SCRIPT and "XMLHttpRequest" not in report_html.SCRIPT
    for tag, attrs in _parse(html).tags:
        assert tag not in ("img", "link", "iframe", "object", "embed"), tag
        assert "src" not in attrs, (tag, attrs)
        href = attrs.get("href") or attrs.get("xlink:href") or ""
        assert not re.match(r"[a-z][a-z0-9+.-]*:", href, re.I), href  # no scheme: local only


def test_hostile_strings_only_escaped(report: tuple[str, Path]) -> None:
    html, _ = report
    assert SCRIPT not in html and IMG not in html and QUOTE + ".mcap" not in html
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    assert "&lt;img src=x onerror=" in html
    for tag, attrs in _parse(html).tags:
        assert not any(name.startswith("on") for name in attrs), (tag, attrs)
    # inside the SVG: well-formed XML whose *text* carries the payload (i.e. it is not markup)
    svgs = re.findall(r"<svg\b.*?</svg>", html, re.S)
    assert len(svgs) == 3
    texts = ["".join(el.itertext()) for svg in svgs for el in ET.fromstring(svg).iter()]
    assert any(IMG in t for t in texts) and any(QUOTE in t for t in texts)
    # the legend (HTML) keeps hostile and "_"-prefixed names, escaped
    assert "SAS_Angle &lt;script&gt;" in html and "_raw &lt;img" in html


def test_html_contents(report: tuple[str, Path], tmp_path: Path) -> None:
    html, path = report
    run = make_run()
    assert list(tmp_path.rglob("*")) == [tmp_path / "out", tmp_path / "out" / "sub", path]
    assert '<span class="verdict FAIL">FAIL</span>' in html and "Run aborted" not in html
    parsed = _parse(html)
    header, *rows = parsed.summary
    assert header == ["Case", "Outcome", "Steps passed", "Bench time", "Wall time"]
    assert [(r[0], r[1], r[2]) for r in rows] == [
        (c.name, c.outcome, f"{len(c.steps) - len(c.failed_steps)} / {len(c.steps)}")
        for c in run.cases]
    assert '<tr class="fail">' in html                       # the failed step is highlighted
    assert ">1.235<" in html and ">–<" in html              # 4 significant digits, None as "–"
    assert "\x00" not in html and "\x1b" not in html
    assert 'href="../../logs/run%20%22%20onerror%3D%22x.mcap"' in html
    ids = [a["id"] for _, a in parsed.tags if a.get("id")]
    assert len(ids) == len(set(ids)), "duplicate ids across inline SVGs"
    refs = re.findall(r'(?:href="#|url\(#)([^")]+)', html)
    assert refs and set(refs) <= set(ids)
    assert html.count('<figure class="plot time">') == 2 and 'class="plot xy"' in html
    assert "no data" in html and "needs a real ECU" in html and "run figures" in html


def test_plot_kinds_and_decimation() -> None:
    plotter = Plotter()
    xy = plotter.render(make_run().cases[0].plots[1], "a")
    assert xy.kind == "xy" and 'viewBox="0 0 420 380"' in xy.svg
    # one plotter draws many plots: an empty plot must not freeze the limits of the next one
    assert "no data" in plotter.render(Plot("e", "t", "v", []), "b").svg
    wide = plotter.render(Plot("t", "t", "v", [Series("s", [0.0, 100.0], [0.0, 50.0])]), "c").svg
    assert ">100<" in wide and ">40<" in wide   # tick labels reach the data's range
    n = 200_000
    x = np.arange(n, dtype=float)
    y = np.sin(x / 5000)
    y[123_457] = 50.0
    y[7] = -50.0
    dx, dy = decimate(x, y)
    assert len(dx) <= MAX_POINTS and dy.max() == 50.0 and dy.min() == -50.0
    assert np.all(np.diff(dx) > 0) and dx[0] == 0 and dx[-1] == n - 1
    sx, _ = decimate(x, y, keep_extremes=False)
    assert len(sx) <= MAX_POINTS and sx[-1] == n - 1


def _junit(tmp_path: Path, run: RunResult) -> ET.Element:
    path = write_junit(run, tmp_path / "j" / "junit.xml")
    return ET.parse(path).getroot()


def test_junit(tmp_path: Path) -> None:
    root = _junit(tmp_path, make_run())
    assert root.tag == "testsuites"
    (suite,) = root.findall("testsuite")
    assert {k: suite.get(k) for k in ("name", "tests", "failures", "errors", "skipped")} == {
        "name": "bench", "tests": "3", "failures": "1", "errors": "0", "skipped": "1"}
    cases = suite.findall("testcase")
    assert [(c.get("classname"), c.get("name")) for c in cases] == [
        ("testcases.test_steer", f"test_ramp[{SCRIPT}]"),
        ("testcases.test_abs.TestAbs", "test_brake[mu=0.2]"),
        ("testcases.test_abs", "test_split_mu")]
    failure = cases[1].find("failure")
    assert failure is not None
    assert "stop distance: measured 41.5, expected 38.0 (±2)" in failure.get("message", "")
    assert "assert 41.5 <= 40" in failure.get("message", "") and IMG in (failure.text or "")
    assert cases[2].find("skipped") is not None and cases[0].find("failure") is None
    out = cases[0].findtext("system-out") or ""
    assert out.splitlines()[0].startswith(f"PASS angle {SCRIPT}: measured 1.235 deg, expected 1.200 deg (±0.05)")


def test_aborted_run(tmp_path: Path) -> None:
    run = make_run()
    run.aborted = True
    run.cases[2] = dataclasses.replace(run.cases[2], outcome="aborted", message="E-stop")
    html = write_html(run, tmp_path / "r.html").read_text(encoding="utf-8")
    assert '<span class="verdict ABORTED">ABORTED</span>' in html
    assert "Run aborted" in html and '<span class="badge aborted">aborted</span>' in html
    root = _junit(tmp_path, run)
    suite = root.find("testsuite")
    assert suite is not None and suite.get("errors") == "2" and suite.get("tests") == "4"
    errors = [(tc.get("classname"), tc.get("name"), tc.find("error").get("type"))  # type: ignore[union-attr]
              for tc in suite.iter("testcase") if tc.find("error") is not None]
    assert errors == [("testcases.test_abs", "test_split_mu", "aborted"),
                      ("bench.run", "aborted", "aborted")]
    assert suite.find("properties/property[@name='aborted']").get("value") == "true"  # type: ignore[union-attr]


def test_empty_run(tmp_path: Path) -> None:
    run = RunResult("2025-01-01T00:00:00", "socketcan", "can0", "real")
    html = write_html(run, tmp_path / "r.html").read_text(encoding="utf-8")
    assert "no cases ran" in html and "FAIL" in html
    assert _junit(tmp_path, run).find("testsuite").get("tests") == "0"  # type: ignore[union-attr]


def test_helpers() -> None:
    assert split_nodeid("testcases/test_x.py::test_y[param]") == ("testcases.test_x", "test_y[param]")
    assert split_nodeid("testcases/sub/test_x.py::test_y[a::b/c]") == (
        "testcases.sub.test_x", "test_y[a::b/c]")
    assert split_nodeid("odd", "name") == ("bench", "name")
    assert xml_safe("a\x00b\x1bc\td\ue000") == "abc\td\ue000"
    assert [fmt(v) for v in (None, 1.23456789, 3, "x", float("nan"), 1e-7)] == [
        "–", "1.235", "3", "x", "NaN", "1e-07"]


def test_bad_data_does_not_cost_the_report(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    inf = float("inf")
    case = CaseResult("t.py::t", "t", "passed", plots=[
        Plot("inf", "t", "v", [Series("s", [0.0, 1.0, 2.0], [0.0, inf, 1.0]),
                               Series("short", [0.0, 1.0, 2.0], [1.0])])])
    run = RunResult("2025-01-01T00:00:00", "embedded", "vcan0", "virtual", cases=[case])
    assert write_html(run, tmp_path / "a.html").read_text(encoding="utf-8").count("<svg") == 1

    def boom(self: Plotter, plot: Plot, prefix: str = "p", spans: object = None) -> None:
        raise ValueError(SCRIPT)

    monkeypatch.setattr(Plotter, "render", boom)
    html = write_html(run, tmp_path / "b.html").read_text(encoding="utf-8")
    assert "plot could not be drawn: ValueError: &lt;script&gt;" in html and SCRIPT not in html
