"""The diagnostic server of the example ECUs: UDS (ISO 14229-1:2013) on ISO-TP (ISO 15765-2), written from
`docs/contract/diagnostics.md` (`DIAG-*`), the nodes' "Diagnostics" sections and `dbc/diagnostics.toml` alone.

Shared by `examples/vcu_ecu.py`, `examples/sbw_ecu.py` and `examples/abs_ecu.py` (nothing of `bench/` or
`plant/`). What a node declares (addresses, DTCs, DIDs, routines, coding limits, timing) is read once at start-up
from `dbc/diagnostics.toml`, the machine-readable part of the contract; what the node *is* (its live values, its
fault results, what its coding does, its routines' preconditions, its identification) comes from the ECU.

- ISO-TP (`DIAG-TP-*`): can-isotp's `TransportLayerLogic`, driven from the ECU's own loop. The ECU hands every
  frame of its physical request identifier and of the functional identifier 0x7DF to `Diagnostics.on_frame` (no
  second reader of the bus, no thread: the ECU's loop stays the only reader and its timing is untouched) and calls
  `Diagnostics.poll` once per loop pass; `process()` never blocks (the receive function returns what the loop
  queued). Two layers: the physical one (requests, our flow control, every response, the tester's flow control
  for it) and a receive-only one for 0x7DF that sees single frames only (`DIAG-TP-04`: FF, CF and FC on 0x7DF
  are ignored). Every frame 8 bytes padded with 0xCC, FC CTS with BS 0 and STmin 0, N_Bs = N_Cr = 1000 ms, a
  receive buffer of 4095 bytes, an FC WAIT ends the response (`DIAG-TP-03`).
- Services (`DIAG-SVC-01`): 0x10, 0x11, 0x14, 0x19 (0x01, 0x02, 0x04, 0x06), 0x22, 0x27 (level 1, the documented
  seed/key), 0x2E (coding DIDs), 0x31 (0x01, 0x03), 0x3E; the checks in the order of `DIAG-NRC-01`, the NRCs of
  `DIAG-NRC-02`, functional requests and suppressPosRspMsgIndicationBit as `DIAG-NRC-03` says.
- Fault memory (`DIAG-DTC-*`, `DIAG-OPC-01`): the eight status bits, confirmation after `confirm_ms`, healing and
  aging over operation cycles, snapshot record 0x01 and extended data record 0x01 (occurrence counter), fed at
  every control step of the ECU with its monitors' results (`FaultMemory.step`).
- Non-volatile memory: with `nvm=PATH` (the examples' `--nvm FILE`) the coding and the fault memory are kept in a
  JSON file across process restarts (a power cycle); without it a process start is an ECU as delivered.

Deliberate defects for checking a tester (`defect=`, the examples' `--diag-defect`, off by default):
- `confirmed-never`: confirmedDTC (bit 3) is never set, so neither is warningIndicatorRequested (bit 7);
- `wrong-nrc`: WriteDataByIdentifier and RoutineControl in the default session get 0x33 (securityAccessDenied)
  instead of 0x7F (the security check made before the session check);
- `snapshot-stale`: a DTC's snapshot record keeps the values of its first occurrence since power-up; later
  occurrences (also after a ClearDiagnosticInformation) bring the old record back instead of a new one.
"""

from __future__ import annotations

import json
import logging
import math
import os
import secrets
import struct
import sys
import time
import tomllib
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import isotp

DECLARATION = Path(__file__).resolve().parent.parent / "dbc" / "diagnostics.toml"
DEFECTS = ("confirmed-never", "wrong-nrc", "snapshot-stale")

# --- Negative response codes (DIAG-NRC-02) ---------------------------------------------------------------------
SERVICE_NOT_SUPPORTED = 0x11
SUB_FUNCTION_NOT_SUPPORTED = 0x12
INCORRECT_LENGTH = 0x13
RESPONSE_TOO_LONG = 0x14
BUSY_REPEAT_REQUEST = 0x21
CONDITIONS_NOT_CORRECT = 0x22
REQUEST_SEQUENCE_ERROR = 0x24
REQUEST_OUT_OF_RANGE = 0x31
SECURITY_ACCESS_DENIED = 0x33
INVALID_KEY = 0x35
EXCEEDED_NUMBER_OF_ATTEMPTS = 0x36
REQUIRED_TIME_DELAY_NOT_EXPIRED = 0x37
RESPONSE_PENDING = 0x78
SERVICE_NOT_SUPPORTED_IN_ACTIVE_SESSION = 0x7F
#: DIAG-NRC-03: a functional request never gets these
SILENT_ON_FUNCTIONAL = {0x11, 0x12, 0x31, 0x7E, 0x7F}

DEFAULT_SESSION, EXTENDED_SESSION = 0x01, 0x03
START_UP_S = 0.100  # DIAG-OPC-01: the monitors give no result in the first 100 ms of an operation cycle
MAX_ISOTP = 4095  # DIAG-TP-02: the 12-bit FF length; DIAG-SVC-02: a longer response is 0x14
PENDING_REPEAT_S = 0.8  # DIAG-SVC-03: the next 0x78 at most 1000 ms after the previous one (margin for a late loop)

VIN_CHARACTERS = set("0123456789ABCDEFGHJKLMNPRSTUVWXYZ")  # DIAG-ID-01: ISO 3779, no I, O, Q
#: DID types (big-endian, DIAG-* "The declaration"): struct format, length, raw range
TYPES: dict[str, tuple[str, int, int, int]] = {
    "uint8": (">B", 1, 0, 0xFF), "int8": (">b", 1, -0x80, 0x7F),
    "uint16": (">H", 2, 0, 0xFFFF), "int16": (">h", 2, -0x8000, 0x7FFF),
    "uint32": (">I", 4, 0, 0xFFFFFFFF), "int32": (">i", 4, -0x80000000, 0x7FFFFFFF),
}


