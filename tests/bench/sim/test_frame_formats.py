"""29-bit identifiers and CAN FD frames from the restbus to the monitor and the log, as 11-bit classical ones go.

A database of its own: an 11-bit and a 29-bit message with the same number (two identifiers on the bus), a 29-bit
CAN FD message of 64 bytes with the bit rate switch and an 11-bit CAN FD message of 12 bytes without it. One station
sends them, another receives them: each is judged valid as its own message, its values arrive, and the log keeps
each frame's format and flags as python-can reads them back. The expected flags come from the database text below,
not from the bench's code.
"""

from __future__ import annotations

import dataclasses
import uuid
from pathlib import Path

import can
import cantools
import pytest

from bench import canid
from bench.checks.monitor import CheckedFrame, Monitor
from bench.config import load_config
from bench.database.codec import Codebook
from bench.errors import ConfigError
from bench.log.canio import MCAPReader
from bench.log.recorder import Recorder
from bench.session import resolve_bus_options
from bench.sim.restbus import Restbus
from bench.sim.station import Station
from bench.transport import BusOptions, VirtualTimeBus, open_bus
from tests.fakes import ipv4_group
from tests.repo import VFRAMEFORMAT_DEFINITION

DBC = f"""VERSION ""
NS_ :
BS_:
BU_: SENDER RECEIVER
BO_ 291 Std: 8 SENDER
 SG_ Value : 0|16@1+ (1,0) [0|65535] "" RECEIVER
BO_ 2147483939 Ext: 8 SENDER
 SG_ Value : 0|16@1+ (1,0) [0|65535] "" RECEIVER
BO_ 2566844672 Fd64: 64 SENDER
 SG_ Head : 0|16@1+ (1,0) [0|65535] "" RECEIVER
 SG_ Tail : 496|16@1+ (1,0) [0|65535] "" RECEIVER
BO_ 512 FdStd: 12 SENDER
 SG_ Value : 80|16@1+ (1,0) [0|65535] "" RECEIVER
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 10000;
{VFRAMEFORMAT_DEFINITION}
BA_DEF_ BO_ "CANFD_BRS" ENUM "0","1";
BA_DEF_DEF_ "GenMsgCycleTime" 0;
BA_DEF_DEF_ "VFrameFormat" "StandardCAN";
BA_DEF_DEF_ "CANFD_BRS" "1";
BA_ "GenMsgCycleTime" BO_ 291 10;
BA_ "GenMsgCycleTime" BO_ 2147483939 10;
BA_ "GenMsgCycleTime" BO_ 2566844672 10;
BA_ "GenMsgCycleTime" BO_ 512 20;
BA_ "VFrameFormat" BO_ 2147483939 1;
BA_ "VFrameFormat" BO_ 2566844672 15;
BA_ "VFrameFormat" BO_ 512 14;
BA_ "CANFD_BRS" BO_ 512 0;
"""
#: message -> (arbitration id, 29-bit, CAN FD, bit rate switch, length), as the database text above declares them
DECLARED = {"Std": (0x123, False, False, False, 8), "Ext": (0x123, True, False, False, 8),
            "Fd64": (0x18FEF100, True, True, True, 64), "FdStd": (0x200, False, True, False, 12)}
VALUES = {"Std": {"Value": 11}, "Ext": {"Value": 29}, "Fd64": {"Head": 100, "Tail": 64_000}, "FdStd": {"Value": 4242}}


@pytest.fixture(scope="module")
def codebook() -> Codebook:
    db = cantools.database.load_string(DBC, "dbc")
    return Codebook([("formats.dbc", db)])


def test_the_codebook_names_each_message_by_identifier_format_and_fd(codebook: Codebook) -> None:
    for name, (ident, extended, fd, brs, length) in DECLARED.items():
        codec = codebook[name]
        assert codec.frame_id == canid.of(ident, extended, is_fd=fd)
        assert codec.send_id == canid.of(ident, extended, is_fd=fd, bitrate_switch=brs)
        assert codebook.by_id[codec.frame_id] is codec and codec.length == length
    assert canid.text(codebook["Std"].frame_id) == "0x123" and canid.text(codebook["Ext"].frame_id) == "0x00000123"


