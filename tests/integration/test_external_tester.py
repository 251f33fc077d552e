"""A tester no one on the team wrote: udsoncan's `Client` on can-isotp's own transport (`isotp.NotifierBasedCanStack`
on a python-can udp_multicast bus, `udsoncan.connections.PythonIsoTpConnection`), against `bench plant` in another
process, with nothing of `bench/`: the DID codecs, the DTC numbers and the seed/key algorithm are written here from
docs/contract/diagnostics.md and read from dbc/diagnostics.toml, as a supplier's tester would.

The fault: `bench plant --fault drop:VCU_WheelCmd_FL@3-6` drops the simulated VCU's command to the front-left wheel
module (the plant sends it: with no test runner on the bus the VCU is the plant's) from 3 s to 6 s after the plant's
start, so the reference WHL_FL reports CMD_TIMEOUT (wheel.md WHL-FLT-01; WHL_Status_FL.WheelFault 3, seen on the bus
when the test was written) and records DTC C1D03-87 (confirm_ms 500, warning_indicator true). The plant's own clock
is read from the node itself: OperatingTime (0xDD00) is its time since power-up (DIAG-DTC-05), the plant's start.
"""

from __future__ import annotations

import socket
import struct
import sys
import time
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import can
import cantools
import isotp
import pytest
from udsoncan import AsciiCodec, DidCodec
from udsoncan.client import Client
from udsoncan.configs import default_client_config
from udsoncan.connections import PythonIsoTpConnection
from udsoncan.exceptions import NegativeResponseException

from tests.child import Child
from tests.fakes import ipv4_group
from tests.repo import CHASSIS_DBC, DBC_DIR, ROOT

DECLARATION: dict[str, Any] = tomllib.loads((DBC_DIR / "diagnostics.toml").read_text(encoding="utf-8"))
PROTOCOL = DECLARATION["protocol"]
IP_MULTICAST_ALL = 49            # linux/in.h: README "udp_multicast": only this bus's own group

pytestmark = pytest.mark.realtime

FAULT_START, FAULT_END = 3.0, 6.0
FAULT = f"drop:VCU_WheelCmd_FL@{FAULT_START:g}-{FAULT_END:g}"

# ISO 14229-1 Annex D status bits (DIAG-DTC-03)
TEST_FAILED, TFTOC, PENDING, CONFIRMED, TNCSLC, TFSLC, TNCTOC, WIR = (1 << bit for bit in range(8))


# -- written from docs/contract/diagnostics.md -------------------------------------------------------------------
def dtc_number(code: str) -> int:
    """DIAG-DTC-01: letter bits (P 00, C 01, B 10, U 11) in 23-22, the first digit in 21-20, three hex digits in
    19-8, the failure type byte in 7-0."""
    digits, ftb = code.split("-")
    return ("PCBU".index(digits[0]) << 22) | (int(digits[1]) << 20) | (int(digits[2:5], 16) << 8) | int(ftb, 16)


def documented_key(seed: int, constant: int) -> int:
    """DIAG-SEC-01: key = rotl32(seed XOR C, 7) XOR 0xA5A5A5A5."""
    x = (seed ^ constant) & 0xFFFFFFFF
    return (((x << 7) | (x >> 25)) & 0xFFFFFFFF) ^ 0xA5A5A5A5


def key_algorithm(level: int, seed: bytes, params: Any) -> bytes:
    """udsoncan's security_algo; params: the node's security_constant."""
    return documented_key(int.from_bytes(seed, "big"), params).to_bytes(4, "big")


FORMATS = {"uint8": ">B", "int8": ">b", "uint16": ">H", "int16": ">h", "uint32": ">I", "int32": ">i"}


class Physical(DidCodec):
    """A numeric DID of the declaration: big-endian raw, physical = raw * scale + offset; an enumeration (`values`)
    decodes to its name and encodes a name or a raw value."""

    def __init__(self, table: dict[str, Any]) -> None:
        self.format = FORMATS[table["type"]]
        self.scale = float(table.get("scale", 1.0))
        self.offset = float(table.get("offset", 0.0))
        self.values: dict[str, int] = dict(table.get("values", {}))

    def encode(self, *did_value: Any) -> bytes:
        value = did_value[0]
        raw = self.values[value] if isinstance(value, str) else round((value - self.offset) / self.scale)
        return struct.pack(self.format, raw)

    def decode(self, did_payload: bytes) -> Any:
        raw: int = struct.unpack(self.format, did_payload)[0]
        if self.values:
            return next((name for name, number in self.values.items() if number == raw), raw)
        return raw * self.scale + self.offset

    def __len__(self) -> int:
        return struct.calcsize(self.format)


