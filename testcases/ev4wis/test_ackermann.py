"""4WIS EV: Ackermann (docs/spec/formulas.md §3, [P2]) in NORMAL mode and the curvature angle X the VCU reports.

NORMAL puts the centre on the rear-axle line, so the front angles must satisfy [P2]'s relations
    1/tan β - 1/tan α = K/L            ([P2]'s K = full track, L = full wheelbase: 1.11 / 2.76)
    1/tan β - 1/tan X = K/(2L),   1/tan X - 1/tan α = K/(2L)
with β the outer and α the inner front angle (magnitudes) and X the curvature angle at the front-axle centre;
the rear wheels stay at 0; the wheel speeds follow V_b = V_d / cos β and V_a = V_b · sin β / sin α.
ADAPTIVE (centre on y = 0) doubles the first difference (§3).

Tolerances: angles 0.05° (issue). A residual of the cotangent relations is checked against how far it can
move when each measured angle is off by 0.05° (d cot β / dβ = -1/sin²β), so the check is exactly as strict
as the angle tolerance. Speeds 0.5 % or 0.2 rpm (issue).
"""

from __future__ import annotations

import math

import pytest

from testcases.ev4wis import oracle
from testcases.ev4wis.plots import plot_wheels
from testcases.ev4wis.steps import (
    ANGLE_TOL,
    CLEAN_BUS_REQS,
    SPEED_ABS_TOL,
    SPEED_REL_TOL,
    VCU_AND_WHEELS,
    expect_fault,
    send_car_mode,
    speed_for,
    start,
    wait_for_targets,
)

pytestmark = [pytest.mark.dut(*VCU_AND_WHEELS)]

NORMAL_HAND_WHEEL = [-750.0, -450.0, -150.0, 120.0, 330.0, 600.0, 900.0]
ADAPTIVE_HAND_WHEEL = [-600.0, 240.0]


def _outer_inner(hand_wheel: float) -> tuple[str, str, str, str]:
    """(outer front, inner front, outer rear, inner rear): a right turn (X > 0) has its outer wheels on the left."""
    return ("FL", "FR", "RL", "RR") if hand_wheel > 0 else ("FR", "FL", "RR", "RL")


@pytest.mark.req("VCU-MODE-04", "VCU-MODE-01", "VCU-OUT-03", "WHL-CTL-01", "WHL-CTL-02", "WHL-STA-01", *CLEAN_BUS_REQS)
@pytest.mark.parametrize("hand_wheel", NORMAL_HAND_WHEEL, ids=[f"NORMAL handwheel={h:g}" for h in NORMAL_HAND_WHEEL])
def test_ackermann_normal(bench, hand_wheel: float) -> None:
    x_cmd = oracle.curvature_from_hand_wheel(hand_wheel)
    centre = oracle.normal_centre(hand_wheel)
    v = speed_for(centre)
    start(bench)
    send_car_mode(bench, "NORMAL", hand_wheel, v)
    wait_for_targets(bench, oracle.car_mode_targets(centre, v), settle=True)
    expect_fault(bench, "OK")

    x_vcu = bench.value("VCU_VehicleState", "CurvatureAngle")
    bench.expect("curvature angle X = HandWheelAngle / 15", x_vcu, x_cmd, abs_tol=ANGLE_TOL, unit="deg",
                 detail="docs/spec/vehicles.md A: ratio 15 in NORMAL")
    outer, inner, outer_rear, inner_rear = _outer_inner(hand_wheel)
    beta = bench.value(f"WHL_Status_{outer}", "SteerAngle")
    alpha = bench.value(f"WHL_Status_{inner}", "SteerAngle")
    beta_exp, alpha_exp = oracle.ackermann_front(x_cmd)
    sign = math.copysign(1.0, x_cmd)
    bench.expect(f"outer front ({outer}) from X: 1/tan β = 1/tan X + K/(2L)", beta, sign * beta_exp,
                 abs_tol=ANGLE_TOL, unit="deg", detail="[P2], docs/spec/formulas.md §3")
    bench.expect(f"inner front ({inner}) from X: 1/tan α = 1/tan X - K/(2L)", alpha, sign * alpha_exp,
                 abs_tol=ANGLE_TOL, unit="deg", detail="[P2], docs/spec/formulas.md §3")
    for wheel in (outer_rear, inner_rear):
        bench.expect(f"{wheel} angle 0 (rear not steered in NORMAL)", bench.value(f"WHL_Status_{wheel}", "SteerAngle"),
                     0.0, abs_tol=ANGLE_TOL, unit="deg")

    k_over_l = oracle.TRACK / oracle.WHEELBASE
    bench.expect("Ackermann 1/tan β - 1/tan α - K/L (measured β, α)",
                 oracle.ackermann_residual(beta, alpha, k_over_l), 0.0,
                 abs_tol=oracle.ackermann_residual_tolerance(beta, alpha, ANGLE_TOL),
                 detail=f"K/L = {k_over_l:.4f} (track / wheelbase); tolerance = 0.05° on each angle")
    t = math.radians(ANGLE_TOL)
    half = oracle.TRACK / (2.0 * oracle.WHEELBASE)
    cot = lambda a: 1.0 / math.tan(math.radians(abs(a)))   # noqa: E731
    bench.expect("1/tan β - 1/tan X - K/(2L) (measured β, X reported by the VCU)", cot(beta) - cot(x_vcu) - half, 0.0,
                 abs_tol=t / math.sin(math.radians(beta)) ** 2 + t / math.sin(math.radians(x_vcu)) ** 2,
                 detail="tolerance = 0.05° on β and on X")
    bench.expect("1/tan X - 1/tan α - K/(2L) (X reported, measured α)", cot(x_vcu) - cot(alpha) - half, 0.0,
                 abs_tol=t / math.sin(math.radians(alpha)) ** 2 + t / math.sin(math.radians(x_vcu)) ** 2,
                 detail="tolerance = 0.05° on α and on X")

    v_d = bench.value(f"WHL_Status_{outer_rear}", "WheelSpeed")
    v_b = bench.value(f"WHL_Status_{outer}", "WheelSpeed")
    v_a = bench.value(f"WHL_Status_{inner}", "WheelSpeed")
    bench.expect(f"V_b ({outer}) = V_d ({outer_rear}) / cos β", v_b, oracle.outer_front_speed_geometric(v_d, beta),
                 abs_tol=SPEED_ABS_TOL, rel_tol=SPEED_REL_TOL, unit="rpm",
                 detail="docs/spec/formulas.md §3 (E2 corrected)")
    bench.expect(f"V_a ({inner}) = V_b · sin β / sin α", v_a, oracle.inner_front_speed(v_b, beta, alpha),
                 abs_tol=SPEED_ABS_TOL, rel_tol=SPEED_REL_TOL, unit="rpm", detail="docs/spec/formulas.md §3")
    bench.expect_clean_bus()
    plot_wheels(bench)


