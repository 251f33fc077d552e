"""The report's timing section: measured cycle times against the DBC, and command → status latencies.

Why streamed: the runner's monitor keeps only the recent part of its histories and intervals (memory stays
flat in long runs, bench/checks/monitor.py), but the report speaks of the whole run. So `TimingCollector` sees
every frame the runner's monitor checks (it is called from the monitor's sink, `bench.run.BenchRun`) and
keeps what the section needs in constant memory per message. It knows no vehicle: which status follows which
command comes from bench.toml (`[timing] latency`, `bench.config.LatencyPair`).

Cycle time, per message: p50, p99 and max of all its frame intervals in the run (every frame, sent or
received, valid or not, as the monitor's intervals), against the DBC cycle time (GenMsgCycleTime).
Intervals are counted in bins of BIN s (exact on the virtual-time bus, whose times are whole ticks); the
max is exact. Over the whole run, so the gaps a case makes on purpose (stop_sending, injected faults) are
in the max; they are counted as gaps (intervals ≥ 3 × the cycle, the timeout of docs/spec/k-matrix.md) and the
verdict uses the robust figures only, with the bounds of `Case.check_cycle_times`: p50 within ±5 % and
p99 ≤ 1.5 × the DBC cycle.

Latency, per pair (command signal c, status signal s, threshold h, window w), from the valid frames in
the order the monitor saw them:

- a *change* is a command frame whose value differs from the previous command frame's by more than h;
  its direction d is the sign of that difference. An *onset* is a change whose previous frame was no
  change in the same direction (a step is one onset, a ramp one onset at its start);
- an onset is *timed* (an event) only when the status is at rest: its last REST_FRAMES frames lie within
  h of each other. A status already on its way (a rate-limited actuator still travelling to an earlier
  target) shows no reaction to a new target, so such onsets are counted as "status moving", not timed.
  s_ref is the value of the last status frame before the event;
- the event is *followed* at the first status frame later than it with d · (s − s_ref) > h; the latency
  is that frame's time minus the event's time;
- an onset in the same direction while an event is pending belongs to that event (the status has not
  started yet); one in the opposite direction supersedes it (the old one is not counted; the new one is
  timed if the status is at rest);
- an event whose status has not followed within w s is *not followed*.

This assumes a status that moves the way its command changes (a positive gain). A status frame is sent
once per status cycle, so a latency includes up to one status cycle of waiting for the next frame: it is
the reaction as seen on the bus, an upper bound on the ECU's own.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from bench import canid
from bench.config import LatencyPair
from bench.database.codec import Codebook, MessageCodec
from bench.errors import BenchError
from bench.results.model import Table

if TYPE_CHECKING:
    from bench.checks.monitor import CheckedFrame

#: The bounds of `Case.check_cycle_times` (fractions of the DBC cycle time); MAX_MAX x is the timeout.
P50_BAND, P99_MAX, MAX_MAX = 0.05, 1.5, 3.0
BIN = 1e-5           # s: resolution of the interval histograms
REST_FRAMES = 3      # status frames that must lie within the threshold for the status to be at rest
WAITING = 64         # frames kept while a pair's default threshold is not known yet (bounded: a message may never come)
MS = 1000.0
_EPS = 1e-9          # s: bench times are sums of ticks


# -- cycle times ---------------------------------------------------------------------------------------------
@dataclass
class CycleStats:
    """Measured cycle time of one message (s); NaN where there are no intervals."""

    message: str
    frame_id: int
    cycle: float | None          # DBC cycle time, s
    intervals: int
    p50: float = math.nan
    p99: float = math.nan
    max: float = math.nan
    gaps: int = 0                # intervals >= MAX_MAX x the DBC cycle (a receiver times the message out)

    @property
    def within_limits(self) -> bool | None:
        """p50 and p99 within the bounds; None when there is nothing to judge (no DBC cycle or no interval)."""
        if self.cycle is None or not self.intervals:
            return None
        c = self.cycle
        return abs(self.p50 - c) <= P50_BAND * c and self.p99 <= P99_MAX * c


class CycleAccumulator:
    """The frame intervals of one message as a histogram (bins of BIN s), plus the exact max and the gaps."""

    __slots__ = ("codec", "last", "bins", "count", "max", "gaps", "_gap")

    def __init__(self, codec: MessageCodec) -> None:
        self.codec = codec
        self.last: float | None = None
        self.bins: Counter[int] = Counter()
        self.count = 0
        self.max = -math.inf
        self.gaps = 0
        self._gap = math.inf if codec.cycle_time is None else MAX_MAX * codec.cycle_time - _EPS

    def add(self, t: float) -> None:
        last, self.last = self.last, t
        if last is None:
            return
        interval = t - last
        self.bins[round(interval / BIN)] += 1
        self.count += 1
        if interval > self.max:
            self.max = interval
        if interval >= self._gap:
            self.gaps += 1

    def stats(self) -> CycleStats:
        codec = self.codec
        out = CycleStats(codec.name, codec.frame_id, codec.cycle_time, self.count, gaps=self.gaps)
        if self.count:
            out.p50, out.p99 = _percentiles(self.bins, self.count, (50.0, 99.0))
            out.max = self.max
        return out


def _percentiles(bins: Counter[int], count: int, qs: Sequence[float]) -> list[float]:
    """Percentiles of binned values: numpy's percentile (bench.checks.steps.percentile's) over the values
    the bins hold."""
    keys = sorted(bins)
    values = np.repeat(np.asarray(keys, dtype=float) * BIN, [bins[k] for k in keys])
    assert len(values) == count
    return [float(v) for v in np.percentile(values, qs)]


# -- latency -------------------------------------------------------------------------------------------------
@dataclass
class LatencyStats:
    """Latencies (s) of one command → status pair."""

    pair: LatencyPair
    threshold: float
    latencies: list[float] = field(default_factory=list)
    not_followed: int = 0
    moving: int = 0          # onsets not timed: the status was not at rest
    error: str = ""

    @property
    def events(self) -> int:
        return len(self.latencies) + self.not_followed


class LatencyFollower:
    """The latency events of one pair, fed frame by frame in bus order (definition in the module docstring)."""

    def __init__(self, threshold: float, window: float) -> None:
        self.threshold = threshold
        self.window = window
        self.latencies: list[float] = []
        self.not_followed = 0
        self.moving = 0
        self.end = -math.inf
        self._last_command: float | None = None
        self._previous = 0                                  # direction of the last command change, 0: none
        self._recent: deque[float] = deque(maxlen=REST_FRAMES)
        self._pending: tuple[float, int, float] | None = None   # (event time, direction, s_ref)

    def _expire(self, t: float) -> None:
        self.end = max(self.end, t)
        if self._pending is not None and t - self._pending[0] > self.window:
            self.not_followed += 1
            self._pending = None

    def status(self, t: float, value: float) -> None:
        self._expire(t)
        pending = self._pending
        if pending is not None:
            t0, direction, ref = pending
            if t > t0 + _EPS and direction * (value - ref) > self.threshold:
                self.latencies.append(t - t0)
                self._pending = None
        self._recent.append(value)

    def command(self, t: float, value: float) -> None:
        self._expire(t)
        last, self._last_command = self._last_command, value
        if last is None:
            return
        change = value - last
        h = self.threshold
        direction = 0 if abs(change) <= h else (1 if change > 0 else -1)
        onset = direction != 0 and direction != self._previous
        self._previous = direction
        pending = self._pending
        if not onset or not self._recent or (pending is not None and pending[1] == direction):
            return
        recent = self._recent
        if len(recent) == REST_FRAMES and max(recent) - min(recent) <= h:
            self._pending = (t, direction, recent[-1])
        else:
            self._pending = None                            # superseded; this onset is not timed
            self.moving += 1

    def finish(self) -> None:
        """An event still pending at the end counts as not followed only if its window had passed."""
        if self._pending is not None and self.end - self._pending[0] > self.window:
            self.not_followed += 1
        self._pending = None


def follow_latencies(t_cmd: Sequence[float], cmd: Sequence[float], t_sts: Sequence[float], sts: Sequence[float],
                     threshold: float, window: float) -> LatencyFollower:
    """The events of two recorded series (each ascending in time), merged in time order; at equal times the
    status frame counts as earlier. For tests and for logs read back."""
    follower = LatencyFollower(threshold, window)
    i = j = 0
    while i < len(t_cmd) or j < len(t_sts):
        if j < len(t_sts) and (i >= len(t_cmd) or t_sts[j] <= t_cmd[i]):
            follower.status(t_sts[j], sts[j])
            j += 1
        else:
            follower.command(t_cmd[i], cmd[i])
            i += 1
    follower.finish()
    return follower


# -- the collector -------------------------------------------------------------------------------------------
class TimingCollector:
    """Called with every frame the runner's monitor checks (a bench.checks.monitor.CheckedFrame, its sink); makes the
    report's timing tables at the end. Never raises on frames: bad pair names are reported in the table.

    A pair without a threshold gets one step of the coarser of its two signals, known once a frame of each
    message has come with its codec; the few frames before that wait in a short buffer.
    """

    def __init__(self, pairs: Sequence[LatencyPair]) -> None:
        self.pairs = tuple(pairs)
        self.cycles: dict[int, CycleAccumulator] = {}
        self.followers = [LatencyFollower(math.nan if p.threshold is None else p.threshold, p.window)
                          for p in self.pairs]
        self._scales: list[dict[bool, float]] = [{} for _ in self.pairs]          # is_command -> signal scale
        self._waiting: list[deque[tuple[bool, float, float]]] = [deque(maxlen=WAITING) for _ in self.pairs]
        self._by_message: dict[str, list[tuple[int, bool, str]]] = {}
        for i, pair in enumerate(self.pairs):
            self._by_message.setdefault(pair.command[0], []).append((i, True, pair.command[1]))
            self._by_message.setdefault(pair.status[0], []).append((i, False, pair.status[1]))

    def __call__(self, frame: CheckedFrame) -> None:
        codec = frame.codec
        if codec is None:
            return                                           # unknown identifiers and error frames
        t = frame.t
        acc = self.cycles.get(codec.frame_id)
        if acc is None:
            acc = self.cycles[codec.frame_id] = CycleAccumulator(codec)
        acc.add(t)
        values = frame.values
        if values is None:
            return
        for i, is_command, signal in self._by_message.get(codec.name, ()):
            value = values.get(signal)
            if value is None:
                continue                                     # no such signal: reported at the end
            follower = self.followers[i]
            if math.isnan(follower.threshold):
                self._scales[i][is_command] = abs(codec.by_name[signal].scale)
                self._waiting[i].append((is_command, t, value))
                if len(self._scales[i]) < 2:
                    continue
                follower.threshold = max(self._scales[i].values())
                waiting, self._waiting[i] = self._waiting[i], deque(maxlen=WAITING)
                for was_command, tw, vw in waiting:
                    (follower.command if was_command else follower.status)(tw, vw)
            elif is_command:
                follower.command(t, value)
            else:
                follower.status(t, value)

    def _check(self, pair: LatencyPair, codebook: Codebook) -> tuple[str, float]:
        """("" or the error, the default threshold) of a pair, against the databases."""
        try:
            scales = []
            for message, signal in (pair.command, pair.status):
                codec = codebook[message]
                if signal not in codec.by_name:
                    codec.physical(signal, 0.0)              # raises the clear error
                scales.append(abs(codec.by_name[signal].scale))
        except BenchError as exc:
            return f"bench.toml [timing]: {exc}", math.nan
        return "", max(scales)

    def cycle_stats(self, codebook: Codebook) -> list[CycleStats]:
        """Every message of the databases (those never seen with no intervals), by identifier."""
        out = []
        for frame_id in sorted(codebook.by_id):
            acc = self.cycles.get(frame_id)
            codec = codebook.by_id[frame_id]
            out.append(acc.stats() if acc is not None else CycleStats(codec.name, frame_id, codec.cycle_time, 0))
        return out

    def latency_stats(self, codebook: Codebook) -> list[LatencyStats]:
        out = []
        for pair, follower in zip(self.pairs, self.followers):
            error, default = self._check(pair, codebook)
            if math.isnan(follower.threshold):
                follower.threshold = default                 # a message never came: nothing was waiting long
            follower.finish()
            out.append(LatencyStats(pair, follower.threshold, list(follower.latencies), follower.not_followed,
                                    follower.moving, error))
        return out

    def tables(self, codebook: Codebook) -> list[Table]:
        """The report's timing section. Never raises: a failure becomes a one-row table, so a bug here
        cannot cost the report of a long run."""
        try:
            tables = [cycle_table(self.cycle_stats(codebook))]
            if self.pairs:
                tables.append(latency_table(self.latency_stats(codebook)))
            return tables
        except Exception as exc:  # noqa: BLE001 - the report matters more
            return [Table("Timing", ["Error"],
                          [[f"the timing section could not be computed: {type(exc).__name__}: {exc}"]])]


# -- report tables ---------------------------------------------------------------------------------------
def _ms(value: float) -> str:
    return "–" if not math.isfinite(value) else f"{value * MS:.2f}"


def cycle_table(stats: Sequence[CycleStats]) -> Table:
    rows = []
    for s in stats:
        cycle = "–" if s.cycle is None else f"{s.cycle * MS:g}"
        deviation = "–" if s.cycle is None or not s.intervals else f"{(s.p50 - s.cycle) / s.cycle * 100:+.1f}"
        verdict = {None: "–" if s.intervals else "no frames", True: "yes", False: "NO"}[s.within_limits]
        gaps = "–" if s.cycle is None else str(s.gaps)
        rows.append([s.message, canid.text(s.frame_id), cycle, str(s.intervals), _ms(s.p50), _ms(s.p99), _ms(s.max),
                     deviation, gaps, verdict])
    return Table(
        f"Timing: cycle time per message over the whole run (gaps: intervals ≥ {MAX_MAX:g}× the DBC cycle, the "
        f"timeout, including those a case makes on purpose such as stop_sending or injected faults; "
        f"limits as check_cycle_times: p50 within ±{P50_BAND:.0%}, p99 ≤ {P99_MAX:g}× the DBC cycle)",
        ["Message", "ID", "DBC cycle [ms]", "Intervals", "p50 [ms]", "p99 [ms]", "max [ms]", "p50 − DBC [%]",
         "Gaps", "p50, p99 within limits"], rows)


def latency_table(stats: Sequence[LatencyStats]) -> Table:
    rows = []
    for s in stats:
        pair = s.pair
        signals = f"{pair.command[0]}.{pair.command[1]} → {pair.status[0]}.{pair.status[1]}"
        threshold = "–" if not math.isfinite(s.threshold) else f"{s.threshold:g}"
        if s.error:
            note = s.error
        elif not s.events and not s.moving:
            note = f"no command change > {s.threshold:g} in the run"
        else:
            note = ""
        lat = np.asarray(s.latencies, dtype=float)
        if lat.size:
            p50, p99 = (float(v) for v in np.percentile(lat, [50, 99]))
            figures = [_ms(float(lat.min())), _ms(p50), _ms(p99), _ms(float(lat.max()))]
        else:
            figures = ["–"] * 4
        rows.append([pair.name, signals, threshold, str(s.events), str(len(s.latencies)), *figures,
                     str(s.not_followed), f"{pair.window:g}", str(s.moving), note])
    return Table(
        "Timing: command → status latency (from the onset of a command change by more than the threshold, with "
        "the status at rest, to the first status frame after it that moved by more than the threshold the same "
        "way; includes up to one status cycle; definition in bench/checks/timing.py)",
        ["Pair", "Command → status", "Threshold", "Timed changes", "Followed", "min [ms]", "p50 [ms]", "p99 [ms]",
         "max [ms]", "Not followed", "Window [s]", "Status moving (not timed)", "Note"], rows)


# -- the bench's own timing (real time) ------------------------------------------------------------------------
#: Lateness below this is the bench on time (a tick is 1 ms): not kept as an event of its own.
LATE_FLOOR = 0.002
#: Late events kept for the per-case figures (the whole-run figures are kept apart, in constant memory).
LATE_EVENTS = 200_000
#: A frame the bench sends late by more than (TIMEOUT_CYCLES - 1) cycles of its message leaves a gap of more
#: than TIMEOUT_CYCLES cycles: its receivers may time it out (docs/spec/k-matrix.md), through no fault of theirs.
TIMEOUT_CYCLES = 3


@dataclass(slots=True)
class Late:
    """One figure of the bench's own lateness: what was late, by how much (s), when it was due (bench time,
    s), and the bound past which a case's checks cannot stand on it (s; inf: a figure only)."""

    what: str
    late: float
    t: float
    bound: float = math.inf

    def text(self) -> str:
        bound = "" if math.isinf(self.bound) else f", bound {self.bound * MS:g} ms"
        return f"{self.what}: late by {self.late * MS:.1f} ms at {self.t:.3f} s{bound}"


