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
"""

from __future__ import annotations

from enum import IntEnum

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
