"""The report's timing section (bench.checks.timing) on synthetic buses: known intervals, known latencies.

A tiny two-message DBC of its own (a command and a status that follows it), so these tests say nothing
about any vehicle. Its messages are unprotected (no E2E attributes: judged on length, timing and ranges, every
frame applied from the first, docs/spec/e2e.md). Frames go through `Monitor.on_frame` in time order and reach
the collector through the monitor's sink, as in a run.
"""

from __future__ import annotations

import math
from pathlib import Path

import cantools
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.checks.monitor import Monitor
from bench.checks.timing import CycleStats, LatencyStats, TimingCollector, follow_latencies
from bench.config import LatencyPair, load_config
from bench.database.codec import Codebook
from bench.errors import ConfigError
from bench.report.html import render_html
from bench.results.model import RunResult

DBC = """VERSION ""
NS_ :
BS_:
BU_: CTRL ACT
BO_ 16 Cmd: 8 CTRL
 SG_ Angle : 0|16@1- (0.01,0) [-300|300] "deg" ACT
 SG_ AliveCounter : 48|4@1+ (1,0) [0|15] "" ACT
 SG_ Checksum : 56|8@1+ (1,0) [0|255] "" ACT
BO_ 32 Sts: 8 ACT
 SG_ Angle : 0|16@1- (0.05,0) [-300|300] "deg" CTRL
 SG_ AliveCounter : 48|4@1+ (1,0) [0|15] "" CTRL
 SG_ Checksum : 56|8@1+ (1,0) [0|255] "" CTRL
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 10000;
BA_DEF_DEF_ "GenMsgCycleTime" 0;
BA_ "GenMsgCycleTime" BO_ 16 10;
BA_ "GenMsgCycleTime" BO_ 32 10;
"""
PAIR = LatencyPair("actuator", ("Cmd", "Angle"), ("Sts", "Angle"))
Series = list[tuple[float, float]]


@pytest.fixture(scope="module")
def timing_codebook() -> Codebook:
    """The two messages of DBC above (not the project's codebook of tests/conftest.py)."""
    return Codebook([("timing.dbc", cantools.database.load_string(DBC, "dbc"))])


def bus(codebook: Codebook, pairs: list[LatencyPair], cmd: Series = (), sts: Series = ()) -> TimingCollector:
    """Both series through a monitor, merged in time order (a status frame first at equal times)."""
    collector = TimingCollector(pairs)
    monitor = Monitor(codebook, sink=collector)
    frames = sorted([(t, 1, "Cmd", v) for t, v in cmd] + [(t, 0, "Sts", v) for t, v in sts])
    for t, _, message, angle in frames:
        codec = codebook[message]
        data = codec.encode({"Angle": angle, "AliveCounter": 0, "Checksum": 0})
        assert codec.protection is None
        assert monitor.on_frame(t, codec.frame_id, bytes(data), "rx")
    return collector


def latency(codebook: Codebook, cmd: Series, sts: Series, pair: LatencyPair = PAIR) -> LatencyStats:
    (stats,) = bus(codebook, [pair], cmd, sts).latency_stats(codebook)
    return stats


def cycles(codebook: Codebook, cmd: Series) -> dict[str, CycleStats]:
    return {s.message: s for s in bus(codebook, [], cmd).cycle_stats(codebook)}


def grid(start: float, end: float, step: float = 0.01) -> list[float]:
    return [round(start + k * step, 9) for k in range(int(round((end - start) / step)) + 1)]


# -- cycle times ---------------------------------------------------------------------------------------------
def test_cycle_statistics_of_known_intervals(timing_codebook: Codebook) -> None:
    times = [0.0, 0.010, 0.020, 0.031, 0.041, 0.051, 0.081]     # intervals 10, 10, 11, 10, 10, 30 ms
    stats = cycles(timing_codebook, [(t, 0.0) for t in times])
    cmd = stats["Cmd"]
    assert cmd.cycle == 0.010 and cmd.intervals == 6
    assert cmd.p50 == pytest.approx(0.010)                      # median of 10 10 10 10 11 30
    # p99, linear interpolation: sorted position 0.99 * 5 = 4.95 between 11 and 30 ms
    assert cmd.p99 == pytest.approx(0.011 + 0.95 * (0.030 - 0.011))
    assert cmd.max == pytest.approx(0.030)
    assert cmd.gaps == 1                                        # 30 ms reaches 3 x 10 ms, the timeout
    assert cmd.within_limits is False                           # p99 29.05 ms > 1.5 x 10 ms
    assert stats["Sts"].intervals == 0 and stats["Sts"].within_limits is None


