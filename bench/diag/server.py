"""The UDS (ISO 14229-1) server of one simulated node: sessions, security, DIDs, DTCs, routines, ECUReset.

Built from the node's declaration, it answers on the bench's own ISO-TP in bench time, so a virtual-time run is
as deterministic with diagnostics as without (seeds come from a generator seeded by the node's name). The node's
behaviour feeds it what only the ECU knows (`report`, `provide`, `on_routine`, `on_reset`) and reads its coding.
`handle` answers one request without ISO-TP: the station's path (`on_frame`, `poll`) and the unit tests share it.
"""

from __future__ import annotations

import math
import random
import struct
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol as TypingProtocol

from bench.diag.declaration import Did, NodeDiagnostics, Protocol, Routine
from bench.diag.faultmemory import AVAILABILITY, FaultMemory
from bench.diag.isotp import IsoTpEndpoint, IsoTpParams
from bench.diag.security import documented_key

DEFAULT_SESSION = 0x01
EXTENDED_SESSION = 0x03
_BOTH = frozenset({DEFAULT_SESSION, EXTENDED_SESSION})

#: services answered in the default session (the extended session answers every supported one)
DEFAULT_SESSION_SERVICES = frozenset({0x10, 0x11, 0x14, 0x19, 0x22, 0x3E})
#: the sub-functions of each service with one, and the sessions each is supported in (NRC 0x12, 0x7E)
SUBFUNCTIONS: dict[int, dict[int, frozenset[int]]] = {
    0x10: {DEFAULT_SESSION: _BOTH, EXTENDED_SESSION: _BOTH},
    0x11: {0x01: _BOTH, 0x03: _BOTH},                       # hardReset, softReset
    0x19: {0x01: _BOTH, 0x02: _BOTH, 0x04: _BOTH, 0x06: _BOTH},
    0x27: {0x01: _BOTH, 0x02: _BOTH},                       # level 1: requestSeed, sendKey
    0x31: {0x01: _BOTH, 0x03: _BOTH},                       # startRoutine, requestRoutineResults
    0x3E: {0x00: _BOTH},
}
#: services whose sub-function's bit 7 suppresses the positive response
SPRMIB_SERVICES = frozenset({0x10, 0x11, 0x27, 0x31, 0x3E})
#: NRCs a functional request never gets (ISO 14229-1 §7.5: only the addressed servers that can act answer)
FUNCTIONAL_SILENT = frozenset({0x11, 0x12, 0x31, 0x7E, 0x7F})

# negative response codes
GENERAL_REJECT = 0x10
SERVICE_NOT_SUPPORTED = 0x11
SUBFUNCTION_NOT_SUPPORTED = 0x12
INCORRECT_LENGTH = 0x13
RESPONSE_TOO_LONG = 0x14
BUSY_REPEAT_REQUEST = 0x21
CONDITIONS_NOT_CORRECT = 0x22
REQUEST_SEQUENCE_ERROR = 0x24
REQUEST_OUT_OF_RANGE = 0x31
SECURITY_ACCESS_DENIED = 0x33
INVALID_KEY = 0x35
EXCEEDED_ATTEMPTS = 0x36
DELAY_NOT_EXPIRED = 0x37
RESPONSE_PENDING = 0x78
SUBFUNCTION_NOT_IN_SESSION = 0x7E
SERVICE_NOT_IN_SESSION = 0x7F

_MIN_LENGTH = {0x10: 2, 0x11: 2, 0x14: 4, 0x19: 2, 0x22: 3, 0x27: 2, 0x2E: 4, 0x31: 2, 0x3E: 2}
_RECORDS = (0x01, 0xFF)       # snapshot / extended data record numbers: the one record, and "all"
#: the longest gap between two responsePending of a running routine (also never more than 0.9 P2*)
PENDING_EVERY = 0.9