def codecs(node: str) -> dict[int, DidCodec]:
    """Every DID the node declares: identification (ASCII), the snapshot's common ones, its own."""
    tables = DECLARATION["identification"] + DECLARATION["snapshot"] + DECLARATION["nodes"][node].get("did", [])
    return {t["id"]: AsciiCodec(t["length"]) if t["type"] == "ascii" else Physical(t) for t in tables}


def test_written_from_the_documents_agree_with_their_examples() -> None:
    """The document's own worked examples, so that a failure below is the node's, not this file's."""
    assert dtc_number("C1A01-1C") == 0x5A011C
    assert documented_key(0x12345678, 0x53425701) == 0x1EA51905
    assert Physical({"type": "int16", "scale": 0.1}).decode(b"\xff\xf6") == pytest.approx(-1.0)


# -- the plant and the tester --------------------------------------------------------------------------------------
@contextmanager
def plant(group: str, *extra: str) -> Iterator[Child]:
    child = Child([sys.executable, "-m", "bench", "plant", "--interface", "udp_multicast", "--channel", group, *extra],
                  ROOT)
    try:
        child.wait_for("simulating", 20)
        yield child
    finally:
        output = child.stop()
    assert child.returncode == 0, output


class Bus:
    """The tester's own python-can bus on the group, with a notifier that also records every frame."""

    def __init__(self, group: str) -> None:
        self.bus = can.Bus(interface="udp_multicast", channel=group)
        self.bus._multicast._socket.setsockopt(socket.IPPROTO_IP, IP_MULTICAST_ALL, 0)
        self.frames: list[tuple[float, can.Message]] = []
        self.notifier = can.Notifier(self.bus, [lambda msg: self.frames.append((time.monotonic(), msg))])

    def close(self) -> None:
        self.notifier.stop()
        self.bus.shutdown()


@contextmanager
def uds_client(bus: Bus, node: str) -> Iterator[Client]:
    table = DECLARATION["nodes"][node]
    address = isotp.Address(isotp.AddressingMode.Normal_11bits, txid=table["request"], rxid=table["response"])
    stack = isotp.NotifierBasedCanStack(bus.bus, bus.notifier, address=address, params={
        "tx_padding": PROTOCOL["padding"], "tx_data_min_length": 8, "blocksize": 0, "stmin": 0,
        "rx_flowcontrol_timeout": PROTOCOL["n_bs_ms"], "rx_consecutive_frame_timeout": PROTOCOL["n_cr_ms"]})
    config = dict(default_client_config)
    config.update({
        "data_identifiers": codecs(node),
        "security_algo": key_algorithm,
        "security_algo_params": table["security_constant"],
        "standard_version": 2013,
        "request_timeout": 5.0,
        "p2_timeout": PROTOCOL["p2_ms"] / 1000 + 0.2,      # the node's P2 plus a loaded host's margin
        "p2_star_timeout": PROTOCOL["p2_star_ms"] / 1000 + 0.5,
        "use_server_timing": False,
        "dtc_snapshot_did_size": 2,
        "extended_data_size": {dtc_number(d["code"]): 1 for d in table.get("dtc", [])},
    })
    with Client(PythonIsoTpConnection(stack), config=config) as client:   # type: ignore[arg-type]
        yield client


def plant_time(client: Client) -> float:
    return float(client.read_data_by_identifier_first(0xDD00))


def statuses(client: Client, mask: int = 0xFF) -> dict[int, int]:
    response = client.get_dtc_by_status_mask(mask)
    return {dtc.id: dtc.status.get_byte_as_int() for dtc in response.service_data.dtcs}


def response_frames(bus: Bus, node: str) -> list[bytes]:
    response_id = DECLARATION["nodes"][node]["response"]
    return [bytes(msg.data) for _, msg in bus.frames if msg.arbitration_id == response_id]


def assert_framing(frames: list[bytes]) -> None:
    """DIAG-TP-02: every frame of the node 8 bytes; a single frame padded with 0xCC after its data."""
    assert frames
    for data in frames:
        assert len(data) == 8, data.hex(" ")
        if data[0] >> 4 == 0:
            assert data[1 + data[0]:] == bytes([PROTOCOL["padding"]]) * (7 - data[0]), data.hex(" ")


