"""The steering robot at the hand wheel: the plant's driver, commanded by BENCH_SteeringRobot (dbc/bench.dbc).

Modes (RobotMode value table): OFF = hands off (no torque, the hand wheel is free), ANGLE = the robot
steers the hand wheel to RobotAngle, TORQUE = it applies RobotTorque at the rim. All bus signs
(positive to the right, docs/spec/formulas.md §1); internally rad, rad/s, N·m.

ANGLE is a stiff position servo, so it imposes the hand-wheel angle ([P1] eq. 1 then gives the torque
it has to apply): the target is rate limited (`robot_rate_limit`, an ISO 7401 step is steered at
200-500 °/s) and smoothed by a critically damped second-order filter (`robot_bandwidth`), so the hand
wheel has a continuous rate and a bounded acceleration even though the test runner updates RobotAngle only
every 10 ms. TORQUE follows RobotTorque with a first-order lag (`robot_torque_lag`). Switching mode is
bumpless: ANGLE starts from where the hand wheel is and how fast it turns.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from plant.vehicles import SbwParams

_RAD = math.pi / 180.0

OFF, ANGLE, TORQUE = 0, 1, 2


class SteeringRobot:
    """Implements plant.sbw.HandWheelDriver."""

    def __init__(self, p: SbwParams) -> None:
        self.rate_limit = p.robot_rate_limit * _RAD
        self.omega = p.robot_bandwidth
        self.torque_lag = p.robot_torque_lag
        self.reset()

    def reset(self) -> None:
        """Hands off, centred."""
        self.mode = OFF
        self.target_angle = 0.0       # rad, RobotAngle
        self.target_torque = 0.0      # N·m, RobotTorque
        self._ramp = 0.0              # rate-limited target, rad
        self._angle = self._rate = 0.0
        self._torque = 0.0
        self._engaged = False         # ANGLE has taken the hand wheel over

    def command(self, message: Mapping[str, float] | None) -> None:
        """Take BENCH_SteeringRobot (decoded values; None when never received or timed out: hands off)."""
        if message is None:
            self.mode = OFF
            return
        mode = message.get("RobotMode", OFF)
        angle, torque = message.get("RobotAngle", 0.0), message.get("RobotTorque", 0.0)
        if mode not in (OFF, ANGLE, TORQUE) or not (math.isfinite(angle) and math.isfinite(torque)):
            self.mode = OFF              # an impossible command: let go rather than act on it
            return
        if mode != ANGLE:
            self._engaged = False
        self.mode = int(mode)
        self.target_angle = angle * _RAD
        self.target_torque = torque

    def advance(self, h: float, angle: float, rate: float) -> tuple[bool, float, float, float]:
        """plant.sbw.HandWheelDriver: move by h; angle/rate are the hand wheel's now (rad, rad/s)."""
        if self.mode == ANGLE:
            if not self._engaged:
                self._angle, self._rate, self._ramp, self._engaged = angle, rate, angle, True
            step = self.rate_limit * h
            error = self.target_angle - self._ramp
            self._ramp += step if error > step else -step if error < -step else error
            w = self.omega
            accel = w * w * (self._ramp - self._angle) - 2.0 * w * self._rate
            self._rate += h * accel
            self._angle += h * self._rate
            return True, self._angle, self._rate, accel
        target = self.target_torque if self.mode == TORQUE else 0.0
        if self.mode == OFF:
            self._torque = 0.0
        else:
            self._torque += (target - self._torque) * (1.0 - math.exp(-h / self.torque_lag))
        return False, self._torque, 0.0, 0.0
