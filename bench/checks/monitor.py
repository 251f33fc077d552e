"""Receive side: every frame on the bus is checked against the DBC and the contract's E2E rules.

One monitor per bus handle decodes every frame, keeps the latest valid values and, when asked,
a time-stamped history per message; it checks length, the AUTOSAR E2E protection of protected messages (the
profile's check and the E2E state machine, bench.e2e.Receiver, docs/spec/e2e.md), signal ranges and timeouts
(3 x cycle time). Invalid frames are counted and logged, never applied.

The E2E receiver has no clock: it judges frames in order of arrival. The consumer's timeout runs from the last
*valid* frame, so that a stream of rejected frames can never time itself back into acceptance.

Two senders of one identifier (a second plant on the channel, a real ECU while its node is still simulated)
are one finding per message (`Monitor.duplicates`, DuplicateSender) with its evidence, not only thousands of
counter errors: a frame received within a few cycles of this station's own frame of the identifier, or,
after a sequence error, two counter streams that each advance by 1 and take turns (bench.e2e.SenderTracker).
"""


from __future__ import annotations

import math
from bisect import bisect_left
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from bench import canid, e2e
from bench.canid import IDENTITY
from bench.database import sendtype
from bench.database.codec import Codebook, MessageCodec
from bench.database.errors import DecodeError
from bench.diag.isotp import IsoTpFraming, IsoTpParams, IsoTpProblem
from bench.errors import BenchError, BenchLimit

TIMEOUT_CYCLES = 3   # docs/spec/k-matrix.md: a message not seen for 3 x its cycle time is timed out
TIME_EPS = 1e-9      # s: bench times are sums of ticks; equal times must compare equal
GAP_SLACK = 0.001    # s: an event frame this much sooner than its minimum gap is still in time (one tick) ...
#: ... or this share of the gap, when more: a frame's receive time on a busy host jitters by milliseconds, and a
#: sender that ignores its gap (sends at once) is still caught
GAP_JITTER = 0.25
# Memory stays flat in long runs: each list keeps at most its cap (trimmed in halves, amortised), and
# counts what it dropped so that queries reaching before the retained data fail loudly, never silently.
HISTORY_CAP = 3000       # frames of decoded history per message kept from before the case in progress
HISTORY_MAX = 200_000    # frames per message kept at most even within a case (2000 s at 10 ms, 200 s at 1 ms): a
                         # history asked beyond it is a limit of the bench (BenchLimit), never the DUT's failure
INTERVALS_CAP = 5000     # frame intervals per message for cycle-time checks (50 s at 10 ms; the report's
                         # timing section keeps its own whole-run histogram, bench/checks/timing.py)
INVALID_CAP = 20000      # invalid-frame records
# Two senders of one identifier (a finding of its own, not thousands of counter errors):
SENDERS_GAP_CYCLES = 3   # a reception gap (no frame at all) longer than this many cycles ends the counter streams
SENDERS_CALM = 32        # accepted frames in a row after which the counter streams are no longer followed
OWN_ECHO_FRAMES = 16     # a received copy of one of the station's last 16 frames of an identifier (one counter
                         # cycle, as many as the kernel's broadcast manager holds) is its own echo, no second sender
FOREIGN_CYCLES = 3       # a frame received within this many cycles of this station's own frame of the
FOREIGN_S = 1.0          # identifier (FOREIGN_S without a cycle time) comes from another sender


class CheckedFrame:
    """A frame as the monitor judged it, handed to its sink (the run's log and timing): one object, its fields
    by name, rather than eight positional arguments every sink had to list in order."""

    __slots__ = ("t", "frame_id", "data", "direction", "valid", "reason", "codec", "values")

    def __init__(self, t: float, frame_id: int, data: bytes, direction: str, valid: bool, reason: str,
                 codec: MessageCodec | None, values: Mapping[str, float] | None) -> None:
        self.t = t                            # bench time, s
        self.frame_id = frame_id              # identifier, format and kind (bench.canid)
        self.data = data
        self.direction = direction            # "rx" or "tx"
        self.valid = valid                    # False: rejected (reason says why), never applied
        self.reason = reason
        self.codec = codec                    # None: an unknown identifier or an error frame
        self.values = values                  # decoded values of a valid frame, else None

    def __repr__(self) -> str:
        return (f"CheckedFrame(t={self.t!r}, frame_id={canid.text(self.frame_id)}, data={self.data!r}, "
                f"direction={self.direction!r}, valid={self.valid!r}, reason={self.reason!r})")


