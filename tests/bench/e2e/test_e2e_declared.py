"""A database brings its own protection (issue 24): the messages that declare an AUTOSAR E2E profile, in DBC
attributes, in ARXML or in bench.toml's [e2e] table, are protected and checked with those parameters, and the
bytes are AUTOSAR's: frames protected by cantools' or `autosar-e2e`'s own functions are judged intact by the
bench's receiver, and every frame the bench sends passes `autosar-e2e`'s check with the declared parameters.
The expected parameters are written here from the databases, never read back from `bench.e2e`."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import cantools
import pytest
from cantools.autosar import apply_profile2_crc, apply_profile5_crc
from e2e import p01, p02, p05, p11

from bench.checks.monitor import Monitor
from bench.database.check import check_file
from bench.database.codec import Codebook, load_codebook
from bench.sim.restbus import Restbus
from tests.repo import ROOT

FIXTURE = ROOT / "tests" / "fixtures" / "e2e_profiles.dbc"
#: The CI keeps `shared/` beside the repository's clone.
ARXML = ROOT.parent / "shared" / "corpus" / "arxml" / "system-4.2.arxml"
needs_arxml = pytest.mark.skipif(not ARXML.is_file(), reason=f"no shared corpus beside the repository ({ARXML})")

P02_IDS = bytes(range(0x10, 0x20))
#: The library's own check of each message of the fixture, with the parameters its attributes declare.
LIBRARY_CHECKS: dict[str, Callable[[bytes], bool]] = {
    "P01_Status": lambda d: p01.e2e_p01_check(bytearray(d), 0x1234, data_id_mode=p01.E2E_P01_DATAID_ALT),
    "P02_Status": lambda d: p02.e2e_p02_check(bytearray(d), P02_IDS, length=0),
    "P05_Status": lambda d: p05.e2e_p05_check(bytearray(d), 0x1235),
    "P11_Status": lambda d: p11.e2e_p11_check(bytearray(d), 0x0111, data_id_mode=p11.E2E_P11_DATAID_NIBBLE,
                                              offset=6),
}
#: Where each profile's counter is in the fixture's frames, and how many values it takes.
COUNTERS: dict[str, tuple[Callable[[bytes], int], int]] = {
    "P01_Status": (lambda d: d[1] & 0x0F, 15), "P02_Status": (lambda d: d[1] & 0x0F, 16),
    "P05_Status": (lambda d: d[2], 256), "P11_Status": (lambda d: d[7] & 0x0F, 15)}


def sent(book: Codebook, name: str, count: int) -> list[bytes]:
    """`count` frames of a message as the bench's restbus builds them."""
    restbus = Restbus(book, ["ECU"])
    restbus.set(name, Level=42.0)
    slot = restbus.slots[name]
    return [restbus.build(slot) for _ in range(count)]


def judged(book: Codebook, frame_id: int, frames: list[bytes], monitor: Monitor | None = None) -> list[bool]:
    """Whether the monitor applied each frame, 10 ms apart (a valid verdict whose values became the latest: the
    first frame after start-up is valid but not applied, docs/spec/e2e.md)."""
    monitor = Monitor(book) if monitor is None else monitor
    state = monitor.states[frame_id]
    return [monitor.on_frame(0.01 * k, frame_id, data, "rx") and state.last_valid == 0.01 * k
            for k, data in enumerate(frames)]


# -- acceptance 4: the ARXML's Profile 2 and 5 messages -------------------------------------------------------
@needs_arxml
def test_arxml_loads_with_its_declared_profiles() -> None:
    book = load_codebook([ARXML])
    message1, message3 = book["Message1"].protection, book["Message3"].protection
    assert message1 is not None and message1.profile == "P02" and message1.data_id_list == bytes(range(123, 139))
    assert message3 is not None and message3.profile == "P05" and message3.data_id == 321
    assert book["Message2"].protection is None and "ARXML" in message1.source


#: A data byte under each message's CRC (Message1: signal5, a raw number; Message3: within its 4 protected bytes).
DATA_BYTE = {"Message1": 5, "Message3": 3}


