"""End-to-end protection of the contract (docs/spec/e2e.md).

One implementation used by both the sender (restbus) and the receiver (monitor), so that
sending and checking can never disagree (the opendbc packer/parser idea).
"""

from __future__ import annotations

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
