"""Reference wheel ECU (nodes WHL_FL, WHL_FR, WHL_RL, WHL_RR): steering servo and hub motor of one corner.

The contract it implements: docs/contract/wheel.md (WHL-*); where this docstring and the contract differ, the
contract is right.

[P0] §2.2: each wheel ECU executes the VCU's steering-angle and wheel-speed targets and reports the
wheel's state. Models (parameters in plant/vehicles/ev4wis.toml, docs/spec/vehicles.md A, all "chosen"):

- Steering servo: first-order lag (servo_lag, 50 ms) with a rate limit (servo_rate_limit, 120 deg/s).
- Hub motor speed loop: first-order lag (hub_motor_lag, 100 ms).
- SteerMotorCurrent: servo_current_per_rate * steering rate (viscous/back-EMF part) plus the aligning
  load servo_twist_current * tanh(rate / 5 deg/s) / (1 + |wheel speed| / 0.5 m/s). The steering axis
  passes through the contact point ([P0] §1.1), so there is no scrub arm: the load is the tyre's
  bore (twisting) torque, full when steering at standstill and fading once the wheel rolls.

WheelFault (dbc value table): 0 OK, 1 SERVO_FAULT and 2 MOTOR_FAULT (reserved, not modelled),
3 CMD_TIMEOUT (io.latest(VCU_WheelCmd_xx) is None: never received or timed out -> hold the angle where
it is, ramp the speed to 0 at timeout_speed_ramp), 4 CMD_INVALID (a command beyond ±steer_limit or
±hub_motor_max_speed is clamped and executed; a non-finite or incomplete one is treated like a timeout;
a last frame that failed the E2E/range check flags 4 while the last valid command is executed).
"""

from __future__ import annotations

import math
from enum import IntEnum

from bench.sim.node import DiagnosticSide, NodeIO
from plant import signal_ranges as ranges
from plant.ecus.diagnostics import EcuDiagnostics
from plant.vehicles import Ev4wisParams


class WheelFault(IntEnum):
    OK = 0
    SERVO_FAULT = 1
    MOTOR_FAULT = 2
    CMD_TIMEOUT = 3
    CMD_INVALID = 4


TWIST_RATE_DPS = 5.0      # steering rate at which the bore torque is fully developed (chosen)
TWIST_FADE_MPS = 0.5      # rolling speed that halves the bore torque (chosen)

_tanh, _isfinite = math.tanh, math.isfinite
_STEER_ANGLE, _WHEEL_SPEED, _CURRENT = ranges.STEER_ANGLE, ranges.WHEEL_SPEED, ranges.STEER_MOTOR_CURRENT
_FAULT_CODE = {f: int(f) for f in WheelFault}     # the number WHL_Status carries (an int, not the enum)
_OK, _TIMEOUT, _INVALID = WheelFault.OK, WheelFault.CMD_TIMEOUT, WheelFault.CMD_INVALID   # (enum lookups are slow)


