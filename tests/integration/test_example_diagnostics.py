"""The example ECUs' diagnostics (examples/uds_server.py in examples/vcu_ecu.py, sbw_ecu.py, abs_ecu.py), judged
service by service against docs/contract/diagnostics.md as a tester sees them.

Each test starts one example as a subprocess on a private udp_multicast group (hop limit 0), talks to it with
udsoncan's client over can-isotp, as a workshop tester would, and stops it. No plant: an example on its own
reports the faults of its missing inputs (the VCU REQUEST_TIMEOUT, the SBW SENSOR_SIGNAL_LOST, the ABS
INPUT_TIMEOUT), which is enough to judge the fault memory's service side. Each example also has a deliberate defect
behind `--diag-defect`; the last test checks that a contract check catches it (and passes without it).
"""

from __future__ import annotations

import os
import random
import signal
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest

from tests.repo import ROOT

can = pytest.importorskip("can")
isotp = pytest.importorskip("isotp")
udsoncan = pytest.importorskip("udsoncan")
from udsoncan.client import Client  # noqa: E402
from udsoncan.connections import PythonIsoTpConnection  # noqa: E402

pytestmark = pytest.mark.realtime

FUNCTIONAL = 0x7DF
IDENTIFICATION = {0xF187: 10, 0xF18C: 12, 0xF190: 17, 0xF195: 8}  # DIAG-ID-01: DID -> length


@dataclass(frozen=True)
class Node:
    name: str
    script: str
    request: int
    response: int
    constant: int  # DIAG-SEC-01's security_constant
    routine: int
    routine_ms: int
    dtc: int  # the DTC the example records on its own (an input never received)
    confirm_ms: int
    defect: str
    snapshot_dids: int  # the DIDs of snapshot record 0x01 (diagnostics.toml `snapshot`)
    coding: dict[int, str] = field(default_factory=dict)  # coding DID -> struct format


VCU = Node("VCU", "vcu_ecu.py", 0x700, 0x708, 0x56435501, 0x0204, 500, 0x5C0587, 500, "snapshot-stale", 12,
           {0xFDC0: ">B"})
SBW = Node("SBW", "sbw_ecu.py", 0x705, 0x70D, 0x53425701, 0x0201, 300, 0x5A0531, 500, "wrong-nrc", 9,
           {0xFDC0: ">B", 0xFDC1: ">H"})
ABS = Node("ABS", "abs_ecu.py", 0x706, 0x70E, 0x41425301, 0x0202, 1000, 0x5B0287, 500, "confirmed-never", 8)
NODES = [VCU, SBW, ABS]


class Number(udsoncan.DidCodec):
    """A numeric DID, big-endian (struct format), as its raw value."""

    def __init__(self, fmt: str) -> None:
        self.fmt = fmt

    def encode(self, value: int) -> bytes:
        return struct.pack(self.fmt, value)

    def decode(self, data: bytes) -> int:
        return int(struct.unpack(self.fmt, data)[0])

    def __len__(self) -> int:
        return struct.calcsize(self.fmt)


def documented_key(seed: int, constant: int) -> int:
    """DIAG-SEC-01: key = rotl32(seed XOR C, 7) XOR 0xA5A5A5A5 (the worked example is checked below)."""
    x = (seed ^ constant) & 0xFFFFFFFF
    return (((x << 7) | (x >> 25)) & 0xFFFFFFFF) ^ 0xA5A5A5A5


def private_group() -> str:
    """An unused multicast group of our own (the examples and the tester limit their sockets to it)."""
    rng = random.Random(os.getpid() * 1_000_003 + time.monotonic_ns())
    return f"239.255.{rng.randint(100, 250)}.{rng.randint(1, 254)}"


def own_group_only(bus: Any) -> None:
    """README "Pointing it at a bus": IP_MULTICAST_ALL = 0 on python-can's udp_multicast socket."""
    sock = bus._multicast._socket
    sock.setsockopt(socket.IPPROTO_IP, 49, 0)
    if sock.family == socket.AF_INET6:
        sock.setsockopt(socket.IPPROTO_IPV6, 29, 0)


