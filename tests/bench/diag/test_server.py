"""The UDS server, driven by udsoncan's client (an independent parser of every response) over the bench's ISO-TP
on a fake clock; `handle` directly for what no client sends (a second request while one is pending)."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import udsoncan
from udsoncan import AsciiCodec, DidCodec, Response
from udsoncan.client import Client
from udsoncan.connections import BaseConnection
from udsoncan.exceptions import NegativeResponseException, TimeoutException

import bench.diag.server as server_module
from bench.diag.declaration import Declaration, NodeDiagnostics, dtc_number, load_declaration
from bench.diag.isotp import IsoTpEndpoint, IsoTpParams
from bench.diag.server import UdsServer
from tests.repo import DBC_DIR

DECLARATION = """\
[protocol]
functional_request = 0x7DF
p2_ms = 50
p2_star_ms = 2000
s3_ms = 5000
security_attempts = 3
security_delay_ms = 10000
aging_cycles = 3
healing_cycles = 1

[[identification]]
id = 0xF190
name = "VIN"
type = "ascii"
length = 17

[[identification]]
id = 0xF195
name = "SoftwareVersion"
type = "ascii"
length = 8

[[snapshot]]
id = 0xDD01
name = "VehicleSpeed"
type = "uint16"
scale = 0.01
unit = "km/h"

[[snapshot]]
id = 0xDD02
name = "SupplyVoltage"
type = "uint8"
scale = 0.1
unit = "V"

[nodes.ECU]
request = 0x7E0
response = 0x7E8
security_constant = 0x1234ABCD
identification = { VIN = "WBA00000000000001", SoftwareVersion = "1.2.3" }
snapshot = [0xDD01, 0xDD02]

[[nodes.ECU.did]]
id = 0x0101
name = "SteeringAngle"
type = "int16"
scale = 0.1
unit = "deg"

[[nodes.ECU.did]]
id = 0x0102
name = "Unprovided"
type = "uint8"

[[nodes.ECU.did]]
id = 0x0201
name = "MaxAngle"
type = "uint16"
scale = 0.1
write = true
default = 45.0
min = 10.0
max = 90.0

[[nodes.ECU.did]]
id = 0x0202
name = "Variant"
type = "uint8"
write = true
default = 1
values = { SEDAN = 1, WAGON = 2 }

[[nodes.ECU.dtc]]
code = "C1A01-1C"
name = "SENSOR_FAULT"
text = "sensor out of range"
requirement = "REQ-1"
confirm_ms = 0

[[nodes.ECU.dtc]]
code = "U0100-87"
name = "LOST"
text = "message missing"
requirement = "REQ-2"
confirm_ms = 500
warning_indicator = false

[[nodes.ECU.routine]]
id = 0x0203
name = "Calibrate"
duration_ms = 3000

