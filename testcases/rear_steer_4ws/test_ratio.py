"""4WS feedforward: the zero-sideslip ratio k(u) on the bus ([P3] §2, docs/spec/formulas.md §5).

The VCU in ADAPTIVE with its default law (FEEDFORWARD, docs/contract/vcu-4ws.md VCU-4WS-02; the case codes
RearSteerLaw = FEEDFORWARD at each scenario start, docs/contract/vcu.md VCU-DIAG-02, as an earlier case may have
coded another law) steers the rear axle by k(u) times the front axle at 20 km/h and above, about one common
rotation centre, with u the VEHICLE's speed (VCU-4WS-01). Measured: the axle angles (mean of the two wheels of an
axle) commanded in VCU_WheelCmd_xx and reached in WHL_Status_xx, and the vehicle's true speed PLANT_Motion.Speed;
expected: k(u) = (−b + m a u²/(C_r L)) / (a + m b u²/(C_f L)) at that speed with docs/spec/vehicles.md A, opposite
phase below u_0 = √(b C_r L/(m a)) = 46.76 km/h and same phase above (testcases/rear_steer_4ws/oracle.py).
Issue 5's checks: opposite phase at 40 km/h, same phase at 100 km/h, sign change within 1 km/h of u_0. The car
really drives each speed (the speed changes at most at the tyres' μ g): held speeds for the 40/100 km/h checks,
slow TargetSpeed ramps for the 25-120 km/h sweep and the scan through u_0.
Also: the four commanded angles are those of a rotation about the centre in VCU_RotationCentre
(docs/spec/formulas.md §2).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.results.model import Series
from testcases.rear_steer_4ws import oracle
from testcases.rear_steer_4ws.steps import SPEED_TOL, WHEELS, axle_angles, commanded_axles, limit, start

pytestmark = [pytest.mark.dut("VCU"), pytest.mark.req("VCU-4WS-01", "VCU-4WS-02", "VCU-4WS-05")]

HAND_WHEEL = 45.0            # deg: front axle X = 3° at ratio 15
SIGN_CHANGE_TOL_KMH = limit("sign_change_tol")
RATIO_ABS_TOL = limit("ratio_abs_tol")
ANGLE_TOL = limit("angle_tol")       # deg
SETTLE_S = 4.0               # s the car gets to reach a held speed (60 km/h at μ g ≈ 1.7 s + the hub motors)
HOLD_S = 0.6                 # s at a settled speed before the angles are read (servo: 50 ms lag)
SWEEP_ACCEL = 2.0            # m/s²: TargetSpeed ramp of the sweep (chosen: the VCU's speed lags ≈ 20 ms, 0.004 in k)
SCAN_ACCEL = 0.25            # m/s²: TargetSpeed ramp through u_0 (chosen: 0.02 km/h per 20 ms request frame)
RAMP_PERIOD_S = 0.02         # s: one TargetSpeed update per DRV_MotionRequest cycle


def _set_speed(bench, u: float) -> None:
    bench.set("DRV_MotionRequest", DriveMode="ADAPTIVE", TargetSpeed=round(u, 2))


def _hold(bench, u: float) -> None:
    """TargetSpeed u until the car runs at it (PLANT_Motion.Speed within SPEED_TOL), then HOLD_S more."""
    _set_speed(bench, u)
    settled = bench.wait_until(lambda: abs(bench.value("PLANT_Motion", "Speed") - u) <= SPEED_TOL * u, SETTLE_S)
    bench.expect_true(f"the car reaches {oracle.kmh(u):.1f} km/h", settled,
                      measured=round(bench.value("PLANT_Motion", "Speed"), 3), expected=f"{u} m/s ± {SPEED_TOL:.1%}")
    bench.run(HOLD_S)


def _ramp(bench, u_from: float, u_to: float, accel: float) -> tuple[float, float]:
    """Ramp TargetSpeed from u_from to u_to at accel (one update per request cycle) and run until the car has
    followed; returns (start, end) bench times of the ramp."""
    t0 = bench.now
    duration = abs(u_to - u_from) / accel
    cancel: list = []

    def tick(now: float) -> None:
        frac = min(1.0, (now - t0) / duration)
        _set_speed(bench, u_from + (u_to - u_from) * frac)
        if frac >= 1.0:
            cancel[0]()

    cancel.append(bench.every(RAMP_PERIOD_S, tick))
    bench.run(duration + 0.5)
    return t0, t0 + duration


def _commanded_k(bench, since: float, until: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, rear axle angle commanded, k commanded, vehicle speed at t) over [since, until]."""
    t, front, rear = commanded_axles(bench, since, until)
    ts, speed = bench.history("PLANT_Motion", "Speed", since)
    return t, rear, rear / front, np.interp(t, ts, speed)


