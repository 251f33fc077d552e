"""The end-to-end profile is found by place, not by name (docs/spec/e2e.md; issue 17, acceptance 3): a database
whose counter and checksum are called `Cnt` and `Crc` is protected and checked exactly like one that calls them
as the contract does. Expected bytes come from tests/reference.py (written from the catalogue), not bench.e2e."""

from __future__ import annotations

import cantools
import pytest

from bench.cli.monitor import values_text
from bench.codec import Codebook
from bench.dbccheck import check_text
from bench.e2e import Layout
from bench.monitor import Monitor
from bench.restbus import Restbus
from tests.bench.test_dbc_check import GOOD
from tests.reference import contract_checksum

FRAME_ID = 256            # test_dbc_check's ECU_Status
CONTRACT_NAMES = ("AliveCounter", "Checksum")


def dbc(counter: str, checksum: str, counter_at: str = "48|4@1+") -> str:
    """test_dbc_check's database (ECU_Status, 8 bytes, every 10 ms: two values, the counter, the checksum) with
    the counter and the checksum under the given names, the counter at `counter_at`."""
    return GOOD.replace(" AliveCounter ", f" {counter} ").replace(" Checksum ", f" {checksum} ") \
               .replace("48|4@1+", counter_at)


def codebook(text: str) -> Codebook:
    database = cantools.database.load_string(text, database_format="dbc", strict=False)
    assert isinstance(database, cantools.database.can.Database)
    return Codebook([("test.dbc", database)])


def frames(book: Codebook, count: int) -> list[bytes]:
    """`count` frames of ECU_Status as the restbus builds them, Speed 12.34 m/s and Mode HIGH."""
    restbus = Restbus(book, ["ECU"])
    restbus.set("ECU_Status", Speed=12.34, Mode="HIGH")
    slot = restbus.periodic["ECU_Status"]
    return [restbus.build(slot) for _ in range(count)]


@pytest.fixture(params=[CONTRACT_NAMES, ("Cnt", "Crc")], ids=["contract-names", "Cnt-Crc"])
def names(request: pytest.FixtureRequest) -> tuple[str, str]:
    return tuple(request.param)


def test_the_codec_learns_the_names_from_the_database(names: tuple[str, str]) -> None:
    codec = codebook(dbc(*names))["ECU_Status"]
    assert codec.e2e and codec.e2e_layout == Layout(*names)
    assert codec.e2e_signals == set(names)


def test_the_restbus_fills_counter_and_checksum(names: tuple[str, str]) -> None:
    book = codebook(dbc(*names))
    sent = frames(book, 18)
    payload = (1234).to_bytes(2, "little") + bytes([2, 0, 0, 0, 0, 0])   # Speed raw 1234, Mode 2, rest zero
    for k, data in enumerate(sent):
        assert data[6] & 0x0F == k % 16                                  # the counter: 0, 1, ... 15, 0, 1
        assert data[:6] == payload[:6] and data[6] & 0xF0 == 0
        assert data[7] == contract_checksum(FRAME_ID, data)
        values = book["ECU_Status"].decode(data)
        assert (values[names[0]], values[names[1]]) == (k % 16, data[7])
    assert sent == frames(codebook(dbc(*CONTRACT_NAMES)), 18)           # byte for byte the contract's frames


def test_the_monitor_flags_a_wrong_checksum(names: tuple[str, str]) -> None:
    book = codebook(dbc(*names))
    monitor = Monitor(book)
    good = frames(book, 4)
    assert monitor.on_frame(0.00, FRAME_ID, good[0], "rx")
    damaged = bytearray(good[1])
    damaged[7] ^= 0x01
    assert not monitor.on_frame(0.01, FRAME_ID, bytes(damaged), "rx")
    assert monitor.state("ECU_Status").invalid == {"checksum": 1}
    assert monitor.latest("ECU_Status", 0.01) == pytest.approx(
        {"Speed": 12.34, "Mode": 2, names[0]: 0, names[1]: good[0][7]})


def test_the_monitor_view_shows_values_without_counter_and_checksum(names: tuple[str, str]) -> None:
    book = codebook(dbc(*names))
    codec = book["ECU_Status"]
    assert values_text(codec, codec.decode(frames(book, 1)[0])) == "Speed=12.34 Mode=HIGH"


def test_dbc_check_judges_the_places_not_the_names(names: tuple[str, str]) -> None:
    good = check_text(dbc(*names))
    assert good.findings == [] and good.e2e == "required"
    misplaced = check_text(dbc(*names, counter_at="52|4@1+"))
    assert [(f.severity, f.kind, f.signal) for f in misplaced.findings] == [("error", "e2e", names[0])]
    assert "4 unsigned Intel bits at bit 48" in misplaced.findings[0].text


def test_the_contract_names_alone_protect_nothing() -> None:
    """Signals called as the contract calls them, but not at the profile's places: no protection."""
    codec = codebook(dbc(*CONTRACT_NAMES, counter_at="52|4@1+"))["ECU_Status"]
    assert not codec.e2e and codec.e2e_layout is None and codec.e2e_signals == frozenset()