class DiagConfigError(ValueError):
    """The declaration and the ECU do not fit together (one line, naming the node and the key)."""


class ValueUnavailable(Exception):
    """A DID has no value at this moment (NRC 0x22, DIAG-SVC-02)."""


# ==============================================================================================================
# The declaration (dbc/diagnostics.toml)
# ==============================================================================================================
@dataclass(frozen=True)
class Did:
    id: int
    name: str
    type: str
    length: int
    scale: float = 1.0
    offset: float = 0.0
    values: dict[str, int] | None = None  # an enumeration: name -> raw
    signal: str | None = None  # "MESSAGE.SIGNAL" the node sends: the DID equals it (DIAG-SVC-02)
    input: str | None = None  # "MESSAGE.SIGNAL" the node reads: the last valid frame's value
    write: bool = False  # a coding DID (DIAG-COD-01)
    default: float | None = None
    minimum: float | None = None
    maximum: float | None = None

    @classmethod
    def of(cls, table: dict[str, Any]) -> Did:
        kind = str(table["type"])
        if kind == "ascii":
            length = int(table["length"])
        elif kind in TYPES:
            length = TYPES[kind][1]
        else:
            raise DiagConfigError(f"DID {table.get('name')}: type {kind!r} is none of ascii, {', '.join(TYPES)}")
        return cls(id=int(table["id"]), name=str(table["name"]), type=kind, length=length,
                   scale=float(table.get("scale", 1.0)), offset=float(table.get("offset", 0.0)),
                   values=dict(table["values"]) if "values" in table else None,
                   signal=table.get("signal"), input=table.get("input"), write=bool(table.get("write", False)),
                   default=table.get("default"), minimum=table.get("min"), maximum=table.get("max"))

    def encode(self, value: float | str) -> bytes:
        """The DID's data: ASCII padded with spaces to its length, or raw = (physical - offset) / scale rounded,
        saturated at the type's range (DIAG-SVC-02), big-endian. A non-finite value has no coding (0x22)."""
        if self.type == "ascii":
            text = str(value).encode("ascii", "replace")[:self.length]
            return text.ljust(self.length, b" ")
        number = float(value)
        if not math.isfinite(number):
            raise ValueUnavailable(self.name)
        fmt, _, lo, hi = TYPES[self.type]
        raw = round((number - self.offset) / self.scale)
        return struct.pack(fmt, min(max(raw, lo), hi))

    def decode(self, data: bytes) -> float:
        """The physical value of a raw big-endian DID value (numeric types only)."""
        fmt = TYPES[self.type][0]
        return float(struct.unpack(fmt, data)[0]) * self.scale + self.offset

    def raw_of(self, data: bytes) -> int:
        return int(struct.unpack(TYPES[self.type][0], data)[0])


@dataclass(frozen=True)
class Dtc:
    code: str  # ISO 15031-6 text, e.g. C1A01-1C
    number: int  # the 3-byte DTC on the bus (DIAG-DTC-01)
    name: str
    fault: str | None  # "MESSAGE.SIGNAL" whose value `name` the DTC records (DIAG-DTC-02), None: own condition
    confirm_ms: float
    warning_indicator: bool


@dataclass(frozen=True)
class Routine:
    id: int
    name: str
    duration_ms: float


def dtc_number(code: str) -> int:
    """DIAG-DTC-01: C1A01-1C -> 0x5A011C (letter bits 23-22, first digit 21-20, three hex digits, failure type)."""
    letter, digits, failure = code[0].upper(), code[1:5], code[6:8]
    if letter not in "PCBU" or len(digits) != 4 or code[5] != "-" or int(digits[0], 16) > 3:
        raise DiagConfigError(f"DTC code {code!r} is not ISO 15031-6 text")
    return ("PCBU".index(letter) << 22) | (int(digits[0], 16) << 20) | (int(digits[1:], 16) << 8) | int(failure, 16)


@dataclass(frozen=True)
class Declaration:
    """One node's part of dbc/diagnostics.toml, with the protocol's common values."""

    node: str
    request: int
    response: int
    functional: int
    padding: int
    p2_ms: int
    p2_star_ms: int
    s3_ms: int
    block_size: int
    stmin_ms: int
    n_bs_ms: int
    n_cr_ms: int
    security_attempts: int
    security_delay_ms: int
    aging_cycles: int
    healing_cycles: int
    security_constant: int
    identification: tuple[Did, ...]
    snapshot: tuple[int, ...]  # the DIDs of snapshot record 0x01, in order
    dids: dict[int, Did]  # every DID the node reads: identification, the common snapshot DIDs, its own
    dtcs: tuple[Dtc, ...]
    routines: dict[int, Routine]
    common: frozenset[int] = field(default_factory=frozenset)  # the protocol's snapshot DIDs (OperatingTime)

    @classmethod
    def load(cls, node: str, path: Path = DECLARATION) -> Declaration:
        with open(path, "rb") as file:
            doc = tomllib.load(file)
        protocol, nodes = doc["protocol"], doc["nodes"]
        if node not in nodes:
            raise DiagConfigError(f"{path}: no [nodes.{node}]")
        table = nodes[node]
        identification = tuple(Did.of(t) for t in doc.get("identification", []))
        common = tuple(Did.of(t) for t in doc.get("snapshot", []))
        own = tuple(Did.of(t) for t in table.get("did", []))
        dids = {d.id: d for d in (*identification, *common, *own)}
        snapshot = tuple(int(i) for i in table.get("snapshot", []))
        for did in snapshot:
            if did not in dids:
                raise DiagConfigError(f"{path}: [nodes.{node}] snapshot names DID 0x{did:04X}, which it lacks")
        dtcs = tuple(Dtc(code=str(t["code"]), number=dtc_number(str(t["code"])), name=str(t["name"]),
                         fault=t.get("fault"), confirm_ms=float(t.get("confirm_ms", 0)),
                         warning_indicator=bool(t.get("warning_indicator", False)))
                     for t in (table.get("dtc") or []))
        routines = {int(t["id"]): Routine(int(t["id"]), str(t["name"]), float(t["duration_ms"]))
                    for t in table.get("routine", [])}
        return cls(node=node, request=int(table["request"]), response=int(table["response"]),
                   functional=int(protocol["functional_request"]), padding=int(protocol["padding"]),
                   p2_ms=int(protocol["p2_ms"]), p2_star_ms=int(protocol["p2_star_ms"]), s3_ms=int(protocol["s3_ms"]),
                   block_size=int(protocol["block_size"]), stmin_ms=int(protocol["stmin_ms"]),
                   n_bs_ms=int(protocol["n_bs_ms"]), n_cr_ms=int(protocol["n_cr_ms"]),
                   security_attempts=int(protocol["security_attempts"]),
                   security_delay_ms=int(protocol["security_delay_ms"]),
                   aging_cycles=int(protocol["aging_cycles"]), healing_cycles=int(protocol["healing_cycles"]),
                   security_constant=int(table["security_constant"]), identification=identification,
                   snapshot=snapshot, dids=dids, dtcs=dtcs, routines=routines,
                   common=frozenset(d.id for d in common))

    def ids(self) -> tuple[int, int]:
        """The identifiers the node receives diagnostic requests on: its physical one and the functional one."""
        return self.request, self.functional