FrameSink = Callable[[CheckedFrame], None]


@dataclass(slots=True)
class MessageState:
    """What the monitor knows of one message."""

    codec: MessageCodec
    latest: dict[str, float] | None = None
    last_valid: float | None = None          # bench time of the last valid frame
    last_seen: float | None = None           # bench time of the last frame, valid or not
    rx: e2e.Receiver | None = field(init=False)   # the E2E receiver (check and state machine); None: unprotected
    starting: int = 0                        # valid frames not applied while the E2E state machine was INIT
    last_invalid: bool = False
    frames: int = 0
    invalid: dict[str, int] = field(default_factory=dict)      # reason -> count
    intervals: list[float] = field(default_factory=list)       # s between consecutive frames
    timeouts: list[float] = field(default_factory=list)        # bench times a timeout began
    timed_out_flag: bool = True
    history_t: list[float] = field(default_factory=list)
    history_v: list[tuple[float, ...]] = field(default_factory=list)
    intervals_dropped: int = 0
    history_dropped: int = 0
    history_limit: int = 0                   # and beyond 2 x HISTORY_CAP, length at which the history is trimmed next
    last_data: bytes = b""                   # E2E messages: the previous frame's payload (a re-sent frame is no
                                             # second sender; its counter starts the first counter stream)
    last_tx: float | None = None             # bench time this station last sent the message itself
    recent_tx: deque[bytes] = field(default_factory=lambda: deque(maxlen=OWN_ECHO_FRAMES))   # its last payloads
    senders: e2e.SenderTracker | None = None  # counter streams, followed after a sequence error
    calm: int = 0                            # accepted frames in a row while they are followed
    unchanged: int = 0                       # an on-change message's frames in a row with the values of the last
    # The message's time limits, s, computed once (inf without a cycle time: never reached); the same sums
    # as written out, so a comparison with them decides as before.
    timeout_s: float = field(init=False)     # a consumer's timeout: TIMEOUT_CYCLES cycles after the last valid
    gap_s: float = field(init=False)         # a reception gap that ends the counter streams (two senders)
    foreign_s: float = field(init=False)     # a received frame this soon after the station's own is another's
    base_timeout_s: float = field(init=False)   # timeout_s of a periodic message while it sends (cyclic_if_active)
    plain_cyclic: bool = field(init=False)   # a frame every cycle whatever its values: no send-type rule to judge

    @property
    def e2e_status(self) -> dict[str, int]:
        """Frames per AUTOSAR check status (its name); empty for an unprotected message."""
        return {} if self.rx is None else {status.value: n for status, n in self.rx.status_counts().items()}

    def __post_init__(self) -> None:
        cycle = self.codec.cycle_time
        periodic = self.codec.sending.periodic   # an event message is never late for being silent
        self.timeout_s = math.inf if cycle is None or not periodic else TIMEOUT_CYCLES * cycle + TIME_EPS
        self.base_timeout_s = self.timeout_s
        self.plain_cyclic = self.codec.sending.kind == sendtype.CYCLIC
        self.gap_s = math.inf if cycle is None else SENDERS_GAP_CYCLES * cycle + TIME_EPS
        p = self.codec.protection
        self.rx = None if p is None else e2e.Receiver(p.counter_modulo, p.max_delta_counter, p.sm)
        self.foreign_s = (FOREIGN_CYCLES * cycle if cycle else FOREIGN_S) + TIME_EPS


@dataclass(slots=True)
class DuplicateSender:
    """A finding: two senders of one identifier, with the evidence that showed it first. One per message:
    later frames that show it only count."""

    frame_id: int
    message: str
    t: float                  # bench time it was first shown, s
    evidence: str
    frames: int = 1           # frames that showed it (alternating counter streams, foreign frames)
    last: float = 0.0         # bench time of the last of them, s

    def describe(self) -> str:
        return f"two senders of {canid.text(self.frame_id)} ({self.message}): {self.evidence}"


