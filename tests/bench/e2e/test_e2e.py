"""The contract's E2E protection (docs/spec/e2e.md): Profile 11 with DataIDMode BOTH, the CRC in byte 6 and
the counter 0 ... 14 in the low nibble of byte 7, as bench.e2e.Protection writes and reads it. Expected bytes
come from tests/reference.py (written from the document), never from bench.e2e or the library it calls."""

from __future__ import annotations

import re

from hypothesis import given
from hypothesis import strategies as st

from bench import e2e
from bench.database.codec import Codebook
from tests import repo
from tests.reference import COUNTER_VALUES, contract_checksum, crc8_j1850_p11, protected

DATA_IDS = st.sampled_from(sorted(range(0x100, 0x170)) + sorted(range(0x680, 0x6A0)))


def _contract(data_id: int) -> e2e.Protection:
    return e2e.Protection("P11", data_id=data_id, data_id_mode="BOTH", offset=48, length=8, max_delta_counter=2)


def test_check_value() -> None:
    assert crc8_j1850_p11(b"123456789") == 0x37


@given(DATA_IDS, st.binary(min_size=8, max_size=8), st.integers(0, 14))
def test_protect_writes_counter_and_crc(data_id: int, payload: bytes, counter: int) -> None:
    """The counter into bits 56-59, then the CRC into byte 6 over DataID low, high, bytes 0-5 and byte 7;
    bytes 0-5 and the upper nibble of byte 7 (a signal's) stay as they were."""
    p = _contract(data_id)
    data = bytearray(payload)
    p.protect(data, counter)
    assert bytes(data) == protected(data_id, payload, counter)
    assert data[7] & 0x0F == counter and data[7] & 0xF0 == payload[7] & 0xF0 and data[:6] == payload[:6]
    assert p.counter_of(data) == counter and p.checksum_of(data) == data[6]


@given(DATA_IDS, st.binary(min_size=8, max_size=8), st.integers(0, 14), st.integers(0, 255))
def test_the_receiver_reads_the_counter_of_intact_frames_only(data_id: int, payload: bytes, counter: int,
                                                              other: int) -> None:
    """counter_if_intact: the counter when byte 6 is the CRC (independent reference), else None."""
    p = _contract(data_id)
    data = bytearray(protected(data_id, payload, counter))
    assert p.counter_if_intact(bytes(data)) == counter
    p.set_checksum(data, data[6] + other)                  # any other byte (mod 256) breaks it
    assert p.checksum_of(data) == (contract_checksum(data_id, data) + other) % 256
    assert p.counter_if_intact(bytes(data)) == (counter if other == 0 else None)


@given(DATA_IDS, st.binary(min_size=8, max_size=8))
def test_a_counter_of_15_is_never_intact(data_id: int, payload: bytes) -> None:
    """15 is outside Profile 11's counter: a frame carrying it fails the check even with its CRC right."""
    assert _contract(data_id).counter_if_intact(protected(data_id, payload, 15)) is None


@given(st.binary(min_size=8, max_size=8), st.integers(0, 14), st.integers(0, 14))
def test_payload_is_the_frame_without_its_e2e_fields(payload: bytes, first: int, second: int) -> None:
    p = _contract(0x123)
    a, b = bytearray(payload), bytearray(payload)
    p.protect(a, first)
    p.protect(b, second)
    assert p.payload(bytes(a)) == p.payload(bytes(b)) == payload[:6] + bytes([0, payload[7] & 0xF0])
    assert p.header_mask == 0x0F_FF << 48


def test_counter_wraps_14_to_0() -> None:
    p = _contract(0x110)
    assert p.counter_modulo == COUNTER_VALUES == 15
    assert p.next_counter(14) == 0 and p.next_counter(3) == 4
    data = bytearray(8)
    p.protect(data, 15)                                    # a counter is written modulo the profile's range
    assert p.counter_of(data) == 0


def test_every_message_describes_its_protection(codebook: Codebook) -> None:
    """One line per message, the parameters a receiver configures (bench dbc check, the report)."""
    text = codebook["DRV_MotionRequest"].protection.describe()
    assert text == ("P11 DataID 0x0102 BOTH, CRC bits 48-55, counter bits 56-59 (0-14), MaxDeltaCounter 2, "
                    "window 2 (init 1/0, valid 2/0, invalid 2/0)")


def test_the_e2e_signals_are_the_header_fields(codebook: Codebook) -> None:
    """The signals a message's database puts on the CRC and the counter are its E2E signals (never set by
    hand); the 4-bit signal of the upper nibble of byte 7 is an ordinary one."""
    codec = codebook["DRV_MotionRequest"]
    assert codec.e2e and codec.e2e_signals == {"AliveCounter", "Checksum"}
    assert "DriveMode" not in codec.e2e_signals and codec.by_name["DriveMode"].start == 60


def test_only_the_e2e_package_calls_the_profiles() -> None:
    """The profiles' CRCs are computed in one place, bench/e2e/profiles.py (sender and receiver cannot
    disagree): no other module of bench/ or plant/ imports the `autosar-e2e` library or computes a
    CRC-8 of its own."""
    root = repo.ROOT
    library = re.compile(r"^\s*(from e2e\b|import e2e\b)")
    own_crc = re.compile(r"\b(crc8\w*|0x1D)\b", re.IGNORECASE)
    found = [f"{path.relative_to(root)}:{n}: {line.strip()}"
             for folder in ("bench", "plant") for path in sorted((root / folder).rglob("*.py"))
             if path.relative_to(root).as_posix() != "bench/e2e/profiles.py"
             for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if library.search(line) or own_crc.search(line)]
    assert found == []


def _attribute_table() -> dict[str, list[str]]:
    """docs/spec/e2e.md's table of DBC attributes: name -> (type, meaning, contract)."""
    lines = (repo.ROOT / "docs" / "spec" / "e2e.md").read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| DBC attribute |")) + 2
    rows = {}
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip()[1:-1].split("|")]
        rows[cells[0].strip("`")] = cells[1:]
    return rows


def test_the_documents_attributes_are_the_databases() -> None:
    """Every E2E_* attribute both databases define is in the document's table, with its ENUM values, and the
    contract's numbers are the databases' defaults; and the table names every parameter the bench reads."""
    import cantools

    table = _attribute_table()
    assert set(table) == {"E2E_" + name for name in e2e.PARAMETERS}
    for path in (repo.CHASSIS_DBC, repo.BENCH_DBC):
        definitions = {k: v for k, v in cantools.database.load_file(str(path)).dbc.attribute_definitions.items()
                       if k.startswith("E2E_")}
        assert set(definitions) == set(table), path.name
        for name, definition in definitions.items():
            kind, _, contract = table[name]
            assert kind.startswith(definition.type_name), name
            for choice in definition.choices or ():
                assert f"`{choice}`" in kind, (name, choice)
            if contract.isdigit():
                assert int(definition.default_value) == int(contract), (path.name, name)
            elif name == "E2E_DataIDMode":
                assert definition.default_value == contract, (path.name, name)
