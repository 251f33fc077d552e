"""The `bench` fixture's scenario protocol comes from bench.toml's [scenario] (bench/ names no message), and
the checks no campaign case happens to use (`always`) still do what their docstrings say."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import replace

import pytest

from bench.case import Case
from bench.checks.steps import StepLog
from bench.config import RunSettings, ScenarioProtocol, load_config
from bench.errors import BenchError
from bench.results.model import CaseResult
from bench.session import BenchSession


def _session(**changes: object) -> Iterator[tuple[BenchSession, Case]]:
    session = BenchSession(replace(load_config(), **changes), RunSettings())   # type: ignore[arg-type]
    session.start()
    try:
        steps = StepLog(session.now)
        result = CaseResult(nodeid="t", name="t", outcome="passed", steps=steps.steps)   # as bench.run does
        yield session, Case(session, result, steps)
    finally:
        session.close()


@pytest.fixture
def on_bench() -> Iterator[tuple[BenchSession, Case]]:
    yield from _session()


def test_start_scenario_uses_the_configured_names(on_bench: tuple[BenchSession, Case]) -> None:
    session, case = on_bench
    protocol = session.project.scenario
    assert protocol is not None
    case.start_scenario(Vehicle="EV4WIS")
    (command, id_signal), (ack, ack_signal) = protocol.command, protocol.ack
    sent = session.runner.restbus.slots[command].values[id_signal]            # type: ignore[union-attr]
    assert sent >= 1 and case.value(ack, ack_signal) == sent
    case.start_scenario(Vehicle="EV4WIS")                                          # the next id, acknowledged
    assert case.value(ack, ack_signal) == sent % 255 + 1                           # ScenarioId: 8 bits, 0..255


def test_values_after_start_scenario_are_the_new_scenarios(on_bench: tuple[BenchSession, Case]) -> None:
    """The CI failure of the example VCU (test_rotation_centre_at_infinity, one run in many): the plant's wheel
    status from before the reset, still the latest when its acknowledgement came, satisfied the next request's
    targets before the VCU had seen it. After start_scenario, value() reads only frames that came with or after
    the acknowledgement: a NaN that says so until the plant sends again, then the reset plant's values."""
    session, case = on_bench
    case.start_scenario(Vehicle="EV4WIS")
    case.set("DRV_MotionRequest", DriveMode="NORMAL", TargetSpeed=1.0)
    case.run(1.0)
    moving = case.value("WHL_Status_FL", "WheelSpeed")
    assert moving > 30.0                                                          # rpm at 1 m/s
    case.start_scenario(Vehicle="EV4WIS")
    monitor = session.runner.monitor                                              # type: ignore[union-attr]
    protocol = session.project.scenario
    assert protocol is not None
    acknowledged_at = monitor.state(protocol.ack[0]).last_valid
    earlier = [name for name, state in monitor.by_name.items()
               if state.last_valid is not None and state.last_valid < acknowledged_at]
    for name in earlier:                                                          # the last scenario's frames
        signal = session.codebook[name].signal_names[0]
        assert math.isnan(case.value(name, signal)), name
        assert "since the scenario started" in str(case.value(name, signal))
    assert earlier                                                                # the check above ran
    case.run(0.03)                                                                # every cycle is ≤ 20 ms
    speed = case.value("WHL_Status_FL", "WheelSpeed")
    assert not math.isnan(speed) and speed < moving / 2                           # the reset plant's


def test_the_timeout_is_the_configured_one() -> None:
    """1 ms is shorter than the plant's acknowledgement (its status message's cycle): the error names the
    configured timeout and acknowledgement signal."""
    base = load_config().scenario
    assert base is not None
    for _, case in _session(scenario=ScenarioProtocol(base.command, base.ack, timeout=0.001)):
        with pytest.raises(BenchError, match=rf"within 0\.001 s \({base.ack[0]}\.{base.ack[1]}\)"):
            case.start_scenario(Vehicle="EV4WIS")


def test_without_a_scenario_table_start_scenario_says_so() -> None:
    for session, case in _session(scenario=None):
        with pytest.raises(BenchError, match=r"has no \[scenario\] table") as error:
            case.start_scenario()
        assert str(session.project.path) in str(error.value)


