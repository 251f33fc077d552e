"""A stand-alone ABS ECU for the A-class car, written from the contract documents alone.

Node `ABS` of `dbc/chassis.dbc`, built only from README.md, `docs/contract/common.md`, `docs/contract/abs.md`,
`docs/contract/plant.md` ("Bench I/O - ABS"), `docs/spec/*.md`, the DBCs and bench.toml, as an outside supplier
would. Comments cite the requirement ids.

- Wires (the bench I/O of `dbc/bench.dbc`, ABS-GEN-01): reads the four wheel-speed sensors from `IO_AbsSensors`
  (5 ms, PLANT-IO-ABS-01) and commands the hydraulic unit's valves in `IO_AbsValves` after each 5 ms control
  step (PLANT-IO-ABS-02).
- Chassis bus: reads `DRV_Pedals` (the brake switch, ABS-GEN-01), sends `ABS_WheelSpeeds` and `ABS_SteerState`
  every 10 ms (ABS-OUT-01, -02).
- [P4] (docs/spec/formulas.md §6): turning state T (eq. 13, erratum E3 corrected) before ABS control on low-pass
  filtered wheel speeds and during ABS control from the control states at the hold -> increase switching
  points (ABS-TURN-01), the reference speed (ABS-EST-01: eq. 5, wheel selection of §3.3, switching-point
  interpolation under ABS with eq. 14), the front-wheel angle (ABS-EST-02, eq. 12), the slip control of the
  pressure cycles, and the fault reactions of ABS-FLT-01 (AbsFault, the passive state).

Calibration (ABS-TURN-01): V_l0 = 0.6, V_l1 = 9.0, V_l2 = 1.35 km/h, t0 = 0.01 s, t1 = 0.05 s; the bench is
told V_l0..V_l2 in bench.toml `[calibration.ABS]` (keep them equal to V_L0, V_L1, V_L2 below).

Choices the documents leave to the ECU (each marked where it is made):
- the pressure cycle: HOLD at the start (slip 0.06, or a braked wheel decelerating beyond 1.5 g), outlet
  (slip 0.11) until the wheel re-accelerates or 15 % of the pressure is out, a hold while it spins up, the
  switching point when it stops accelerating (its own acceleration, not the reference speed it helps to find),
  a fast increase to 92 % of the pressure at the last reduction (the unit's law of PLANT-IO-ABS-02 gives the
  pressure) and a stepped one (inlet duty 0.12); each wheel's slip against its speed moved to the centre of gravity
  (eq. 14 / eq. 5); in an identified braked turn the front thresholds are halved (steerability: a braked outer
  front wheel makes the car turn less than eq. 11 says, and delta-bar reads low);
- a switching point counts (an interpolation point of the reference speed, an axle difference) only if the
  wheel re-accelerated (beyond 5 m/s^2) since its pressure reduction began: one that did not still slips; the
  identification under ABS arms a side when its two wheels were each in DECREASE in one of the last 10 updates
  while the other side's are in INCREASE (ABS-TURN-01's window; read from one update alone, the pattern
  appeared only when the two inner wheels' cycles overlapped, and an angle step was identified in about half
  of the real-time runs), takes axle differences only at the switching points of the armed side's inner
  wheels and forgets them when the other side is armed and after 0.5 s; the extrapolation starts from the
  reference speed at the start of ABS control but does not take it as an interpolation point;
- a new world (the bench restarts a scenario without telling an external ECU, PLANT-SCN-04) shows as a jump of
  the four wheels' mean by more than 4 km/h in one 5 ms sample: the filters restart and T = 0; after any restart
  of the estimate (power-up, a fault cleared, a new world) T stays 0 for 0.5 s while the filters settle (the
  stimulus resumes before the bench restarts the world, PLANT-SCN-04: the old world's turn would otherwise show
  in the new case's first frames);
- IO_AbsSensors timed out: the wires carry no pulses, the sensors read 0 km/h;
- under ABS delta is held below 12 km/h (the reference: 20 km/h).

End-to-end protection as an AUTOSAR stack does it (docs/spec/e2e.md, COM-E2E-*, COM-RX-*), configured from the
DBCs' `E2E_*` attributes, CRCs by the `autosar-e2e` library (the same code as examples/vcu_ecu.py).

Run it as the external ABS of the bench (three processes on one host):

    bench plant --interface udp_multicast --channel 239.255.1.3 --external ABS &
    python examples/abs_ecu.py --interface udp_multicast --channel 239.255.1.3
    bench run --interface udp_multicast --channel 239.255.1.3 --external all --dut ABS

Diagnostics (abs.md ABS-DIAG-01..03, docs/contract/diagnostics.md): a UDS server on ISO-TP (`examples/uds_server.py`,
shared by the three examples) on 0x706/0x70E and the functional 0x7DF: sessions, ECUReset, the fault memory fed at
every 5 ms step with the AbsFault it sends (WHEEL_SPEED_INVALID, INPUT_TIMEOUT), identification and live DIDs,
SecurityAccess with the documented seed/key, routine 0x0202 ValveAndPumpTest (precondition: standstill, RefVehicleSpeed
below 1 km/h, and the brake switch open, else NRC 0x22; the valves stay as the control sets them: the rig's unit has
nothing to show). The ABS has no coding. ECUReset restarts the control and the receivers as at power-up (the
AliveCounters carry on); the fault memory is kept (`--nvm FILE`: also across process restarts). The ISO-TP layer
(can-isotp) runs inside the 5 ms step and never blocks: the step, the bus's only reader, hands it the frames of 0x706
and 0x7DF it drains and calls the server's `poll()` after sending its frames, so the frames keep their grid and no
second reader or thread competes with the step for the bus or the interpreter; a request is answered within one step
(5 ms) of its last frame, well within P2 = 50 ms, and a diagnostic frame never reaches the E2E receivers.

Diagnostic defect for checking a tester (off by default): `--diag-defect confirmed-never`: confirmedDTC (status bit 3)
is never set, so a fault that lasts beyond its 500 ms shows 0x27 instead of 0xAF and warningIndicatorRequested
(bit 7) is never requested either (DIAG-DTC-04).

It prints a line with `running` once it is on the bus; SIGINT or SIGTERM stops it ("stopped", exit 0). Needs
python-can, cantools, autosar-e2e (import name `e2e`), can-isotp (import name `isotp`) and the standard library only;
nothing of the bench.
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

#: DIAG-ID-01: this ABS's own identification (the VIN is the vehicle's, programmed at the end of the line: --vin)
IDENTIFICATION = {"SparePartNumber": "ABS-EX0001", "EcuSerialNumber": "ABS-EX000001",
                  "VehicleIdentificationNumber": "BENCH000000000001", "SoftwareVersionNumber": "EX-2.0"}
TEST_MAX_SPEED = 1.0  # km/h, ABS-DIAG-02's precondition (RefVehicleSpeed), with the brake switch open

# --- Vehicle B (docs/spec/vehicles.md B, docs/spec/formulas.md §6) ----------------------------------------------
A_CG, B_CG = 1.06, 1.59  # m, centre of gravity to the front / rear axle
WHEELBASE = A_CG + B_CG  # L = 2.65 m
TRACK = 1.55  # B, m
K_STAB = 1.90e-3  # K, s^2/m^2 (ABS-EST-02)
KMH = 1.0 / 3.6  # m/s per km/h
WHEELS = ("FL", "FR", "RL", "RR")  # wheels 1-4 of [P4]

# --- Calibration (ABS-TURN-01; bench.toml [calibration.ABS]) --------------------------------------------------
V_L0, V_L1, V_L2 = 0.6, 9.0, 1.35  # km/h
T0_S = 0.01  # side pattern held this long arms the identification under ABS
PATTERN_WINDOW = 10  # updates (0.1 s): a wheel in DECREASE in one of them counts as decreasing (ABS-TURN-01)
T1_S = 0.05  # a new T holds this long before it is taken (before ABS) / confirmed (under ABS)
FILTER_TAU_S = 0.3  # low-pass of the wheel speeds before ABS control (ABS-TURN-01, informative)
T_SETTLE_S = 0.5  # after a restart of the estimate T stays 0 this long (the filters settle from the raw speeds)
T_MIN_SPEED = 5.0  # km/h: below it (filtered rear mean) T = 0 (ABS-TURN-01)
DELTA_HOLD_SPEED = 12.0  # km/h: under ABS below it the last delta is held (the reference: 20, ABS-EST-02)
DELTA_AVG_FRAMES = 30  # 10 ms frames of the moving averages under ABS (ABS-EST-02, informative)
REAR_RELEASE_SETTLE_S = 0.1  # after releasing the rear axle, eq. 5 on its wheels (ABS-EST-01, informative)

# --- Brake switch and faults (ABS-GEN-01, ABS-FLT-01) ---------------------------------------------------------
BAR_PER_PEDAL_PCT = 1.5
BRAKE_SWITCH_BAR = 2.0
SENSOR_RANGE_MAX = 200.0  # km/h, the measuring range (PLANT-IO-ABS-01)
OPEN_LINE_BELOW, OPEN_LINE_OTHERS_ABOVE, OPEN_LINE_S = 1.0, 20.0, 0.5
OK, WHEEL_SPEED_INVALID, INPUT_TIMEOUT = 0, 1, 2

# --- Hydraulic unit (PLANT-IO-ABS-02) and the slip control ------------------------------------------------------
HOLD, INCREASE, DECREASE, RELEASED = 0, 1, 2, 3  # IO_AbsValves.ValveXX
K_IN, K_OUT = 110.0, 160.0  # bar^0.5/s
MASTER_RATE, MASTER_MAX = 1000.0, 200.0  # bar/s, bar
CONTROL_S = 0.005  # the control period (ABS-FLT-01: the reference's 5 ms; IO_AbsValves cycle)
SLIP_HOLD = 0.06  # a braked wheel beyond it starts a cycle with HOLD (ABS-OUT-02)
SLIP_DECREASE = 0.11  # beyond it the pressure is reduced
SLIP_RECOVERED = 0.03  # re-accelerated: the hold -> increase switching point
DECEL_START = -15.0  # m/s^2: a braked wheel decelerating faster starts a cycle (1.5 g: no car brakes so hard)
DECEL_LOCK = -25.0  # m/s^2: a wheel decelerating faster tends to lock (no car brakes at 2.5 g)
ACCEL_RECOVER = 5.0  # m/s^2: a wheel accelerating faster is spinning up again (end of the outlet phase)
SPIN_UP_MIN_S, SPIN_UP_MAX_S = 0.01, 0.15  # the hold after the outlet phase: at least, at most
AXLE_DV_MAX_AGE_S = 0.5  # an axle difference taken at a switching point counts this long
JUMP_KMH = 4.0  # a change of the four wheels' mean in one 5 ms sample that no car makes (a scenario restart)
TURN_FRONT_SLIP_SCALE = 0.5  # front slip thresholds in an identified braked turn (steerability)
OUTLET_SHARE = 0.85  # the outlet phase ends at the latest at this share of the pressure at its start
FAST_INCREASE_SHARE = 0.92  # fast increase up to this share of the pressure at the last reduction
STEP_DUTY = 0.12  # inlet opening of the stepped increase
ABS_MIN_SPEED = 3.0  # km/h: ABS control ends below it (and starts only above 5 km/h)
ABS_START_SPEED = 5.0
SLOPE_MIN, SLOPE_MAX = -11.0, -1.0  # m/s^2: the reference speed's slope under ABS
SLOPE_WINDOW_S = 0.5  # switching points used for the slope

#: The messages the ABS reads (ABS-GEN-01) and in which database each is
INPUTS = {"DRV_Pedals": "chassis", "IO_AbsSensors": "bench"}
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
    this ABS only writes the counter it sends and reads the counter it receives, in the field where the
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
        self.cycle_s = (message.cycle_time or 0) / 1000.0
        # the check's state (E2E_PXXCheckInit): the counter before a first 0, so that 0 is in sequence
        self.last_counter = self.e2e.counter_values - 1 if self.e2e is not None else 0
        # the state machine (E2E_SMCheckInit): NODATA, an empty window of the last WindowSize statuses
        self.state = SMState.NODATA
        self.window: deque[str] = deque(maxlen=self.e2e.window_size if self.e2e is not None else 1)
        self.last_accepted_t: float | None = None
        self.values: dict[str, float] | None = None
        self.last_rejected = False  # the last received frame was rejected ("invalid" in the node contracts)
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
        decoded = self.message.decode(bytes(data), decode_choices=False)
        assert isinstance(decoded, dict)
        values = {name: float(v) for name, v in decoded.items()}  # type: ignore[arg-type]
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
        raw = {s.name: _raw_on_grid(s, values.get(s.name, _start_value(s))) for s in self.message.signals}
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
    lo = math.ceil(((signal.minimum or 0.0) - signal.offset) / signal.scale - 1e-9)
    hi = math.floor(((signal.maximum or 0.0) - signal.offset) / signal.scale + 1e-9)
    return int(min(max(raw, lo), hi))


def _start_value(signal: cantools.database.Signal) -> float:
    """The signal's GenSigStartValue, scaled (COM-FRM-02)."""
    initial = signal.initial
    return float(initial) if isinstance(initial, (int, float)) else 0.0


