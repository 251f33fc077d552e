"""End-to-end protection of the contract (docs/spec/e2e.md).

One implementation used by both the sender (restbus) and the receiver (monitor), so that
sending and checking can never disagree (the opendbc packer/parser idea). The receiver's rules
(docs/spec/e2e.md "Receiver") are the small state machine `Receiver` at the end of this module.

The profile is positional: an 8-byte frame carries the counter in the low nibble of byte 6 and the
checksum in byte 7. A database marks a message as protected by declaring a signal at each of those
places; their names are the database's own (`Layout` records them per message), the bench never
assumes one.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum

FRAME_LENGTH = 8          # the profile protects classical 8-byte frames only
COUNTER_BYTE = 6          # the counter: 4 bits at bit 48 = low nibble of byte 6
CHECKSUM_BYTE = 7         # the checksum: byte 7
COUNTER_START, COUNTER_LENGTH = 8 * COUNTER_BYTE, 4
CHECKSUM_START, CHECKSUM_LENGTH = 8 * CHECKSUM_BYTE, 8
COUNTER_MODULO = 16


@dataclass(frozen=True, slots=True)
class Layout:
    """The names a database gives one protected message's counter and checksum: code that keys decoded values
    or sets values by name (the value cache, the monitor's E2E column) asks here instead of assuming a name."""

    counter: str
    checksum: str


def is_counter(start: int, length: int, little_endian: bool) -> bool:
    """Whether a signal sits where the profile's counter does (4 little-endian bits at bit 48)."""
    return little_endian and start == COUNTER_START and length == COUNTER_LENGTH


def is_checksum(start: int, length: int, little_endian: bool) -> bool:
    """Whether a signal sits where the profile's checksum does (8 little-endian bits at bit 56)."""
    return little_endian and start == CHECKSUM_START and length == CHECKSUM_LENGTH


def layout(frame_length: int, signals: Iterable[tuple[str, int, int, bool]]) -> Layout | None:
    """The E2E layout of a message from its length and its signals as (name, start, length, little_endian):
    an 8-byte frame with a signal at the counter's place and one at the checksum's (the first of each, in
    signal order), else None (the message is not protected)."""
    if frame_length != FRAME_LENGTH:
        return None
    counter = checksum = None
    for name, start, length, little_endian in signals:
        if counter is None and is_counter(start, length, little_endian):
            counter = name
        elif checksum is None and is_checksum(start, length, little_endian):
            checksum = name
    return None if counter is None or checksum is None else Layout(counter, checksum)

_POLY = 0x1D
_INIT = 0xFF
_XOR_OUT = 0xFF


def _make_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ _POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_TABLE = _make_table()


def crc8_sae_j1850(data: bytes | bytearray) -> int:
    """CRC-8/SAE-J1850: poly 0x1D, init 0xFF, no reflection, final XOR 0xFF (check value 0x4B)."""
    crc = _INIT
    table = _TABLE
    for byte in data:
        crc = table[crc ^ byte]
    return crc ^ _XOR_OUT


def checksum(frame_id: int, data: bytes | bytearray) -> int:
    """The contract's checksum: CRC over id low byte, id high byte, then data bytes 0-6."""
    crc = _INIT
    table = _TABLE
    crc = table[crc ^ (frame_id & 0xFF)]
    crc = table[crc ^ ((frame_id >> 8) & 0xFF)]
    for byte in data[:CHECKSUM_BYTE]:
        crc = table[crc ^ byte]
    return crc ^ _XOR_OUT


def counter_of(data: bytes | bytearray) -> int:
    """The counter of a frame (low nibble of byte 6)."""
    return data[COUNTER_BYTE] & 0x0F


def checksum_of(data: bytes | bytearray) -> int:
    """The checksum a frame carries (byte 7), right or wrong."""
    return data[CHECKSUM_BYTE]


def set_checksum(data: bytearray, value: int) -> None:
    """Write a checksum byte (value mod 256) into an 8-byte payload, in place, whatever it should be."""
    data[CHECKSUM_BYTE] = value & 0xFF


def counter_if_intact(frame_id: int, data: bytes | bytearray) -> int | None:
    """The counter of a frame whose checksum is right; None when it is wrong (a damaged frame's counter
    is not read). The receiver's hot path: one call per frame, the CRC of `checksum` written out here."""
    crc = _INIT
    table = _TABLE
    crc = table[crc ^ (frame_id & 0xFF)]
    crc = table[crc ^ ((frame_id >> 8) & 0xFF)]
    for byte in data[:CHECKSUM_BYTE]:
        crc = table[crc ^ byte]
    if data[CHECKSUM_BYTE] != crc ^ _XOR_OUT:
        return None
    return data[COUNTER_BYTE] & 0x0F


def payload(data: bytes) -> bytes:
    """The frame without its E2E bytes (counter nibble cleared, checksum byte left out): what stays the
    same from one frame of a message to the next while its signals do."""
    return data[:COUNTER_BYTE] + bytes((data[COUNTER_BYTE] & 0xF0,))


def protect(frame_id: int, data: bytearray, counter: int) -> None:
    """Write the counter and then the checksum into an 8-byte payload, in place."""
    data[COUNTER_BYTE] = (data[COUNTER_BYTE] & 0xF0) | (counter & 0x0F)
    data[CHECKSUM_BYTE] = checksum(frame_id, data)


def next_counter(counter: int) -> int:
    return (counter + 1) % COUNTER_MODULO


# -- receiver (docs/spec/e2e.md "Receiver") --------------------------------------------------------------
MAX_DELTA_COUNTER = 1     # the only counter step accepted: a lost frame (step 2) is a wrong sequence
REVALIDATION_FRAMES = 2   # consecutive in-sequence frames after a sequence error; the last of them is accepted
RESYNC_GAP_CYCLES = 3     # a reception gap (any frame) longer than this many cycles resynchronises


class Check(Enum):
    """What one frame's protection shows, judged against the reference counter."""

    INITIAL = "initial"                # first intact frame without a reference: it starts the sequence
    OK = "ok"                          # counter = reference + 1
    REPEATED = "repeated"              # counter = reference
    WRONG_SEQUENCE = "wrong sequence"  # any other counter: skipped, backwards, stale, a second sender
    ERROR = "error"                    # wrong length or checksum: its counter is not read, it took one slot


class RxState(Enum):
    """The receiver's state of one message."""

    NODATA = "nodata"      # nothing intact since the start or since a reception gap: no reference counter
    VALID = "valid"        # in sequence: in-sequence frames are accepted
    INVALID = "invalid"    # after a sequence error: counting in-sequence frames up to REVALIDATION_FRAMES


_VALID, _OK = RxState.VALID, Check.OK


@dataclass(slots=True)
class Receiver:
    """Per-message E2E state machine (transition table in docs/spec/e2e.md). No clock: the monitor calls
    `resync` when a frame arrives after a reception gap, then `receive` for every frame."""

    state: RxState = RxState.NODATA
    reference: int | None = None   # counter of the previous frame since the last resync (ERROR: reference + 1)
    good: int = 0                  # consecutive in-sequence frames while INVALID

    def resync(self) -> None:
        """A real reception gap: forget the sequence; the next intact frame starts a new one."""
        self.state, self.reference, self.good = RxState.NODATA, None, 0

    def receive(self, intact: bool, counter: int) -> tuple[Check, bool]:
        """One frame of the message: `intact` = right length and checksum. Returns its check and whether
        its protection lets it be applied (the signal checks still follow)."""
        reference = self.reference
        if intact and self.state is _VALID and reference is not None and counter == (reference + 1) % COUNTER_MODULO:
            self.reference = counter                       # the common case, VALID + OK, without the table
            return _OK, True
        if not intact:
            check = Check.ERROR
        elif self.reference is None:
            check = Check.INITIAL
        else:
            delta = (counter - self.reference) % COUNTER_MODULO
            check = Check.REPEATED if delta == 0 else Check.OK if delta <= MAX_DELTA_COUNTER else Check.WRONG_SEQUENCE
        if intact:
            self.reference = counter
        elif self.reference is not None:   # a frame came in its slot: the next one must carry the counter after it
            self.reference = (self.reference + 1) % COUNTER_MODULO
        return check, self._step(check)

    def _step(self, check: Check) -> bool:
        state = self.state
        if check is Check.ERROR:
            self.good = 0                                  # rejected; it interrupts a re-validation, no more
            return False
        if check is Check.INITIAL:
            self.state, self.good = RxState.VALID, 0
            return True
        if check is Check.OK:
            if state is RxState.VALID:
                return True
            self.good += 1
            if self.good >= REVALIDATION_FRAMES:
                self.state, self.good = RxState.VALID, 0
                return True
            return False
        self.state, self.good = RxState.INVALID, 0        # REPEATED, WRONG_SEQUENCE
        return False


# -- two senders of one message (docs/spec/e2e.md "Counter patterns": two interleaved senders) -----------
# The receiver above only rejects; it cannot say *why*. After a sequence error the monitor follows the
# message's counters as streams, each advancing by 1: one broken sender (frozen, skipped, stale, counting
# down) leaves at most one stream that keeps advancing; two senders leave two that take turns for as long
# as both send. One sender whose frames were held back for a while (a delay that ends) also leaves two
# streams taking turns, the held-back frames and the new ones, but only for as many frames as it held back:
# a finding needs both streams to have carried more than 16 frames (every counter value, and then some).
STREAMS_KEPT = 4        # streams followed at once (the least recently fed is forgotten)
STREAM_FRAMES = COUNTER_MODULO + 1   # frames each of the two streams needs ...
STREAM_SWITCHES = 4     # ... and how often the frames alternate between them (A B A B A)
STREAM_EVIDENCE = 4     # counters of each stream quoted as evidence
STREAM_GAP_CYCLES = 4   # a stream without a frame for longer than this many cycles has ended: a counter that
                        # comes round again (modulo 16) after it belongs to no stream of the past


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

    __slots__ = ("streams", "switches", "max_gap", "_last", "_next_ident")

    def __init__(self, cycle: float | None, previous: tuple[int, float] | None = None) -> None:
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
        stream.expect = (counter + 1) % COUNTER_MODULO
        stream.frames += 1
        stream.last_t = t
        stream.counters = [*stream.counters[-(STREAM_EVIDENCE - 1):], counter]
        last, self._last = self._last, stream.ident
        if last is None or last == stream.ident:
            return None
        pair = (min(last, stream.ident), max(last, stream.ident))
        switches = self.switches[pair] = self.switches.get(pair, 0) + 1
        other = next((s for s in self.streams if s.ident == last), None)
        if other is None or switches < STREAM_SWITCHES or min(other.frames, stream.frames) < STREAM_FRAMES:
            return None
        first, second = sorted((other, stream), key=lambda s: s.ident)
        return list(first.counters), list(second.counters)
