"""A stand-alone steer-by-wire ECU (SBW) of the A-class car, written from the contract documents alone.

Node `SBW` of `dbc/chassis.dbc`, built only from README.md, `docs/contract/sbw.md`, `common.md`, `plant.md`
("Bench I/O — SBW"), `docs/spec/*.md` and the DBCs, as an outside supplier would. Comments cite the requirement ids.

- Wired I/O (`dbc/bench.dbc`, PLANT-IO-SBW-01..06, 5 ms): reads `IO_SbwHandWheel` (hand-wheel sensor, column
  angle, torsion-bar torque), `IO_SbwPinion` (pinion sensor, actuator rotor angle) and `IO_SbwCurrents`, and sends
  `IO_SbwActuators` (pinion position request, road-feel torque request) at once when a hand-wheel sample arrives,
  the request extrapolated over the sample's age (a late task does not steer to where the hand wheel was).
- Chassis bus (SBW-GEN-01): sends `SBW_HandWheel` and `SBW_Pinion` on its own 10 ms clock, both carrying the
  values of the same complete 5 ms sample (SBW-OUT-03: no age difference between them); reads `IMU_Motion` and
  `ABS_WheelSpeeds` for the optional yaw-rate feedback (SBW-CTL-05: coded `SteeringMode` YAW_RATE, see
  Diagnostics; DIRECT as delivered).
- Steering (SBW-CTL-01): the pinion is requested to the hand-wheel angle (ratio 1); the rig's position servo
  follows it (PLANT-IO-SBW-03). Road feel (SBW-CTL-04): the driver holds a quarter of the rack's load torque
  (from the steering motor's current) plus a light centring spring; the road-feel motor also damps the column on
  its torsion bar (PLANT-IO-SBW-04) and the hand wheel, so that it returns when let go.
- Faults (SBW-FLT-01..04): plausibility of both angle sensors against the independent channels (column estimate,
  actuator rotor angle), in the priority 3, 2, 1, 4.
- Diagnostics (SBW-DIAG-01..04, docs/contract/diagnostics.md): a UDS server on ISO-TP (`examples/uds_server.py`,
  shared by the three examples; can-isotp driven from this loop, see below) on 0x705/0x70D and the functional
  0x7DF. Coding: `SteeringMode` (0xFDC0) DIRECT or YAW_RATE (this SBW has no YAW_RATE_LAT_ACCEL: a write of it is
  refused with NRC 0x31) and `IdealYawGain` (0xFDC1), in force from the next hand-wheel sample; `--mode` and
  `--ideal-yaw-gain` are the coding as delivered. Fault memory fed every 10 ms (the SBW_Pinion clock) from the
  SbwFault it sends, and SENSOR_SIGNAL_LOST (SBW-FLT-06's condition: an IO_Sbw* input timed out; only the DTC:
  this SBW's bus reaction to it is unchanged, SbwFault does not go to INPUT_TIMEOUT for it). Routine 0x0201
  SteeringAngleSensorZero checks its precondition (VehicleSpeed below 1 km/h, else NRC 0x22) and changes nothing
  (the rig's sensors read 0 straight ahead). ECUReset restarts the steering and the receivers as at power-up (the
  AliveCounters carry on); coding and fault memory are kept (`--nvm FILE`: also across process restarts).

  Why the ISO-TP layer runs in this loop and not in a thread of its own: this loop is the bus's only reader (a
  NotifierBasedCanStack would need a second reader, a can.Notifier, and a thread that competes with the 5 ms task
  for the interpreter); the loop passes every frame of 0x705 and 0x7DF to the server and calls its `poll()` once
  per pass, which never blocks. The loop wakes at least every 7 ms (its clocks), well within P2 = 50 ms and the
  ISO-TP timeouts; a diagnostic frame never reaches the E2E receivers (its identifier is none of theirs).

Diagnostic defect for checking a tester (off by default): `--diag-defect wrong-nrc`: WriteDataByIdentifier and
RoutineControl in the default session are answered with NRC 0x33 (securityAccessDenied) instead of 0x7F
(serviceNotSupportedInActiveSession, DIAG-NRC-01 item 3 before item 7).

End-to-end protection as an AUTOSAR stack does it (docs/spec/e2e.md, COM-E2E-*, COM-RX-*): each message's profile
and parameters are the DBC's `E2E_*` attributes (through cantools), CRC and counter are the `autosar-e2e`
library's; each received message has the profile's check and the E2E state machine, and a frame is applied only
with status OK or OKSOMELOST in state VALID and every signal within its DBC range.

Run it as the external SBW of the bench (three processes on one host):

    bench plant --interface udp_multicast --channel 239.255.1.3 --external SBW &
    python examples/sbw_ecu.py --interface udp_multicast --channel 239.255.1.3
    bench run --interface udp_multicast --channel 239.255.1.3 --external all --dut SBW

It prints a line with `running` once it is on the bus and `stopped` at the end (SIGINT or SIGTERM, exit 0).
Needs python-can, cantools, autosar-e2e (import name `e2e`), can-isotp (import name `isotp`) and the standard
library only; nothing of the bench.
"""

from __future__ import annotations

import argparse
import gc
import math
import signal
import socket
import sys
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
import cantools
from e2e import p01, p11

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT / "examples") not in sys.path:
    sys.path.insert(0, str(ROOT / "examples"))  # the examples' shared diagnostic server
import uds_server  # noqa: E402

