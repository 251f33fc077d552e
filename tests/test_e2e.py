"""E2E protection against the contract: CRC-8/SAE-J1850 and the AliveCounter."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from bench import e2e
from tests.reference import crc8_j1850


def test_check_value() -> None:
    assert e2e.crc8_sae_j1850(b"123456789") == 0x4B
    assert crc8_j1850(b"123456789") == 0x4B


@given(st.binary(max_size=64))
def test_table_crc_matches_bitwise_reference(data: bytes) -> None:
    assert e2e.crc8_sae_j1850(data) == crc8_j1850(data)


@given(st.integers(0, 0x7FF), st.binary(min_size=8, max_size=8), st.integers(0, 15))
def test_protect_writes_counter_and_checksum_over_id_and_bytes_0_to_6(frame_id: int, payload: bytes,
                                                                       counter: int) -> None:
    data = bytearray(payload)
    e2e.protect(frame_id, data, counter)
    assert data[6] & 0x0F == counter
    assert data[6] & 0xF0 == payload[6] & 0xF0          # the upper nibble belongs to a signal
    assert data[:6] == payload[:6]
    expected = crc8_j1850(bytes([frame_id & 0xFF, frame_id >> 8]) + bytes(data[:7]))
    assert data[7] == expected
    assert e2e.counter_of(data) == counter


def test_counter_wraps_15_to_0() -> None:
    assert e2e.next_counter(15) == 0
    assert e2e.next_counter(3) == 4
