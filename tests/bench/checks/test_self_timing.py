"""The bench's own timing in real time (issue 25): what it sent is timed by when it went out, a late bench is
named with its figures, a starved tick loop ends its case by the watchdog, and a long case keeps its history.

The real-time tests are short (under 2 s of wall time each) and run on udp_multicast with hop limit 0 on a
random group, so nothing leaves the host and two runs side by side do not meet.
"""

from __future__ import annotations

import json
import math
import random
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import can
import pytest

from bench.case import Case
from bench.checks.monitor import HISTORY_CAP, Monitor
from bench.checks.steps import StepLog
from bench.checks.timing import Late, SelfTiming, TimingCollector
from bench.cli.run import EXIT_INCONCLUSIVE
from bench.config import RunSettings, load_config
from bench.database.codec import load_codebook
from bench.errors import BenchLimit, ConfigError, Inconclusive
from bench.results.model import CaseResult
from bench.session import BenchSession
from bench.sim.clock import Scheduler, WallClock, watchdog_bound
from bench.sim.restbus import Restbus
from bench.sim.station import LATE_CYCLES, Station
from tests.fakes import ipv4_group
from tests.repo import ROOT

STIMULUS = "DRV_Pedals"     # 10 ms, sent by the runner (the stimulus node DRIVER)


def _case(session: BenchSession, duts: list[str] | None = None) -> Case:
    steps = StepLog(session.now)
    result = CaseResult(nodeid="t", name="t", outcome="passed", steps=steps.steps, sim_start=session.now(),
                        duts=list(duts or []))
    return Case(session, result, steps)


# -- the figures ------------------------------------------------------------------------------------------------
def test_between_cases_nothing_is_counted() -> None:
    """`bench run` pauses the bench's own timing until the first case and after each: a stall while it starts or
    writes a case's results is no case's, and the whole run's table says "during the cases"."""
    timing = SelfTiming()
    timing.pause()
    timing.add("tick loop", 0.280, 0.001)                # the start, before the first case
    timing.resume(1.0)
    timing.add("tick loop", 0.004, 1.5)
    timing.pause()                                       # the case ended
    timing.add("tick loop", 0.090, 2.1)                  # its plots and results
    timing.resume(3.0)
    timing.add("tick loop", 0.006, 3.2)
    rows = {row[0]: row for row in timing.table().rows}
    assert rows["tick loop"][1] == "2" and float(rows["tick loop"][4]) == pytest.approx(6.0, abs=0.01), rows
    assert [e.late for e in timing.since(0.0)] == [pytest.approx(0.006)]


def test_a_case_sees_its_events_out_of_time_order() -> None:
    """A frame that waited in its socket is timed at its arrival, which may come before the case started, after
    events of the case's own ticks: the case's figures still hold every event since it began."""
    timing = SelfTiming()
    timing.add("tick loop", 0.050, 0.5)                  # the case before
    timing.resume(1.0)
    timing.add("tick loop", 0.250, 1.001)                # the case's first tick, late
    timing.add("receive path", 0.030, 0.999)             # a frame that arrived just before the case began
    timing.add("tick loop", 0.003, 1.2)
    worst = {e.what: e.late for e in timing.since(1.0)}
    assert worst == {"tick loop": pytest.approx(0.250)}, worst
    assert [e.late for e in timing.since(0.0)][0] == pytest.approx(0.250)


def test_self_timing_keeps_the_worst_per_source_and_names_what_passed_its_bound() -> None:
    timing = SelfTiming()
    timing.add("stimulus A", 0.001, 1.0, 0.02)          # on time: counted, no event
    timing.add("stimulus A", 0.146, 12.3, 0.02)         # past its bound
    timing.add("stimulus A", 0.010, 12.4, 0.02)
    timing.add("tick loop", 0.050, 12.35)               # a figure only (no bound)
    assert [e.what for e in timing.since(12.0)] == ["stimulus A", "tick loop"]
    assert timing.since(12.0)[0].late == pytest.approx(0.146)
    assert timing.since(13.0) == []
    line = SelfTiming.verdict(timing.since(0.0))
    assert line == "bench late by 146.0 ms on stimulus A at 12.300 s (bound 20 ms)"
    assert SelfTiming.verdict([Late("stimulus A", 0.019, 1.0, 0.02)]) == ""
    rows = {row[0]: row for row in timing.table().rows}
    assert rows["stimulus A"][1] == "3" and rows["stimulus A"][4] == "146.00" and rows["stimulus A"][-1] == "1"


