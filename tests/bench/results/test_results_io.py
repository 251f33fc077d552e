"""The worker's part of a run (bench.results.store): the fast writer gives the text asdict gave, and reads back."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import pytest

from bench.results import store as results_io
from bench.results.model import (
    CaseRef,
    CaseResult,
    FaultRecord,
    Finding,
    Plot,
    RequirementInfo,
    RunResult,
    Series,
    Step,
    Table,
)


def _run() -> RunResult:
    """Every kind of field: nested dataclasses, NaN and infinities, None, tuples, empty lists, unicode."""
    step = Step("FL angle", math.nan, 12.5, "±0.05", "fail", 1.25, unit="°", detail="τ")
    plot = Plot("angles", "t [s]", "deg", [Series("FL", [0.0, 0.001, 0.002], [1.0, math.inf, -math.inf], gap=0.025),
                                           Series("FR", [], [], None)], kind="xy", x0=None)
    fault = FaultRecord("drop:VCU_WheelCmd@case+0.5-1", "command line", "drop", "VCU_WheelCmd", 0.5, None, frames=3,
                        relative="case")
    case = CaseResult("t.py::test_a[S=(1,2)]", "test_a[S=(1,2)]", "failed", 0.05, 1.0, 3.0, steps=[step],
                      plots=[plot], tables=[Table("t", ["a", "b"], [["1", "2"]])], notes=["n"], message="m",
                      duts=["VCU"], reqs=["VCU-FLT-03"], faults=[fault], invalid_frames=2,
                      invalid=[["WHL_Status_FL", "E2E counter", "2"]])
    run = RunResult("2026-11-24T21:00:00+00:00", "embedded", "", "virtual", external=["SBW"], cases=[case],
                    mcap_path="run-gw0.mcap", wall_time=9.5, sim_time=134.8, frames=269504,
                    requirements=[RequirementInfo("VCU-FLT-03", "Priority between faults", "docs/contract/vcu.md", 40)],
                    deselected=[CaseRef("t.py::test_b", "test_b", ["ABS"], [])], faults=[fault],
                    findings=[Finding("bench.sim.station", "warning", "not sent", None, 2)])
    run.tables.append(Table("tuple rows", ["x"], [("a",), ("b",)]))   # type: ignore[list-item]
    return run


def test_dumps_is_the_text_asdict_gave() -> None:
    """The merged report and results.json must not change: same keys, order, floats and NaN spelling."""
    run = _run()
    assert results_io.dumps(run) == json.dumps(asdict(run), allow_nan=True)


def test_dump_and_load_round_trip(tmp_path: Path) -> None:
    run = _run()
    run.tables.pop()   # tuples come back as lists: not a round trip by design
    results_io.dump(run, tmp_path / "parts" / "gw0.json")
    back = results_io.load(tmp_path / "parts" / "gw0.json")
    assert results_io.dumps(back) == results_io.dumps(run)
    assert back.cases[0].plots[0].series[0].y[1] == math.inf and math.isnan(back.cases[0].steps[0].measured)


def test_dumps_refuses_what_json_cannot_write() -> None:
    run = _run()
    run.cases[0].notes.append(object())   # type: ignore[arg-type]
    with pytest.raises(TypeError, match="object is not JSON serializable"):
        results_io.dumps(run)


def test_a_time_plot_is_written_to_the_microsecond(tmp_path: Path) -> None:
    """Issue 27, finding 4: a campaign's results.json was 16 MB, 60 % of it the times of its time plots written as
    0.0019999999999999983 (bench time minus the plot's start). To the microsecond they are the ticks again; the
    values, an xy plot's coordinates, the steps and the verdicts are written as they were."""
    start = 7.3                                      # a plot that starts late: its times carry the subtraction's noise
    ticks = [round(start + k * 0.001, 3) - start for k in range(2, 6)]
    assert ticks[0] != 0.002 and len(repr(ticks[0])) > 18
    noisy = [0.1 + 0.2, 1 / 3, math.nan]
    run = _run()
    case = run.cases[0]
    case.plots.append(Plot("time", "t [s]", "deg", [Series("FL", [*ticks, math.nan], [*noisy, 1.0], gap=0.025)],
                           x0=start))
    text = results_io.dumps(run)
    written = json.loads(text)["cases"][0]["plots"]
    assert written[1]["series"][0]["x"][:4] == [0.002, 0.003, 0.004, 0.005] and "0.0019999" not in text
    assert math.isnan(written[1]["series"][0]["x"][4])
    assert written[1]["series"][0]["y"][:2] == noisy[:2]                           # values untouched
    assert written[0] == json.loads(json.dumps(asdict(case.plots[0]), allow_nan=True))   # xy: as it was
    path = tmp_path / "results.json"
    results_io.dump(run, path)
    back = results_io.load(path)
    assert [(s.name, s.expected, s.verdict, s.time) for s in back.cases[0].steps] == [
        (s.name, s.expected, s.verdict, s.time) for s in case.steps]
    assert back.verdict == run.verdict and back.cases[0].outcome == case.outcome


def test_cases_that_never_ran_survive_the_round_trip_and_the_merge(tmp_path: Path) -> None:
    """Issue 27 finding 7: an aborted run counts the cases that never ran; results.json keeps the count and merging
    stopped shards sums it."""
    run = _run()
    run.tables.pop()
    run.aborted, run.not_run = True, 6
    results_io.dump(run, tmp_path / "r.json")
    back = results_io.load(tmp_path / "r.json")
    assert back.not_run == 6
    assert results_io.merge([("a", back), ("b", results_io.load(tmp_path / "r.json"))], 1.0).not_run == 12
