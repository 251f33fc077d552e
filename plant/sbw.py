"""Steer-by-wire mechanics of [P1] (eq. 1-10, docs/spec/formulas.md §4): hand wheel with torsion bar, road-feel
motor with its worm gear, steering actuator DC motor, rack and pinion with dry friction and aligning torque.

Coordinates: every angle is a hand-wheel angle in rad, positive to the right (bus convention,
docs/spec/formulas.md §1): the hand wheel θ_h, the column below the torsion bar θ_c = θ_m / r_m (θ_m the road-feel
motor's angle, r_m its gear ratio) and the pinion θ_p (the road wheels turn θ_p / i_s, i_s =
`steering_ratio`). [P1]'s equations, written at the column and at the pinion:

    (1) F_h = J_h θ̈_h + B_h θ̇_h + F_m                  hand wheel, F_h the driver's (robot's) torque
    (2) F_m = K_h (θ_h − θ_m / r_m)                     torsion bar (the driver-torque sensor)
    (3) T_m = J_m θ̈_m + B_m θ̇_m − F_m / r_m             road-feel motor, at its shaft
    (4) T_m = K_m i_m     (5) U_m = R_m i_m + L_m di_m/dt + K_m θ̇_m
    (6) T_M = J_M θ̈_M + B_M θ̇_M + T_r / r_M             steering motor at its shaft, θ_M = r_M θ_p
    (7) T_M = K_M i_M     (8) U_M = R_M i_M + L_M di_M/dt + K_M θ̇_M
    (9) T_t = J_p θ̈_p + B_p θ̇_p + T_f                   rack and pinion, T_f dry friction
    (10) T_t = T_r + T_a                               T_a aligning torque at the pinion

so that (J_m r_m²) θ̈_c = r_m K_m i_m − B_m r_m² θ̇_c + F_m and
(J_p + J_M r_M²) θ̈_p = r_M K_M i_M − (B_p + B_M r_M²) θ̇_p − T_f + T_a. The OCR prints r_m (the
road-feel gear) in eq. 6 too; the steering motor has its own reduction r_M here (`steer_motor_gear_ratio`).

Aligning torque (eq. 10) from the vehicle's front axle force: T_a = −t F_yf / i_s with t the total trail
(pneumatic + caster), F_yf = C_f α_f, α_f = θ_p / i_s − (β + a r / u) in bus signs: the caller sets the
front axle through `set_front_axle` every plant tick, the pinion's own angle enters at every substep.

Integration per substep h (the ECU's control period, plant/ecus/sbw.py): currents exactly for the
voltage and speed held over h; velocities then positions semi-implicitly (stable: h·√(K/J) ≪ 1);
dry friction by a stick-slip (Karnopp) rule, so the pinion rests instead of chattering; rigid end stops
at ±`pinion_travel`. In ANGLE mode the steering robot imposes θ_h (plant/driver.py) and eq. 1 gives the
torque it needs; in TORQUE and OFF modes the hand wheel is free under the robot's torque.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Final, Protocol

from plant.vehicles import SbwParams

_RAD = math.pi / 180.0


class SensorFault:
    """What the plant's sensor model may do (BENCH_SbwSensorFault.SensorFault, dbc/bench.dbc)."""

    NONE: Final = 0
    HANDWHEEL_STUCK: Final = 1      # the hand-wheel angle sensor freezes at its value when the fault starts
    HANDWHEEL_OFFSET: Final = 2     # the hand-wheel angle sensor reads `offset` too much
    PINION_OFFSET: Final = 3        # the pinion angle sensor reads `offset` too much