[[nodes.ECU.routine]]
id = 0x0204
name = "Quick"
duration_ms = 0
"""

CONSTANT = 0x1234ABCD
SENSOR = dtc_number("C1A01-1C")
LOST = dtc_number("U0100-87")
CODECS: dict[int, Any] = {
    0xF190: AsciiCodec(17), 0xF195: AsciiCodec(8), 0xDD01: DidCodec(">H"), 0xDD02: DidCodec(">B"),
    0x0101: DidCodec(">h"), 0x0102: DidCodec(">B"), 0x0201: DidCodec(">H"), 0x0202: DidCodec(">B"),
    0xBEEF: DidCodec(">B"),
}


def documented_key(seed: bytes, constant: int = CONSTANT) -> bytes:
    """DIAG-SEC-01 written out from its formula: rotl32(seed ^ constant, 7) ^ 0xA5A5A5A5, 4 bytes big-endian."""
    x = int.from_bytes(seed, "big") ^ constant
    x = ((x << 7) | (x >> 25)) & 0xFFFFFFFF
    return (x ^ 0xA5A5A5A5).to_bytes(4, "big")


def test_the_key_formula_of_this_module_gives_the_contract_s_worked_example() -> None:
    assert documented_key(bytes.fromhex("12345678"), 0x53425701) == bytes.fromhex("1EA51905")   # DIAG-SEC-01


class Bus:
    """CAN between the tester's ISO-TP and the server on a fake clock: frames in order, 1 ms a step, everything with
    timers polled while busy (as the station does)."""

    def __init__(self) -> None:
        self.ms = 0
        self.queue: deque[tuple[int, bytes]] = deque()
        self.log: list[tuple[float, int, bytes]] = []
        self.listeners: list[tuple[int, Callable[[float, int, bytes], None]]] = []
        self.pollers: list[Any] = []

    @property
    def t(self) -> float:
        return self.ms / 1000

    def send(self, frame_id: int, data: bytes) -> None:
        self.queue.append((frame_id, bytes(data)))
        self.log.append((self.t, frame_id, bytes(data)))

    def deliver(self) -> None:
        while self.queue:
            frame_id, data = self.queue.popleft()
            for wanted, listener in self.listeners:
                if wanted == frame_id:
                    listener(self.t, frame_id, data)

    def step(self) -> None:
        self.deliver()
        for poller in self.pollers:
            if poller.busy:
                poller.poll(self.t)
        self.deliver()
        self.ms += 1

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds * 1000)):
            self.step()

    def frames(self, frame_id: int, since: float = 0.0) -> list[tuple[float, bytes]]:
        return [(t, data) for t, i, data in self.log if i == frame_id and t >= since]


class Wire(BaseConnection):
    """udsoncan's connection: the tester's ISO-TP endpoint on the bus (or a functional single frame); a wait
    steps the fake clock."""

    def __init__(self, bus: Bus, node: NodeDiagnostics, functional_id: int) -> None:
        super().__init__("test")
        self.bus, self.functional_id = bus, functional_id
        self.endpoint = IsoTpEndpoint(node.request, node.response, bus.send, IsoTpParams())
        self.functional = False
        self.opened = False
        bus.listeners.append((node.response, lambda t, i, data: self.endpoint.on_frame(t, data)))
        bus.pollers.append(self.endpoint)

    def open(self) -> Wire:
        self.opened = True
        return self

    def close(self) -> None:
        self.opened = False

    def is_open(self) -> bool:
        return self.opened

    def empty_rxqueue(self) -> None:
        self.endpoint.received.clear()

    def specific_send(self, payload: bytes, timeout: float | None = None) -> None:
        if self.functional:
            assert len(payload) <= 7
            self.bus.send(self.functional_id, (bytes([len(payload)]) + payload).ljust(8, b"\xCC"))
        else:
            self.endpoint.transmit(self.bus.t, payload)

    def specific_wait_frame(self, timeout: float | None = None) -> bytes | None:
        end = self.bus.ms + round((5.0 if timeout is None else timeout) * 1000)
        received = self.endpoint.received
        while not received and self.bus.ms < end:
            self.bus.step()
        return received.popleft()[1] if received else None


@dataclass
class Rig:
    declaration: Declaration
    node: NodeDiagnostics
    bus: Bus
    server: UdsServer
    wire: Wire
    client: Client

    def response_frames(self, since: float) -> list[bytes]:
        return [data for _, data in self.bus.frames(self.node.response, since)]


@pytest.fixture
def declaration(tmp_path: Path) -> Declaration:
    path = tmp_path / "diagnostics.toml"
    path.write_text(DECLARATION, encoding="utf-8")
    return load_declaration(path)


def make_rig(declaration: Declaration) -> Rig:
    node = declaration.node("ECU")
    bus = Bus()
    server = UdsServer(node, declaration.protocol, bus.send)
    for frame_id in server.frame_ids:
        bus.listeners.append((frame_id, server.on_frame))
    bus.pollers.append(server)
    wire = Wire(bus, node, declaration.protocol.functional_request)
    config: dict[str, Any] = dict(udsoncan.configs.default_client_config)
    config.update({
        "data_identifiers": CODECS,
        "security_algo": lambda level, seed, params=None: documented_key(seed),
        "request_timeout": None, "p2_timeout": 0.2, "p2_star_timeout": 2.5, "use_server_timing": False,
        "standard_version": 2013, "dtc_snapshot_did_size": 2, "extended_data_size": 1,
    })
    client = Client(wire, config=config)
    client.open()
    return Rig(declaration, node, bus, server, wire, client)


@pytest.fixture
def rig(declaration: Declaration) -> Iterator[Rig]:
    rig = make_rig(declaration)
    yield rig
    assert rig.server.endpoint.problems == [] and rig.wire.endpoint.problems == []


def nrc(call: Callable[[], Any]) -> int:
    """The NRC udsoncan parsed from the server's negative response to the call."""
    with pytest.raises(NegativeResponseException) as info:
        call()
    code = info.value.response.code
    assert isinstance(code, int)
    return code