@pytest.mark.req("VCU-MODE-05", "VCU-MODE-06", "VCU-MODE-01", "VCU-OUT-03", "WHL-CTL-01", "WHL-STA-01",
                 *CLEAN_BUS_REQS)
@pytest.mark.parametrize("hand_wheel", ADAPTIVE_HAND_WHEEL,
                         ids=[f"ADAPTIVE handwheel={h:g}" for h in ADAPTIVE_HAND_WHEEL])
def test_ackermann_difference_doubles_in_adaptive(bench, hand_wheel: float) -> None:
    """§3: "for a centre on y = 0 (symmetric 4WS) the difference doubles": 1/tan β - 1/tan α = 2 K/L;
    the rear wheels mirror the front ones."""
    x_cmd = oracle.curvature_from_hand_wheel(hand_wheel)
    centre = oracle.adaptive_centre(hand_wheel)
    v = speed_for(centre)
    start(bench)
    send_car_mode(bench, "ADAPTIVE", hand_wheel, v)
    wait_for_targets(bench, oracle.car_mode_targets(centre, v), settle=True)
    expect_fault(bench, "OK")
    bench.expect("curvature angle X = HandWheelAngle / 15", bench.value("VCU_VehicleState", "CurvatureAngle"), x_cmd,
                 abs_tol=ANGLE_TOL, unit="deg")
    outer, inner, outer_rear, inner_rear = _outer_inner(hand_wheel)
    beta = bench.value(f"WHL_Status_{outer}", "SteerAngle")
    alpha = bench.value(f"WHL_Status_{inner}", "SteerAngle")
    k_over_l = 2.0 * oracle.TRACK / oracle.WHEELBASE
    bench.expect("1/tan β - 1/tan α - 2 K/L (measured β, α)", oracle.ackermann_residual(beta, alpha, k_over_l), 0.0,
                 abs_tol=oracle.ackermann_residual_tolerance(beta, alpha, ANGLE_TOL),
                 detail="docs/spec/formulas.md §3, centre on y = 0; tolerance = 0.05° on each angle")
    for front, rear in ((outer, outer_rear), (inner, inner_rear)):
        bench.expect(f"{rear} mirrors {front}", bench.value(f"WHL_Status_{rear}", "SteerAngle"),
                     -bench.value(f"WHL_Status_{front}", "SteerAngle"), abs_tol=2 * ANGLE_TOL, unit="deg",
                     detail="[P0] §3: rear angles mirror the front; each angle within 0.05° → 0.1° for the pair")
    bench.expect_clean_bus()
    plot_wheels(bench)