def security_key(seed: int, constant: int) -> int:
    """DIAG-SEC-01: key = rotl32(seed XOR C, 7) XOR 0xA5A5A5A5."""
    x = (seed ^ constant) & 0xFFFFFFFF
    return (((x << 7) | (x >> 25)) & 0xFFFFFFFF) ^ 0xA5A5A5A5


# ==============================================================================================================
# The fault memory (DIAG-DTC-*, DIAG-OPC-01)
# ==============================================================================================================
TEST_FAILED, TEST_FAILED_THIS_CYCLE, PENDING, CONFIRMED = 0x01, 0x02, 0x04, 0x08
NOT_COMPLETED_SINCE_CLEAR, FAILED_SINCE_CLEAR, NOT_COMPLETED_THIS_CYCLE, WARNING_INDICATOR = 0x10, 0x20, 0x40, 0x80
AS_DELIVERED = NOT_COMPLETED_SINCE_CLEAR | NOT_COMPLETED_THIS_CYCLE  # 0x50 (DIAG-DTC-03)


@dataclass
class DtcState:
    dtc: Dtc
    status: int = AS_DELIVERED
    failing_since: float | None = None  # the first of the uninterrupted failed results (confirmation)
    healing: int = 0  # complete operation cycles without failure in a row (DIAG-DTC-04)
    aging: int = 0
    snapshot: bytes | None = None  # the DIDs of record 0x01 with their data
    occurrences: int = 0  # extended data record 0x01
    first_snapshot: bytes | None = None  # the defect snapshot-stale's memory (never cleared)

    def to_json(self) -> dict[str, Any]:
        return {"status": self.status, "healing": self.healing, "aging": self.aging,
                "snapshot": self.snapshot.hex() if self.snapshot is not None else None,
                "occurrences": self.occurrences}

    def load(self, saved: dict[str, Any]) -> None:
        self.status = int(saved["status"]) & 0xFF
        self.healing, self.aging = int(saved["healing"]), int(saved["aging"])
        self.snapshot = bytes.fromhex(saved["snapshot"]) if saved.get("snapshot") else None
        self.occurrences = min(255, int(saved["occurrences"]))