class WheelEcu:
    """One corner's wheel ECU; exposes its true state (angle_deg, speed_rpm) for the body model."""

    def __init__(self, corner: str, params: Ev4wisParams) -> None:
        self.corner = corner
        self.nodes: tuple[str, ...] = (f"WHL_{corner}",)
        self.cmd_message = f"VCU_WheelCmd_{corner}"
        self.status_message = f"WHL_Status_{corner}"
        self._limit = params.steer_limit
        self._max_rpm = params.hub_motor_max_speed
        self._rate_limit = params.servo_rate_limit
        self._servo_tau = params.servo_lag
        self._motor_tau = params.hub_motor_lag
        self._ramp = params.timeout_speed_ramp
        self._k_rate = params.servo_current_per_rate
        self._k_twist = params.servo_twist_current
        self._mps_per_rpm = math.pi * params.wheel_radius / 30.0
        self._dt = -1.0
        self._servo_gain = self._motor_gain = self._max_move = self._ramp_step = 0.0
        self.diagnostics = EcuDiagnostics(self.nodes[0], WheelFault, self._diagnostic_setup)
        self.reset()

    def reset(self) -> None:
        """Straight ahead, at rest, no fault."""
        self.angle_deg = 0.0
        self.speed_rpm = 0.0
        self.rate_dps = 0.0
        self.current = 0.0
        self.fault = WheelFault.OK

    def _diagnostic_setup(self, side: DiagnosticSide, io: NodeIO) -> None:
        side.on_reset(self.reset)

    def preset(self, angle_deg: float, speed_rpm: float) -> None:
        """Start a scenario in this state (BENCH_Control.InitialSpeed)."""
        self.angle_deg, self.speed_rpm = angle_deg, speed_rpm

    def wheel_state(self, io: NodeIO) -> tuple[float, float]:
        """The true (angle deg, speed rpm), for the body (plant.body.WheelSource)."""
        return self.angle_deg, self.speed_rpm

    def _command(self, io: NodeIO) -> tuple[WheelFault, tuple[float, float] | None]:
        """The fault of this tick and the (angle deg, speed rpm) to execute (None: hold, ramp down)."""
        cmd = io.latest(self.cmd_message)
        if cmd is None:
            return _TIMEOUT, None
        angle, speed = cmd.get("SteerAngleCmd", math.nan), cmd.get("WheelSpeedCmd", math.nan)
        try:                                    # ranges.finite(angle, speed) written out (four wheels every tick)
            usable = _isfinite(angle) and _isfinite(speed)
        except TypeError:
            usable = False
        if not usable:
            return _INVALID, None
        fault = _INVALID if io.invalid(self.cmd_message) else _OK
        if abs(angle) > self._limit:
            angle, fault = math.copysign(self._limit, angle), _INVALID
        if abs(speed) > self._max_rpm:
            speed, fault = math.copysign(self._max_rpm, speed), _INVALID
        return fault, (angle, speed)

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        if dt != self._dt:     # exact discretisation of both lags, stable for any dt
            self._dt = dt
            self._servo_gain = 1.0 - math.exp(-dt / self._servo_tau) if dt > 0 else 0.0
            self._motor_gain = 1.0 - math.exp(-dt / self._motor_tau) if dt > 0 else 0.0
            self._max_move = self._rate_limit * dt
            self._ramp_step = self._ramp * dt
        fault, target = self._command(io)
        self.fault = fault
        self.diagnostics.report(io, t, _FAULT_CODE[fault])
        if target is None:          # hold the angle, ramp the speed down
            move = 0.0
            ramp = self._ramp_step
            n = self.speed_rpm
            self.speed_rpm = 0.0 if abs(n) <= ramp else n - math.copysign(ramp, n)
        else:
            angle_cmd, speed_cmd = target
            move = (angle_cmd - self.angle_deg) * self._servo_gain
            max_move = self._max_move
            if move > max_move:
                move = max_move
            elif move < -max_move:
                move = -max_move
            self.speed_rpm += (speed_cmd - self.speed_rpm) * self._motor_gain
        angle = self.angle_deg + move
        self.angle_deg = angle
        rate = move / dt if dt > 0 else 0.0
        self.rate_dps = rate
        speed_rpm = self.speed_rpm
        v = abs(speed_rpm) * self._mps_per_rpm
        current = self._k_rate * rate + self._k_twist * _tanh(rate / TWIST_RATE_DPS) / (1.0 + v / TWIST_FADE_MPS)
        self.current = current
        # ranges.clamp written out (hot: four wheels every tick); a NaN, never expected, is sent as 0
        lo, hi = _STEER_ANGLE
        angle = 0.0 if angle != angle else lo if angle < lo else hi if angle > hi else angle
        lo, hi = _WHEEL_SPEED
        speed_rpm = 0.0 if speed_rpm != speed_rpm else lo if speed_rpm < lo else hi if speed_rpm > hi else speed_rpm
        lo, hi = _CURRENT
        current = 0.0 if current != current else lo if current < lo else hi if current > hi else current
        io.send_values(self.status_message, SteerAngle=angle, WheelSpeed=speed_rpm, SteerMotorCurrent=current,
                       WheelFault=_FAULT_CODE[fault])