def raw_nrc(client: Client, payload: bytes, call: Callable[[], Any]) -> int:
    """The NRC to a request of these exact bytes (the call is a client call of the same service)."""
    with client.payload_override(payload):
        return nrc(call)


def unlock(client: Client) -> None:
    client.change_session(3)
    client.unlock_security_access(1)


def keep_alive(rig: Rig, seconds: float) -> None:
    """Let fake time pass in a non-default session, with TesterPresent every second (S3 is 5 s)."""
    end = rig.bus.ms + round(seconds * 1000)
    while rig.bus.ms < end:
        rig.client.tester_present()
        rig.bus.run(min(1.0, (end - rig.bus.ms) / 1000))


# -- the API -----------------------------------------------------------------------------------------------------
def test_frame_ids_busy_and_the_behaviour_side(rig: Rig) -> None:
    server = rig.server
    assert server.frame_ids == (0x7E0, 0x7DF)
    assert not server.busy
    assert server.report == server.memory.report
    server.report(0.0, "SENSOR_FAULT")
    assert server.memory.status(SENSOR) == 0xAF
    assert server.coding("MaxAngle") == 45.0 and server.coding("Variant") == 1.0
    with pytest.raises(KeyError, match=r"ECU: no DID 'Nope' \(DIDs: 0xF190 VIN, "):
        server.provide("Nope", lambda: 1.0)
    with pytest.raises(KeyError, match="ECU: no coding DID 'SteeringAngle' .*MaxAngle, Variant"):
        server.coding("SteeringAngle")
    with pytest.raises(KeyError, match="ECU: no routine 'Nope'.*0x0203 Calibrate"):
        server.on_routine("Nope", lambda: None)
    rig.client.change_session(3)
    assert server.busy and server.session == 3     # S3 runs: poll is needed


def test_the_same_node_name_gives_the_same_nonzero_seeds(declaration: Declaration) -> None:
    seeds = []
    for _ in range(2):
        rig = make_rig(declaration)
        rig.client.change_session(3)
        seeds.append([rig.client.request_seed(1).service_data.seed for _ in range(3)])
    assert seeds[0] == seeds[1]
    assert all(len(s) == 4 and s != b"\0\0\0\0" for s in seeds[0]) and len(set(seeds[0])) == 3


# -- 0x10 and S3 -------------------------------------------------------------------------------------------------
def test_session_control_answers_p2_and_p2_star(rig: Rig) -> None:
    assert rig.server.handle(0.0, b"\x10\x03") == bytes.fromhex("50 03 00 32 00 C8")   # DIAG-SES-01
    response = rig.client.change_session(3)
    assert response.service_data.session_echo == 3
    assert response.service_data.p2_server_max == 0.05 and response.service_data.p2_star_server_max == 2.0
    assert rig.client.change_session(1).service_data.session_echo == 1
    assert nrc(lambda: rig.client.change_session(2)) == 0x12                       # programming: not supported
    assert raw_nrc(rig.client, b"\x10", lambda: rig.client.change_session(3)) == 0x13
    assert raw_nrc(rig.client, b"\x10\x03\x00", lambda: rig.client.change_session(3)) == 0x13


def test_a_session_transition_locks_security(rig: Rig) -> None:
    unlock(rig.client)
    assert rig.server.unlocked
    assert rig.client.request_seed(1).service_data.seed == b"\0\0\0\0"              # already unlocked
    rig.client.change_session(3)                                                     # the same session again
    assert not rig.server.unlocked
    seed = rig.client.request_seed(1).service_data.seed
    assert seed != b"\0\0\0\0"
    rig.client.change_session(3)                                                     # drops the pending seed too
    assert nrc(lambda: rig.client.send_key(2, documented_key(seed))) == 0x24


