"""Reference SBW ECU (node SBW): [P1]'s bilateral control and [P3] §1's yaw-rate feedback.

Bilateral strategy, "force control + position-deviation feedback" ([P1] §2.3, Fig. 5-8; docs/spec/formulas.md §4):
- the driver's torque (torsion-bar sensor, eq. 2) commands the steering motor: target torque at the pinion
  G·(T_d + τ_d·Ṫ_d) − D·θ̇_p (G `assist_gain`; τ_d `torque_rate_gain`, whose derivative of the twist damps the
  hand-wheel/pinion loop without the ramp lag a damping on θ̇_p would add; D `pinion_damping_gain`, a mild
  active damping for a clean return when the driver lets go: all chosen, [P1] gives no gains)
  → target current → PID current loop (Fig. 8);
- the deviation between the pinion and the hand wheel's column commands the road-feel motor through
  P (position, Fig. 7: target column speed K·(θ_p − Δ − θ_c), plus the pinion's own speed as feedforward)
  → PI (speed) → PID (current). The driver therefore holds the torque that steers the road wheels (road feel),
  and the pinion follows the hand wheel with the torsion-bar twist T_a/(G·K_h) as its only steady error.
  Both current loops have a back-EMF feedforward and the derivative on the measured current.
These loops run at `control_rate` (≥ 1 kHz) inside the plant's time step: plant.sbw.SbwMechanics.advance
calls `control` every substep. Once per plant tick `step` reads the bus, runs the yaw-rate feedback and
publishes SBW_HandWheel and SBW_Pinion (sent every 10 ms by the restbus).

Steering mode: the diagnostic coding SteeringMode (DID 0xFDC0, docs/contract/sbw.md SBW-DIAG-02), written by a
tester with WriteDataByIdentifier; DIRECT, its default, until one writes another (and DIRECT with the parameter
file's G_r in a project that declares no diagnostics):
- DIRECT: ratio 1 (pinion = hand wheel, the mechanical 15:1 car), Δ = 0.
- YAW_RATE ([P3] §1.1): an "ideal steering ratio": reference yaw rate r* = G_r·θ_h (G_r the coding
  IdealYawGain, DID 0xFDC1, default 0.28 1/s), through a first-order lag (`yaw_reference_lag`); the
  front wheels get the additional angle δ_fa = PI(r* − r) (gains `yaw_feedback_kp/ki`), the pinion the
  offset Δ = i_s·δ_fa from the hand wheel (limited to `additional_angle_limit` and `_rate`, road wheel).
- YAW_RATE_LAT_ACCEL ([P3] §1.2, whose formula the OCR lost): the same PI on the blended error
  (1 − w)(r* − r) + w (u r* − a_y)/u, w = `lat_accel_weight`; both terms vanish together in steady state.
Inputs of the feedback: IMU_Motion (YawRate, LatAccel) and the speed u = mean of the rear wheels of
ABS_WheelSpeeds; the feedback is off below `feedback_min_speed`.

SbwFault (SBW_Pinion, dbc/chassis.dbc value table), the first that applies in this order:
- 3 PINION_RANGE, when the pinion angle sensor is beyond ±`pinion_range` or more than `plausibility_limit` from
  the steering motor's rotor angle: the rotor angle replaces the sensor; feedback off.
- 2 HANDWHEEL_STUCK, when the sensor has not changed while the column estimate moved more than `stuck_motion`
  (latched until the sensor changes): the estimate θ_c + T_d/K_h replaces the sensor; feedback off.
- 1 HANDWHEEL_RANGE, when the hand-wheel angle sensor is beyond ±`hand_wheel_range` (the DBC range) or more than
  `plausibility_limit` from the column estimate θ_c + T_d/K_h (column from the road-feel motor's rotor sensor,
  T_d from the torsion bar): as HANDWHEEL_STUCK (the estimate is clamped to the range on the bus).
- 4 INPUT_TIMEOUT, when a YAW mode is selected and IMU_Motion or ABS_WheelSpeeds is timed out: feedback off.
"Feedback off": Δ returns to 0 at the rate limit, so the car steers at the fixed ratio of the mechanical car;
the bilateral loops never use the hand-wheel or bus inputs, so steering and road feel continue. A fault
clears when its condition does. Nothing NaN or out of range reaches the bus (every value is clamped).
"""