# ==============================================================================================================
# [P4]'s equations (docs/spec/formulas.md §6); speeds in km/h, [P4]'s signs (left positive)
# ==============================================================================================================
def turn_state(dv1: float, dv2: float) -> int:
    """Eq. 13 with erratum E3 corrected (ABS-TURN-01): both axle differences inside (V_l0, V_l1), the same way,
    and Delta-Delta-V = |dV1 - dV2| below V_l2 for either sign."""
    if abs(dv1 - dv2) >= V_L2:
        return 0
    if V_L0 < dv1 < V_L1 and V_L0 < dv2 < V_L1:
        return 1
    if V_L0 < -dv1 < V_L1 and V_L0 < -dv2 < V_L1:
        return -1
    return 0


def front_angle(dv2: float, x_dot: float) -> float:
    """Eq. 12: delta = L (1 + K x'^2) dV2 / (B x'), degrees, left positive ([P4]'s sign)."""
    u = x_dot * KMH
    if u < 0.5:
        return 0.0
    return math.degrees(WHEELBASE * (1.0 + K_STAB * u * u) * dv2 * KMH / (TRACK * u))


def yaw_rate(x_dot: float, delta_deg: float) -> float:
    """Eq. 11: r = (x'/L)/(1 + K x'^2) delta, rad/s, left positive."""
    u = x_dot * KMH
    return (u / WHEELBASE) / (1.0 + K_STAB * u * u) * math.radians(delta_deg)