def test_s3_falls_back_to_the_default_session_and_locks(rig: Rig) -> None:
    unlock(rig.client)
    rig.bus.run(4.9)
    rig.client.tester_present()                                                      # restarts S3
    rig.bus.run(4.9)
    assert rig.server.session == 3 and rig.server.unlocked
    rig.bus.run(0.2)
    assert rig.server.session == 1 and not rig.server.unlocked and not rig.server.busy
    assert nrc(lambda: rig.client.write_data_by_identifier(0x0201, 600)) == 0x7F


# -- NRC precedence ----------------------------------------------------------------------------------------------
def test_unsupported_service_and_service_not_in_session(rig: Rig) -> None:
    assert nrc(lambda: rig.client.control_dtc_setting(1)) == 0x11
    assert nrc(lambda: rig.client.write_data_by_identifier(0x0201, 600)) == 0x7F
    # the session is checked before the length and the sub-function
    assert raw_nrc(rig.client, b"\x2E", lambda: rig.client.write_data_by_identifier(0x0201, 600)) == 0x7F
    assert raw_nrc(rig.client, b"\x27\x05", lambda: rig.client.request_seed(1)) == 0x7F


def test_minimum_length_then_sub_function_then_its_length(rig: Rig) -> None:
    rig.client.change_session(3)
    assert raw_nrc(rig.client, b"\x27", lambda: rig.client.request_seed(1)) == 0x13
    assert raw_nrc(rig.client, b"\x27\x05\x00", lambda: rig.client.request_seed(1)) == 0x12
    assert raw_nrc(rig.client, b"\x27\x02\x00", lambda: rig.client.request_seed(1)) == 0x13   # before 0x24
    assert nrc(lambda: rig.client.request_seed(3)) == 0x12                           # level 1 only


