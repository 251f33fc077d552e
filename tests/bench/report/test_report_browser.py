"""The HTML report in a real browser (headless Chromium): it renders, logs no errors, and
hostile strings stay text.

The payloads would change ``document.title`` to "PWNED" and add a ``<pwned>`` element if
they ever ran; the word is built at run time ('PW'+'NED') so it never appears in the
escaped text. The report's CSP would block the scripts, so the DOM is also searched for
injected elements and event attributes. A control test proves these checks fire when
escaping is switched off.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from jinja2 import Environment, PackageLoader

import bench.report.html as report_html
from bench.report import write_html
from bench.results.model import CaseResult, Plot, RunResult, Series, Step
from tests.browser import IMG, JS, SCRIPT, Dom, dump, problems, run_browser


def hostile_run() -> RunResult:
    t = list(np.linspace(0, 3, 400))
    case = CaseResult(
        nodeid=f"testcases/test_x.py::test_a[{IMG}]", name=f"test_a[{IMG}]", outcome="failed",
        steps=[Step(SCRIPT, 1.0, 2.0, "±0.1", "fail", 0.5, IMG)],
        plots=[Plot(SCRIPT, f"t {SCRIPT}", f"v {IMG}",
                    [Series(IMG, t, list(np.sin(t))), Series(SCRIPT, t, list(np.cos(t)))]),
               Plot("top", "x", "y", [Series("p", list(np.cos(t)), list(np.sin(t)))], kind="xy")],
        notes=[IMG], message=f"boom {SCRIPT}", wall_time=1.0, sim_time=3.0,
    )
    ok = CaseResult(nodeid="testcases/test_x.py::test_b", name="test_b", outcome="passed",
                    steps=[Step("fine", 1.0, 1.0, "±0.1", "pass", 0.1)])
    return RunResult(started="2025-03-01T10:00:00", interface="embedded", channel="vcan0",
                     time_mode="virtual", external=[IMG], cases=[case, ok], frames=10,
                     mcap_path=f'run" onmouseover="{JS}.mcap')


def test_report_in_browser(tmp_path: Path) -> None:
    page = write_html(hostile_run(), tmp_path / "report.html")
    dom, err = dump(tmp_path, page)
    assert 'id="summary"' in dom and "test_b" in dom
    assert problems(dom, err) == []
    parsed = Dom()
    parsed.feed(dom)
    assert parsed.title.startswith("Bench report FAIL") and parsed.summary_rows == 3
    assert dom.count("<svg") == 2

    shot = tmp_path / "shot.png"
    run_browser(tmp_path, f"--screenshot={shot}", "--window-size=1280,1600", page.as_uri())
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(shot.read_bytes()[16:20]), int.from_bytes(shot.read_bytes()[20:24])
    assert (width, height) == (1280, 1600)
    import matplotlib.image

    pixels = (matplotlib.image.imread(shot)[..., :3] * 255).round().astype(int)
    colours = np.unique(pixels.reshape(-1, 3), axis=0)
    assert len(colours) > 50, "screenshot looks blank"
    red = np.all(np.abs(pixels - (0xCF, 0x22, 0x2E)) < 12, axis=-1)  # the FAIL badge
    assert red.sum() > 200


def _no_escape_env() -> Environment:
    env = Environment(loader=PackageLoader("bench.report", "templates"), autoescape=False)
    env.filters.update(report_html.FILTERS)
    return env


def test_checks_detect_an_escaping_failure(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Control: with autoescape off the same run must be flagged, with and without the CSP."""
    monkeypatch.setattr(report_html, "_env", _no_escape_env)
    page = write_html(hostile_run(), tmp_path / "broken.html")
    dom, err = dump(tmp_path, page)
    assert any("injected element" in p for p in problems(dom, err))
    no_csp = tmp_path / "broken-no-csp.html"
    no_csp.write_text(re.sub(r'<meta http-equiv="Content-Security-Policy"[^>]*>', "",
                             page.read_text(encoding="utf-8")), encoding="utf-8")
    dom, err = dump(tmp_path, no_csp)
    assert any("title changed" in p for p in problems(dom, err))


def test_filter_script_runs_under_the_csp(tmp_path: Path) -> None:
    """The page's script is allowed by its hash: a link to a collapsed case opens it (an injected
    script, with another hash, would be blocked: see test_report_in_browser)."""
    page = write_html(hostile_run(), tmp_path / "report.html")
    closed, _ = dump(tmp_path, page)
    opened, err = run_browser(tmp_path, "--enable-logging=stderr", "--v=0", "--dump-dom", page.as_uri() + "#case-2")
    assert re.search(r'<details class="case passed" id="case-2"[^>]*>', closed).group(0).count("open") == 0  # type: ignore[union-attr]
    assert " open" in re.search(r'<details class="case passed" id="case-2"[^>]*>', opened).group(0)  # type: ignore[union-attr]
    assert problems(opened, err) == [] and "Refused to execute" not in err
