"""End-to-end protection of the contract (docs/spec/e2e.md).

One implementation used by both the sender (restbus) and the receiver (monitor), so that
sending and checking can never disagree (the opendbc packer/parser idea). The receiver's rules
(docs/spec/e2e.md "Receiver") are the small state machine `Receiver` at the end of this module.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

COUNTER_BYTE = 6          # AliveCounter: 4 bits at bit 48 = low nibble of byte 6
CHECKSUM_BYTE = 7         # Checksum: byte 7
COUNTER_MODULO = 16

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
    """AliveCounter of a frame (low nibble of byte 6)."""
    return data[COUNTER_BYTE] & 0x0F


def protect(frame_id: int, data: bytearray, counter: int) -> None:
    """Write the AliveCounter and then the Checksum into an 8-byte payload, in place."""
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