@dataclass(slots=True)
class InvalidFrame:
    t: float
    frame_id: int             # identifier, format and kind (bench.canid)
    message: str
    reason: str


class Monitor:
    """Checks and remembers every frame; optional sink gets every frame with its verdict (the log)."""

    def __init__(self, codebook: Codebook, *, keep_history: bool = False, keep_intervals: bool = True,
                 sink: FrameSink | None = None) -> None:
        self.codebook = codebook
        self.keep_history = keep_history
        self.keep_intervals = keep_intervals   # a plant's ECUs need no cycle-time statistics
        self.sink = sink
        self.states: dict[int, MessageState] = {cid: MessageState(c) for cid, c in codebook.by_id.items()
                                                if not c.diagnostic}
        # Diagnostic messages (ISO-TP, bench.diag) are judged by their framing, not by cycle, E2E or range: their
        # checker per identifier (`watch_framing`); without one a diagnostic frame is logged as valid.
        self.diagnostic: dict[int, MessageCodec] = {cid: c for cid, c in codebook.by_id.items() if c.diagnostic}
        self.framing: dict[int, IsoTpFraming] = {}
        self._connections: list[tuple[tuple[int, int], IsoTpFraming]] = []   # ((request, response), its checker)
        self._pair: dict[int, tuple[int, int]] = {}                           # either id -> (request, response)
        self.by_name: dict[str, MessageState] = {s.codec.name: s for s in self.states.values()}
        self.unknown_frames = 0
        self.invalid_log: list[InvalidFrame] = []
        self.invalid_dropped = 0
        self.frames = 0
        self.duplicates: dict[int, DuplicateSender] = {}   # identifier -> finding (docs/spec/e2e.md)
        # The history from this bench time on is kept whole (up to HISTORY_MAX frames per message): the case in
        # progress sets it at its start (bench.case.Case), so that it keeps what it asks for over its whole length.
        self.history_from = math.inf

    def join_mid_stream(self) -> None:
        """Take each E2E message's first intact frame as in sequence (its counter starts the count): for a monitor
        that joins a bus whose senders are running (`bench monitor`), where AUTOSAR's check would give the first
        frame of every healthy message REPEATED or WRONGSEQUENCE. That frame still only moves the state machine
        from NODATA to INIT (not applied, as after power-up). The bench's own runs keep AUTOSAR's rule: their
        monitor starts before the senders it judges."""
        for state in self.states.values():
            if state.rx is not None:
                state.rx.joins = True

    # -- frames ------------------------------------------------------------------------------
    def on_frame(self, t: float, frame_id: int, data: bytes, direction: str) -> bool:
        """Check one frame (`frame_id`: its identifier, format and kind, bench.canid); apply it only when valid and
        its E2E state machine is VALID. Returns whether it was applied: a frame that is valid but came while the
        state machine was only INIT (the first frame after start-up, docs/spec/e2e.md) is logged as valid, counted
        in `starting`, and not applied. Never raises on bus data."""
        self.frames += 1
        sink = self.sink
        identity = frame_id & IDENTITY
        state = self.states.get(identity)
        if state is None:
            if identity in self.diagnostic:
                return self._diagnostic_frame(t, identity, data, direction)
            self.unknown_frames += 1
            name, reason = _unknown(frame_id, self.codebook)
            self._invalid(InvalidFrame(t, frame_id, name, reason))
            if sink:
                sink(CheckedFrame(t, frame_id, data, direction, False, reason, None, None))
            return False
        codec = state.codec
        last_valid = state.last_valid
        if last_valid is not None and not state.timed_out_flag and t - last_valid > state.timeout_s:
            self._time_out(state)   # the consumer went 3 cycles without a valid frame: record the timeout
        prev_seen = state.last_seen
        if prev_seen is not None:
            if t - prev_seen > state.gap_s:
                state.senders = None   # a real reception gap (no frame at all): the sender may have restarted
            if self.keep_intervals:
                intervals = state.intervals
                intervals.append(t - prev_seen)
                if len(intervals) > 2 * INTERVALS_CAP:
                    state.intervals_dropped += _trim(intervals, INTERVALS_CAP)
        state.last_seen = t
        state.frames += 1
        if direction == "tx":
            state.last_tx = t
            state.recent_tx.append(data)
        elif state.last_tx is not None and data not in state.recent_tx and t - state.last_tx <= state.foreign_s:
            # (a copy of one of the station's own recent frames is its echo, e.g. the kernel's broadcast manager
            # handing a message back to the tick scheduler on socketcan: seen in the vcan lane at scenario changes)
            self._duplicate(state, t, frame_id, "frames received while this station sends it")
        kind = reason = ""
        values = None
        starting = False
        size = len(data)
        length_ok = size == codec.length or size == codec.frame_length
        rx = state.rx
        if rx is not None:
            found = codec.counter_if_intact(data) if length_ok else None
            expected = rx.next
            status, accepted = rx.receive(found)
            if not accepted:   # (a damaged frame's counter is not read: the receiver ignores it)
                if rx.held_back:   # no fault of its sender (the receiver's start): logged as valid, not applied
                    starting = True
                else:
                    kind, reason = _e2e_rejection(rx, status, found, expected, length_ok)
            if (kind or state.senders is not None) and length_ok and kind not in ("checksum", "length"):
                self._follow_counters(state, t, frame_id, data, kind, prev_seen)
            state.last_data = data
        if not length_ok:
            kind, reason = "length", f"length {len(data)}, DBC says {codec.length}"
        elif not kind:
            try:
                values, bad = codec.decode_checked(data)
            except DecodeError as exc:
                kind, reason = "decode", f"decode: {exc}"
            else:
                if bad:
                    kind, reason = "range", "range: " + ", ".join(f"{n}={values[n]:g}" for n in bad)
        if reason:
            state.invalid[kind] = state.invalid.get(kind, 0) + 1
            state.last_invalid = True
            self._invalid(InvalidFrame(t, frame_id, codec.name, reason))
            if sink:
                sink(CheckedFrame(t, frame_id, data, direction, False, reason, codec, None))
            return False
        assert values is not None
        if not state.plain_cyclic:   # judged by its send type (bench.database.sendtype)
            rule = self._sending(state, values, t, prev_seen, direction)
            if rule:
                state.invalid["send-type"] = state.invalid.get("send-type", 0) + 1
                state.last_invalid = True
                self._invalid(InvalidFrame(t, frame_id, codec.name, rule))
                if sink:
                    sink(CheckedFrame(t, frame_id, data, direction, False, rule, codec, None))
                return False
        if starting:   # a valid frame (so logged), not applied: the E2E state machine is not VALID yet
            state.starting += 1
            if sink:
                sink(CheckedFrame(t, frame_id, data, direction, True, "", codec, values))
            return False
        if codec.multiplexed:   # a frame carries its variant's signals: the others keep their last values
            state.latest = {**(state.latest or {}), **values}
        else:
            state.latest = values
        state.last_valid = t
        state.last_invalid = False
        state.timed_out_flag = False
        if self.keep_history:
            state.history_t.append(t)
            # (a multiplexed frame: NaN for the signals it does not carry, which `history` leaves out)
            state.history_v.append(tuple(values.get(n, math.nan) for n in codec.signal_names) if codec.multiplexed
                                   else tuple(values.values()))
            length = len(state.history_t)
            if length > 2 * HISTORY_CAP and length > state.history_limit:
                self._trim_history(state)
        if sink:
            sink(CheckedFrame(t, frame_id, data, direction, True, "", codec, values))
        return True

    @staticmethod
    def _sending(state: MessageState, values: Mapping[str, float], t: float, prev_seen: float | None,
                 direction: str) -> str:
        """What a valid frame breaks of its message's send type ("" when nothing): an event frame sooner than its
        minimum gap after the previous one (GAP_SLACK, GAP_JITTER), an on-change frame without a change beyond its
        repetitions. A cyclic-if-active message is late only while active: its timeout holds while its last frame
        has a signal away from the inactive value. The station's own frames ("tx") are not judged: its restbus
        keeps the gaps by counting ticks (tests/bench/sim/test_send_types.py), and in real time their send stamps
        show the bench's own lateness, which its timing report judges."""
        codec = state.codec
        sending = codec.sending
        kind = sending.kind
        if kind == sendtype.IF_ACTIVE:
            inactive = codec.inactive or {}
            active = any(values[n] != v for n, v in inactive.items() if n not in codec.e2e_signals)
            state.timeout_s = state.base_timeout_s if active else math.inf
            return ""
        if kind not in (sendtype.ON_CHANGE, sendtype.ON_WRITE) or direction == "tx":
            return ""
        latest = state.latest
        same = latest is not None and all(latest.get(n) == v for n, v in values.items() if n not in codec.e2e_signals)
        state.unchanged = state.unchanged + 1 if same else 0
        repeat = same and state.unchanged <= sending.repetitions     # one of an event's repetitions
        if kind == sendtype.ON_CHANGE and same and not repeat:
            return (f"send type on_change: sent again without a change ({state.unchanged} alike after the first; "
                    f"GenMsgNrOfRepetition allows {sending.repetitions})")
        gap, what = ((sending.repeat_gap, "its repetitions' gap is") if repeat
                     else (sending.min_gap, "its minimum gap is"))
        if gap and prev_seen is not None and t - prev_seen < gap - max(GAP_SLACK, GAP_JITTER * gap):
            return (f"send type {kind}: {(t - prev_seen) * 1000:.1f} ms after its previous frame, {what} "
                    f"{gap * 1000:g} ms ({'GenMsgCycleTimeFast' if repeat else 'GenMsgDelayTime'})")
        return ""

    def _trim_history(self, state: MessageState) -> None:
        """Drop the frames before `history_from` beyond the last HISTORY_CAP, and beyond HISTORY_MAX any frame;
        trimmed again at twice what is left (amortised)."""
        ts = state.history_t
        keep = max(HISTORY_CAP, len(ts) - bisect_left(ts, self.history_from))
        if keep > HISTORY_MAX:
            keep = HISTORY_MAX // 2
        _trim(state.history_v, keep)
        state.history_dropped += _trim(ts, keep)
        state.history_limit = 2 * len(ts)

    def _follow_counters(self, state: MessageState, t: float, frame_id: int, data: bytes, kind: str,
                         prev_seen: float | None) -> None:
        """An intact frame while the message's counters are out of sequence (or were lately): follow them as
        streams (bench.e2e.SenderTracker) until SENDERS_CALM frames in a row are accepted."""
        tracker = state.senders
        if tracker is None:
            prev = state.last_data   # the previous frame of the message: its counter starts the first stream
            protection = state.codec.protection
            assert protection is not None
            previous = None if prev_seen is None or len(prev) != len(data) else (protection.counter_of(prev), prev_seen)
            tracker = state.senders = e2e.SenderTracker(state.codec.cycle_time, protection.counter_modulo, previous)
            state.calm = 0
        if kind:
            state.calm = 0
        else:
            state.calm += 1
            if state.calm >= SENDERS_CALM:
                state.senders = None
                return
        cycle = state.codec.cycle_time
        if data == state.last_data and prev_seen is not None and cycle and t - prev_seen < cycle / 4:
            return     # the same frame again at once (a re-sent frame, the `duplicate` fault): one sender
        streams = tracker.feed(state.codec.protection.counter_of(data), t)  # type: ignore[union-attr]
        if streams is not None:
            first, second = (",".join(str(c) for c in s) for s in streams)
            self._duplicate(state, t, frame_id, f"counters {first} and {second} interleaved")

    def _duplicate(self, state: MessageState, t: float, frame_id: int, evidence: str) -> None:
        frame_id &= IDENTITY
        found = self.duplicates.get(frame_id)
        if found is None:
            self.duplicates[frame_id] = DuplicateSender(frame_id, state.codec.name, t, evidence, 1, t)
        else:
            found.frames += 1
            found.last = t

    def note_send_failure(self, t: float, frame_id: int, reason: str) -> None:
        """A frame this station could not send (queue full, bus-off): logged as invalid, never applied."""
        state = self.states.get(frame_id & IDENTITY)
        name = state.codec.name if state else canid.text(frame_id)
        self._invalid(InvalidFrame(t, frame_id, name, f"send failed: {reason}"))

    def watch_framing(self, a_id: int, b_id: int, params: IsoTpParams) -> None:
        """Check the ISO-TP framing of one diagnostic connection (request and response identifiers)."""
        checker = IsoTpFraming(a_id, b_id, params)
        self.framing[a_id] = self.framing[b_id] = checker
        self._pair[a_id] = self._pair[b_id] = (a_id, b_id)
        self._connections.append(((a_id, b_id), checker))

    def _diagnostic_frame(self, t: float, frame_id: int, data: bytes, direction: str) -> bool:
        codec = self.diagnostic[frame_id]
        checker = self.framing.get(frame_id)
        problems = checker.on_frame(t, frame_id, data) if checker is not None else []
        own = []
        for problem in problems:   # (a timeout this frame revealed may be the other side's: its own record)
            at_fault = _at_fault(problem, self._pair[frame_id], frame_id)
            if at_fault == frame_id:
                own.append(problem)
            else:
                self._invalid(InvalidFrame(problem.t, at_fault, self.diagnostic[at_fault].name,
                                           f"ISO-TP {problem.rule}: {problem.text}"))
        reason = "; ".join(f"ISO-TP {p.rule}: {p.text}" for p in own)
        if reason:
            self._invalid(InvalidFrame(t, frame_id, codec.name, reason))
        if self.sink:
            # (no codec: a diagnostic frame is in no cycle-time statistics)
            self.sink(CheckedFrame(t, frame_id, data, direction, not reason, reason, None, None))
        return not reason

    def _invalid(self, record: InvalidFrame) -> None:
        self.invalid_log.append(record)
        if len(self.invalid_log) > 2 * INVALID_CAP:
            self.invalid_dropped += _trim(self.invalid_log, INVALID_CAP)

    # -- time ------------------------------------------------------------------------------------
    def check_timeouts(self, now: float) -> None:
        """Record every timeout that has begun by `now`. Not needed per tick: a timeout is also recorded
        when the next frame ends it, and its start time is exact either way; queries call this."""
        for state in self.states.values():
            cycle = state.codec.cycle_time
            if cycle is None or state.timed_out_flag or state.last_valid is None:
                continue
            if now - state.last_valid > state.timeout_s:
                self._time_out(state)
        for ids, checker in self._connections:   # ISO-TP's N_Bs / N_Cr of a diagnostic exchange in progress
            for problem in checker.check_timeouts(now):
                at_fault = _at_fault(problem, ids, ids[0])
                self._invalid(InvalidFrame(problem.t, at_fault, self.diagnostic[at_fault].name,
                                           f"ISO-TP {problem.rule}: {problem.text}"))

    @staticmethod
    def _time_out(state: MessageState) -> None:
        cycle = state.codec.cycle_time
        assert cycle is not None and state.last_valid is not None
        state.timed_out_flag = True
        state.timeouts.append(state.last_valid + TIMEOUT_CYCLES * cycle)
        # no resynchronisation here: frames may still be arriving, rejected (on_frame resyncs on a real gap)

    # -- queries ---------------------------------------------------------------------------------
    def state(self, message: str) -> MessageState:
        try:
            return self.by_name[message]
        except KeyError:
            self.codebook[message]  # raises the clear error
            raise

    def latest(self, message: str, now: float, since: float = -math.inf) -> dict[str, float] | None:
        """The message's latest valid values; None before the first, when it came before `since` (bench time,
        s) or while it is timed out. (A plant's behaviours ask several times per tick: `timed_out`'s rule,
        written out here.)"""
        state = self.by_name.get(message)
        if state is None:
            state = self.state(message)
        last_valid = state.last_valid
        if last_valid is None or last_valid < since or now - last_valid > state.timeout_s:
            return None
        return state.latest

    def timed_out(self, message: str, now: float) -> bool:
        state = self.by_name.get(message) or self.state(message)
        last_valid = state.last_valid
        return last_valid is None or now - last_valid > state.timeout_s

    def invalid(self, message: str) -> bool:
        return (self.by_name.get(message) or self.state(message)).last_invalid

    def history(self, message: str, signal: str, since: float = -math.inf) -> tuple[list[float], list[float]]:
        state = self.state(message)
        try:
            index = state.codec.signal_names.index(signal)
        except ValueError:
            state.codec.physical(signal, 0.0)  # raises the clear error
            raise
        ts, vs = state.history_t, state.history_v
        if state.history_dropped and ts and since < ts[0]:
            if since >= self.history_from:   # within the case: the bench's own limit
                raise BenchLimit(f"bench limit: history of {message} since {since:.3f} s was asked, but the bench "
                                 f"keeps at most {HISTORY_MAX} frames of a message within a case (from {ts[0]:.3f} s)")
            raise BenchError(f"history of {message} since {since:.3f} s was asked, before the case started "
                             f"({self.history_from:.3f} s); from before it only the last {HISTORY_CAP}-"
                             f"{2 * HISTORY_CAP} frames are kept (from {ts[0]:.3f} s): ask for less")
        start = _first_at_or_after(ts, since)
        if state.codec.multiplexed:   # the frames that carried the signal
            pairs = [(t, v[index]) for t, v in zip(ts[start:], vs[start:]) if v[index] == v[index]]
            return [t for t, _ in pairs], [v for _, v in pairs]
        return ts[start:], [v[index] for v in vs[start:]]

    @property
    def invalid_frames(self) -> int:
        """Frames that failed a check, unknown identifiers and error frames, and failed sends."""
        return self.invalid_dropped + len(self.invalid_log)


