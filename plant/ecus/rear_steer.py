"""[P3] §2's rear-steering laws for the reference VCU's ADAPTIVE mode above its low-speed range.

Selected by the bench-private coding BENCH_VcuConfig.RearSteerLaw (dbc/bench.dbc; a real VCU ignores it):

- OFF (2WS): δ_r = 0; the centre lies on the rear-axle line (like NORMAL).
- FEEDFORWARD: δ_r = k(u) δ_f with the zero-sideslip ratio of docs/spec/formulas.md §5 ([P3] §2, Fig. 3a)
      k(u) = (−b + m a u²/(C_r L)) / (a + m b u²/(C_f L)),
  opposite phase below u_0 = √(b C_r L/(m a)), same phase above (EV: u_0 = 12.99 m/s = 46.8 km/h).
- FEEDBACK: δ_r = −C1 δ_f + C2 u r ([P3] §2, Fig. 3b) with the measured yaw rate r (IMU_Motion).
      C1 = 1.0 ([P3]: "at very low speed rear opposite to front 1:1").
      C2 = m b/(C_f L) + m a/(C_r L)   [s²/m]   (EV: 0.018182 s²/m)
  The OCR prints C2 as "(mb/kfl)+(ma/k。1)", i.e. m b/(k_f l) + m a/(k_r l) with k the axle cornering
  stiffnesses and l the wheelbase, which is what this derivation gives: with δ_r = −δ_f + C2 u r in the §5
  steady state r = (u/L)(δ_f − δ_r)/(1 + K u²), zero sideslip (δ_r = k(u) δ_f) at every speed needs
      C2 = m b/(C_f L) + m a/(C_r L) + (a − b)/u².
  The last term vanishes for the EV (a = b = 1.38 m): the constant C2 holds β at zero "without retuning" at
  every speed, as [P3] claims; for a ≠ b (the A-class car, docs/spec/vehicles.md B) a constant C2 leaves a small
  steady sideslip that shrinks with speed. The steady yaw gain is then
      r/δ_f = (u/L)(1 + C1)/(1 + K u² + C2 u²/L)   (docs/spec/formulas.md §5).
  Without a valid IMU_Motion (never received, timed out, not finite) the law falls back to FEEDFORWARD
  (no sensor needed) rather than to −δ_f, which would double the yaw gain at speed.

All angles in degrees and rates in deg/s with the bus signs of docs/spec/formulas.md §1: the laws are odd, so they read
the same in the ISO convention of §5 (δ_r[deg] = −C1 δ_f[deg] + C2 u r[deg/s]).

The speed u of every law (and of the 20 km/h switch) is the VEHICLE's forward speed as the VCU can know it over
the bus (`VehicleSpeedEstimate`, docs/contract/vcu-4ws.md VCU-4WS-01), never |TargetSpeed|: a request says where
the car shall go, not where it is; after a step from 100 to 30 km/h, k(30 km/h) would steer the rear in opposite
phase while the car still runs at 100 km/h, the destabilising case 4WS exists to avoid.
"""

from __future__ import annotations

import math
from enum import IntEnum

from bench.node import NodeIO
from plant import signal_ranges as ranges
from plant.body import VelocityFit
from plant.vehicles import Ev4wisParams


class Strategy(IntEnum):
    """BENCH_VcuConfig.RearSteerLaw value table (dbc/bench.dbc)."""

    OFF = 0
    FEEDFORWARD = 1
    FEEDBACK = 2


DEFAULT_LAW = Strategy.FEEDFORWARD   # BENCH_VcuConfig absent (its DBC start value)
C1 = 1.0                                  # [P3] §2


class SeedLaws:
    """The three laws for one vehicle's §5 parameters (docs/spec/vehicles.md A)."""

    def __init__(self, params: Ev4wisParams) -> None:
        m, a, b = params.mass, params.cog_to_front_axle, params.cog_to_rear_axle
        cf, cr = params.cornering_stiffness_front, params.cornering_stiffness_rear
        big_l = a + b
        self._a, self._b = a, b
        self._num_gain = m * a / (cr * big_l)      # k(u) numerator: −b + m a u²/(C_r L)
        self._den_gain = m * b / (cf * big_l)      # k(u) denominator: a + m b u²/(C_f L)
        self.c1 = C1
        self.c2 = m * b / (cf * big_l) + m * a / (cr * big_l)

    def ratio(self, u: float) -> float:
        """k(u), the zero-sideslip rear/front ratio (docs/spec/formulas.md §5)."""
        u2 = u * u
        return (-self._b + self._num_gain * u2) / (self._a + self._den_gain * u2)

    def rear_angle(self, law: Strategy, front_deg: float, speed: float, yaw_rate_dps: float | None) -> float:
        """Rear-axle angle (deg) for the front-axle angle, the speed (m/s, ≥ 0) and the measured yaw rate
        (deg/s; None when not available: FEEDBACK falls back to FEEDFORWARD)."""
        if law == Strategy.OFF:
            return 0.0
        if law == Strategy.FEEDBACK and yaw_rate_dps is not None:
            return -self.c1 * front_deg + self.c2 * speed * yaw_rate_dps
        return self.ratio(speed) * front_deg