class FaultMemory:
    """The status bytes, snapshot records and occurrence counters of one node's DTCs.

    `step(now, failed)` is the monitors' result at one control step (failed: the names of the DTCs whose result is
    "failed"; every other DTC "passed"); `start_cycle(now)` is the start of an operation cycle (power-up, ECUReset);
    `clear(numbers)` is ClearDiagnosticInformation. `snapshot` gives the record's data at the current control step."""

    def __init__(self, decl: Declaration, snapshot: Callable[[], bytes], defect: str | None = None) -> None:
        self.decl = decl
        self.entries = [DtcState(d) for d in decl.dtcs]
        self.by_number = {e.dtc.number: e for e in self.entries}
        self.by_name = {e.dtc.name: e for e in self.entries}
        self.snapshot = snapshot
        self.defect = defect
        self.cycle_start = -math.inf

    def start_cycle(self, now: float) -> None:
        """DIAG-OPC-01 and DIAG-DTC-04 at the end of one operation cycle and the start of the next."""
        for e in self.entries:
            completed = not e.status & NOT_COMPLETED_THIS_CYCLE
            failed = bool(e.status & TEST_FAILED_THIS_CYCLE)
            if failed:
                e.healing = e.aging = 0  # a cycle with a failure sets both counts back
            elif completed:  # a cycle that completed the test without failure (else: neither count changes)
                e.healing += 1
                e.aging += 1
                e.status &= ~PENDING
                if e.healing >= self.decl.healing_cycles:
                    e.status &= ~WARNING_INDICATOR  # healing
                if e.aging >= self.decl.aging_cycles:
                    e.status &= ~CONFIRMED  # aging: testFailedSinceLastClear stays
                    e.snapshot, e.occurrences = None, 0
            e.status = (e.status & ~TEST_FAILED_THIS_CYCLE) | NOT_COMPLETED_THIS_CYCLE
            e.failing_since = None  # the start of an operation cycle restarts the confirmation time
        self.cycle_start = now

    def in_start_up(self, now: float) -> bool:
        return now - self.cycle_start < START_UP_S

    def step(self, now: float, failed: set[str]) -> None:
        """DIAG-DTC-02..05: one result per DTC (none during the start-up time of the cycle)."""
        if self.in_start_up(now):
            return
        for e in self.entries:
            before = e.status
            status = before & ~(NOT_COMPLETED_SINCE_CLEAR | NOT_COMPLETED_THIS_CYCLE)  # any result completes
            if e.dtc.name in failed:
                if not before & TEST_FAILED:  # testFailed 0 -> 1: an occurrence (DIAG-DTC-05)
                    e.occurrences = min(255, e.occurrences + 1)
                    self._store_snapshot(e)
                    e.failing_since = now
                elif e.failing_since is None:
                    e.failing_since = now  # failing over the start of the cycle: the time restarts
                status |= TEST_FAILED | TEST_FAILED_THIS_CYCLE | PENDING | FAILED_SINCE_CLEAR
                if now - e.failing_since >= e.dtc.confirm_ms / 1000.0 - 1e-9 and self.defect != "confirmed-never":
                    status |= CONFIRMED | (WARNING_INDICATOR if e.dtc.warning_indicator else 0)
            else:
                status &= ~TEST_FAILED
                e.failing_since = None
            e.status = status

    def _store_snapshot(self, e: DtcState) -> None:
        if self.defect == "snapshot-stale" and e.first_snapshot is not None:
            e.snapshot = e.first_snapshot  # the defect: the first occurrence's record comes back
            return
        e.snapshot = self.snapshot()
        if e.first_snapshot is None:
            e.first_snapshot = e.snapshot

    def clear(self, numbers: list[int] | None) -> None:
        """DIAG-DTC-06: status 0x50, no record, occurrence counter 0, healing and aging counts 0."""
        for e in self.entries:
            if numbers is None or e.dtc.number in numbers:
                e.status, e.snapshot, e.occurrences = AS_DELIVERED, None, 0
                e.healing = e.aging = 0
                e.failing_since = None


# ==============================================================================================================
# ISO-TP (DIAG-TP-*) with can-isotp, driven from the ECU's loop
# ==============================================================================================================
class IsoTpPort:
    """The node's two ISO-TP endpoints: physical (request id -> response id) and functional (0x7DF, receive only,
    single frames). `feed` queues a received frame, `process` runs both layers once without blocking."""

    def __init__(self, decl: Declaration, send: Callable[[can.Message], bool]) -> None:
        self.decl, self._send = decl, send
        self.rx_physical: deque[isotp.CanMessage] = deque()
        self.rx_functional: deque[isotp.CanMessage] = deque()
        self.errors = 0
        params = {
            "stmin": decl.stmin_ms, "blocksize": decl.block_size,
            "rx_flowcontrol_timeout": decl.n_bs_ms, "rx_consecutive_frame_timeout": decl.n_cr_ms,
            "tx_padding": decl.padding, "tx_data_length": 8, "tx_data_min_length": 8,
            "max_frame_size": MAX_ISOTP, "wftmax": 0, "can_fd": False, "blocking_send": False,
            "wait_func": lambda _: None,  # never sleeps: the ECU's loop is the only timing
            "logger_name": "uds_server.isotp",
        }
        self.physical = isotp.TransportLayerLogic(
            rxfn=lambda _timeout: self.rx_physical.popleft() if self.rx_physical else None,
            txfn=self._tx,
            address=isotp.Address(isotp.AddressingMode.Normal_11bits, rxid=decl.request, txid=decl.response),
            error_handler=self._on_error, params=params)
        self.functional = isotp.TransportLayerLogic(
            rxfn=lambda _timeout: self.rx_functional.popleft() if self.rx_functional else None,
            txfn=self._tx,
            address=isotp.Address(isotp.AddressingMode.Normal_11bits, rxid=decl.functional, txid=decl.response),
            error_handler=None, params={**params, "listen_mode": True})  # never sends (no FC on 0x7DF)
        logging.getLogger("uds_server.isotp").setLevel(logging.CRITICAL)  # a tester's framing error: no log line

    def feed(self, msg: can.Message) -> None:
        frame = isotp.CanMessage(arbitration_id=msg.arbitration_id, data=bytes(msg.data), dlc=len(msg.data),
                                 extended_id=False, is_fd=False)
        if msg.arbitration_id == self.decl.request:
            self.rx_physical.append(frame)
        elif msg.data and msg.data[0] >> 4 == 0:  # DIAG-TP-04: single frames only on 0x7DF
            self.rx_functional.append(frame)

    def busy(self) -> bool:
        """Whether a layer needs `process` (frames queued, a segmented transfer under way, a response queued)."""
        return bool(self.rx_physical or self.rx_functional or self.physical.is_rx_active()
                    or self.physical.transmitting())

    def process(self) -> list[tuple[bytes, bool]]:
        """Run both layers once; the requests received, each with `functional`."""
        requests: list[tuple[bytes, bool]] = []
        if self.rx_functional:
            self.functional.process()
            while (payload := self.functional.recv()) is not None:
                requests.append((bytes(payload), True))
        self.physical.process()
        while (payload := self.physical.recv()) is not None:
            requests.append((bytes(payload), False))
        return requests

    def send(self, payload: bytes) -> None:
        self.physical.send(payload)
        self.physical.process(do_rx=False)  # a single frame goes out at once (P2)

    def reset(self) -> None:
        self.rx_physical.clear()
        self.rx_functional.clear()
        self.physical.reset()
        self.functional.reset()

    def _tx(self, frame: isotp.CanMessage) -> None:
        self._send(can.Message(arbitration_id=frame.arbitration_id, data=bytes(frame.data), is_extended_id=False))

    def _on_error(self, error: Exception) -> None:
        self.errors += 1
        if isinstance(error, isotp.errors.UnsupportedWaitFrameError):
            self.physical.stop_sending()  # DIAG-TP-03: an FC WAIT ends the response as an N_Bs timeout would