def test_the_watchdog_bound_comes_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("BENCH_WATCHDOG", raising=False)
    assert watchdog_bound() == 1.0
    monkeypatch.setenv("BENCH_WATCHDOG", "0")
    assert math.isinf(watchdog_bound())
    monkeypatch.setenv("BENCH_WATCHDOG", "0.25")
    assert watchdog_bound() == 0.25
    monkeypatch.setenv("BENCH_WATCHDOG", "soon")
    with pytest.raises(ConfigError, match="BENCH_WATCHDOG"):
        watchdog_bound()


# -- acceptance 4: a delay injected into the bench's own sending shows ----------------------------------------
@pytest.fixture
def realtime_runner() -> Iterator[tuple[BenchSession, TimingCollector]]:
    """The runner alone (every other node external) on udp_multicast, its frames into a timing collector."""
    project = load_config()
    timing = TimingCollector(())
    session = BenchSession(project, RunSettings(interface="udp_multicast", channel=ipv4_group(), external=["all"]),
                           sink=timing)
    session.start()
    try:
        yield session, timing
    finally:
        session.close()


def test_a_delay_injected_into_the_bench_sending_shows_in_the_timing_table(
        realtime_runner: tuple[BenchSession, TimingCollector]) -> None:
    """The driver takes 120 ms for one frame of the stimulus: the cycle-time table (the run's timing section)
    shows a gap of at least that much, not the schedule's 10 ms, and the bench's own lateness names it."""
    session, timing = realtime_runner
    runner = session.runner
    assert runner is not None
    frame_id = session.codebook[STIMULUS].frame_id
    send, seen = runner.bus.send, [0]

    def slow_send(msg: can.Message, timeout: float | None = None) -> None:
        if msg.arbitration_id == frame_id:
            seen[0] += 1
            if seen[0] == 30:
                time.sleep(0.12)   # the bench's own sending, delayed (as a starved host would)
        send(msg, timeout)

    runner.bus.send = slow_send   # type: ignore[method-assign]
    session.run_until(0.8)
    stats = {s.message: s for s in timing.cycle_stats(session.codebook)}[STIMULUS]
    assert stats.max >= 0.12 and stats.gaps >= 1, stats
    assert session.self_timing is not None
    worst = {e.what: e for e in session.self_timing.since(0.0)}
    late = worst[f"stimulus {STIMULUS}"]
    assert late.late >= 0.10 and late.bound == pytest.approx(LATE_CYCLES * 0.01)
    assert "bench late by" in SelfTiming.verdict(session.self_timing.since(0.0))
    table = session.self_timing.table()
    assert any(row[0] == f"stimulus {STIMULUS}" and float(row[4]) >= 100.0 for row in table.rows), table.rows


def test_on_time_sending_is_timed_within_a_tick(realtime_runner: tuple[BenchSession, TimingCollector]) -> None:
    """Without a delay the same run's stimulus stays at its cycle: the stamps are the sending's, not noise."""
    session, timing = realtime_runner
    session.run_until(0.5)
    stats = {s.message: s for s in timing.cycle_stats(session.codebook)}[STIMULUS]
    assert stats.intervals >= 30 and abs(stats.p50 - 0.01) < 0.002, stats


def test_a_message_stopped_and_resumed_is_not_late(realtime_runner: tuple[BenchSession, TimingCollector]) -> None:
    """A stop on purpose (stop_sending, a scenario's stimulus) is no lateness: the resumed message is due from its
    resumption, not from its schedule before the stop."""
    session, _ = realtime_runner
    case = _case(session)
    case.stop_sending(STIMULUS)
    case.run(0.3)
    case.resume_sending(STIMULUS)
    case.run(0.1)
    worst = {e.what: e for e in session.self_timing.since(0.0)} if session.self_timing else {}
    assert f"stimulus {STIMULUS}" not in worst or worst[f"stimulus {STIMULUS}"].late < 0.02, worst


# -- the watchdog -------------------------------------------------------------------------------------------------
class _Stall:
    """A behaviour that blocks its tick loop once, at bench time `at`, for `seconds`."""

    nodes: tuple[str, ...] = ()

    def __init__(self, at: float, seconds: float) -> None:
        self.at, self.seconds, self.done = at, seconds, False

    def reset(self) -> None:
        pass

    def step(self, io: object, t: float, dt: float) -> None:
        if t >= self.at and not self.done:
            self.done = True
            time.sleep(self.seconds)


