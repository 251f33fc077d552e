"""4WS: the switch between the low-speed ADAPTIVE steering and the rear-steer law at 20 km/h follows the vehicle's
speed, not the request (docs/contract/vcu-4ws.md VCU-4WS-04, vcu.md VCU-MODE-06).

ADAPTIVE with the default law (FEEDFORWARD), hand wheel 45° (front axle X = 3°), TargetSpeed stepped from 15 to
25 km/h and, once the car runs at 25 km/h, ramped back to 15 km/h at 2 m/s² (the speed changes within which
VCU-4WS-01 promises its accuracy). Below 20 km/h the rear angles mirror the front ones (vcu.md VCU-MODE-05: the
axle ratio δ_r/X = −1), at 20 km/h and above they follow k(u) (VCU-4WS-02, k(20 km/h) = −0.668), with u the
vehicle's speed. Right after the step the request is already above 20 km/h while the car is not: a VCU that
switched on |TargetSpeed| shows the wrong ratio there (the ramp, where the car lags its request by less than
1 km/h, judges the switch on the way down but cannot tell the request from the car).

Measured: the commanded axle angles (VCU_WheelCmd_xx, mean of the two wheels of an axle) and the vehicle's true
speed (PLANT_Motion.Speed). Expected: δ_r/X = −1 within ratio_abs_tol where the car runs below 20 km/h − 1 km/h,
|δ_r/X − k(u)| ≤ k_tol where it runs above 20 km/h + 1 km/h (the ±1 km/h of the speed estimate, VCU-4WS-01), and
each switch at a true speed within 20 ± 1 km/h. k(u) from testcases/rear_steer_4ws/oracle.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from testcases.rear_steer_4ws import oracle
from testcases.rear_steer_4ws.steps import SPEED_TOL, commanded_axles, limit, start

pytestmark = [pytest.mark.dut("VCU"), pytest.mark.req("VCU-4WS-04", "VCU-MODE-06", "VCU-MODE-05", "VCU-4WS-01")]

HAND_WHEEL = 45.0                     # deg: front axle X = 3° at ratio 15
LOW_KMH, HIGH_KMH = 15.0, 25.0
SWITCH_KMH = 20.0                     # docs/contract/vcu.md VCU-MODE-06
SWITCH_TOL_KMH = limit("switch_speed_tol")
RATIO_ABS_TOL = limit("ratio_abs_tol")
K_TOL = limit("k_tol")
SETTLE_S = 3.0                        # s the car gets to reach a request (10 km/h at μ g: about 0.3 s)
HOLD_S = 0.5
RAMP_ACCEL = 2.0                      # m/s²: the steepest ramp of VCU-4WS-01's accuracy clause
RAMP_PERIOD_S = 0.02                  # s: one TargetSpeed update per DRV_MotionRequest cycle


def _run_to(bench, speed_kmh: float, ramp_from_kmh: float | None = None) -> float:
    """TargetSpeed to speed_kmh (a step, or a RAMP_ACCEL ramp from ramp_from_kmh) until the car runs at it, then
    HOLD_S more; returns the bench time the change began."""
    u = round(oracle.mps(speed_kmh), 2)
    t_step = bench.now
    if ramp_from_kmh is None:
        bench.set("DRV_MotionRequest", DriveMode="ADAPTIVE", TargetSpeed=u)
    else:
        u_from = oracle.mps(ramp_from_kmh)
        duration = abs(u - u_from) / RAMP_ACCEL
        cancel: list = []

        def tick(now: float) -> None:
            frac = min(1.0, (now - t_step) / duration)
            bench.set("DRV_MotionRequest", DriveMode="ADAPTIVE", TargetSpeed=round(u_from + (u - u_from) * frac, 2))
            if frac >= 1.0:
                cancel[0]()

        cancel.append(bench.every(RAMP_PERIOD_S, tick))
        bench.run(duration)
    settled = bench.wait_until(lambda: abs(bench.value("PLANT_Motion", "Speed") - u) <= SPEED_TOL * u, SETTLE_S)
    bench.expect_true(f"the car reaches {speed_kmh:g} km/h", settled,
                      measured=round(bench.value("PLANT_Motion", "Speed"), 3), expected=f"{u} m/s ± {SPEED_TOL:.1%}")
    bench.run(HOLD_S)
    return t_step


def _ratio(bench, since: float, until: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, δ_r/X commanded, vehicle speed km/h) of the VCU_WheelCmd_FL frames in [since, until]."""
    t, front, rear = commanded_axles(bench, since, until)
    ts, speed = bench.history("PLANT_Motion", "Speed", since)
    return t, rear / front, oracle.kmh(np.interp(t, ts, speed))


