"""E2E protection against the contract (docs/spec/e2e.md): CRC-8/SAE-J1850, the AliveCounter, and the
receiver's transition table as the document writes it."""

from __future__ import annotations

import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bench import e2e
from tests import repo
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


@given(st.integers(0, 0x7FF), st.binary(min_size=8, max_size=8), st.integers(0, 15), st.integers(0, 255))
def test_the_receiver_reads_the_counter_of_intact_frames_only(frame_id: int, payload: bytes, counter: int,
                                                              other: int) -> None:
    """counter_if_intact: the counter when the Checksum is the CRC (independent reference), else None."""
    data = bytearray(payload)
    e2e.protect(frame_id, data, counter)
    assert e2e.counter_if_intact(frame_id, bytes(data)) == counter
    assert e2e.checksum_of(data) == crc8_j1850(bytes([frame_id & 0xFF, frame_id >> 8]) + bytes(data[:7]))
    e2e.set_checksum(data, data[7] + other)             # any other byte (mod 256) breaks it
    assert e2e.checksum_of(data) == (e2e.checksum(frame_id, data) + other) % 256
    assert e2e.counter_if_intact(frame_id, bytes(data)) == (counter if other == 0 else None)


@given(st.binary(min_size=8, max_size=8), st.integers(0, 15), st.integers(0, 15))
def test_payload_is_the_frame_without_its_e2e_bytes(payload: bytes, first: int, second: int) -> None:
    a, b = bytearray(payload), bytearray(payload)
    e2e.protect(0x123, a, first)
    e2e.protect(0x123, b, second)
    assert e2e.payload(bytes(a)) == e2e.payload(bytes(b)) == payload[:6] + bytes([payload[6] & 0xF0])


def test_only_e2e_py_reads_or_writes_the_e2e_bytes() -> None:
    """Counter and checksum bytes go through bench/e2e.py everywhere else (sender and receiver cannot disagree):
    no other module of bench/ or plant/ indexes or slices a frame with COUNTER_BYTE or CHECKSUM_BYTE."""
    root = repo.ROOT
    pattern = re.compile(r"\[[^\]]*\b(COUNTER_BYTE|CHECKSUM_BYTE)\b[^\]]*\]")   # a subscript or slice with one
    found = [f"{path.relative_to(root)}:{n}: {line.strip()}"
             for folder in ("bench", "plant") for path in sorted((root / folder).rglob("*.py"))
             if path.name != "e2e.py"
             for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if pattern.search(line)]
    assert found == []


def test_counter_wraps_15_to_0() -> None:
    assert e2e.next_counter(15) == 0
    assert e2e.next_counter(3) == 4


# -- the receiver's transition table (docs/spec/e2e.md "States and transitions") ------------------------------
E2E_DOC = repo.ROOT / "docs" / "spec" / "e2e.md"
TABLE_HEADER = "| state | check | next state | frame accepted |"
REFERENCE = 5          # the reference counter of a receiver that has one


def _transition_rows() -> list[list[str]]:
    lines = E2E_DOC.read_text(encoding="utf-8").splitlines()
    start = lines.index(TABLE_HEADER) + 2            # skip the header and its |---| line
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def _frame_for(check: str) -> tuple[bool, int]:
    """(intact, counter) of a frame showing `check` against REFERENCE (no reference for INITIAL)."""
    return {"ERROR": (False, REFERENCE + 1), "INITIAL": (True, 11), "OK": (True, REFERENCE + 1),
            "REPEATED": (True, REFERENCE), "WRONG_SEQUENCE": (True, REFERENCE + 2)}[check]


def test_transition_table_covers_every_state_and_check() -> None:
    text = E2E_DOC.read_text(encoding="utf-8")     # the document's numbers are the code's
    assert f"REVALIDATION_FRAMES = {e2e.REVALIDATION_FRAMES}" in text and e2e.REVALIDATION_FRAMES == 2
    assert f"MAX_DELTA_COUNTER = {e2e.MAX_DELTA_COUNTER}" in text
    rows = [r for r in _transition_rows() if r[0] != "any"]
    covered = {(state, check.split(",")[0]) for state, check, _, _ in rows}
    assert covered == {("NODATA", "ERROR"), ("NODATA", "INITIAL"),
                       *((s, c) for s in ("VALID", "INVALID") for c in ("ERROR", "OK", "REPEATED", "WRONG_SEQUENCE"))}


@pytest.mark.parametrize("row", _transition_rows(), ids=lambda r: f"{r[0]} {r[1]}")
def test_receiver_follows_the_documented_transition(row: list[str]) -> None:
    state_text, check_text, next_text, accepted_text = row
    if state_text == "any":                          # the reception gap: resync, then the NODATA rows
        for state in e2e.RxState:
            rx = e2e.Receiver(state, None if state is e2e.RxState.NODATA else REFERENCE, 1)
            rx.resync()
            assert (rx.state, rx.reference, rx.good) == (e2e.RxState.NODATA, None, 0)
        return
    check_name = check_text.split(",")[0]
    good = 1 if "good + 1 = 2" in check_text else 0
    state = e2e.RxState[state_text]
    rx = e2e.Receiver(state, None if state is e2e.RxState.NODATA else REFERENCE, good)
    counters = [_frame_for(check_name)]
    if check_name == "WRONG_SEQUENCE":               # every step from 2 to 15, each from a fresh receiver
        counters = [(True, (REFERENCE + d) % 16) for d in range(2, 16)]
    for intact, counter in counters:
        rx = e2e.Receiver(state, None if state is e2e.RxState.NODATA else REFERENCE, good)
        check, accepted = rx.receive(intact, counter)
        assert check is e2e.Check[check_name]
        assert accepted == (accepted_text == "yes")
        next_state, _, next_good = next_text.partition(", good")
        assert rx.state is e2e.RxState[next_state]
        if next_good.strip() == "= 0":
            assert rx.good == 0
        elif next_good.strip() == "+ 1":
            assert rx.good == good + 1
        # an intact frame becomes the reference; one that is not takes its slot: reference + 1
        assert rx.reference == (counter if intact else (None if state is e2e.RxState.NODATA else REFERENCE + 1))