def _exchange(codebook: Codebook, sender_bus: can.BusABC, receiver_bus: can.BusABC, ticks: int,
              sink: list[CheckedFrame]) -> Monitor:
    """The sender's restbus for `ticks` 1 ms ticks; the receiver reads every frame into its monitor."""
    t = {"now": 0.0}
    sender = Station("sender", sender_bus, Restbus(codebook, {"SENDER"}), Monitor(codebook), lambda: t["now"])
    received = Monitor(codebook, keep_history=True, sink=sink.append)
    receiver = Station("receiver", receiver_bus, Restbus(codebook, {"RECEIVER"}), received, lambda: t["now"])
    for name, values in VALUES.items():
        sender.restbus.set(name, **values)
    for tick in range(ticks):
        t["now"] = tick * 0.001
        sender.tick(tick, t["now"], 0.001)
        deadline = 200
        while receiver.poll(0.05 if not isinstance(receiver_bus, VirtualTimeBus) else 0.0) and deadline:
            deadline -= 1
    for _ in range(20):    # a real bus: the last frames may still be on their way
        receiver.poll(0.05)
    return received


def _check_received(received: Monitor, frames: list[CheckedFrame], ticks: int) -> None:
    assert received.invalid_log == [] and received.unknown_frames == 0
    for name, values in VALUES.items():
        state = received.state(name)
        cycle = 0.02 if name == "FdStd" else 0.01
        assert state.frames == pytest.approx(ticks * 0.001 / cycle, abs=1), name
        assert {k: state.latest[k] for k in values} == values, name
    flags = {(f.codec.name if f.codec else "?", canid.is_extended(f.frame_id), canid.is_fd(f.frame_id),
              bool(f.frame_id & canid.BRS)) for f in frames}
    assert flags == {(name, ext, fd, brs) for name, (_, ext, fd, brs, _) in DECLARED.items()}


def test_the_embedded_bus_carries_29_bit_and_fd_frames(codebook: Codebook, tmp_path: Path) -> None:
    channel = f"formats-{uuid.uuid4()}"
    frames: list[CheckedFrame] = []
    received = _exchange(codebook, VirtualTimeBus(channel=channel), VirtualTimeBus(channel=channel), 100, frames)
    _check_received(received, frames, 100)

    # the log keeps each frame's format and flags: python-can reads them back from the MCAP file
    path = tmp_path / "formats.mcap"
    recorder = Recorder(path, [db for _, db in codebook.databases])
    assert recorder.frames([(f.t, f.frame_id, f.data, f.direction, f.valid, f.reason) for f in frames],
                           channel="bench", codecs=codebook.by_id) == []
    recorder.close()
    with open(path, "rb") as file:
        back = list(MCAPReader(file))
    assert len(back) == len(frames)
    seen = {(m.arbitration_id, m.is_extended_id, m.is_fd, m.bitrate_switch, len(m.data)) for m in back}
    assert seen == set(DECLARED.values())


def test_udp_multicast_carries_them_between_processes_buses(codebook: Codebook) -> None:
    group = ipv4_group()
    options = BusOptions(fd=True)
    with open_bus("udp_multicast", group, options) as receiver_bus, \
            open_bus("udp_multicast", group, options) as sender_bus:
        frames: list[CheckedFrame] = []
        received = _exchange(codebook, sender_bus, receiver_bus, 60, frames)
    _check_received(received, frames, 60)


def test_a_classical_frame_of_an_fd_message_is_the_messages_fault(codebook: Codebook) -> None:
    monitor = Monitor(codebook)
    codec = codebook["FdStd"]
    data = bytes(codec.encode(codec.start_values()))
    assert not monitor.on_frame(0.0, codec.frame_id & ~canid.FD, data, "rx")      # sent as classical CAN
    assert [(f.message, f.reason) for f in monitor.invalid_log] == [
        ("FdStd", "frame format: a classical CAN frame, the database declares CAN FD")]
    assert monitor.on_frame(0.01, codec.frame_id | canid.BRS, data, "rx")          # BRS does not name a message