def corrected(speeds: list[float], x_dot: float, delta_deg: float) -> list[float]:
    """Each wheel's speed moved to the centre of gravity (ABS-EST-01): the front wheels by eq. 14
    (V_w1 - (a delta - B/2) r, V_w2 - (a delta + B/2) r), the rear ones to the axle's centre as eq. 5 does
    (V_w3 + B/2 r, V_w4 - B/2 r); r by eq. 11 with the identified delta (0 before it: no correction)."""
    r = yaw_rate(x_dot, delta_deg)
    d = math.radians(delta_deg)
    half = TRACK / 2.0
    return [speeds[0] - (A_CG * d - half) * r / KMH, speeds[1] - (A_CG * d + half) * r / KMH,
            speeds[2] + half * r / KMH, speeds[3] - half * r / KMH]


def ranked(values: list[float], place: int) -> float:
    """The place-th largest value (1 = the largest)."""
    return sorted(values, reverse=True)[place - 1]


# ==============================================================================================================
# Pressure control of one wheel circuit (ABS-OUT-02, ABS-BRK-01; valves of PLANT-IO-ABS-02)
# ==============================================================================================================
class Phase:
    PASSIVE = "passive"  # not under ABS: valves unpowered, the pressure follows the driver
    HOLD_START = "hold-start"  # the hold at the start of a cycle, before the first reduction
    OUTLET = "outlet"  # reduction: outlet open
    SPIN_UP = "spin-up"  # hold while the wheel re-accelerates (still part of the DECREASE phase)
    FAST = "fast"  # fast increase after the switching point
    STEPPED = "stepped"  # stepped increase (inlet PWM)
    KEPT_RELEASED = "kept-released"  # pressure kept released (the rear axle in an identified braked turn)


#: PressureStateXX of each phase (ABS-OUT-02): 0 HOLD, 1 INCREASE, 2 DECREASE
PRESSURE_STATE = {Phase.PASSIVE: 1, Phase.HOLD_START: 0, Phase.OUTLET: 2, Phase.SPIN_UP: 2, Phase.FAST: 1,
                  Phase.STEPPED: 1, Phase.KEPT_RELEASED: 2}
#: The valve command of each phase (PLANT-IO-ABS-02) and the inlet duty in INCREASE
VALVES = {Phase.PASSIVE: (RELEASED, 1.0), Phase.HOLD_START: (HOLD, 1.0), Phase.OUTLET: (DECREASE, 1.0),
          Phase.SPIN_UP: (HOLD, 1.0), Phase.FAST: (INCREASE, 1.0), Phase.STEPPED: (INCREASE, STEP_DUTY),
          Phase.KEPT_RELEASED: (DECREASE, 1.0)}


def pressure_after(p: float, valve: int, duty: float, p_master: float, dt: float) -> float:
    """The wheel-cylinder pressure after dt under a valve command, by the hydraulic unit's law of
    PLANT-IO-ABS-02 (1 ms steps): INCREASE d k_in sign(p_m - p) sqrt|p_m - p| never past p_m, DECREASE
    -k_out sqrt(p) never below 0, HOLD constant, RELEASED = INCREASE with d = 1."""
    steps = max(1, round(dt / 0.001))
    h = dt / steps
    for _ in range(steps):
        if valve in (INCREASE, RELEASED):
            d = 1.0 if valve == RELEASED else duty
            gap = p_master - p
            step = d * K_IN * math.copysign(math.sqrt(abs(gap)), gap) * h
            p = min(p + step, p_master) if gap > 0 else max(p + step, p_master)
        elif valve == DECREASE:
            p = max(0.0, p - K_OUT * math.sqrt(max(p, 0.0)) * h)
    return p