class UdsTester:
    """udsoncan's client over can-isotp on the example's group, plus raw access for the NRC checks."""

    def __init__(self, node: Node, channel: str) -> None:
        self.node = node
        self.process: subprocess.Popen[str] | None = None
        self.bus = can.Bus(interface="udp_multicast", channel=channel, hop_limit=0)
        own_group_only(self.bus)
        self.notifier = can.Notifier(self.bus, [])
        self.pending = 0  # NRC 0x78 seen by the client
        address = isotp.Address(isotp.AddressingMode.Normal_11bits, txid=node.request, rxid=node.response)
        self.stack = isotp.NotifierBasedCanStack(self.bus, self.notifier, address=address,
                                                 params={"tx_padding": 0xCC, "tx_data_min_length": 8,
                                                         "blocksize": 0, "stmin": 0})
        config = dict(udsoncan.configs.default_client_config)
        config.update({
            "data_identifiers": {**{did: udsoncan.AsciiCodec(n) for did, n in IDENTIFICATION.items()},
                                 0xDD00: Number(">I"), **{did: Number(f) for did, f in node.coding.items()}},
            "security_algo": lambda level, seed, params: documented_key(
                int.from_bytes(seed, "big"), node.constant).to_bytes(4, "big"),
            "nrc78_callback": self._on_pending, "p2_timeout": 0.3, "p2_star_timeout": 2.5,
            "use_server_timing": False,
        })
        self.client = Client(PythonIsoTpConnection(self.stack), config=config, request_timeout=6)
        self.client.open()

    def _on_pending(self) -> None:
        self.pending += 1

    def close(self) -> None:
        self.client.close()
        self.notifier.stop()
        self.bus.shutdown()

    def raw(self, hexstring: str, timeout: float = 0.5) -> bytes | None:
        """One physical request; the first response (None: none within `timeout`)."""
        self.client.conn.empty_rxqueue()
        self.client.conn.send(bytes.fromhex(hexstring.replace(" ", "")))
        frame = self.client.conn.wait_frame(timeout=timeout, exception=False)
        return None if frame is None else bytes(frame)

    def functional(self, hexstring: str, timeout: float = 0.3) -> bytes | None:
        """One functional request (a single frame on 0x7DF, padded); the node's answer on its response id."""
        payload = bytes.fromhex(hexstring.replace(" ", ""))
        self.client.conn.empty_rxqueue()
        data = bytes([len(payload)]) + payload
        self.bus.send(can.Message(arbitration_id=FUNCTIONAL, data=data.ljust(8, b"\xCC"), is_extended_id=False))
        frame = self.client.conn.wait_frame(timeout=timeout, exception=False)
        return None if frame is None else bytes(frame)

    def nrc(self, hexstring: str) -> int | None:
        response = self.raw(hexstring)
        assert response is not None, f"{self.node.name}: no response to {hexstring}"
        return response[2] if response[0] == 0x7F and response[1] == int(hexstring[:2], 16) else None

    def unlock(self) -> None:
        self.client.change_session(3)
        self.client.unlock_security_access(1)

    def dtcs(self, mask: int = 0xFF) -> dict[int, int]:
        response = self.raw(f"1902{mask:02X}")
        assert response is not None and response[:3] == bytes([0x59, 0x02, 0xFF]), response
        return {int.from_bytes(response[i:i + 3], "big"): response[i + 3] for i in range(3, len(response), 4)}

    def snapshot(self, dtc: int) -> bytes:
        response = self.raw(f"1904{dtc:06X}01")
        assert response is not None and response[:5] == bytes([0x59, 0x04]) + dtc.to_bytes(3, "big"), response
        return response


