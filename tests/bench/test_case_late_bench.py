"""Issue 25, acceptance 0: a step's verdict always agrees with the figure it prints, also when the bench runs late.

Found on an external VCU at load 5-10: `PASS VCU flags REQUEST_INVALID: measured 17.7287 s, expected ≤ 0.2 s s
(eventually)`. In real time the limit of `eventually` was counted in the tick loop's ticks, and the figure on the
clock: a tick loop that had fallen behind gave the check 17.7 s of bench time, and the step passed.

Here a real-time bench (udp_multicast on one IPv4 group with hop limit 0, its plant in the process) is made late on
purpose: a timer of the runner blocks 10 ms in every 1 ms tick, so its ticks fall behind the clock about tenfold.
Each check is given a predicate that turns at a tick (the tick loop's time, as frames read by a late loop) or at
a moment of the clock; whatever the verdict, it must follow from the figure.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Iterator

import pytest

from bench.case import Case
from bench.checks.steps import StepLog
from bench.checks.timing import SelfTiming
from bench.config import RunSettings, load_config
from bench.results.model import CaseResult, Step
from bench.session import BenchSession
from tests.fakes import ipv4_group

BLOCK_S = 0.010    # each tick of the runner blocks this long (a blocking sleep in the runner between ticks)
LIMIT_S = 0.4      # every check's limit
IN_TIME, TOO_LATE = 0.05, 0.8   # s of the clock: well inside the limit (a stalled tick or two), and past it
LATE_TICKS = 0.2   # s of ticks: about 2 s of the clock at ten times late, far past the limit


@pytest.fixture
def late_bench() -> Iterator[tuple[BenchSession, Case]]:
    group = ipv4_group()
    session = BenchSession(load_config(), RunSettings(interface="udp_multicast", channel=group))
    session.start()
    try:
        steps = StepLog(session.now)
        case = Case(session, CaseResult(nodeid="t", name="t", outcome="passed", steps=steps.steps), steps)
        case.every(0.001, lambda now: time.sleep(BLOCK_S))
        yield session, case
    finally:
        session.close()


def _ticks_after(session: BenchSession, seconds: float) -> Callable[[], bool]:
    """True from the tick `seconds` after now on (the tick loop's time: a late loop gets there late)."""
    end = session.scheduler.now + seconds
    return lambda: session.scheduler.now >= end


def _clock_after(session: BenchSession, seconds: float) -> Callable[[], bool]:
    """True from `seconds` of bench time (the clock) after now on."""
    end = session.now() + seconds
    return lambda: session.now() >= end


def _not(predicate: Callable[[], bool]) -> Callable[[], bool]:
    return lambda: not predicate()


def _recording(session: BenchSession, turns: Callable[[], bool], held_at: list[float]) -> Callable[[], bool]:
    """`turns`, and the bench time (since now) of the first check that found it true into `held_at`."""
    t0 = session.now()

    def predicate() -> bool:
        if turns():
            held_at.append(session.now() - t0)
            return True
        return False

    return predicate


def _eventually_agrees(step: Step) -> None:
    """pass ⇔ the measured time is a number ≤ the limit; the unit is the step's, once."""
    assert step.unit == "s" and step.expected == f"≤ {LIMIT_S:g}", step
    if isinstance(step.measured, float):
        assert step.verdict == ("pass" if step.measured <= LIMIT_S else "fail"), step
    else:
        assert (step.verdict, step.measured) == ("fail", f"not within {LIMIT_S:g}"), step


def _always_agrees(step: Step) -> None:
    """fail ⇔ violated at a time inside the window; pass ⇔ "held" the window."""
    assert step.expected == f"for {LIMIT_S:g} s" and step.unit == "", step
    violated = re.fullmatch(r"violated at \+([0-9.e-]+) s", str(step.measured))
    if violated:
        assert step.verdict == "fail" and float(violated.group(1)) <= LIMIT_S, step
    else:
        assert (step.verdict, step.measured) == ("pass", f"held {LIMIT_S:g} s"), step


def test_the_bench_is_late(late_bench: tuple[BenchSession, Case]) -> None:
    """The premise: a tick of the runner costs the clock 10 ms or more."""
    session, case = late_bench
    t0, tick0 = case.now, session.scheduler.now
    case.run(0.02)
    assert case.now - t0 >= 5 * (session.scheduler.now - tick0), (case.now - t0, session.scheduler.now - tick0)


def test_eventually_passes_only_on_a_figure_within_its_limit(late_bench: tuple[BenchSession, Case]) -> None:
    session, case = late_bench
    # the failure: the limit counted in ticks, 0.2 s of ticks ≈ 2 s of bench time, and a pass
    case.eventually("turns at a late tick", _ticks_after(session, LATE_TICKS), LIMIT_S)
    case.eventually("turns on the clock in time", _clock_after(session, IN_TIME), LIMIT_S)
    case.eventually("turns on the clock too late", _clock_after(session, TOO_LATE), LIMIT_S)
    case.eventually("true at once", lambda: True, LIMIT_S)
    late, in_time, too_late, at_once = case.result.steps
    for step in case.result.steps:
        _eventually_agrees(step)
    assert late.verdict == "fail" and too_late.verdict == "fail", (late, too_late)
    assert in_time.verdict == "pass" and at_once.verdict == "pass", (in_time, at_once)


def test_always_fails_only_on_a_violation_inside_its_window(late_bench: tuple[BenchSession, Case]) -> None:
    session, case = late_bench
    # before: violated at a tick 0.2 s on, seen ≈ 2 s of bench time on: "violated at +2.0 s" for 0.4 s, a fail
    case.always("breaks at a late tick", _not(_ticks_after(session, LATE_TICKS)), LIMIT_S)
    case.always("breaks on the clock inside the window", _not(_clock_after(session, IN_TIME)), LIMIT_S)
    case.always("holds", lambda: True, LIMIT_S)
    late, inside, holds = case.result.steps
    for step in case.result.steps:
        _always_agrees(step)
    assert inside.verdict == "fail" and holds.verdict == "pass", (inside, holds)
    assert late.verdict == "pass", late   # the window ended before the late loop reached the violation


def test_wait_until_is_true_only_within_its_limit(late_bench: tuple[BenchSession, Case]) -> None:
    """wait_until records no step: its answer must agree with the bench time at which the predicate held."""
    session, case = late_bench
    for make, seconds in ((_ticks_after, LATE_TICKS), (_clock_after, IN_TIME), (_clock_after, TOO_LATE)):
        held_at: list[float] = []
        t0 = case.now
        answer = case.wait_until(_recording(session, make(session, seconds), held_at), LIMIT_S)
        assert answer == (bool(held_at) and held_at[0] <= LIMIT_S), (make.__name__, seconds, answer, held_at)
        assert case.now - t0 < LIMIT_S + 0.8, "it ran on long after its limit"   # 10 ms ticks: a few late


def test_own_frames_late_make_the_case_inconclusive(late_bench: tuple[BenchSession, Case]) -> None:
    """The bench's own frames (its simulated VCU) come ten times too seldom: their cycle-time step fails, and how far
    past its bound is a figure of the bench's lateness, so the case is inconclusive on it alone. CI, 2026-11-29: a
    fully simulated real-time run failed `cycle time VCU_WheelCmd_FL` at p99 15.38 ms on a busy host, each frame
    late by less than the 20 ms that the bench's per-frame figures tolerate."""
    session, case = late_bench
    case.run(0.08)    # about 0.8 s of the clock: within the watchdog's 1 s
    assert not case.check_cycle_times(["VCU_WheelCmd_FL"], min_frames=2)
    assert session.self_timing is not None
    figures = {f.what: f for f in session.self_timing.since(case.start)}
    p99 = figures["VCU_WheelCmd_FL sent by the bench, cycle p99"]
    assert p99.late > p99.bound == pytest.approx(0.005), p99
    assert SelfTiming.verdict([p99]).startswith("bench late by "), p99