def test_a_single_gap_shows_in_max_and_gaps_not_in_the_verdict(timing_codebook: Codebook) -> None:
    # 200 intervals of 10 ms, one of 29 ms (below the timeout) and one of 310 ms (a deliberate silence)
    times = grid(0.0, 1.0) + [1.029] + [1.029 + 0.01 * k for k in range(1, 101)] + [2.029 + 0.31]
    cmd = cycles(timing_codebook, [(t, 0.0) for t in times])["Cmd"]
    assert cmd.intervals == 202 and cmd.gaps == 1 and cmd.max == pytest.approx(0.31)
    assert cmd.p50 == pytest.approx(0.010) and cmd.p99 < 0.015
    assert cmd.within_limits is True


@settings(max_examples=40, deadline=None)
@given(intervals=st.lists(st.integers(min_value=1, max_value=5000), min_size=1, max_size=300))
def test_histogram_percentiles_match_numpy(timing_codebook: Codebook, intervals: list[int]) -> None:
    """Intervals on the histogram's 10 µs grid: p50/p99/max equal numpy's on the same values."""
    import numpy as np
    times = [0.0]
    for n in intervals:
        times.append(times[-1] + n * 1e-5)
    cmd = cycles(timing_codebook, [(t, 0.0) for t in times])["Cmd"]
    values = np.diff(times)
    assert cmd.intervals == len(intervals)
    assert cmd.p50 == pytest.approx(float(np.percentile(values, 50)), abs=1e-9)
    assert cmd.p99 == pytest.approx(float(np.percentile(values, 99)), abs=1e-9)
    assert cmd.max == pytest.approx(float(values.max()), abs=1e-12)


# -- latency -------------------------------------------------------------------------------------------------
def test_steps_give_their_known_latencies(timing_codebook: Codebook) -> None:
    # command: 0, a step to +5 deg at t = 0.50, a step to -2 deg at t = 1.20 (frames every 10 ms)
    cmd = [(t, 0.0 if t < 0.5 else 5.0 if t < 1.2 else -2.0) for t in grid(0.0, 2.0)]
    # status frames 3 ms after each command frame; it starts to move at 0.543 (+43 ms) and at 1.263 (+63 ms)
    sts = [(t, 0.0 if t < 0.543 else 5.0 if t < 1.263 else -2.0) for t in grid(0.003, 2.003)]
    stats = latency(timing_codebook, cmd, sts)
    assert stats.threshold == 0.05                    # default: one step of the coarser signal (Sts, 0.05 deg)
    assert stats.latencies == pytest.approx([0.043, 0.063])
    assert stats.events == 2 and stats.not_followed == 0 and not stats.error


def test_a_ramp_is_one_event_and_a_silent_status_is_not_followed(timing_codebook: Codebook) -> None:
    # command ramps +0.2 deg per frame from t = 0.30 to 0.50, holds, then steps at 1.00; the status follows the
    # ramp from 0.333 (+33 ms after the ramp's onset) and never follows the step
    cmd = [(t, 0.0 if t < 0.3 else min(4.0, 0.2 * round((t - 0.29) / 0.01)) if t < 1.0 else 9.0)
           for t in grid(0.0, 2.5)]
    sts = [(t, 0.0 if t < 0.333 else min(4.0, 0.2 * round((t - 0.323) / 0.01))) for t in grid(0.003, 2.503)]
    stats = latency(timing_codebook, cmd, sts, LatencyPair("p", ("Cmd", "Angle"), ("Sts", "Angle"), threshold=0.1,
                                                    window=0.5))
    assert stats.latencies == pytest.approx([0.033])
    assert stats.not_followed == 1