# -- the tests -----------------------------------------------------------------------------------------------------
def test_cmd_timeout_is_recorded_confirmed_snapshotted_and_cleared() -> None:
    node = DECLARATION["nodes"]["WHL_FL"]
    dtc = next(d for d in node["dtc"] if d["name"] == "CMD_TIMEOUT")
    number = dtc_number(dtc["code"])
    assert (dtc["code"], number, dtc["confirm_ms"], dtc["warning_indicator"]) == ("C1D03-87", 0x5D0387, 500, True)
    group = ipv4_group()
    bus = Bus(group)
    try:
        with plant(group, "--fault", FAULT), uds_client(bus, "WHL_FL") as client:
            started = plant_time(client)
            assert started < FAULT_START - 1.0, f"the tester reached the plant only at {started:.2f} s"
            # as delivered, before its monitors' first result: every DTC 0x50 (DIAG-DTC-03; the first 100 ms of
            # DIAG-OPC-01 give none) -- seen only when the tester is that early
            if started < 0.09:
                assert set(statuses(client).values()) <= {0x50}
            while plant_time(client) < 0.5:
                time.sleep(0.05)
            # before the fault, tested: nothing recorded, not even the command timeout the wheel module shows at
            # its start-up until its first commands arrive (DIAG-OPC-01's start-up time)
            before = statuses(client)
            assert before == {}, {f"0x{k:06X}": f"0x{v:02X}" for k, v in before.items()}
            assert client.read_data_by_identifier_first(0xFD13) == "OK"

            # through the fault, every ~30 ms: the DTC's status and the node's fault code (its DID 0xFD13), with the
            # plant's time read just before and just after (the values are of a moment between the two)
            seen: list[tuple[float, int, str, float]] = []
            while (now := plant_time(client)) < FAULT_END + 0.3:
                if now > FAULT_START - 0.2:
                    status = statuses(client).get(number, 0x00)
                    seen.append((now, status, client.read_data_by_identifier_first(0xFD13), plant_time(client)))
                time.sleep(0.03)
            shown = ", ".join(f"{t0:.3f}-{t1:.3f} 0x{s:02X} {f}" for t0, s, f, t1 in seen)

            def onset(status: int) -> tuple[float, float]:
                """When the status became `status`: after the start of the last sample before, at the latest at
                the end of the first sample with it."""
                i = next(i for i, sample in enumerate(seen) if sample[1] == status)
                return seen[i - 1][0], seen[i][3]

            # the status byte's documented sequence (DIAG-DTC-03): never failed 0x00, failing 0x27, confirmed with
            # the warning indicator 0xAF, passing again 0xAE (testFailed clear, confirmedDTC and WIR kept)
            order = [s for i, (_, s, _, _) in enumerate(seen) if i == 0 or s != seen[i - 1][1]]
            assert order == [0x00, 0x27, 0xAF, 0xAE], shown
            failed, confirmed, passed = onset(0x27), onset(0xAF), onset(0xAE)
            # the wheel's command timeout (3 cycles of VCU_WheelCmd_FL, 10 ms) after the drop began
            assert failed[1] >= FAULT_START and failed[0] <= FAULT_START + 0.25, shown
            confirm = dtc["confirm_ms"] / 1000   # confirmedDTC after confirm_ms of continuous failure
            assert confirmed[0] - failed[1] <= confirm + 0.03 and confirmed[1] - failed[0] >= confirm - 0.03, shown
            assert passed[1] >= FAULT_END and passed[0] <= FAULT_END + 0.25, shown
            # the node's fault code (DIAG-SVC-02) agrees with the fault memory away from the changes
            assert {f for t0, _, f, t1 in seen if t1 < FAULT_START} == {"OK"}, shown
            assert {f for t0, _, f, t1 in seen if failed[1] < t0 and t1 < FAULT_END} == {"CMD_TIMEOUT"}, shown
            assert {f for t0, _, f, t1 in seen if t0 > passed[1]} == {"OK"}, shown

            # ... and on the bus: WHL_Status_FL.WheelFault (cantools, the contract's DBC)
            status_msg = cantools.database.load_file(str(CHASSIS_DBC)).get_message_by_name("WHL_Status_FL")
            faults = {status_msg.decode(bytes(m.data), decode_choices=False)["WheelFault"]
                      for _, m in bus.frames if m.arbitration_id == status_msg.frame_id}
            assert 3 in faults, faults     # CMD_TIMEOUT

            # reportDTCByStatusMask with a mask: only the DTCs with one of its bits (DIAG-DTC-07)
            assert statuses(client, TEST_FAILED) == {}
            assert statuses(client, CONFIRMED) == {number: 0xAE}

            # the snapshot record of the occurrence (DIAG-DTC-05): the node's snapshot DIDs in order, taken when
            # testFailed went to 1
            response = client.get_dtc_snapshot_by_dtc_number(number, record_number=1)
            [record] = response.service_data.dtcs
            assert record.id == number and record.status.get_byte_as_int() == 0xAE
            assert [s.record_number for s in record.snapshots] == [1] * len(node["snapshot"])
            assert [s.did for s in record.snapshots] == node["snapshot"]
            values = {s.did: s.data for s in record.snapshots}
            assert failed[0] <= values[0xDD00] <= failed[1], (values, shown)   # OperatingTime: when it failed
            assert all(isinstance(v, float) for v in values.values()), values
            # its occurrence counter (extended data record 0x01): one occurrence
            response = client.get_dtc_extended_data_by_dtc_number(number, 1, data_size=1)
            assert response.service_data.dtcs[0].extended_data[0].raw_data == b"\x01"

            # clear that DTC (0x14): status back to 0x50, then the next passed result 0x00; no record, count 0
            client.clear_dtc(number)
            assert number not in statuses(client)
            response = client.get_dtc_snapshot_by_dtc_number(number, record_number=0xFF)
            [record] = response.service_data.dtcs
            assert record.status.get_byte_as_int() in (0x00, 0x50) and record.snapshots == []
            response = client.get_dtc_extended_data_by_dtc_number(number, 1, data_size=1)
            assert response.service_data.dtcs[0].extended_data[0].raw_data == b"\x00"
            # a DTC of another node is not this node's to clear (DIAG-DTC-06)
            with pytest.raises(NegativeResponseException) as refused:
                client.clear_dtc(dtc_number("C1A01-1C"))
            assert refused.value.response.code == 0x31
    finally:
        bus.close()
    assert_framing(response_frames(bus, "WHL_FL"))