class SbwSensors:
    """What the SBW ECU measures, refreshed before every substep (rad, rad/s, N·m, A; bus signs).

    `hand_wheel` and `pinion` are the angle sensors (subject to injected faults); `column` and
    `column_rate` come from the road-feel motor's rotor sensor through its gear, `motor_pinion` and
    `pinion_rate` from the steering motor's rotor sensor through its reduction (independent channels).
    """

    __slots__ = ("hand_wheel", "torsion_torque", "column", "column_rate", "road_feel_current",
                 "pinion", "motor_pinion", "pinion_rate", "steer_current")

    def __init__(self) -> None:
        self.hand_wheel = self.torsion_torque = self.column = self.column_rate = 0.0
        self.road_feel_current = self.pinion = self.motor_pinion = self.pinion_rate = self.steer_current = 0.0


class MotorController(Protocol):
    """The ECU's fast loops, called once per substep (plant/ecus/sbw.py implements it)."""

    def control(self, sensors: SbwSensors, h: float) -> tuple[float, float]:
        """(road-feel motor voltage U_m, steering motor voltage U_M), V."""


class HandWheelDriver(Protocol):
    """The steering robot as the hand wheel sees it (plant/driver.py implements it)."""

    def advance(self, h: float, angle: float, rate: float) -> tuple[bool, float, float, float]:
        """Move by h. (True, θ, θ̇, θ̈) when it imposes the hand-wheel angle, else (False, torque, 0, 0)."""