def test_a_reversal_supersedes_the_pending_event(timing_codebook: Codebook) -> None:
    # +3 at 0.20 and back to 0 at 0.25, before the status moved: the reversal supersedes the first event; the
    # status never goes below 0, and the second +3 at 0.40 supersedes the reversal. The status moves at 0.423:
    # one event followed, after 23 ms, none counted as not followed.
    cmd = [(t, 3.0 if 0.2 <= t < 0.25 or t >= 0.4 else 0.0) for t in grid(0.0, 1.0)]
    sts = [(t, 0.0 if t < 0.423 else 3.0) for t in grid(0.003, 1.003)]
    stats = latency(timing_codebook, cmd, sts)
    assert stats.latencies == pytest.approx([0.023])
    assert stats.not_followed == 0


def test_a_change_while_the_status_travels_is_not_timed(timing_codebook: Codebook) -> None:
    """A rate-limited status on its way to -90 when the target changes to -70 shows no reaction to it (it keeps
    travelling down at 1.2 deg per frame): counted as "status moving", never as a latency."""
    cmd = [(t, 0.0 if t < 0.10 else -90.0 if t < 0.30 else -70.0) for t in grid(0.0, 1.5)]
    sts = [(t, max(-70.0, -1.2 * (round((t - 0.103) / 0.01) + 1)) if t >= 0.103 else 0.0) for t in grid(0.003, 1.503)]
    stats = latency(timing_codebook, cmd, sts)
    assert stats.latencies == pytest.approx([0.003])             # the first step, from rest
    assert stats.moving == 1 and stats.not_followed == 0


@settings(max_examples=60, deadline=None)
@given(delay=st.floats(min_value=0.001, max_value=0.2), phase=st.floats(min_value=0.0, max_value=0.0099),
       steps=st.lists(st.floats(min_value=-50, max_value=50).filter(lambda v: abs(v) > 1.0), min_size=1, max_size=6))
def test_a_delayed_copy_has_latency_between_delay_and_delay_plus_a_cycle(delay: float, phase: float,
                                                                         steps: list[float]) -> None:
    """The status is the command delayed by `delay` (> 0: a status cannot answer at the command's instant),
    sampled every 10 ms at another phase: every step of the command is followed, with a latency in
    [delay, delay + 10 ms] (the wait for the next status frame)."""
    cycle = 0.01
    change_times = [0.5 + 0.5 * k for k in range(len(steps))]
    levels = [sum(steps[: k + 1]) for k in range(len(steps))]

    def command(t: float) -> float:
        value = 0.0
        for when, level in zip(change_times, levels):
            if t >= when - 1e-12:
                value = level
        return value

    t_cmd = [k * cycle for k in range(int(0.5 * (len(steps) + 2) / cycle))]
    t_sts = [phase + k * cycle for k in range(len(t_cmd))]
    result = follow_latencies(t_cmd, [command(t) for t in t_cmd], t_sts, [command(t - delay) for t in t_sts],
                              threshold=0.5, window=0.45)
    assert result.not_followed == 0 and result.moving == 0 and len(result.latencies) == len(steps)
    for value in result.latencies:
        assert delay - 1e-9 <= value <= delay + cycle + 1e-9


def test_unknown_names_are_reported_not_raised(timing_codebook: Codebook) -> None:
    cmd = [(t, 0.0) for t in grid(0.0, 0.5)]
    stats = latency(timing_codebook, cmd, cmd, LatencyPair("bad", ("Cmd", "Angel"), ("Sts", "Angle")))
    assert "Angel" in stats.error and "bench.toml [timing]" in stats.error
    stats = latency(timing_codebook, cmd, cmd, LatencyPair("bad", ("Nope", "Angle"), ("Sts", "Angle")))
    assert "Nope" in stats.error


def test_waiting_for_a_message_that_never_comes_stays_bounded(timing_codebook: Codebook) -> None:
    collector = bus(timing_codebook, [PAIR], cmd=[(t, float(int(t * 10))) for t in grid(0.0, 30.0)])
    assert all(len(w) <= 64 for w in collector._waiting)
    (stats,) = collector.latency_stats(timing_codebook)
    assert stats.events == 0 and stats.threshold == 0.05


