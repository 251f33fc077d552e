"""The test oracle of the ABS turning-state cases ([P4], docs/spec/formulas.md §6), written independently of `plant/`.

The formulas are typed from docs/spec/formulas.md §6 and docs/spec/vehicles.md B; nothing is read from plant/.
Plain floats.
Signs as in the paper: wheels 1-4 = FL, FR, RL, RR; a left turn has V_w2 > V_w1 and V_w4 > V_w3; T = 1 left,
-1 right, 0 straight (docs/spec/formulas.md §1 keeps that exception on the bus).
"""

from __future__ import annotations

import math

KMH = 3.6
G = 9.81

# -- docs/spec/vehicles.md B (A-class car) and [P4] §4 --------------------------------------------------------------
TRACK = 1.55                 # B, m
WHEELBASE = 2.65             # L = a + b, m
HAND_WHEEL_RATIO = 18.0      # i_w of [P4]'s tests (§4): delta_f = theta / i_w
#: tyre for braking, Magic Formula (B, C, D, E): dry and wet (docs/spec/vehicles.md B)
TYRE_DRY = (10.0, 1.9, 1.0, 0.97)
TYRE_WET = (12.0, 2.3, 0.82, 1.0)

#: [P4] §4, the paper's accuracy table (docs/spec/formulas.md §6): (T, V_f error mean, max abs in km/h,
#: delta error mean, max abs in deg). Left turn, hand wheel about 180 deg, i_w = 18.
PAPER_TABLE = {
    "steady-state circular (Fig. 3-5)": (1, 0.16, 0.88, -0.56, 1.2),
    "angle step while braking under ABS (Fig. 6-8)": (1, 0.58, 1.54, -0.82, 1.29),
}


def front_wheel_angle_from_hand_wheel(hand_wheel_deg: float) -> float:
    """[P4] §4: the reference front-wheel angle delta_f = theta / i_w, deg (sign as given)."""
    return hand_wheel_deg / HAND_WHEEL_RATIO


# -- eq. 13 ------------------------------------------------------------------------------------------------

def turn_corrected(dv1: float, dv2: float, ddv: float, v_l0: float, v_l1: float, v_l2: float) -> int:
    """Eq. 13 with erratum E3 corrected (docs/spec/formulas.md §6): the ddV < V_l2 condition for both signs."""
    if v_l0 < dv1 < v_l1 and v_l0 < dv2 < v_l1 and ddv < v_l2:
        return 1
    if v_l0 < -dv1 < v_l1 and v_l0 < -dv2 < v_l1 and ddv < v_l2:
        return -1
    return 0


def turn_printed(dv1: float, dv2: float, ddv: float, v_l0: float, v_l1: float, v_l2: float) -> int:
    """Eq. 13 as printed in [P4]: the right-turn branch asks -ddV < V_l2, always true as ddV = |...| >= 0."""
    if v_l0 < dv1 < v_l1 and v_l0 < dv2 < v_l1 and ddv < v_l2:
        return 1
    if v_l0 < -dv1 < v_l1 and v_l0 < -dv2 < v_l1 and -ddv < v_l2:
        return -1
    return 0


def axle_differences(fl: float, fr: float, rl: float, rr: float) -> tuple[float, float, float]:
    """Eq. 6-8: dV1 = V_w2 - V_w1, dV2 = V_w4 - V_w3, ddV = |dV1 - dV2| (same unit as the speeds)."""
    dv1, dv2 = fr - fl, rr - rl
    return dv1, dv2, abs(dv1 - dv2)


# -- tyre (docs/spec/vehicles.md B) ----------------------------------------------------------------------------------

def magic_formula(slip: float, tyre: tuple[float, float, float, float]) -> float:
    """Friction coefficient at a longitudinal slip: D sin(C atan(B s - E (B s - atan(B s))))."""
    b, c, d, e = tyre
    bs = b * slip
    return d * math.sin(c * math.atan(bs - e * (bs - math.atan(bs))))


def mu_locked(tyre: tuple[float, float, float, float]) -> float:
    """Sliding friction of a locked wheel (slip 1)."""
    return magic_formula(1.0, tyre)


def mu_peak(tyre: tuple[float, float, float, float]) -> float:
    """Peak of the curve, by a fine scan of slip 0..1 (independent of any closed form)."""
    return max(magic_formula(i / 10000.0, tyre) for i in range(1, 10001))


def locked_stopping_distance(speed: float, tyre: tuple[float, float, float, float]) -> float:
    """Distance (m) four locked wheels need from `speed` (m/s): v^2 / (2 g mu_locked)."""
    return speed * speed / (2.0 * G * mu_locked(tyre))
