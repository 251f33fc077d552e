"""Independent references the bench's tests check it against: written from the contract's protection
(docs/spec/e2e.md, AUTOSAR E2E Profile 11 with DataIDMode BOTH and Offset 48), never from bench.e2e nor from
the `autosar-e2e` library the bench computes its CRCs with."""

from __future__ import annotations

#: The contract's header (docs/spec/e2e.md "The contract's protection"): the CRC in byte 6, the counter in the
#: low nibble of byte 7, 0 ... 14.
CRC_BYTE = 6
COUNTER_BYTE = 7
COUNTER_VALUES = 15


def crc8_j1850_p11(data: bytes) -> int:
    """CRC-8/SAE-J1850 as Profiles 1 and 11 compute it, bit by bit: polynomial 0x1D, start value 0x00, no
    reflection, no final XOR (check value 0x37 over b"123456789")."""
    crc = 0x00
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def p11_crc(data_id: int, data: bytes, offset_byte: int = CRC_BYTE) -> int:
    """Profile 11, DataIDMode BOTH: the CRC over the DataID's low byte, its high byte, then every data byte but
    the CRC's own."""
    return crc8_j1850_p11(bytes([data_id & 0xFF, (data_id >> 8) & 0xFF])
                          + bytes(data[:offset_byte]) + bytes(data[offset_byte + 1:]))


def contract_checksum(data_id: int, data: bytes) -> int:
    """The contract's CRC of a frame (byte 6), whatever byte 6 holds now."""
    return p11_crc(data_id, data)


def protected(data_id: int, payload: bytes, counter: int) -> bytes:
    """The payload with the contract's counter (low nibble of byte 7, any 4-bit value: 15 too, which no sender
    may send) and CRC (byte 6)."""
    data = bytearray(payload)
    data[COUNTER_BYTE] = (data[COUNTER_BYTE] & 0xF0) | (counter & 0x0F)
    data[CRC_BYTE] = contract_checksum(data_id, bytes(data))
    return bytes(data)


def counter_of(data: bytes) -> int:
    """The contract's AliveCounter of a frame (the low nibble of byte 7)."""
    return data[COUNTER_BYTE] & 0x0F


def intact(data_id: int, data: bytes) -> bool:
    """Whether a frame carries the contract's CRC in byte 6 and a counter Profile 11 can send (0 ... 14)."""
    return len(data) == 8 and data[CRC_BYTE] == contract_checksum(data_id, data) and counter_of(data) < COUNTER_VALUES