def _unknown(frame_id: int, codebook: Codebook) -> tuple[str, str]:
    """(name, reason) of a frame no message of the databases is: an error or remote frame, a message's identifier in
    the other frame format (classical CAN for a CAN FD message or the reverse: the message's own fault), or an
    identifier the databases do not have."""
    if frame_id & canid.ERR:
        return "error frame", "error frame"
    if frame_id & canid.RTR:
        return canid.text(frame_id), "remote frame"
    other = codebook.by_id.get((frame_id ^ canid.FD) & IDENTITY)
    if other is not None:
        sent, declared = ("CAN FD", "classical CAN") if frame_id & canid.FD else ("classical CAN", "CAN FD")
        return other.name, f"frame format: a {sent} frame, the database declares {declared}"
    return canid.text(frame_id), "unknown identifier"


def _e2e_rejection(rx: e2e.Receiver, status: e2e.Status, found: int | None, expected: int,
                   length_ok: bool) -> tuple[str, str]:
    """(kind, reason) of a frame the receiver did not let through: the AUTOSAR check status and the state
    machine's state by their names (`expected`: the counter an in-sequence frame carried)."""
    state = rx.state.value
    if status is e2e.Status.ERROR:
        if not length_ok:
            return "length", "length"
        return "checksum", f"E2E ERROR: CRC wrong, state {state}"   # (also a counter the profile never sends)
    if status is e2e.Status.REPEATED:
        return "counter", f"E2E REPEATED: counter {found} again, state {state}"
    if status is e2e.Status.WRONGSEQUENCE:
        return "counter", f"E2E WRONGSEQUENCE: counter {found}, expected {expected}, state {state}"
    return "state", f"E2E {status.value}: counter {found} in sequence, state {state} (not VALID yet)"


def _at_fault(problem: IsoTpProblem, ids: tuple[int, ...], default: int) -> int:
    """The identifier of a connection whose sender broke the rule, so that the problem is recorded as that message's
    (and judged as its sender's, bench.case.Case.expect_clean_bus): a timeout's is the side that owed the missing
    frame, which its text names (N_Bs: "no flow control on 0x70D within N_Bs ...", N_Cr: "no CF on 0x70D within
    N_Cr ..."); any other problem's is the frame that showed it (`default`). The tester's flow control is the last
    frame before a response's N_Cr timeout: recorded as the request's, the ECU's fault was judged the tester's."""
    if problem.rule in ("N_Bs timeout", "N_Cr timeout"):
        for frame_id in ids:
            if f" on {canid.text(frame_id)} within N_" in problem.text:
                return frame_id
    return default


def _trim(items: list[Any], keep: int) -> int:
    """Drop all but the last `keep` items in place; returns how many were dropped."""
    dropped = len(items) - keep
    if dropped > 0:
        del items[:dropped]
    return max(dropped, 0)


def _first_at_or_after(ts: list[float], since: float) -> int:
    return bisect_left(ts, since)
