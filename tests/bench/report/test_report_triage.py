"""The report for an engineer in a hurry (issue 16, findings 6 and 7): failures first with links,
filters and search, collapsed cases, small plots that break at gaps and keep silent series in the legend."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from bench.report import write_html
from bench.report.plots import Plotter
from bench.results.model import CaseResult, FaultRecord, Plot, RunResult, Series, Step

T = np.arange(0, 5, 0.01)


def _run() -> RunResult:
    ok = [CaseResult(f"testcases/test_x.py::test_ok[{i}]", f"test_ok[{i}]", "passed", reqs=["VCU-MODE-01"],
                     steps=[Step("fine", 1.0, 1.0, "±0.1", "pass", 0.1)]) for i in range(60)]
    bad = CaseResult("testcases/test_y.py::test_bad", "test_bad", "failed", sim_start=10.0, sim_time=5.0,
                     steps=[Step("steer angle FL", 3.2, 4.5, "±0.1 deg", "fail", 12.0, "deg"),
                            Step("fine", 1.0, 1.0, "±0.1", "pass", 12.5)],
                     faults=[FaultRecord("drop:VCU_WheelCmd_FL@case+1-2", "command line", "drop", "VCU_WheelCmd_FL",
                                         11.0, 12.0, 100)],
                     plots=[Plot("wheel", "time since case start [s]", "deg",
                                 [Series("VCU_WheelCmd_FL.SteerAngleCmd", list(T), list(np.sin(T)), gap=0.025)],
                                 x0=10.0)])
    broken = CaseResult("testcases/test_y.py::test_broken", "test_broken", "error",
                        message="Traceback ...\nBenchError: the plant did not acknowledge scenario 3")
    return RunResult("2026-01-01T00:00:00", "embedded", "", "virtual", cases=[*ok[:30], bad, *ok[30:], broken],
                     faults=list(bad.faults))


def test_failures_first_with_links(tmp_path: Path) -> None:
    html = write_html(_run(), tmp_path / "r.html").read_text(encoding="utf-8")
    box = html[html.index('<section id="failures">'):]
    box = box[:box.index("</section>")]
    assert html.index('<section id="failures">') < html.index('<dl class="facts">') < html.index('id="summary"')
    assert "2 cases did not pass" in box
    assert '<a href="#case-31">test_bad</a>' in box and '<a href="#case-62">test_broken</a>' in box
    assert "steer angle FL: measured" in box and "4.5" in box and "fine" not in box   # only the failed steps
    assert "BenchError: the plant did not acknowledge scenario 3" in box             # the error's last line


def test_filters_search_and_collapsed_cases(tmp_path: Path) -> None:
    html = write_html(_run(), tmp_path / "r.html").read_text(encoding="utf-8")
    assert '<input type="search" id="q"' in html
    boxes = re.findall(r'<input type="checkbox" value="(\w+)" checked> \w+ \((\d+)\)', html)
    assert boxes == [("passed", "60"), ("failed", "1"), ("error", "1")]
    rows = re.findall(r'<tr class="[^"]*" data-outcome="(\w+)" data-name="([^"]*)"', html)
    assert len(rows) == 62 and rows[30][0] == "failed" and "drop:vcu_wheelcmd_fl@case+1-2" in rows[30][1]
    assert "vcu-mode-01" in rows[0][1]                                         # requirements are searchable
    cases = re.findall(r"<details class=\"case (\w+)\"([^>]*)>", html)
    assert len(cases) == 62
    # the two that did not pass open at the top (issue 27 finding 7), in the summary's order; the rest collapsed
    assert [(c, " open" in attrs) for c, attrs in cases[:2]] == [("failed", True), ("error", True)]
    assert not any(" open" in attrs for _, attrs in cases[2:])


def test_plots_are_small_and_break_at_gaps() -> None:
    plotter = Plotter()
    n = 100_000
    t = np.linspace(0, 100, n)
    noisy = np.sin(t) + np.random.default_rng(1).normal(0, 0.3, n)
    big = plotter.render(Plot("noise", "t", "v", [Series("n", list(t), list(noisy))]), "a").svg
    smooth = plotter.render(Plot("sine", "t", "v", [Series("s", list(t), list(np.sin(t)))]), "b").svg
    assert len(big) < 16_000 and len(smooth) < 6_000        # 100 000 points each; about 2.4 MB as raw text
    # a 0.5 s pause of a 10 ms message: two lines, not a ramp across the pause
    x = np.r_[np.arange(0, 1, 0.01), np.arange(1.5, 2.5, 0.01)]
    gap = plotter.render(Plot("g", "t", "v", [Series("m", list(x), list(x), gap=0.025),
                                              Series("same, no cycle known", list(x), list(x + 1))]), "c")
    d = re.findall(r'<path class="s" stroke="[^"]+" d="([^"]*)"', gap.svg)
    assert d[0].count("M") == 2 and d[1].count("M") == 1
    # a series without points keeps its place in the legend
    empty = plotter.render(Plot("e", "t", "v", [Series("A.x", [], []), Series("B.y", [0.0, 1.0], [1.0, 2.0])]), "d")
    assert empty.legend == [("A.x (no frames)", ""), ("B.y", "#d62728")]


def test_fault_window_is_shaded(tmp_path: Path) -> None:
    html = write_html(_run(), tmp_path / "r.html").read_text(encoding="utf-8")
    case = html[html.index('id="case-31"'):]
    rect = re.search(r'<rect class="fault" x="([\d.]+)" y="\d+" width="([\d.]+)"', case)
    assert rect is not None and "fault drop:VCU_WheelCmd_FL@case+1-2 (100 frames)" in case
    # bench time 11-12 s with x0 = 10 s: x from 1 s to 2 s of a 0..4.99 s axis (56 px margin, 574 px wide)
    x0, width = float(rect.group(1)), float(rect.group(2))
    span = 4.99 * 1.06    # the data range plus 3 % padding either side
    assert abs(width - 574 * 1.0 / span) < 1.0 and abs(x0 - (56 + 574 * (1.0 + 0.03 * 4.99) / span)) < 1.0


def _points(d: str) -> list[tuple[float, float]]:
    """The absolute points of a path written as bench.report.plots._path writes it (M x y, then l dx dy ...)."""
    head, _, steps = d.partition("l")
    x, y = (float(v) for v in head[1:].split())
    points = [(x, y)]
    numbers = [float(v) for v in re.findall(r"-?\d*\.?\d+", steps)]
    for dx, dy in zip(numbers[::2], numbers[1::2]):
        x, y = x + dx, y + dy
        points.append((x, y))
    return points


def test_plot_y_range_has_a_margin() -> None:
    """Issue 27 finding 7: a signal held at its maximum or minimum lay on the plot's frame (3 % margin). Now the
    extremes are at least 5 % of the axes' height inside it."""
    from bench.report import plots

    t = [0.0, 1.0, 1.0, 2.0, 2.0, 3.0]
    held = plots.Plotter().render(Plot("step", "t", "deg", [Series("held", t, [0.0, 0.0, 1.0, 1.0, 0.0, 0.0])]), "m")
    [d] = re.findall(r'<path class="s" stroke="[^"]+" d="([^"]*)"', held.svg)
    ys = [y for _, y in _points(d)]
    height = plots._SIZE["time"][1] - plots._TOP - plots._BOTTOM
    top, bottom = plots._TOP, plots._TOP + height
    assert min(ys) - top >= 0.05 * height and bottom - max(ys) >= 0.05 * height, (top, min(ys), max(ys), bottom)
