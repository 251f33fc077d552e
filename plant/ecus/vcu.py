"""Reference VCU (node VCU): the four drive modes of docs/spec/vehicles.md A as wheel commands ([P0] §1.2, §2).

The contract it implements: docs/contract/vcu.md (VCU-*) and, for ADAPTIVE at speed, docs/contract/vcu-4ws.md.
This docstring summarises it for the code; where they differ, the contract is right.

Inputs: DRV_MotionRequest (DriveMode, PivotX, PivotY, TargetSpeed), DRV_Steering (HandWheelAngle, in
NORMAL and ADAPTIVE only), WHL_Status_xx (faults and the VehicleSpeed estimate), IMU_Motion (yaw rate,
for ADAPTIVE's feedback law or hook); ADAPTIVE's rear-steering law is the diagnostic coding RearSteerLaw (DID
0xFDC0, docs/contract/vcu.md VCU-DIAG-02), written by a tester. TargetSpeed is the signed centre speed v
(docs/spec/k-matrix.md).

Modes (every one a rotation about a point, [P0] §1.2):
- NORMAL: curvature angle X = HandWheelAngle / hand_wheel_ratio at the front-axle centre, centre on the
  rear-axle line y = -L ([P2], docs/spec/formulas.md §3), rear wheels 0; angles and speeds by docs/spec/formulas.md §2.
- LATERAL: every wheel +90° and every speed 30 v / (pi r), signed: v > 0 moves right, v < 0 left with negative
  rpm at the same +90° (road-wheel angles lie in (-90°, +90°], docs/spec/formulas.md §1).
- PIVOT: centre (PivotX, PivotY), §2 with v_o = TargetSpeed (positive clockwise).
- ADAPTIVE: below adaptive_low_speed_limit (20 km/h) opposite-phase 4WS, the centre on y = 0 with the
  front-axle curvature angle X = HandWheelAngle / ratio ([P0] §3's U-turn). Above it the front-axle
  angle stays X (fixed ratio 15) and the rear-axle angle comes from [P3] §2's law chosen by the
  coding RearSteerLaw (plant/ecus/rear_steer.py: OFF = 2WS, FEEDFORWARD = zero-sideslip k(u) X, FEEDBACK =
  −X + C2 u r with the IMU_Motion yaw rate; FEEDFORWARD, the default, until a tester writes another and in a
  project that declares no diagnostics; REQUEST_INVALID should the coding hold a value without a law, which a
  tester cannot write), or, when the VCU is built with a hook `high_speed_law(X, |u|, measured yaw rate)`
  (u: the vehicle speed estimate of rear_steer.py), from the hook instead; all four wheels steer about the one
  centre of the two axle headings (VCU_RotationCentre).
In NORMAL and ADAPTIVE a positive v drives forward: v_o = v * sign(x_centre) in §2's convention.

Faults (VCU_VehicleState.VcuFault), checked in this order, the first found is sent:
  5 REQUEST_TIMEOUT  DRV_MotionRequest (or DRV_Steering in NORMAL/ADAPTIVE) never received or timed out.
  4 REQUEST_INVALID  its last frame failed E2E/range checks, a value is non-finite, the mode is unknown,
                     or the request needs more than hub_motor_max_speed on a wheel or more than
                     max_yaw_rate (e.g. a centre a few cm off the origin), or (ADAPTIVE above its low-speed
                     range) the coding RearSteerLaw names no law (a tester cannot write one): never an
                     out-of-range command. The limit check runs after 1-3 (their centres have no speeds):
                     docs/contract/vcu.md VCU-FLT-03.
  1 CENTRE_AT_ORIGIN centre within 1 cm of the origin with v != 0 (v = 0 sets the spin-in-place angles).
  2 CENTRE_ON_WHEEL  centre within 1 cm of a contact point.
  3 ANGLE_OVER_90    "a wheel that would need more than 90°": in the car-like modes (NORMAL, ADAPTIVE)
                     every wheel must roll forward when the vehicle drives forward; a centre strictly
                     between the wheels of an axle (|x| < K, i.e. NORMAL |X| > atan(2L/K) = 78.6°,
                     ADAPTIVE |X| > atan(L/K) = 68.1°), or |X| >= 90°, would need the inner wheels beyond
                     ±90° (§2's fold would reverse them instead). In PIVOT §2's fold is legitimate and
                     never a fault. With ratio 15 and the DBC's ±900° hand wheel (|X| <= 60°) the fault
                     is unreachable from the bus; it guards other ratios and the hook.
  6 WHEEL_FAULT      a WHL_Status_xx reports WheelFault != 0 or is silent (ignored for
                     WHEEL_FAULT_GRACE_S after a reset: the wheels have not heard the VCU yet).
On any fault: wheel speeds 0, wheel angles held at the last valid command (straight after a reset) so a
wheel never swings on bad input; ActiveMode, CurvatureAngle and the centre stay those of that command,
YawRateTarget is 0. Recovery is immediate on the next valid request. Never NaN, never an exception.

Timing: the control task runs every TASK_PERIOD_S = 5 ms, like an ECU's cyclic task (the commands are
10 ms frames); a request change reaches the wheel-command values within 5 ms.
VCU_RotationCentre: the centre steered about, each coordinate clamped to ±CENTRE_AT_INFINITY_M (the
DBC's range end, which means "at infinity"). A translation (straight, crab, LATERAL) has its centre at
infinity to the right of the wheels' common heading θ: the direction (cos θ, −sin θ) scaled until one
coordinate reaches the range end (straight: (+5242.87, 0); LATERAL at +90°: (0, −5242.87)).
VCU_VehicleState.VehicleSpeed: the centre speed estimated from the four WHL_Status (least-squares rigid
fit), signed as TargetSpeed in the active mode; 0 unless all four are received.
CurvatureAngle: X at the front-axle centre (deg, 0 straight; +90° in LATERAL, like the wheels).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum

from bench.sim.node import DiagnosticSide, NodeIO
from plant import signal_ranges as ranges
from plant.body import VelocityFit
from plant.ecus.diagnostics import EcuDiagnostics
from plant.ecus.rear_steer import DEFAULT_LAW, SeedLaws, Strategy, VehicleSpeedEstimate
from plant.kinematics import (
    CORNERS,
    centre_from_axle_angles,
    classify_centre,
    curvature_angle,
    rotation,
    translation,
    yaw_rate,
)
from plant.vehicles import Ev4wisParams

CENTRE_AT_INFINITY_M = 5242.87  # VCU_RotationCentre range end = centre at infinity (dbc/chassis.dbc comment)
WHEEL_FAULT_GRACE_S = 0.1       # wheel faults ignored this long after a reset
TASK_PERIOD_S = 0.005           # the control task's period (an ECU's cyclic task; half the 10 ms command cycle)


class DriveMode(IntEnum):
    NORMAL = 0
    LATERAL = 1
    ADAPTIVE = 2
    PIVOT = 3


class VcuFault(IntEnum):
    OK = 0
    CENTRE_AT_ORIGIN = 1
    CENTRE_ON_WHEEL = 2
    ANGLE_OVER_90 = 3
    REQUEST_INVALID = 4
    REQUEST_TIMEOUT = 5
    WHEEL_FAULT = 6


#: ADAPTIVE rear-steering law: (front curvature angle X deg, speed m/s >= 0, measured yaw rate deg/s)
#: -> rear-axle-centre angle deg (bus signs, docs/spec/formulas.md §1).
RearSteerLaw = Callable[[float, float, float], float]


def opposite_phase(front_deg: float, speed: float, yaw_rate_dps: float) -> float:
    """Low-speed 4WS ([P0] §3, [P3] "at very low speed rear opposite to front 1:1"): centre on y = 0."""
    return -front_deg


@dataclass(frozen=True, slots=True)
class Plan:
    """One valid command set."""

    mode: int
    angles: tuple[float, ...]
    rpm: tuple[float, ...]
    centre: tuple[float, float] | None   # None: at infinity (translation)
    curvature: float                     # deg
    yaw_rate: float                      # deg/s, clockwise
    direction: tuple[float, float]       # body-frame unit vector of positive v (for the speed sign)


_STRAIGHT = Plan(DriveMode.NORMAL, (0.0,) * 4, (0.0,) * 4, None, 0.0, 0.0, (0.0, 1.0))
_MODES = frozenset(int(m) for m in DriveMode)


class Vcu:
    """The reference VCU behaviour."""

    nodes: tuple[str, ...] = ("VCU",)

    def __init__(self, params: Ev4wisParams, high_speed_law: RearSteerLaw | None = None) -> None:
        self.params = params
        self.geometry = params.geometry
        self.high_speed_law = high_speed_law
        self.laws = SeedLaws(params)
        self.vehicle_speed = VehicleSpeedEstimate(params)   # u of the rear-steer laws (rear_steer.py)
        self._ratio = params.hand_wheel_ratio
        self._low_speed = params.adaptive_low_speed_limit / 3.6
        self._max_rpm = min(params.hub_motor_max_speed, ranges.WHEEL_SPEED_CMD[1])
        self._max_yaw = min(params.max_yaw_rate, ranges.YAW_RATE_TARGET[1])
        self._fit = VelocityFit(self.geometry)
        self._status = tuple(f"WHL_Status_{c}" for c in CORNERS)
        self._cmd = tuple(f"VCU_WheelCmd_{c}" for c in CORNERS)
        self.diagnostics = EcuDiagnostics("VCU", VcuFault, self._diagnostic_setup)
        self.reset()

    def _diagnostic_setup(self, side: DiagnosticSide, io: NodeIO) -> None:
        """What an ECUReset does, and the DID only the reference VCU knows (docs/contract/vcu.md VCU-DIAG-*)."""
        side.on_reset(self.reset)

        def timed_out() -> float:   # bit 0 FL .. bit 3 RR
            return float(sum(1 << i for i, name in enumerate(self._status) if io.timed_out(name)))

        side.provide("WheelStatusTimedOut", timed_out)

    def reset(self) -> None:
        self.held: Plan = _STRAIGHT
        self.fault = VcuFault.OK
        self._t_start: float | None = None
        self._cache: tuple[tuple[float | None, ...], tuple[VcuFault, Plan | None]] | None = None
        self._next_task = -math.inf
        self.vehicle_speed.reset()

    # -- decision --------------------------------------------------------------------------------
    def decide(self, io: NodeIO) -> tuple[VcuFault, Plan | None]:
        """The fault and, when OK, the plan for the current request."""
        req = io.latest("DRV_MotionRequest")
        if req is None:
            return VcuFault.REQUEST_TIMEOUT, None
        if io.invalid("DRV_MotionRequest"):
            return VcuFault.REQUEST_INVALID, None
        fmode = req.get("DriveMode", math.nan)
        px, py = req.get("PivotX", math.nan), req.get("PivotY", math.nan)
        v = req.get("TargetSpeed", math.nan)
        if not ranges.finite(fmode, px, py, v) or fmode not in _MODES:
            return VcuFault.REQUEST_INVALID, None
        mode = int(fmode)
        hw = rear = 0.0
        if mode in (DriveMode.NORMAL, DriveMode.ADAPTIVE):
            steering = io.latest("DRV_Steering")
            if steering is None:
                return VcuFault.REQUEST_TIMEOUT, None
            hw = steering.get("HandWheelAngle", math.nan)
            if io.invalid("DRV_Steering") or not ranges.finite(hw):
                return VcuFault.REQUEST_INVALID, None
            if mode == DriveMode.ADAPTIVE:
                u = self.vehicle_speed.value      # the vehicle's speed, not the request's (VCU-4WS-01)
                rear = self._rear_angle(hw / self._ratio, abs(v) if u is None else abs(u), io)
        key: tuple[float | None, ...] = (mode, px, py, v, hw, rear)
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        result = self._plan(mode, px, py, v, hw / self._ratio, rear)
        self._cache = (key, result)
        return result

    def _rear_angle(self, front: float, speed: float, io: NodeIO) -> float:
        if speed < self._low_speed:
            return opposite_phase(front, speed, 0.0)
        imu = io.latest("IMU_Motion")
        yaw = imu.get("YawRate", 0.0) if imu is not None else 0.0
        if self.high_speed_law is None:
            strategy = self._strategy(io)
            if strategy is None:
                return math.nan                     # an unknown coding: REQUEST_INVALID
            measured = yaw if imu is not None and ranges.finite(yaw) and not io.invalid("IMU_Motion") else None
            return self.laws.rear_angle(strategy, front, speed, measured)
        try:
            rear = float(self.high_speed_law(front, speed, yaw if ranges.finite(yaw) else 0.0))
        except Exception:       # a broken hook is a bad request, never a crash of the VCU
            return math.nan
        return rear

    def _strategy(self, io: NodeIO) -> Strategy | None:
        """The rear-steering law from the coding (docs/contract/vcu.md VCU-DIAG-02, written by a tester with
        WriteDataByIdentifier); DEFAULT_LAW for a project without diagnostics; None when the coding names no law."""
        side = self.diagnostics.side(io)
        if side is None:
            return DEFAULT_LAW
        value = side.coding("RearSteerLaw")
        return Strategy(int(value)) if value in (0, 1, 2) else None

    def _plan(self, mode: int, px: float, py: float, v: float, x_deg: float,
              rear: float) -> tuple[VcuFault, Plan | None]:
        g = self.geometry
        if mode == DriveMode.LATERAL:     # +90° both ways, the sign of v in the rpm (VCU-MODE-08)
            angles, rpm = translation(90.0, v, g)
            plan = Plan(mode, angles, rpm, None, 90.0, 0.0, (1.0, 0.0))
        elif mode == DriveMode.PIVOT:
            undefined = classify_centre(px, py, v, g)
            if undefined is not None:
                return VcuFault(undefined), None
            angles, rpm = rotation(px, py, v, g)
            r_o = math.hypot(px, py)
            direction = (-py / r_o, px / r_o) if r_o > 0.0 else (0.0, 1.0)
            plan = Plan(mode, angles, rpm, (px, py), curvature_angle(px, py, g), yaw_rate(px, py, v), direction)
        else:  # NORMAL (rear 0) and ADAPTIVE (rear from the law)
            if not ranges.finite(rear):
                return VcuFault.REQUEST_INVALID, None
            if abs(x_deg) >= 90.0 or abs(rear) >= 90.0:
                return VcuFault.ANGLE_OVER_90, None
            centre = centre_from_axle_angles(x_deg, rear, g)
            if centre is None:        # parallel headings: straight ahead or crab
                angles, rpm = translation(x_deg, v, g)
                plan = Plan(mode, angles, rpm, None, x_deg + 0.0, 0.0, (0.0, 1.0))
            else:
                cx, cy = centre
                undefined = classify_centre(cx, cy, v, g, forward_only=True)
                if undefined is not None:
                    return VcuFault(undefined), None
                v_o = v if cx > 0.0 else -v
                angles, rpm = rotation(cx, cy, v_o, g)
                plan = Plan(mode, angles, rpm, centre, x_deg + 0.0, yaw_rate(cx, cy, v_o), (0.0, 1.0))
        if max(abs(n) for n in plan.rpm) > self._max_rpm or abs(plan.yaw_rate) > self._max_yaw:
            return VcuFault.REQUEST_INVALID, None
        return VcuFault.OK, plan

    def _wheel_fault(self, io: NodeIO, t: float) -> bool:
        in_grace = self._t_start is not None and t - self._t_start < WHEEL_FAULT_GRACE_S
        for message in self._status:
            status = io.latest(message)
            if status is None:
                if not in_grace:
                    return True
                continue
            code = status.get("WheelFault", 0.0)
            if code != 0.0 and not (in_grace and code == 3.0):
                return True
        return False

    def _speed_estimate(self, io: NodeIO, direction: tuple[float, float]) -> float:
        angles, speeds = [], []
        for message in self._status:
            status = io.latest(message)
            if status is None:
                return 0.0
            angles.append(status.get("SteerAngle", math.nan))
            speeds.append(status.get("WheelSpeed", math.nan))
        if not ranges.finite(*angles, *speeds):
            return 0.0
        vx, vy, _ = self._fit(angles, speeds)
        magnitude = math.hypot(vx, vy)
        return magnitude if vx * direction[0] + vy * direction[1] >= 0.0 else -magnitude

    # -- tick --------------------------------------------------------------------------------------
    def step(self, io: NodeIO, t: float, dt: float) -> None:
        """Runs the control task every TASK_PERIOD_S (between runs the last values stay on the bus)."""
        if t < self._next_task:
            return
        self._next_task = t + TASK_PERIOD_S - 1e-9
        if self._t_start is None:
            self._t_start = t
        try:
            self.vehicle_speed.update(io, t)
            fault, plan = self.decide(io)
        except (ArithmeticError, TypeError, ValueError):   # defensive: the checks above should catch it
            fault, plan = VcuFault.REQUEST_INVALID, None
        if fault == VcuFault.OK and self._wheel_fault(io, t):
            fault = VcuFault.WHEEL_FAULT
        self.fault = fault
        self.diagnostics.report(io, t, int(fault))
        if fault == VcuFault.OK and plan is not None:
            self.held = plan
            rpm, yaw = plan.rpm, plan.yaw_rate
        else:
            rpm, yaw = (0.0, 0.0, 0.0, 0.0), 0.0
        held = self.held
        clamp = ranges.clamp
        for message, angle, n in zip(self._cmd, held.angles, rpm):
            io.send_values(message, SteerAngleCmd=clamp(angle, ranges.STEER_ANGLE_CMD),
                           WheelSpeedCmd=clamp(n, ranges.WHEEL_SPEED_CMD))
        io.send_values("VCU_VehicleState", ActiveMode=int(held.mode),
                       VehicleSpeed=clamp(self._speed_estimate(io, held.direction), ranges.VEHICLE_SPEED),
                       YawRateTarget=clamp(yaw, ranges.YAW_RATE_TARGET),
                       CurvatureAngle=clamp(held.curvature, ranges.CURVATURE_ANGLE), VcuFault=int(fault))
        if held.centre is None:
            theta = math.radians(held.angles[0])
            right = (math.cos(theta), -math.sin(theta))
            scale = CENTRE_AT_INFINITY_M / max(abs(right[0]), abs(right[1]))
            cx, cy = right[0] * scale, right[1] * scale
        else:
            bound = (-CENTRE_AT_INFINITY_M, CENTRE_AT_INFINITY_M)
            cx, cy = clamp(held.centre[0], bound), clamp(held.centre[1], bound)
        io.send_values("VCU_RotationCentre", RotationCentreX=cx, RotationCentreY=cy)