@dataclass
class WheelControl:
    """One wheel's pressure cycle: HOLD at the start, outlet until the wheel re-accelerates, hold while it spins
    up, then the hold -> increase switching point, a fast increase to part of the pressure at the last reduction
    and a stepped increase until the slip grows again (the classic cycle [P4] §3.2 reads its states from)."""

    phase: str = Phase.PASSIVE
    since: float = 0.0
    p: float = 0.0  # the wheel-cylinder pressure as the unit's law gives it for the commands sent, bar
    p_onset: float = 0.0  # the pressure when the last reduction started, bar
    full_since: float | None = None  # stepped increase at the master pressure since
    spun_up: bool = False  # the wheel re-accelerated (beyond ACCEL_RECOVER) since the last reduction began

    @property
    def state(self) -> int:
        return PRESSURE_STATE[self.phase]

    @property
    def valve(self) -> tuple[int, float]:
        valve, duty = VALVES[self.phase]
        return valve, (STEP_DUTY if self.phase == Phase.STEPPED else duty)

    def go(self, phase: str, t: float) -> None:
        if phase == Phase.OUTLET and self.phase != Phase.SPIN_UP:
            self.spun_up = False
        if phase == Phase.OUTLET:
            self.p_onset = self.p
        self.phase, self.since = phase, t
        self.full_since = None

    def model(self, p_master: float, dt: float) -> None:
        valve, duty = self.valve
        self.p = pressure_after(self.p, valve, duty, p_master, dt)

    def step(self, t: float, slip: float, accel: float, p_master: float, may_start: bool,
             scale: float = 1.0) -> bool:
        """One control step; True at the hold -> increase switching point (the end of a DECREASE). `scale`
        lowers the slip thresholds (a front wheel in an identified turn keeps more of its lateral grip)."""
        slip /= scale
        held = t - self.since
        phase = self.phase
        if phase in (Phase.OUTLET, Phase.SPIN_UP) and accel > ACCEL_RECOVER:
            self.spun_up = True
        if phase == Phase.PASSIVE:
            # a braked wheel decelerating faster than any car can is running into the slip, even while the
            # reference (the second-largest wheel before ABS) still slips with it
            if may_start and (slip > SLIP_HOLD or (accel < DECEL_START and slip > SLIP_RECOVERED)):
                self.go(Phase.HOLD_START, t)
                if slip > SLIP_DECREASE:
                    self.go(Phase.OUTLET, t)
        elif phase == Phase.HOLD_START:
            if slip > SLIP_DECREASE or (accel < DECEL_LOCK and slip > SLIP_HOLD):
                self.go(Phase.OUTLET, t)
            elif slip < SLIP_RECOVERED and held >= 0.05:
                self.p_onset = self.p
                self.go(Phase.STEPPED, t)
        elif phase == Phase.OUTLET:
            # the outlet closes once the wheel recovers, or once enough pressure is out (a shallow reduction
            # keeps the wheel near the peak of its grip)
            if accel > ACCEL_RECOVER or slip < 0.0 or self.p <= OUTLET_SHARE * self.p_onset:
                self.go(Phase.SPIN_UP, t)
        elif phase == Phase.SPIN_UP:
            # the switching point: the wheel has stopped spinning up (it rolls with the car at the held
            # pressure), judged by its own acceleration and not by the reference speed it helps to find
            if (held >= SPIN_UP_MIN_S and accel < 0.0) or held >= SPIN_UP_MAX_S:
                if slip > SLIP_DECREASE:
                    self.go(Phase.OUTLET, t)  # not recovered at the held pressure: reduce further
                    return False
                self.go(Phase.FAST if self.p < FAST_INCREASE_SHARE * self.p_onset else Phase.STEPPED, t)
                return True
        elif phase in (Phase.FAST, Phase.STEPPED):
            if slip > SLIP_DECREASE or (accel < DECEL_LOCK and slip > SLIP_HOLD):
                self.go(Phase.OUTLET, t)
            elif phase == Phase.FAST and self.p >= FAST_INCREASE_SHARE * self.p_onset:
                self.go(Phase.STEPPED, t)
            elif phase == Phase.STEPPED:
                if self.p >= p_master - 1.0:
                    self.full_since = t if self.full_since is None else self.full_since
                    if t - self.full_since >= 0.3:  # the driver's pressure no longer locks it: ABS not needed
                        self.go(Phase.PASSIVE, t)
                else:
                    self.full_since = None
        return False


# ==============================================================================================================
# Estimation and identification ([P4] §3; ABS-TURN-01, ABS-EST-01, ABS-EST-02)
# ==============================================================================================================
class Accel:
    """A wheel's acceleration, m/s^2: the least-squares slope over its last 5 readings (20 ms)."""

    def __init__(self) -> None:
        self.points: deque[tuple[float, float]] = deque(maxlen=5)

    def update(self, t: float, v: float) -> float:
        self.points.append((t, v * KMH))
        n = len(self.points)
        if n < 3:
            return 0.0
        tm = sum(p[0] for p in self.points) / n
        vm = sum(p[1] for p in self.points) / n
        den = sum((p[0] - tm) ** 2 for p in self.points)
        return 0.0 if den <= 0 else sum((p[0] - tm) * (p[1] - vm) for p in self.points) / den


@dataclass
class Outputs:
    """What the next ABS_SteerState carries (ABS-OUT-02)."""

    turn: int = 0
    ref_speed: float = 0.0
    angle: float = 0.0  # FrontWheelAngleEst, bus sign (right positive)
    active: int = 0
    states: tuple[int, int, int, int] = (1, 1, 1, 1)
    fault: int = OK