#: DIAG-ID-01: this SBW's own identification (the VIN is the vehicle's, programmed at the end of the line: --vin)
IDENTIFICATION = {"SparePartNumber": "SBW-EX0001", "EcuSerialNumber": "SBW-EX000001",
                  "VehicleIdentificationNumber": "BENCH000000000001", "SoftwareVersionNumber": "EX-2.0"}
STEERING_MODES = {0: "DIRECT", 1: "YAW_RATE"}  # SteeringMode (0xFDC0) values this SBW has (SBW-DIAG-02)
ZERO_LEARN_MAX_SPEED = 1.0  # km/h, SBW-DIAG-03's precondition

# --- The steering system (sbw.md, "The steering system the SBW drives") ----------------------------------------
K_H = 372.0 * math.pi / 180.0  # torsion bar, N·m per hand-wheel degree (6.49)
NM_PER_A = 0.8  # K_m r_m = K_M r_M: 1 A is 0.8 N·m at the column (road feel) and at the pinion (steering motor)
B_PINION = 0.2 + 1.0e-4 * 20.0**2  # B_p + B_M r_M², N·m·s/rad at the pinion
R_PINION = 0.008  # pinion radius, m
RACK_FORCE_TAU = 0.020  # s, RackForce low-passed like the reference's (SBW-OUT-02)

# --- Road feel (SBW-CTL-04: this SBW's design; only its monotony and the return are judged) ---------------------
FEEL_GAIN = 0.25  # driver torque per rack-load torque at the pinion (the reference's assist gain 4)
CENTRE_NM_PER_DEG = 0.01  # centring spring at the hand wheel (returns it also where the tyres align nothing)
LOAD_TAU = 0.030  # s, low-pass of the rack load before it becomes a torque at the driver's hands
HANDWHEEL_DAMPING = 0.3  # N·m·s/rad on the hand wheel's (column estimate's) speed: damps the hands-off return
TWIST_DAMPING = 0.6  # N·m·s/rad on the torsion bar's twist rate: damps the column's 17.5 Hz mode (PLANT-IO-SBW-04);
#                      chosen on a model of the column with a 5 ms loop: stable up to 4.5 ms of I/O delay hands-off
RATE_TAU = 0.020  # s, low-pass of the angle rates (0.1° sensors sampled every 5 ms)
APPLY_LEAD = 0.0015  # s: the request is the hand wheel extrapolated over its sample's age plus this (PLANT-IO-SBW-03:
#                      the rig applies a frame from its next 1 ms tick). Measured on udp_multicast at 1 Hz: phase lag
#                      1.2-1.6° (3-4 ms) without any lead, -0.3° with the age and 2 ms
MAX_LEAD_RATE = 1000.0  # deg/s: a faster step of θ_h between two samples is a restart, not a motion (no lead)
JUMP_DEG = 20.0  # a step of an independent channel above this in 5 ms is a restart of the mechanics, not motion
MAX_FEEL_NM = 20.0  # RoadFeelTorqueRequest range

# --- Faults (SBW-FLT-*) -----------------------------------------------------------------------------------------
OK, HANDWHEEL_RANGE, HANDWHEEL_STUCK, PINION_RANGE, INPUT_TIMEOUT = range(5)
HANDWHEEL_LIMIT = 900.0  # deg, SBW-FLT-01 (the DBC range)
PINION_LIMIT = 600.0  # deg, SBW-FLT-03
PLAUSIBLE_DEG = 20.0  # SBW-FLT-01 / -03: sensor against its independent channel
STUCK_DEG = 5.0  # SBW-FLT-02

# --- Yaw-rate feedback (SBW-CTL-05; this supplier's coding: --mode YAW_RATE --ideal-yaw-gain G) -----------------
RATIO = 15.0
FEEDBACK_MIN_SPEED = 10.0 / 3.6  # m/s
FEEDBACK_LIMIT = 5.0 * RATIO  # ±5° of road wheel, in hand-wheel degrees
FEEDBACK_RATE = 100.0  # hand-wheel deg/s: the additional angle's rate limit (returns to 0 at it, SBW-FLT-04)
FEEDBACK_KI = 10.0  # hand-wheel deg per (deg/s of yaw-rate error) per s: ~0.4 s to settle (yaw gain 0.23-0.28)
REFERENCE_TAU = 0.1  # s, first-order yaw-rate reference

PERIOD = 0.005  # s, the I/O cycle (PLANT-IO-SBW-02)
OUT_PERIOD = 0.010  # s, SBW_HandWheel and SBW_Pinion (SBW-GEN-01)
IO_INPUTS = ("IO_SbwHandWheel", "IO_SbwPinion", "IO_SbwCurrents")
BUS_INPUTS = ("IMU_Motion", "ABS_WheelSpeeds")


# ==============================================================================================================
# E2E from the DBC attributes (COM-E2E-*, docs/spec/e2e.md)
# ==============================================================================================================
class ConfigError(ValueError):
    """The database configures something this ECU cannot use (one line, naming the message)."""


PROFILES: dict[str, tuple[Any, Any, dict[str, int]]] = {
    "P01": (p01.e2e_p01_protect, p01.e2e_p01_check,
            {"BOTH": p01.E2E_P01_DATAID_BOTH, "ALT": p01.E2E_P01_DATAID_ALT, "LOW": p01.E2E_P01_DATAID_LOW,
             "NIBBLE": p01.E2E_P01_DATAID_NIBBLE}),
    "P11": (p11.e2e_p11_protect, p11.e2e_p11_check,
            {"BOTH": p11.E2E_P11_DATAID_BOTH, "NIBBLE": p11.E2E_P11_DATAID_NIBBLE}),
}
COUNTER_VALUES = 15  # P01/P11: 0 … 14 in the low nibble of the byte after the CRC


