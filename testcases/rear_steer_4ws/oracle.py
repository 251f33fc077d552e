"""Test oracle of the four-wheel-steering cases ([P3] §2, docs/spec/formulas.md §5): closed forms and course
geometry, written here independently of `plant/` (own numbers typed from docs/spec/vehicles.md, own formulas).

Signs: docs/spec/formulas.md §5 is ISO left-positive; every formula below is odd in the angles and rates, so it holds
unchanged in the bus convention of §1 (positive to the right) with every angle, rate and acceleration flipped
together, which is how the cases use it. Units SI (rad, rad/s) unless a name says deg.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Vehicle:
    """The linear 2-DOF model's numbers (docs/spec/formulas.md §5): mass m, yaw inertia I_z, CoG to front/rear axle a/b,
    axle cornering stiffnesses C_f/C_r, hand-wheel ratio."""

    name: str
    m: float
    iz: float
    a: float
    b: float
    cf: float
    cr: float
    ratio: float

    @property
    def wheelbase(self) -> float:
        return self.a + self.b


#: docs/spec/vehicles.md A (the 4WIS EV): CoG at the geometric centre, a = b = 2L/2 = 1.38 m; ratio 15 (NORMAL and the
#: reference VCU's ADAPTIVE front angle).
EV = Vehicle("EV4WIS", 900.0, 1100.0, 1.38, 1.38, 45000.0, 55000.0, 15.0)
#: docs/spec/vehicles.md B (the A-class car).
ACLASS = Vehicle("ACLASS", 1350.0, 2050.0, 1.06, 1.59, 85000.0, 120000.0, 15.0)

C1 = 1.0   # [P3] §2: rear opposite to front 1:1 at very low speed


def kmh(u: float) -> float:
    return u * 3.6


def mps(speed_kmh: float) -> float:
    return speed_kmh / 3.6


# -- docs/spec/formulas.md §5 ---------------------------------------------------------------------------------------

def stability_factor(v: Vehicle) -> float:
    """K_s = m/L² (b/C_f − a/C_r), s²/m²."""
    return v.m / v.wheelbase ** 2 * (v.b / v.cf - v.a / v.cr)


def characteristic_speed(v: Vehicle) -> float:
    """u_ch = 1/√K_s, m/s (understeer)."""
    return 1.0 / math.sqrt(stability_factor(v))


def zero_sideslip_ratio(v: Vehicle, u: float) -> float:
    """k(u) = (−b + m a u²/(C_r L)) / (a + m b u²/(C_f L))."""
    big_l = v.wheelbase
    return (-v.b + v.m * v.a * u * u / (v.cr * big_l)) / (v.a + v.m * v.b * u * u / (v.cf * big_l))


def sign_change_speed(v: Vehicle) -> float:
    """u_0 = √(b C_r L/(m a)), m/s: k(u_0) = 0."""
    return math.sqrt(v.b * v.cr * v.wheelbase / (v.m * v.a))


def c2(v: Vehicle) -> float:
    """The feedback gain C2 = m b/(C_f L) + m a/(C_r L), s²/m ([P3]'s garbled "(mb/kfl)+(ma/k。1)" read as
    m b/(k_f l) + m a/(k_r l)). Derivation: with δ_r = −C1 δ_f + C2 u r and the steady state
    r = (u/L)(δ_f − δ_r)/(1 + K u²), zero sideslip (δ_r = k(u) δ_f) needs C2 = m b/(C_f L) + m a/(C_r L) +
    (a − b)/u²; the last term is 0 for the EV (a = b), so this C2 zeroes its sideslip at every speed."""
    big_l = v.wheelbase
    return v.m * v.b / (v.cf * big_l) + v.m * v.a / (v.cr * big_l)


def steady_state(v: Vehicle, u: float, delta_f: float, delta_r: float) -> tuple[float, float]:
    """(β, r) of the §5 equations with β̇ = ṙ = 0, solved by hand:
        r = (u/L)(δ_f − δ_r)/(1 + K u²)
        β = [(b − m a u²/(C_r L)) δ_f + (a + m b u²/(C_f L)) δ_r] / (L (1 + K u²))."""
    big_l = v.wheelbase
    den = 1.0 + stability_factor(v) * u * u
    r = u / big_l * (delta_f - delta_r) / den
    beta = ((v.b - v.m * v.a * u * u / (v.cr * big_l)) * delta_f
            + (v.a + v.m * v.b * u * u / (v.cf * big_l)) * delta_r) / (big_l * den)
    return beta, r


def yaw_gain_2ws(v: Vehicle, u: float) -> float:
    """r/δ_f = (u/L)/(1 + K u²), 1/s."""
    return u / v.wheelbase / (1.0 + stability_factor(v) * u * u)


def yaw_gain_feedforward(v: Vehicle, u: float) -> float:
    """r/δ_f with δ_r = k(u) δ_f: (u/L)(1 − k(u))/(1 + K u²), 1/s."""
    return yaw_gain_2ws(v, u) * (1.0 - zero_sideslip_ratio(v, u))


def yaw_gain_feedback(v: Vehicle, u: float, c1: float = C1, gain_c2: float | None = None) -> float:
    """r/δ_f with δ_r = −C1 δ_f + C2 u r: (u/L)(1 + C1)/(1 + K u² + C2 u²/L), 1/s (docs/spec/formulas.md §5)."""
    g = c2(v) if gain_c2 is None else gain_c2
    return u / v.wheelbase * (1.0 + c1) / (1.0 + stability_factor(v) * u * u + g * u * u / v.wheelbase)


def sideslip_gain_2ws(v: Vehicle, u: float) -> float:
    """β/δ_f of the 2WS car in steady state."""
    return steady_state(v, u, 1.0, 0.0)[0]


def yaw_gain(v: Vehicle, strategy: str, u: float) -> float:
    """Steady r/δ_f (1/s) of a strategy: "2WS", "FEEDFORWARD" or "FEEDBACK"."""
    return {"2WS": yaw_gain_2ws, "FEEDFORWARD": yaw_gain_feedforward, "FEEDBACK": yaw_gain_feedback}[strategy](v, u)


# -- rotation about a point (docs/spec/formulas.md §2), for the common centre of the four wheels ---------------------

EV_HALF_TRACK = 1.11 / 2.0       # K, m (docs/spec/vehicles.md A)
EV_HALF_WHEELBASE = 2.76 / 2.0   # L (§2's half wheelbase), m
EV_WHEELS = {"FL": (-EV_HALF_TRACK, EV_HALF_WHEELBASE), "FR": (EV_HALF_TRACK, EV_HALF_WHEELBASE),
             "RL": (-EV_HALF_TRACK, -EV_HALF_WHEELBASE), "RR": (EV_HALF_TRACK, -EV_HALF_WHEELBASE)}


def wheel_angle_about(centre_x: float, centre_y: float, wheel: str) -> float:
    """§2 eq. 1-4: β_i = atan((y_i − y)/(x − x_i)), deg (the centre on the bus, body frame of §1)."""
    px, py = EV_WHEELS[wheel]
    return math.degrees(math.atan((py - centre_y) / (centre_x - px)))


# -- ISO 7401 metrics --------------------------------------------------------------------------------------

def response_time(t: list[float] | tuple[float, ...], y: list[float] | tuple[float, ...], t_input: float,
                  steady: float, fraction: float = 0.9) -> float:
    """ISO 7401 response time: from the input's 50 % point t_input to the first time y reaches `fraction` of
    its steady value (linear interpolation between samples); NaN when it never does."""
    target = fraction * steady
    previous_t, previous_y = None, None
    for ti, yi in zip(t, y):
        if ti < t_input:
            previous_t, previous_y = ti, yi
            continue
        if (yi - target) * (1.0 if steady > 0 else -1.0) >= 0.0:
            if previous_t is None or previous_t < t_input or yi == previous_y:
                return ti - t_input
            return previous_t + (target - previous_y) / (yi - previous_y) * (ti - previous_t) - t_input
        previous_t, previous_y = ti, yi
    return math.nan


# -- ISO 3888-1 double lane change ----------------------------------------------------------------------

#: ISO 3888-1 (severe lane change): section lengths (m), and lane width = factor · w + 0.25 m for the three lanes.
DLC_SECTIONS = (15.0, 30.0, 25.0, 25.0, 15.0)
DLC_LANE_FACTORS = (1.1, 1.2, 1.3)
DLC_LANE_ALLOWANCE = 0.25
DLC_OFFSET = 3.5
#: the EV's width w: contact-patch centres 1.11 m apart (docs/spec/vehicles.md A) plus one tyre width. The tyre is
#: chosen as 145/80 R13 (radius 0.5·330.2 mm + 0.8·145 mm = 281 mm, the wheel radius of [P0] §3), so w =
#: 1.11 + 0.145 = 1.255 m (tyre outer edges; the EV's body is not specified).
EV_TYRE_WIDTH = 0.145
EV_WIDTH = 1.11 + EV_TYRE_WIDTH
#: the footprint's length: the tyres' outer extent, wheelbase + tyre diameter = 2.76 + 0.562 m.
EV_LENGTH = 2.76 + 2 * 0.281


@dataclass(frozen=True)
class Lane:
    """A gated section: the vehicle's footprint must stay within x_left..x_right while its corners are at
    y_start..y_end (course frame: x right, y along the course, = the start pose's world frame)."""

    name: str
    y_start: float
    y_end: float
    x_left: float
    x_right: float

    @property
    def centre(self) -> float:
        return 0.5 * (self.x_left + self.x_right)

    @property
    def width(self) -> float:
        return self.x_right - self.x_left


def dlc_lanes(y0: float, width: float = EV_WIDTH) -> tuple[Lane, Lane, Lane]:
    """The three lanes of ISO 3888-1 starting at y0, changing to the LEFT (−x) as the standard draws it.

    Offset measurement (the standard's 3.5 m): between the right-hand boundaries (cone lines) of section 1
    and section 3, i.e. between the boundaries on the same side of the two lanes; section 5 shares its
    right-hand boundary with section 1 (the vehicle returns to its lane). Lane 1 is centred on x = 0."""
    w1, w3, w5 = (f * width + DLC_LANE_ALLOWANCE for f in DLC_LANE_FACTORS)
    s1, s2, s3, s4, s5 = DLC_SECTIONS
    right1 = w1 / 2.0
    right3 = right1 - DLC_OFFSET
    y = y0
    lane1 = Lane("section 1", y, y + s1, right1 - w1, right1)
    y += s1 + s2
    lane3 = Lane("section 3", y, y + s3, right3 - w3, right3)
    y += s3 + s4
    lane5 = Lane("section 5", y, y + s5, right1 - w5, right1)
    return lane1, lane3, lane5


def cones(lanes: tuple[Lane, ...], per_side: int = 5) -> list[tuple[float, float]]:
    """Cone positions (x, y): `per_side` cones evenly spaced along each boundary of each lane (ends included)."""
    out = []
    for lane in lanes:
        for i in range(per_side):
            y = lane.y_start + (lane.y_end - lane.y_start) * i / (per_side - 1)
            out += [(lane.x_left, y), (lane.x_right, y)]
    return out


def footprint(x: float, y: float, heading_deg: float, width: float = EV_WIDTH,
              length: float = EV_LENGTH) -> list[tuple[float, float]]:
    """World corners (FL, FR, RR, RL) of the vehicle's rectangle centred at (x, y), heading clockwise from +y."""
    h = math.radians(heading_deg)
    c, s = math.cos(h), math.sin(h)
    out = []
    for bx, by in ((-width / 2, length / 2), (width / 2, length / 2), (width / 2, -length / 2),
                   (-width / 2, -length / 2)):
        out.append((x + bx * c + by * s, y - bx * s + by * c))
    return out


def inside(point: tuple[float, float], corners: list[tuple[float, float]]) -> bool:
    """True when the point lies strictly inside the convex polygon `corners` (given in order)."""
    sign = 0.0
    n = len(corners)
    for i in range(n):
        (x1, y1), (x2, y2) = corners[i], corners[(i + 1) % n]
        cross = (x2 - x1) * (point[1] - y1) - (y2 - y1) * (point[0] - x1)
        if cross == 0.0:
            return False
        if sign == 0.0:
            sign = cross
        elif (cross > 0.0) != (sign > 0.0):
            return False
    return True


def clearance(point: tuple[float, float], x: float, y: float, heading_deg: float, width: float = EV_WIDTH,
              length: float = EV_LENGTH) -> float:
    """Signed distance (m) from a point (a cone) to the footprint rectangle centred at (x, y) with the heading
    (clockwise from +y): positive outside, negative inside (minus the depth to the nearest edge)."""
    h = math.radians(heading_deg)
    c, s = math.cos(h), math.sin(h)
    px, py = point[0] - x, point[1] - y
    bx, by = px * c - py * s, px * s + py * c          # body frame: x right, y forward
    dx, dy = abs(bx) - width / 2.0, abs(by) - length / 2.0
    if dx < 0.0 and dy < 0.0:
        return max(dx, dy)
    return math.hypot(max(dx, 0.0), max(dy, 0.0))


def lane_margin(corners: list[tuple[float, float]], lanes: tuple[Lane, ...]) -> float:
    """The smallest distance (m) of a footprint corner to the boundary of the lane it is in (negative: outside),
    over the corners that lie inside a gated section; +inf when none does."""
    worst = math.inf
    for cx, cy in corners:
        for lane in lanes:
            if lane.y_start <= cy <= lane.y_end:
                worst = min(worst, cx - lane.x_left, lane.x_right - cx)
    return worst


# -- slalom --------------------------------------------------------------------------------------------------

#: Cone spacing of the slalom: 30 m, GB/T 6323-2014 (snake test) for passenger cars ([P3] names the test
#: "蛇行" without a layout); the cones stand on the course's centre line.
SLALOM_SPACING = 30.0
SLALOM_CONES = 7


def slalom_cones(y0: float, spacing: float = SLALOM_SPACING, count: int = SLALOM_CONES) -> list[tuple[float, float]]:
    return [(0.0, y0 + i * spacing) for i in range(count)]