class SbwMechanics:
    """State and substep of [P1]'s SBW system (see the module docstring)."""

    def __init__(self, p: SbwParams) -> None:
        self.p = p
        self.j_h, self.b_h, self.k_h = p.hand_wheel_inertia, p.hand_wheel_damping, p.torsion_bar_stiffness
        rm, rM = p.road_feel_gear_ratio, p.steer_motor_gear_ratio
        self.j_c = p.road_feel_inertia * rm * rm
        self.b_c = p.road_feel_damping * rm * rm
        self.kt_c = p.road_feel_torque_constant * rm            # N·m at the column per A (and V per rad/s)
        self.j_p = p.pinion_inertia + p.steer_motor_inertia * rM * rM
        self.b_p = p.pinion_damping + p.steer_motor_damping * rM * rM
        self.kt_p = p.steer_motor_torque_constant * rM          # N·m at the pinion per A (and V per rad/s)
        self.friction = p.dry_friction
        self.ratio = p.steering_ratio
        self.trail = p.tyre_trail
        self.travel = p.pinion_travel * _RAD
        self._r_m, self._r_M = p.road_feel_resistance, p.steer_motor_resistance
        self._h = -1.0
        self._decay_m = self._decay_M = 0.0
        self.reset()

    def reset(self) -> None:
        """Centred, at rest, no current, no tyre load, no sensor fault."""
        self.theta_h = self.omega_h = 0.0
        self.theta_c = self.omega_c = 0.0
        self.theta_p = self.omega_p = 0.0
        self.i_m = self.i_M = 0.0
        self.driver_torque = 0.0          # F_h, what the robot (driver) applies at the rim, N·m
        self.aligning_torque = 0.0        # T_a at the pinion, N·m
        self._cf = self._slip_offset = self._force_offset = 0.0
        self.fault = SensorFault.NONE
        self.fault_offset = 0.0
        self._stuck_value: float | None = None

    # -- inputs from the vehicle and the bench -------------------------------------------------------
    def set_front_axle(self, cornering_stiffness: float, slip_offset: float, force: float = 0.0) -> None:
        """Front axle force F_yf = C_f (θ_p / i_s − slip_offset) + force, N (bus signs): C_f the axle
        cornering stiffness (0 when the vehicle is kinematic), slip_offset = β + a r / u, force a fixed part."""
        self._cf, self._slip_offset, self._force_offset = cornering_stiffness, slip_offset, force

    def set_sensor_fault(self, fault: int, offset: float = 0.0) -> None:
        """Inject a sensor fault (SensorFault) with its offset (rad); NONE clears it."""
        if fault != self.fault:
            self._stuck_value = self.theta_h if fault == SensorFault.HANDWHEEL_STUCK else None
        self.fault, self.fault_offset = fault, offset

    @property
    def front_lateral_force(self) -> float:
        """F_yf at the present pinion angle, N (bus signs: positive to the right)."""
        return self._cf * (self.theta_p / self.ratio - self._slip_offset) + self._force_offset

    @property
    def road_feel_torque(self) -> float:
        """Torque of the road-feel motor at the column (hand-wheel side of its gear), N·m."""
        return self.kt_c * self.i_m

    @property
    def torsion_torque(self) -> float:
        """F_m of eq. 2, N·m: what the driver-torque sensor reads."""
        return self.k_h * (self.theta_h - self.theta_c)

    @property
    def road_wheel_angle(self) -> float:
        """δ_f = θ_p / i_s, rad (bus signs)."""
        return self.theta_p / self.ratio

    # -- sensors -------------------------------------------------------------------------------------------
    def read(self, s: SbwSensors) -> None:
        """Fill `s` with what the ECU's sensors read now (faults applied)."""
        fault = self.fault
        hand = self.theta_h
        if fault == SensorFault.HANDWHEEL_STUCK and self._stuck_value is not None:
            hand = self._stuck_value
        elif fault == SensorFault.HANDWHEEL_OFFSET:
            hand += self.fault_offset
        s.hand_wheel = hand
        s.torsion_torque = self.k_h * (self.theta_h - self.theta_c)
        s.column = self.theta_c
        s.column_rate = self.omega_c
        s.road_feel_current = self.i_m
        s.pinion = self.theta_p + (self.fault_offset if fault == SensorFault.PINION_OFFSET else 0.0)
        s.motor_pinion = self.theta_p
        s.pinion_rate = self.omega_p
        s.steer_current = self.i_M

    # -- dynamics -------------------------------------------------------------------------------------------
    def substep(self, h: float, u_m: float, u_M: float, driver: HandWheelDriver) -> None:
        """Advance by h with the motor voltages held (V) and the robot acting on the hand wheel.
        (Hot: runs control_rate times a second; state in locals, the same operations in the same order.)"""
        if h != self._h:
            p = self.p
            self._h = h
            self._decay_m = math.exp(-h * p.road_feel_resistance / p.road_feel_inductance)
            self._decay_M = math.exp(-h * p.steer_motor_resistance / p.steer_motor_inductance)
        r_m, r_M = self._r_m, self._r_M
        omega_c, omega_p = self.omega_c, self.omega_p
        theta_h, theta_c = self.theta_h, self.theta_c
        kt_c = self.kt_c
        # (5), (8): currents, exact for the voltage and the back-EMF held over h
        i_ss = (u_m - kt_c * omega_c) / r_m
        i_m = i_ss + (self.i_m - i_ss) * self._decay_m
        self.i_m = i_m
        i_ss = (u_M - self.kt_p * omega_p) / r_M
        i_M = i_ss + (self.i_M - i_ss) * self._decay_M
        self.i_M = i_M
        # (2): torsion bar
        f_m = self.k_h * (theta_h - theta_c)
        # (1): hand wheel, imposed by the robot or free under its torque
        imposed, a, b, c = driver.advance(h, theta_h, self.omega_h)
        if imposed:
            self.theta_h, self.omega_h = a, b
            self.driver_torque = self.j_h * c + self.b_h * b + f_m
        else:
            self.driver_torque = a
            omega_h = self.omega_h + h * (a - self.b_h * self.omega_h - f_m) / self.j_h
            self.omega_h = omega_h
            self.theta_h = theta_h + h * omega_h
        # (3), (4): column and road-feel motor
        omega_c += h * (kt_c * i_m - self.b_c * omega_c + f_m) / self.j_c
        self.omega_c = omega_c
        self.theta_c = theta_c + h * omega_c
        # (6), (7), (9), (10): pinion with the steering motor, dry friction and aligning torque
        theta_p = self.theta_p
        ratio = self.ratio
        t_a = -self.trail * (self._cf * (theta_p / ratio - self._slip_offset) + self._force_offset) / ratio
        self.aligning_torque = t_a
        drive = self.kt_p * i_M - self.b_p * omega_p + t_a
        w = omega_p
        friction = self.friction
        if w == 0.0 and abs(drive) <= friction:
            pass                                                      # sticking: static friction holds
        else:
            direction = w if w != 0.0 else drive
            w_new = w + h * (drive - math.copysign(friction, direction)) / self.j_p
            if w != 0.0 and w_new * w < 0.0:
                w_new = 0.0                                           # reversal: stick for now
            omega_p = w_new
        theta = theta_p + h * omega_p
        travel = self.travel
        if theta > travel:
            theta, omega_p = travel, min(omega_p, 0.0)
        elif theta < -travel:
            theta, omega_p = -travel, max(omega_p, 0.0)
        self.omega_p = omega_p
        self.theta_p = theta

    def advance(self, dt: float, controller: MotorController, driver: HandWheelDriver,
                sensors: SbwSensors, substeps: int) -> None:
        """One plant tick dt: `substeps` times (read the sensors, let the ECU's fast loops set the
        voltages, move by dt/substeps). The ECU therefore runs at substeps/dt (≥ 1 kHz)."""
        h = dt / substeps
        read, control, substep = self.read, controller.control, self.substep
        for _ in range(substeps):
            read(sensors)
            u_m, u_M = control(sensors, h)
            substep(h, u_m, u_M, driver)


