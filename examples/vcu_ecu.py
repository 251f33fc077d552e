"""A stand-alone VCU for the 4WIS EV, written from the contract documents alone.

Node `VCU` of `dbc/chassis.dbc`, built only from README.md, `docs/contract/common.md`, `docs/contract/vcu.md`,
`docs/contract/vcu-4ws.md`, `docs/spec/*.md` and the DBC, as an outside supplier would (issue 13). It reads
`DRV_MotionRequest`, `DRV_Steering`, the four `WHL_Status_xx` and `IMU_Motion` and sends `VCU_WheelCmd_FL/FR/RL/RR`
(10 ms), `VCU_VehicleState` and `VCU_RotationCentre` (20 ms). Comments cite the requirement ids.

End-to-end protection as an AUTOSAR stack does it (docs/spec/e2e.md, COM-E2E-*, COM-RX-*): each message's
profile and parameters are the DBC's `E2E_*` attributes (read through cantools), the CRC and the counter's
increment are the `autosar-e2e` library's (P01, P02, P05, P11), and each received message has the profile's
check (OK, OKSOMELOST, REPEATED, WRONGSEQUENCE, ERROR) and the E2E state machine (NODATA, INIT, VALID, INVALID);
a frame is applied only when its status is OK or OKSOMELOST and the state is VALID after it.

Run it as the external VCU of the bench (three processes on one host):

    bench plant --interface udp_multicast --channel 239.255.1.2 --external VCU &
    python examples/vcu_ecu.py --interface udp_multicast --channel 239.255.1.2
    bench run --interface udp_multicast --channel 239.255.1.2 --external all --dut VCU

Rear steering at speed (vcu-4ws.md VCU-4WS-10): the law its coding `RearSteerLaw` (DID 0xFDC0) names, in force
from the next 10 ms task: FEEDFORWARD (VCU-4WS-02, the default, as delivered), OFF (2WS, delta_r = 0) and FEEDBACK
(delta_r = -X + C2 u r with IMU_Motion.YawRate, FEEDFORWARD without a valid IMU_Motion); all three are this VCU's.

Diagnostics (vcu.md VCU-DIAG-01..04, docs/contract/diagnostics.md): a UDS server on ISO-TP (`examples/uds_server.py`,
shared by the three examples) on 0x700/0x708 and the functional 0x7DF: sessions, ECUReset, the fault memory fed at
every task with the VcuFault it evaluated (one DTC per value but OK), identification and live DIDs, the coding,
SecurityAccess with the documented seed/key, routine 0x0204 StraightAheadLearn (precondition VehicleSpeed below
0.05 m/s, else NRC 0x22; it changes nothing: the bench's wheels have no trim). ECUReset restarts the control and the
receivers as at power-up (its AliveCounters carry on); coding and fault memory are kept (`--nvm FILE`: also across
process restarts). The ISO-TP layer (can-isotp) runs inside the 10 ms task and never blocks: the task, the bus's
only reader, hands it the frames of 0x700 and 0x7DF it drains and calls the server's `poll()` after its evaluation,
so the periodic frames keep their grid (they go out first, at the task's start) and no second reader or thread
competes with it for the bus or the interpreter. A request is answered within one task (10 ms) of its last frame,
well within P2 = 50 ms; a diagnostic frame never reaches the E2E receivers (its identifier is none of theirs). On
socketcan the kernel's acceptance filters pass the two diagnostic identifiers too.

Diagnostic defect for checking a tester (off by default): `--diag-defect snapshot-stale`: a DTC's snapshot record
(ReadDTCInformation 0x04) keeps the values of its first occurrence since power-up; later occurrences, also after a
ClearDiagnosticInformation, show that old record instead of their own (DIAG-DTC-05: "replacing the previous record").

It prints a line with `running` once it is on the bus; Ctrl-C (SIGINT) stops it. Needs python-can, cantools,
autosar-e2e (import name `e2e`), can-isotp (import name `isotp`) and the standard library only; nothing of the bench.
"""

from __future__ import annotations

import argparse
import math
import signal
import socket
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import can
import cantools
from e2e import p01, p02, p05, p11

if str(Path(__file__).resolve().parent) not in sys.path:
    sys.path.insert(0, str(Path(__file__).resolve().parent))  # the examples' shared diagnostic server
import uds_server  # noqa: E402

# --- Vehicle A (docs/spec/vehicles.md A, vcu.md symbols, vcu-4ws.md symbols) ---------------------------------
K = 0.555  # half track, m
L = 1.38  # half wheelbase, m (docs/spec/formulas.md §2's L)
WHEEL_RADIUS = 0.281  # m
RPM_PER_MPS = 30.0 / (math.pi * WHEEL_RADIUS)  # 33.983 (vcu.md symbols)
HANDWHEEL_RATIO = 15.0
WHEELS: dict[str, tuple[float, float]] = {"FL": (-K, L), "FR": (K, L), "RL": (-K, -L), "RR": (K, -L)}
MASS, A_CG, B_CG, C_F, C_R = 900.0, 1.38, 1.38, 45000.0, 55000.0  # vcu-4ws.md symbols
WHEELBASE = A_CG + B_CG  # 2.76 m, vcu-4ws.md's L

# --- Limits and thresholds ------------------------------------------------------------------------------------
MAX_RPM = 1500.0  # VCU-LIM-01
MAX_YAW_DEG_S = 120.0  # VCU-LIM-01
CENTRE_TOL = 0.01  # m, VCU-FLT-04 / VCU-FLT-05
SWITCH_SPEED = 20.0 / 3.6  # m/s, VCU-MODE-06 / VCU-4WS-04
WHEEL_GRACE_S = 0.1  # VCU-FLT-07
RANGE_END = 5242.87  # m, VCU-OUT-07

NORMAL, LATERAL, ADAPTIVE, PIVOT = 0, 1, 2, 3
OK, CENTRE_AT_ORIGIN, CENTRE_ON_WHEEL, ANGLE_OVER_90, REQUEST_INVALID, REQUEST_TIMEOUT, WHEEL_FAULT = range(7)

# --- Rear-steering laws (vcu-4ws.md VCU-4WS-10; RearSteerLaw 0xFDC0, vcu.md VCU-DIAG-02) ----------------------
LAW_OFF, LAW_FEEDFORWARD, LAW_FEEDBACK = 0, 1, 2
C1, C2 = 1.0, MASS * B_CG / (C_F * WHEELBASE) + MASS * A_CG / (C_R * WHEELBASE)  # FEEDBACK, C2 = 0.018182 s^2/m
LEARN_MAX_SPEED = 0.05  # m/s: VCU-DIAG-03's precondition (VehicleSpeed 0xFD00)
#: DIAG-ID-01: this VCU's own identification (the VIN is the vehicle's, programmed at the end of the line: --vin)
IDENTIFICATION = {"SparePartNumber": "VCU-EX0001", "EcuSerialNumber": "VCU-EX000001",
                  "VehicleIdentificationNumber": "BENCH000000000001", "SoftwareVersionNumber": "EX-2.0"}

TASK_S = 0.010  # VCU-GEN-02: inputs evaluated at least every 10 ms (each task, after its frames are sent)
#: The messages the VCU reads (VCU-GEN-01: its receivers); the bus delivers only these (receive_filters)
INPUTS = ("DRV_MotionRequest", "DRV_Steering", "IMU_Motion", *(f"WHL_Status_{w}" for w in WHEELS))


# ==============================================================================================================
# E2E protection: AUTOSAR E2E by the autosar-e2e library, configured from the DBC (COM-E2E-*, docs/spec/e2e.md)
# ==============================================================================================================
#: A message's E2E parameters are DBC attributes named "E2E_" + the AUTOSAR parameter (E2E_Profile, E2E_DataID,
#: E2E_MaxDeltaCounter, ...); what a message does not set is the database's default (BA_DEF_DEF_). A profile
#: reads only the parameters it has (P02: E2E_DataIDList, no E2E_Offset or E2E_DataID; P05: no E2E_DataIDMode).
E2E_ATTRIBUTE = "E2E_"


class E2EConfigError(ValueError):
    """The DBC configures a message's protection in a way no profile of the library can use."""