def test_always_holds_and_is_violated(on_bench: tuple[BenchSession, Case]) -> None:
    session, case = on_bench
    t0 = case.now
    assert case.always("holds", lambda: True, 0.05)
    assert case.now == pytest.approx(t0 + 0.05, abs=0.0015)                       # it ran the whole 50 ms
    t1 = case.now
    assert not case.always("violated", lambda: session.now() < t1 + 0.02, 0.1)
    assert case.now == pytest.approx(t1 + 0.02, abs=0.0015)                       # it stopped at the violation
    held, violated = case.result.steps[-2:]
    assert (held.verdict, held.measured, held.expected) == ("pass", "held 0.05 s", "for 0.05 s")
    assert violated.verdict == "fail" and violated.measured.startswith("violated at +0.02")   # type: ignore[union-attr]


def test_check_cycle_times_fails_a_periodic_message_that_never_arrived(on_bench: tuple[BenchSession, Case]) -> None:
    """Issue 27 finding 5: a message a simulated node sends periodically, dropped for the whole case, is a failed
    cycle-time step (it used to get no step at all: only messages seen were checked)."""
    _, case = on_bench
    case.start_scenario(Vehicle="EV4WIS")
    case.inject("drop", "WHL_Status_FL")
    case.start_scenario(Vehicle="EV4WIS")          # the case's measurement starts after the last frame came
    case.run(0.5)
    assert not case.check_cycle_times()
    steps = {s.name: s for s in case.result.steps}
    dropped = steps["cycle time WHL_Status_FL"]
    assert (dropped.verdict, dropped.measured) == ("fail", "no frames since the case started")
    assert steps["cycle time WHL_Status_FR"].verdict == "pass"   # its neighbours came and pass
    assert [s.name for s in case.result.steps if s.verdict == "fail"] == ["cycle time WHL_Status_FL"]


def test_expect_clean_bus_judges_each_invalid_frame_as_its_senders(on_bench: tuple[BenchSession, Case]) -> None:
    """Invalid frames of a message the DUT does not send are its sender's step (the bench's own stimulus out of
    sequence on a late host is not the DUT's failure); the DUT's own invalid frames fail the case."""
    _, case = on_bench
    case.result.duts = ["VCU"]
    case.start_scenario(Vehicle="EV4WIS")
    assert case.expect_clean_bus()                                               # nothing invalid: one pass
    assert [(s.name, s.verdict, s.node) for s in case.result.steps[-1:]] == [
        ("no invalid frame on the bus (range, E2E, length)", "pass", "")]
    case.inject("counter_jump", "DRV_Steering", duration=0.05, param=5)              # sent by DRIVER, simulated
    case.run(0.2)
    assert not case.expect_clean_bus()
    step = case.result.steps[-1]
    assert (step.verdict, step.node) == ("fail", "DRIVER") and "DRV_Steering" in step.detail
    assert not case.result.failed_steps                                          # not the VCU's failure
    case.inject("counter_jump", "VCU_WheelCmd_FL", duration=0.05, param=5)           # the DUT's own message
    case.run(0.2)
    assert not case.expect_clean_bus()
    assert [s.name for s in case.result.failed_steps] == ["no invalid frame on the bus (range, E2E, length)"]
    assert "VCU_WheelCmd_FL" in case.result.failed_steps[0].detail


def test_e2e_statuses_count_since_the_scenario_started(on_bench: tuple[BenchSession, Case]) -> None:
    """One dropped frame of a 20 ms E2E message: the frame after it is OKSOMELOST (docs/spec/e2e.md). Counts start
    again with each scenario; a name no database has is refused."""
    session, case = on_bench
    case.start_scenario(Vehicle="EV4WIS")
    case.run(0.5)
    assert set(case.e2e_statuses("DRV_MotionRequest")) == {"OK"}
    case.inject("drop", "DRV_MotionRequest", after=0.0005, duration=0.020)
    case.run(0.2)
    assert case.e2e_statuses("DRV_MotionRequest").get("OKSOMELOST") == 1
    case.start_scenario(Vehicle="EV4WIS")
    assert "OKSOMELOST" not in case.e2e_statuses("DRV_MotionRequest")
    with pytest.raises(Exception, match="DRV_MotionReqest"):
        case.e2e_statuses("DRV_MotionReqest")