IO_CYCLE = 0.005          # s, GenMsgCycleTime of IO_SbwActuators (dbc/bench.dbc)
_COUNTER_MODULO = 15      # E2E Profile 11 AliveCounter 0..14


class ActuatorEmulation:
    """The rig's "smart actuators" for an external SBW (docs/contract/plant.md PLANT-IO-SBW-03, -04, -06): a
    MotorController that realises IO_SbwActuators on the mechanics.

    Steering actuator: a position servo with the request's rate as feed-forward. The k-th frame, applied at t_k,
    gives θ_k and w_k = (θ_k − θ_{k−1}) / (n · IO_CYCLE) (n the AliveCounter steps between the two frames; w = 0
    for the first frame after none or a timeout): the SBW sends one frame per 5 ms I/O sample, so the counter,
    not the receive times, gives the rate, and bunched or late frames keep it right (several in one tick: the
    last is applied; a late one: the reference holds after IO_CYCLE of extrapolation); the reference is
    r = θ_k + w_k · min(t − t_k, IO_CYCLE) with rate ṙ. The servo imposes
    θ̈_p = ω_n² (r − θ_p) + 2 ζ ω_n (ṙ − θ̇_p) by computed torque: the pinion's inertia (J_p + J_M r_M²) times
    that acceleration plus the load the rig knows (viscous and dry friction, the aligning
    torque), as a target current limited to the motor's current limit. Road-feel motor: target current
    RoadFeelTorqueRequest / (K_m r_m), limited likewise. Both currents follow their targets as first-order lags
    of `rig_current_time_constant`: the voltage of each substep is the one that, held over h, moves the motor's
    current (eq. 5/8, integrated exactly by SbwMechanics.substep) by (1 − e^{−h/τ}) of the way to its target,
    within the supply voltage. No valid frame (`take(None)`): the last position request is held (none yet:
    centre) and the road-feel torque is 0.
    """

    def __init__(self, mech: SbwMechanics) -> None:
        p = mech.p
        self.mech = mech
        self.wn, self.zeta = p.rig_servo_frequency, p.rig_servo_damping
        self.tau = p.rig_current_time_constant
        self.j_p, self.b_p, self.friction = mech.j_p, mech.b_p, mech.friction
        self.kt_p, self.kt_c = mech.kt_p, mech.kt_c
        self.i_p_max, self.i_c_max = p.steer_motor_current_limit, p.road_feel_current_limit
        self.u_max = p.supply_voltage
        self._r_c, self._l_c = p.road_feel_resistance, p.road_feel_inductance
        self._r_p, self._l_p = p.steer_motor_resistance, p.steer_motor_inductance
        self._h = -1.0
        self._decay_c = self._decay_p = self._step = 0.0
        self.reset()

    def reset(self) -> None:
        """No frame yet: reference centred, no road-feel torque."""
        self.request = 0.0          # θ_k, rad
        self.rate = 0.0             # w_k, rad/s
        self.elapsed = 0.0          # t − t_k, s
        self.torque = 0.0           # road-feel torque request, N·m at the column
        self._frame: object = None  # the values mapping last applied (a new mapping = a new frame)
        self._counter: float | None = None

    def take(self, frame: Mapping[str, float] | None) -> None:
        """Once per plant tick, before the substeps: the latest valid IO_SbwActuators values (None: none yet or
        timed out)."""
        if frame is None:
            if self._frame is not None:          # timeout: hold the last request, no road-feel torque
                self._frame, self._counter = None, None
                self.rate = 0.0
                self.torque = 0.0
            return
        if frame is self._frame:
            return
        request = frame["PinionAngleRequest"] * _RAD
        counter = frame.get("AliveCounter")
        if self._frame is None or counter is None or self._counter is None:
            self.rate = 0.0
        else:
            steps = int(counter - self._counter) % _COUNTER_MODULO or 1
            self.rate = (request - self.request) / (steps * IO_CYCLE)
        self.request, self.elapsed = request, 0.0
        self.torque = frame["RoadFeelTorqueRequest"]
        self._frame, self._counter = frame, counter

    def _set_h(self, h: float) -> None:
        self._h = h
        self._decay_c = math.exp(-h * self._r_c / self._l_c)
        self._decay_p = math.exp(-h * self._r_p / self._l_p)
        self._step = 1.0 - math.exp(-h / self.tau)

    def _voltage(self, current: float, target: float, decay: float, resistance: float, emf: float) -> float:
        """The voltage that, held over h, moves the current by `_step` of the way to `target` (eq. 5/8)."""
        wanted = current + (target - current) * self._step
        steady = (wanted - current * decay) / (1.0 - decay)
        u = resistance * steady + emf
        limit = self.u_max
        return limit if u > limit else -limit if u < -limit else u

    def control(self, sensors: SbwSensors, h: float) -> tuple[float, float]:
        """(U_m, U_M) for the substep h (plant.sbw.MotorController)."""
        if h != self._h:
            self._set_h(h)
        mech = self.mech
        elapsed = self.elapsed
        if elapsed < IO_CYCLE:
            reference, rate = self.request + self.rate * elapsed, self.rate
        else:
            reference, rate = self.request + self.rate * IO_CYCLE, 0.0
        self.elapsed = elapsed + h
        theta, omega = mech.theta_p, mech.omega_p
        wn = self.wn
        accel = wn * wn * (reference - theta) + 2.0 * self.zeta * wn * (rate - omega)
        direction = omega if omega != 0.0 else accel
        dry = math.copysign(self.friction, direction) if direction != 0.0 else 0.0
        aligning = -mech.trail * mech.front_lateral_force / mech.ratio
        torque = self.j_p * accel + self.b_p * omega + dry - aligning
        limit = self.i_p_max
        target = torque / self.kt_p
        target = limit if target > limit else -limit if target < -limit else target
        u_p = self._voltage(mech.i_M, target, self._decay_p, self._r_p, self.kt_p * omega)
        limit = self.i_c_max
        target = self.torque / self.kt_c
        target = limit if target > limit else -limit if target < -limit else target
        u_c = self._voltage(mech.i_m, target, self._decay_c, self._r_c, self.kt_c * mech.omega_c)
        return u_c, u_p