def test_the_watchdog_ends_a_run_whose_ticks_fall_behind_the_wall_clock(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("BENCH_WATCHDOG", "0.2")
    codebook = load_codebook(load_config().databases)
    clock = WallClock()
    bus = can.Bus(interface="virtual", channel=f"watchdog-{random.random()}")   # python-can's: real time
    try:
        station = Station("plant", bus, Restbus(codebook, set()), Monitor(codebook), clock.now, [_Stall(0.05, 0.3)])
        scheduler = Scheduler([station], clock)   # a plant's ticks are never skipped: it falls behind
        scheduler.self_timing = timing = SelfTiming()
        clock.start()
        with pytest.raises(Inconclusive, match=r"watchdog: bench time fell behind wall time by 0\.[2-9]\d* s"):
            scheduler.run_until(5.0)
        assert clock.now() < 1.0                          # ended at once, not after the 5 s asked
        assert scheduler.now >= 0.3                        # and went on from the wall clock's tick
        assert timing.sources["tick loop"].worst is not None
        scheduler.run_until(scheduler.now + 0.05)          # the next case runs on time again
        time.sleep(0.4)                                    # a pause between cases: no tick runs, by design
        scheduler.begin_case()
        scheduler.run_until(scheduler.now + 0.5)           # replays the pause's ticks: no watchdog
    finally:
        bus.shutdown()


# -- inconclusive, not failed -------------------------------------------------------------------------------------
def test_a_case_whose_stimulus_was_late_past_its_bound_is_inconclusive_with_the_figures(
        realtime_runner: tuple[BenchSession, TimingCollector]) -> None:
    session, _ = realtime_runner
    case = _case(session)
    case.every(0.2, lambda now: time.sleep(0.08))   # the runner blocked 80 ms: its 10 ms stimulus late by that
    case.run(0.5)
    line = case.bench_verdict()
    assert line.startswith("bench late by ") and " on stimulus " in line and "(bound 20 ms)" in line, line
    assert case.result.bench_timing and "late by" in case.result.bench_timing[0]
    case.close()


def _frames_with_gap(session: BenchSession, message: str, t0: float, gap_from: int) -> None:
    """20 frames of `message` every 10 ms from t0 into the runner's monitor, with 100 ms missing after frame
    `gap_from` (as `bench plant` in another process, stalled, would leave them)."""
    codec = session.codebook[message]
    restbus = Restbus(session.codebook, set(codec.senders))
    slot = restbus.slots[message]
    times = [t0 + 0.01 * i for i in range(1, gap_from + 1)] + [t0 + 0.1 + 0.01 * i for i in range(gap_from, 20)]
    for t in times:
        session.monitor.on_frame(t, codec.frame_id, restbus.build(slot), "rx")


def test_a_stalled_process_of_other_nodes_is_no_failure_of_the_dut(
        realtime_runner: tuple[BenchSession, TimingCollector]) -> None:
    """`bench plant` in another process starved for 100 ms: WHL_Status_FL and IMU_Motion, which the DUT reads,
    came 90 ms late at the same time; a VCU case that failed under it is inconclusive."""
    session, _ = realtime_runner
    case = _case(session, duts=["VCU"])
    _frames_with_gap(session, "WHL_Status_FL", case.start, 10)
    _frames_with_gap(session, "IMU_Motion", case.start, 10)
    line = case.bench_verdict()
    assert line.startswith("a sender other than the DUT late by 90.0 ms on input "), line
    judged = _case(session, duts=["WHL_FL"])   # a case that judges the wheel: the wheel's gap is the wheel's
    judged.start = case.start
    assert "WHL_Status_FL" not in judged.bench_verdict()


def test_a_stalled_plant_gapping_only_its_own_io_is_no_failure_of_the_dut(
        realtime_runner: tuple[BenchSession, TimingCollector]) -> None:
    """`bench plant` stalled 23.3 ms: its three 5 ms SBW I/O messages (all from PLANT) came 18.3 ms late, past
    LATE_CYCLES x 5 ms = 10 ms (and past the SBW's 15 ms I/O timeout), while its 10 ms messages stayed within
    their 20 ms bound. One node, three messages at once: a stall, so an SBW case that failed under it is
    inconclusive, not failed (it was failed before: "one node silent alone" took the stall as meant)."""
    session, _ = realtime_runner
    case = _case(session, duts=["SBW"])
    restbus = Restbus(session.codebook, {"PLANT"})
    cycle, stall = 0.005, 0.0233
    for k, message in enumerate(("IO_SbwHandWheel", "IO_SbwPinion", "IO_SbwCurrents")):
        codec = session.codebook[message]
        assert codec.cycle_time == cycle and tuple(codec.senders) == ("PLANT",)
        slot = restbus.slots[message]
        times = [case.start + 0.001 * k + cycle * i for i in range(1, 11)]
        times += [times[-1] + stall + cycle * i for i in range(10)]
        for t in times:
            session.monitor.on_frame(t, codec.frame_id, restbus.build(slot), "rx")
    line = case.bench_verdict()
    bound = LATE_CYCLES * cycle
    assert line.startswith(f"a sender other than the DUT late by {(stall - cycle) * 1000:.1f} ms on input IO_Sbw"), line
    assert f"(bound {bound * 1000:g} ms)" in line and "and 2 more" in line, line


def test_a_plant_stall_seen_past_its_bound_only_on_its_5_ms_io_is_no_failure_of_the_dut(
        realtime_runner: tuple[BenchSession, TimingCollector]) -> None:
    """CI rehearsal, 2026-11-29, the example ABS: `bench plant` stalled about 17 ms; IO_AbsSensors (5 ms) came 16.5 ms
    late, past its 10 ms bound, and PLANT_Motion (10 ms) 16.2 ms late, within its 20 ms bound. The ABS timed its
    sensors out and three steady cases failed: one message past its bound alone was taken as meant. The other
    message, as late at the same time, shows the stall: the case is inconclusive."""
    session, _ = realtime_runner
    case = _case(session, duts=["ABS"])
    restbus = Restbus(session.codebook, {"PLANT"})
    for message, stall in (("IO_AbsSensors", 0.0215), ("PLANT_Motion", 0.0262)):
        codec = session.codebook[message]
        cycle = codec.cycle_time
        assert cycle is not None and tuple(codec.senders) == ("PLANT",)
        slot = restbus.slots[message]
        times = [case.start + cycle * i for i in range(1, round(0.05 / cycle) + 1)]   # both stall at +0.05 s
        times += [times[-1] + stall + cycle * i for i in range(10)]
        for t in times:
            session.monitor.on_frame(t, codec.frame_id, restbus.build(slot), "rx")
    line = case.bench_verdict()
    assert line.startswith("a sender other than the DUT late by 16.5 ms on input IO_AbsSensors"), \
        (line, case.result.bench_timing)


def test_one_node_silent_alone_is_taken_as_meant(realtime_runner: tuple[BenchSession, TimingCollector]) -> None:
    """One node's message silent while every other sender goes on (a sensor fault the case asked the plant for)
    is a figure on the record, not a reason to call the case inconclusive."""
    session, _ = realtime_runner
    case = _case(session, duts=["VCU"])
    _frames_with_gap(session, "IMU_Motion", case.start, 10)
    assert case.bench_verdict() == ""
    assert any(line.startswith("input IMU_Motion from IMU: late by 90.0 ms") for line in case.result.bench_timing)


def test_the_bench_on_time_rules_nothing(realtime_runner: tuple[BenchSession, TimingCollector]) -> None:
    session, _ = realtime_runner
    case = _case(session)
    case.run(0.3)
    assert case.bench_verdict() == ""


def test_a_step_that_judges_another_node_is_that_nodes_and_never_fails_the_case() -> None:
    session = BenchSession(load_config(), RunSettings())
    session.start()
    try:
        case = _case(session, duts=["VCU"])
        case.expect("plant model against its reference", 4.67, 0.0, abs_tol=0.1, node="PLANT")
        case.run(0.5)
        case.check_cycle_times(["DRV_Pedals"], p50_band=0.0, p99_max=0.0)   # judges DRIVER (the bench's own)
        assert len(case.result.other_failed_steps) == 2
        assert {s.node for s in case.result.other_failed_steps} == {"PLANT", "DRIVER"}
        assert case.result.failed_steps == []
        case.expect("the DUT's own", 1.0, 2.0)
        assert [s.name for s in case.result.failed_steps] == ["the DUT's own"]
    finally:
        session.close()


# -- acceptance 3: a long case keeps its whole history -----------------------------------------------------------
def test_a_60_s_case_keeps_its_whole_history_for_a_check_and_a_plot_at_its_end() -> None:
    """60 s of (virtual) bench time: 6000 frames of a 10 ms message, twice what the monitor keeps from before a
    case (HISTORY_CAP); the case's history and its plot still start at the case's start."""
    session = BenchSession(replace(load_config()), RunSettings())
    session.start()
    try:
        session.run_until(40.0)                  # before the case: only the last frames are kept
        case = _case(session)
        case.start_scenario(Vehicle="EV4WIS")
        case.run(60.0)
        t, v = case.history("WHL_Status_FL", "SteerAngle")
        assert len(t) >= 5990 and t[0] - case.start < 0.011, (len(t), t[0], case.start)
        assert session.monitor.state("WHL_Status_FL").history_dropped > 0   # it did trim: what was before the case
        assert len(session.monitor.state("WHL_Status_FL").history_t) > 2 * HISTORY_CAP - 100
        assert t[-1] - t[0] > 59.9 and len(v) == len(t)
        case.plot("wheel FL", [("WHL_Status_FL", "SteerAngle")])
        assert len(case.result.plots[0].series[0].x) == len(t)
        with pytest.raises(Exception, match="before the case started"):   # before it: as before, ask for less
            case.history("WHL_Status_FL", "SteerAngle", since=1.0)
        case.close()
    finally:
        session.close()


def test_a_history_beyond_the_bench_limit_is_the_benchs_error(monkeypatch: pytest.MonkeyPatch) -> None:
    import bench.checks.monitor as monitor_module
    monkeypatch.setattr(monitor_module, "HISTORY_CAP", 50)
    monkeypatch.setattr(monitor_module, "HISTORY_MAX", 400)
    codebook = load_codebook(load_config().databases)
    monitor = Monitor(codebook, keep_history=True)
    restbus = Restbus(codebook, codebook["DRV_Pedals"].senders)
    slot = restbus.slots["DRV_Pedals"]
    frame_id = slot.codec.frame_id
    monitor.history_from = 0.0
    for i in range(300):   # within the limit: all kept
        monitor.on_frame(i * 0.01, frame_id, restbus.build(slot), "rx")
    # all kept: every applied frame, the first one held back by the E2E state machine (INIT, docs/spec/e2e.md)
    assert len(monitor.history("DRV_Pedals", "AccelPedal", 0.0)[0]) == 300 - 1
    for i in range(300, 900):
        monitor.on_frame(i * 0.01, frame_id, restbus.build(slot), "rx")
    with pytest.raises(BenchLimit, match="bench limit: history of DRV_Pedals"):
        monitor.history("DRV_Pedals", "AccelPedal", 0.0)


# -- the outcome through `bench run`: console, JUnit, results.json, exit code -----------------------------------
USER_CASES = '''
import time

import pytest


@pytest.mark.dut("VCU")
def test_late(bench):
    bench.every(0.25, lambda now: time.sleep(0.08))   # the runner blocked: its 10 ms stimulus 80 ms late
    bench.run(0.6)
    bench.expect("a check that fails under it", 1.0, 2.0)


@pytest.mark.dut("VCU")
def test_on_time(bench):
    bench.run(0.1)
    bench.expect_true("the DUT's", True)
    bench.expect("the plant's model", 1.0, 2.0, node="PLANT")   # judges the PLANT: never fails a VCU case


def test_skipped_while_late(bench):
    bench.every(0.2, lambda now: time.sleep(0.08))
    bench.run(0.3)
    pytest.skip("a skip stays a skip, however late the bench")
'''


def test_bench_run_reports_an_inconclusive_case_apart_and_exits_3(tmp_path: Path) -> None:
    (tmp_path / "test_user.py").write_text(USER_CASES, encoding="utf-8")
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "bench", "run", str(tmp_path / "test_user.py"), "--interface",
                          "udp_multicast", "--channel", ipv4_group(), "--out", str(out)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == EXIT_INCONCLUSIVE, run.stdout + run.stderr
    assert "inconclusive test_user::test_late: bench late by " in run.stdout, run.stdout
    assert "1 passed, 1 inconclusive, 1 skipped" in run.stdout and "bench run: INCONCLUSIVE" in run.stdout, run.stdout
    suite = ET.parse(out / "junit.xml").getroot().find("testsuite")
    assert suite is not None and suite.get("failures") == "0" and suite.get("skipped") == "2"
    cases = {c.get("name"): c for c in suite.findall("testcase")}
    skipped = cases["test_late"].find("skipped")
    assert skipped is not None and skipped.get("type") == "inconclusive"
    assert (skipped.get("message") or "").startswith("inconclusive: bench late by ")
    assert any(p.get("name") == "bench_timing" for p in cases["test_late"].iter("property"))
    assert cases["test_on_time"].find("skipped") is None and cases["test_on_time"].find("failure") is None
    record = {c["name"]: c for c in json.loads((out / "results.json").read_text())["cases"]}
    assert record["test_late"]["outcome"] == "inconclusive" and record["test_late"]["inconclusive"]
    assert record["test_on_time"]["outcome"] == "passed"
    assert record["test_skipped_while_late"]["outcome"] == "skipped"
    assert [s["node"] for s in record["test_on_time"]["steps"] if s["verdict"] == "fail"] == ["PLANT"]
    html = (out / "report.html").read_text()
    assert "Inconclusive: bench late by" in html and "judges PLANT, not the DUT" in html