# -- the report ----------------------------------------------------------------------------------------------
def test_tables_reach_the_html_report(timing_codebook: Codebook) -> None:
    cmd = [(t, 0.0 if t < 0.5 else 5.0) for t in grid(0.0, 1.0)]
    sts = [(t, 0.0 if t < 0.543 else 5.0) for t in grid(0.003, 1.003)]
    bad = LatencyPair("bad", ("Cmd", "Angel"), ("Sts", "Angle"))
    tables = bus(timing_codebook, [PAIR, bad], cmd, sts).tables(timing_codebook)
    cycle, latency_ = tables
    assert cycle.rows[0] == ["Cmd", "0x010", "10", "100", "10.00", "10.00", "10.00", "+0.0", "0", "yes"]
    assert cycle.rows[1][3] == "100"
    assert latency_.rows[0][2:12] == ["0.05", "1", "1", "43.00", "43.00", "43.00", "43.00", "0", "1", "0"]
    assert "Angel" in latency_.rows[1][-1]
    run = RunResult(started="2026-01-01T00:00:00", interface="embedded", channel="", time_mode="virtual",
                    tables=tables)
    page = render_html(run)
    assert "Timing: cycle time per message" in page and "Timing: command → status latency" in page
    assert "43.00" in page


def test_timing_tables_never_raise(timing_codebook: Codebook) -> None:
    tables = TimingCollector([]).tables(None)  # type: ignore[arg-type]
    assert tables[0].title == "Timing" and "could not be computed" in tables[0].rows[0][0]


# -- configuration -------------------------------------------------------------------------------------------
BASE = """[bench]
databases = ["a.dbc"]
stimulus = ["DRIVER"]
plant = "chassis"
testcases = "testcases"
reports = "reports"
"""


def test_the_timing_table_loads(tmp_path: Path) -> None:
    (tmp_path / "a.dbc").write_text("")
    path = tmp_path / "bench.toml"
    path.write_text(BASE + '[timing]\nlatency = [{command = "Cmd.Angle", status = "Sts.Angle", threshold = 0.1, '
                           'window = 2}, {command = "A.x", status = "B.y", name = "ab"}]\n')
    first, second = load_config(path).latency
    assert first == LatencyPair("Cmd.Angle → Sts.Angle", ("Cmd", "Angle"), ("Sts", "Angle"), 0.1, 2.0)
    assert second.name == "ab" and second.threshold is None and second.window == 1.0
    path.write_text(BASE)
    assert load_config(path).latency == ()


@pytest.mark.parametrize(("timing", "needle"), [
    ('latency = [{command = "CmdAngle", status = "Sts.Angle"}]', 'command must be "Message.Signal"'),
    ('latency = [{command = "Cmd.Angle"}]', "status must be"),
    ('latency = [{command = "Cmd.Angle", status = "Sts.Angle", threshold = -1}]', "threshold must be a positive"),
    ('latency = [{command = "Cmd.Angle", status = "Sts.Angle", window = nan}]', "window must be a positive"),
    ('latency = [{command = "Cmd.Angle", status = "Sts.Angle", treshold = 1}]', "unknown key(s) treshold"),
    ('latency = {command = "Cmd.Angle"}', "latency must be a list"),
    ('latency = ["Cmd.Angle"]', "latency entry 1 must be a table"),
    ("pairs = []", "[timing] unknown key(s) pairs"),
])
def test_bad_timing_tables_are_clear_errors(tmp_path: Path, timing: str, needle: str) -> None:
    (tmp_path / "a.dbc").write_text("")
    path = tmp_path / "bench.toml"
    path.write_text(BASE + "[timing]\n" + timing + "\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert needle in str(info.value) and str(path) in str(info.value)


def test_the_projects_pairs_name_real_signals() -> None:
    """bench.toml's pairs resolve against the project's databases (else the report would say so)."""
    from bench.database.codec import load_codebook
    project = load_config()
    assert project.latency
    for stats in TimingCollector(project.latency).latency_stats(load_codebook(project.databases)):
        assert not stats.error and math.isfinite(stats.threshold), stats
