"""4WIS EV: wheel speeds against docs/spec/formulas.md §2 ([P0] eq. 6-10, E1 corrected), clockwise and counter-
clockwise, an independent rigid-body check, LATERAL, and the errata E1 and E2.

Rigid-body check (no paper formula): a rotation about S at ω = v_o / r_o (the definition of v_o, the
speed of the geometric centre at r_o from S) moves each contact point P at ω × (P - S). Measured from the
bus: the heading of each wheel (WHL_Status SteerAngle, 0 = +y, clockwise) and its signed circumferential
speed (WheelSpeed · π r / 30). The heading must be perpendicular to P - S and the signed speed must equal
the projection of ω × (P - S) on it. Ground truth (PLANT_Motion, PLANT_Dynamics) confirms the direction.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from testcases.ev4wis import oracle
from testcases.ev4wis.oracle import WHEEL_POSITION, WHEELS
from testcases.ev4wis.plots import plot_wheels
from testcases.ev4wis.steps import (
    ANGLE_TOL,
    CLEAN_BUS_REQS,
    GROUND_TRUTH_YAW_ABS_TOL,
    SPEED_ABS_TOL,
    SPEED_REL_TOL,
    VCU_AND_WHEELS,
    WHEEL_SPEED_LIMIT,
    YAW_ABS_TOL,
    expect_fault,
    expect_wheels,
    send_car_mode,
    send_pivot,
    speed_for,
    start,
    wait_for_targets,
)

pytestmark = [pytest.mark.dut(*VCU_AND_WHEELS)]

TRAVEL_S = 0.5               # s of steady LATERAL motion judged (VCU-MODE-08)
GROUND_SPEED_LSB = 0.0025    # m/s: one LSB of PLANT_Motion.Speed (dbc/bench.dbc)

CENTRES = [(3.0, 2.0), (-4.0, -1.38), (0.3, 1.38), (-2.0, 0.0), (0.0, 2.5), (5.0, -6.0), (-0.3, -2.5),
           (1000.0, 0.0)]
DIRECTIONS = {"clockwise": 1.0, "counter-clockwise": -1.0}
CASES = [(c, d) for c in CENTRES for d in DIRECTIONS]


def _fold(angle_deg: float) -> float:
    """A direction (deg from +y, clockwise) folded into (-90, 90] like a wheel angle (the sign goes to the speed)."""
    a = (angle_deg + 180.0) % 360.0 - 180.0
    if a > 90.0:
        a -= 180.0
    elif a <= -90.0:
        a += 180.0
    return a


@pytest.mark.req("VCU-MODE-01", "VCU-MODE-02", "VCU-REQ-01", "VCU-OUT-01", "VCU-OUT-05", "WHL-CTL-01", "WHL-CTL-02",
                 "WHL-STA-01", *CLEAN_BUS_REQS)
@pytest.mark.parametrize("centre,direction", CASES,
                         ids=[f"centre=({c[0]:g},{c[1]:g}) {d}" for c, d in CASES])
def test_wheel_speeds(bench, centre: tuple[float, float], direction: str) -> None:
    x, y = centre
    v_o = DIRECTIONS[direction] * speed_for(centre)
    targets = oracle.rotation_targets(x, y, v_o)
    start(bench)
    send_pivot(bench, x, y, v_o)
    bench.note(f"PIVOT about S = ({x:g}, {y:g}) m at v_o = {v_o:+g} m/s ({direction}, docs/spec/k-matrix.md: "
               "positive = "
               f"clockwise); §2 speeds: " + ", ".join(f"{w} {t.rpm:+.2f} rpm" for w, t in targets.items()))
    wait_for_targets(bench, targets, settle=True)
    expect_fault(bench, "OK")
    expect_wheels(bench, targets, "docs/spec/formulas.md §2 eq. 7-10, E1 corrected", angles=False)
    for w in WHEELS:
        measured = bench.value(f"WHL_Status_{w}", "WheelSpeed")
        same_sign = math.copysign(1, measured) == math.copysign(1, targets[w].rpm)
        bench.expect_true(f"{w} sign of the reached speed", same_sign,
                          measured=measured, expected="+" if targets[w].rpm > 0 else "-",
                          detail="positive = toward +y at angle 0 (§2); counter-clockwise negates every speed")

    # rigid body, no paper formula: wheel velocity = ω × (P - S)
    omega = v_o / math.hypot(x, y)                    # rad/s, clockwise positive
    for w in WHEELS:
        p = WHEEL_POSITION[w]
        angle = bench.value(f"WHL_Status_{w}", "SteerAngle")
        n = bench.value(f"WHL_Status_{w}", "WheelSpeed")
        heading = oracle.heading_vector(angle)
        radius_vec = (p[0] - x, p[1] - y)
        bench.expect(f"{w} heading ⟂ (P - S)", oracle.angle_between(heading, radius_vec), 90.0,
                     abs_tol=ANGLE_TOL, unit="deg", detail="rigid body: velocity ⟂ radius")
        vel = oracle.rigid_velocity(p, centre, omega)
        projected_rpm = oracle.rpm_from_speed(vel[0] * heading[0] + vel[1] * heading[1])
        bench.expect(f"{w} speed = (ω × (P - S)) · heading", n, projected_rpm, abs_tol=SPEED_ABS_TOL,
                     rel_tol=SPEED_REL_TOL, unit="rpm", detail=f"rigid body, ω = {math.degrees(omega):+.3f} °/s")

    # ground truth of the plant: yaw rate and direction of travel of the geometric centre
    yaw = math.degrees(omega)
    bench.expect("ground truth yaw rate (PLANT_Motion.YawRate)", bench.value("PLANT_Motion", "YawRate"), yaw,
                 abs_tol=GROUND_TRUTH_YAW_ABS_TOL, rel_tol=SPEED_REL_TOL, unit="deg/s",
                 detail="positive clockwise; ω = v_o / r_o ([P0] eq. 5); abs. tolerance from the 0.1 rpm "
                        "resolution of the wheel-speed commands")
    vo = oracle.rigid_velocity((0.0, 0.0), centre, omega)
    direction = _fold(math.degrees(math.atan2(vo[0], vo[1])))
    sideslip = bench.value("PLANT_Dynamics", "Sideslip")
    bench.expect("ground truth direction of the centre's velocity (PLANT_Dynamics.Sideslip), modulo 180°",
                 direction + _fold(sideslip - direction), direction, abs_tol=ANGLE_TOL, unit="deg",
                 detail=f"ω × (O - S); Sideslip is folded into (-90°, 90°], so -90° and +90° are one direction "
                        f"(bus value {sideslip:g}°)")
    bench.expect("VCU VehicleSpeed (signed as TargetSpeed)", bench.value("VCU_VehicleState", "VehicleSpeed"), v_o,
                 abs_tol=SPEED_REL_TOL * abs(v_o) + 0.005, unit="m/s",
                 detail="docs/spec/k-matrix.md; an estimate from the four WHL_Status: 0.5 % (the wheel-speed "
                        "tolerance) "
                        "+ half an LSB (0.005 m/s)")
    bench.expect_clean_bus()
    plot_wheels(bench)


@pytest.mark.req("VCU-MODE-08", "VCU-REQ-01", "VCU-OUT-01", "WHL-CTL-01", "WHL-CTL-02", "WHL-STA-01", *CLEAN_BUS_REQS)
@pytest.mark.parametrize("v", [1.5, -1.5], ids=["LATERAL right v=+1.5", "LATERAL left v=-1.5"])
def test_lateral_speeds(bench, v: float) -> None:
    """LATERAL (docs/contract/vcu.md VCU-MODE-08): all wheels +90°, one signed speed (eq. 6; v < 0: negative rpm
    at the same +90°, road-wheel angles lie in (-90°, +90°], docs/spec/formulas.md §1); once the wheels have
    reached the commands the body translates at v, to the right for v > 0, without turning: judged on the
    plant's ground truth of its velocity and path, not on when the bench received the frames (VCU-GEN-02: the
    VCU's timing does not enter a steady motion)."""
    targets = oracle.lateral_targets(v)
    start(bench)
    bench.set("DRV_MotionRequest", DriveMode="LATERAL", TargetSpeed=v)
    wait_for_targets(bench, targets, settle=True)
    expect_fault(bench, "OK")
    expect_wheels(bench, targets, "docs/spec/vehicles.md A LATERAL; eq. 6")
    since = bench.now
    bench.run(TRAVEL_S)
    # Judged on the plant's ground truth alone, never on the bench's receive stamps (docs/contract/vcu.md
    # VCU-MODE-08, VCU-GEN-02): each PLANT_Motion/PLANT_Dynamics frame carries the centre's velocity at the
    # plant's tick (plant.md PLANT-GT-01/02), so a frame received late changes no value judged here.
    _, speed = bench.history("PLANT_Motion", "Speed", since=since)
    _, sideslip = bench.history("PLANT_Dynamics", "Sideslip", since=since)
    beta = math.radians(float(np.mean(sideslip)))
    lateral, forward = float(np.mean(speed)) * math.sin(beta), float(np.mean(speed)) * math.cos(beta)
    bench.expect(f"ground truth: the centre moves to the right at v (mean of {TRAVEL_S:g} s)", lateral, v,
                 abs_tol=GROUND_SPEED_LSB, rel_tol=SPEED_REL_TOL, unit="m/s",
                 detail="PLANT_Motion.Speed along PLANT_Dynamics.Sideslip, body frame; positive = right "
                        "(docs/spec/k-matrix.md); 0.5 % = the wheel speeds' tolerance (VCU-MODE-08)")
    bench.expect(f"ground truth: no forward velocity (mean of {TRAVEL_S:g} s)", forward, 0.0,
                 abs_tol=GROUND_SPEED_LSB, unit="m/s", detail="one LSB of PLANT_Motion.Speed")
    # the path itself, which needs no clock: its direction in the body frame (the wheels' commands reach them a
    # few ms apart, one frame phase each, so the body may have yawed a few hundredths of a degree while
    # steering to 90°)
    _, xs = bench.history("PLANT_Position", "PosX", since=since)
    _, ys = bench.history("PLANT_Position", "PosY", since=since)
    dx, dy = float(xs[-1] - xs[0]), float(ys[-1] - ys[0])
    h = math.radians(bench.value("PLANT_Motion", "Heading"))
    body_dx, body_dy = dx * math.cos(h) - dy * math.sin(h), dx * math.sin(h) + dy * math.cos(h)
    bench.expect_true(f"ground truth: travelled {'right' if v > 0 else 'left'} (body frame)",
                      body_dx * v > 0.0, measured=round(body_dx, 3), expected="> 0 m" if v > 0 else "< 0 m",
                      detail=f"PLANT_Position, first to last frame of {TRAVEL_S:g} s")
    bench.expect(f"ground truth: travelled forward in {TRAVEL_S:g} s (body frame)", body_dy, 0.0, abs_tol=0.002,
                 unit="m", detail="0.002 m = two LSB of PLANT_Position")
    bench.expect("ground truth yaw rate", bench.value("PLANT_Motion", "YawRate"), 0.0, abs_tol=YAW_ABS_TOL,
                 unit="deg/s")
    bench.expect_clean_bus()
    plot_wheels(bench)