@pytest.fixture
def start() -> Iterator[Callable[..., UdsTester]]:
    """Start an example (with extra arguments) on a group of its own; stop it at the end, checking its exit."""
    running: list[tuple[subprocess.Popen[str], UdsTester]] = []

    def _start(node: Node, *args: str) -> UdsTester:
        channel = private_group()
        process = subprocess.Popen([sys.executable, str(ROOT / "examples" / node.script), "--interface",
                                    "udp_multicast", "--channel", channel, *args], cwd=ROOT,
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        first = process.stdout.readline() if process.stdout else ""
        assert "running" in first, f"{node.script}: {first}{process.communicate(timeout=5)[0]}"
        tester = UdsTester(node, channel)
        tester.process = process
        running.append((process, tester))
        return tester

    yield _start
    for process, tester in running:
        stop(process, tester)


def stop(process: subprocess.Popen[str], tester: UdsTester) -> None:
    """SIGTERM: the example stops within a second, exit 0, no traceback."""
    if process.returncode is not None:
        return
    tester.close()
    process.send_signal(signal.SIGTERM)
    output = process.communicate(timeout=10)[0]
    assert process.returncode == 0, output
    assert "Traceback" not in output, output


@pytest.mark.parametrize("node", NODES, ids=lambda n: n.name)
def test_identification_sessions_security_and_nrcs(start: Callable[..., UdsTester], node: Node) -> None:
    """DIAG-ID-01, DIAG-SES-01/03, DIAG-SEC-01/02, DIAG-NRC-01..03: identification, sessions, the documented
    seed/key with the attempt counter, NRCs in their precedence, functional addressing and the SPRMIB."""
    assert documented_key(0x12345678, 0x53425701) == 0x1EA51905  # the worked example of DIAG-SEC-01
    tester = start(node)
    client = tester.client
    for did, length in IDENTIFICATION.items():  # exactly `length` printable ASCII characters
        text = client.read_data_by_identifier(did).service_data.values[did]
        assert len(text) == length and all(0x20 <= ord(c) <= 0x7E for c in text), (hex(did), text)
    first = client.read_data_by_identifier(0xDD00).service_data.values[0xDD00]  # OperatingTime, ms
    time.sleep(0.2)
    assert 150 <= client.read_data_by_identifier(0xDD00).service_data.values[0xDD00] - first <= 2000
    # a segmented request and response: four DIDs in one read, in the order requested
    response = tester.raw("22F195F187F190F18C")
    assert response is not None and response[0] == 0x62 and len(response) == 1 + 4 * 2 + 8 + 10 + 17 + 12
    assert [response[i:i + 2].hex() for i in (1, 11, 23, 42)] == ["f195", "f187", "f190", "f18c"]
    # NRCs in the order of DIAG-NRC-01
    assert tester.nrc("85") == 0x11                                  # unknown SID
    assert tester.nrc("2EFDC001") == 0x7F                             # 0x2E in the default session
    assert tester.nrc(f"3101{node.routine:04X}") == 0x7F              # 0x31 in the default session
    assert tester.nrc("2701") == 0x7F                                 # 0x27 in the default session
    assert tester.nrc("1002") == 0x12 and tester.nrc("1102") == 0x12 and tester.nrc("3E01") == 0x12
    assert tester.nrc("100300") == 0x13                               # 0x10 with a byte too many
    assert tester.nrc("22F1") == 0x13 and tester.nrc("22F190F1") == 0x13 and tester.nrc("22FFFF") == 0x31
    assert tester.nrc("1982FF") == 0x12 and tester.nrc("1902") == 0x13 and tester.nrc("14FFFF") == 0x13
    assert tester.nrc("14123456") == 0x31 and tester.nrc("190412345601") == 0x31
    assert tester.nrc(f"1904{node.dtc:06X}02") == 0x31                # record 0x02 does not exist
    assert tester.raw("3E00") == b"\x7e\x00" and tester.raw("3E80", timeout=0.2) is None
    # functional addressing: answered on the physical response id, silent for 0x11/0x12/0x31/0x7F, SPRMIB
    assert tester.functional("22F190")[:3] == b"\x62\xf1\x90"  # type: ignore[index]
    assert tester.functional("85") is None and tester.functional("2701") is None
    assert tester.functional("1083") is None                         # extended session, silently
    assert tester.raw("2701")[:2] == b"\x67\x01"  # type: ignore[index] # a seed: 0x27 is served, so extended
    # sessions: 10 03 -> 50 03 00 32 00 C8 (P2 50 ms, P2* 200 x 10 ms)
    assert tester.raw("1003") == bytes.fromhex("5003003200C8")
    assert tester.nrc("2EFDC001") == (0x31 if node is ABS else 0x33)  # not a coding DID (ABS) / locked
    # security: wrong keys count in a row, the third gets 0x36 and starts the delay (0x37); a reset ends it
    for expected in (0x35, 0x35, 0x36):
        seed = tester.raw("2701")
        assert seed is not None and seed[:2] == b"\x67\x01" and int.from_bytes(seed[2:6], "big") != 0
        wrong = documented_key(int.from_bytes(seed[2:6], "big"), node.constant) ^ 0x1
        assert tester.nrc(f"2702{wrong:08X}") == expected
    assert tester.nrc("2701") == 0x37 and tester.nrc("270200000000") == 0x24
    assert tester.raw("1101") == b"\x51\x01"                          # ECUReset: default session, delay cleared
    time.sleep(0.15)
    assert tester.nrc("2701") == 0x7F
    tester.unlock()                                                    # the documented key opens it
    assert tester.raw("2701") == bytes.fromhex("670100000000")        # unlocked: seed 0
    assert tester.nrc("270200000000") == 0x24                         # no seed awaits a key
    assert tester.raw("1001") is not None and tester.raw("1003") is not None
    assert tester.nrc(f"3101{node.routine:04X}") == 0x33              # every session change locks again


@pytest.mark.parametrize("node", NODES, ids=lambda n: n.name)
def test_coding_routine_reset_and_fault_memory(start: Callable[..., UdsTester], node: Node) -> None:
    """DIAG-COD-01, DIAG-SVC-03, DIAG-RST-*, DIAG-DTC-*: coding written and read back (kept over a reset), the
    routine with NRC 0x78 while it runs and 0x21 to anything else, the fault memory of the example's own fault."""
    tester = start(node)
    client = tester.client
    assert tester.nrc(f"3103{node.routine:04X}") == 0x7F
    tester.unlock()
    # coding: written, read back, refused when out of range or an optional function the example lacks
    if node is VCU:
        assert client.read_data_by_identifier(0xFDC0).service_data.values[0xFDC0] == 1  # FEEDFORWARD, delivered
        client.write_data_by_identifier(0xFDC0, 0)                                        # OFF
        assert tester.nrc("2EFDC003") == 0x31 and tester.nrc("2EFDC0") == 0x13
    elif node is SBW:
        assert client.read_data_by_identifier(0xFDC0).service_data.values[0xFDC0] == 0  # DIRECT, delivered
        client.write_data_by_identifier(0xFDC0, 1)                                        # YAW_RATE
        client.write_data_by_identifier(0xFDC1, 3500)                                     # G_r 0.35 1/s
        assert tester.nrc("2EFDC002") == 0x31                   # YAW_RATE_LAT_ACCEL: not in this SBW
        assert tester.nrc("2EFDC11389") == 0x31 and tester.nrc("2EFDC101F3") == 0x31  # 0.5001 and 0.0499 1/s
        assert tester.nrc("2EFDC100") == 0x13
    else:
        assert tester.nrc("2EF19041") == 0x31                   # the ABS has no coding; identification is read only
    assert tester.nrc("2EF18741") == 0x31
    # the routine: 0x78 at once, 0x21 to another request meanwhile, UdsTesterPresent answered, the final response
    assert tester.nrc(f"3103{node.routine:04X}") == 0x24                  # not started in this cycle
    assert tester.nrc("31010FFF") == 0x31 and tester.nrc("3102" + f"{node.routine:04X}") == 0x12
    t0 = time.monotonic()
    tester.client.conn.empty_rxqueue()
    tester.client.conn.send(bytes.fromhex(f"3101{node.routine:04X}"))
    assert tester.client.conn.wait_frame(timeout=0.2) == b"\x7f\x31\x78"
    assert tester.raw("22F190") == b"\x7f\x22\x21"
    assert tester.raw("3E00") == b"\x7e\x00"
    final = None
    while time.monotonic() - t0 < node.routine_ms / 1000.0 + 1.0:
        frame = tester.client.conn.wait_frame(timeout=0.3, exception=False)
        if frame is not None and bytes(frame) != b"\x7f\x31\x78":
            final = bytes(frame)
            break
    elapsed = time.monotonic() - t0
    assert final == bytes([0x71, 0x01]) + node.routine.to_bytes(2, "big")
    assert node.routine_ms / 1000.0 - 0.01 <= elapsed <= node.routine_ms / 1000.0 + 0.15, elapsed
    tester.pending = 0
    client.start_routine(node.routine)                                        # udsoncan sees the 0x78 too
    assert tester.pending >= 1 + (node.routine_ms >= 1000)
    assert tester.raw(f"3103{node.routine:04X}") == bytes([0x71, 0x03]) + node.routine.to_bytes(2, "big")
    # the fault memory: the example's own fault, failing and confirmed after confirm_ms
    time.sleep(node.confirm_ms / 1000.0 + 0.1)
    assert tester.dtcs() == {node.dtc: 0xAF}
    assert tester.raw(f"1906{node.dtc:06X}01") == bytes([0x59, 0x06]) + node.dtc.to_bytes(3, "big") + b"\xaf\x01\x01"
    number = tester.raw("190109")
    assert number is not None and number[:4] == bytes.fromhex("5901FF01") and number[4:] == b"\x00\x01"
    record = tester.snapshot(node.dtc)
    assert record[5] == 0xAF and record[6:8] == bytes([0x01, node.snapshot_dids]) and record[8:10] == b"\xdd\x00"
    # ECUReset: coding kept, session and security back to default, a new operation cycle, fault memory kept
    assert tester.raw("1101") == b"\x51\x01"
    assert tester.dtcs()[node.dtc] == 0xED   # bit 6 set, bit 1 cleared; start-up: no result yet (bit 0 kept)
    assert tester.nrc("2EFDC001") == 0x7F and tester.nrc(f"3103{node.routine:04X}") == 0x7F
    if node is VCU:
        assert client.read_data_by_identifier(0xFDC0).service_data.values[0xFDC0] == 0
    elif node is SBW:
        values = client.read_data_by_identifier([0xFDC0, 0xFDC1]).service_data.values
        assert values == {0xFDC0: 1, 0xFDC1: 3500}
    time.sleep(0.2)
    assert tester.dtcs()[node.dtc] == 0xAF                # still failing: the same occurrence, confirmed
    # clear: 0x50 at once, then a new first occurrence
    assert tester.raw("14FFFFFF") == b"\x54"
    status = tester.dtcs()[node.dtc]
    assert status in (0x50, 0x27), hex(status)           # 0x50 until the next step, then failing anew
    time.sleep(0.05)
    assert tester.raw(f"1906{node.dtc:06X}FF") == bytes([0x59, 0x06]) + node.dtc.to_bytes(3, "big") + b"\x27\x01\x01"


def defect_visible(node: Node, tester: UdsTester) -> bool:
    """The contract check each defect fails: True when the example answers as the contract says."""
    if node is SBW:  # DIAG-NRC-01: the session check (0x7F) comes before the security check (0x33)
        return tester.nrc("2EFDC001") == 0x7F and tester.nrc(f"3101{node.routine:04X}") == 0x7F
    if node is ABS:  # DIAG-DTC-04: failing for confirm_ms confirms (and requests the warning indicator)
        time.sleep(node.confirm_ms / 1000.0 + 0.15)
        return tester.dtcs().get(node.dtc) == 0xAF
    # VCU, DIAG-DTC-05: the record is the most recent occurrence's (a clear and a new occurrence replace it)
    time.sleep(0.2)
    before = int.from_bytes(tester.snapshot(node.dtc)[10:14], "big")  # OperatingTime, ms
    time.sleep(0.3)
    cleared_at = tester.client.read_data_by_identifier(0xDD00).service_data.values[0xDD00]
    assert tester.raw("14FFFFFF") == b"\x54"
    time.sleep(0.1)
    after = int.from_bytes(tester.snapshot(node.dtc)[10:14], "big")
    return after >= cleared_at > before


@pytest.mark.parametrize("node", NODES, ids=lambda n: n.name)
def test_diag_defect_flag_is_caught(start: Callable[..., UdsTester], node: Node) -> None:
    """Each example's --diag-defect breaks one contract check that passes without it."""
    assert defect_visible(node, start(node)), f"{node.name} without --diag-defect"
    assert not defect_visible(node, start(node, "--diag-defect", node.defect)), f"{node.name} {node.defect}"


def test_s3_timeout_and_tester_present(start: Callable[..., UdsTester]) -> None:
    """DIAG-SES-03: functional `3E 80` at least every 4 s keeps the extended session silently; without any request
    for more than S3 = 5 s the node is back in the default session and locked."""
    tester = start(SBW)
    tester.unlock()
    for _ in range(2):
        time.sleep(2.5)
        assert tester.functional("3E80", timeout=0.05) is None
    time.sleep(2.5)
    assert tester.nrc("2EFDC000") is None                 # still extended and unlocked: written (6E FD C0)
    time.sleep(5.3)
    assert tester.nrc("2701") == 0x7F                     # S3 expired: default session


def test_nvm_keeps_coding_and_fault_memory_over_a_power_cycle(start: Callable[..., UdsTester], tmp_path: Any) -> None:
    """DIAG-COD-01 / DIAG-DTC-05 with `--nvm FILE`: a process restart is a power cycle; the coding and the fault
    memory survive it and a new operation cycle begins (bit 6 set, bit 1 cleared until the first result)."""
    nvm = tmp_path / "sbw.json"
    tester = start(SBW, "--nvm", str(nvm))
    tester.unlock()
    tester.client.write_data_by_identifier(0xFDC1, 2000)  # G_r 0.2 1/s
    time.sleep(SBW.confirm_ms / 1000.0 + 0.1)
    assert tester.dtcs() == {SBW.dtc: 0xAF}
    assert tester.process is not None
    stop(tester.process, tester)                          # power-down: the file is saved
    again = start(SBW, "--nvm", str(nvm))
    assert again.client.read_data_by_identifier(0xFDC1).service_data.values[0xFDC1] == 2000
    assert again.dtcs()[SBW.dtc] in (0xED, 0xAF)          # kept; a new cycle (0xED until its first result)
    assert again.raw(f"1906{SBW.dtc:06X}01")[-1] == 1     # type: ignore[index] # the same occurrence
