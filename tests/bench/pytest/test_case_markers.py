"""Acceptance of the campaign's conformance markers: every case that uses the `bench` fixture says which
node(s) it judges (@pytest.mark.dut), and every requirement id a case names (@pytest.mark.req) exists in
the contract documents that bench.toml lists. Each offender is named.

The project's test cases are collected (not run) in-process with pytest's own API, so module, class
and parameter marks count exactly as they do in a run.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from bench.config import ProjectConfig, load_config
from bench.pytest.marks import read_marks
from tests.repo import ROOT


@dataclass(eq=False)   # pytest keeps plugins in sets
class _Collected:
    """A pytest plugin that keeps what collection found: each case's fixtures and marks, and the errors."""

    cases: list[tuple[str, bool, list[str], list[str]]] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    exit_code: int = 0

    def pytest_collectreport(self, report: pytest.CollectReport) -> None:
        if report.failed:
            self.errors.append(f"{report.nodeid}: {report.longreprtext}")

    def pytest_collection_modifyitems(self, items: list[pytest.Item]) -> None:
        for item in items:
            marks = read_marks(item)
            self.cases.append((item.nodeid, "bench" in getattr(item, "fixturenames", ()), marks.duts, marks.reqs))


@pytest.fixture(scope="module")
def project() -> ProjectConfig:
    return load_config(ROOT / "bench.toml")


@pytest.fixture(scope="module")
def collected(project: ProjectConfig) -> _Collected:
    found = _Collected()
    found.exit_code = pytest.main([str(project.testcases), "--collect-only", "-p", "no:terminal",
                                   "-p", "no:cacheprovider",
                                   "--rootdir", str(ROOT), "--bench-config", str(project.path)], plugins=[found])
    return found


def test_the_campaign_collects(collected: _Collected) -> None:
    """The plugin turns a bad marker (unknown node, unknown requirement id, empty marker) into its module's
    collection error, naming the case and the value."""
    assert not collected.errors, "collection errors:\n" + "\n".join(collected.errors)
    assert collected.exit_code == pytest.ExitCode.OK, f"pytest --collect-only exited {collected.exit_code}"
    assert sum(1 for _, bench, _, _ in collected.cases if bench) > 0


def test_every_bench_case_declares_the_nodes_it_judges(collected: _Collected) -> None:
    missing = [nodeid for nodeid, bench, duts, _ in collected.cases if bench and not duts]
    assert not missing, f"{len(missing)} case(s) without @pytest.mark.dut(...):\n" + "\n".join(missing)


def test_every_requirement_id_is_in_the_contract(collected: _Collected, project: ProjectConfig) -> None:
    assert project.contract, f"{project.path} lists no [contract] documents"
    known = {r.id for r in project.requirements}
    unknown = [f"{nodeid}: {rid}" for nodeid, _, _, reqs in collected.cases for rid in reqs if rid not in known]
    assert not unknown, f"{len(unknown)} requirement id(s) not in {', '.join(map(str, project.contract))}:\n" + \
        "\n".join(unknown)


def test_every_bench_case_checks_a_requirement(collected: _Collected) -> None:
    missing = [nodeid for nodeid, bench, _, reqs in collected.cases if bench and not reqs]
    assert not missing, f"{len(missing)} case(s) without @pytest.mark.req(...):\n" + "\n".join(missing)


def test_calibration_marker_is_checked_against_bench_toml_for_external_nodes_only() -> None:
    """@pytest.mark.calibration names what bench.toml's [calibration.NODE] must give while NODE is external: a
    missing name or another unit is one line naming the key; the bench's own simulated ECU needs none; a malformed
    marker is a marker problem."""
    from types import SimpleNamespace

    from bench.pytest.marks import missing_calibration

    def marks_of(*marks: pytest.Mark):   # read_marks reads an item's iter_markers only
        return read_marks(SimpleNamespace(iter_markers=lambda: list(marks)))    # type: ignore[arg-type]

    marks = marks_of(pytest.mark.calibration("ABS", v_l0="km/h", v_l1="km/h").mark)
    assert marks.calibration == {"ABS": {"v_l0": "km/h", "v_l1": "km/h"}} and not marks.problems
    table = {"ABS": {"v_l0": (0.6, "km/h"), "v_l1": (2.5, "m/s")}}
    assert missing_calibration(marks, external={"VCU"}, calibration={}) == []          # simulated ABS: none needed
    assert missing_calibration(marks, external={"ABS"}, calibration=table) == [
        "[calibration.ABS] v_l1: unit 'm/s', the case needs 'km/h'"]
    assert missing_calibration(marks, external={"ABS"}, calibration={}) == [
        '[calibration.ABS] v_l0: missing (give v_l0 = { value = <number>, unit = "km/h" }, the external ABS\'s value)',
        '[calibration.ABS] v_l1: missing (give v_l1 = { value = <number>, unit = "km/h" }, the external ABS\'s value)']
    for bad in (pytest.mark.calibration("ABS"), pytest.mark.calibration("ABS", "VCU", v_l0="km/h"),
                pytest.mark.calibration("ABS", v_l0="")):
        assert marks_of(bad.mark).problems, bad
