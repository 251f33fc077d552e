"""4WS at a speed step: the rear steers by k(the vehicle's speed), never by k(TargetSpeed) (issue 13, item 11).

ADAPTIVE with FEEDFORWARD (the default law, docs/contract/vcu-4ws.md VCU-4WS-02), 3° of front steer, TargetSpeed
stepped from 100 to 30 km/h. The car cannot lose 70 km/h at once: its tyres give at most μ g (about 2 s on the
dry road), so for that time the car still runs well above u_0 = 46.8 km/h, where k(u) > 0 asks for the rear in
the SAME phase as the front. A VCU that evaluated k at |TargetSpeed| (the old reference VCU) steered it at once
in OPPOSITE phase (k(30 km/h) = −0.39) at 100 km/h: the destabilising case 4WS exists to avoid.

Measured: the commanded and reached axle angles (VCU_WheelCmd_xx, WHL_Status_xx; mean of the two wheels of an
axle) and the vehicle's true speed (PLANT_Motion.Speed) throughout the deceleration. Expected: the phase and the
value of k(u) (docs/spec/formulas.md §5, [P3] §2) at the measured speed, from testcases/rear_steer_4ws/oracle.py;
phase only where |k| ≥ PHASE_BAND (near u_0 the sign is within the speed estimate's tolerance). Also the plant's ground
truth: the deceleration stays within what the tyres can give (docs/contract/plant.md PLANT-DYN-03), a step that
names PLANT: the plant's verdict, never the VCU's.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.results.model import Series
from testcases.rear_steer_4ws import oracle
from testcases.rear_steer_4ws.steps import commanded_axles, limit, start

pytestmark = [pytest.mark.dut("VCU"), pytest.mark.req("VCU-4WS-01", "VCU-4WS-02", "VCU-4WS-03", "PLANT-DYN-03")]

HAND_WHEEL = 45.0           # deg: front axle 3° at ratio 15
FROM_KMH, TO_KMH = 100.0, 30.0
HOLD_BEFORE_S = 1.0
HOLD_AFTER_S = 3.5          # the tyres need about 2 s for 70 km/h at μ = 1
PHASE_BAND = limit("phase_band")     # |k| below this (u within about ±2.5 km/h of u_0): no phase verdict
K_TOL = limit("k_tol")               # VCU-4WS-01: the speed estimate within ±1 km/h + 10 ms frames
REACHED_PHASE_BAND = limit("reached_phase_band")   # the reached angles lag the command by the servo
MU = 1.0
G = 9.81
DECEL_MARGIN = 0.02         # PLANT-DYN-03


def _axle(bench, source: str, signal: str, since: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, front, rear) of an axle-mean angle history, on the FL frames' times. The VCU's commands: each wheel's
    frame of the same cycle (`commanded_axles`: one sender, four frames per cycle). The reached angles come from
    four wheel ECUs, each on a cycle of its own: interpolated to the FL frame's time."""
    if source == "VCU_WheelCmd":
        return commanded_axles(bench, since)
    t, fl = bench.history(f"{source}_FL", signal, since)
    series = [np.interp(t, *bench.history(f"{source}_{w}", signal, since)) for w in ("FR", "RL", "RR")]
    return t, 0.5 * (fl + series[0]), 0.5 * (series[1] + series[2])