# ==============================================================================================================
# The UDS server (DIAG-SES-*, DIAG-RST-*, DIAG-SVC-*, DIAG-NRC-*, DIAG-SEC-*, DIAG-ID-01, DIAG-COD-01)
# ==============================================================================================================
@dataclass(frozen=True)
class Service:
    sessions: frozenset[int]
    min_length: int
    sub_functions: frozenset[int] | None = None  # None: no sub-function
    suppress_bit: bool = False  # bit 7 of the sub-function is suppressPosRspMsgIndicationBit


BOTH = frozenset({DEFAULT_SESSION, EXTENDED_SESSION})
EXTENDED = frozenset({EXTENDED_SESSION})
#: DIAG-SVC-01 and the minimum lengths of DIAG-NRC-01 item 4
SERVICES = {
    0x10: Service(BOTH, 2, frozenset({0x01, 0x03}), True),
    0x11: Service(BOTH, 2, frozenset({0x01, 0x03}), True),
    0x14: Service(BOTH, 4),
    0x19: Service(BOTH, 2, frozenset({0x01, 0x02, 0x04, 0x06}), False),
    0x22: Service(BOTH, 3),
    0x27: Service(EXTENDED, 2, frozenset({0x01, 0x02}), True),
    0x2E: Service(EXTENDED, 4),
    0x31: Service(EXTENDED, 2, frozenset({0x01, 0x03}), True),
    0x3E: Service(BOTH, 2, frozenset({0x00}), True),
}


@dataclass
class Running:
    """A routine whose final response is owed (DIAG-SVC-03)."""

    routine: Routine
    ends: float
    next_pending: float