from __future__ import annotations

import functools
import math
from enum import IntEnum

from bench.sim.node import DiagnosticSide, NodeIO
from plant import signal_ranges as ranges
from plant.ecus.diagnostics import EcuDiagnostics
from plant.sbw import SbwSensors
from plant.vehicles import SbwParams

_RAD = math.pi / 180.0
_DEG = 180.0 / math.pi
_KMH = 1.0 / 3.6
TORQUE_RATE_FILTER = 5e-4   # s, first-order filter of the driver-torque rate (chosen: a real sensor is noisy)
ADDITIONAL_ANGLE_FILTER = 0.02   # s, first-order filter of the feedback's additional angle (chosen)



class SbwFault(IntEnum):
    OK = 0
    HANDWHEEL_RANGE = 1
    HANDWHEEL_STUCK = 2
    PINION_RANGE = 3
    INPUT_TIMEOUT = 4


_OK, _RANGE, _STUCK = int(SbwFault.OK), int(SbwFault.HANDWHEEL_RANGE), int(SbwFault.HANDWHEEL_STUCK)
_PINION_RANGE, _INPUT_TIMEOUT = int(SbwFault.PINION_RANGE), int(SbwFault.INPUT_TIMEOUT)


class SteeringMode(IntEnum):
    """The coding DID SteeringMode's value table (dbc/diagnostics.toml, docs/contract/sbw.md SBW-DIAG-02)."""

    DIRECT = 0
    YAW_RATE = 1
    YAW_RATE_LAT_ACCEL = 2


_MODES = {int(m): m for m in SteeringMode}   # a valid raw SteeringMode -> its member (no enum call per tick)
_DIRECT, _LAT_ACCEL = SteeringMode.DIRECT, SteeringMode.YAW_RATE_LAT_ACCEL   # (an enum attribute is a slow lookup)


class _Pid:
    """Current loop: PI on the error, D on the measurement, back-EMF feedforward, clamp with anti-windup."""

    __slots__ = ("kp", "ki", "kd", "limit", "integral", "last")

    def __init__(self, kp: float, ki: float, kd: float, limit: float) -> None:
        self.kp, self.ki, self.kd, self.limit = kp, ki, kd, limit
        self.integral = self.last = 0.0

    def reset(self) -> None:
        self.integral = self.last = 0.0

    def __call__(self, target: float, measured: float, feedforward: float, h: float) -> float:
        error = target - measured
        derivative = (measured - self.last) / h
        self.last = measured
        out = self.kp * error + self.integral - self.kd * derivative + feedforward
        limit = self.limit
        if out > limit:
            out = limit
            if error < 0.0:
                self.integral += self.ki * error * h
        elif out < -limit:
            out = -limit
            if error > 0.0:
                self.integral += self.ki * error * h
        else:
            self.integral += self.ki * error * h
        return out


def _clamp(value: float, lo: float, hi: float) -> float:
    return lo if value < lo else hi if value > hi else value


