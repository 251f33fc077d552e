"""plant.kinematics against hand-computed cases, docs/spec/formulas.md §2-3 and an independent vector check."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from plant.kinematics import (
    CENTRE_TOLERANCE_M,
    Geometry,
    Undefined,
    ackermann_front,
    centre_from_axle_angles,
    centre_x_on_mid_axle,
    centre_x_on_rear_axle,
    classify_centre,
    curvature_angle,
    rotation,
    translation,
    yaw_rate,
)

EV = Geometry(half_track=1.11 / 2, half_wheelbase=2.76 / 2, wheel_radius=0.281)   # docs/spec/vehicles.md A
UNIT = Geometry(half_track=1.0, half_wheelbase=2.0, wheel_radius=30.0 / math.pi)   # 1 rpm per m/s
K, L = EV.half_track, EV.half_wheelbase


def rpm(v: float, g: Geometry = EV) -> float:
    return 30.0 * v / (math.pi * g.wheel_radius)


# -- §2 by hand --------------------------------------------------------------------------------------

def test_hand_computed_centre_right_of_vehicle():
    # S = (3, 0), v_o = 3 -> Omega = 1 rad/s; wheels FL (-1, 2), FR (1, 2), RL (-1, -2), RR (1, -2).
    angles, speeds = rotation(3.0, 0.0, 3.0, UNIT)
    a = math.degrees(math.atan(0.5))
    assert angles == pytest.approx((a, 45.0, -a, -45.0), abs=1e-12)
    assert speeds == pytest.approx((math.sqrt(20), math.sqrt(8), math.sqrt(20), math.sqrt(8)), rel=1e-12)


def test_counter_clockwise_is_every_speed_negated():
    a1, n1 = rotation(3.0, 0.0, 3.0, UNIT)
    a2, n2 = rotation(3.0, 0.0, -3.0, UNIT)
    assert a1 == a2 and n2 == pytest.approx(tuple(-n for n in n1))


def test_erratum_e1_right_rear_uses_x_minus_k():
    x, y, v_o = 3.0, 0.0, 3.0
    angles, speeds = rotation(x, y, v_o, UNIT)
    r_o, k = math.hypot(x, y), UNIT.half_track
    cos4 = math.cos(math.radians(angles[3]))
    corrected = 30 * v_o * (x - k) / (math.pi * UNIT.wheel_radius * r_o * cos4)
    as_printed = 30 * v_o * (x + k) / (math.pi * UNIT.wheel_radius * r_o * cos4)
    assert speeds[3] == pytest.approx(corrected, rel=1e-12)
    assert speeds[3] != pytest.approx(as_printed, rel=1e-3)
    # and the paper's eq. 7-9 hold as printed for the other three wheels
    for i, sign in ((0, +1), (1, -1), (2, +1)):
        c = math.cos(math.radians(angles[i]))
        assert speeds[i] == pytest.approx(30 * v_o * (x + sign * k) / (math.pi * UNIT.wheel_radius * r_o * c))


def test_centre_between_wheels_of_an_axle_folds_and_reverses():
    # S = (0.5, 0) lies between FL and FR: FR's velocity points backwards -> folded angle, negative speed.
    angles, speeds = rotation(0.5, 0.0, 0.5, UNIT)
    assert angles[1] == pytest.approx(math.degrees(math.atan(2 / -0.5)))
    assert speeds[1] == pytest.approx(-math.hypot(2, 0.5))
    assert speeds[0] > 0 and speeds[1] < 0


def test_zero_denominator_gives_90_degrees():
    # S = (1, -5): FR straight above, numerator 7 > 0 -> +90 deg, rolling forward at 7 Omega.
    angles, speeds = rotation(1.0, -5.0, math.hypot(1, 5), UNIT)
    assert angles[1] == 90.0 and speeds[1] == pytest.approx(7.0)
    # S = (1, 5): numerator -3 < 0: the paper's -90 deg is reported as +90 deg rolling backwards.
    angles, speeds = rotation(1.0, 5.0, math.hypot(1, 5), UNIT)
    assert angles[1] == 90.0 and speeds[1] == pytest.approx(-3.0)


def test_spin_about_origin_at_zero_speed_has_angles():
    angles, speeds = rotation(0.0, 0.0, 0.0, EV)
    a = math.degrees(math.atan(L / K))
    assert angles == pytest.approx((a, -a, -a, a))
    assert speeds == (0.0, 0.0, 0.0, 0.0)


def test_undefined_inputs_raise_in_the_pure_function():
    with pytest.raises(ValueError):
        rotation(0.0, 0.0, 1.0, EV)
    with pytest.raises(ValueError):
        rotation(K, L, 1.0, EV)


def test_yaw_rate_is_v_over_r():
    assert yaw_rate(3.0, 4.0, 5.0) == pytest.approx(math.degrees(1.0))
    assert yaw_rate(0.0, 0.0, 0.0) == 0.0


# -- undefined requests ----------------------------------------------------------------------------------

@pytest.mark.parametrize("x, y, v, forward_only, expected", [
    (0.0, 0.0, 1.0, False, Undefined.CENTRE_AT_ORIGIN),
    (0.005, -0.005, -1.0, False, Undefined.CENTRE_AT_ORIGIN),
    (0.0, 0.0, 0.0, False, None),                       # spin pose without motion is defined
    (-K, L, 0.0, False, Undefined.CENTRE_ON_WHEEL),
    (K + 0.006, -L - 0.006, 1.0, False, Undefined.CENTRE_ON_WHEEL),
    (K + 0.02, -L, 1.0, False, None),
    (0.3, -L, 1.0, False, None),                        # PIVOT may fold
    (0.3, -L, 1.0, True, Undefined.ANGLE_OVER_90),      # a car-like mode may not
    (-0.3, 0.0, 1.0, True, Undefined.ANGLE_OVER_90),
    (-K - 0.5, 0.0, 1.0, True, None),
])
def test_classify_centre(x, y, v, forward_only, expected):
    assert classify_centre(x, y, v, EV, forward_only=forward_only) == expected


# -- [P0] §3 U-turn numbers (docs/spec/formulas.md §2) -----------------------------------------------------------

def test_uturn_normal_mode():
    # FL -38 deg with S on the rear-axle line y = -L.
    x = 2 * L / math.tan(math.radians(-38.0)) - K
    assert x == pytest.approx(-4.088, abs=5e-4)
    angles, _ = rotation(x, -L, 1.0, EV)
    assert angles[0] == pytest.approx(-38.0)
    assert angles[1] == pytest.approx(-30.7, abs=0.05)
    assert angles[2] == 0.0 and angles[3] == 0.0
    assert 2 * math.hypot(K - x, L - (-L)) == pytest.approx(10.80, abs=0.005)   # outer front wheel (FR)


def test_uturn_adaptive_mode():
    x = L / math.tan(math.radians(-37.0)) - K
    assert x == pytest.approx(-2.386, abs=5e-4)
    angles, speeds = rotation(x, 0.0, 1.0, EV)
    assert angles[0] == pytest.approx(-37.0)
    assert angles[1] == pytest.approx(-25.1, abs=0.05)
    assert angles[2] == pytest.approx(37.0) and angles[3] == pytest.approx(25.1, abs=0.05)
    assert speeds[0] == pytest.approx(speeds[2]) and speeds[1] == pytest.approx(speeds[3])
    d_adaptive = 2 * math.hypot(K - x, L)
    assert d_adaptive == pytest.approx(6.50, abs=0.005)
    d_normal = 2 * math.hypot(K - (2 * L / math.tan(math.radians(-38.0)) - K), 2 * L)
    assert d_adaptive / d_normal == pytest.approx(0.60, abs=0.005)


# -- §3 Ackermann and the curvature angle ------------------------------------------------------------------

@pytest.mark.parametrize("x_deg", [2.0, 10.0, 25.0, 34.03, 45.0, 60.0])
def test_ackermann_relations(x_deg):
    cx = centre_x_on_rear_axle(x_deg, EV)
    assert cx == pytest.approx(2 * L / math.tan(math.radians(x_deg)))
    assert curvature_angle(cx, -L, EV) == pytest.approx(x_deg)
    angles, speeds = rotation(cx, -L, 1.0, EV)
    beta, alpha = abs(angles[0]), abs(angles[1])     # right turn: FL outer, FR inner
    cot = lambda d: 1.0 / math.tan(math.radians(d))  # noqa: E731
    track, wheelbase = 2 * K, 2 * L                  # [P2]'s K and L
    assert cot(beta) - cot(alpha) == pytest.approx(track / wheelbase)
    assert cot(beta) - cot(x_deg) == pytest.approx(track / (2 * wheelbase))
    assert cot(x_deg) - cot(alpha) == pytest.approx(track / (2 * wheelbase))
    assert ackermann_front(x_deg, EV) == pytest.approx((beta, alpha))
    # speeds (erratum E2): outer front = outer rear / cos(beta); inner front = outer front sin(beta)/sin(alpha)
    v_b, v_d = speeds[0], speeds[2]
    assert v_b == pytest.approx(v_d / math.cos(math.radians(beta)))
    assert speeds[1] == pytest.approx(v_b * math.sin(math.radians(beta)) / math.sin(math.radians(alpha)))
    assert speeds[2] != pytest.approx(speeds[3])      # the rear wheels differ by the track


def test_symmetric_4ws_doubles_the_difference():
    cx = centre_x_on_mid_axle(-20.0, EV)
    assert curvature_angle(cx, 0.0, EV) == pytest.approx(-20.0)
    angles, _ = rotation(cx, 0.0, 1.0, EV)
    cot = lambda d: 1.0 / math.tan(math.radians(abs(d)))  # noqa: E731
    assert cot(angles[1]) - cot(angles[0]) == pytest.approx(2 * (2 * K) / (2 * L))


def test_centre_from_axle_angles():
    assert centre_from_axle_angles(20.0, 0.0, EV) == pytest.approx((centre_x_on_rear_axle(20.0, EV), -L))
    assert centre_from_axle_angles(-30.0, 30.0, EV) == pytest.approx((centre_x_on_mid_axle(-30.0, EV), 0.0))
    assert centre_from_axle_angles(10.0, 10.0, EV) is None
    assert centre_x_on_rear_axle(0.0, EV) is None and centre_x_on_mid_axle(0.0, EV) is None


def test_translation():
    angles, speeds = translation(90.0, 2.0, EV)
    assert angles == (90.0,) * 4 and speeds == pytest.approx((rpm(2.0),) * 4)


# -- independent rigid-body check (vectors, not the module) -------------------------------------------------

def rigid_check(x: float, y: float, v_o: float, g: Geometry) -> None:
    angles, speeds = rotation(x, y, v_o, g)
    omega = np.array([0.0, 0.0, -v_o / math.hypot(x, y)])          # clockwise positive -> -z
    s = np.array([x, y, 0.0])
    k, h = g.half_track, g.half_wheelbase
    for p, a, n in zip([(-k, h), (k, h), (-k, -h), (k, -h)], angles, speeds):
        vel = np.cross(omega, np.array([p[0], p[1], 0.0]) - s)[:2]
        heading = np.array([math.sin(math.radians(a)), math.cos(math.radians(a))])
        scale = max(1.0, float(np.linalg.norm(vel)))
        assert abs(vel[0] * heading[1] - vel[1] * heading[0]) <= 1e-9 * scale   # along the heading
        assert n * math.pi * g.wheel_radius / 30.0 == pytest.approx(float(vel @ heading), rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("x, y", [(3.0, 0.0), (-4.0876, -L), (0.3, 0.2), (-0.555, 7.0), (100.0, -50.0), (0.1, -3.0)])
def test_rigid_body_property(x, y):
    rigid_check(x, y, 1.7, EV)


coord = st.floats(min_value=-60.0, max_value=60.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=400, deadline=None)
@given(x=coord, y=coord, v_o=st.floats(min_value=-30.0, max_value=30.0, allow_nan=False))
def test_random_centres_give_finite_folded_commands(x, y, v_o):
    assume(math.hypot(x, y) >= CENTRE_TOLERANCE_M)
    assume(all(math.hypot(x - px, y - py) >= CENTRE_TOLERANCE_M for px, py in EV.wheel_positions))
    assert classify_centre(x, y, v_o, EV) is None
    angles, speeds = rotation(x, y, v_o, EV)
    assert all(math.isfinite(a) and -90.0 < a <= 90.0 for a in angles)
    assert all(math.isfinite(n) for n in speeds)
    if v_o != 0.0:
        rigid_check(x, y, v_o, EV)


@settings(max_examples=200, deadline=None)
@given(x=st.sampled_from([-K, K, 0.0]), y=coord)
def test_zero_denominators_stay_in_range(x, y):
    assume(all(math.hypot(x - px, y - py) >= CENTRE_TOLERANCE_M for px, py in EV.wheel_positions))
    assume(math.hypot(x, y) >= CENTRE_TOLERANCE_M)
    angles, speeds = rotation(x, y, 1.0, EV)
    assert all(-90.0 < a <= 90.0 for a in angles) and all(math.isfinite(n) for n in speeds)