def test_an_fd_database_on_a_classical_bus_is_refused_at_the_door(codebook: Codebook) -> None:
    project = dataclasses.replace(load_config(), bus=BusOptions())   # a project whose bench.toml says nothing of FD
    with pytest.raises(ConfigError, match=r"CAN FD messages on a bus opened as classical CAN: Fd64 .*fd = true"):
        resolve_bus_options(project, BusOptions(), codebook)
    assert resolve_bus_options(project, BusOptions(fd=True), codebook).fd is True


def test_e2e_profile_5_protects_a_64_byte_fd_frame(tmp_path: Path) -> None:
    """The fixture's Profile 5 message made a 64-byte CAN FD frame with a signal in its last bytes: the restbus's
    frames pass autosar-e2e's own P05 check over all 64 bytes, the monitor applies them, and a bit flipped in byte
    61 fails both."""
    from e2e import p05

    from tests.repo import ROOT

    text = (ROOT / "tests" / "fixtures" / "e2e_profiles.dbc").read_text(encoding="utf-8")
    text = text.replace("BO_ 261 P05_Status: 8 ECU", "BO_ 261 P05_Status: 64 ECU").replace(
        ' SG_ Level : 24|16@1+ (0.1,0) [0|1000] "%" TESTER',
        ' SG_ Level : 24|16@1+ (0.1,0) [0|1000] "%" TESTER\n SG_ Far : 488|16@1+ (1,0) [0|65535] "-" TESTER')
    text += ('BA_DEF_ BO_ "VFrameFormat" ENUM "StandardCAN","ExtendedCAN","reserved","reserved","reserved",'
             '"reserved","reserved","reserved","reserved","reserved","reserved","reserved","reserved","reserved",'
             '"StandardCAN_FD","ExtendedCAN_FD";\nBA_ "VFrameFormat" BO_ 261 14;\n')
    path = tmp_path / "fd_e2e.dbc"
    path.write_text(text, encoding="utf-8")
    from bench.database.codec import load_codebook

    book = load_codebook([path])
    codec = book["P05_Status"]
    assert canid.is_fd(codec.frame_id) and codec.length == 64 and codec.protection is not None
    restbus = Restbus(book, ["ECU"])
    restbus.set("P05_Status", Level=42.0, Far=0xBEEF)
    frames = [restbus.build(restbus.slots["P05_Status"]) for _ in range(20)]
    assert all(len(f) == 64 and p05.e2e_p05_check(bytearray(f), 4661) for f in frames)
    monitor = Monitor(book)
    applied = [monitor.on_frame(k * 0.01, codec.frame_id, f, "rx") for k, f in enumerate(frames)]
    assert applied == [False] + [True] * 19 and monitor.state("P05_Status").latest["Far"] == 0xBEEF
    damaged = bytearray(frames[5])
    damaged[61] ^= 0x01
    assert not p05.e2e_p05_check(bytearray(damaged), 4661)
    assert not monitor.on_frame(0.2, codec.frame_id, bytes(damaged), "rx")
    assert monitor.invalid_log[-1].reason.startswith("E2E ERROR: CRC wrong")


def test_a_bitflip_reaches_every_bit_of_an_fd_frame_and_no_further(codebook: Codebook) -> None:
    """bitflip's BIT runs over the target's own payload: 0..511 on the 64-byte Fd64, 0..63 on the 8-byte Std."""
    from bench.faults.plan import validate

    assert validate(["bitflip:Fd64:511@1"], codebook) == []
    for spec, limit in (("bitflip:Fd64:512@1", "0..511 (Fd64 has 64 bytes)"), ("bitflip:Std:64@1", "0..63 (Std")):
        problems = validate([spec], codebook)
        assert len(problems) == 1 and limit in problems[0], problems
