"""The fixture reference, docs/reference/fixture.md, is markdown read in the repository without a build step
(issue 27, finding 6: it was `::: bench.case.Case`, a directive only an mkdocs build with the docs extra turns into
text). `python -m bench.pytest.fixturedoc` writes it from bench/case.py's docstrings and bench.toml's [scenario]; these
tests fail while the checked-in page is not what the command writes."""

from __future__ import annotations

import subprocess
import sys

from bench.case import Case
from bench.config import load_config
from bench.pytest import fixturedoc
from tests.repo import ROOT

PAGE = ROOT / "docs" / "reference" / "fixture.md"


def test_the_page_is_what_the_command_writes() -> None:
    assert PAGE.read_text(encoding="utf-8") == fixturedoc.render(load_config(ROOT / "bench.toml")), (
        "docs/reference/fixture.md is out of date: run `python -m bench.pytest.fixturedoc`")


def test_the_page_is_text_not_a_directive() -> None:
    page = PAGE.read_text(encoding="utf-8")
    assert ":::" not in page
    for name, member in vars(Case).items():
        if not name.startswith("_") and callable(member):
            assert f"### `{name}(" in page, name


def test_the_page_lists_the_settings_of_a_scenario() -> None:
    """start_scenario's settings (InitialSpeed, RoadMu, ...) were listed nowhere: they come from bench.toml's
    [scenario] command message, with unit, range, start value and value table."""
    page = PAGE.read_text(encoding="utf-8")
    for row in ("| `RoadMu` | - | 0 … 1.5 | 1 |", "| `InitialSpeed` | m/s | 0 … 80 | 0 |",
                "| `Vehicle` | - | 0 … 15 | 0 | 0 `EV4WIS`, 1 `ACLASS`, 2 `ACLASS_ABS` |"):
        assert row in page, row
    assert "`ScenarioId` |" not in page and "`AliveCounter` |" not in page   # the id and E2E are the bench's


def test_the_page_explains_dut_and_req() -> None:
    page = PAGE.read_text(encoding="utf-8")
    assert "## Conformance markers: `dut` and `req`" in page
    assert "- `dut(NODE, ...)`:" in page and "- `req(ID, ...)`:" in page and "bench run --dut NODE" in page


def test_check_mode() -> None:
    result = subprocess.run([sys.executable, "-m", "bench.pytest.fixturedoc", "--check"], cwd=ROOT, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
