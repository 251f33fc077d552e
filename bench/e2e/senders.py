"""Two senders of one message: counter streams that tell two interleaved senders from one broken sender.

The receiver (bench.e2e.receiver) only rejects; it cannot say *why*. After a sequence error the monitor follows
the message's counters as streams, each advancing by 1 (docs/spec/e2e.md "Two senders of one identifier").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# -- two senders of one message (docs/spec/e2e.md "Counter patterns": two interleaved senders) -----------
# The receiver above only rejects; it cannot say *why*. After a sequence error the monitor follows the
# message's counters as streams, each advancing by 1: one broken sender (frozen, skipped, stale, counting
# down) leaves at most one stream that keeps advancing; two senders leave two that take turns for as long
# as both send. One sender whose frames were held back for a while (a delay that ends) also leaves two
# streams taking turns, the held-back frames and the new ones, but only for as many frames as it held back:
# a finding needs both streams to have carried more frames than the counter has values.
STREAMS_KEPT = 4        # streams followed at once (the least recently fed is forgotten)
STREAM_SWITCHES = 4     # ... and how often the frames alternate between them (A B A B A)
STREAM_EVIDENCE = 4     # counters of each stream quoted as evidence
STREAM_GAP_CYCLES = 4   # a stream without a frame for longer than this many cycles has ended: a counter that
                        # comes round again (modulo the counter's range) after it belongs to no stream of the past


@dataclass(slots=True)
class _Stream:
    ident: int
    expect: int                 # the counter this stream's sender sends next
    counters: list[int]         # its last few counters (the evidence)
    last_t: float = 0.0         # time of its last frame, s
    frames: int = 1


class SenderTracker:
    """Counter streams of one message: tells two interleaved senders from one broken sender. Feed it the
    counter and time of every intact frame (in order of arrival) once a sequence error happened; `feed`
    returns the two streams' recent counters as soon as they have alternated STREAM_SWITCHES times.
    `cycle`: the message's cycle time, s (None: streams never end by time)."""

    __slots__ = ("streams", "switches", "max_gap", "modulo", "frames_needed", "_last", "_next_ident")

    def __init__(self, cycle: float | None, modulo: int, previous: tuple[int, float] | None = None) -> None:
        self.modulo = modulo
        # every counter value, and then some (a 32-bit counter: as many as an 8-bit one; it never wraps in a run)
        self.frames_needed = min(modulo, 256) + 1
        self.streams: list[_Stream] = []
        self.switches: dict[tuple[int, int], int] = {}
        self.max_gap = math.inf if cycle is None else STREAM_GAP_CYCLES * cycle
        self._last: int | None = None          # ident of the stream the previous frame went to
        self._next_ident = 0
        if previous is not None:
            self.feed(*previous)

    def feed(self, counter: int, t: float) -> tuple[list[int], list[int]] | None:
        max_gap = self.max_gap
        stream = next((s for s in self.streams if s.expect == counter and t - s.last_t <= max_gap), None)
        if stream is None:
            stream = _Stream(self._next_ident, counter, [])
            stream.frames = 0
            self._next_ident += 1
            self.streams.append(stream)
            if len(self.streams) > STREAMS_KEPT:
                gone = self.streams.pop(0).ident
                self.switches = {pair: n for pair, n in self.switches.items() if gone not in pair}
        else:
            self.streams.remove(stream)
            self.streams.append(stream)        # most recently fed last
        stream.expect = (counter + 1) % self.modulo
        stream.frames += 1
        stream.last_t = t
        stream.counters = [*stream.counters[-(STREAM_EVIDENCE - 1):], counter]
        last, self._last = self._last, stream.ident
        if last is None or last == stream.ident:
            return None
        pair = (min(last, stream.ident), max(last, stream.ident))
        switches = self.switches[pair] = self.switches.get(pair, 0) + 1
        other = next((s for s in self.streams if s.ident == last), None)
        if other is None or switches < STREAM_SWITCHES or min(other.frames, stream.frames) < self.frames_needed:
            return None
        first, second = sorted((other, stream), key=lambda s: s.ident)
        return list(first.counters), list(second.counters)