class _LateAccumulator:
    """Whole-run figures of one source of lateness: count, the late ones, binned lateness, the worst."""

    __slots__ = ("count", "over", "bins", "worst")

    def __init__(self) -> None:
        self.count = 0
        self.over = 0
        self.bins: Counter[int] = Counter()
        self.worst: Late | None = None


class SelfTiming:
    """The bench's own timing in real time, from the stamps of what really happened (bench.sim.station,
    bench.sim.clock):

    - a frame it sends (stimulus, simulated node): its lateness = the clock read after the driver took it minus the
      tick it was due at on its schedule (the restbus's next due tick, before a late station skipped it);
    - the tick loop: how far the wall clock had passed a tick when the loop got to it;
    - the receive path: how long a received frame waited in its socket (the clock's read at the poll minus the
      frame's receive stamp; a lower bound: that read may be up to a tick's work old).

    Every figure goes into a whole-run accumulator (the report's table `table`), and every lateness above
    LATE_FLOOR into a bounded list of events, from which `since` gives a case its worst figures. What was due
    before the case in progress started (`resume`) is not counted: between cases the bench pauses on purpose."""

    def __init__(self) -> None:
        self.sources: dict[str, _LateAccumulator] = {}
        self.events: deque[Late] = deque(maxlen=LATE_EVENTS)
        self.counted_from = -math.inf
        self._appended = 0                            # events appended so far (the deque drops the oldest)
        self._resumed: list[tuple[float, int]] = []   # (bench time, events appended before it) of each resume

    def resume(self, t: float) -> None:
        """A case starts at bench time t: what was due before it (while the bench paused between cases, by
        design, or set itself up) is not counted."""
        self.counted_from = t
        self._resumed.append((t, self._appended))

    def pause(self) -> None:
        """Between cases (before the first, after each): nothing is counted until the next `resume`."""
        self.counted_from = math.inf

    def add(self, what: str, late: float, t: float, bound: float = math.inf) -> None:
        if t < self.counted_from:
            return
        acc = self.sources.get(what)
        if acc is None:
            acc = self.sources[what] = _LateAccumulator()
        acc.count += 1
        if late <= LATE_FLOOR:
            acc.bins[0] += 1
            return
        acc.bins[round(late / BIN)] += 1
        event = Late(what, late, t, bound)
        if late > bound:
            acc.over += 1
        if acc.worst is None or late > acc.worst.late:
            acc.worst = event
        self.events.append(event)
        self._appended += 1

    def since(self, t0: float) -> list[Late]:
        """The worst lateness of each source from bench time t0 on, worst against its bound first."""
        # the events appended since the case of t0 began, whatever their own times: they are not in time order (a
        # frame that waited in its socket is timed at its arrival, after events of later ticks)
        begun = next((index for t, index in reversed(self._resumed) if t <= t0), 0)
        dropped = self._appended - len(self.events)   # the oldest, gone from the bounded deque
        worst: dict[str, Late] = {}
        for event in itertools.islice(reversed(self.events), self._appended - max(begun, dropped)):
            if event.t < t0:
                continue
            if event.what not in worst or event.late > worst[event.what].late:
                worst[event.what] = event
        return sorted(worst.values(), key=lambda e: (-(e.late / e.bound if e.bound else 0.0), -e.late))

    @staticmethod
    def verdict(figures: Sequence[Late]) -> str:
        """The line that makes a case inconclusive ("" when no figure is past its bound), e.g. "bench late by
        146.0 ms on stimulus MSG at 12.300 s (bound 20 ms)"."""
        over = [f for f in figures if f.late > f.bound]
        if not over:
            return ""
        first = over[0]
        more = f"; and {len(over) - 1} more: " + ", ".join(f"{f.what} {f.late * MS:.1f} ms" for f in over[1:4]) \
            if len(over) > 1 else ""
        who = "a sender other than the DUT" if first.what.startswith("input ") else "bench"   # Case._input_gaps
        return (f"{who} late by {first.late * MS:.1f} ms on {first.what} at {first.t:.3f} s "
                f"(bound {first.bound * MS:g} ms){more}")

    def table(self) -> Table:
        rows = []
        for what in sorted(self.sources):
            acc = self.sources[what]
            p50, p99 = _percentiles(acc.bins, acc.count, (50.0, 99.0)) if acc.count else (math.nan, math.nan)
            worst = acc.worst
            rows.append([what, str(acc.count), _ms(p50), _ms(p99), _ms(worst.late) if worst else "–",
                         f"{worst.t:.3f}" if worst else "–",
                         "–" if worst is None or math.isinf(worst.bound) else f"{worst.bound * MS:g}", str(acc.over)])
        return Table(
            "Timing: the bench's own lateness in real time, during the cases (frames it sent: the clock after the "
            "driver took the frame minus the tick it was due; tick loop: how far the wall clock had passed a tick; "
            f"receive path: how long a frame waited in its socket, a lower bound; below {LATE_FLOOR * MS:g} ms counts "
            "as 0)",
            ["Source", "Count", "p50 [ms]", "p99 [ms]", "max [ms]", "max at [s]", "bound [ms]", "over the bound"],
            rows)
