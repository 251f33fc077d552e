"""The project's test cases are grouped per campaign: every case carries exactly one
`@pytest.mark.campaign(name=...)` (set from its package's CAMPAIGN by testcases/conftest.py), each campaign's
cases live in its own package, and `-m "campaign(name='...')"` selects exactly that package, so no list of
cases is needed to run one campaign (the vcan lane selects the 4WIS campaign by its package path).

The cases are collected (not run) in-process with pytest's own API, so marks count exactly as in a run.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from bench.pytest.marks import CAMPAIGN
from testcases.limits import load_limits
from tests.repo import ROOT

TESTCASES = ROOT / "testcases"
#: campaign -> its package under testcases/ (the issue's four campaigns)
PACKAGES = {"4WIS": "ev4wis", "4WS": "rear_steer_4ws", "SBW": "sbw", "ABS": "abs", "diagnostics": "diagnostics"}
#: campaign -> the table of its package's limits.toml
LIMIT_TABLES = {"4WIS": "4wis", "4WS": "4ws", "SBW": "sbw", "ABS": "abs", "diagnostics": "diagnostics"}


@dataclass(eq=False)   # pytest keeps plugins in sets
class _Collected:
    """A pytest plugin that keeps each collected case's campaign marks, and the collection errors."""

    cases: dict[str, list[str]] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    exit_code: int = 0

    def pytest_collectreport(self, report: pytest.CollectReport) -> None:
        if report.failed:
            self.errors.append(f"{report.nodeid}: {report.longreprtext}")

    @pytest.hookimpl(trylast=True)   # after -m has deselected
    def pytest_collection_modifyitems(self, items: list[pytest.Item]) -> None:
        for item in items:
            self.cases[item.nodeid] = [str(m.kwargs.get("name", m.args[0] if m.args else ""))
                                       for m in item.iter_markers(CAMPAIGN)]


def _collect(*extra: str) -> _Collected:
    found = _Collected()
    found.exit_code = pytest.main([str(TESTCASES), "--collect-only", "-p", "no:terminal", "-p", "no:cacheprovider",
                                   "--rootdir", str(ROOT), "--bench-config", str(ROOT / "bench.toml"), *extra],
                                  plugins=[found])
    assert not found.errors, "collection errors:\n" + "\n".join(found.errors)
    return found


@pytest.fixture(scope="module")
def collected() -> _Collected:
    return _collect()


def test_every_case_has_exactly_one_campaign(collected: _Collected) -> None:
    assert collected.exit_code == pytest.ExitCode.OK and collected.cases
    wrong = [f"{nodeid}: {names or 'none'}" for nodeid, names in collected.cases.items() if len(names) != 1]
    assert not wrong, f"{len(wrong)} case(s) without exactly one campaign:\n" + "\n".join(wrong)


def test_each_campaign_is_its_own_package(collected: _Collected) -> None:
    assert {names[0] for names in collected.cases.values()} == set(PACKAGES)
    misplaced = [f"{nodeid}: {names[0]}" for nodeid, names in collected.cases.items()
                 if not nodeid.startswith(f"testcases/{PACKAGES[names[0]]}/")]
    assert not misplaced, "cases outside their campaign's package:\n" + "\n".join(misplaced)


@pytest.mark.parametrize("campaign", ["4WIS", "ABS"])
def test_a_campaign_is_selected_by_its_marker(collected: _Collected, campaign: str) -> None:
    """-m selects the same cases as the package path, and nothing else."""
    selected = _collect("-m", f"campaign(name='{campaign}')")
    in_package = {n for n in collected.cases if n.startswith(f"testcases/{PACKAGES[campaign]}/")}
    assert in_package and set(selected.cases) == in_package


@pytest.mark.parametrize("campaign", sorted(PACKAGES))
def test_each_campaign_has_its_limits_with_sources(campaign: str) -> None:
    """Every campaign keeps its acceptance limits in its own package, each with a unit and a source."""
    limits = load_limits(TESTCASES / PACKAGES[campaign] / "limits.toml", LIMIT_TABLES[campaign])
    assert limits
    unsourced = [name for name, (_, unit, source) in limits.items() if not unit.strip() or not source.strip()]
    assert not unsourced, f"limits without a unit or a source: {unsourced}"