@dataclass(frozen=True)
class Layout:
    """A profile as the library lays its header out, from the header's first byte (E2E_Offset / 8; P02: byte 0):
    the CRC's bytes, the counter's byte and bits, and how many counter values there are (the library's
    increment wraps after the last: P01 and P11 count 0-14, P02 0-15, P05 0-255)."""

    protect: Callable[..., None]
    check: Callable[..., bool]
    crc_bytes: int
    counter_byte: int
    counter_mask: int
    counter_values: int
    modes: dict[str, int] = field(default_factory=dict)  # E2E_DataIDMode -> the library's constant
    has_offset: bool = True
    data_id_list: bool = False  # P02: 16 Data IDs (E2E_DataIDList), one per counter value, not one E2E_DataID


LAYOUTS = {
    "P01": Layout(p01.e2e_p01_protect, p01.e2e_p01_check, 1, 1, 0x0F, 15,
                  {"BOTH": p01.E2E_P01_DATAID_BOTH, "ALT": p01.E2E_P01_DATAID_ALT, "LOW": p01.E2E_P01_DATAID_LOW,
                   "NIBBLE": p01.E2E_P01_DATAID_NIBBLE}),
    "P02": Layout(p02.e2e_p02_protect, p02.e2e_p02_check, 1, 1, 0x0F, 16, has_offset=False, data_id_list=True),
    "P05": Layout(p05.e2e_p05_protect, p05.e2e_p05_check, 2, 2, 0xFF, 256),
    "P11": Layout(p11.e2e_p11_protect, p11.e2e_p11_check, 1, 1, 0x0F, 15,
                  {"BOTH": p11.E2E_P11_DATAID_BOTH, "NIBBLE": p11.E2E_P11_DATAID_NIBBLE}),
}


def e2e_attributes(db: cantools.database.Database, message: cantools.database.Message) -> dict[str, object]:
    """The message's E2E_* attributes by parameter name: its own value, else the database's default. cantools
    gives a message's ENUM value as the index of its choice and a default as the choice itself: both become
    the choice (E2E_Profile "P11", E2E_DataIDMode "BOTH")."""
    definitions = db.dbc.attribute_definitions if db.dbc is not None else {}
    values = {name[len(E2E_ATTRIBUTE):]: _choice(definition, definition.default_value)
              for name, definition in definitions.items()
              if name.startswith(E2E_ATTRIBUTE) and definition.default_value is not None}
    own = message.dbc.attributes if message.dbc is not None else {}
    values.update({name[len(E2E_ATTRIBUTE):]: _choice(attribute.definition, attribute.value)
                   for name, attribute in own.items() if name.startswith(E2E_ATTRIBUTE)})
    return values


def _choice(definition: object, value: object) -> object:
    choices = getattr(definition, "choices", None)
    if getattr(definition, "type_name", None) == "ENUM" and choices and isinstance(value, int):
        return choices[value] if isinstance(choices, list) else choices.get(value, value)
    return value


@dataclass(frozen=True)
class E2EConfig:
    """One message's AUTOSAR E2E configuration (E2E_PXXConfigType and E2E_SMConfigType), every value from the DBC.

    `protect` and `check` are the library's (COM-E2E-02: the CRC is the profile's, computed by the library);
    this VCU only writes the counter it sends and reads the counter it receives, in the field where the
    library's layout puts it."""

    message: str
    profile: str
    layout: Layout
    data_id: int | bytes  # P02: the DataIDList
    offset: int  # byte of the header's first byte (E2E_Offset / 8)
    library_args: dict[str, int]  # length (E2E_DataLength / 8, 0: the whole frame), offset, data_id_mode
    max_delta_counter: int
    window_size: int
    min_ok: dict[str, int]  # per state (INIT, VALID, INVALID): MinOkState*
    max_error: dict[str, int]  # per state: MaxErrorState*
    nibble: bool = False  # E2E_DataIDMode NIBBLE: the library also writes the Data ID's bits 8-11 (P01, P11)

    @property
    def counter_values(self) -> int:
        return self.layout.counter_values

    def counter_of(self, data: bytes | bytearray) -> int:
        """The counter a frame carries (in the library's layout)."""
        return data[self.offset + self.layout.counter_byte] & self.layout.counter_mask

    def protect(self, data: bytearray, previous: int) -> None:
        """COM-E2E-01/02: the counter after `previous` (the library increments it and wraps it) and the CRC,
        written in place; `data` holds the frame's signals, the header's bits 0."""
        index, mask = self.offset + self.layout.counter_byte, self.layout.counter_mask
        data[index] = (data[index] & ~mask & 0xFF) | (previous & mask)
        self.layout.protect(data, self.data_id, increment_counter=True, **self.library_args)

    def check(self, data: bytes | bytearray) -> bool:
        """Whether the frame's CRC is right (the library's check; it wants a writable buffer)."""
        return self.layout.check(bytearray(data), self.data_id, **self.library_args)

    def header_bits(self) -> tuple[set[int], set[int], set[int]]:
        """The CRC's bits, the counter's bits and every bit the library writes (Intel numbering: bit 0 = the LSB
        of byte 0). In the NIBBLE modes the library also writes the Data ID's bits 8-11 into the counter's byte."""
        first = 8 * self.offset
        crc = set(range(first, first + 8 * self.layout.crc_bytes))
        counter_first = 8 * (self.offset + self.layout.counter_byte)
        counter = {counter_first + bit for bit in range(8) if self.layout.counter_mask >> bit & 1}
        written = crc | counter
        if self.nibble:  # into the upper half of the counter's byte
            written |= set(range(counter_first, counter_first + 8))
        return crc, counter, written


