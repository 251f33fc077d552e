"""The oracle against the formula sheet's worked numbers and against itself (no bench needed).

If the oracle were wrong, every 4WIS case would check the wrong thing; these checks pin it to the numbers
docs/spec/formulas.md §2 prints for the U-turn and to the independent rigid-body formulation.
"""

from __future__ import annotations

import math

import pytest

from testcases.ev4wis import oracle
from testcases.ev4wis.oracle import WHEEL_POSITION, WHEELS


def test_uturn_numbers_of_the_formula_sheet() -> None:
    """docs/spec/formulas.md §2: "FL -38° puts S at x = -4.088 m on y = -L and gives FR -30.7°; FL -37° with S on y = 0
    gives S at x = -2.386 m and FR -25.1°. The outer front wheel's path diameter is 10.80 m and 6.50 m ...
    the ratio 0.60"."""
    normal = oracle.uturn_centre_from_fl("NORMAL", -38.0)
    adaptive = oracle.uturn_centre_from_fl("ADAPTIVE", -37.0)
    assert normal[0] == pytest.approx(-4.088, abs=5e-4) and normal[1] == -oracle.L
    assert adaptive[0] == pytest.approx(-2.386, abs=5e-4) and adaptive[1] == 0.0
    assert oracle.paper_angle(*normal, "FR") == pytest.approx(-30.7, abs=0.05)
    assert oracle.paper_angle(*adaptive, "FR") == pytest.approx(-25.1, abs=0.05)
    assert oracle.paper_angle(*adaptive, "RL") == pytest.approx(37.0, abs=1e-9)
    d_normal = 2 * math.dist(WHEEL_POSITION["FR"], normal)
    d_adaptive = 2 * math.dist(WHEEL_POSITION["FR"], adaptive)
    assert d_normal == pytest.approx(10.80, abs=0.005)
    assert d_adaptive == pytest.approx(6.50, abs=0.005)
    assert d_adaptive / d_normal == pytest.approx(0.60, abs=0.005)


def test_hand_wheel_round_trip() -> None:
    for mode, fl in (("NORMAL", -38.0), ("ADAPTIVE", -37.0)):
        centre = oracle.uturn_centre_from_fl(mode, fl)
        hw = oracle.hand_wheel_for_centre(mode, centre)
        back = (oracle.normal_centre if mode == "NORMAL" else oracle.adaptive_centre)(hw)
        assert back == pytest.approx(centre, abs=1e-9)


CENTRES = [(3.0, 2.0), (-4.0, -1.38), (0.3, 1.38), (-2.0, 0.0), (0.0, 2.5), (5.0, -6.0), (-0.3, -2.5),
           (0.0, 1.38), (0.56, 4.0), (1000.0, 0.0), (0.0, -1000.0), (0.555, 3.0), (-0.555, -3.0)]


@pytest.mark.parametrize("centre", CENTRES)
@pytest.mark.parametrize("v_o", [1.0, -1.0])
def test_section_2_agrees_with_the_rigid_body(centre: tuple[float, float], v_o: float) -> None:
    """Eq. 1-10 (E1 corrected, bus convention) give each wheel the velocity ω × (P - S), ω = v_o / r_o."""
    targets = oracle.rotation_targets(*centre, v_o)
    omega = v_o / math.hypot(*centre)
    for w in WHEELS:
        t = targets[w]
        assert -90.0 < t.angle <= 90.0
        heading = oracle.heading_vector(t.angle)
        speed = oracle.speed_from_rpm(t.rpm)
        expected = oracle.rigid_velocity(WHEEL_POSITION[w], centre, omega)
        assert heading[0] * speed == pytest.approx(expected[0], abs=1e-9)
        assert heading[1] * speed == pytest.approx(expected[1], abs=1e-9)


def test_erratum_e1_changes_only_rr() -> None:
    x, y = 3.0, 2.0
    for w in WHEELS:
        corrected = oracle.paper_rpm(x, y, 1.0, w)
        printed = oracle.paper_rpm(x, y, 1.0, w, erratum_e1_corrected=False)
        assert (corrected == printed) == (w != "RR")


@pytest.mark.parametrize("hand_wheel", [-900.0, -300.0, 45.0, 450.0, 900.0])
def test_ackermann_holds_for_the_normal_targets(hand_wheel: float) -> None:
    """§3 with X on the rear-axle centre line agrees with §2 for NORMAL's centre; speeds V_b = V_d / cos β."""
    x_deg = oracle.curvature_from_hand_wheel(hand_wheel)
    centre = oracle.normal_centre(hand_wheel)
    t = oracle.car_mode_targets(centre, 1.0)
    outer, inner, outer_rear = ("FL", "FR", "RL") if hand_wheel > 0 else ("FR", "FL", "RR")
    beta, alpha = oracle.ackermann_front(x_deg)
    assert abs(t[outer].angle) == pytest.approx(beta, abs=1e-9)
    assert abs(t[inner].angle) == pytest.approx(alpha, abs=1e-9)
    assert oracle.ackermann_residual(beta, alpha, oracle.TRACK / oracle.WHEELBASE) == pytest.approx(0.0, abs=1e-12)
    assert oracle.curvature_angle(*centre) == pytest.approx(x_deg, abs=1e-9)
    assert t[outer].rpm == pytest.approx(oracle.outer_front_speed_geometric(t[outer_rear].rpm, beta), rel=1e-12)
    assert t[inner].rpm == pytest.approx(oracle.inner_front_speed(t[outer].rpm, beta, alpha), rel=1e-12)


def test_body_to_world_turns_clockwise_with_the_heading() -> None:
    """Heading 90° (clockwise, facing +x): the body's front point (0, 1) is at (1, 0), its right (1, 0) at (0, -1)."""
    assert oracle.body_to_world((0.0, 1.0), (0.0, 0.0), 90.0) == pytest.approx((1.0, 0.0), abs=1e-12)
    assert oracle.body_to_world((1.0, 0.0), (0.0, 0.0), 90.0) == pytest.approx((0.0, -1.0), abs=1e-12)