def test_switch_at_20_kmh_follows_the_vehicle_speed(bench):
    v = oracle.EV
    start(bench, LOW_KMH, "FEEDFORWARD")
    bench.set("DRV_Steering", HandWheelAngle=HAND_WHEEL)
    bench.run(HOLD_S)
    t_up = _run_to(bench, HIGH_KMH)
    t_down = _run_to(bench, LOW_KMH, ramp_from_kmh=HIGH_KMH)
    rows = []
    for label, t0, t1 in (("step 15 → 25 km/h", t_up, t_down), ("ramp 25 → 15 km/h", t_down, bench.now)):
        t, k, u = _ratio(bench, t0, t1)
        k_law = np.array([oracle.zero_sideslip_ratio(v, oracle.mps(x)) for x in u])
        low = u < SWITCH_KMH - SWITCH_TOL_KMH
        high = u > SWITCH_KMH + SWITCH_TOL_KMH
        low_err = np.abs(k[low] + 1.0)
        high_err = np.abs(k[high] - k_law[high])
        bench.expect(f"{label}: δ_r/X = −1 (mirrored) while the car runs below "
                     f"{SWITCH_KMH - SWITCH_TOL_KMH:g} km/h, worst", float(low_err.max()) if low.any() else np.nan,
                     0.0, abs_tol=RATIO_ABS_TOL,
                     detail=f"{int(low.sum())} commanded frames; vcu.md VCU-MODE-05 (centre on y = 0)")
        bench.expect(f"{label}: δ_r/X = k(u) while the car runs above {SWITCH_KMH + SWITCH_TOL_KMH:g} km/h, worst",
                     float(high_err.max()) if high.any() else np.nan, 0.0, abs_tol=K_TOL,
                     detail=f"{int(high.sum())} commanded frames; docs/spec/formulas.md §5 at PLANT_Motion.Speed "
                            "(VCU-4WS-03's tolerance while the speed changes)")
        mirrored = np.abs(k + 1.0) <= RATIO_ABS_TOL
        change = np.flatnonzero(mirrored[:-1] != mirrored[1:])
        at = float(0.5 * (u[change[0]] + u[change[0] + 1])) if change.size else np.nan
        bench.expect(f"{label}: the switch at the vehicle's speed", at, SWITCH_KMH, abs_tol=SWITCH_TOL_KMH,
                     unit="km/h", detail=f"{change.size} change(s) of the ratio between −1 and k(u) "
                                         "(VCU-4WS-04: no hysteresis; VCU-4WS-01: ±1 km/h)")
        bench.expect_true(f"{label}: one switch, no chatter", change.size == 1, measured=int(change.size),
                          expected=1)
        rows.append([label, int(low.sum()), int(high.sum()), at])
    bench.table("switch between mirrored rear angles and k(u)",
                ["TargetSpeed", "frames below 19 km/h", "frames above 21 km/h", "switch at km/h"], rows)
    bench.plot("speed: request and vehicle", [("DRV_MotionRequest", "TargetSpeed"), ("PLANT_Motion", "Speed")],
               ylabel="m/s")