def e2e_config(db: cantools.database.Database, message: cantools.database.Message) -> E2EConfig | None:
    """The protection the DBC gives a message, or None for E2E_Profile "None" (an unprotected message: judged on
    its length and ranges only). An E2EConfigError names the message and the attribute."""
    values = e2e_attributes(db, message)
    name = message.name
    profile = str(values.get("Profile", "None"))
    if profile == "None":
        return None
    if profile not in LAYOUTS:
        raise E2EConfigError(f"{name}: E2E_Profile {profile!r} is none of {', '.join(LAYOUTS)}")
    layout = LAYOUTS[profile]

    def integer(parameter: str, lo: int, hi: int) -> int:
        if parameter not in values:
            raise E2EConfigError(f"{name}: no E2E_{parameter}, and the database defines no default for it")
        raw = values[parameter]
        try:
            number = int(raw, 0) if isinstance(raw, str) else int(raw)  # type: ignore[call-overload]
        except (TypeError, ValueError):
            raise E2EConfigError(f"{name}: E2E_{parameter} {raw!r} is not a whole number") from None
        if not lo <= number <= hi:
            raise E2EConfigError(f"{name}: E2E_{parameter} {number} is outside {lo}-{hi}")
        return number

    frame_bits = 8 * message.length
    data_id: int | bytes
    if layout.data_id_list:
        try:
            data_id = bytes(int(part, 16) for part in str(values.get("DataIDList", "")).replace(",", " ").split())
        except ValueError:
            data_id = b""
        if len(data_id) != 16:
            raise E2EConfigError(f"{name}: E2E_DataIDList {values.get('DataIDList')!r} is not 16 hex bytes")
    else:
        data_id = integer("DataID", 0, 0xFFFF)
    offset_bits = integer("Offset", 0, frame_bits - 8) if layout.has_offset else 0
    length_bits = integer("DataLength", 0, frame_bits)
    if offset_bits % 8 or length_bits % 8:
        raise E2EConfigError(f"{name}: E2E_Offset {offset_bits} and E2E_DataLength {length_bits} must be whole bytes")
    library_args = {"length": length_bits // 8}
    if layout.has_offset:
        library_args["offset"] = offset_bits // 8
    mode = ""
    if layout.modes:
        mode = str(values.get("DataIDMode", ""))
        if mode not in layout.modes:
            raise E2EConfigError(f"{name}: E2E_DataIDMode {mode!r} is none of {', '.join(layout.modes)} for {profile}")
        library_args["data_id_mode"] = layout.modes[mode]
    window = integer("WindowSize", 1, 255)
    states = ("Init", "Valid", "Invalid")
    config = E2EConfig(
        message=name, profile=profile, layout=layout, data_id=data_id, offset=offset_bits // 8,
        library_args=library_args,
        max_delta_counter=integer("MaxDeltaCounter", 1, layout.counter_values - 1),
        window_size=window,
        min_ok={state.upper(): integer(f"MinOkState{state}", 0, window) for state in states},
        max_error={state.upper(): integer(f"MaxErrorState{state}", 0, window) for state in states},
        nibble=mode == "NIBBLE",
    )
    _check_header_place(message, config, length_bits or frame_bits)
    return config


def _check_header_place(message: cantools.database.Message, config: E2EConfig, covered_bits: int) -> None:
    """The header lies in the frame and in what the CRC covers, and no signal lies on it but the CRC's and the
    counter's own (the library writes those bits: a signal there would be overwritten)."""
    crc, counter, written = config.header_bits()
    if max(written) >= min(8 * message.length, covered_bits):
        raise E2EConfigError(f"{message.name}: the {config.profile} header (bits {min(written)}-{max(written)}) is "
                             f"not within the frame's {covered_bits // 8} protected bytes")
    for sig in message.signals:
        if sig.byte_order != "little_endian":
            continue  # COM-FRM-01: the contract's signals are Intel
        bits = set(range(sig.start, sig.start + sig.length))
        if bits & written and bits not in (crc, counter):
            raise E2EConfigError(f"{message.name}: signal {sig.name} (bits {sig.start}-{sig.start + sig.length - 1})"
                                 f" lies on the {config.profile} header (bits {min(written)}-{max(written)})")


# --- The receiver (COM-RX-01, docs/spec/e2e.md) ---------------------------------------------------------------
class Status:
    """The profile check's status of one received frame (E2E_PXXCheckStatusType)."""

    OK, OKSOMELOST, REPEATED, WRONGSEQUENCE, ERROR = "OK", "OKSOMELOST", "REPEATED", "WRONGSEQUENCE", "ERROR"


class SMState:
    """The E2E state machine's states (E2E_SMStateType)."""

    NODATA, INIT, VALID, INVALID = "NODATA", "INIT", "VALID", "INVALID"


#: Statuses the state machine's window counts as OK; ERROR counts as an error, REPEATED and WRONGSEQUENCE as
#: neither (they take their place in the window all the same).
OK_STATUSES = (Status.OK, Status.OKSOMELOST)


class E2EReceiver:
    """The receiver of one message (COM-RX-01, COM-RX-02): the profile's check, the E2E state machine and the
    consumer's rule: a frame's values are applied only when its status is OK or OKSOMELOST and the state
    machine is VALID after it, and then only when every signal is within its DBC range (COM-VAL-01).

    The check and the state machine run once per received frame; that a message stopped coming is the
    deadline monitoring of `timed_out` (COM-RX-02), not theirs: there is no resynchronisation on a gap."""

    def __init__(self, db: cantools.database.Database, message: cantools.database.Message) -> None:
        self.message = message
        self.e2e = e2e_config(db, message)  # None: an unprotected message, judged on length and ranges only
        self.cycle_s = message.cycle_time / 1000.0
        # the check's state (E2E_PXXCheckInit): the counter before a first 0, so that 0 is in sequence
        self.last_counter = self.e2e.counter_values - 1 if self.e2e is not None else 0
        # the state machine (E2E_SMCheckInit): NODATA, an empty window of the last WindowSize statuses
        self.state = SMState.NODATA
        self.window: deque[str] = deque(maxlen=self.e2e.window_size if self.e2e is not None else 1)
        self.last_accepted_t: float | None = None
        self.values: dict[str, float] | None = None
        self.last_rejected = False  # the last received frame was rejected ("invalid" in vcu.md)
        self.accepted = self.rejected = 0  # for --stats
        self.statuses: Counter[str] = Counter()  # status -> frames, for --stats

    def on_frame(self, data: bytes, t: float) -> bool:
        """Judge one frame; return whether it was accepted and its values applied."""
        if self.e2e is None:
            applicable = len(data) == self.message.length  # COM-RX-01: the DBC length
        else:
            status = self.check(data)
            self.statuses[status] += 1
            state = self.sm_check(status)  # every status enters the state machine, ERROR included
            applicable = status in OK_STATUSES and state == SMState.VALID
        accepted = applicable and self._apply_if_in_range(data, t)
        self.last_rejected = not accepted
        self.accepted += accepted
        self.rejected += not accepted
        return accepted

    def timed_out(self, now: float) -> bool:
        """COM-RX-02: no applied frame for more than 3 cycles, or never one since power-up."""
        return self.last_accepted_t is None or now - self.last_accepted_t > 3 * self.cycle_s

    def check(self, data: bytes) -> str:
        """The profile's check of one frame (E2E_PXXCheck with new data): ERROR when the length is not the DBC's
        or the library finds the CRC wrong (the counter is not read: the reference counter stays); else the
        counter's step from the previous frame's, modulo the counter's values: 1 OK, 0 REPEATED,
        2 to E2E_MaxDeltaCounter OKSOMELOST, any other WRONGSEQUENCE (too far, back, a second sender). Every
        frame but an ERROR becomes the reference."""
        assert self.e2e is not None
        if len(data) != self.message.length or not self.e2e.check(data):
            return Status.ERROR
        counter = self.e2e.counter_of(data)
        if counter >= self.e2e.counter_values:  # P01/P11: 15 is never sent (the library's check refuses it too)
            return Status.ERROR
        step = (counter - self.last_counter) % self.e2e.counter_values
        self.last_counter = counter
        if step == 1:
            return Status.OK
        if step == 0:
            return Status.REPEATED
        return Status.OKSOMELOST if step <= self.e2e.max_delta_counter else Status.WRONGSEQUENCE

    def sm_check(self, status: str) -> str:
        """The E2E state machine (E2E_SMCheck), one status in, the state after it out. NODATA leaves for INIT at
        the first status that is not ERROR, with the window emptied and that status not in it. In the other
        states the status enters the window (the oldest of WindowSize leaves) and the window's OK count (OK and
        OKSOMELOST) and ERROR count decide: INIT -> VALID with at least MinOkStateInit OK and at most
        MaxErrorStateInit ERROR, -> INVALID with more ERROR than that; VALID stays with at least MinOkStateValid
        OK and at most MaxErrorStateValid ERROR, else -> INVALID; INVALID -> VALID with at least
        MinOkStateInvalid OK and at most MaxErrorStateInvalid ERROR."""
        e2e = self.e2e
        assert e2e is not None
        if self.state == SMState.NODATA:
            if status != Status.ERROR:
                self.window.clear()
                self.state = SMState.INIT
            return self.state
        self.window.append(status)
        ok = sum(1 for s in self.window if s in OK_STATUSES)
        errors = self.window.count(Status.ERROR)
        fits = ok >= e2e.min_ok[self.state] and errors <= e2e.max_error[self.state]
        if self.state == SMState.INIT:
            if fits:
                self.state = SMState.VALID
            elif errors > e2e.max_error[SMState.INIT]:
                self.state = SMState.INVALID
        elif self.state == SMState.VALID:
            if not fits:
                self.state = SMState.INVALID
        elif fits:  # INVALID
            self.state = SMState.VALID
        return self.state

    def _apply_if_in_range(self, data: bytes, t: float) -> bool:
        """COM-VAL-01 / COM-RX-01: a frame with a signal outside its DBC range is rejected, no E2E error."""
        values = self.message.decode(bytes(data), decode_choices=False)
        for sig in self.message.signals:
            value = values[sig.name]
            if not math.isfinite(value):
                return False
            if sig.minimum is not None and value < sig.minimum - 1e-9:
                return False
            if sig.maximum is not None and value > sig.maximum + 1e-9:
                return False
        self.values = values
        self.last_accepted_t = t
        return True


class E2ESender:
    """COM-E2E-01/02/03: write the signals, then the library writes the next counter and the CRC. The counter
    advances when the frame was transmitted (`sent`): a frame the driver refused is not on the bus, and its
    counter value goes with the next frame, so that receivers see neither a skipped nor a repeated value."""

    def __init__(self, db: cantools.database.Database, message: cantools.database.Message) -> None:
        self.message = message
        self.e2e = e2e_config(db, message)
        # the counter of the last transmitted frame; the library's increment makes the first frame's 0
        # (COM-E2E-01: the first value after power-up is free)
        self.counter = self.e2e.counter_values - 1 if self.e2e is not None else 0

    def frame(self, values: dict[str, float]) -> can.Message:
        # the CRC's and the counter's signals get their start value: protect writes over them
        raw = {s.name: _raw_on_grid(s, values.get(s.name, s.initial or 0)) for s in self.message.signals}
        data = bytearray(self.message.encode(raw, scaling=False, strict=False))  # COM-FRM-01: unused bits 0
        if self.e2e is not None:
            self.e2e.protect(data, self.counter)
        return can.Message(arbitration_id=self.message.frame_id, data=bytes(data), is_extended_id=False)

    def sent(self, frame: can.Message) -> None:
        """The frame went out: the next one carries the next counter value (COM-E2E-01)."""
        if self.e2e is not None:
            self.counter = self.e2e.counter_of(frame.data)


def _raw_on_grid(signal: cantools.database.Signal, value: float) -> int:
    """COM-VAL-01: a finite value on the raw grid within [min|max]; a non-finite value sends the start value."""
    if not math.isfinite(value):
        return int(signal.raw_initial or 0)
    raw = round((value - signal.offset) / signal.scale)
    lo = math.ceil((signal.minimum - signal.offset) / signal.scale - 1e-9)
    hi = math.floor((signal.maximum - signal.offset) / signal.scale + 1e-9)
    return int(min(max(raw, lo), hi))


# ==============================================================================================================
# Kinematics: rotation about a point (VCU-MODE-01, docs/spec/formulas.md §2)
# ==============================================================================================================
@dataclass(frozen=True)
class Command:
    """One executed command: what the VCU sends while it is the last valid one (VCU-OUT-*)."""

    mode: int
    angles: dict[str, float]  # deg, (-90, +90]
    speeds: dict[str, float]  # rpm
    curvature: float  # deg, VCU-OUT-03
    yaw_rate: float  # deg/s, VCU-OUT-04
    centre: tuple[float, float]  # m, as sent (VCU-OUT-06/07)
    forward: tuple[float, float]  # direction positive v moves the centre (VCU-OUT-05 sign)


POWER_UP = Command(  # VCU-GEN-03
    mode=NORMAL,
    angles={w: 0.0 for w in WHEELS},
    speeds={w: 0.0 for w in WHEELS},
    curvature=0.0,
    yaw_rate=0.0,
    centre=(RANGE_END, 0.0),
    forward=(0.0, 1.0),
)


def wheel_angle(centre: tuple[float, float], wheel: tuple[float, float]) -> float:
    """VCU-MODE-01: beta_i = atan((y_i - y)/(x - x_i)) in degrees, +90 at x = x_i."""
    (x, y), (xi, yi) = centre, wheel
    return 90.0 if x == xi else math.degrees(math.atan((yi - y) / (x - xi)))


def rotation(centre: tuple[float, float], v_o: float) -> tuple[dict[str, float], dict[str, float], float]:
    """Wheel angles (deg), speeds (rpm) and omega (rad/s, clockwise) about S at centre speed v_o (VCU-MODE-01)."""
    x, y = centre
    r_o = math.hypot(x, y)
    omega = 0.0 if v_o == 0.0 else v_o / r_o  # VCU-MODE-03: v_o = 0 needs no division
    angles: dict[str, float] = {}
    speeds: dict[str, float] = {}
    for name, (xi, yi) in WHEELS.items():
        beta = wheel_angle(centre, (xi, yi))
        b = math.radians(beta)
        # projection of the wheel's rigid-body velocity on its heading (VCU-MODE-01, erratum E1 corrected)
        rpm = RPM_PER_MPS * omega * ((yi - y) * math.sin(b) + (x - xi) * math.cos(b))
        if round(beta, 2) <= -90.0:  # COM-VAL-02 / VCU-MODE-01: -90 is not a bus angle: +90, rolling the other way
            beta, rpm = 90.0, -rpm   # what the bus carries: within half its 0.01 deg step of beta + 180
        angles[name], speeds[name] = beta, rpm
    return angles, speeds, omega


def centre_at_infinity(heading_deg: float) -> tuple[float, float]:
    """VCU-OUT-07: (cos theta, -sin theta) scaled until one coordinate reaches the range end."""
    dx, dy = math.cos(math.radians(heading_deg)), -math.sin(math.radians(heading_deg))
    scale = RANGE_END / max(abs(dx), abs(dy))
    return _snap(dx * scale), _snap(dy * scale)


def _snap(value: float) -> float:
    """Clear the float noise of cos(90 deg) so that LATERAL sends exactly (0, -5242.87)."""
    return 0.0 if abs(value) < 1e-6 else value


def saturate_centre(centre: tuple[float, float]) -> tuple[float, float]:
    """VCU-OUT-06: each coordinate saturated separately to +/-5242.87 m."""
    x, y = centre
    return max(-RANGE_END, min(RANGE_END, x)), max(-RANGE_END, min(RANGE_END, y))


def translation(mode: int, heading_deg: float, v: float, curvature: float) -> Command:
    """A translation: every wheel at one angle, every speed n = 30 v/(pi r) (VCU-MODE-07, VCU-MODE-08)."""
    theta = math.radians(heading_deg)
    return Command(
        mode=mode,
        angles={w: heading_deg for w in WHEELS},
        speeds={w: RPM_PER_MPS * v for w in WHEELS},
        curvature=curvature,
        yaw_rate=0.0,  # VCU-OUT-04: 0 for a translation
        centre=centre_at_infinity(heading_deg),
        forward=(math.sin(theta), math.cos(theta)),
    )


# ==============================================================================================================
# Requests: one plan per mode (VCU-REQ-*, VCU-MODE-*, VCU-4WS-*)
# ==============================================================================================================
@dataclass(frozen=True)
class Plan:
    """A request turned into a centre (or a translation) before the fault checks of VCU-FLT-03 step 4."""

    mode: int
    v: float  # TargetSpeed, m/s
    centre: tuple[float, float] | None = None  # None: a translation
    heading: float = 0.0  # common heading of a translation, deg
    curvature: float = 0.0  # X, deg (VCU-OUT-03)
    steered_by_handwheel: bool = False  # NORMAL / ADAPTIVE: the checks of VCU-FLT-06 apply
    rear_axle_angle: float = 0.0  # ADAPTIVE at speed, deg


def zero_sideslip_ratio(u: float) -> float:
    """VCU-4WS-02: k(u) = (-b + m a u^2/(C_r L)) / (a + m b u^2/(C_f L)) (docs/spec/formulas.md §5.3)."""
    u2 = u * u
    return (-B_CG + MASS * A_CG * u2 / (C_R * WHEELBASE)) / (A_CG + MASS * B_CG * u2 / (C_F * WHEELBASE))


def plan_pivot(pivot_x: float, pivot_y: float, v: float) -> Plan:
    """VCU-MODE-02: S = (PivotX, PivotY) as received, v_o = v; VCU-OUT-03: X = heading at (0, L) about S."""
    if (pivot_x, pivot_y) == (0.0, L):
        curvature = 0.0
    else:
        curvature = wheel_angle((pivot_x, pivot_y), (0.0, L))
    return Plan(mode=PIVOT, v=v, centre=(pivot_x, pivot_y), curvature=curvature)


def plan_normal(handwheel: float, v: float) -> Plan:
    """VCU-MODE-04: X = HandWheelAngle/15, S = (2L/tan X, -L); X = 0 is straight (VCU-MODE-07)."""
    x_angle = handwheel / HANDWHEEL_RATIO
    if x_angle == 0.0:
        return Plan(mode=NORMAL, v=v, heading=0.0, curvature=0.0, steered_by_handwheel=True)
    centre = (2 * L / _tan_deg(x_angle), -L)
    return Plan(mode=NORMAL, v=v, centre=centre, curvature=x_angle, steered_by_handwheel=True)


def plan_adaptive(handwheel: float, v: float, u: float, law: int = LAW_FEEDFORWARD,
                  yaw_rate: float | None = None) -> Plan:
    """VCU-MODE-06 / VCU-4WS-04: below 20 km/h of the vehicle's speed u VCU-MODE-05, at and above the coded law of
    VCU-4WS-10 (FEEDFORWARD VCU-4WS-02; OFF; FEEDBACK with `yaw_rate`, deg/s of the latest valid IMU_Motion,
    FEEDFORWARD when there is none)."""
    x_angle = handwheel / HANDWHEEL_RATIO
    if u < SWITCH_SPEED:
        if x_angle == 0.0:  # VCU-MODE-07
            return Plan(mode=ADAPTIVE, v=v, heading=0.0, curvature=0.0, steered_by_handwheel=True)
        centre = (L / _tan_deg(x_angle), 0.0)  # VCU-MODE-05: centre on y = 0, rear mirrors front
        return Plan(mode=ADAPTIVE, v=v, centre=centre, curvature=x_angle, steered_by_handwheel=True)
    if law == LAW_OFF:
        rear = 0.0  # VCU-4WS-10 OFF (2WS): the centre on the rear-axle line, as NORMAL
    elif law == LAW_FEEDBACK and yaw_rate is not None:
        rear = -C1 * x_angle + C2 * abs(u) * yaw_rate  # VCU-4WS-10 FEEDBACK ([P3] §2, Fig. 3b), degrees
    else:
        rear = zero_sideslip_ratio(u) * x_angle  # VCU-4WS-02: delta_r = k(u) X
    tan_front, tan_rear = _tan_deg(x_angle), _tan_deg(rear)
    if tan_front == tan_rear:  # VCU-4WS-05: parallel headings are a translation (straight included)
        return Plan(mode=ADAPTIVE, v=v, heading=x_angle, curvature=x_angle, steered_by_handwheel=True,
                    rear_axle_angle=rear)
    x_s = WHEELBASE / (tan_front - tan_rear)  # VCU-4WS-05: perpendiculars at the axle centres (0, +/-L)
    y_s = L - x_s * tan_front
    return Plan(mode=ADAPTIVE, v=v, centre=(x_s, y_s), curvature=x_angle, steered_by_handwheel=True,
                rear_axle_angle=rear)


def plan_lateral(v: float) -> Plan:
    """VCU-MODE-08: every wheel at +90 deg, sign of v in the speed; CurvatureAngle +90 (VCU-OUT-03)."""
    return Plan(mode=LATERAL, v=v, heading=90.0, curvature=90.0)


def _tan_deg(angle: float) -> float:
    return math.tan(math.radians(angle))


def centre_fault(plan: Plan) -> int:
    """VCU-FLT-03 step 4: CENTRE_AT_ORIGIN, then CENTRE_ON_WHEEL, then ANGLE_OVER_90."""
    if plan.steered_by_handwheel and (abs(plan.curvature) >= 90.0 or abs(plan.rear_axle_angle) >= 90.0):
        return ANGLE_OVER_90  # VCU-FLT-06 (|X| >= 90, or the rear angle at speed reaches 90)
    if plan.centre is None:
        return OK
    x, y = plan.centre
    if math.hypot(x, y) < CENTRE_TOL and plan.v != 0.0:
        return CENTRE_AT_ORIGIN  # VCU-FLT-04
    if any(math.hypot(x - xi, y - yi) < CENTRE_TOL for xi, yi in WHEELS.values()):
        return CENTRE_ON_WHEEL  # VCU-FLT-05
    if plan.steered_by_handwheel and abs(x) < K:
        return ANGLE_OVER_90  # VCU-FLT-06: centre strictly between the wheels of an axle
    return OK


def centre_speed(plan: Plan) -> float:
    """VCU-REQ-01: v_o = v in PIVOT; NORMAL/ADAPTIVE forward is clockwise about a centre with x > 0."""
    if plan.mode == PIVOT or plan.centre is None:
        return plan.v
    return plan.v if plan.centre[0] > 0 else -plan.v


def execute(plan: Plan) -> Command:
    """The wheel commands and state outputs of a plan without a centre fault (VCU-MODE-*, VCU-OUT-*)."""
    if plan.centre is None:
        return translation(plan.mode, plan.heading, plan.v, plan.curvature)
    v_o = centre_speed(plan)
    angles, speeds, omega = rotation(plan.centre, v_o)
    x, y = plan.centre
    r_o = math.hypot(x, y)
    if plan.mode == PIVOT:  # VCU-OUT-05: clockwise about S, (-y, x)/r_o
        forward = (-y / r_o, x / r_o) if r_o > 0 else (0.0, 1.0)
    else:
        forward = (0.0, 1.0)
    return Command(
        mode=plan.mode,
        angles=angles,
        speeds=speeds,
        curvature=plan.curvature,
        yaw_rate=math.degrees(omega),  # VCU-OUT-04
        centre=saturate_centre(plan.centre),  # VCU-OUT-06
        forward=forward,
    )


def exceeds_limits(command: Command) -> bool:
    """VCU-LIM-01: more than 1500 rpm on a wheel or 120 deg/s of yaw rate."""
    return any(abs(n) > MAX_RPM for n in command.speeds.values()) or abs(command.yaw_rate) > MAX_YAW_DEG_S


# ==============================================================================================================
# Vehicle speed (VCU-OUT-05, VCU-4WS-01)
# ==============================================================================================================
#: Sums over the four wheels for the rigid fit's normal equations (VCU-OUT-05)
_N = len(WHEELS)
_SUM_X = sum(x for x, _ in WHEELS.values())
_SUM_Y = sum(y for _, y in WHEELS.values())
_SUM_R2 = sum(x * x + y * y for x, y in WHEELS.values())


def rigid_fit(status: dict[str, tuple[float, float]]) -> tuple[float, float, float]:
    """(v_x, v_y, omega) of the centre from each wheel's (SteerAngle deg, WheelSpeed rpm) (VCU-OUT-05): the least
    squares fit of u_i = (v_x + omega y_i, v_y - omega x_i) to the wheels' velocities, by its normal equations
    (n v_x + omega Sy = Sux, n v_y - omega Sx = Suy, v_x Sy - v_y Sx + omega Sr2 = S(y ux - x uy))."""
    sum_ux = sum_uy = moment = 0.0
    for name, (xi, yi) in WHEELS.items():
        angle, rpm = status[name]
        speed = rpm / RPM_PER_MPS
        a = math.radians(angle)
        ux, uy = speed * math.sin(a), speed * math.cos(a)
        sum_ux += ux
        sum_uy += uy
        moment += yi * ux - xi * uy
    omega = ((moment - (_SUM_Y * sum_ux - _SUM_X * sum_uy) / _N)
             / (_SUM_R2 - (_SUM_X * _SUM_X + _SUM_Y * _SUM_Y) / _N))
    return (sum_ux - omega * _SUM_Y) / _N, (sum_uy + omega * _SUM_X) / _N, omega


def signed_vehicle_speed(v_x: float, v_y: float, forward: tuple[float, float]) -> float:
    """VCU-OUT-05: |(v_x, v_y)| signed by its projection on the direction positive v moves the centre."""
    magnitude = math.hypot(v_x, v_y)
    return -magnitude if v_x * forward[0] + v_y * forward[1] < 0 else magnitude


@dataclass
class SpeedEstimator:
    """VCU-4WS-01: the vehicle's forward speed from the wheels while they roll, LongAccel while they slide.

    The informative estimator of vcu-4ws.md VCU-4WS-01, rules 1-6 as written. Each task (period dt) reads w,
    the forward component of the wheels' rigid fit (VCU-OUT-05), and a, the latest valid LongAccel plus the
    body-frame term YawRate * v_x of the fit (which VCU-4WS-01 allows; u_dot of IMU-OUT-01's body frame):
      1. u undefined, no valid IMU_Motion, LongAccel at its range end (+/-30 m/s^2: the IMU clamps there, so
         it bounds the acceleration without measuring it), or more than 50 ms since the previous task: u = w.
      2. predict p = u + a dt, e = w - p.
      3. |e| <= B: u = p + clamp(e, -D, D) (the wheels, at most D per task away from the prediction).
      4. the wheels slide the way the IMU pushes (e < -B with a <= -A, or e > +B with a >= +A): u = p.
      5. the wheels lie on the side the IMU excludes (e > +B with a <= -A, or e < -B with a >= +A): u = w.
      6. otherwise (|e| > B, |a| < A): u = p until the disagreement has lasted T_c, then u = w.
    Rules 1 and 3-5 clear the disagreement's start t_d; rule 6 sets it at its first task. Time is the sum of
    the tasks' dt (the caller's clock), so "now - t_d" is the time since the task that began the disagreement
    (with 10 ms tasks rule 6 takes the wheels at the 4th task of a disagreement: 30 ms after the 1st).
    Not in the rule (the estimate is not judged then, VCU-FLT-07): while a WHL_Status_xx is timed out there is
    no w; the estimate is then predicted from a valid IMU_Motion, else held, and t_d cleared.
    """

    BAND = 0.3  # B, m/s
    SLIDE_ACCEL = 1.5  # A, m/s^2
    CONFIRM_S = 0.030  # T_c, s
    STEP = 0.05  # D, m/s per task
    MAX_GAP_S = 0.050  # rule 1: more than 50 ms since the previous task
    ACCEL_RANGE_END = 30.0  # rule 1: IMU_Motion.LongAccel's range end (dbc/chassis.dbc), m/s^2

    u: float | None = None
    t_d: float | None = None  # when an unconfirmed disagreement began (rule 6), None: none
    now: float = 0.0  # the estimator's clock: the sum of the tasks' dt

    def update(self, dt: float, wheels: tuple[float, float, float] | None,
               imu: dict[str, float] | None) -> float | None:
        """One task: the new estimate (None until the four wheels have been received). `imu`: the values of the
        latest valid IMU_Motion frame, None when there is none (never received, timed out, last frame invalid)."""
        self.now += dt
        a = None
        if imu is not None:  # a: LongAccel + the body-frame term YawRate * v_x of the fit (VCU-4WS-01 inputs)
            a = imu["LongAccel"] + (math.radians(imu["YawRate"]) * wheels[0] if wheels is not None else 0.0)
        if wheels is None:  # a wheel timed out: no w (WHEEL_FAULT, the estimate is not judged)
            self.t_d = None
            if self.u is not None and a is not None:
                self.u += a * dt
            return self.u
        w = wheels[1]
        clamped = imu is not None and abs(imu["LongAccel"]) >= self.ACCEL_RANGE_END
        if self.u is None or a is None or clamped or dt > self.MAX_GAP_S:  # rule 1
            self.u, self.t_d = w, None
            return self.u
        p = self.u + a * dt  # rule 2
        e = w - p
        if abs(e) <= self.BAND:  # rule 3: the wheels roll with the car; the step limit D
            self.u, self.t_d = p + max(-self.STEP, min(self.STEP, e)), None
        elif (e < 0.0 and a <= -self.SLIDE_ACCEL) or (e > 0.0 and a >= self.SLIDE_ACCEL):  # rule 4: a slide
            self.u, self.t_d = p, None
        elif (e > 0.0 and a <= -self.SLIDE_ACCEL) or (e < 0.0 and a >= self.SLIDE_ACCEL):  # rule 5: lost the car
            self.u, self.t_d = w, None
        else:  # rule 6: |a| < A, the IMU does not say which: confirm for T_c
            if self.t_d is None:
                self.t_d = self.now
            if self.now - self.t_d >= self.CONFIRM_S - 1e-9:  # 1 ns: float rounding of the summed dt
                self.u, self.t_d = w, None
            else:
                self.u = p
        return self.u


# ==============================================================================================================
# The VCU: inputs, one evaluation, outputs
# ==============================================================================================================
@dataclass
class Outputs:
    """What the next frames carry (VCU-GEN-02: all written by one evaluation)."""

    command: Command = POWER_UP
    speeds: dict[str, float] = field(default_factory=lambda: dict(POWER_UP.speeds))
    yaw_rate: float = 0.0
    fault: int = REQUEST_TIMEOUT  # VCU-GEN-03 / VCU-FLT-01: no request received yet
    vehicle_speed: float = 0.0


class Vcu:
    """Receivers, the evaluation of VCU-FLT-03 and the resulting outputs."""

    def __init__(self, db: cantools.database.Database, start: float, law: int = LAW_FEEDFORWARD) -> None:
        self.start = start
        self.law = law  # RearSteerLaw, the coding (VCU-4WS-10)
        self.rx = {name: E2EReceiver(db, db.get_message_by_name(name)) for name in INPUTS}
        self.by_id = {r.message.frame_id: r for r in self.rx.values()}
        self.last_executed = POWER_UP  # VCU-FLT-08: 0 deg before any executed command
        self.out = Outputs()
        self.speed = SpeedEstimator()
        self._last_eval: float | None = None

    def receive(self, msg: can.Message, t: float) -> None:
        receiver = self.by_id.get(msg.arbitration_id)
        # COM-RX-03: an error frame belongs to no message
        if receiver is not None and not (msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame):
            receiver.on_frame(bytes(msg.data), t)

    # --- one evaluation (VCU-GEN-02) ---
    def evaluate(self, now: float) -> Outputs:
        dt = TASK_S if self._last_eval is None else now - self._last_eval
        self._last_eval = now
        wheels = self._wheel_fit(now)
        u = self.speed.update(dt, wheels, self._imu(now))
        fault, command = self._decide(now, u)
        if fault == OK:  # VCU-FLT-10: no latching, executed at once
            self.last_executed = command
            speeds, yaw = command.speeds, command.yaw_rate
        else:  # VCU-FLT-08: speeds 0 exactly, angles/mode/curvature/centre held, yaw 0
            command = self.last_executed
            speeds, yaw = {w: 0.0 for w in WHEELS}, 0.0
        vehicle_speed = 0.0 if wheels is None else signed_vehicle_speed(wheels[0], wheels[1], command.forward)
        self.out = Outputs(command=command, speeds=speeds, yaw_rate=yaw, fault=fault, vehicle_speed=vehicle_speed)
        return self.out

    def _decide(self, now: float, u: float | None) -> tuple[int, Command | None]:
        """VCU-FLT-03: the first fault that applies, in this order; else the command to execute."""
        request_rx, steering_rx = self.rx["DRV_MotionRequest"], self.rx["DRV_Steering"]
        if request_rx.timed_out(now):
            return REQUEST_TIMEOUT, None  # step 1, VCU-FLT-01
        if request_rx.last_rejected:
            return REQUEST_INVALID, None  # step 2, VCU-FLT-02.1
        request = request_rx.values
        assert request is not None
        mode, v = int(request["DriveMode"]), float(request["TargetSpeed"])
        if mode in (NORMAL, ADAPTIVE):  # step 3: DRV_Steering only in NORMAL and ADAPTIVE (VCU-GEN-01)
            if steering_rx.timed_out(now):
                return REQUEST_TIMEOUT, None  # VCU-FLT-01
            if steering_rx.last_rejected:
                return REQUEST_INVALID, None  # VCU-FLT-02.2
        plan = self._plan(mode, v, request, u)
        fault = centre_fault(plan)  # step 4
        if fault != OK:
            return fault, None
        command = execute(plan)
        if exceeds_limits(command):
            return REQUEST_INVALID, None  # step 5, VCU-LIM-01 / VCU-FLT-02.3
        if self._wheel_fault(now):
            return WHEEL_FAULT, None  # step 6, VCU-FLT-07 (after its grace no estimate means a silent wheel)
        return OK, command

    def _plan(self, mode: int, v: float, request: dict[str, float], u: float | None) -> Plan:
        """VCU-REQ-01: the mode selects the plan; PivotX/Y in PIVOT only, HandWheelAngle in NORMAL/ADAPTIVE."""
        if mode == PIVOT:
            return plan_pivot(float(request["PivotX"]), float(request["PivotY"]), v)
        if mode == LATERAL:
            return plan_lateral(v)
        steering = self.rx["DRV_Steering"].values
        assert steering is not None
        handwheel = float(steering["HandWheelAngle"])
        if mode == NORMAL:
            return plan_normal(handwheel, v)
        # VCU-4WS-01's one exception: within VCU-FLT-07's grace, an undefined estimate is u = |TargetSpeed|
        yaw_rate = None
        if self.law == LAW_FEEDBACK and self._last_eval is not None:  # the evaluation's time (evaluate sets it)
            imu = self._imu(self._last_eval)
            yaw_rate = None if imu is None else float(imu["YawRate"])
        return plan_adaptive(handwheel, v, abs(v) if u is None else u, self.law, yaw_rate)

    def _wheel_fault(self, now: float) -> bool:
        """VCU-FLT-07: a wheel timed out or WheelFault != 0; silent or CMD_TIMEOUT ignored in the first 100 ms."""
        in_grace = now - self.start < WHEEL_GRACE_S
        for name in WHEELS:
            rx = self.rx[f"WHL_Status_{name}"]
            if rx.timed_out(now):
                if in_grace and rx.values is None:
                    continue
                return True
            code = int(rx.values["WheelFault"]) if rx.values else 0
            if code != 0 and not (in_grace and code == 3):
                return True
        return False

    def _wheel_fit(self, now: float) -> tuple[float, float, float] | None:
        """VCU-OUT-05: the rigid fit of the four wheels, None while any WHL_Status_xx is timed out."""
        status = {}
        for name in WHEELS:
            values = self._valid(f"WHL_Status_{name}", now)
            if values is None:
                return None
            status[name] = (float(values["SteerAngle"]), float(values["WheelSpeed"]))
        return rigid_fit(status)

    def _imu(self, now: float) -> dict[str, float] | None:
        """VCU-4WS-01: the latest valid IMU_Motion, None when never received, timed out or its last frame invalid."""
        rx = self.rx["IMU_Motion"]
        return None if rx.last_rejected else self._valid("IMU_Motion", now)

    def _valid(self, name: str, now: float) -> dict[str, float] | None:
        rx = self.rx[name]
        return None if rx.timed_out(now) else rx.values


# ==============================================================================================================
# Frames out (VCU-GEN-01, VCU-OUT-*)
# ==============================================================================================================
class Transmitter:
    """Builds the VCU's frames from the latest outputs (COM-E2E-*, COM-VAL-01)."""

    def __init__(self, db: cantools.database.Database) -> None:
        self.wheel_cmd = {w: E2ESender(db, db.get_message_by_name(f"VCU_WheelCmd_{w}")) for w in WHEELS}
        self.state = E2ESender(db, db.get_message_by_name("VCU_VehicleState"))
        self.centre = E2ESender(db, db.get_message_by_name("VCU_RotationCentre"))
        self.by_id = {s.message.frame_id: s for s in (*self.wheel_cmd.values(), self.state, self.centre)}
        self.values: dict[str, dict[str, float]] = {}  # the signals of each message's latest frame (DIAG-SVC-02)

    def sent(self, frame: can.Message) -> None:
        """COM-E2E-01: a transmitted frame advances its message's AliveCounter."""
        self.by_id[frame.arbitration_id].sent(frame)

    def wheel_frames(self, out: Outputs) -> list[can.Message]:
        """VCU-OUT-01: SteerAngleCmd and WheelSpeedCmd of each wheel."""
        return [self.wheel_cmd[w].frame({"SteerAngleCmd": out.command.angles[w], "WheelSpeedCmd": out.speeds[w]})
                for w in WHEELS]

    def state_frames(self, out: Outputs) -> list[can.Message]:
        """VCU-OUT-02..07: VCU_VehicleState and VCU_RotationCentre."""
        state, centre = state_values(out), centre_values(out)
        self.values["VCU_VehicleState"], self.values["VCU_RotationCentre"] = state, centre
        return [self.state.frame(state), self.centre.frame(centre)]


def state_values(out: Outputs) -> dict[str, float]:
    """VCU_VehicleState's signals (VCU-OUT-02..05, VCU-FLT-*)."""
    return {
        "VehicleSpeed": out.vehicle_speed,  # VCU-OUT-05
        "ActiveMode": out.command.mode,  # VCU-OUT-02
        "YawRateTarget": out.yaw_rate,  # VCU-OUT-04
        "CurvatureAngle": out.command.curvature,  # VCU-OUT-03
        "VcuFault": out.fault,  # VCU-FLT-*
    }


def centre_values(out: Outputs) -> dict[str, float]:
    """VCU_RotationCentre's signals (VCU-OUT-06/07)."""
    x, y = out.command.centre
    return {"RotationCentreX": x, "RotationCentreY": y}


# ==============================================================================================================
# Running on a bus
# ==============================================================================================================
def drain(bus: can.BusABC, vcu: Vcu, now: float, diag: uds_server.Diagnostics | None = None) -> None:
    """Judge every frame that arrived since the last task, in order, each at its reception time.

    The task reads the bus itself (no receive thread): after the process was descheduled it first takes in
    everything that arrived meanwhile, stamped by the kernel (python-can's timestamp, the wall clock of
    time.time()), so a late task never mistakes its own stall for a silent sender (COM-RX-02). `now` is the
    task's one read of that clock: a stamp more than a second away from it is of another clock (an interface
    without receive timestamps), and the frame gets `now`. Where the driver filters (socketcan's kernel, a CAN
    controller) the bus delivers only what the VCU reads (`receive_filters`); elsewhere Vcu.receive ignores the
    rest."""
    while True:
        try:
            msg = bus.recv(timeout=0.0)
        except can.CanError:
            return
        if msg is None:
            return
        if diag is not None and diag.on_frame(msg):
            continue  # a diagnostic request's frame: the UDS server's, never an input's
        vcu.receive(msg, msg.timestamp if abs(now - msg.timestamp) < 1.0 else now)


@dataclass
class TaskStats:
    """What --stats prints: faults per evaluation, late tasks, frames per input message."""

    faults: Counter = field(default_factory=Counter)
    skipped_slots: int = 0
    max_late_ms: float = 0.0

    def report(self, vcu: Vcu) -> str:
        inputs = " ".join(f"{name}:{rx.accepted}/{rx.rejected}/{rx.state}"
                          + "".join(f" {s}={n}" for s, n in sorted(rx.statuses.items()) if s != OK)
                          for name, rx in vcu.rx.items())
        line = (f"stats faults={dict(sorted(self.faults.items()))} skipped={self.skipped_slots} "
                f"max_late={self.max_late_ms:.1f}ms accepted/rejected/E2E state {inputs}")
        self.faults.clear()
        self.skipped_slots, self.max_late_ms = 0, 0.0
        return line


class Ecu:
    """The VCU's software on its bus: the control (Vcu) and the frames' senders (Transmitter). `restart` is what
    power-up does, and what an ECUReset does (DIAG-RST-02): outputs from their power-up state, receivers that have
    applied no frame; the coding is put in force again by the diagnostic server. The AliveCounters, which the
    contract leaves free to start anew, carry on (this VCU's choice): the receivers of its messages see the new
    outputs in sequence, without the WRONGSEQUENCE and the rejected frames of a restarted counter."""

    def __init__(self, db: cantools.database.Database) -> None:
        self.db = db
        self.vcu, self.tx = Vcu(db, time.time()), Transmitter(db)
        self.restarted = False

    def restart(self) -> None:
        self.vcu = Vcu(self.db, time.time(), self.vcu.law)
        self.restarted = True

    # --- what the diagnostic server reads (VCU-DIAG-04) ---
    def outputs(self, message: str) -> dict[str, float] | None:
        """The signals of the message's latest frame (sent in the last 20 ms, or at the next task): a DID with a
        signal equals one of the VCU's frames (DIAG-SVC-02). None before the first: the DBC start value."""
        return self.tx.values.get(message)

    def inputs(self, message: str) -> dict[str, float] | None:
        rx = self.vcu.rx.get(message)
        return None if rx is None else rx.values

    def wheel_status_timed_out(self) -> float:
        """0xFD0A: bit 0 FL, 1 FR, 2 RL, 3 RR while that WHL_Status_xx is timed out (COM-RX-02), at the last task."""
        vcu = self.vcu
        now = vcu._last_eval if vcu._last_eval is not None else time.time()
        return float(sum(1 << i for i, w in enumerate(WHEELS) if vcu.rx[f"WHL_Status_{w}"].timed_out(now)))


def control_loop(bus: can.BusABC, ecu: Ecu, stop: threading.Event, send: Callable[[can.Message], bool],
                 stats_every: float = 0.0, diag: uds_server.Diagnostics | None = None) -> None:
    """The 10 ms task on an absolute grid: send the frames of the last evaluation at once (COM-CYC-01: the
    wheels every task, the state every 2nd), then read the bus and evaluate for the next task, then give the
    fault memory the evaluation's result and let the diagnostic server answer what it received.

    Sending first keeps the frames on the grid whatever the evaluation costs; a request received after one
    task's evaluation is in the frames of the task after next, at most 20 ms later, which VCU-GEN-02 allows
    (the next frame sent at least 10 ms after the request) and so does VCU-FLT-09 for a fault.

    A task reads the clocks three times: the grid's (time.monotonic) before and after its sleep, and the wall
    clock of the frames' stamps (time.time) once for its drain and its evaluation. On a slow machine a clock
    read is not free (a system call of about 55 us in a User-mode Linux guest, docs/vcan-lane.md); python-can's
    socketcan `recv` and `send` still read the clock and call select() once each per frame."""
    tick, next_t = 0, time.monotonic()
    stats, next_stats = TaskStats(), next_t + stats_every
    pending = frames_of_task(ecu.tx, ecu.vcu.out, tick)
    while not stop.is_set():
        now = time.monotonic()
        if next_t > now:
            time.sleep(next_t - now)
            now = time.monotonic()
        late = now - next_t
        stats.max_late_ms = max(stats.max_late_ms, late * 1000.0)
        tx = ecu.tx
        for frame in pending:
            if send(frame):
                tx.sent(frame)
        wall = time.time()
        drain(bus, ecu.vcu, wall, diag)  # frames received up to now (VCU-GEN-02)
        out = ecu.vcu.evaluate(wall)
        stats.faults[out.fault] += 1
        missed = max(0, int(late / TASK_S) - 1)   # the slots that passed meanwhile but the last (it runs at once)
        stats.skipped_slots += missed
        tick += 1 + missed  # a late task skips the slots it missed instead of sending a burst
        next_t += TASK_S * (1 + missed)
        pending = frames_of_task(ecu.tx, out, tick)  # VCU-GEN-02: all outputs of one evaluation together
        if diag is not None:
            diag.control_step(diag.failing({"VCU_VehicleState.VcuFault": out.fault}))  # DIAG-DTC-02
            diag.poll()  # ISO-TP and UDS, never blocking; an ECUReset restarts `ecu`
            if ecu.restarted:  # the power-up outputs, in frames of the new AliveCounters
                ecu.restarted = False
                pending = frames_of_task(ecu.tx, ecu.vcu.out, tick)
        if stats_every and now >= next_stats:
            print(stats.report(ecu.vcu), flush=True)
            next_stats = now + stats_every


def frames_of_task(tx: Transmitter, out: Outputs, tick: int) -> list[can.Message]:
    """The wheel commands every 10 ms task, the state and centre every 2nd (COM-CYC-01)."""
    return tx.wheel_frames(out) + (tx.state_frames(out) if tick % 2 == 0 else [])


def make_sender(bus: can.BusABC) -> Callable[[can.Message], bool]:
    """VCU-GEN-01: never stop sending; a full transmit buffer costs one frame, not the node. The sender says
    whether the frame went out (its AliveCounter advances only then, COM-E2E-01)."""
    def send(frame: can.Message) -> bool:
        try:
            bus.send(frame, timeout=0.005)
        except can.CanError:
            return False
        return True
    return send


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    default_dbc = Path(__file__).resolve().parent.parent / "dbc" / "chassis.dbc"
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--interface", default="udp_multicast", help="python-can interface (default udp_multicast)")
    parser.add_argument("--channel", default=None, help="python-can channel (e.g. 239.255.1.2, vcan0)")
    parser.add_argument("--bitrate", type=int, default=None, help="bitrate, for interfaces that take one")
    parser.add_argument("--dbc", type=Path, default=default_dbc, help="the chassis DBC (default: dbc/chassis.dbc)")
    parser.add_argument("--stats", type=float, default=0.0, metavar="S",
                        help="print faults, late tasks and received frames every S seconds (diagnosis)")
    parser.add_argument("--vin", default=IDENTIFICATION["VehicleIdentificationNumber"],
                        help="the VIN this VCU holds (0xF190, 17 characters; '' for none programmed)")
    parser.add_argument("--nvm", type=Path, default=None, metavar="FILE",
                        help="non-volatile memory (coding, fault memory) kept in FILE across restarts; "
                             "default: none, every start is a VCU as delivered")
    parser.add_argument("--diag-defect", choices=("snapshot-stale",), default=None,
                        help="a deliberate diagnostic defect (off by default) for checking a tester: snapshot-stale "
                             "keeps each DTC's first snapshot record since power-up instead of the latest occurrence's")
    return parser.parse_args(argv)


def receive_filters(db: cantools.database.Database) -> list[can.typechecking.CanFilter]:
    """Acceptance filters for exactly the identifiers the VCU reads (INPUTS), 11-bit data frames, as a real
    ECU's CAN controller has them. python-can sets them in the kernel on socketcan (CAN_RAW_FILTER), so the
    process never reads the rest of the bus (on the 4WIS network more than half its frames, among them the
    VCU's own and the bench's); `open_bus` keeps them only where the driver applies them."""
    return [{"can_id": db.get_message_by_name(name).frame_id, "can_mask": 0x7FF, "extended": False}
            for name in INPUTS]


def open_bus(args: argparse.Namespace, filters: list[can.typechecking.CanFilter] | None = None) -> can.BusABC:
    kwargs: dict[str, object] = {"interface": args.interface, "can_filters": filters}
    if args.channel is not None:
        kwargs["channel"] = args.channel
    if args.bitrate is not None:
        kwargs["bitrate"] = args.bitrate
    if args.interface == "udp_multicast":
        kwargs["hop_limit"] = 0  # keep the traffic on this host, as the bench does
    bus = can.Bus(**kwargs)
    if filters and not getattr(bus, "_is_filtered", False):
        # python-can filters this interface in software, and then recv(timeout=0) returns None at the first
        # frame it drops, as if the bus were empty: `drain` would stop early. Vcu.receive ignores what it does
        # not read, so such a bus goes unfiltered.
        bus.set_filters(None)
    if args.interface == "udp_multicast":
        only_own_group(bus)
    return bus


def only_own_group(bus: can.BusABC) -> None:
    """Receive only our multicast group: python-can binds to the port on every address, and Linux then delivers
    every group any process on the host joined on that port (IP_MULTICAST_ALL defaults to 1). Other benches'
    frames would look like a second sender to the E2E receivers (docs/spec/e2e.md). What the socket queued
    before the setting is dropped: nothing of our own group is due before the VCU says it is running."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None:
        return
    ip_multicast_all, ipv6_multicast_all = 49, 29  # linux/in.h, linux/in6.h
    try:
        if sock.family == socket.AF_INET:
            sock.setsockopt(socket.IPPROTO_IP, ip_multicast_all, 0)
        else:
            sock.setsockopt(socket.IPPROTO_IPV6, ipv6_multicast_all, 0)
    except OSError:
        return  # not Linux: no such leak to close
    while True:  # what arrived between python-can's bind and the setting above may be another group's
        try:
            sock.recv(65535, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return


def make_diagnostics(ecu: Ecu, bus: can.BusABC, args: argparse.Namespace) -> uds_server.Diagnostics:
    """The VCU's diagnostic server (VCU-DIAG-01..04): its values, its coding and its routine's precondition."""

    def apply_coding(name: str, value: float) -> None:
        if name == "RearSteerLaw":
            ecu.vcu.law = int(value)  # in force from the next task (DIAG-COD-01)

    return uds_server.Diagnostics(
        "VCU", make_sender(bus), identification={**IDENTIFICATION, "VehicleIdentificationNumber": args.vin},
        live={"WheelStatusTimedOut": ecu.wheel_status_timed_out}, outputs=ecu.outputs, inputs=ecu.inputs,
        signals=[ecu.db], apply_coding=apply_coding,
        coding_supported=lambda name, value: name != "RearSteerLaw" or int(value) in (LAW_OFF, LAW_FEEDFORWARD,
                                                                                     LAW_FEEDBACK),
        preconditions={"StraightAheadLearn": lambda: abs(ecu.vcu.out.vehicle_speed) < LEARN_MAX_SPEED},
        on_reset=ecu.restart, defect=args.diag_defect, nvm=args.nvm)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    db = cantools.database.load_file(str(args.dbc))
    ecu = Ecu(db)
    # the diagnostic server's identifiers pass the acceptance filters too (the physical and the functional request)
    bus = open_bus(args, receive_filters(db) + [{"can_id": i, "can_mask": 0x7FF, "extended": False}
                                                for i in uds_server.Declaration.load("VCU").ids()])
    try:
        diag = make_diagnostics(ecu, bus, args)
    except (OSError, ValueError) as error:  # a DiagConfigError is a ValueError
        bus.shutdown()
        print(f"vcu_ecu: {error}", flush=True)
        return 2
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):  # also when started in the background (SIGINT ignored there)
        signal.signal(signum, lambda *_: stop.set())
    print(f"VCU running on {args.interface} {args.channel or ''}".rstrip(), flush=True)
    try:
        control_loop(bus, ecu, stop, make_sender(bus), args.stats, diag)
    finally:
        diag.close()
        bus.shutdown()
        print("VCU stopped", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
