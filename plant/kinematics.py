"""Kinematics of the 4WIS EV: rotation about a point (docs/spec/formulas.md §2) and Ackermann (§3 there).

Pure functions on plain floats (they run every plant tick). Frame and signs: docs/spec/formulas.md §1 ([P0]
§2.1): origin at the geometric centre, +x right, +y forward; wheels FL (-K, L), FR (K, L), RL (-K, -L),
RR (K, -L); every angle 0 along +y and positive clockwise (to the right); v_o > 0 turns the vehicle
clockwise about the centre S = (x, y).

Road-wheel angles are returned in (-90°, +90°]: the paper's "denominator 0 and numerator negative ->
-90°" (eq. 1-4) is the same wheel pose as +90° rolling backwards, and docs/spec/formulas.md §1 fixes the range,
so that case is reported as +90° with the wheel speed negated (the physical command is identical).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

CORNERS: tuple[str, str, str, str] = ("FL", "FR", "RL", "RR")

#: A centre closer than this to the origin or to a wheel is treated as being on it (undefined request).
CENTRE_TOLERANCE_M = 0.01

_DEG = 180.0 / math.pi
_HALF_PI = math.pi / 2.0


@dataclass(frozen=True, slots=True)
class Geometry:
    """The wheel layout of [P0] §2.1: K = half the track, L = half the wheelbase, r = wheel radius."""

    half_track: float
    half_wheelbase: float
    wheel_radius: float

    @property
    def wheel_positions(self) -> tuple[tuple[float, float], ...]:
        """Contact points (= steering axes, [P0] §1.1) in CORNERS order."""
        k, half_l = self.half_track, self.half_wheelbase
        return ((-k, half_l), (k, half_l), (-k, -half_l), (k, -half_l))

    @property
    def rpm_per_mps(self) -> float:
        """[P0] eq. 6: n = 30 v / (pi r)."""
        return 30.0 / (math.pi * self.wheel_radius)


class Undefined(IntEnum):
    """Requests §2 cannot serve (numbers equal VCU_VehicleState.VcuFault's)."""

    CENTRE_AT_ORIGIN = 1   # r_o = 0 with v_o != 0: v_o / r_o undefined (a spin needs a yaw rate instead)
    CENTRE_ON_WHEEL = 2    # r_i = 0: that wheel's angle is undefined
    ANGLE_OVER_90 = 3      # a car-like mode would need a wheel beyond ±90° (see classify_centre)


def _heading(num: float, den: float) -> tuple[float, float]:
    """Angle (deg, in (-90, 90]) and speed factor of a point whose velocity is Omega * (num, den).

    [P0] eq. 1-4: beta = atan(num / den), den = 0 -> ±90°. The speed factor is the velocity's
    projection on the wheel heading per unit Omega: den / cos(beta) = sign(den) * hypot(num, den)
    (eq. 7-10), and num at den = 0.
    """
    if den != 0.0:
        angle = math.atan(num / den) * _DEG
        factor = math.copysign(math.hypot(num, den), den)
    else:
        angle, factor = 90.0, num
    if angle <= -90.0:          # atan overflowed to -90°: fold to +90°, rolling the other way
        angle, factor = 90.0, -factor
    return angle + 0.0, factor  # + 0.0: no -0.0 on the bus


def rotation(x: float, y: float, v_o: float, g: Geometry) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Wheel angles (deg) and wheel speeds (rpm) for a rotation about S = (x, y) at centre speed v_o.

    docs/spec/formulas.md §2, [P0] eq. 1-4 and 7-10 with erratum E1 corrected (the paper prints x + K
    for the right-rear wheel; geometry gives x - K):
        beta_i = atan((y_i - y) / (x - x_i))               beta1 = atan((L - y)/(x + K)) ...
        n_i = 30 v_o (x - x_i) / (pi r r_o cos beta_i)     n4 = 30 v_o (x - K)/(pi r r_o cos beta4)
    A centre between the wheels of one axle folds the angle into (-90°, 90°] and reverses that wheel
    (the sign of x - x_i does it). Raises ValueError for the undefined cases (classify_centre first).
    """
    r_o = math.hypot(x, y)
    if r_o == 0.0:
        if v_o != 0.0:
            raise ValueError("rotation centre at the origin with non-zero speed: v_o / r_o undefined")
        omega = 0.0
    else:
        omega = v_o / r_o
    n_per_v = g.rpm_per_mps
    angles: list[float] = []
    speeds: list[float] = []
    for px, py in g.wheel_positions:
        num, den = py - y, x - px
        if num == 0.0 and den == 0.0:
            raise ValueError(f"rotation centre ({x}, {y}) on the wheel at ({px}, {py}): angle undefined")
        angle, factor = _heading(num, den)
        angles.append(angle)
        speeds.append(omega * factor * n_per_v + 0.0)
    return tuple(angles), tuple(speeds)


def yaw_rate(x: float, y: float, v_o: float) -> float:
    """Yaw rate (deg/s, positive clockwise) of a rotation about (x, y): v_o / r_o ([P0] eq. 5); 0 at r_o = 0."""
    r_o = math.hypot(x, y)
    return v_o / r_o * _DEG if r_o > 0.0 else 0.0


def classify_centre(x: float, y: float, v_o: float, g: Geometry, *, forward_only: bool = False,
                    tol: float = CENTRE_TOLERANCE_M) -> Undefined | None:
    """Why a rotation about (x, y) cannot be commanded, or None when it can (docs/spec/formulas.md §2, undefined cases).

    - CENTRE_AT_ORIGIN: |S| < tol with v_o != 0 (with v_o = 0 the spin-in-place angles are defined).
    - CENTRE_ON_WHEEL: S within tol of a contact point, whatever v_o.
    - ANGLE_OVER_90, only with forward_only (the car-like modes NORMAL and ADAPTIVE, where every wheel
      must roll forward when the vehicle does): S strictly between the wheels of an axle, |x| < K. There
      the inner wheels would have to point beyond ±90° to roll forward; §2's fold would reverse them
      instead, which a car-like mode must not do. In PIVOT the fold is legitimate and never a fault.
    Inputs must be finite.
    """
    if v_o != 0.0 and math.hypot(x, y) < tol:
        return Undefined.CENTRE_AT_ORIGIN
    for px, py in g.wheel_positions:
        if math.hypot(x - px, y - py) < tol:
            return Undefined.CENTRE_ON_WHEEL
    if forward_only and abs(x) < g.half_track:
        return Undefined.ANGLE_OVER_90
    return None


# -- Ackermann and the curvature angle (docs/spec/formulas.md §3, [P2]) --------------------------------------

def curvature_angle(x: float, y: float, g: Geometry) -> float:
    """[P2]'s curvature angle X (deg): the heading of the front-axle centre (0, L) rotating about (x, y).

    tan X = (L - y) / x, folded into (-90°, 90°] like a wheel angle. For a centre on the rear-axle line
    this is the angle between C-O and the rear axle of [P2] §2. A centre exactly at the front-axle
    centre leaves that point still: no heading, reported as 0.
    """
    num = g.half_wheelbase - y
    if x == 0.0 and num == 0.0:
        return 0.0
    return _heading(num, x)[0]


def centre_x_on_rear_axle(curvature_deg: float, g: Geometry) -> float | None:
    """NORMAL: x of the centre on y = -L whose curvature angle is X: x = 2L / tan X; None when straight.

    [P2] §2/§4 (the centre lies on the rear-axle line). |X| must be below 90°.
    """
    if curvature_deg == 0.0:
        return None
    return 2.0 * g.half_wheelbase / math.tan(math.radians(curvature_deg))


def centre_x_on_mid_axle(curvature_deg: float, g: Geometry) -> float | None:
    """ADAPTIVE at low speed: x of the centre on y = 0 whose curvature angle is X: x = L / tan X; None when straight.

    [P0] §3 (the 4WS U-turn: rear angles mirror the front). |X| must be below 90°.
    """
    if curvature_deg == 0.0:
        return None
    return g.half_wheelbase / math.tan(math.radians(curvature_deg))


def centre_from_axle_angles(front_deg: float, rear_deg: float, g: Geometry) -> tuple[float, float] | None:
    """The one centre about which the front-axle centre heads at front_deg and the rear-axle centre at rear_deg.

    Intersection of the normals at (0, L) and (0, -L): tan F = (L - y)/x, tan R = (-L - y)/x, so
    x = 2L / (tan F - tan R), y = L - x tan F. None when the headings are parallel (a translation:
    straight ahead or crab). Rear = 0 gives NORMAL's centre on y = -L, rear = -front the centre on y = 0.
    """
    tf, tr = math.tan(math.radians(front_deg)), math.tan(math.radians(rear_deg))
    if tf == tr:
        return None
    x = 2.0 * g.half_wheelbase / (tf - tr)
    return x, g.half_wheelbase - x * tf


def ackermann_front(curvature_deg: float, g: Geometry) -> tuple[float, float]:
    """Outer and inner front-wheel angle magnitudes (deg) for curvature angle X, centre on the rear axle.

    [P2] §4 in §2's symbols (2K track, 2L wheelbase): 1/tan(beta) - 1/tan(X) = K/(2L) for the outer
    wheel, 1/tan(X) - 1/tan(alpha) = K/(2L) for the inner one. 0 < |X| < atan(2L/K) (inner below 90°).
    """
    cot_x = 1.0 / math.tan(math.radians(abs(curvature_deg)))
    d = g.half_track / (2.0 * g.half_wheelbase)
    outer = math.degrees(math.atan(1.0 / (cot_x + d)))
    inner = math.degrees(math.atan2(1.0, cot_x - d))
    return outer, inner


def translation(angle_deg: float, speed: float, g: Geometry) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Every wheel at one angle and one speed: the rotation centre at infinity (straight, crab, LATERAL)."""
    n = speed * g.rpm_per_mps + 0.0
    a = angle_deg + 0.0
    return (a, a, a, a), (n, n, n, n)
