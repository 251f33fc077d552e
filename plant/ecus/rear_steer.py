"""[P3] §2's rear-steering laws for the reference VCU's ADAPTIVE mode above its low-speed range.

Selected by the VCU's diagnostic coding RearSteerLaw (DID 0xFDC0, dbc/diagnostics.toml, docs/contract/vcu.md
VCU-DIAG-02), which a tester writes with WriteDataByIdentifier; a real VCU has the same coding (FEEDFORWARD
required, OFF and FEEDBACK optional, docs/contract/vcu-4ws.md VCU-4WS-10):

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

from bench.sim.node import NodeIO
from plant import signal_ranges as ranges
from plant.body import VelocityFit
from plant.vehicles import Ev4wisParams


class Strategy(IntEnum):
    """The coding DID RearSteerLaw's value table (dbc/diagnostics.toml, docs/contract/vcu.md VCU-DIAG-02)."""

    OFF = 0
    FEEDFORWARD = 1
    FEEDBACK = 2


DEFAULT_LAW = Strategy.FEEDFORWARD   # the coding's default (dbc/diagnostics.toml); also without diagnostics
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
    speeds; forward component w of the least-squares rigid fit, plant.body.VelocityFit) while the wheels roll,
    IMU_Motion.LongAccel a integrated while they slip. It is the informative estimator of
    docs/contract/vcu-4ws.md VCU-4WS-01 as written there (band B, slide acceleration A, confirmation time T_c,
    step limit D; rules 1-6), so the reference VCU meets the requirement's convergence after a restart without
    knowing that a scenario started (its reset only makes the estimate undefined again, as at power-up).

    Rule per control task: 1. undefined, no valid IMU_Motion or a gap > MAX_GAP_S: take w. Else predict
    p = u + a·Δt, e = w − p: 3. |e| ≤ B: follow the wheels, at most D away from p per task; 4. the wheels slide
    the way the IMU pushes the car (e < −B with a ≤ −A, e > B with a ≥ A): p; 5. the wheels lie beyond the band
    on the side the IMU excludes (e > B with a ≤ −A, e < −B with a ≥ A: a restart, a slide's end): take w;
    6. otherwise (|a| < A) keep p until the disagreement has lasted T_c, then take w. None until the four
    WHL_Status have arrived.
    """

    BAND = 0.3           # m/s: B
    SLIDE_ACCEL = 1.5    # m/s²: A
    CONFIRM_S = 0.03     # s: T_c (the IMU's lag of up to 10 ms plus two of its 10 ms cycles)
    STEP = 0.05          # m/s per task: D
    MAX_GAP_S = 0.05     # s: a longer gap between tasks restarts from the wheels (rule 1)

    def __init__(self, params: Ev4wisParams) -> None:
        self._fit = VelocityFit(params.geometry)
        self._status = tuple(f"WHL_Status_{c}" for c in ("FL", "FR", "RL", "RR"))
        self.reset()

    def reset(self) -> None:
        self.value: float | None = None
        self._t: float | None = None
        self._disagree_since: float | None = None

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
        """IMU_Motion.LongAccel (m/s², positive forward); None when absent, timed out, invalid, not finite or at
        its range end (±30 m/s², imu.md: clamped there, so it bounds the acceleration but does not measure it;
        the plant's kinematic body spins up faster than that from standstill, with the wheels rolling)."""
        imu = io.latest("IMU_Motion")
        if imu is None or io.invalid("IMU_Motion"):
            return None
        a = imu.get("LongAccel", math.nan)
        return a if ranges.finite(a) and ranges.IMU_ACCEL[0] < a < ranges.IMU_ACCEL[1] else None

    def update(self, io: NodeIO, t: float) -> float | None:
        """Advance to bench time t (once per control task); returns the estimate."""
        w = self.wheels(io)
        a = self.long_accel(io)
        u, t_prev = self.value, self._t
        self._t = t
        if w is None:
            return self.value                    # WHEEL_FAULT stops the car anyway; hold the last estimate
        if u is None or a is None or t_prev is None or not 0.0 < t - t_prev <= self.MAX_GAP_S:   # rule 1
            self.value, self._disagree_since = w, None
            return w
        p = u + a * (t - t_prev)                                                                # rule 2
        e = w - p
        band, accel = self.BAND, self.SLIDE_ACCEL
        if abs(e) <= band:                                                                      # rule 3
            self.value, self._disagree_since = p + max(-self.STEP, min(self.STEP, e)), None
        elif (e < -band and a <= -accel) or (e > band and a >= accel):                          # rule 4
            self.value, self._disagree_since = p, None
        elif (e > band and a <= -accel) or (e < -band and a >= accel):                          # rule 5
            self.value, self._disagree_since = w, None
        else:                                                                                   # rule 6
            if self._disagree_since is None:
                self._disagree_since = t
            if t - self._disagree_since >= self.CONFIRM_S - 1e-9:
                self.value, self._disagree_since = w, None
            else:
                self.value = p
        return self.value