def test_speed_step_100_to_30_kmh_rear_phase_follows_the_vehicle_speed(bench):
    v = oracle.EV
    start(bench, FROM_KMH, "FEEDFORWARD", mu=MU)
    bench.set("DRV_Steering", HandWheelAngle=HAND_WHEEL)
    bench.run(HOLD_BEFORE_S)
    t_step = bench.now
    bench.set("DRV_MotionRequest", DriveMode="ADAPTIVE", TargetSpeed=round(oracle.mps(TO_KMH), 2))
    bench.run(HOLD_AFTER_S)

    ts, speed = bench.history("PLANT_Motion", "Speed", t_step)
    rows, worst = [], {}
    for source, signal, band in (("VCU_WheelCmd", "SteerAngleCmd", PHASE_BAND),
                                 ("WHL_Status", "SteerAngle", REACHED_PHASE_BAND)):
        t, front, rear = _axle(bench, source, signal, t_step)
        u = np.interp(t, ts, speed)
        k_expected = np.array([oracle.zero_sideslip_ratio(v, x) for x in u])
        k = rear / front
        judged = np.abs(k_expected) >= band
        wrong = judged & (np.sign(k) != np.sign(k_expected))
        first = float(t[wrong][0] - t_step) if wrong.any() else float("nan")
        bench.expect_true(f"rear phase = phase of k(vehicle speed) throughout ({source})", not wrong.any(),
                          measured=f"{int(wrong.sum())} of {int(judged.sum())} frames wrong",
                          expected="0 wrong",
                          detail=(f"first wrong {first:.3f} s after the step at {oracle.kmh(u[wrong][0]):.1f} km/h: "
                                  f"k = {k[wrong][0]:+.3f}, k(u) = {k_expected[wrong][0]:+.3f}" if wrong.any()
                                  else f"|k(u)| ≥ {band} judged; docs/spec/formulas.md §5"))
        same = judged & (k_expected > 0)
        bench.expect_true(f"same phase while the car is above u_0 after the step ({source})",
                          bool(same.any()) and bool(np.all(k[same] > 0)),
                          measured=f"{int(same.sum())} frames above u_0, "
                                   f"{oracle.kmh(u[same]).max() if same.any() else 0:.1f} km/h the fastest",
                          expected="> 0 frames, all k > 0")
        if source == "VCU_WheelCmd":
            err = np.abs(k - k_expected)
            i = int(np.argmax(err))
            worst = {"err": float(err[i]), "u": oracle.kmh(float(u[i])), "t": float(t[i] - t_step)}
            bench.expect("k commanded vs k(vehicle speed), worst over the deceleration", float(err[i]), 0.0,
                         abs_tol=K_TOL, detail=f"at {worst['u']:.1f} km/h, {worst['t']:.3f} s after the step "
                                               "(VCU-4WS-01: speed estimate ±1 km/h)")
            curve = Series("k(PLANT_Motion.Speed), docs/spec/formulas.md §5", (t - t_step).tolist(),
                           k_expected.tolist())
            measured = Series("rear/front commanded (VCU_WheelCmd)", (t - t_step).tolist(), k.tolist())
            bench.plot_series("k during the 100 → 30 km/h step", [curve, measured],
                              xlabel="time since the step [s]", ylabel="k = δ_r/δ_f [-]")
        rows.append([source, int(judged.sum()), int(wrong.sum())])

    # the car actually slowed down through u_0 (the case judged both phases) and arrived
    bench.expect("speed after the step", float(speed[-1]), round(oracle.mps(TO_KMH), 2), abs_tol=0.05, unit="m/s")
    _, long_accel = bench.history("PLANT_Dynamics", "LongAccel", t_step)
    bench.expect_between("deceleration within the tyres' limit (PLANT_Dynamics.LongAccel)", float(long_accel.min()),
                         -MU * G * (1.0 + DECEL_MARGIN), 0.5, unit="m/s²",
                         detail=f"μ g = {MU * G:.2f} m/s² + {DECEL_MARGIN:.0%} (PLANT-DYN-03)",
                         node="PLANT")   # the plant's physics, never the VCU's verdict
    bench.table("frames judged (|k(u)| beyond the band around u_0)", ["source", "judged", "wrong phase"], rows)
    bench.plot("speed: request and vehicle", [("DRV_MotionRequest", "TargetSpeed"), ("PLANT_Motion", "Speed"),
                                              ("VCU_VehicleState", "VehicleSpeed")], ylabel="m/s")