def test_sub_function_not_in_the_active_session_comes_before_its_length(rig: Rig,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    # no sub-function of the decided tables is session-bound; restrict softReset to show the check's place
    monkeypatch.setitem(server_module.SUBFUNCTIONS, 0x11, {0x01: frozenset({1, 3}), 0x03: frozenset({3})})
    assert raw_nrc(rig.client, b"\x11\x03\x00", lambda: rig.client.ecu_reset(3)) == 0x7E
    rig.wire.functional = True
    since = rig.bus.t
    with pytest.raises(TimeoutException):
        rig.client.ecu_reset(3)
    assert rig.response_frames(since) == []


# -- 0x27 --------------------------------------------------------------------------------------------------------
def test_security_access_unlocks_with_the_documented_key(rig: Rig) -> None:
    assert nrc(lambda: rig.client.request_seed(1)) == 0x7F                           # default session
    rig.client.change_session(3)
    seed = rig.client.request_seed(1).service_data.seed
    assert rig.client.send_key(2, documented_key(seed)).positive
    assert rig.server.unlocked


def test_send_key_without_a_seed_is_a_sequence_error(rig: Rig) -> None:
    rig.client.change_session(3)
    assert nrc(lambda: rig.client.send_key(2, b"\0\0\0\0")) == 0x24
    seed = rig.client.request_seed(1).service_data.seed
    assert nrc(lambda: rig.client.send_key(2, bytes(4))) == 0x35
    assert nrc(lambda: rig.client.send_key(2, documented_key(seed))) == 0x24        # a seed answers one key


def test_wrong_keys_count_then_delay_the_next_seed(rig: Rig) -> None:
    rig.client.change_session(3)
    rig.client.set_config("security_algo", lambda level, seed, params=None: bytes(4))
    codes = [nrc(lambda: rig.client.unlock_security_access(1)) for _ in range(3)]
    assert codes == [0x35, 0x35, 0x36]
    assert nrc(lambda: rig.client.request_seed(1)) == 0x37
    keep_alive(rig, 9.8)
    assert nrc(lambda: rig.client.request_seed(1)) == 0x37
    keep_alive(rig, 0.3)                                                             # 10 s since the third key
    # the delay over, the count starts again: a wrong key is one of three again
    assert nrc(lambda: rig.client.unlock_security_access(1)) == 0x35
    rig.client.set_config("security_algo", lambda level, seed, params=None: documented_key(seed))
    rig.client.unlock_security_access(1)
    assert rig.server.unlocked


def test_ecu_reset_clears_the_wrong_key_count_and_the_delay(rig: Rig) -> None:
    rig.client.change_session(3)
    rig.client.set_config("security_algo", lambda level, seed, params=None: bytes(4))
    assert [nrc(lambda: rig.client.unlock_security_access(1)) for _ in range(3)] == [0x35, 0x35, 0x36]
    rig.client.ecu_reset(1)
    rig.bus.run(0.002)
    rig.client.change_session(3)
    assert nrc(lambda: rig.client.unlock_security_access(1)) == 0x35                # a seed, and one of three again


def test_a_session_change_clears_neither_the_count_nor_the_delay(rig: Rig) -> None:
    rig.client.change_session(3)
    rig.client.set_config("security_algo", lambda level, seed, params=None: bytes(4))
    assert [nrc(lambda: rig.client.unlock_security_access(1)) for _ in range(2)] == [0x35, 0x35]
    rig.client.change_session(3)
    assert nrc(lambda: rig.client.unlock_security_access(1)) == 0x36
    rig.client.change_session(1)
    rig.client.change_session(3)
    assert nrc(lambda: rig.client.request_seed(1)) == 0x37


# -- 0x22 and 0x2E -----------------------------------------------------------------------------------------------
def test_read_identification_live_and_coding_dids(rig: Rig) -> None:
    rig.server.provide("SteeringAngle", lambda: -12.3)
    values = rig.client.read_data_by_identifier([0xF190, 0xF195, 0x0101, 0x0201, 0x0202]).service_data.values
    assert values[0xF190] == "WBA00000000000001"
    assert values[0xF195] == "1.2.3   "                       # ASCII padded with spaces to its length
    assert values[0x0101] == (-123,) and values[0x0201] == (450,) and values[0x0202] == (1,)


def test_read_unknown_unprovided_and_valueless_dids(rig: Rig) -> None:
    assert nrc(lambda: rig.client.read_data_by_identifier(0xBEEF)) == 0x31
    assert nrc(lambda: rig.client.read_data_by_identifier(0x0102)) == 0x22   # declared, no value (DIAG-SVC-02)
    rig.server.provide("SteeringAngle", lambda: math.nan)
    assert nrc(lambda: rig.client.read_data_by_identifier(0x0101)) == 0x22
    assert raw_nrc(rig.client, b"\x22\xF1", lambda: rig.client.read_data_by_identifier(0xF190)) == 0x13


def test_read_leaves_out_unsupported_dids_when_one_is_supported_and_saturates(rig: Rig) -> None:
    server = rig.server
    assert server.handle(0.0, b"\x22\xBE\xEF\xF1\x95") == b"\x62\xF1\x95" + b"1.2.3   "
    server.provide("SteeringAngle", lambda: 5000.0)
    assert server.handle(0.0, b"\x22\x01\x01") == b"\x62\x01\x01\x7F\xFF"
    server.provide("SteeringAngle", lambda: -math.inf)
    assert server.handle(0.0, b"\x22\x01\x01") == b"\x62\x01\x01\x80\x00"


def test_a_response_longer_than_iso_tp_carries_is_refused(rig: Rig) -> None:
    response = rig.server.handle(0.0, b"\x22" + b"\xF1\x90" * 230)                 # 1 + 230 * 19 bytes > 4095
    assert response is not None
    parsed = Response.from_payload(response)
    assert not parsed.positive and parsed.code == 0x14
    rig.server.provide("SteeringAngle", lambda: math.nan)                            # the length is checked first
    assert rig.server.handle(0.0, b"\x22\x01\x01" + b"\xF1\x90" * 230) == b"\x7F\x22\x14"


def test_write_coding_in_the_extended_session_unlocked(rig: Rig) -> None:
    client, server = rig.client, rig.server
    client.change_session(3)
    assert nrc(lambda: client.write_data_by_identifier(0x0201, 600)) == 0x33
    assert nrc(lambda: client.write_data_by_identifier(0xBEEF, 1)) == 0x31          # before the security check
    client.unlock_security_access(1)
    assert client.write_data_by_identifier(0x0201, 600).service_data.did_echo == 0x0201
    assert server.coding("MaxAngle") == 60.0
    assert client.read_data_by_identifier(0x0201).service_data.values[0x0201] == (600,)
    assert client.write_data_by_identifier(0x0202, 2).positive
    assert server.coding("Variant") == 2.0


def test_write_refusals(rig: Rig) -> None:
    client = rig.client
    unlock(client)
    assert nrc(lambda: client.write_data_by_identifier(0x0201, 1000)) == 0x31      # 100 deg > max 90
    assert nrc(lambda: client.write_data_by_identifier(0x0201, 50)) == 0x31        # 5 deg < min 10
    assert nrc(lambda: client.write_data_by_identifier(0x0202, 3)) == 0x31         # no enumeration value
    assert nrc(lambda: client.write_data_by_identifier(0x0101, 1)) == 0x31         # live, not coding
    assert nrc(lambda: client.write_data_by_identifier(0xF190, "X" * 17)) == 0x31  # identification
    assert raw_nrc(client, b"\x2E\x02\x01\x02", lambda: client.write_data_by_identifier(0x0201, 600)) == 0x13
    assert rig.server.coding("MaxAngle") == 45.0


# -- 0x19 and 0x14 -----------------------------------------------------------------------------------------------
def test_read_dtc_information_by_status_mask(rig: Rig) -> None:
    client, server = rig.client, rig.server
    assert client.get_number_of_dtc_by_status_mask(0xFF).service_data.dtc_count == 2   # both 0x50: untested
    server.report(rig.bus.t, "SENSOR_FAULT")
    count = client.get_number_of_dtc_by_status_mask(0x08).service_data
    assert count.dtc_count == 1 and count.status_availability.get_byte_as_int() == 0xFF
    assert count.dtc_format == udsoncan.Dtc.Format.ISO14229_1
    assert client.get_number_of_dtc_by_status_mask(0xFF).service_data.dtc_count == 1   # LOST passed: 0x00
    found = client.get_dtc_by_status_mask(0xFF).service_data.dtcs
    assert [(d.id, d.status.get_byte_as_int()) for d in found] == [(SENSOR, 0xAF)]
    assert raw_nrc(client, b"\x19\x02", lambda: client.get_dtc_by_status_mask(0xFF)) == 0x13
    assert nrc(lambda: client.get_supported_dtc()) == 0x12


def test_snapshot_record_of_the_occurrence(rig: Rig) -> None:
    client, server = rig.client, rig.server
    server.provide("VehicleSpeed", lambda: 87.5)
    server.provide("SupplyVoltage", lambda: 13.2)
    server.report(rig.bus.t, "SENSOR_FAULT")
    for record in (0x01, 0xFF):
        dtc = client.get_dtc_snapshot_by_dtc_number(SENSOR, record_number=record).service_data.dtcs[0]
        assert dtc.id == SENSOR and dtc.status.get_byte_as_int() == 0xAF
        assert [(s.record_number, s.did, s.data) for s in dtc.snapshots] == [(1, 0xDD01, (8750,)),
                                                                             (1, 0xDD02, (132,))]
    without = client.get_dtc_snapshot_by_dtc_number(LOST, record_number=1).service_data.dtcs[0]
    assert without.id == LOST and without.snapshots == []
    assert nrc(lambda: client.get_dtc_snapshot_by_dtc_number(0x123456, 1)) == 0x31
    assert nrc(lambda: client.get_dtc_snapshot_by_dtc_number(SENSOR, 2)) == 0x31


def test_extended_data_record_is_the_occurrence_counter(rig: Rig) -> None:
    client, server = rig.client, rig.server
    for t in (0.0, 0.1, 0.2):
        server.report(t, "SENSOR_FAULT")
        server.report(t + 0.05)
    for record in (0x01, 0xFF):
        dtc = client.get_dtc_extended_data_by_dtc_number(SENSOR, record, data_size=1).service_data.dtcs[0]
        assert dtc.status.get_byte_as_int() == 0xAE
        assert [(e.record_number, e.raw_data) for e in dtc.extended_data] == [(1, b"\x03")]
    assert nrc(lambda: client.get_dtc_extended_data_by_dtc_number(0x123456, 1, data_size=1)) == 0x31
    assert nrc(lambda: client.get_dtc_extended_data_by_dtc_number(SENSOR, 2, data_size=1)) == 0x31


def test_clear_dtcs(rig: Rig) -> None:
    client, server = rig.client, rig.server
    server.report(0.0, "SENSOR_FAULT", "LOST")
    assert client.clear_dtc(SENSOR).positive
    assert server.memory.status(SENSOR) == 0x50 and server.memory.status(LOST) == 0x27
    assert nrc(lambda: client.clear_dtc(0x123456)) == 0x31
    assert raw_nrc(client, b"\x14\xFF\xFF", lambda: client.clear_dtc()) == 0x13
    assert client.clear_dtc().positive
    statuses = client.get_dtc_by_status_mask(0xFF).service_data.dtcs
    assert [(d.id, d.status.get_byte_as_int()) for d in statuses] == [(SENSOR, 0x50), (LOST, 0x50)]


# -- 0x31 --------------------------------------------------------------------------------------------------------
def test_a_routine_answers_pending_within_every_second_then_positive(rig: Rig) -> None:
    client = rig.client
    started: list[float] = []
    rig.server.on_routine("Calibrate", lambda: started.append(rig.bus.t))
    pending: list[float] = []
    client.set_config("nrc78_callback", lambda: pending.append(rig.bus.t))
    unlock(client)
    assert nrc(lambda: client.get_routine_result(0x0203)) == 0x24                   # before any start
    since = rig.bus.t
    response = client.start_routine(0x0203)
    assert response.service_data.control_type_echo == 1 and response.service_data.routine_id_echo == 0x0203
    assert len(started) == 1 and len(pending) == 4
    frames = rig.bus.frames(rig.node.response, since)
    t0 = frames[0][0]
    assert [(round(t - t0, 3), data[:5]) for t, data in frames] == [
        (0.0, b"\x03\x7F\x31\x78\xCC"), (0.9, b"\x03\x7F\x31\x78\xCC"), (1.8, b"\x03\x7F\x31\x78\xCC"),
        (2.7, b"\x03\x7F\x31\x78\xCC"), (3.0, b"\x04\x71\x01\x02\x03")]
    assert client.get_routine_result(0x0203).service_data.routine_id_echo == 0x0203


def test_a_request_while_a_routine_runs_is_busy(rig: Rig) -> None:
    unlock(rig.client)
    server, t = rig.server, rig.bus.t
    assert server.handle(t, b"\x31\x01\x02\x03") == b"\x7F\x31\x78"
    for request in (b"\x22\xF1\x90", b"\x31\x01\x02\x03", b"\x10\x01", b"\x85\x01"):   # first of all checks
        response = server.handle(t + 0.5, request, functional=request[0] == 0x85)
        assert response is not None
        parsed = Response.from_payload(response)
        assert parsed.service is not None and parsed.service.request_id() == request[0]
        assert not parsed.positive and parsed.code == 0x21
    assert server.handle(t + 0.5, b"\x3E\x00") == b"\x7E\x00"                        # keeps the session
    since = rig.bus.t
    rig.bus.run(3.1)
    assert b"\x04\x71\x01\x02\x03" in [data[:5] for data in rig.response_frames(since)]
    assert server.handle(rig.bus.t, b"\x22\xF1\x95") == b"\x62\xF1\x95" + b"1.2.3   "


def test_routine_refusals_and_an_instant_routine(rig: Rig) -> None:
    client = rig.client
    assert nrc(lambda: client.start_routine(0x0204)) == 0x7F                        # default session
    client.change_session(3)
    assert nrc(lambda: client.start_routine(0x9999)) == 0x31                        # unknown, before security
    assert nrc(lambda: client.start_routine(0x0204)) == 0x33
    client.unlock_security_access(1)
    assert nrc(lambda: client.stop_routine(0x0204)) == 0x12
    assert raw_nrc(client, b"\x31\x01\x02", lambda: client.start_routine(0x0204)) == 0x13
    pending: list[float] = []
    client.set_config("nrc78_callback", lambda: pending.append(rig.bus.t))
    assert client.start_routine(0x0204).service_data.routine_id_echo == 0x0204 and pending == []
    assert client.get_routine_result(0x0204).positive


# -- 0x11 and 0x3E -----------------------------------------------------------------------------------------------
def test_ecu_reset_restarts_the_node_but_keeps_coding_and_fault_memory(rig: Rig) -> None:
    client, server = rig.client, rig.server
    resets: list[float] = []
    server.on_reset(lambda: resets.append(rig.bus.t))
    unlock(client)
    client.write_data_by_identifier(0x0201, 600)
    server.report(rig.bus.t, "SENSOR_FAULT")
    assert client.ecu_reset(1).service_data.reset_type_echo == 1
    rig.bus.run(0.002)
    assert len(resets) == 1 and server.session == 1 and not server.unlocked
    assert server.coding("MaxAngle") == 60.0
    # a new operation cycle: TFTOC cleared, TNCTOC set; still failed, pending and confirmed
    assert server.memory.status(SENSOR) == 0xED
    assert client.ecu_reset(3).service_data.reset_type_echo == 3
    assert nrc(lambda: client.ecu_reset(2)) == 0x12


def test_tester_present(rig: Rig) -> None:
    assert rig.client.tester_present().positive
    assert raw_nrc(rig.client, b"\x3E\x00\x00", lambda: rig.client.tester_present()) == 0x13
    assert raw_nrc(rig.client, b"\x3E\x01", lambda: rig.client.tester_present()) == 0x12


# -- SPRMIB and functional requests ------------------------------------------------------------------------------
def test_suppressed_positive_responses_and_nrcs_still_sent(rig: Rig) -> None:
    client, server = rig.client, rig.server
    resets: list[float] = []
    server.on_reset(lambda: resets.append(rig.bus.t))
    since = rig.bus.t
    with client.suppress_positive_response:
        assert client.change_session(3) is None
        assert client.tester_present() is None
        assert client.ecu_reset(1) is None
    rig.bus.run(0.1)
    assert rig.response_frames(since) == []
    assert len(resets) == 1
    with client.suppress_positive_response(wait_nrc=True):
        assert nrc(lambda: client.change_session(2)) == 0x12


def test_functional_requests_leave_out_the_silent_nrcs(rig: Rig) -> None:
    client = rig.client
    rig.wire.functional = True
    assert client.tester_present().positive
    since = rig.bus.t
    silent: list[Callable[[], Any]] = [
        lambda: client.control_dtc_setting(1),              # 0x11
        lambda: client.write_data_by_identifier(0x0201, 600),   # 0x7F
        lambda: client.change_session(2),                   # 0x12
        lambda: client.read_data_by_identifier(0xBEEF),     # 0x31
    ]
    for call in silent:
        with pytest.raises(TimeoutException):
            call()
    assert rig.response_frames(since) == []
    assert raw_nrc(client, b"\x10", lambda: client.change_session(1)) == 0x13        # other NRCs are sent
    with client.suppress_positive_response:
        client.tester_present()
    rig.bus.run(0.1)
    assert len(rig.response_frames(since)) == 1
    rig.bus.send(0x7DF, b"\x10\x0A\x22\xF1\x90\xF1\x95\xF1")                        # a first frame: ignored
    rig.bus.run(0.1)
    assert len(rig.response_frames(since)) == 1
    assert client.read_data_by_identifier(0xF195).service_data.values[0xF195] == "1.2.3   "


# -- the project's own declaration ---------------------------------------------------------------------------------
PROJECT = DBC_DIR / "diagnostics.toml"


@pytest.mark.skipif(not PROJECT.exists(), reason="dbc/diagnostics.toml not written yet")
def test_every_node_of_the_project_declaration_serves_its_basics() -> None:
    declaration = load_declaration(PROJECT)
    for node in declaration.nodes.values():
        server = UdsServer(node, declaration.protocol, lambda frame_id, data: None)
        assert server.handle(0.0, b"\x19\x01\xFF") == bytes([0x59, 0x01, 0xFF, 0x01, 0, len(node.dtcs)])
        for name in node.identification:
            did = node.did(name)
            response = server.handle(0.0, b"\x22" + did.id.to_bytes(2, "big"))
            assert response is not None and response[:3] == b"\x62" + did.id.to_bytes(2, "big"), name
        server.report(0.0, *(d.name for d in node.dtcs))
        for dtc in node.dtcs:
            response = server.handle(0.0, b"\x19\x04" + dtc.number.to_bytes(3, "big") + b"\x01")
            assert response is not None and response[:2] == b"\x59\x04", dtc.code