class SbwEcu:
    """The SBW node: plant.sbw.MotorController (fast loops) and a bench Behaviour (bus side)."""

    nodes: tuple[str, ...] = ("SBW",)

    def __init__(self, p: SbwParams) -> None:
        self.p = p
        self.k_h = p.torsion_bar_stiffness
        self.kt_c = p.road_feel_torque_constant * p.road_feel_gear_ratio
        self.kt_p = p.steer_motor_torque_constant * p.steer_motor_gear_ratio
        self.b_p = p.pinion_damping + p.steer_motor_damping * p.steer_motor_gear_ratio ** 2
        self.gain = p.assist_gain
        self.damping = p.pinion_damping_gain
        self.torque_rate_gain = p.torque_rate_gain
        self.kpos = p.position_gain
        self.kps, self.kis = p.speed_kp, p.speed_ki
        self.i_rf_max = p.road_feel_current_limit
        self.i_sm_max = p.steer_motor_current_limit
        self.rf_pid = _Pid(p.road_feel_current_kp, p.road_feel_current_ki, p.road_feel_current_kd, p.supply_voltage)
        self.sm_pid = _Pid(p.steer_current_kp, p.steer_current_ki, p.steer_current_kd, p.supply_voltage)
        self.hw_range = p.hand_wheel_range * _RAD
        self.pin_range = p.pinion_range * _RAD
        self.plausibility = p.plausibility_limit * _RAD
        self.stuck_motion = p.stuck_motion * _RAD
        self.ratio = p.steering_ratio
        self._additional_angle_limit = p.additional_angle_limit * _RAD
        self._dt = -1.0                     # the tick the factors below are for (the plant's dt is fixed)
        self._reference_factor = self._smoothing = self._angle_step = self._rack_factor = 0.0
        self.diagnostics = EcuDiagnostics("SBW", SbwFault, self._diagnostic_setup)
        self.reset()

    def _set_dt(self, dt: float) -> None:
        """The per-tick factors of `step` for the tick dt (the same expressions, evaluated once)."""
        p = self.p
        self._dt = dt
        self._reference_factor = 1.0 - math.exp(-dt / p.yaw_reference_lag)
        self._smoothing = 1.0 - math.exp(-dt / ADDITIONAL_ANGLE_FILTER)
        self._angle_step = p.additional_angle_rate * _RAD * dt
        self._rack_factor = 1.0 - math.exp(-dt / p.rack_force_filter)

    def reset(self) -> None:
        """Power-on state: centred, loops at rest, DIRECT mode, no fault."""
        self.rf_pid.reset()
        self.sm_pid.reset()
        self.speed_integral = 0.0
        self._td_last: float | None = None
        self.torque_rate = 0.0              # filtered dT_d/dt, N·m/s
        self.offset = 0.0                   # Δ: pinion minus hand wheel the ECU steers to, rad (hand-wheel)
        self.hand_wheel = 0.0               # hand-wheel angle used (sensor or estimate), rad
        self.pinion = 0.0                   # pinion angle used, rad
        self.driver_torque = self.road_feel_current = self.steer_current = self.pinion_rate = 0.0
        self.rack_force = 0.0               # N, filtered estimate
        self.hand_fault = _OK               # SbwFault HANDWHEEL_RANGE / HANDWHEEL_STUCK / OK, as an int
        self.pinion_fault = False
        self.input_fault = False
        self._hw_last: float | None = None
        self._est_at_change = 0.0
        self._stuck = False
        # yaw-rate feedback (tick rate)
        self.mode = SteeringMode.DIRECT
        self.ideal_gain = self.p.ideal_yaw_gain
        self.yaw_reference = 0.0            # r*, filtered, rad/s
        self.additional_angle = 0.0         # δ_fa demanded by the feedback, rad (road wheel)
        self._yaw_integral = 0.0
        self.feedback_active = False
        self.speed = 0.0                    # m/s, from ABS_WheelSpeeds
        # hand-wheel sensor, column estimate, pinion sensor, steering motor's rotor angle (pinion), rad
        self.sensors = (0.0, 0.0, 0.0, 0.0)

    # -- fast loops (plant.sbw.MotorController) -----------------------------------------------------------
    def control(self, s: SbwSensors, h: float) -> tuple[float, float]:
        """One control period h: validate the angle sensors, then the two motors' cascades; (U_m, U_M) in V.
        (Hot: runs control_rate times a second; plain locals and int fault codes on purpose.)"""
        t_d = s.torsion_torque
        column = s.column
        estimate = column + t_d / self.k_h              # hand wheel from the column and the torsion bar
        hw = s.hand_wheel
        self.sensors = (hw, estimate, s.pinion, s.motor_pinion)   # the readings this period (diagnostics)
        if hw != self._hw_last:
            self._hw_last, self._est_at_change, self._stuck = hw, estimate, False
        elif not self._stuck and abs(estimate - self._est_at_change) > self.stuck_motion:
            self._stuck = True
        if self._stuck:
            self.hand_fault = _STUCK
        elif hw > self.hw_range or hw < -self.hw_range or abs(hw - estimate) > self.plausibility:
            self.hand_fault = _RANGE
        else:
            self.hand_fault = _OK
        self.hand_wheel = hw if self.hand_fault == _OK else estimate
        pin, motor_pin = s.pinion, s.motor_pinion
        fault = abs(pin) > self.pin_range or abs(pin - motor_pin) > self.plausibility
        self.pinion_fault = fault
        theta_p = motor_pin if fault else pin
        self.pinion = theta_p
        w_p = s.pinion_rate
        kt_p, kt_c = self.kt_p, self.kt_c
        # steering motor: force control by the driver's torque (PD: its rate damps the twist without a lag),
        # active damping of the pinion, PID current loop (Fig. 8)
        last = self._td_last
        if last is not None:
            self.torque_rate += ((t_d - last) / h - self.torque_rate) * h / (h + TORQUE_RATE_FILTER)
        self._td_last = t_d
        force = self.gain * (t_d + self.torque_rate_gain * self.torque_rate)
        i_max = self.i_sm_max
        i_target = (force - self.damping * w_p) / kt_p
        i_target = i_max if i_target > i_max else -i_max if i_target < -i_max else i_target
        u_sm = self.sm_pid(i_target, s.steer_current, kt_p * w_p, h)
        # road-feel motor: P position -> PI speed -> PID current (Fig. 7), on the pinion-column deviation
        column_rate = s.column_rate
        speed_error = self.kpos * (theta_p - self.offset - column) + w_p - column_rate
        i_rf = (self.kps * speed_error + self.speed_integral) / kt_c
        i_max = self.i_rf_max
        if -i_max < i_rf < i_max or (i_rf > 0.0) != (speed_error > 0.0):
            self.speed_integral += self.kis * speed_error * h
        i_rf = i_max if i_rf > i_max else -i_max if i_rf < -i_max else i_rf
        u_rf = self.rf_pid(i_rf, s.road_feel_current, kt_c * column_rate, h)
        self.driver_torque = t_d
        self.pinion_rate = w_p
        self.road_feel_current = s.road_feel_current
        self.steer_current = s.steer_current
        return u_rf, u_sm

    # -- bus side (bench.sim.node.Behaviour) --------------------------------------------------------------
    def _read_config(self, io: NodeIO) -> None:
        """The steering mode and G_r from the coding (docs/contract/sbw.md SBW-DIAG-02, written by a tester with
        WriteDataByIdentifier); DIRECT and the parameter file's G_r for a project without diagnostics."""
        mode, gain = _DIRECT, self.p.ideal_yaw_gain
        side = self.diagnostics.side(io)
        if side is not None:
            raw_mode, raw_gain = side.coding("SteeringMode"), side.coding("IdealYawGain")
            if raw_mode in _MODES and ranges.finite(raw_gain) and raw_gain > 0.0:
                mode, gain = _MODES[int(raw_mode)], raw_gain
        self.mode, self.ideal_gain = mode, gain

    def _inputs(self, io: NodeIO) -> tuple[float, float, float] | None:
        """(u m/s, r rad/s, a_y m/s²) from the bus, bus signs; None when an input is missing."""
        imu, wheels = io.latest("IMU_Motion"), io.latest("ABS_WheelSpeeds")
        if imu is None or wheels is None:
            return None
        r, ay = imu.get("YawRate", math.nan), imu.get("LatAccel", math.nan)
        rl, rr = wheels.get("WheelSpeedRL", math.nan), wheels.get("WheelSpeedRR", math.nan)
        if not ranges.finite(r, ay, rl, rr):
            return None
        return 0.5 * (rl + rr) * _KMH, r * _RAD, ay

    def _feedback(self, dt: float, inputs: tuple[float, float, float] | None) -> float:
        """δ_fa target (rad, road wheel) of [P3] §1.1/§1.2 for this tick; 0 and reset when off."""
        p = self.p
        active = (self.mode != _DIRECT and inputs is not None and self.hand_fault == _OK
                  and not self.pinion_fault and inputs[0] >= p.feedback_min_speed * _KMH)
        self.feedback_active = active
        if not active:
            self._yaw_integral = 0.0
            self.yaw_reference = self.ideal_gain * self.hand_wheel
            return 0.0
        assert inputs is not None
        u, r, ay = inputs
        self.speed = u
        target = self.ideal_gain * self.hand_wheel
        self.yaw_reference += (target - self.yaw_reference) * self._reference_factor
        error = self.yaw_reference - r
        if self.mode == _LAT_ACCEL:
            w = p.lat_accel_weight
            error = (1.0 - w) * error + w * (u * self.yaw_reference - ay) / u
        limit = self._additional_angle_limit
        demand = p.yaw_feedback_kp * error + self._yaw_integral
        if -limit < demand < limit or (demand > 0.0) != (error > 0.0):
            self._yaw_integral += p.yaw_feedback_ki * error * dt
        return _clamp(demand, -limit, limit)

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        if dt != self._dt:
            self._set_dt(dt)
        self._read_config(io)
        inputs = self._inputs(io)
        self.input_fault = self.mode != _DIRECT and inputs is None
        if inputs is not None:
            self.speed = inputs[0]
        demand = self._feedback(dt, inputs)
        if self.feedback_active:   # smooth the 10 ms staircase of the bus inputs (off: back to 0 at the rate limit)
            demand = self.additional_angle + (demand - self.additional_angle) * self._smoothing
        step = self._angle_step
        self.additional_angle += _clamp(demand - self.additional_angle, -step, step)
        self.offset = self.ratio * self.additional_angle
        # rack force: the load the steering motor balances (quasi-static: motor torque minus the known
        # viscous part, at the pinion radius), first-order filtered
        load = -(self.kt_p * self.steer_current - self.b_p * self.pinion_rate) / self.p.pinion_radius
        self.rack_force += (load - self.rack_force) * self._rack_factor
        self._publish(io)
        self.diagnostics.report(io, t, self._fault_code())

    def _diagnostic_setup(self, side: DiagnosticSide, io: NodeIO) -> None:
        """The reference SBW's diagnostic values (docs/contract/sbw.md SBW-DIAG-*): what an ECUReset does, and
        the DIDs only it knows (the bench serves those that equal a signal it sends or reads)."""
        side.on_reset(self.reset)
        side.provide("VehicleSpeed", lambda: self.speed * 3.6)
        for index, name in enumerate(("HandWheelSensorAngle", "ColumnAngleEstimate", "PinionSensorAngle",
                                      "ActuatorAngle")):
            side.provide(name, functools.partial(self._sensor_deg, index))

    def _sensor_deg(self, index: int) -> float:
        return self.sensors[index] * _DEG

    @property
    def fault(self) -> SbwFault:
        return SbwFault(self._fault_code())

    def _fault_code(self) -> int:
        """SBW_Pinion.SbwFault: the first fault that applies (module docstring), as the number on the bus."""
        if self.pinion_fault:
            return _PINION_RANGE
        if self.hand_fault != _OK:
            return self.hand_fault
        if self.input_fault:
            return _INPUT_TIMEOUT
        return _OK

    def _publish(self, io: NodeIO) -> None:
        # every value limited to its ranges.* bounds, a NaN (never expected) sent as 0: ranges.clamp written out
        # (hot: every tick)
        hand, torque = self.hand_wheel * _DEG, self.driver_torque
        feel, current = self.kt_c * self.road_feel_current, self.road_feel_current
        lo, hi = ranges.SBW_HAND_WHEEL_ANGLE
        hand = 0.0 if hand != hand else lo if hand < lo else hi if hand > hi else hand
        lo, hi = ranges.SBW_DRIVER_TORQUE
        torque = 0.0 if torque != torque else lo if torque < lo else hi if torque > hi else torque
        lo, hi = ranges.SBW_ROAD_FEEL_TORQUE
        feel = 0.0 if feel != feel else lo if feel < lo else hi if feel > hi else feel
        lo, hi = ranges.SBW_ROAD_FEEL_CURRENT
        current = 0.0 if current != current else lo if current < lo else hi if current > hi else current
        io.send_values("SBW_HandWheel", HandWheelAngle=hand, DriverTorque=torque, RoadFeelTorque=feel,
                       RoadFeelMotorCurrent=current)
        pinion, target = self.pinion * _DEG, (self.hand_wheel + self.offset) * _DEG
        lo, hi = ranges.SBW_PINION_ANGLE
        pinion = 0.0 if pinion != pinion else lo if pinion < lo else hi if pinion > hi else pinion
        target = 0.0 if target != target else lo if target < lo else hi if target > hi else target
        current, force = self.steer_current, self.rack_force
        lo, hi = ranges.SBW_STEER_MOTOR_CURRENT
        current = 0.0 if current != current else lo if current < lo else hi if current > hi else current
        lo, hi = ranges.SBW_RACK_FORCE
        force = 0.0 if force != force else lo if force < lo else hi if force > hi else force
        io.send_values("SBW_Pinion", PinionAngle=pinion, PinionAngleTarget=target, SteerMotorCurrent=current,
                       RackForce=force, SbwFault=self._fault_code())