class VehicleSpeedEstimate:
    """The vehicle's forward speed (m/s) from what the VCU receives: the four WHL_Status_xx (angles and wheel
    speeds; forward component of the least-squares rigid fit, plant.body.VelocityFit) while the wheels roll,
    IMU_Motion.LongAccel integrated while they slip (docs/contract/vcu-4ws.md VCU-4WS-01).

    Why both: a speed step makes the hub motors brake (or drive) the wheels faster than the tyres can slow
    (or push) the car; the wheels then slide and their speed is no longer the car's. Rule per control task:
    predict u + LongAccel·Δt; take the wheels' value when it lies within SLIP_BAND of the prediction (rolling:
    the estimate is re-anchored to the wheels every task, so an IMU bias never accumulates), else the
    prediction (slipping). A slip ends, besides the wheels meeting the prediction again, when the wheels
    roll at a steady speed (changing less than STEADY_WHEEL_RATE) while the IMU measures no acceleration
    (|LongAccel| < STEADY_ACCEL) for RESYNC_S: a sustained slip needs a force, which would accelerate the car.
    In the first GRACE_S after a reset, without a valid IMU_Motion, or after a gap longer than MAX_GAP_S, the
    wheels' value is taken as it is. None until the four WHL_Status have arrived.
    """

    SLIP_BAND = 0.3      # m/s: wheel fit vs prediction (rolling at μ g moves WHL_Status ≤ 0.1 m/s per 10 ms; chosen)
    GRACE_S = 0.1        # s after a reset: frames from before the scenario start may still be the latest
    MAX_GAP_S = 0.05     # s: a longer gap between updates restarts from the wheels
    RESYNC_S = 0.2       # s of steady wheels and no acceleration that end a slip (chosen)
    STEADY_ACCEL = 0.5   # m/s² (chosen: well above the IMU's resolution, well below a slip's μ g)
    STEADY_WHEEL_RATE = 0.5   # m/s² of the wheels' speed (chosen, as STEADY_ACCEL)
    WHEEL_LSB = 0.01     # m/s: allowance for WHL_Status's 0.1 rpm steps (0.003 m/s) between frames

    def __init__(self, params: Ev4wisParams) -> None:
        self._fit = VelocityFit(params.geometry)
        self._status = tuple(f"WHL_Status_{c}" for c in ("FL", "FR", "RL", "RR"))
        self.reset()

    def reset(self) -> None:
        self.value: float | None = None
        self.slipping = False
        self._t: float | None = None
        self._t0: float | None = None
        self._wheels: float | None = None
        self._steady_since: float | None = None

    def wheels(self, io: NodeIO) -> float | None:
        """Forward speed of the rigid fit to the four WHL_Status_xx, m/s; None when one is missing."""
        angles, speeds = [], []
        for message in self._status:
            status = io.latest(message)
            if status is None:
                return None
            angles.append(status.get("SteerAngle", math.nan))
            speeds.append(status.get("WheelSpeed", math.nan))
        if not ranges.finite(*angles, *speeds):
            return None
        return self._fit(angles, speeds)[1]

    @staticmethod
    def long_accel(io: NodeIO) -> float | None:
        """IMU_Motion.LongAccel (m/s², positive forward); None when absent, invalid or not finite."""
        imu = io.latest("IMU_Motion")
        if imu is None or io.invalid("IMU_Motion"):
            return None
        a = imu.get("LongAccel", math.nan)
        return a if ranges.finite(a) else None

    def update(self, io: NodeIO, t: float) -> float | None:
        """Advance to bench time t (once per control task); returns the estimate."""
        if self._t0 is None:
            self._t0 = t
        wheels = self.wheels(io)
        accel = self.long_accel(io)
        previous, t_prev, wheels_prev = self.value, self._t, self._wheels
        self._t, self._wheels = t, wheels
        if wheels is None:
            return self.value                    # WHEEL_FAULT stops the car anyway; hold the last estimate
        if (previous is None or t_prev is None or wheels_prev is None or accel is None
                or t - self._t0 < self.GRACE_S or not 0.0 < t - t_prev <= self.MAX_GAP_S):
            self.value, self.slipping, self._steady_since = wheels, False, None
            return self.value
        dt = t - t_prev
        predicted = previous + accel * dt
        steady = (abs(accel) < self.STEADY_ACCEL
                  and abs(wheels - wheels_prev) < self.STEADY_WHEEL_RATE * dt + self.WHEEL_LSB)
        if not steady:
            self._steady_since = None
        elif self._steady_since is None:
            self._steady_since = t
        resync = self._steady_since is not None and t - self._steady_since >= self.RESYNC_S
        self.slipping = abs(wheels - predicted) > self.SLIP_BAND and not resync
        self.value = predicted if self.slipping else wheels
        return self.value