# -- errata -------------------------------------------------------------------------------------------

E1_CENTRES = [(3.0, 2.0), (-2.0, 0.0), (5.0, -6.0), (0.0, 2.5)]
E2_HAND_WHEEL = 450.0          # NORMAL, X = 30°: a right turn, outer wheels FL/RL, inner FR/RR


@pytest.mark.req("VCU-MODE-01", "VCU-MODE-02", "VCU-MODE-04", "WHL-CTL-02", "WHL-STA-01", *CLEAN_BUS_REQS)
def test_errata_e1_e2(bench) -> None:
    """E1 ([P0] eq. 10 prints x + K for RR; geometry: x - K) and E2 ([P2] §4 prints V_b = V_d × cos β
    and equal rear speeds; geometry: V_b = V_d / cos β, rear wheels differ). The bench checks the geometry:
    the wheel speeds must match it within 0.5 % or 0.2 rpm and differ from the printed formulas."""
    rows = []
    for x, y in E1_CENTRES:
        v = speed_for((x, y))
        geometric = oracle.paper_rpm(x, y, v, "RR")
        printed = oracle.paper_rpm(x, y, v, "RR", erratum_e1_corrected=False)
        start(bench)
        send_pivot(bench, x, y, v)
        wait_for_targets(bench, oracle.rotation_targets(x, y, v))
        measured = bench.value("WHL_Status_RR", "WheelSpeed")
        label = f"E1 centre ({x:g}, {y:g})"
        bench.expect(f"{label}: RR speed = geometry (x - K)", measured, geometric, abs_tol=SPEED_ABS_TOL,
                     rel_tol=SPEED_REL_TOL, unit="rpm")
        limit = max(SPEED_ABS_TOL, SPEED_REL_TOL * abs(printed))
        bench.expect_true(f"{label}: RR speed differs from the printed x + K", abs(measured - printed) > limit,
                          measured=round(measured - printed, 3), expected=f"|difference| > {limit:.3g} rpm")
        rows.append(["E1", f"({x:g}, {y:g}) m, v_o {v:+g} m/s", "n4 (RR) rpm", f"{printed:.2f}",
                     f"{geometric:.2f}", f"{measured:.1f}"])
        bench.expect_clean_bus()

    # E2: NORMAL, centre on the rear-axle line; outer wheels FL/RL in a right turn
    start(bench)
    v = 2.0
    centre = oracle.normal_centre(E2_HAND_WHEEL)
    targets = oracle.car_mode_targets(centre, v)
    send_car_mode(bench, "NORMAL", E2_HAND_WHEEL, v)
    wait_for_targets(bench, targets, settle=True)
    beta = bench.value("WHL_Status_FL", "SteerAngle")      # outer front angle
    v_d = bench.value("WHL_Status_RL", "WheelSpeed")       # outer rear
    v_b = bench.value("WHL_Status_FL", "WheelSpeed")       # outer front
    v_inner_rear = bench.value("WHL_Status_RR", "WheelSpeed")
    geometric = oracle.outer_front_speed_geometric(v_d, beta)
    printed = oracle.outer_front_speed_printed_e2(v_d, beta)
    bench.expect("E2: outer front V_b = V_d / cos β", v_b, geometric, abs_tol=SPEED_ABS_TOL, rel_tol=SPEED_REL_TOL,
                 unit="rpm", detail=f"β = {beta:.2f}° (FL reached), V_d = RL reached")
    limit = max(SPEED_ABS_TOL, SPEED_REL_TOL * abs(printed))
    bench.expect_true("E2: V_b differs from the printed V_d × cos β", abs(v_b - printed) > limit,
                      measured=round(v_b - printed, 3), expected=f"|difference| > {limit:.3g} rpm")
    rear_ratio = (centre[0] + oracle.K) / (centre[0] - oracle.K)     # outer / inner rear turning radius
    bench.expect("E2: rear wheels differ by the track (outer/inner = (x + K)/(x - K))", v_d / v_inner_rear,
                 rear_ratio, rel_tol=2 * SPEED_REL_TOL,
                 detail=f"ratio of two speeds each within {WHEEL_SPEED_LIMIT}: 2 × 0.5 %")
    rows.append(["E2", f"NORMAL X = 30°, v {v:+g} m/s", "V_b (outer front) rpm", f"{printed:.2f}",
                 f"{geometric:.2f}", f"{v_b:.1f}"])
    rows.append(["E2", "same", "rear speeds RL / RR rpm (paper: equal)", "equal", f"{targets['RL'].rpm:.2f} / "
                 f"{targets['RR'].rpm:.2f}", f"{v_d:.1f} / {v_inner_rear:.1f}"])
    bench.expect_clean_bus()
    bench.table("Errata: printed formula vs geometry vs bench (reached WHL_Status speeds)",
                ["erratum", "request", "quantity", "printed in the paper", "geometry (checked)", "bench"], rows)
    bench.note("The bench checks the geometry: E1 corrected (n4 uses x - K, [P0] eq. 10 prints x + K) and "
               "E2 corrected (V_b = V_d / cos β, [P2] §4 prints V_d × cos β; the rear wheels differ by the "
               "track). docs/spec/formulas.md §2 and §3.")
    plot_wheels(bench, "E2 request (NORMAL, X = 30°)")