class Abs:
    """Receivers, the 5 ms control step, and the outputs."""

    def __init__(self, chassis: cantools.database.Database, bench: cantools.database.Database) -> None:
        dbs = {"chassis": chassis, "bench": bench}
        self.rx = {name: E2EReceiver(dbs[db], dbs[db].get_message_by_name(name)) for name, db in INPUTS.items()}
        self.by_id = {r.message.frame_id: r for r in self.rx.values()}
        self.wheels = [WheelControl() for _ in WHEELS]
        self.readings = [0.0] * 4  # the sensors' last readings, km/h (ABS-OUT-01)
        self.samples: list[tuple[float, list[float]]] = []  # new sensor readings since the last step
        self.p_master = 0.0
        self.last_step: float | None = None
        self.open_line_since: list[float | None] = [None] * 4
        self.out = Outputs()
        self.restart()

    # --- the estimate's state, restarted at power-up, when a fault clears and when the ABS stops acting ---
    def restart(self, keep_turn: bool = False) -> None:
        self.filt: list[float] | None = None
        self.last_mean = 0.0
        self.inhibit_until: float | None = None  # T stays 0 until the filters have settled after a restart
        if not keep_turn:
            self.turn, self.turn_candidate, self.candidate_since = 0, 0, 0.0
        self.accel = [Accel() for _ in WHEELS]
        self.ref = 0.0
        self.ref_history: deque[tuple[float, float]] = deque()
        self.delta = 0.0  # [P4]'s sign, degrees; published only while T != 0
        self.delta_published = False
        self._reset_abs_episode()

    def _reset_abs_episode(self) -> None:
        self.abs_active = False
        self.points: deque[tuple[float, float]] = deque()
        self.start_point = (0.0, 0.0)
        self.slope0 = -5.0
        self.pattern, self.pattern_since, self.armed = 0, 0.0, 0
        self.recent_states: deque[list[int]] = deque(maxlen=PATTERN_WINDOW)
        self.axle_dv: list[float | None] = [None, None]
        self.axle_dv_t = [0.0, 0.0]
        self.pending: tuple[int, float] | None = None
        self.confirmed = False
        self.release_t: float | None = None
        self.avg_dv2: deque[float] = deque(maxlen=DELTA_AVG_FRAMES)
        self.avg_rear: deque[float] = deque(maxlen=DELTA_AVG_FRAMES)
        self.frame_parity = 0
        self.delta_running = 0.0

    # --- inputs ---
    def receive(self, msg: can.Message, t: float) -> None:
        receiver = self.by_id.get(msg.arbitration_id)
        # COM-RX-03: an error frame belongs to no message
        if receiver is None or msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
            return
        if receiver.on_frame(bytes(msg.data), t) and receiver.message.name == "IO_AbsSensors":
            values = receiver.values
            assert values is not None
            self.samples.append((t, [float(values[f"WheelSensor{w}"]) for w in WHEELS]))

    def brake_demand(self, now: float) -> float | None:
        """ABS-GEN-01: BrakePressure when above 0, else BrakePedal x 1.5 bar/%; None while DRV_Pedals is timed
        out."""
        rx = self.rx["DRV_Pedals"]
        if rx.timed_out(now) or rx.values is None:
            return None
        pressure = float(rx.values["BrakePressure"])
        return pressure if pressure > 0 else float(rx.values["BrakePedal"]) * BAR_PER_PEDAL_PCT

    # --- the 5 ms control step ---
    def step(self, now: float) -> None:
        demand = self.brake_demand(now)
        braking = demand is not None and demand >= BRAKE_SWITCH_BAR
        dt = CONTROL_S if self.last_step is None else min(max(now - self.last_step, 0.0), 0.05)
        self.last_step = now
        # the master cylinder as the plant's (PLANT-IO-ABS-02: the demand, at 1000 bar/s at most, 200 bar at most)
        target = min(demand or 0.0, MASTER_MAX)
        self.p_master += max(-MASTER_RATE * dt, min(MASTER_RATE * dt, target - self.p_master))
        for wheel in self.wheels:
            wheel.model(self.p_master, dt)
        samples, self.samples = self.samples, []
        if self.rx["IO_AbsSensors"].timed_out(now):
            # no signal on the wires reads as sensors without pulses: 0 km/h (the open line of PLANT-IO-ABS-03)
            samples = [(now, [0.0] * 4)]
        for t, speeds in samples:
            self.readings = speeds
            fault = self.fault(t, speeds, braking, demand is None)
            if fault != OK:
                self.passive(speeds, fault)
            else:
                if self.out.fault != OK:
                    self.restart()  # ABS-FLT-01: the estimate restarts as at power-up
                self.sample(t, speeds, braking)

    def fault(self, t: float, speeds: list[float], braking: bool, pedals_timed_out: bool) -> int:
        """ABS-FLT-01, evaluated every control period: WHEEL_SPEED_INVALID before INPUT_TIMEOUT."""
        invalid = any(not math.isfinite(v) or v < 0.0 or v > SENSOR_RANGE_MAX for v in speeds)
        for i, v in enumerate(speeds):
            others = [speeds[j] for j in range(4) if j != i]
            if v < OPEN_LINE_BELOW and all(o > OPEN_LINE_OTHERS_ABOVE for o in others) and not braking:
                since = self.open_line_since[i]
                self.open_line_since[i] = t if since is None else since
                if t - self.open_line_since[i] >= OPEN_LINE_S:  # type: ignore[operator]
                    invalid = True
            else:
                self.open_line_since[i] = None  # counts again from 0 whenever its condition breaks
        if invalid:
            return WHEEL_SPEED_INVALID
        return INPUT_TIMEOUT if pedals_timed_out else OK

    def passive(self, speeds: list[float], fault: int) -> None:
        """ABS-FLT-01: valves unpowered, AbsActive 0, every PressureState INCREASE, T 0, delta 0, the reference
        speed the third-largest wheel."""
        for wheel in self.wheels:
            wheel.go(Phase.PASSIVE, 0.0)
        self._reset_abs_episode()
        self.turn = 0
        finite = [v if math.isfinite(v) else 0.0 for v in speeds]
        self.out = Outputs(turn=0, ref_speed=ranked(finite, 3), angle=0.0, active=0, states=(1, 1, 1, 1),
                           fault=fault)

    def sample(self, t: float, speeds: list[float], braking: bool) -> None:
        """One sensor sample without a fault: reference speed, slip control, identification, outputs."""
        accel = [self.accel[i].update(t, v) for i, v in enumerate(speeds)]
        if self.filt is None:
            self.filt = list(speeds)
        if self.abs_active:
            ref = self.ref_under_abs(t, speeds)
        else:
            ref = self.ref_before_abs(t, speeds, braking)
        self.ref = max(0.0, ref)
        # the slip control (ABS-BRK-01)
        was_active = self.abs_active
        may_start = braking and self.ref > ABS_START_SPEED
        if not braking or self.ref < ABS_MIN_SPEED:
            for wheel in self.wheels:
                wheel.go(Phase.PASSIVE, t)
        else:
            # each wheel against the speed it would roll at: the wheel's speed moved to the centre of gravity
            # (eq. 14 / eq. 5 with the identified delta; no correction before a turn is identified)
            moved = corrected(speeds, self.ref, self.delta_running if self.confirmed else 0.0)
            for i, wheel in enumerate(self.wheels):
                slip = (self.ref - moved[i]) / self.ref if self.ref > 0.5 else 0.0
                scale = TURN_FRONT_SLIP_SCALE if (i < 2 and self.confirmed) else 1.0
                if wheel.step(t, slip, accel[i], self.p_master, may_start, scale):
                    self.switching_point(t, i, speeds)
        active = any(w.phase != Phase.PASSIVE for w in self.wheels)
        if active and not was_active:
            self.start_abs(t)
        elif was_active and not active:
            self._reset_abs_episode()  # the ABS stopped acting: the filters restart from the raw speeds
            self.filt = list(speeds)
        self.abs_active = active
        if active:
            self.identify_under_abs(t, speeds)
        self.ref_history.append((t, self.ref))
        while self.ref_history and t - self.ref_history[0][0] > 0.1:
            self.ref_history.popleft()
        self.publish()

    # --- before ABS control ---
    def ref_before_abs(self, t: float, speeds: list[float], braking: bool) -> float:
        """ABS-TURN-01 on the filtered speeds, ABS-EST-01's selection, ABS-EST-02 (eq. 12, filtered)."""
        filt = self.filt
        assert filt is not None
        mean = sum(speeds) / 4.0
        if abs(mean - self.last_mean) > JUMP_KMH:
            # no car changes its speed by that in one sample: a new world (the bench restarted the scenario, the
            # ECU was not told, PLANT-SCN-04); the old differences are forgotten
            filt[:] = [mean] * 4
            self.turn = self.turn_candidate = 0
            self.inhibit_until = t + T_SETTLE_S
        if self.inhibit_until is None:
            self.inhibit_until = t + T_SETTLE_S  # the first sample after a restart (power-up, a fault cleared)
        self.last_mean = mean
        alpha = CONTROL_S / (FILTER_TAU_S + CONTROL_S)
        for i, v in enumerate(speeds):
            filt[i] += (v - filt[i]) * alpha
        rear = (filt[2] + filt[3]) / 2.0
        dv1, dv2 = filt[1] - filt[0], filt[3] - filt[2]
        if rear < T_MIN_SPEED or t < self.inhibit_until:
            self.turn = self.turn_candidate = 0
        else:
            candidate = turn_state(dv1, dv2)
            if candidate == self.turn:
                self.turn_candidate = candidate
            elif candidate != self.turn_candidate:
                self.turn_candidate, self.candidate_since = candidate, t
            elif t - self.candidate_since >= T1_S - 1e-9:
                self.turn = candidate
        self.delta = front_angle(dv2, rear) if self.turn != 0 else 0.0
        self.delta_published = self.turn != 0
        if braking:
            return ranked(speeds, 2)  # braking before ABS: the second-largest wheel
        if self.turn != 0:
            return (speeds[2] + speeds[3]) / 2.0  # eq. 5
        return ranked(speeds, 3)  # straight: the third-largest wheel

    # --- under ABS control ---
    def start_abs(self, t: float) -> None:
        self._reset_abs_episode()
        self.abs_active = True
        # the reference speed at the start is the extrapolation's base until the first switching point; it is
        # no interpolation point (before ABS the second-largest wheel slips with the others: it reads low, and
        # a slope through it and the first free-rolling point would point upwards)
        self.start_point = (t, self.ref)
        if len(self.ref_history) >= 2 and self.ref_history[-1][0] - self.ref_history[0][0] > 0.02:
            (t0, v0), (t1, v1) = self.ref_history[0], self.ref_history[-1]
            self.slope0 = (v1 - v0) * KMH / (t1 - t0)
        self.slope0 = min(SLOPE_MAX, max(SLOPE_MIN, self.slope0))
        if self.turn != 0:  # a turn identified before ABS control: taken as confirmed
            self.confirm(t, self.turn)

    def confirm(self, t: float, turn: int) -> None:
        self.turn, self.confirmed, self.release_t = turn, True, t
        self.delta_published = False
        self.avg_dv2.clear()
        self.avg_rear.clear()
        for i in (2, 3):  # ABS-EST-01 (informative): the rear axle released in an identified braked turn
            self.wheels[i].go(Phase.KEPT_RELEASED, t)

    def rear_free(self, t: float) -> bool:
        return self.confirmed and self.release_t is not None and t - self.release_t >= REAR_RELEASE_SETTLE_S

    def ref_under_abs(self, t: float, speeds: list[float]) -> float:
        """ABS-EST-01 under ABS: eq. 5 on the freely rolling rear wheels once released; before that the
        switching points as interpolation points, extrapolated with the slope of the last ones, never below the
        second-largest corrected wheel."""
        if self.rear_free(t):
            return (speeds[2] + speeds[3]) / 2.0
        tp, vp = self.points[-1] if self.points else self.start_point
        recent = [p for p in self.points if t - p[0] <= SLOPE_WINDOW_S]
        slope = self.slope0
        if len(recent) >= 2 and recent[-1][0] - recent[0][0] >= 0.03:
            n = len(recent)
            tm = sum(p[0] for p in recent) / n
            vm = sum(p[1] for p in recent) / n
            den = sum((p[0] - tm) ** 2 for p in recent)
            slope = sum((p[0] - tm) * (p[1] - vm) for p in recent) / den * KMH
        slope = min(SLOPE_MAX, max(SLOPE_MIN, slope))
        ref = vp + slope * (t - tp) / KMH
        return max(ref, ranked(corrected(speeds, self.ref, self.delta), 2))

    def switching_point(self, t: float, i: int, speeds: list[float]) -> None:
        """A wheel's hold -> increase switching point: an interpolation point of the reference speed and, on an
        axle whose other wheel is in INCREASE, the axle's difference (ABS-TURN-01 step 2)."""
        if not self.wheels[i].spun_up:
            return  # a wheel that has not re-accelerated still slips: no free-rolling speed at its switching point
        self.points.append((t, corrected(speeds, self.ref, self.delta)[i]))
        while len(self.points) > 2 and t - self.points[0][0] > 2 * SLOPE_WINDOW_S:
            self.points.popleft()
        # step 2: an inner wheel of the armed side (left turn: FL, RL; right turn: FR, RR), the outer wheel of
        # its axle in INCREASE
        inner_is_left = i % 2 == 0
        if self.armed == 0 or inner_is_left != (self.armed == 1):
            return
        axle = 0 if i < 2 else 1
        if self.wheels[i ^ 1].state == 1:  # INCREASE
            left, right = 2 * axle, 2 * axle + 1
            self.axle_dv[axle] = speeds[right] - speeds[left]  # dV1 = V_w2 - V_w1, dV2 = V_w4 - V_w3
            self.axle_dv_t[axle] = t
            self.evaluate_candidate(t)

    def evaluate_candidate(self, t: float) -> None:
        """ABS-TURN-01 step 2: with both axles measured, eq. 13 gives a candidate, kept only if it is the armed
        side; any evaluation that differs contradicts the pending one."""
        dv1, dv2 = self.axle_dv
        if self.confirmed or dv1 is None or dv2 is None or t - min(self.axle_dv_t) > AXLE_DV_MAX_AGE_S:
            return
        candidate = turn_state(dv1, dv2)
        if candidate != 0 and candidate == self.armed:
            if self.pending is None or self.pending[0] != candidate:
                self.pending = (candidate, t)
        else:
            self.pending = None

    def identify_under_abs(self, t: float, speeds: list[float]) -> None:
        """ABS-TURN-01 steps 1-3 and ABS-EST-02 under ABS."""
        states = [w.state for w in self.wheels]
        self.recent_states.append(states)
        # step 1: an inner wheel decreasing in one update of the window counts (the inner front and rear wheels
        # cycle on their own: their DECREASE stretches often alternate without sharing an update)
        decreasing = [any(past[i] == DECREASE for past in self.recent_states) for i in range(4)]
        left = decreasing[0] and decreasing[2] and states[1] == states[3] == INCREASE
        right = decreasing[1] and decreasing[3] and states[0] == states[2] == INCREASE
        pattern = 1 if left and not right else -1 if right and not left else 0   # both: no pattern
        if pattern != self.pattern:
            self.pattern, self.pattern_since = pattern, t
        if pattern != 0 and t - self.pattern_since >= T0_S - 1e-9 and pattern != self.armed:
            self.armed = pattern  # step 1: the other side's measurements no longer count
            self.axle_dv = [None, None]
            self.pending = None
        if not self.confirmed and self.pending is not None and t - self.pending[1] >= T1_S - 1e-9:
            self.confirm(t, self.pending[0])  # step 2: not contradicted for t1
        if self.rear_free(t):  # step 3: delta from the released rear axle, moving averages of 30 frames of 10 ms
            self.frame_parity ^= 1
            if self.frame_parity:
                self.avg_dv2.append(speeds[3] - speeds[2])
                self.avg_rear.append((speeds[2] + speeds[3]) / 2.0)
            if len(self.avg_dv2) >= 5:  # the angle the wheels are corrected with (slip control) meanwhile
                self.delta_running = front_angle(sum(self.avg_dv2) / len(self.avg_dv2),
                                                 sum(self.avg_rear) / len(self.avg_rear))
            if len(self.avg_dv2) == DELTA_AVG_FRAMES:
                rear = sum(self.avg_rear) / DELTA_AVG_FRAMES
                if rear >= DELTA_HOLD_SPEED or not self.delta_published:
                    self.delta = front_angle(sum(self.avg_dv2) / DELTA_AVG_FRAMES, rear)
                self.delta_published = True

    def publish(self) -> None:
        angle = -self.delta if (self.turn != 0 and self.delta_published) else 0.0  # bus sign: right positive
        self.out = Outputs(turn=self.turn, ref_speed=self.ref, angle=angle, active=int(self.abs_active),
                           states=tuple(w.state for w in self.wheels), fault=OK)  # type: ignore[arg-type]