class Diagnostics:
    """The node's diagnostic server: ISO-TP port, UDS services, fault memory, coding.

    The ECU gives:
    - `send(frame) -> bool`: its own transmit function (the bus it already sends on);
    - `identification`: DID name -> text (DIAG-ID-01: the ECU's own values);
    - `live`: DID name -> a function giving its physical value now, for every DID of the node that has neither
      `signal`, `input` nor `write`;
    - `outputs(message) -> values | None`: the signal values of the ECU's latest frame (or of the next one, the
      latest control step's) of one of its messages, for the DIDs with `signal`;
    - `inputs(message) -> values | None`: the values of the last valid frame of an input, for the DIDs with
      `input` (the DBC start value before the first);
    - `signals`: the cantools databases, for the start values and ranges of those signals;
    - `coding_supported(name, value) -> bool`: False for a value that selects a function the ECU does not have
      (0x31); `apply_coding(name, value)`: puts a coding value in force (at start-up and at each write);
    - `preconditions`: routine name -> a function that is True while the routine may start (else 0x22);
    - `on_reset()`: restarts the ECU's control as after power-up (DIAG-RST-02).
    """

    def __init__(self, node: str, send: Callable[[can.Message], bool], *, identification: dict[str, str],
                 live: dict[str, Callable[[], float]], outputs: Callable[[str], dict[str, float] | None],
                 inputs: Callable[[str], dict[str, float] | None], signals: list[Any],
                 apply_coding: Callable[[str, float], None] | None = None,
                 coding_supported: Callable[[str, float], bool] | None = None,
                 initial_coding: dict[str, float] | None = None,
                 preconditions: dict[str, Callable[[], bool]] | None = None,
                 on_reset: Callable[[], None] | None = None, defect: str | None = None,
                 nvm: Path | None = None, declaration: Path = DECLARATION,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if defect is not None and defect not in DEFECTS:
            raise DiagConfigError(f"unknown diagnostic defect {defect!r} (one of {', '.join(DEFECTS)})")
        self.decl = Declaration.load(node, declaration)
        self.clock, self.defect, self.nvm = clock, defect, nvm
        self.identification = identification
        self.live, self.outputs, self.inputs = live, outputs, inputs
        self.apply_coding = apply_coding or (lambda _name, _value: None)
        self.coding_supported = coding_supported or (lambda _name, _value: True)
        self.preconditions = preconditions or {}
        self.on_reset = on_reset or (lambda: None)
        self._signals = {f"{m.name}.{s.name}": s for db in signals for m in db.messages for s in m.signals}
        self._check_sources()
        self._fault_names: dict[tuple[str, int], str] = {}
        for dtc in self.decl.dtcs:
            if dtc.fault is None:
                continue
            sig = self._signals.get(dtc.fault)
            choices = {str(name): int(value) for value, name in (sig.choices or {}).items()} if sig else {}
            if dtc.name not in choices:
                raise DiagConfigError(f"{node}: DTC {dtc.name}: {dtc.fault} has no value {dtc.name}")
            self._fault_names[(dtc.fault, choices[dtc.name])] = dtc.name
        self.port = IsoTpPort(self.decl, send)
        self.power_up = clock()
        self.memory = FaultMemory(self.decl, self._snapshot_record, defect)
        self.coding = {d.name: float(d.default) for d in self.decl.dids.values()
                       if d.write and d.default is not None}
        for name, value in (initial_coding or {}).items():
            if name not in self.coding:
                raise DiagConfigError(f"[nodes.{node}] has no coding DID {name}")
            self.coding[name] = float(value)
        self._load_nvm()
        self.session = DEFAULT_SESSION
        self.unlocked = False
        self.seed: int | None = None  # a seed awaiting its key
        self.wrong_keys = 0
        self.delay_until: float | None = None  # the end of the delay after the last allowed wrong key
        self.running: Running | None = None  # a routine whose final response is owed
        self.started: set[int] = set()  # routines started in this operation cycle
        self.last_exchange = self.power_up
        self.reset_due = False
        for name, value in self.coding.items():
            self.apply_coding(name, value)
        self._start_cycle(self.power_up)
        self.requests = self.negative = self.internal_errors = 0  # statistics for the ECU's --stats

    # --- the ECU's side -------------------------------------------------------------------------------------
    def on_frame(self, msg: can.Message) -> bool:
        """Take a received frame if it is a diagnostic request frame (True); the ECU's receivers never see it."""
        if msg.arbitration_id not in (self.decl.request, self.decl.functional):
            return False
        if not (msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or msg.is_fd):
            self.port.feed(msg)
        return True

    def failing(self, faults: dict[str, int], conditions: set[str] | frozenset[str] = frozenset()) -> set[str]:
        """DIAG-DTC-02: the DTCs that fail at this step. `faults`: each fault signal ("SBW_Pinion.SbwFault") with
        the code the ECU puts into it now; a DTC with that `fault` fails while the code is its name's value (the
        signal's value table). `conditions`: the DTCs without `fault` whose condition holds now."""
        failed = set(conditions)
        for path, code in faults.items():
            name = self._fault_names.get((path, int(code)))
            if name is not None:
                failed.add(name)
        return failed

    def control_step(self, failed: set[str]) -> None:
        """The monitors' results at one control step of the ECU: the names of the DTCs that fail now."""
        try:
            self.memory.step(self.clock(), failed)
        except Exception:  # noqa: BLE001 - a fault of the diagnostics never stops the ECU's control
            self._internal_error()

    def poll(self) -> None:
        """One pass of the server: ISO-TP, the requests received, the routine's responses, S3, a due reset.
        Cheap when nothing happens (a few comparisons)."""
        try:
            self._poll()
        except Exception:  # noqa: BLE001 - a fault of the diagnostics never stops the ECU's control
            self._internal_error()

    def _internal_error(self) -> None:
        self.internal_errors += 1
        if self.internal_errors <= 10:
            traceback.print_exc(file=sys.stderr)

    def _poll(self) -> None:
        now = self.clock()
        if self.port.busy():
            for request, functional in self.port.process():
                self._request(request, functional, now)
            if self.port.physical.transmitting():
                self.last_exchange = self.clock()  # S3 restarts when the response has been sent
        if self.running is not None:
            self._run_routine(now)
        elif self.session == EXTENDED_SESSION and now - self.last_exchange > self.decl.s3_ms / 1000.0:
            self._enter_default()  # DIAG-SES-03
        if self.reset_due and not self.port.physical.transmitting():
            self._reset()

    def close(self) -> None:
        """Power-down: the non-volatile memory is saved."""
        self._save_nvm()

    def operating_time(self) -> float:
        """DIAG-DTC-05: seconds since power-up (an ECUReset does not restart it)."""
        return self.clock() - self.power_up

    # --- sessions, cycles, reset ------------------------------------------------------------------------------
    def _start_cycle(self, now: float) -> None:
        self.session = DEFAULT_SESSION
        self.unlocked, self.seed = False, None
        self.wrong_keys, self.delay_until = 0, None  # DIAG-RST-02 / DIAG-SEC-02: no delay after power-up
        self.running = None
        self.started = set()
        self.last_exchange = now
        self.reset_due = False
        self.memory.start_cycle(now)

    def _enter_default(self) -> None:
        self.session = DEFAULT_SESSION
        self.unlocked, self.seed = False, None

    def _reset(self) -> None:
        """DIAG-RST-02: the ECU restarts as after power-up; coding and fault memory kept; a new cycle."""
        self.port.reset()
        self.on_reset()
        for name, value in self.coding.items():
            self.apply_coding(name, value)
        self._start_cycle(self.clock())
        self._save_nvm()

    # --- one request ------------------------------------------------------------------------------------------
    def _request(self, request: bytes, functional: bool, now: float) -> None:
        self.requests += 1
        self.last_exchange = now  # any request keeps the session (DIAG-SES-03)
        if not request:
            return
        sid = request[0]
        answer, suppress = self._check_and_serve(request, now)
        if isinstance(answer, int):  # a negative response (DIAG-NRC-03: never suppressed by the bit)
            self.negative += 1
            if functional and answer in SILENT_ON_FUNCTIONAL:
                return
            self.port.send(bytes([0x7F, sid, answer]))
        elif answer is not None and not suppress:
            self.port.send(answer)
        self.last_exchange = self.clock()

    def _check_and_serve(self, req: bytes, now: float) -> tuple[bytes | int | None, bool]:
        """DIAG-NRC-01: the checks in order; the positive response (or None: none to send now) and whether the
        positive response is suppressed."""
        sid = req[0]
        if self.running is not None and sid != 0x3E:
            return BUSY_REPEAT_REQUEST, False  # 1
        service = SERVICES.get(sid)
        if service is None:
            return SERVICE_NOT_SUPPORTED, False  # 2
        if self.session not in service.sessions:  # 3
            if self.defect == "wrong-nrc" and sid in (0x2E, 0x31):
                return SECURITY_ACCESS_DENIED, False  # the defect: security checked before the session
            return SERVICE_NOT_SUPPORTED_IN_ACTIVE_SESSION, False
        if len(req) < service.min_length:
            return INCORRECT_LENGTH, False  # 4
        sub, suppress = 0, False
        if service.sub_functions is not None:  # 5 (6: every sub-function in every session of its service)
            sub = req[1]
            if service.suppress_bit:
                sub, suppress = sub & 0x7F, bool(sub & 0x80)
            if sub not in service.sub_functions:
                return SUB_FUNCTION_NOT_SUPPORTED, False
        handler = {0x10: self._session_control, 0x11: self._ecu_reset, 0x14: self._clear, 0x19: self._read_dtc,
                   0x22: self._read_did, 0x27: self._security, 0x2E: self._write_did, 0x31: self._routine,
                   0x3E: self._tester_present}[sid]
        return handler(req, sub, suppress, now), suppress

    def _session_control(self, req: bytes, sub: int, _suppress: bool, _now: float) -> bytes | int:
        if len(req) != 2:
            return INCORRECT_LENGTH
        self.session = sub
        self.unlocked, self.seed = False, None  # DIAG-SES-01: every session control locks
        p2, p2_star = self.decl.p2_ms, self.decl.p2_star_ms // 10
        return bytes([0x50, sub]) + struct.pack(">HH", p2, p2_star)

    def _ecu_reset(self, req: bytes, sub: int, _suppress: bool, _now: float) -> bytes | int:
        if len(req) != 2:
            return INCORRECT_LENGTH
        self.reset_due = True  # DIAG-RST-01: after the response has gone out completely
        return bytes([0x51, sub])

    def _tester_present(self, req: bytes, sub: int, _suppress: bool, _now: float) -> bytes | int:
        return INCORRECT_LENGTH if len(req) != 2 else bytes([0x7E, sub])

    def _clear(self, req: bytes, _sub: int, _suppress: bool, _now: float) -> bytes | int:
        if len(req) != 4:
            return INCORRECT_LENGTH
        group = int.from_bytes(req[1:4], "big")
        if group == 0xFFFFFF:
            self.memory.clear(None)
        elif group in self.memory.by_number:
            self.memory.clear([group])
        else:
            return REQUEST_OUT_OF_RANGE
        self._save_nvm()
        return b"\x54"

    def _read_dtc(self, req: bytes, sub: int, _suppress: bool, _now: float) -> bytes | int:
        if len(req) != (3 if sub in (0x01, 0x02) else 6):
            return INCORRECT_LENGTH
        entries = self.memory.entries
        if sub in (0x01, 0x02):
            mask = req[2]
            matching = [e for e in entries if e.status & mask]
            if sub == 0x01:
                return bytes([0x59, 0x01, 0xFF, 0x01]) + struct.pack(">H", len(matching))
            return bytes([0x59, 0x02, 0xFF]) + b"".join(e.dtc.number.to_bytes(3, "big") + bytes([e.status])
                                                         for e in matching)
        number, record = int.from_bytes(req[2:5], "big"), req[5]
        entry = self.memory.by_number.get(number)
        if entry is None or record not in (0x01, 0xFF):
            return REQUEST_OUT_OF_RANGE
        head = bytes([0x59, sub]) + req[2:5] + bytes([entry.status])
        if sub == 0x04:
            if entry.snapshot is None:
                return head
            return head + bytes([0x01, len(self.decl.snapshot)]) + entry.snapshot
        return head + bytes([0x01, entry.occurrences])

    def _read_did(self, req: bytes, _sub: int, _suppress: bool, _now: float) -> bytes | int:
        if len(req) % 2 == 0:
            return INCORRECT_LENGTH
        ids = [int.from_bytes(req[i:i + 2], "big") for i in range(1, len(req), 2)]
        known = [i for i in ids if i in self.decl.dids]
        if not known:
            return REQUEST_OUT_OF_RANGE
        if 1 + sum(2 + self.decl.dids[i].length for i in known) > MAX_ISOTP:
            return RESPONSE_TOO_LONG
        try:
            return b"\x62" + b"".join(i.to_bytes(2, "big") + self.did_data(self.decl.dids[i]) for i in known)
        except ValueUnavailable:
            return CONDITIONS_NOT_CORRECT

    def _security(self, req: bytes, sub: int, _suppress: bool, now: float) -> bytes | int:
        if sub == 0x01:  # requestSeed
            if self.delay_until is not None:
                if now < self.delay_until:
                    return REQUIRED_TIME_DELAY_NOT_EXPIRED
                self.delay_until, self.wrong_keys = None, 0  # the first requestSeed after the delay
            if self.unlocked:
                self.seed = None
                return b"\x67\x01" + bytes(4)
            self.seed = secrets.randbelow(0xFFFFFFFF) + 1  # never 0 while locked, unpredictable
            return b"\x67\x01" + self.seed.to_bytes(4, "big")
        if len(req) != 6:  # sendKey
            return INCORRECT_LENGTH
        if self.seed is None:
            return REQUEST_SEQUENCE_ERROR
        seed, self.seed = self.seed, None  # used up either way
        if int.from_bytes(req[2:6], "big") == security_key(seed, self.decl.security_constant):
            self.unlocked, self.wrong_keys = True, 0
            return b"\x67\x02"
        self.wrong_keys += 1
        if self.wrong_keys >= self.decl.security_attempts:
            self.delay_until = now + self.decl.security_delay_ms / 1000.0
            return EXCEEDED_NUMBER_OF_ATTEMPTS
        return INVALID_KEY

    def _write_did(self, req: bytes, _sub: int, _suppress: bool, _now: float) -> bytes | int:
        did = self.decl.dids.get(int.from_bytes(req[1:3], "big"))
        if did is None or not did.write:
            return REQUEST_OUT_OF_RANGE
        if not self.unlocked:
            return SECURITY_ACCESS_DENIED
        if len(req) != 3 + did.length:
            return INCORRECT_LENGTH
        data = req[3:]
        value = did.decode(data)
        if did.values is not None:
            if did.raw_of(data) not in did.values.values():
                return REQUEST_OUT_OF_RANGE
        elif ((did.minimum is not None and value < float(did.minimum) - 1e-9)
              or (did.maximum is not None and value > float(did.maximum) + 1e-9)):
            return REQUEST_OUT_OF_RANGE
        if not self.coding_supported(did.name, value):
            return REQUEST_OUT_OF_RANGE  # DIAG-COD-01: an optional function the ECU does not have
        self.coding[did.name] = value
        self.apply_coding(did.name, value)  # in force from the next control step
        self._save_nvm()
        return b"\x6E" + req[1:3]

    def _routine(self, req: bytes, sub: int, suppress: bool, now: float) -> bytes | int | None:
        if len(req) < 4:
            return INCORRECT_LENGTH
        routine = self.decl.routines.get(int.from_bytes(req[2:4], "big"))
        if routine is None:
            return REQUEST_OUT_OF_RANGE
        if not self.unlocked:
            return SECURITY_ACCESS_DENIED
        if sub == 0x03:
            if routine.id not in self.started:
                return REQUEST_SEQUENCE_ERROR
            return bytes([0x71, 0x03]) + req[2:4]
        check = self.preconditions.get(routine.name)
        if check is not None and not check():
            return CONDITIONS_NOT_CORRECT
        self.started.add(routine.id)
        self.running = Running(routine, now + routine.duration_ms / 1000.0, now + PENDING_REPEAT_S)
        self.port.send(bytes([0x7F, 0x31, RESPONSE_PENDING]))  # at once, within P2
        return None  # the final response follows after a 0x78: never suppressed (DIAG-SVC-03)

    def _run_routine(self, now: float) -> None:
        running = self.running
        assert running is not None
        if now >= running.ends:
            self.running = None
            self.port.send(bytes([0x71, 0x01]) + running.routine.id.to_bytes(2, "big"))
            self.last_exchange = now
        elif now >= running.next_pending:
            running.next_pending = now + PENDING_REPEAT_S
            self.port.send(bytes([0x7F, 0x31, RESPONSE_PENDING]))

    # --- values -----------------------------------------------------------------------------------------------
    def _check_sources(self) -> None:
        for did in self.decl.dids.values():
            if did.type == "ascii":  # DIAG-ID-01: printable ASCII of at most `length`, the VIN ISO 3779 or blank
                text = self.identification.get(did.name)
                if text is None:
                    raise DiagConfigError(f"{self.decl.node}: no identification value for {did.name}")
                if len(text) > did.length or not all(0x20 <= ord(c) <= 0x7E for c in text):
                    raise DiagConfigError(f"{self.decl.node}: {did.name} {text!r} is not {did.length} printable "
                                          "ASCII characters")
                if did.id == 0xF190 and text.strip() and (len(text) != 17 or not set(text) <= VIN_CHARACTERS):
                    raise DiagConfigError(f"{self.decl.node}: VIN {text!r} is not 17 characters of ISO 3779 "
                                          "(digits, capital letters but I, O, Q)")
            elif did.write or did.id in self.decl.common:
                continue
            elif did.signal or did.input:
                if (did.signal or did.input) not in self._signals:
                    raise DiagConfigError(f"{self.decl.node}: DID {did.name}: no signal {did.signal or did.input}")
            elif did.name not in self.live:
                raise DiagConfigError(f"{self.decl.node}: no live value for DID {did.name} (0x{did.id:04X})")

    def value(self, did: Did) -> float | str:
        """The DID's physical value now (the ECU's latest control step)."""
        if did.type == "ascii":
            return self.identification[did.name]
        if did.id in self.decl.common:
            return self.operating_time()
        if did.write:
            return self.coding[did.name]
        if did.signal or did.input:
            path = did.signal or did.input
            assert path is not None
            message, name = path.split(".", 1)
            sig = self._signals[path]
            values = (self.outputs if did.signal else self.inputs)(message)
            value = values.get(name) if values is not None else None
            if value is None:  # the DBC start value before the first frame
                return float(sig.raw_initial or 0) * float(sig.scale) + float(sig.offset)
            value = float(value)
            if did.signal and math.isfinite(value):  # what the frame carries: saturated to the DBC range
                lo = -math.inf if sig.minimum is None else float(sig.minimum)
                hi = math.inf if sig.maximum is None else float(sig.maximum)
                value = min(max(value, lo), hi)
            return value
        return float(self.live[did.name]())

    def did_data(self, did: Did) -> bytes:
        return did.encode(self.value(did))

    def _snapshot_record(self) -> bytes:
        """DIAG-DTC-05: each snapshot DID (2 bytes) with its data, as at this control step."""
        out = bytearray()
        for i in self.decl.snapshot:
            did = self.decl.dids[i]
            try:
                data = self.did_data(did)
            except ValueUnavailable:
                data = bytes(did.length)
            out += i.to_bytes(2, "big") + data
        return bytes(out)

    # --- non-volatile memory ----------------------------------------------------------------------------------
    def _load_nvm(self) -> None:
        if self.nvm is None or not self.nvm.exists():
            return
        try:
            saved = json.loads(self.nvm.read_text())
        except (OSError, ValueError) as error:
            raise DiagConfigError(f"{self.nvm}: unreadable non-volatile memory ({error})") from None
        for name, value in saved.get("coding", {}).items():
            if name in self.coding:
                self.coding[name] = float(value)
        for code, state in saved.get("dtc", {}).items():
            for e in self.memory.entries:
                if e.dtc.code == code:
                    e.load(state)

    def _save_nvm(self) -> None:
        """Written on diagnostic events only (a coding write, a clear, a reset, power-down), never per step."""
        if self.nvm is None:
            return
        data = {"node": self.decl.node, "coding": self.coding,
                "dtc": {e.dtc.code: e.to_json() for e in self.memory.entries}}
        tmp = self.nvm.with_suffix(self.nvm.suffix + ".tmp")
        try:
            tmp.write_text(json.dumps(data, indent=1))
            os.replace(tmp, self.nvm)
        except OSError:
            pass  # a full disk costs the save, not the ECU
