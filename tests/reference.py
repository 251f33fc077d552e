"""Independent references the bench's tests check it against: written from the contract's catalogue
parameters (docs/spec/e2e.md), never from bench.e2e."""

from __future__ import annotations


def crc8_j1850(data: bytes) -> int:
    """CRC-8/SAE-J1850 bit by bit: poly 0x1D, init 0xFF, no reflection, final XOR 0xFF (check value 0x4B)."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def contract_checksum(frame_id: int, data: bytes) -> int:
    """The contract's checksum: over the identifier's low byte, its high byte, then data bytes 0-6."""
    return crc8_j1850(bytes([frame_id & 0xFF, (frame_id >> 8) & 0xFF]) + bytes(data[:7]))


def protected(frame_id: int, payload: bytes, counter: int) -> bytes:
    """The payload with the contract's AliveCounter (low nibble of byte 6) and Checksum (byte 7)."""
    data = bytearray(payload)
    data[6] = (data[6] & 0xF0) | (counter & 0x0F)
    data[7] = contract_checksum(frame_id, bytes(data))
    return bytes(data)