def test_feedforward_ratio_phase_and_sign_change(bench):
    v = oracle.EV
    u0 = oracle.sign_change_speed(v)
    start(bench, oracle.kmh(u0), "FEEDFORWARD")
    bench.set("DRV_Steering", HandWheelAngle=HAND_WHEEL)
    rows = []
    # -- opposite phase at 40 km/h, same phase at 100 km/h: commanded and reached, at the speed driven --------
    for speed_kmh, phase in ((40.0, "opposite"), (100.0, "same")):
        u_target = round(oracle.mps(speed_kmh), 2)
        _hold(bench, u_target)
        u = bench.value("PLANT_Motion", "Speed")
        expected = oracle.zero_sideslip_ratio(v, u)
        for source in ("VCU_WheelCmd", "WHL_Status"):
            front, rear = axle_angles(bench, source)
            k = rear / front
            sign_ok = (k < 0.0) if phase == "opposite" else (k > 0.0)
            bench.expect_true(f"{phase} phase at {speed_kmh:g} km/h ({source})", sign_ok, measured=round(k, 4),
                              expected="< 0" if phase == "opposite" else "> 0",
                              detail=f"rear {rear:.3f}° / front {front:.3f}°")
            bench.expect(f"k({speed_kmh:g} km/h) ({source})", k, expected, abs_tol=RATIO_ABS_TOL,
                         detail=f"docs/spec/formulas.md §5 k(u) at PLANT_Motion.Speed = {u:.3f} m/s, "
                                "docs/spec/vehicles.md A")
            rows.append([f"{speed_kmh:g}", source, front, rear, k, expected])
        # the four wheels about the centre the VCU reports (docs/spec/formulas.md §2)
        cx = bench.value("VCU_RotationCentre", "RotationCentreX")
        cy = bench.value("VCU_RotationCentre", "RotationCentreY")
        for w in WHEELS:
            bench.expect(f"{w} commanded angle about VCU_RotationCentre at {speed_kmh:g} km/h",
                         bench.value(f"VCU_WheelCmd_{w}", "SteerAngleCmd"), oracle.wheel_angle_about(cx, cy, w),
                         abs_tol=ANGLE_TOL, unit="deg",
                         detail=f"centre ({cx:.2f}, {cy:.2f}) m, docs/spec/formulas.md §2")
    bench.table("k(u) at 40 and 100 km/h (front/rear = axle means, deg)",
                ["km/h", "source", "front", "rear", "k measured", "k(u) docs/spec/formulas.md §5"], rows)

    # -- sweep 25-120 km/h: a slow ramp, k commanded against k(the speed driven) -------------------------------
    _hold(bench, round(oracle.mps(25.0), 2))
    t0, t1 = _ramp(bench, round(oracle.mps(25.0), 2), round(oracle.mps(120.0), 2), SWEEP_ACCEL)
    t, _, sweep_k, sweep_u = _commanded_k(bench, t0, t1)
    k_expected = np.array([oracle.zero_sideslip_ratio(v, x) for x in sweep_u])
    deviation = np.abs(sweep_k - k_expected)
    i = int(np.argmax(deviation))
    bench.expect("k(u) over 25-120 km/h, worst deviation", float(deviation[i]), 0.0, abs_tol=RATIO_ABS_TOL,
                 detail=f"commanded axle angles vs docs/spec/formulas.md §5 at PLANT_Motion.Speed; worst at "
                        f"{oracle.kmh(float(sweep_u[i])):.1f} km/h ({len(t)} frames, ramp {SWEEP_ACCEL:g} m/s²)")

    # -- scan through u_0: the speed at which the commanded rear angle changes sign -----------------------------
    lo, hi = round(u0 - oracle.mps(2.0), 2), round(u0 + oracle.mps(2.0), 2)
    _hold(bench, lo)
    t0, t1 = _ramp(bench, lo, hi, SCAN_ACCEL)
    t, rear, scan_k, scan_u = _commanded_k(bench, t0, t1)
    crossing = math.nan
    up = np.flatnonzero((rear[:-1] < 0.0) & (rear[1:] >= 0.0))
    if up.size:
        crossing = oracle.kmh(0.5 * float(scan_u[up[0]] + scan_u[up[0] + 1]))
    bench.expect("k(u) changes sign at u_0 = √(b C_r L/(m a))", crossing, oracle.kmh(u0),
                 abs_tol=SIGN_CHANGE_TOL_KMH, unit="km/h",
                 detail=f"vehicle speed (PLANT_Motion.Speed) at the first commanded rear-axle angle ≥ 0 after a "
                        f"negative one, TargetSpeed ramp {SCAN_ACCEL:g} m/s²")
    curve_u = [20.0 + i for i in range(101)]
    bench.plot_series("k(u): rear/front axle angle commanded by the VCU (FEEDFORWARD) vs docs/spec/formulas.md §5",
                      [Series("k(u) docs/spec/formulas.md §5", curve_u,
                              [oracle.zero_sideslip_ratio(v, oracle.mps(s)) for s in curve_u]),
                       Series("VCU sweep (VCU_WheelCmd)", oracle.kmh(sweep_u).tolist(), sweep_k.tolist()),
                       Series("VCU scan near u_0", oracle.kmh(scan_u).tolist(), scan_k.tolist())],
                      xlabel="vehicle speed PLANT_Motion.Speed [km/h]", ylabel="k = δ_r/δ_f [-]")
    bench.table("sign change of k(u)", ["quantity", "value"],
                [["u_0 = √(b C_r L/(m a)) (docs/spec/formulas.md §5, docs/spec/vehicles.md A)",
                  f"{oracle.kmh(u0):.2f} km/h"],
                 ["sign change measured on the bus (vehicle speed)", f"{crossing:.2f} km/h"],
                 ["k(40 km/h), k(100 km/h) (docs/spec/formulas.md §5)",
                  f"{oracle.zero_sideslip_ratio(v, 40 / 3.6):.4f}, {oracle.zero_sideslip_ratio(v, 100 / 3.6):.4f}"]])
    bench.plot("axle angles during the sweep", [(f"VCU_WheelCmd_{w}", "SteerAngleCmd", f"{w} commanded")
                                                for w in WHEELS], ylabel="deg")