def e2e_attributes(db: Any, message: Any) -> dict[str, Any]:
    """The message's E2E_* attributes (own value over the database default), ENUMs as their choice's name."""
    definitions = db.dbc.attribute_definitions if db.dbc is not None else {}

    def choice(definition: Any, value: Any) -> Any:
        choices = getattr(definition, "choices", None)
        if getattr(definition, "type_name", None) == "ENUM" and choices and isinstance(value, int):
            return choices[value] if isinstance(choices, list) else choices.get(value, value)
        return value

    values = {name[4:]: choice(d, d.default_value) for name, d in definitions.items()
              if name.startswith("E2E_") and d.default_value is not None}
    own = message.dbc.attributes if message.dbc is not None else {}
    values.update({name[4:]: choice(a.definition, a.value) for name, a in own.items() if name.startswith("E2E_")})
    return values


@dataclass(frozen=True)
class E2E:
    """One message's Profile 1/11 configuration and state-machine parameters, all from the DBC."""

    protect_fn: Callable[..., None]
    check_fn: Callable[..., bool]
    data_id: int
    args: dict[str, int]
    counter_byte: int
    max_delta: int
    window: int
    min_ok: dict[str, int]
    max_error: dict[str, int]

    @classmethod
    def of(cls, db: Any, message: Any) -> E2E | None:
        values = e2e_attributes(db, message)
        profile = str(values.get("Profile", "None"))
        if profile == "None":
            return None
        if profile not in PROFILES:
            raise ConfigError(f"{message.name}: E2E_Profile {profile} is not supported by this ECU (P01, P11)")

        def number(key: str) -> int:
            if key not in values:
                raise ConfigError(f"{message.name}: no E2E_{key} and no database default")
            raw = values[key]
            return int(raw, 0) if isinstance(raw, str) else int(raw)

        protect_fn, check_fn, modes = PROFILES[profile]
        mode = str(values.get("DataIDMode", "BOTH"))
        if mode not in modes:
            raise ConfigError(f"{message.name}: E2E_DataIDMode {mode} is none of {', '.join(modes)}")
        offset, length = number("Offset"), number("DataLength")
        if offset % 8 or length % 8 or offset // 8 + 1 >= message.length:
            raise ConfigError(f"{message.name}: E2E_Offset {offset} / E2E_DataLength {length} unusable")
        states = ("Init", "Valid", "Invalid")
        return cls(protect_fn, check_fn, number("DataID"),
                   {"length": length // 8, "offset": offset // 8, "data_id_mode": modes[mode]},
                   offset // 8 + 1, number("MaxDeltaCounter"), number("WindowSize"),
                   {s.upper(): number(f"MinOkState{s}") for s in states},
                   {s.upper(): number(f"MaxErrorState{s}") for s in states})

    def counter(self, data: bytes | bytearray) -> int:
        return data[self.counter_byte] & 0x0F

    def protect(self, data: bytearray, previous: int) -> None:
        """COM-E2E-01/02: the counter after `previous` (the library increments it) and the CRC, in place."""
        data[self.counter_byte] = (data[self.counter_byte] & 0xF0) | (previous & 0x0F)
        self.protect_fn(data, self.data_id, increment_counter=True, **self.args)

    def crc_ok(self, data: bytes | bytearray) -> bool:
        return bool(self.check_fn(bytearray(data), self.data_id, **self.args))


class Receiver:
    """COM-RX-01/02: the profile's check, the E2E state machine, the consumer rule and the timeout."""

    def __init__(self, db: Any, message: Any) -> None:
        self.message = message
        self.e2e = E2E.of(db, message)
        self.cycle = message.cycle_time / 1000.0
        self.last = COUNTER_VALUES - 1  # E2E_P11CheckInit: a first 0 is in sequence
        self.state = "NODATA"
        self.window: deque[str] = deque(maxlen=self.e2e.window if self.e2e else 1)
        self.values: dict[str, float] | None = None
        self.t: float | None = None  # reception stamp of the last applied frame
        self.applied = self.rejected = 0

    def on_frame(self, data: bytes, t: float) -> bool:
        if self.e2e is None:
            ok = len(data) == self.message.length
        else:
            status = self._check(data)
            state = self._sm(status)
            ok = status in ("OK", "OKSOMELOST") and state == "VALID"
        if ok:
            values = self.message.decode(bytes(data), decode_choices=False)
            ok = all(math.isfinite(v) and (s.minimum is None or v >= s.minimum - 1e-9)
                     and (s.maximum is None or v <= s.maximum + 1e-9)
                     for s in self.message.signals for v in (values[s.name],))
            if ok:
                self.values, self.t = values, t
        self.applied += ok
        self.rejected += not ok
        return bool(ok)

    def timed_out(self, now: float) -> bool:
        return self.t is None or now - self.t > 3 * self.cycle

    def _check(self, data: bytes) -> str:
        assert self.e2e is not None
        if len(data) != self.message.length or not self.e2e.crc_ok(data):
            return "ERROR"
        counter = self.e2e.counter(data)
        if counter >= COUNTER_VALUES:
            return "ERROR"
        step, self.last = (counter - self.last) % COUNTER_VALUES, counter
        if step == 1:
            return "OK"
        if step == 0:
            return "REPEATED"
        return "OKSOMELOST" if step <= self.e2e.max_delta else "WRONGSEQUENCE"

    def _sm(self, status: str) -> str:
        assert self.e2e is not None
        if self.state == "NODATA":
            if status != "ERROR":
                self.window.clear()
                self.state = "INIT"
            return self.state
        self.window.append(status)
        ok = sum(s in ("OK", "OKSOMELOST") for s in self.window)
        errors = self.window.count("ERROR")
        fits = ok >= self.e2e.min_ok[self.state] and errors <= self.e2e.max_error[self.state]
        if self.state == "INIT":
            self.state = "VALID" if fits else "INVALID" if errors > self.e2e.max_error["INIT"] else "INIT"
        elif self.state == "VALID":
            self.state = "VALID" if fits else "INVALID"
        elif fits:
            self.state = "VALID"
        return self.state


class Sender:
    """COM-FRM-01, COM-VAL-01, COM-E2E-01..03: signals on their raw grid within range, then counter and CRC."""

    def __init__(self, db: Any, message: Any) -> None:
        self.message = message
        self.e2e = E2E.of(db, message)
        self.counter = COUNTER_VALUES - 1  # the library's increment makes the first frame's 0

    def frame(self, values: dict[str, float]) -> can.Message:
        raw = {s.name: raw_on_grid(s, values.get(s.name, s.initial or 0)) for s in self.message.signals}
        data = bytearray(self.message.encode(raw, scaling=False, strict=False))
        if self.e2e is not None:
            self.e2e.protect(data, self.counter)
        return can.Message(arbitration_id=self.message.frame_id, data=bytes(data), is_extended_id=False)

    def sent(self, frame: can.Message) -> None:
        if self.e2e is not None:
            self.counter = self.e2e.counter(frame.data)


def raw_on_grid(sig: Any, value: float) -> int:
    """COM-VAL-01: saturated to the DBC range, on the raw grid; a non-finite value sends the start value."""
    if not math.isfinite(value):
        return int(sig.raw_initial or 0)
    lo = math.ceil((sig.minimum - sig.offset) / sig.scale - 1e-9)
    hi = math.floor((sig.maximum - sig.offset) / sig.scale + 1e-9)
    return int(min(max(round((value - sig.offset) / sig.scale), lo), hi))


# ==============================================================================================================
# The SBW's functions
# ==============================================================================================================
class LowPass:
    """First-order low-pass sampled every `PERIOD` (its `value` may be set: a restart of the mechanics)."""

    def __init__(self, tau: float, value: float = 0.0) -> None:
        self.a = PERIOD / (tau + PERIOD)
        self.value = value

    def __call__(self, x: float) -> float:
        self.value += self.a * (x - self.value)
        return self.value


@dataclass
class Sample:
    """One 5 ms sample of the wired sensors (PLANT-IO-SBW-02), as last applied."""

    handwheel: float = 0.0  # hand-wheel angle sensor, deg
    column: float = 0.0  # column angle θ_c, deg
    torque: float = 0.0  # torsion-bar torque F_m, N·m
    pinion: float = 0.0  # pinion angle sensor, deg
    actuator: float = 0.0  # pinion angle from the actuator's rotor, deg
    i_feel: float = 0.0  # road-feel motor current, A
    i_steer: float = 0.0  # steering motor current, A


class Sbw:
    """Steering, road feel and fault handling, evaluated on each sample's three I/O frames (every 5 ms): the
    hand-wheel frame drives the steering and the road feel (sent at once), the pinion frame the pinion's side,
    the currents frame the load."""

    def __init__(self, mode: str, ideal_yaw_gain: float) -> None:
        self.mode, self.g_r = mode, ideal_yaw_gain
        self.io = Sample()
        self.fault = OK
        self.handwheel = 0.0  # θ_h as measured (the column estimate in a hand-wheel fault), deg
        self.pinion = 0.0  # θ_p as measured (the actuator's angle in a pinion fault), deg
        self.target = 0.0  # PinionAngleTarget, deg
        self.rate = 0.0  # θ_h's rate between the last two samples, deg/s (the request's extrapolation)
        self.feel_request = 0.0  # RoadFeelTorqueRequest, N·m
        self.hw_range = self.p_range = self.timeout = False
        self.rack_force = LowPass(RACK_FORCE_TAU)
        self.load = LowPass(LOAD_TAU)
        self.wheel_rate = LowPass(RATE_TAU)
        self.pinion_rate = LowPass(RATE_TAU)
        self.prev_hand: tuple[float, float] | None = None  # (column estimate, torsion-bar torque) of the last sample
        self.prev_actuator: float | None = None
        self.stuck_value: float | None = None  # hand-wheel sensor reading while SBW-FLT-02 watches it
        self.stuck_reference = 0.0  # column estimate when the sensor last changed
        self.stuck = False
        self.additional = 0.0  # SBW-CTL-05 additional pinion angle, hand-wheel deg
        self.reference = 0.0  # yaw-rate reference, deg/s

    def column_estimate(self) -> float:
        """SBW-FLT-01: the road-feel motor's rotor angle (the column) plus the torsion bar's twist T_d / K_h."""
        return self.io.column + self.io.torque / K_H

    def _set_fault(self) -> None:
        """SBW_Pinion.SbwFault: the first that applies in the order 3, 2, 1, 4; each clears with its condition."""
        self.fault = (PINION_RANGE if self.p_range else HANDWHEEL_STUCK if self.stuck
                      else HANDWHEEL_RANGE if self.hw_range else INPUT_TIMEOUT if self.timeout else OK)

    def on_handwheel(self, feedback_inputs: tuple[float, float] | None, inputs_timed_out: bool) -> None:
        """A new hand-wheel sample: faults of the hand wheel, the pinion request and the road-feel torque.
        feedback_inputs: (yaw rate deg/s, vehicle speed m/s) while both messages are valid."""
        io = self.io
        estimate = self.column_estimate()
        prev = self.prev_hand
        restart = prev is not None and abs(estimate - prev[0]) > JUMP_DEG
        if prev is None or restart:  # the mechanics restarted (PLANT-IO-SBW-01): rates start at 0
            self.wheel_rate.value = 0.0
            prev = (estimate, io.torque)
        wheel_rate = self.wheel_rate((estimate - prev[0]) / PERIOD)  # deg/s
        twist_rate = (io.torque - prev[1]) / PERIOD  # N·m/s
        self.prev_hand = (estimate, io.torque)

        # SBW-FLT-02: the sensor did not change while the column estimate moved more than 5° (latched)
        if self.stuck_value is None or io.handwheel != self.stuck_value or restart:
            self.stuck_value, self.stuck_reference, self.stuck = io.handwheel, estimate, False
        elif abs(estimate - self.stuck_reference) > STUCK_DEG:
            self.stuck = True
        # SBW-FLT-01: beyond ±900° or more than 20° from the column estimate
        self.hw_range = abs(io.handwheel) > HANDWHEEL_LIMIT or abs(io.handwheel - estimate) > PLAUSIBLE_DEG
        feedback_on = self.mode != "DIRECT"
        self.timeout = feedback_on and inputs_timed_out  # SBW-FLT-04
        self._set_fault()
        # reaction of SBW-FLT-01/-02: the column estimate (clamped to ±900°) replaces the sensor
        last = self.handwheel
        self.handwheel = (max(-HANDWHEEL_LIMIT, min(HANDWHEEL_LIMIT, estimate)) if self.stuck or self.hw_range
                          else io.handwheel)

        # SBW-CTL-01 / -05: the pinion to the hand wheel at ratio 1, plus the feedback's additional angle (off in
        # any fault)
        self._feedback(feedback_inputs if self.fault == OK and feedback_on else None)
        self.target = self.handwheel + self.additional
        rate = (self.handwheel - last) / PERIOD
        self.rate = 0.0 if restart or abs(rate) > MAX_LEAD_RATE else rate

        # SBW-CTL-04: the driver holds a share of the rack's load plus a centring spring; the column holds
        # F_m = -RoadFeelTorque at rest (PLANT-IO-SBW-04, [P1] eq. 3-4); damping of the hand wheel and of the
        # torsion bar's twist: c (θ̇_h − θ̇_c) = c Ḟ_m / K_h
        driver_torque = FEEL_GAIN * self.load.value + CENTRE_NM_PER_DEG * self.handwheel
        feel = (-driver_torque - HANDWHEEL_DAMPING * math.radians(wheel_rate)
                + TWIST_DAMPING * twist_rate / math.degrees(K_H))
        self.feel_request = max(-MAX_FEEL_NM, min(MAX_FEEL_NM, feel))

    def on_pinion(self) -> None:
        """A new pinion sample: SBW-FLT-03 (beyond ±600° or more than 20° from the actuator's rotor angle; the
        rotor angle then replaces the sensor) and the pinion's rate."""
        io = self.io
        restart = self.prev_actuator is None or abs(io.actuator - self.prev_actuator) > JUMP_DEG
        if restart:
            self.pinion_rate.value = 0.0
        else:
            assert self.prev_actuator is not None
            self.pinion_rate((io.actuator - self.prev_actuator) / PERIOD)
        self.prev_actuator = io.actuator
        self.p_range = abs(io.pinion) > PINION_LIMIT or abs(io.pinion - io.actuator) > PLAUSIBLE_DEG
        self._set_fault()
        self.pinion = io.actuator if self.p_range else io.pinion

    def on_currents(self) -> None:
        """A new currents sample: the rack's load torque at the pinion (+ to the right) from the steering motor,
        less the viscous part; RackForce (SBW-OUT-02: positive pushes the rack to steer right)."""
        load = NM_PER_A * self.io.i_steer - B_PINION * math.radians(self.pinion_rate.value)
        self.load(load)
        self.rack_force(-load / R_PINION)

    def _feedback(self, inputs: tuple[float, float] | None) -> None:
        """SBW-CTL-05 (coding --mode): integral of the yaw-rate error against G_r·θ_h, limited to ±5° of road
        wheel and rate limited; off (back to 0 at the rate limit) below 10 km/h, in a fault or without inputs."""
        wanted = 0.0
        if inputs is not None and inputs[1] >= FEEDBACK_MIN_SPEED:
            yaw_rate = inputs[0]
            self.reference += PERIOD / (REFERENCE_TAU + PERIOD) * (self.g_r * self.handwheel - self.reference)
            wanted = self.additional + FEEDBACK_KI * (self.reference - yaw_rate) * PERIOD
            wanted = max(-FEEDBACK_LIMIT, min(FEEDBACK_LIMIT, wanted))
        else:
            self.reference = self.g_r * self.handwheel
        step = FEEDBACK_RATE * PERIOD
        self.additional += max(-step, min(step, wanted - self.additional))


# ==============================================================================================================
# Running on a bus
# ==============================================================================================================
class Node:
    """Receivers, senders and the task's timing: event-driven on the I/O samples, with a clock fallback so that
    every message keeps its cycle whatever the inputs do (COM-FRM-02)."""

    def __init__(self, chassis: Any, bench: Any, sbw: Sbw, bus: can.BusABC) -> None:
        self.chassis, self.bench = chassis, bench
        self.sbw, self.bus = sbw, bus
        self.diag: uds_server.Diagnostics | None = None
        self.send_errors = 0
        self.max_age = 0.0  # s, for --stats
        self.restart()

    def restart(self) -> None:
        """Power-up (and ECUReset, DIAG-RST-02): steering state and receivers from the start; the coding stays (the
        diagnostic server puts it in force again). The AliveCounters, which the contract leaves free to start
        anew, carry on over an ECUReset (this SBW's choice): the receivers of its messages, the rig's included,
        see no WRONGSEQUENCE."""
        chassis, bench = self.chassis, self.bench
        self.sbw = Sbw(self.sbw.mode, self.sbw.g_r)
        self.rx: dict[int, Receiver] = {}
        for db, names in ((bench, IO_INPUTS), (chassis, BUS_INPUTS)):
            for name in names:
                message = db.get_message_by_name(name)
                self.rx[message.frame_id] = Receiver(db, message)
        self.by_name = {r.message.name: r for r in self.rx.values()}
        if not hasattr(self, "actuators"):  # power-up only
            self.actuators = Sender(bench, bench.get_message_by_name("IO_SbwActuators"))
            self.handwheel_tx = Sender(chassis, chassis.get_message_by_name("SBW_HandWheel"))
            self.pinion_tx = Sender(chassis, chassis.get_message_by_name("SBW_Pinion"))
        self.last_act = -1.0  # time.monotonic() of the last IO_SbwActuators
        self.next_out = time.monotonic()  # the next slot of SBW_HandWheel and SBW_Pinion (own 10 ms grid)
        self.snapshot = self.outputs()  # the values of the last complete I/O sample
        self.sent_values: dict[str, dict[str, float]] = {}  # the signals of each message's latest frame

    def send_frame(self, frame: can.Message) -> bool:
        """A frame of the diagnostic server (ISO-TP); the same bus and the same non-blocking send."""
        try:
            self.bus.send(frame, timeout=0.005)
        except can.CanError:
            self.send_errors += 1
            return False
        return True

    def send(self, sender: Sender, values: dict[str, float]) -> None:
        frame = sender.frame(values)
        try:
            self.bus.send(frame, timeout=0.005)
        except can.CanError:
            self.send_errors += 1  # not on the bus: its counter value goes with the next frame (COM-E2E-01)
            return
        sender.sent(frame)

    def receive(self, msg: can.Message, wall: float) -> None:
        rx = self.rx.get(msg.arbitration_id)
        if rx is None or msg.is_extended_id or msg.is_error_frame or msg.is_remote_frame:
            return  # COM-RX-03: an error frame belongs to no message
        stamp = msg.timestamp if abs(wall - msg.timestamp) < 1.0 else wall  # COM-RX-02: the driver's stamp
        if not rx.on_frame(bytes(msg.data), stamp):
            return
        v, io, name = rx.values, self.sbw.io, rx.message.name
        assert v is not None
        mono = time.monotonic()
        if name == "IO_SbwHandWheel":
            io.handwheel, io.column, io.torque = v["HandWheelSensor"], v["ColumnAngle"], v["TorsionBarTorque"]
            self.evaluate(wall)
            age = time.time() - stamp  # how long ago the sample arrived (a task descheduled meanwhile: more)
            self.max_age = max(self.max_age, age)
            self.send_actuators(mono, True, age)
        elif name == "IO_SbwPinion":
            io.pinion, io.actuator = v["PinionSensor"], v["ActuatorAngle"]
            self.sbw.on_pinion()
        elif name == "IO_SbwCurrents":
            io.i_feel, io.i_steer = v["RoadFeelMotorCurrent"], v["SteerMotorCurrent"]
            self.sbw.on_currents()
            self.snapshot = self.outputs()  # the sample is complete: hand wheel, pinion and currents of one instant

    def evaluate(self, wall: float) -> None:
        imu, abs_ = self.by_name["IMU_Motion"], self.by_name["ABS_WheelSpeeds"]
        timed_out = imu.timed_out(wall) or abs_.timed_out(wall)
        inputs = None
        if not timed_out and imu.values is not None and abs_.values is not None:
            speed = (abs_.values["WheelSpeedRL"] + abs_.values["WheelSpeedRR"]) / 2.0 / 3.6  # SBW-GEN-01
            inputs = (imu.values["YawRate"], speed)
        self.sbw.on_handwheel(inputs, timed_out)

    def send_actuators(self, mono: float, hand_in: bool, age: float = 0.0) -> None:
        """PLANT-IO-SBW-03/-04; while the hand-wheel samples are missing, the last request and no torque.
        The request is the target extrapolated with the hand wheel's rate over the sample's age and the rig's
        apply delay, so that the pinion is steered to where the hand wheel is, not to where it was when sampled
        (SBW-OUT-03: an age is a lag); PinionAngleTarget stays the target itself. hand_in: a hand-wheel sample
        is at hand (the frame just applied, or on the clock: IO_SbwHandWheel not timed out)."""
        lead = self.sbw.rate * (min(age, 3 * PERIOD) + APPLY_LEAD) if hand_in else 0.0
        self.send(self.actuators, {"PinionAngleRequest": self.sbw.target + lead,
                                   "RoadFeelTorqueRequest": self.sbw.feel_request if hand_in else 0.0})
        self.last_act = mono

    def outputs(self) -> tuple[dict[str, float], dict[str, float]]:
        """SBW-OUT-01/-02 from the current state."""
        s, io = self.sbw, self.sbw.io
        return ({"HandWheelAngle": s.handwheel, "DriverTorque": io.torque,
                 "RoadFeelTorque": NM_PER_A * io.i_feel, "RoadFeelMotorCurrent": io.i_feel},
                {"PinionAngle": s.pinion, "PinionAngleTarget": s.target, "SteerMotorCurrent": io.i_steer,
                 "RackForce": s.rack_force.value, "SbwFault": s.fault})

    def send_outputs(self, wall: float) -> None:
        """SBW-OUT-01/-02 on the SBW's own 10 ms clock (COM-CYC-01 whatever the I/O's timing), both frames back to
        back with the values of one complete I/O sample (SBW-OUT-03: no age difference between them, at most
        one sample of age); without I/O samples, the current state."""
        if self.by_name["IO_SbwCurrents"].timed_out(wall):
            self.snapshot = self.outputs()
        hand, pinion = self.snapshot
        self.send(self.handwheel_tx, hand)
        self.send(self.pinion_tx, pinion)
        self.sent_values = {"SBW_HandWheel": hand, "SBW_Pinion": pinion}

    def monitor(self) -> None:
        """The fault memory's control step (DIAG-DTC-02), every 10 ms after SBW_Pinion: SbwFault as just sent, and
        SENSOR_SIGNAL_LOST while an IO_Sbw* input is timed out (SBW-FLT-06's condition). The frames that arrived
        meanwhile are taken in first: a late task must not judge an input's age before reading it (COM-RX-02)."""
        assert self.diag is not None
        while True:
            try:
                msg = self.bus.recv(timeout=0.0)
            except can.CanError:
                break
            if msg is None:
                break
            if not self.diag.on_frame(msg):
                self.receive(msg, time.time())
        wall = time.time()
        io_lost = any(self.by_name[name].timed_out(wall) for name in IO_INPUTS)
        fault = int(self.sent_values["SBW_Pinion"]["SbwFault"])
        self.diag.control_step(self.diag.failing({"SBW_Pinion.SbwFault": fault},
                                                 {"SENSOR_SIGNAL_LOST"} if io_lost else set()))

    # --- what the diagnostic server reads (SBW-DIAG-04) ---
    def vehicle_speed(self) -> float:
        """0xFD00: the mean of the rear wheels of the last valid ABS_WheelSpeeds, km/h (0 before the first)."""
        values = self.by_name["ABS_WheelSpeeds"].values
        return 0.0 if values is None else (values["WheelSpeedRL"] + values["WheelSpeedRR"]) / 2.0

    def output_values(self, message: str) -> dict[str, float] | None:
        """The signals of the message's latest frame (sent in the last 10 ms): a DID with a signal equals one of
        the SBW's frames (DIAG-SVC-02). None before the first: the DBC start value."""
        return self.sent_values.get(message)

    def input_values(self, message: str) -> dict[str, float] | None:
        rx = self.by_name.get(message)
        return None if rx is None else rx.values

    def run(self, stop: Callable[[], bool]) -> None:
        """Read frames as they come (IO_SbwActuators goes out at each hand-wheel sample); the clock sends SBW_*
        every 10 ms and IO_SbwActuators when no sample triggered it for 7 ms (then every 5 ms)."""
        while not stop():
            if self.diag is not None:
                self.diag.poll()  # ISO-TP and UDS, never blocking (a reset restarts this node's state)
            mono = time.monotonic()
            if mono >= self.next_out:
                self.send_outputs(time.time())
                missed = int((mono - self.next_out) / OUT_PERIOD)  # a late task skips the slots it missed
                self.next_out += OUT_PERIOD * (1 + missed)
                if self.diag is not None:
                    self.monitor()
            if mono - self.last_act >= 0.007:
                hand_in = not self.by_name["IO_SbwHandWheel"].timed_out(time.time())
                self.send_actuators(mono - 0.002, hand_in)  # then every 5 ms until the samples come back
            timeout = max(0.0, min(self.next_out, self.last_act + 0.007) - time.monotonic())
            try:
                msg = self.bus.recv(timeout=timeout)
            except can.CanError:
                msg = None
            if msg is not None and not (self.diag is not None and self.diag.on_frame(msg)):
                self.receive(msg, time.time())


def only_own_group(bus: can.BusABC) -> None:
    """README, "Pointing it at a bus": receive only our multicast group (IP_MULTICAST_ALL = 0; IPv6 also 29)."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None:
        return
    try:
        sock.setsockopt(socket.IPPROTO_IP, 49, 0)
        if sock.family == socket.AF_INET6:
            sock.setsockopt(socket.IPPROTO_IPV6, 29, 0)
    except OSError:
        return
    while True:  # what arrived before the setting may be another group's
        try:
            sock.recv(65535, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--interface", default="udp_multicast", help="python-can interface (default udp_multicast)")
    parser.add_argument("--channel", default=None, help="python-can channel (e.g. 239.255.1.3, vcan0)")
    parser.add_argument("--bitrate", type=int, default=None, help="bitrate, for interfaces that take one")
    parser.add_argument("--dbc", type=Path, default=ROOT / "dbc" / "chassis.dbc", help="the chassis DBC")
    parser.add_argument("--io-dbc", type=Path, default=ROOT / "dbc" / "bench.dbc", help="the bench I/O DBC")
    parser.add_argument("--mode", choices=("DIRECT", "YAW_RATE"), default="DIRECT",
                        help="SteeringMode as delivered: DIRECT (SBW-CTL-01, the contract's default) or the yaw-rate "
                             "feedback (SBW-CTL-05); a tester codes it with WriteDataByIdentifier 0xFDC0")
    parser.add_argument("--ideal-yaw-gain", type=float, default=0.28,
                        help="IdealYawGain G_r as delivered, 1/s (0.05-0.5; coded with WriteDataByIdentifier 0xFDC1)")
    parser.add_argument("--vin", default=IDENTIFICATION["VehicleIdentificationNumber"],
                        help="the VIN this SBW holds (0xF190, 17 characters; '' for none programmed)")
    parser.add_argument("--nvm", type=Path, default=None, metavar="FILE",
                        help="non-volatile memory (coding, fault memory) kept in FILE across restarts; "
                             "default: none, every start is an SBW as delivered")
    parser.add_argument("--diag-defect", choices=("wrong-nrc",), default=None,
                        help="a deliberate diagnostic defect (off by default) for checking a tester: wrong-nrc "
                             "answers WriteDataByIdentifier and RoutineControl in the default session with NRC 0x33 "
                             "instead of 0x7F")
    parser.add_argument("--stats", type=float, default=0.0, metavar="S", help="print receive counts every S s")
    return parser.parse_args(argv)


def make_diagnostics(node: Node, args: argparse.Namespace) -> uds_server.Diagnostics:
    """The SBW's diagnostic server (SBW-DIAG-01..04): its values, its coding and its routine's precondition."""

    def apply_coding(name: str, value: float) -> None:
        if name == "SteeringMode":
            node.sbw.mode = STEERING_MODES[int(value)]
        elif name == "IdealYawGain":
            node.sbw.g_r = value

    def supported(name: str, value: float) -> bool:  # SBW-DIAG-02: YAW_RATE_LAT_ACCEL is not in this SBW
        return name != "SteeringMode" or int(value) in STEERING_MODES

    live = {"VehicleSpeed": node.vehicle_speed,
            "HandWheelSensorAngle": lambda: node.sbw.io.handwheel,
            "ColumnAngleEstimate": lambda: node.sbw.column_estimate(),
            "PinionSensorAngle": lambda: node.sbw.io.pinion,
            "ActuatorAngle": lambda: node.sbw.io.actuator}
    modes = {name: raw for raw, name in STEERING_MODES.items()}
    return uds_server.Diagnostics(
        "SBW", node.send_frame, identification={**IDENTIFICATION, "VehicleIdentificationNumber": args.vin},
        live=live, outputs=node.output_values, inputs=node.input_values, signals=[node.chassis, node.bench],
        apply_coding=apply_coding, coding_supported=supported,
        initial_coding={"SteeringMode": modes[args.mode], "IdealYawGain": args.ideal_yaw_gain},
        preconditions={"SteeringAngleSensorZero": lambda: node.vehicle_speed() < ZERO_LEARN_MAX_SPEED},
        on_reset=node.restart, defect=args.diag_defect, nvm=args.nvm)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        chassis = cantools.database.load_file(str(args.dbc))
        bench = cantools.database.load_file(str(args.io_dbc))
        sbw = Sbw(args.mode, args.ideal_yaw_gain)
        kwargs: dict[str, Any] = {"interface": args.interface}
        if args.channel is not None:
            kwargs["channel"] = args.channel
        if args.bitrate is not None:
            kwargs["bitrate"] = args.bitrate
        if args.interface == "udp_multicast":
            kwargs["hop_limit"] = 0  # the traffic never leaves the host, as the bench's
        bus = can.Bus(**kwargs)
        node = Node(chassis, bench, sbw, bus)
        try:
            node.diag = make_diagnostics(node, args)
        except ValueError:  # a DiagConfigError: the bus was opened for nothing
            bus.shutdown()
            raise
        gc.collect()
        gc.freeze()  # the databases' objects out of the collector's way: shorter pauses of the 5 ms task
    except (OSError, ValueError, KeyError, can.CanError) as error:  # DiagConfigError is a ValueError
        print(f"sbw_ecu: {error}", file=sys.stderr)
        return 2
    if args.interface == "udp_multicast":
        only_own_group(bus)
    stopping = False

    def on_signal(*_: object) -> None:
        nonlocal stopping
        stopping = True

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, on_signal)
    next_stats = time.monotonic() + args.stats

    def stop() -> bool:
        nonlocal next_stats
        if args.stats and time.monotonic() >= next_stats:
            next_stats += args.stats
            counts = " ".join(f"{r.message.name}:{r.applied}/{r.rejected}/{r.state}" for r in node.rx.values())
            diag = node.diag
            assert diag is not None
            print(f"stats fault={node.sbw.fault} diag={diag.requests}/{diag.negative} "
                  f"send_errors={node.send_errors} max_age={node.max_age * 1e3:.1f}ms "
                  f"{counts}", flush=True)
            node.max_age = 0.0
        return stopping

    print(f"SBW running on {args.interface} {args.channel or ''}".rstrip(), flush=True)
    try:
        node.run(stop)
    finally:
        if node.diag is not None:
            node.diag.close()
        bus.shutdown()
        print("SBW stopped", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