# ==============================================================================================================
# Frames out (ABS-GEN-01, ABS-OUT-*, PLANT-IO-ABS-02)
# ==============================================================================================================
class Transmitter:
    def __init__(self, chassis: cantools.database.Database, bench: cantools.database.Database) -> None:
        self.speeds = E2ESender(chassis, chassis.get_message_by_name("ABS_WheelSpeeds"))
        self.state = E2ESender(chassis, chassis.get_message_by_name("ABS_SteerState"))
        self.valves = E2ESender(bench, bench.get_message_by_name("IO_AbsValves"))
        self.by_id = {s.message.frame_id: s for s in (self.speeds, self.state, self.valves)}
        self.values: dict[str, dict[str, float]] = {}  # the signals of each message's latest frame (DIAG-SVC-02)

    def sent(self, frame: can.Message) -> None:
        self.by_id[frame.arbitration_id].sent(frame)

    def valve_frame(self, ecu: Abs) -> can.Message:
        values: dict[str, float] = {}
        for name, wheel in zip(WHEELS, ecu.wheels):
            valve, duty = wheel.valve
            if ecu.out.fault != OK:
                valve, duty = RELEASED, 1.0  # ABS-FLT-01: valves unpowered
            values[f"Valve{name}"], values[f"InletDuty{name}"] = valve, duty
        return self.valves.frame(values)

    def chassis_frames(self, ecu: Abs) -> list[can.Message]:
        speeds, state = wheel_speed_values(ecu), steer_state_values(ecu)
        self.values["ABS_WheelSpeeds"], self.values["ABS_SteerState"] = speeds, state
        return [self.speeds.frame(speeds), self.state.frame(state)]  # ABS-OUT-01, -02