def _arxml_frames(book: Codebook, name: str, count: int) -> list[bytes]:
    """Frames protected by cantools' own functions, with the counter of each profile in sequence (Profile 2:
    the low nibble of byte 1; Profile 5: byte 2), the ARXML message passed for its Data IDs."""
    codec = book[name]
    base = codec.encode({"signal1": 10.0, "signal6": 0.0, "signal5": 0.0, "message1_SeqCounter": 0.0,
                         "message1_CRC": 0.0} if name == "Message1" else
                        {"message3_CRC": 0, "message3_SeqCounter": 0, "Message3_Freshness": 0,
                         "Message3_Authenticator": 0})
    base[DATA_BYTE[name]] = 0x5A
    out = []
    for k in range(count):
        payload = bytearray(base)
        if name == "Message1":
            payload[1] = k % 16
            protected = apply_profile2_crc(bytes(payload), codec.message)
        else:
            payload[2] = k % 256
            protected = apply_profile5_crc(bytes(payload), codec.message)
        assert protected is not None
        out.append(bytes(protected))
    return out


@needs_arxml
@pytest.mark.parametrize("name", ["Message1", "Message3"])
def test_arxml_frames_protected_by_cantools_are_intact(name: str) -> None:
    book = load_codebook([ARXML])
    codec = book[name]
    frames = _arxml_frames(book, name, 40)                       # Profile 2 wraps its counter twice
    assert [codec.counter_if_intact(f) for f in frames] == [k % (16 if name == "Message1" else 256)
                                                            for k in range(40)]
    assert judged(book, codec.frame_id, frames) == [False] + [True] * 39   # the first frame starts the E2E_SM
    damaged = bytearray(frames[7])
    damaged[DATA_BYTE[name]] ^= 0x01                             # a data bit under the CRC
    assert codec.counter_if_intact(bytes(damaged)) is None
    monitor = Monitor(book)
    assert judged(book, codec.frame_id, frames[:7], monitor) == [False] + [True] * 6
    assert not monitor.on_frame(0.07, codec.frame_id, bytes(damaged), "rx")
    assert monitor.state(name).invalid == {"checksum": 1}
    assert monitor.invalid_log[-1].reason.startswith("E2E ERROR: CRC wrong")


@needs_arxml
def test_bench_dbc_check_lists_the_arxml_protection(capsys: pytest.CaptureFixture[str]) -> None:
    from bench.cli import main

    main(["dbc", "check", str(ARXML)])
    out = capsys.readouterr().out
    assert f"{ARXML}: Message1 0x005: P02 DataIDList 7B 7C" in out
    assert f"{ARXML}: Message3 0x064: P05 DataID 0x0141" in out
    assert f"{ARXML}: Message2 0x006: unprotected" in out
    assert "error [e2e]" not in out                              # rejected for other reasons, not for E2E


# -- a database of our own: P01, P02, P05 and P11 by DBC attributes ------------------------------------------
def test_the_fixture_checks_clean() -> None:
    result = check_file(FIXTURE)
    assert result.findings == [] and result.accepted
    assert (result.protected, result.unprotected) == (4, 1)
    assert {p.name: p.protection.profile for p in result.protections if p.protection} == {
        "P01_Status": "P01", "P02_Status": "P02", "P05_Status": "P05", "P11_Status": "P11"}


@pytest.mark.parametrize("name", sorted(LIBRARY_CHECKS))
def test_the_restbus_frames_pass_the_library_and_the_monitor(name: str) -> None:
    book = load_codebook([FIXTURE])
    frames = sent(book, name, 300)                               # every counter wraps (P05 after 256)
    read, modulo = COUNTERS[name]
    assert [read(f) for f in frames] == [k % modulo for k in range(300)]
    assert all(LIBRARY_CHECKS[name](f) for f in frames)
    assert judged(book, book[name].frame_id, frames) == [False] + [True] * 299
    copied = bytearray(frames[5])
    copied[3] ^= 0x80                                            # a data byte under the CRC
    assert not LIBRARY_CHECKS[name](bytes(copied))


def test_a_frame_under_another_identifier_fails_its_data_id() -> None:
    """The P01 frame replayed as the P11 message's identifier: the Data ID differs, the CRC is wrong there."""
    book = load_codebook([FIXTURE])
    frame = sent(book, "P11_Status", 3)[2]
    assert LIBRARY_CHECKS["P11_Status"](frame)
    assert not p11.e2e_p11_check(bytearray(frame), 0x0101, data_id_mode=p11.E2E_P11_DATAID_NIBBLE, offset=6)


