"""The test oracle of the 4WIS EV: the papers' formulas, written independently of `plant/`.

Every expected value of the 4WIS test cases comes from here. Nothing is read from `plant/`: the
vehicle numbers are written below with their source, the formulas are typed from the formula sheet
(`docs/spec/formulas.md`, "§n" below) and the papers it cites (`docs/spec/references.md`). Plain floats, no bench.

Frame and signs (§1, [P0] §2.1): origin at the geometric centre, +x right, +y forward; wheels
FL (-K, L), FR (K, L), RL (-K, -L), RR (K, -L); every angle 0 along +y, positive to the right
(clockwise seen from above); road-wheel angles on the bus in (-90°, +90°]; positive rpm drives a wheel
toward +y when its angle is 0; v_o > 0 turns the vehicle clockwise about the centre S = (x, y).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# -- vehicle (docs/spec/vehicles.md A) ---------------------------------------------------------------------------
TRACK = 1.11             # 2K, m: track between the steering pivots (docs/spec/vehicles.md A; [P0] §3)
WHEELBASE = 2.76         # 2L, m (docs/spec/vehicles.md A; [P0] §3)
WHEEL_RADIUS = 0.281     # r, m (docs/spec/vehicles.md A; [P0] §3)
HAND_WHEEL_RATIO = 15.0  # hand wheel : curvature angle X in NORMAL (docs/spec/vehicles.md A, "chosen"); the VCU
                         # contract uses the same ratio in ADAPTIVE (docs/contract/vcu.md VCU-MODE-05)
K = TRACK / 2.0          # half track, m
L = WHEELBASE / 2.0      # half wheelbase, m

WHEELS: tuple[str, ...] = ("FL", "FR", "RL", "RR")
#: contact points = steering axes ([P0] §2.1, Fig. 4: A (-K, L), B (K, L), C (-K, -L), D (K, -L))
WHEEL_POSITION: dict[str, tuple[float, float]] = {"FL": (-K, L), "FR": (K, L), "RL": (-K, -L), "RR": (K, -L)}

# -- bus resolutions (dbc/chassis.dbc), so that requests are sent exactly -------------------------------
PIVOT_RESOLUTION = 0.02       # m, DRV_MotionRequest.PivotX/PivotY
HAND_WHEEL_RESOLUTION = 0.1   # deg, DRV_Steering.HandWheelAngle

_DEG = 180.0 / math.pi


@dataclass(frozen=True)
class WheelTarget:
    """What §2 asks of one wheel: angle on the bus (deg, (-90, 90]) and speed (rpm, signed)."""

    angle: float
    rpm: float


def rpm_from_speed(v: float) -> float:
    """[P0] eq. 6: v = r · n · 2π/60, so n = 30 v / (π r)."""
    return 30.0 * v / (math.pi * WHEEL_RADIUS)


def speed_from_rpm(n: float) -> float:
    """Eq. 6 inverted: circumferential speed of a wheel, m/s."""
    return n * math.pi * WHEEL_RADIUS / 30.0


def on_grid(value: float, resolution: float) -> bool:
    """True when a physical value is exactly one raw step of the DBC (the bus carries it unchanged)."""
    return abs(value / resolution - round(value / resolution)) < 1e-9


# -- §2: rotation about an arbitrary point ([P0] eq. 1-10) ------------------------------------------

def paper_angle(x: float, y: float, wheel: str) -> float:
    """[P0] eq. 1-4 as printed: β = atan(numerator / denominator), deg, in [-90, 90].

        β1 = atan((L - y)/(x + K))   β2 = atan((L - y)/(x - K))
        β3 = atan((-L - y)/(x + K))  β4 = atan((-L - y)/(x - K))
    Denominator 0: +90° if the numerator is positive, -90° if negative ([P0] below eq. 4).
    """
    num, den = _num_den(x, y, wheel)
    if den == 0.0:
        if num == 0.0:
            raise ValueError(f"centre ({x}, {y}) on wheel {wheel}: angle undefined (§2)")
        return 90.0 if num > 0.0 else -90.0
    return math.atan(num / den) * _DEG


def _num_den(x: float, y: float, wheel: str) -> tuple[float, float]:
    numerator = {"FL": L - y, "FR": L - y, "RL": -L - y, "RR": -L - y}[wheel]
    denominator = {"FL": x + K, "FR": x - K, "RL": x + K, "RR": x - K}[wheel]
    return numerator, denominator


def paper_rpm(x: float, y: float, v_o: float, wheel: str, *, erratum_e1_corrected: bool = True) -> float:
    """[P0] eq. 7-10: n_i = 30 v_o (x ± K) / (π r r_o cos β_i), rpm, for the paper's angle β_i.

    The factor (x ± K) is the denominator of eq. 1-4 (x + K for the left wheels, x - K for the right ones).
    Erratum E1 (§2): eq. 10 prints x + K for RR; `erratum_e1_corrected=False` gives the printed formula.
    At a zero denominator (β = ±90°) the quotient (x ± K)/cos β is 0/0; its limit along the paper's sign
    rule is the wheel's turning radius |numerator| (the wheel rolls toward the angle the paper gives).
    """
    r_o = math.hypot(x, y)
    if r_o == 0.0:
        raise ValueError("centre at the origin: v_o / r_o undefined (§2)")
    num, den = _num_den(x, y, wheel)
    beta = math.radians(paper_angle(x, y, wheel))
    factor = abs(num) if den == 0.0 else den / math.cos(beta)
    if wheel == "RR" and not erratum_e1_corrected:
        factor = (x + K) / math.cos(beta) if den != 0.0 else math.nan   # eq. 10 as printed
    return 30.0 * v_o * factor / (math.pi * WHEEL_RADIUS * r_o)


def rotation_targets(x: float, y: float, v_o: float) -> dict[str, WheelTarget]:
    """§2 for every wheel, E1 corrected, in the bus convention of §1.

    The paper's -90° (zero denominator, negative numerator) is outside §1's (-90°, +90°]: the same wheel
    pose is +90° rolling the other way, so the angle becomes +90° and the speed is negated. A centre
    between the wheels of an axle needs no special case: the sign of (x ± K) already reverses that wheel
    (§2, "fold the angle and reverse that wheel").
    """
    out = {}
    for wheel in WHEELS:
        angle, n = paper_angle(x, y, wheel), paper_rpm(x, y, v_o, wheel)
        if angle == -90.0:
            angle, n = 90.0, -n
        out[wheel] = WheelTarget(angle + 0.0, n + 0.0)
    return out


def translation_targets(angle: float, v: float) -> dict[str, WheelTarget]:
    """Centre at infinity (§2 special cases): every wheel at one angle, one speed (eq. 6)."""
    return {w: WheelTarget(angle, rpm_from_speed(v)) for w in WHEELS}


def yaw_rate(x: float, y: float, v_o: float) -> float:
    """[P0] eq. 5: ω = v_o / r_o, deg/s, positive clockwise."""
    return v_o / math.hypot(x, y) * _DEG


def curvature_angle(x: float, y: float) -> float | None:
    """[P2]'s curvature angle X (DBC: a virtual wheel at the front-axle centre (0, L) about S), deg.

    Eq. 1-4 for a wheel at (0, L): atan((L - y)/x), in the bus range (-90°, +90°]. None when S is the
    front-axle centre itself (that point does not move: no heading).
    """
    num, den = L - y, x
    if den == 0.0:
        if num == 0.0:
            return None
        return 90.0
    return math.atan(num / den) * _DEG


# -- drive modes (docs/spec/vehicles.md A, docs/spec/k-matrix.md) ------------------------------------------------------

def curvature_from_hand_wheel(hand_wheel: float) -> float:
    """X = HandWheelAngle / ratio (docs/spec/vehicles.md A), deg."""
    return hand_wheel / HAND_WHEEL_RATIO


def normal_centre(hand_wheel: float) -> tuple[float, float] | None:
    """NORMAL: centre on the rear-axle line y = -L (§2 special cases) whose curvature angle is X.

    tan X = (L - y)/x = 2L/x ([P2] §2), so x = 2L / tan X. None when straight (X = 0).
    """
    x_deg = curvature_from_hand_wheel(hand_wheel)
    if x_deg == 0.0:
        return None
    return WHEELBASE / math.tan(math.radians(x_deg)), -L


def adaptive_centre(hand_wheel: float) -> tuple[float, float] | None:
    """ADAPTIVE at low speed: centre on y = 0 (§2: "low-speed 4WS U-turn = centre on y = 0", [P0] §3).

    tan X = (L - 0)/x, so x = L / tan X. None when straight.
    """
    x_deg = curvature_from_hand_wheel(hand_wheel)
    if x_deg == 0.0:
        return None
    return L / math.tan(math.radians(x_deg)), 0.0


def forward_v_o(centre_x: float, v: float) -> float:
    """NORMAL/ADAPTIVE: TargetSpeed v is positive forward (docs/spec/k-matrix.md). A forward drive about a centre on
    the right (x > 0) is clockwise, so v_o = v; about a centre on the left it is counter-clockwise, v_o = -v."""
    return v if centre_x > 0.0 else -v


def car_mode_targets(centre: tuple[float, float] | None, v: float) -> dict[str, WheelTarget]:
    """Wheels of NORMAL or ADAPTIVE for a centre (None = straight ahead) and a forward speed v."""
    if centre is None:
        return translation_targets(0.0, v)
    return rotation_targets(centre[0], centre[1], forward_v_o(centre[0], v))


def lateral_targets(v: float) -> dict[str, WheelTarget]:
    """LATERAL: every wheel at +90° with one signed speed (eq. 6); positive v = to the right (docs/spec/k-matrix.md).

    At +90° positive rpm rolls a wheel toward +x. Moving left (v < 0) is the same +90° with negative rpm:
    road-wheel angles lie in (-90°, +90°] (docs/spec/formulas.md §1), so the paper's -90° is not a bus angle
    (docs/contract/vcu.md VCU-MODE-08)."""
    return translation_targets(90.0, v)


# -- §3: Ackermann and the curvature angle ([P2]) ---------------------------------------------------

def ackermann_front(x_deg: float) -> tuple[float, float]:
    """Outer and inner front-wheel angle magnitudes (deg) for curvature angle X, centre on the rear axle.

    [P2] in its own symbols (K = full track, L = full wheelbase):
        1/tan β - 1/tan X = K/(2L)   (outer, β)        1/tan X - 1/tan α = K/(2L)   (inner, α)
    """
    cot_x = 1.0 / math.tan(math.radians(abs(x_deg)))
    d = TRACK / (2.0 * WHEELBASE)
    return math.degrees(math.atan(1.0 / (cot_x + d))), math.degrees(math.atan2(1.0, cot_x - d))


def ackermann_residual(outer_deg: float, inner_deg: float, k_over_l: float) -> float:
    """1/tan β - 1/tan α - K/L ([P2]): 0 when the two front angles satisfy Ackermann."""
    return 1.0 / math.tan(math.radians(abs(outer_deg))) - 1.0 / math.tan(math.radians(abs(inner_deg))) - k_over_l


def ackermann_residual_tolerance(outer_deg: float, inner_deg: float, angle_tol_deg: float) -> float:
    """How far the residual may move when each angle is off by angle_tol_deg: d(cot β)/dβ = -1/sin²β."""
    t = math.radians(angle_tol_deg)
    return t / math.sin(math.radians(abs(outer_deg))) ** 2 + t / math.sin(math.radians(abs(inner_deg))) ** 2


def outer_front_speed_geometric(v_outer_rear: float, outer_deg: float) -> float:
    """§3: V_b = V_d / cos β (outer front from outer rear), the geometry."""
    return v_outer_rear / math.cos(math.radians(outer_deg))


def outer_front_speed_printed_e2(v_outer_rear: float, outer_deg: float) -> float:
    """Erratum E2 ([P2] §4) as printed: V_b = V_d × cos β."""
    return v_outer_rear * math.cos(math.radians(outer_deg))


def inner_front_speed(v_outer_front: float, outer_deg: float, inner_deg: float) -> float:
    """§3: V_a = V_b · sin β / sin α."""
    return v_outer_front * math.sin(math.radians(abs(outer_deg))) / math.sin(math.radians(abs(inner_deg)))


# -- rigid body, no paper (§2 "independent check") ------------------------------------------------------

def rigid_velocity(point: tuple[float, float], centre: tuple[float, float], omega_cw: float) -> tuple[float, float]:
    """Velocity (m/s) of a body point for a rotation about `centre` at omega_cw (rad/s, clockwise positive).

    ω × (P - S) with ω = -omega_cw ẑ (clockwise seen from above, +x right, +y forward, z up):
    (-ω ẑ) × (dx, dy, 0) = ω (dy, -dx).
    """
    dx, dy = point[0] - centre[0], point[1] - centre[1]
    return omega_cw * dy, -omega_cw * dx


def heading_vector(angle_deg: float) -> tuple[float, float]:
    """Unit vector a wheel rolls along for positive rpm: 0° = +y, positive clockwise (toward +x)."""
    a = math.radians(angle_deg)
    return math.sin(a), math.cos(a)


def angle_between(u: tuple[float, float], w: tuple[float, float]) -> float:
    """Unsigned angle between two vectors, deg, in [0, 180]."""
    return math.degrees(math.atan2(abs(u[0] * w[1] - u[1] * w[0]), u[0] * w[0] + u[1] * w[1]))


# -- U-turn ([P0] §3, docs/spec/formulas.md §2 "U-turn experiment") -------------------------------------------

PAPER_UTURN = {
    #         FL     FR     RL    RR    max trajectory width (m)
    "NORMAL": (-38.0, -31.0, 0.0, 0.0, 10.3),
    "ADAPTIVE": (-37.0, -25.0, 37.0, 25.0, 6.3),
}
PAPER_WIDTH_RATIO = 0.61          # 6.3 / 10.3 as the formula sheet states it
LANE_WIDTH = 3.5                  # m ([P0] §3: a two-way four-lane road)
MEDIAN_WIDTH = 1.0                # m


def uturn_centre_from_fl(mode: str, fl_deg: float) -> tuple[float, float]:
    """The centre that puts FL at fl_deg: NORMAL on y = -L, ADAPTIVE on y = 0 (docs/spec/formulas.md §2).

    Eq. 1: tan β1 = (L - y)/(x + K), so x = (L - y)/tan β1 - K.
    """
    y = -L if mode == "NORMAL" else 0.0
    return (L - y) / math.tan(math.radians(fl_deg)) - K, y


def hand_wheel_for_centre(mode: str, centre: tuple[float, float]) -> float:
    """The hand-wheel angle whose curvature angle puts the centre there (inverse of normal/adaptive_centre)."""
    x, y = centre
    return HAND_WHEEL_RATIO * math.degrees(math.atan((L - y) / x))


def arc_width_across(point: tuple[float, float], centre: tuple[float, float], turn_deg: float) -> float:
    """Extent in x of the arc a body point draws while the body turns turn_deg about a fixed centre.

    Counter-clockwise for turn_deg < 0 (a left U-turn), in the start frame; the analytic width the
    simulated trajectory is compared with in the report (no check rests on it).
    """
    dx, dy = point[0] - centre[0], point[1] - centre[1]
    radius, a0 = math.hypot(dx, dy), math.atan2(dy, dx)
    angles = [a0 - math.radians(turn_deg) * i / 3600 for i in range(3601)]   # ccw: polar angle grows
    xs = [centre[0] + radius * math.cos(a) for a in angles]
    return max(xs) - min(xs)


def body_to_world(point: tuple[float, float], position: tuple[float, float], heading_deg: float) -> tuple[float, float]:
    """A body-frame point in the start frame, for a body at `position` with heading (0 = +y, clockwise +).

    The body's +y axis is (sin h, cos h) in the start frame and its +x axis (cos h, -sin h).
    """
    h = math.radians(heading_deg)
    bx, by = point
    return (position[0] + bx * math.cos(h) + by * math.sin(h),
            position[1] - bx * math.sin(h) + by * math.cos(h))
