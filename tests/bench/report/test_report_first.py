"""The report opens on what failed (issue 27, finding 7 and acceptance 4): in a report of 147 cases with one failure,
its timing and database tables (several screens long) and a conformance section, the failing case is open at the
top, its steps on the first screen of a 1280x900 window in headless Chromium; and the contract documents of a
bench.toml kept elsewhere are named by their path in their repository.

The run is built here (like the other report tests), not run: the campaign runs once, in
tests/integration/test_report_campaign.py, which checks the same on the real report.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from bench.config import load_config
from bench.pytest.plugin import _catalogue
from bench.report import write_html
from bench.results.model import CaseResult, Plot, RequirementInfo, RunResult, Series, Step, Table
from tests.browser import problems, run_browser
from tests.repo import ROOT

SCREEN = (1280, 900)
MARK = (0x00, 0xFF, 0x00)   # the failing case's step rows, painted in the copy the browser shows (layout unchanged)
STEPS = 4


def _campaign() -> RunResult:
    t = list(np.linspace(0.0, 3.0, 300))
    cases = [CaseResult(f"testcases/ev4wis/test_x.py::test_ok[{i}]", f"test_ok[{i}]", "passed", sim_time=3.0,
                        wall_time=0.2, reqs=["VCU-MODE-01"], duts=["VCU"],
                        steps=[Step("angle", 1.0, 1.0, "±0.05 deg", "pass", 1.0, "deg")],
                        plots=[Plot("angle", "t", "deg", [Series("a", t, list(np.sin(t)))])]) for i in range(146)]
    failing = CaseResult(
        "testcases/sbw/test_z.py::test_the_one_that_fails", "test_the_one_that_fails", "failed", sim_start=400.0,
        sim_time=3.0, wall_time=0.3, reqs=["SBW-CTL-01"], duts=["SBW"],
        steps=[Step("pinion angle", -4.9, -4.8862962808010275, "±0.005 deg", "fail", 401.0, "deg"),
               *(Step(f"check {k}", 1.0, 1.0, "±0.1", "pass", 401.5, "") for k in range(STEPS - 1))],
        plots=[Plot("pinion", "t", "deg", [Series("p", t, list(np.cos(t)))])])
    rows = [[f"0x{i:03X}", f"MSG_{i}", "VCU", "10", "a comment long enough to wrap a little in a table cell"]
            for i in range(150)]
    tables = [Table(f"Timing: cycle times part {k}", ["id", "message", "sender", "cycle [ms]", "comment"], rows)
              for k in range(3)]
    requirements = [RequirementInfo("VCU-MODE-01", "Modes", "docs/contract/vcu.md", 10),
                    RequirementInfo("SBW-CTL-01", "Control", "docs/contract/sbw.md", 20)]
    return RunResult("2026-11-27T10:00:00", "embedded", "", "virtual", cases=[*cases, failing], tables=tables,
                     requirements=requirements, frames=724330, wall_time=28.4, sim_time=476.3)


def _marked_rows(pixels: np.ndarray) -> list[int]:
    """The first screen's pixel rows where a marked step row shows."""
    mark = np.all(np.abs(pixels - MARK) < 24, axis=-1)
    return [int(y) for y in np.flatnonzero(mark.sum(axis=1) > 40)]


def test_the_failing_case_s_steps_are_on_the_first_screen(tmp_path: Path) -> None:
    page = write_html(_campaign(), tmp_path / "report.html")
    html = page.read_text(encoding="utf-8")
    dom, stderr = run_browser(tmp_path, "--enable-logging=stderr", "--v=0", "--dump-dom", page.as_uri())
    assert problems(dom, stderr) == []
    case = dom.index('id="case-147"')
    assert dom.rfind("<details", 0, case) > dom.rfind(">", 0, dom.rfind("<details", 0, case))   # sanity
    opening = dom[dom.rfind("<details", 0, case):dom.index(">", case)]
    assert " open" in opening                                                     # expanded, not collapsed
    assert case < dom.index('id="summary"') < dom.index("Timing: cycle times part 0")   # before every table

    # the copy the browser shows paints that case's step rows (background only: the layout is the report's)
    paint = ("<style>#case-147 table.steps td { background: #00ff00 !important; color: #00ff00 !important; }"
             "</style></head>")
    shown = tmp_path / "painted.html"
    shown.write_text(html.replace("</head>", paint, 1), encoding="utf-8")
    shot = tmp_path / "first-screen.png"
    run_browser(tmp_path, f"--screenshot={shot}", f"--window-size={SCREEN[0]},{SCREEN[1]}", shown.as_uri())
    import matplotlib.image

    pixels = (matplotlib.image.imread(shot)[..., :3] * 255).round().astype(int)
    assert pixels.shape[:2] == (SCREEN[1], SCREEN[0])
    rows = _marked_rows(pixels)
    assert rows, "the failing case's steps are not on the first screen"
    bands = 1 + sum(1 for a, b in zip(rows, rows[1:]) if b > a + 1)               # one band per table row
    assert bands == STEPS and max(rows) < SCREEN[1] - 1, (bands, min(rows), max(rows))   # every step, whole


def test_contract_paths_from_a_config_elsewhere_are_the_repository_s(tmp_path: Path) -> None:
    """A bench.toml outside the repository naming its documents by a relative path: the conformance table
    showed `../../repo/docs/contract/vcu.md`; now the path in the repository."""
    text = (ROOT / "bench.toml").read_text(encoding="utf-8")
    there = os.path.relpath(ROOT, tmp_path)
    for folder in ("dbc/", "docs/contract/", "testcases", "reports"):
        text = text.replace(f'"{folder}', f'"{there}/{folder}')
    config = tmp_path / "bench.toml"
    config.write_text(text, encoding="utf-8")
    documents = {r.document for r in _catalogue(load_config(config))}
    assert documents and all(d.startswith("docs/contract/") and ".." not in d for d in documents), documents
    assert "docs/contract/vcu.md" in documents