def wheel_speed_values(ecu: Abs) -> dict[str, float]:
    """ABS_WheelSpeeds' signals (ABS-OUT-01): the sensors' last readings."""
    return {f"WheelSpeed{w}": v for w, v in zip(WHEELS, ecu.readings)}


def steer_state_values(ecu: Abs) -> dict[str, float]:
    """ABS_SteerState's signals (ABS-OUT-02)."""
    out = ecu.out
    state: dict[str, float] = {"TurnDirection": out.turn, "RefVehicleSpeed": out.ref_speed,
                               "FrontWheelAngleEst": out.angle, "AbsActive": out.active, "AbsFault": out.fault}
    state.update({f"PressureState{w}": s for w, s in zip(WHEELS, out.states)})
    return state


# ==============================================================================================================
# Running on a bus
# ==============================================================================================================
def drain(bus: can.BusABC, ecu: Abs, now: float, diag: uds_server.Diagnostics | None = None) -> None:
    """Judge every frame that arrived since the last step, in order, each at its receive time (COM-RX-02: the
    driver's timestamp, epoch seconds; a stamp more than a second from `now` is of another clock and the frame
    gets `now`)."""
    while True:
        try:
            msg = bus.recv(timeout=0.0)
        except can.CanError:
            return
        if msg is None:
            return
        if diag is not None and diag.on_frame(msg):
            continue  # a diagnostic request's frame: the UDS server's, never an input's
        ecu.receive(msg, msg.timestamp if abs(now - msg.timestamp) < 1.0 else now)


@dataclass
class TaskStats:
    faults: Counter[int] = field(default_factory=Counter)
    skipped_slots: int = 0
    max_late_ms: float = 0.0
    max_late_at: float = 0.0

    def report(self, ecu: Abs) -> str:
        inputs = " ".join(f"{name}:{rx.accepted}/{rx.rejected}/{rx.state}" for name, rx in ecu.rx.items())
        line = (f"stats faults={dict(sorted(self.faults.items()))} skipped={self.skipped_slots} "
                f"max_late={self.max_late_ms:.1f}ms at {time.strftime('%H:%M:%S', time.localtime(self.max_late_at))} "
                f"accepted/rejected/E2E state {inputs}")
        self.faults.clear()
        self.skipped_slots, self.max_late_ms = 0, 0.0
        return line


class Node:
    """The ABS's software on its bus: the control (Abs) and the frames' senders (Transmitter). `restart` is what
    power-up does, and what an ECUReset does (DIAG-RST-02): the estimate, the slip control and the outputs from
    their power-up state, receivers that have applied no frame. The AliveCounters, which the contract leaves free
    to start anew, carry on (this ABS's choice): the receivers of its messages see no WRONGSEQUENCE."""

    def __init__(self, chassis: cantools.database.Database, bench: cantools.database.Database) -> None:
        self.chassis, self.bench = chassis, bench
        self.ecu, self.tx = Abs(chassis, bench), Transmitter(chassis, bench)

    def restart(self) -> None:
        self.ecu = Abs(self.chassis, self.bench)

    # --- what the diagnostic server reads (ABS-DIAG-03) ---
    def outputs(self, message: str) -> dict[str, float] | None:
        """The signals of the message's latest frame (sent in the last 10 ms): a DID with a signal equals one of the
        ABS's frames (DIAG-SVC-02). None before the first: the DBC start value."""
        return self.tx.values.get(message)

    def inputs(self, message: str) -> dict[str, float] | None:
        rx = self.ecu.rx.get(message)
        return None if rx is None else rx.values

    def brake_demand(self) -> float:
        """0xFD01: the driver's brake demand from the last valid DRV_Pedals (ABS-GEN-01), bar; 0 before the first."""
        values = self.ecu.rx["DRV_Pedals"].values
        if values is None:
            return 0.0
        pressure = float(values["BrakePressure"])
        return pressure if pressure > 0 else float(values["BrakePedal"]) * BAR_PER_PEDAL_PCT

    def may_test(self) -> bool:
        """ABS-DIAG-02: at standstill and not braking (the brake switch open: no demand of 2 bar or more)."""
        demand = self.ecu.brake_demand(time.time())
        return self.ecu.out.ref_speed < TEST_MAX_SPEED and not (demand is not None and demand >= BRAKE_SWITCH_BAR)