def test_the_unprotected_message_is_sent_and_accepted_as_is() -> None:
    book = load_codebook([FIXTURE])
    codec = book["Plain_Status"]
    assert codec.protection is None and not codec.e2e
    frames = sent(book, "Plain_Status", 3)
    assert frames == [(420).to_bytes(2, "little") + bytes(6)] * 3
    assert judged(book, codec.frame_id, frames) == [True] * 3


# -- bench.toml [e2e] over the database --------------------------------------------------------------------
def test_an_override_changes_what_is_sent_and_checked() -> None:
    """[e2e.P11_Status] DataID = 0x0222, DataIDMode = "BOTH": the frames carry the new Data ID, the old fails."""
    book = load_codebook([FIXTURE], {"P11_Status": {"DataID": 0x0222, "DataIDMode": "BOTH"}})
    protection = book["P11_Status"].protection
    assert protection is not None and protection.data_id == 0x0222 and "bench.toml [e2e]" in protection.source
    frames = sent(book, "P11_Status", 20)
    assert all(p11.e2e_p11_check(bytearray(f), 0x0222, data_id_mode=p11.E2E_P11_DATAID_BOTH, offset=6)
               for f in frames)
    assert not any(LIBRARY_CHECKS["P11_Status"](f) for f in frames)
    assert judged(book, book["P11_Status"].frame_id, frames) == [False] + [True] * 19
    plain = load_codebook([FIXTURE], {"Plain_Status": {"Profile": "P11", "DataID": 0x120, "Offset": 48}})
    assert plain["Plain_Status"].protection is not None                 # protection given by bench.toml alone


def test_the_log_process_and_the_mcap_writer_load_with_the_override(tmp_path: Path) -> None:
    """The run's log child and python-can's MCAP writer load the databases as the run does: an override that no
    profile can use stops them with its reason, a good one is what their monitor checks."""
    from bench.errors import BenchError
    from bench.log.canio import MCAPWriter
    from bench.log.logproc import LogProcess

    bad = {"P11_Status": {"Offset": 44}}
    with pytest.raises(BenchError, match="Offset 44 is not a multiple of 8"):
        LogProcess(tmp_path / "run.mcap", [FIXTURE], "test", bad)
    log = LogProcess(tmp_path / "good.mcap", [FIXTURE], "test", {"P11_Status": {"DataID": 0x0222}})
    log.close()
    assert _max_delta_counter(MCAPWriter(tmp_path / "w.mcap", dbc=str(FIXTURE),
                                         e2e={"P11_Status": {"MaxDeltaCounter": 4}})) == 4
    config = tmp_path / "bench.toml"
    config.write_text(f'[bench]\ndatabases = ["{FIXTURE}"]\nstimulus = ["TESTER"]\nplant = "p"\ntestcases = "t"\n'
                      'reports = "r"\n\n[e2e.P11_Status]\nMaxDeltaCounter = 5\n', encoding="utf-8")
    assert _max_delta_counter(MCAPWriter(tmp_path / "c.mcap", dbc=str(FIXTURE), config=str(config))) == 5


def _max_delta_counter(writer: Any) -> int:
    """The MaxDeltaCounter the writer's monitor applies to P11_Status (the writer is stopped)."""
    try:
        assert writer.monitor is not None
        protection = writer.monitor.codebook["P11_Status"].protection
        assert protection is not None
        return protection.max_delta_counter
    finally:
        writer.stop()


def test_dbc_check_applies_the_override(tmp_path: Path) -> None:
    result = check_file(FIXTURE, e2e_overrides={"P11_Status": {"Offset": 40}})
    # the CRC moves to bits 40-47 and the counter to 48-51: the Crc signal at 48 now sits on the counter
    finding = next(f for f in result.warnings if f.kind == "e2e")
    assert (finding.message, finding.signal) == ("P11_Status", "Crc") and "counter field (bits 48-51)" in finding.text
    refused = check_file(FIXTURE, e2e_overrides={"P01_Status": {"Profile": "P04"}})
    error = next(f for f in refused.errors if f.kind == "e2e")
    assert error.message == "P01_Status" and "'P04' is not supported" in error.text and "bench.toml" in error.text


def test_cantools_sees_the_same_attributes() -> None:
    """The fixture is a plain DBC: cantools reads the E2E_* attributes the bench reads."""
    database = cantools.database.load_file(str(FIXTURE))
    assert isinstance(database, cantools.database.can.Database)
    message = database.get_message_by_name("P11_Status")
    assert message.dbc is not None and message.dbc.attributes["E2E_DataID"].value == 0x0111