@pytest.mark.parametrize("name", ["WHL_FL", "SBW", "VCU"])
def test_identification(name: str) -> None:
    """DIAG-ID-01: F187, F18C, F190, F195 in one request (a segmented response through can-isotp's flow control),
    each exactly its length of printable ASCII, the reference's values."""
    wanted = DECLARATION["nodes"][name]["identification"]
    group = ipv4_group()
    bus = Bus(group)
    try:
        with plant(group), uds_client(bus, name) as client:
            response = client.read_data_by_identifier([0xF187, 0xF18C, 0xF190, 0xF195])
            values = response.service_data.values
            one = client.read_data_by_identifier_first(0xF190)
    finally:
        bus.close()
    for did in DECLARATION["identification"]:
        value = values[did["id"]]
        assert len(value) == did["length"] and all(0x20 <= ord(c) <= 0x7E for c in value), (did, value)
        assert value == wanted[did["name"]].ljust(did["length"]), (did, value)
    assert one == "BENCH000000000001"
    frames = response_frames(bus, name)
    assert_framing(frames)
    assert any(data[0] >> 4 == 1 for data in frames) and any(data[0] >> 4 == 2 for data in frames)   # FF and CFs


def test_session_security_coding_and_routine() -> None:
    """DIAG-SES-01's timing figures, DIAG-SEC-01 with the documented algorithm (a wrong key first: 0x35),
    DIAG-COD-01 (write, read back, limits, write the default back) and DIAG-SVC-03 (0x78 while it runs)."""
    group = ipv4_group()
    bus = Bus(group)
    try:
        with plant(group), uds_client(bus, "SBW") as client:
            with pytest.raises(NegativeResponseException) as refused:
                client.unlock_security_access(1)                    # default session: not supported there
            assert refused.value.response.code == 0x7F
            response = client.change_session(3)
            assert response.service_data.p2_server_max == pytest.approx(PROTOCOL["p2_ms"] / 1000)
            assert response.service_data.p2_star_server_max == pytest.approx(PROTOCOL["p2_star_ms"] / 1000)
            with pytest.raises(NegativeResponseException) as refused:
                client.write_data_by_identifier(0xFDC0, "YAW_RATE")  # locked
            assert refused.value.response.code == 0x33
            seed = client.request_seed(1).service_data.seed
            assert seed != b"\x00\x00\x00\x00"
            wrong = bytes(b ^ 0xFF for b in key_algorithm(1, seed, DECLARATION["nodes"]["SBW"]["security_constant"]))
            with pytest.raises(NegativeResponseException) as refused:
                client.send_key(2, wrong)
            assert refused.value.response.code == 0x35
            client.unlock_security_access(1)
            assert client.read_data_by_identifier_first(0xFDC0) == "DIRECT"
            client.write_data_by_identifier(0xFDC0, "YAW_RATE")
            assert client.read_data_by_identifier_first(0xFDC0) == "YAW_RATE"
            with pytest.raises(NegativeResponseException) as refused:
                client.write_data_by_identifier(0xFDC1, 0.9)          # IdealYawGain max 0.5
            assert refused.value.response.code == 0x31
            assert client.read_data_by_identifier_first(0xFDC1) == pytest.approx(0.28)
            client.write_data_by_identifier(0xFDC0, "DIRECT")
            begun = time.monotonic()
            client.start_routine(0x0201)                              # SteeringAngleSensorZero, 300 ms
            took = time.monotonic() - begun
            assert 0.3 <= took <= 1.0, took
            client.routine_control(0x0201, 3)                         # its results, once it ran
    finally:
        bus.close()
    frames = response_frames(bus, "SBW")
    assert_framing(frames)
    assert bytes.fromhex("03 7F 31 78") in (data[:4] for data in frames)   # responsePending while it ran