def control_loop(bus: can.BusABC, node: Node, stop: threading.Event, send: Callable[[can.Message], bool],
                 stats_every: float = 0.0, diag: uds_server.Diagnostics | None = None) -> None:
    """The 5 ms control step on an absolute grid: read the bus, evaluate, send IO_AbsValves at once
    (PLANT-IO-ABS-02: after each control step), and ABS_WheelSpeeds / ABS_SteerState every 2nd step (10 ms,
    ABS-GEN-01), so no output is older than one step after the newest reading it uses (ABS-EST-01). Then the
    fault memory gets the step's AbsFault and the diagnostic server answers what it received (after the frames:
    a diagnostic response never delays them)."""
    tick, next_t = 0, time.monotonic()
    stats, next_stats = TaskStats(), next_t + stats_every
    while not stop.is_set():
        now = time.monotonic()
        if next_t > now:
            time.sleep(next_t - now)
            now = time.monotonic()
        late = now - next_t
        if late * 1000.0 > stats.max_late_ms:
            stats.max_late_ms, stats.max_late_at = late * 1000.0, time.time()
        wall = time.time()
        ecu, tx = node.ecu, node.tx
        drain(bus, ecu, wall, diag)
        ecu.step(wall)
        stats.faults[ecu.out.fault] += 1
        frames = [tx.valve_frame(ecu)]
        if tick % 2 == 0:
            frames += tx.chassis_frames(ecu)
        for frame in frames:
            if send(frame):
                tx.sent(frame)
        if diag is not None:
            diag.control_step(diag.failing({"ABS_SteerState.AbsFault": ecu.out.fault}))  # DIAG-DTC-02
            diag.poll()  # ISO-TP and UDS, never blocking; an ECUReset restarts `node.ecu` for the next step
        missed = max(0, int(late / CONTROL_S) - 1)  # a late step skips the slots it missed instead of a burst
        stats.skipped_slots += missed
        tick += 1 + missed
        next_t += CONTROL_S * (1 + missed)
        if stats_every and now >= next_stats:
            print(stats.report(node.ecu), flush=True)
            next_stats = now + stats_every


def make_sender(bus: can.BusABC) -> Callable[[can.Message], bool]:
    """COM-FRM-02: never stop sending; a full transmit buffer costs one frame (its counter goes with the next)."""
    def send(frame: can.Message) -> bool:
        try:
            bus.send(frame, timeout=0.002)
        except can.CanError:
            return False
        return True
    return send


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    dbc = Path(__file__).resolve().parent.parent / "dbc"
    parser = argparse.ArgumentParser(description=(__doc__ or "ABS ECU").splitlines()[0])
    parser.add_argument("--interface", default="udp_multicast", help="python-can interface (default udp_multicast)")
    parser.add_argument("--channel", default=None, help="python-can channel (e.g. 239.255.1.3, vcan0)")
    parser.add_argument("--bitrate", type=int, default=None, help="bitrate, for interfaces that take one")
    parser.add_argument("--dbc", type=Path, default=dbc / "chassis.dbc", help="the chassis DBC")
    parser.add_argument("--bench-dbc", type=Path, default=dbc / "bench.dbc", help="the bench I/O DBC")
    parser.add_argument("--stats", type=float, default=0.0, metavar="S",
                        help="print faults, late steps and received frames every S seconds (diagnosis)")
    parser.add_argument("--vin", default=IDENTIFICATION["VehicleIdentificationNumber"],
                        help="the VIN this ABS holds (0xF190, 17 characters; '' for none programmed)")
    parser.add_argument("--nvm", type=Path, default=None, metavar="FILE",
                        help="non-volatile memory (the fault memory) kept in FILE across restarts; "
                             "default: none, every start is an ABS as delivered")
    parser.add_argument("--diag-defect", choices=("confirmed-never",), default=None,
                        help="a deliberate diagnostic defect (off by default) for checking a tester: confirmed-never "
                             "never sets confirmedDTC (status bit 3) nor, therefore, warningIndicatorRequested (bit 7)")
    return parser.parse_args(argv)


def open_bus(args: argparse.Namespace) -> can.BusABC:
    kwargs: dict[str, object] = {"interface": args.interface}
    if args.channel is not None:
        kwargs["channel"] = args.channel
    if args.bitrate is not None:
        kwargs["bitrate"] = args.bitrate
    if args.interface == "udp_multicast":
        kwargs["hop_limit"] = 0  # keep the traffic on this host, as the bench does
    bus = can.Bus(**kwargs)  # type: ignore[arg-type]
    if args.interface == "udp_multicast":
        only_own_group(bus)
    return bus


def only_own_group(bus: can.BusABC) -> None:
    """Receive only our multicast group (README.md, "Pointing it at a bus"): IP_MULTICAST_ALL = 0, and for the
    dual-stack IPv6 socket IPV6_MULTICAST_ALL = 0 as well; then drop what was queued before."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None:
        return
    try:
        if sock.family == socket.AF_INET6:
            sock.setsockopt(socket.IPPROTO_IPV6, 29, 0)  # IPV6_MULTICAST_ALL, linux/in6.h
        sock.setsockopt(socket.IPPROTO_IP, 49, 0)  # IP_MULTICAST_ALL, linux/in.h
    except OSError:
        return  # not Linux: no such leak to close
    while True:
        try:
            sock.recv(65535, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        chassis = cantools.database.load_file(str(args.dbc))
        bench = cantools.database.load_file(str(args.bench_dbc))
        if not isinstance(chassis, cantools.database.can.Database) or \
                not isinstance(bench, cantools.database.can.Database):
            raise E2EConfigError(f"{args.dbc}, {args.bench_dbc}: not CAN databases")
        node = Node(chassis, bench)
    except (OSError, KeyError, ValueError, cantools.database.errors.Error) as exc:  # E2EConfigError, DiagConfigError
        print(f"abs_ecu: {exc}", flush=True)
        return 2
    try:
        bus = open_bus(args)
    except (can.CanError, OSError, ValueError) as exc:
        where = f"{args.interface} {args.channel}" if args.channel else args.interface
        print(f"abs_ecu: cannot open {where}: {exc}", flush=True)
        return 2
    try:
        diag = uds_server.Diagnostics(
            "ABS", make_sender(bus), identification={**IDENTIFICATION, "VehicleIdentificationNumber": args.vin},
            live={"BrakeDemand": node.brake_demand}, outputs=node.outputs, inputs=node.inputs,
            signals=[chassis, bench], preconditions={"ValveAndPumpTest": node.may_test}, on_reset=node.restart,
            defect=args.diag_defect, nvm=args.nvm)
    except (OSError, ValueError) as exc:  # a DiagConfigError is a ValueError
        bus.shutdown()
        print(f"abs_ecu: {exc}", flush=True)
        return 2
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):  # also when started in the background (SIGINT ignored there)
        signal.signal(signum, lambda *_: stop.set())
    print(f"ABS running on {args.interface} {args.channel or ''}".rstrip(), flush=True)
    try:
        control_loop(bus, node, stop, make_sender(bus), args.stats, diag)
    finally:
        diag.close()
        bus.shutdown()
        print("ABS stopped", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