class _Refusal(Exception):
    """A negative response, raised where the check is and answered by `handle`."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


@dataclass(slots=True)
class _Running:
    """A started routine the server still owes its final response for."""

    routine: Routine
    end: float
    next_pending: float


class _Report(TypingProtocol):
    def __call__(self, t: float, *failed: str) -> None: ...


class UdsServer:
    """The diagnostic side of one simulated node: a station listener on its request and the functional address."""

    def __init__(self, node: NodeDiagnostics, protocol: Protocol, send: Callable[[int, bytes], None]) -> None:
        self.node, self.protocol = node, protocol
        self.frame_ids: tuple[int, ...] = (node.request, protocol.functional_request)
        self.params = IsoTpParams(padding=protocol.padding, block_size=protocol.block_size, stmin=protocol.stmin,
                                  n_bs=protocol.n_bs, n_cr=protocol.n_cr)
        #: the physical connection (its `problems`: what the tester broke of ISO 15765-2)
        self.endpoint = IsoTpEndpoint(node.response, node.request, send, self.params)
        self.memory = FaultMemory(node, protocol, self._snapshot_record)
        #: = memory.report, bound once: a behaviour calls it every step
        self.report: _Report = self.memory.report
        self._dids = {did.id: did for did in node.dids}
        self._coding = {did.name: float(did.default) for did in node.dids if did.write and did.type != "ascii"}
        self._providers: dict[int, Callable[[], float | str]] = {}
        self._routine_callbacks: dict[int, list[Callable[[], None]]] = {}
        self._reset_callbacks: list[Callable[[], None]] = []
        self._pending_every = min(PENDING_EVERY, 0.9 * protocol.p2_star)
        self._seeds = random.Random(node.node)    # str seeds are hashed the same in every process
        self._session = DEFAULT_SESSION
        self._unlocked = False
        self._seed: bytes | None = None           # awaiting its key
        self._last_seed = b"\0\0\0\0"
        self._failed_keys = 0
        self._delay_until: float | None = None
        self._s3_from = 0.0
        self._running: _Running | None = None
        self._started: set[int] = set()          # routines started since power-up (requestRoutineResults)
        self._reset_due = False
        self._outbox: deque[bytes] = deque()      # responses waiting for the endpoint to finish sending
        self._work = False                        # a timer or a pending action for poll (see `busy`)

    # -- the behaviour's side ----------------------------------------------------------------------------------
    def provide(self, name: str, source: Callable[[], float | str]) -> None:
        """Where a DID's live value comes from, by DID name; KeyError names the node and its DIDs."""
        self._providers[self.node.did(name).id] = source

    def coding(self, name: str) -> float:
        """A coding DID's current value: its default until a tester writes it (kept over an ECUReset)."""
        try:
            return self._coding[name]
        except KeyError:
            raise KeyError(f"{self.node.node}: no coding DID {name!r} (coding DIDs: "
                           f"{', '.join(self._coding) or 'none'})") from None

    def on_routine(self, name: str, start: Callable[[], None]) -> None:
        """Call `start` when a tester starts the routine (by name; KeyError names the node and its routines)."""
        self._routine_callbacks.setdefault(self.node.routine(name).id, []).append(start)

    def on_reset(self, callback: Callable[[], None]) -> None:
        """Call `callback` when an ECUReset takes effect."""
        self._reset_callbacks.append(callback)

    @property
    def session(self) -> int:
        """The active diagnostic session (0x01 default, 0x03 extended)."""
        return self._session

    @property
    def unlocked(self) -> bool:
        """Security level 1 unlocked."""
        return self._unlocked

    # -- the station's side ------------------------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        """Something for `poll`: ISO-TP in progress, a non-default session (S3), a routine, a reset or a queued
        response. The station asks every tick: two attribute reads when idle."""
        return self._work or self.endpoint.busy

    def on_frame(self, t: float, frame_id: int, data: bytes) -> None:
        """A frame on the node's request identifier (ISO-TP) or the functional one (single frames only)."""
        if frame_id == self.node.request:
            endpoint = self.endpoint
            endpoint.on_frame(t, data)
            received = endpoint.received
            while received:
                self._answer(t, received.popleft()[1], False)
        elif frame_id == self.protocol.functional_request and data and data[0] >> 4 == 0:
            length = data[0] & 0x0F
            if 1 <= length <= 7 and len(data) > length:
                self._answer(t, bytes(data[1:1 + length]), True)

    def poll(self, t: float) -> None:
        """ISO-TP's consecutive frames and timers, queued responses, a running routine, an ECUReset, S3."""
        endpoint = self.endpoint
        endpoint.poll(t)
        self._flush(t)
        running = self._running
        if running is not None:
            if t + 1e-9 >= running.end:
                self._running = None
                self._s3_from = t
                self._respond(t, bytes([0x71, 0x01]) + running.routine.id.to_bytes(2, "big"))
            elif t + 1e-9 >= running.next_pending:
                running.next_pending = t + self._pending_every
                self._respond(t, bytes([0x7F, 0x31, RESPONSE_PENDING]))
        if self._reset_due and not self._outbox:     # its response is out: an SF goes at once
            self._reset()
        if self._session != DEFAULT_SESSION and self._running is None:
            if endpoint.busy or self._outbox:
                self._s3_from = t       # S3 runs from the end of the exchange (ISO 14229-2)
            elif t - self._s3_from > self.protocol.s3:
                self._enter_session(DEFAULT_SESSION, t)
        self._update_work()

    def _answer(self, t: float, request: bytes, functional: bool) -> None:
        response = self.handle(t, request, functional)
        if response is not None:
            self._respond(t, response)
        self._update_work()

    def _respond(self, t: float, payload: bytes) -> None:
        self._outbox.append(payload)
        self._flush(t)

    def _flush(self, t: float) -> None:
        outbox = self._outbox
        while outbox:
            try:
                self.endpoint.transmit(t, outbox[0])
            except ValueError:      # the previous response is still being sent (lengths are checked in handle)
                return
            outbox.popleft()

    def _update_work(self) -> None:
        self._work = (self._session != DEFAULT_SESSION or self._running is not None or self._reset_due
                      or bool(self._outbox))

    # -- one request -------------------------------------------------------------------------------------------
    def handle(self, t: float, request: bytes, functional: bool = False) -> bytes | None:
        """The response to one request (None: no response), in ISO 14229-1's order of checks (Figure 5, DIAG-NRC-01)."""
        if not request:
            return None
        self._s3_from = t
        sid = request[0]
        try:
            response = self._dispatch(t, sid, request)
        except _Refusal as refusal:
            self._update_work()
            if functional and refusal.code in FUNCTIONAL_SILENT:
                return None
            return bytes([0x7F, sid, refusal.code])
        self._update_work()
        if len(response) > self.params.max_length:
            return bytes([0x7F, sid, RESPONSE_TOO_LONG])
        if sid in SPRMIB_SERVICES and request[1] & 0x80 and response[0] != 0x7F:
            return None
        return response

    def _dispatch(self, t: float, sid: int, request: bytes) -> bytes:
        if self._running is not None and sid != 0x3E:
            raise _Refusal(BUSY_REPEAT_REQUEST)   # a routine's final response is owed (DIAG-NRC-01: checked first)
        handler = self._HANDLERS.get(sid)
        if handler is None:
            raise _Refusal(SERVICE_NOT_SUPPORTED)
        if self._session != EXTENDED_SESSION and sid not in DEFAULT_SESSION_SERVICES:
            raise _Refusal(SERVICE_NOT_IN_SESSION)
        if len(request) < _MIN_LENGTH[sid]:
            raise _Refusal(INCORRECT_LENGTH)
        sub = 0
        subfunctions = SUBFUNCTIONS.get(sid)
        if subfunctions is not None:
            sub = request[1] & 0x7F if sid in SPRMIB_SERVICES else request[1]
            sessions = subfunctions.get(sub)
            if sessions is None:
                raise _Refusal(SUBFUNCTION_NOT_SUPPORTED)
            if self._session not in sessions:
                raise _Refusal(SUBFUNCTION_NOT_IN_SESSION)
        return handler(self, t, request, sub)

    @staticmethod
    def _length(request: bytes, length: int) -> None:
        if len(request) != length:
            raise _Refusal(INCORRECT_LENGTH)

    # 0x10 DiagnosticSessionControl
    def _session_control(self, t: float, request: bytes, sub: int) -> bytes:
        self._length(request, 2)
        self._enter_session(sub, t)
        p2 = min(round(self.protocol.p2 * 1000), 0xFFFF)
        p2_star = min(round(self.protocol.p2_star * 100), 0xFFFF)
        return struct.pack(">BBHH", 0x50, sub, p2, p2_star)

    def _enter_session(self, session: int, t: float) -> None:
        """Every session transition locks security (ISO 14229-1 §9.2: also into the same non-default session)."""
        self._session = session
        self._unlocked = False
        self._seed = None
        self._s3_from = t

    # 0x11 ECUReset
    def _ecu_reset(self, t: float, request: bytes, sub: int) -> bytes:
        self._length(request, 2)
        self._reset_due = True      # after the response: the next poll
        return bytes([0x51, sub])

    def _reset(self) -> None:
        """The node starts again as after power-up (wrong-key count and delay cleared, DIAG-RST-02); coding and
        fault memory are kept, and a new operation cycle begins."""
        self._reset_due = False
        self.endpoint.reset()
        self._session = DEFAULT_SESSION
        self._unlocked = False
        self._seed = None
        self._failed_keys, self._delay_until = 0, None
        self._running = None
        self._started.clear()
        self.memory.new_operation_cycle()
        for callback in self._reset_callbacks:
            callback()

    # 0x14 ClearDiagnosticInformation
    def _clear(self, t: float, request: bytes, sub: int) -> bytes:
        self._length(request, 4)
        if not self.memory.clear(int.from_bytes(request[1:4], "big")):
            raise _Refusal(REQUEST_OUT_OF_RANGE)
        return b"\x54"

    # 0x19 ReadDTCInformation
    def _read_dtc(self, t: float, request: bytes, sub: int) -> bytes:
        memory = self.memory
        if sub in (0x01, 0x02):
            self._length(request, 3)
            found = memory.dtcs_by_mask(request[2])
            if sub == 0x01:
                return struct.pack(">BBBBH", 0x59, 0x01, AVAILABILITY, 0x01, len(found))
            return bytes([0x59, 0x02, AVAILABILITY]) + b"".join(
                number.to_bytes(3, "big") + bytes([status]) for number, status in found)
        self._length(request, 6)
        number, record = int.from_bytes(request[2:5], "big"), request[5]
        if not memory.known(number) or record not in _RECORDS:
            raise _Refusal(REQUEST_OUT_OF_RANGE)
        head = bytes([0x59, sub]) + request[2:5] + bytes([memory.status(number)])
        if sub == 0x04:
            return head + (memory.snapshot(number) or b"")
        return head + bytes([0x01, memory.occurrences(number)])    # extended data record 0x01: occurrences

    # 0x22 ReadDataByIdentifier
    def _read_did(self, t: float, request: bytes, sub: int) -> bytes:
        if len(request) % 2 != 1:
            raise _Refusal(INCORRECT_LENGTH)
        dids = self._dids
        found = [dids[i] for i in struct.unpack(f">{len(request) // 2}H", request[1:]) if i in dids]
        if not found:                   # ISO: an unsupported DID is left out unless none is supported
            raise _Refusal(REQUEST_OUT_OF_RANGE)
        if 1 + sum(2 + did.length for did in found) > self.params.max_length:
            raise _Refusal(RESPONSE_TOO_LONG)   # before reading a value (DIAG-NRC-01)
        parts = [b"\x62"]
        for did in found:
            data = self._value(did)
            if data is None:            # declared, but this node has no value for it now (DIAG-SVC-02)
                raise _Refusal(CONDITIONS_NOT_CORRECT)
            parts.append(did.id.to_bytes(2, "big") + data)
        return b"".join(parts)

    def _has_value(self, did: Did) -> bool:
        return did.name in self._coding or did.id in self._providers or did.name in self.node.identification

    def _value(self, did: Did) -> bytes | None:
        """A DID's bytes now: coding, else its provider's value, else its identification text; None: no value."""
        if did.name in self._coding:
            return did.encode(self._coding[did.name])
        source = self._providers.get(did.id)
        if source is not None:
            data = _saturated(did, source())
            if data is None:
                raise _Refusal(CONDITIONS_NOT_CORRECT)   # NaN or an unknown name: the ECU has no value now
            return data
        text = self.node.identification.get(did.name)
        return None if text is None else did.encode(text)

    def _snapshot_record(self) -> bytes:
        """Snapshot record 0x01 now: record number, number of DIDs, then each DID and its data (a DID without a
        value gives its default)."""
        parts = [bytes([0x01, len(self.node.snapshot)])]
        for did_id in self.node.snapshot:
            did = self._dids[did_id]
            try:
                data = self._value(did)
            except _Refusal:
                data = None
            if data is None:
                data = did.encode("" if did.type == "ascii" else did.default)
            parts.append(did_id.to_bytes(2, "big") + data)
        return b"".join(parts)

    # 0x2E WriteDataByIdentifier
    def _write_did(self, t: float, request: bytes, sub: int) -> bytes:
        did = self._dids.get(int.from_bytes(request[1:3], "big"))
        if did is None or did.name not in self._coding:
            raise _Refusal(REQUEST_OUT_OF_RANGE)
        if not self._unlocked:
            raise _Refusal(SECURITY_ACCESS_DENIED)
        self._length(request, 3 + did.length)
        value = did.decode(request[3:])
        if isinstance(value, str):           # never: ascii DIDs are no coding
            raise _Refusal(REQUEST_OUT_OF_RANGE)
        if (did.values and int(value) not in did.values.values()) or not did.in_range(value):
            raise _Refusal(REQUEST_OUT_OF_RANGE)
        self._coding[did.name] = float(value)
        return b"\x6E" + request[1:3]

    # 0x27 SecurityAccess
    def _security(self, t: float, request: bytes, sub: int) -> bytes:
        if sub == 0x01:
            if self._delay_until is not None:
                if t < self._delay_until:
                    raise _Refusal(DELAY_NOT_EXPIRED)
                self._delay_until, self._failed_keys = None, 0
            if self._unlocked:
                return b"\x67\x01\x00\x00\x00\x00"
            fresh = self._last_seed
            while fresh in (self._last_seed, b"\0\0\0\0"):    # never 0, never the previous one (DIAG-SEC-01)
                fresh = self._seeds.getrandbits(32).to_bytes(4, "big")
            self._seed = self._last_seed = fresh
            return b"\x67\x01" + fresh
        self._length(request, 6)
        seed, self._seed = self._seed, None      # a seed answers one key
        if seed is None:
            raise _Refusal(REQUEST_SEQUENCE_ERROR)
        if request[2:] == documented_key(seed, self.node.security_constant):
            self._unlocked, self._failed_keys = True, 0
            return b"\x67\x02"
        self._failed_keys += 1
        if self._failed_keys >= self.protocol.security_attempts:
            self._delay_until = t + self.protocol.security_delay
            raise _Refusal(EXCEEDED_ATTEMPTS)
        raise _Refusal(INVALID_KEY)

    # 0x31 RoutineControl
    def _routine_control(self, t: float, request: bytes, sub: int) -> bytes:
        if len(request) < 4:
            raise _Refusal(INCORRECT_LENGTH)
        routine_id = int.from_bytes(request[2:4], "big")
        routine = next((r for r in self.node.routines if r.id == routine_id), None)
        if routine is None:
            raise _Refusal(REQUEST_OUT_OF_RANGE)
        if not self._unlocked:
            raise _Refusal(SECURITY_ACCESS_DENIED)
        if sub == 0x03:
            if routine_id not in self._started:
                raise _Refusal(REQUEST_SEQUENCE_ERROR)
            return b"\x71\x03" + request[2:4]
        self._started.add(routine_id)
        for start in self._routine_callbacks.get(routine_id, ()):
            start()
        if routine.duration <= 0:
            return b"\x71\x01" + request[2:4]
        self._running = _Running(routine, t + routine.duration, t + self._pending_every)
        return bytes([0x7F, 0x31, RESPONSE_PENDING])   # the final response comes from poll, SPRMIB or not

    # 0x3E TesterPresent
    def _tester_present(self, t: float, request: bytes, sub: int) -> bytes:
        self._length(request, 2)
        return b"\x7E\x00"

    _HANDLERS: dict[int, Callable[[UdsServer, float, bytes, int], bytes]] = {
        0x10: _session_control, 0x11: _ecu_reset, 0x14: _clear, 0x19: _read_dtc, 0x22: _read_did,
        0x27: _security, 0x2E: _write_did, 0x31: _routine_control, 0x3E: _tester_present,
    }


def _saturated(did: Did, value: float | str) -> bytes | None:
    """A provider's value as the DID's bytes, saturated to its type as an ECU's fixed-point conversion is; None
    for NaN or a name that is none of the enumeration's."""
    try:
        return did.encode(value)
    except ValueError:
        if isinstance(value, str) or math.isnan(value):
            return None
    bits = 8 * did.length
    signed = did.type.startswith("int")
    low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    raw = (value - did.offset) / did.scale
    number = high if raw > high else low if raw < low else round(raw)
    return number.to_bytes(did.length, "big", signed=signed)
