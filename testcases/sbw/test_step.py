"""SBW hand-wheel angle step at 50 km/h ([P1] §4.1, docs/spec/formulas.md §4; issue 4).

The robot steps the hand wheel to the angle that gives the plain 15:1 car a steady lateral acceleration of
3 m/s² (docs/spec/formulas.md §5: θ_h = 15 a_y / (u · r/δ_f), about 48°). Checks: the steady lateral acceleration
(3 ± 0.3 m/s²); the pinion follows the hand wheel with a steady error ≤ 0.5° and reaches 90 % at most
50 ms after the hand wheel does; the yaw rate's ISO 7401 figures (response time to 90 %, peak response time,
overshoot, from the instant the hand wheel reaches 50 %) next to the linear 2-DOF model's prediction for a
mechanical 15:1 steering driven by the same hand wheel; and the vehicle in the loop against the same model
driven by the true pinion angle (PLANT_SbwAngles, with the simulated or an external SBW alike), a check of the
plant (`PLANT-DYN-02`): its step names PLANT, so it is the plant's verdict, never the SBW's
(docs/contract/README.md). Limits: testcases/sbw/limits.toml [sbw].
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.results.model import Series
from testcases.sbw import oracle
from testcases.sbw.steps import (
    Limits,
    plot_steering,
    predicted_yaw,
    robot_angle,
    signal,
    start,
    steady,
)

HOLD_BEFORE = 0.5     # s straight before the step
HOLD_AFTER = 3.0      # s after the step (the 2-DOF yaw response settles within about 1 s)
RATIO = 1.0 / oracle.STEERING_RATIO   # road-wheel angle per hand-wheel (pinion) angle


@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-CTL-01", "SBW-CTL-02", "SBW-OUT-01", "SBW-OUT-02", "PLANT-DYN-02", "COM-E2E-01", "COM-E2E-02",
                 "COM-VAL-01")
def test_sbw_step_50kmh(bench) -> None:
    lim = Limits(bench)
    u = start(bench, lim["step_speed"])
    target = round(oracle.hand_wheel_for_lat_accel(u, lim["step_lat_accel"]), 2)
    bench.note(f"u = {u} m/s (BENCH_Control.InitialSpeed); hand-wheel step to {target}° "
               f"(docs/spec/formulas.md §5: 15 · a_y / (u · r/δ_f), r/δ_f = {oracle.yaw_gain(u):.4f} 1/s, "
               f"K_s = {oracle.stability_factor():.3e} s²/m²)")
    robot_angle(bench, 0.0)
    bench.run(HOLD_BEFORE)
    robot_angle(bench, target)
    bench.run(HOLD_AFTER)

    # steady state
    lim.condition("speed (PLANT_Motion.Speed)", "step_speed", steady(bench, "PLANT_Motion", "Speed") * 3.6, "km/h")
    lim.within("steady lateral acceleration (IMU_Motion.LatAccel)", "step_lat_accel", "step_lat_accel_tol",
               steady(bench, "IMU_Motion", "LatAccel"))
    hand, pinion = steady(bench, "SBW_HandWheel", "HandWheelAngle"), steady(bench, "SBW_Pinion", "PinionAngle")
    lim.at_most("steady |hand wheel − pinion| (SBW_HandWheel, SBW_Pinion)", "step_steady_error_max",
                abs(hand - pinion), detail=f"hand wheel {hand:.2f}°, pinion {pinion:.2f}°")

    # pinion lag: 90 % of the final angle, each against its own final value
    th, hw = signal(bench, "SBW_HandWheel", "HandWheelAngle")
    tp, pin = signal(bench, "SBW_Pinion", "PinionAngle")
    t90_hand = oracle.crossing_time(th, hw, 0.9 * hand)
    t90_pinion = oracle.crossing_time(tp, pin, 0.9 * pinion)
    lim.at_most("pinion reaches 90 % after the hand wheel", "step_t90_lag_max", t90_pinion - t90_hand,
                detail=f"hand wheel at {t90_hand:.4f} s, pinion at {t90_pinion:.4f} s (linear interpolation "
                       f"between the 10 ms frames)")

    # yaw rate: ISO 7401 figures, measured vs the 2-DOF model with a mechanical 15:1 steering
    ty, yaw = signal(bench, "IMU_Motion", "YawRate")
    measured = oracle.step_metrics(th, hw, ty, yaw)
    t_pred, r_pred, ay_pred = predicted_yaw(bench, u, ("SBW_HandWheel", "HandWheelAngle"), RATIO)
    predicted = oracle.step_metrics(th, hw, t_pred, r_pred)
    ideal = oracle.ideal_step_metrics(u)
    lim.relative("steady yaw rate vs the 2-DOF model (mechanical 15:1)", "step_yaw_steady_rel_tol",
                 measured.steady, predicted.steady, "deg/s")
    lim.at_most("ISO 7401 response time minus the 2-DOF model's", "step_response_time_excess_max",
                measured.response_time - predicted.response_time,
                detail=f"measured {measured.response_time:.4f} s, model {predicted.response_time:.4f} s")
    bench.table("yaw-rate response, ISO 7401 (time origin: hand wheel at 50 %)",
                ["metric", "2-DOF, ideal road-wheel step", "2-DOF, measured hand wheel / 15", "measured (IMU_Motion)",
                 "unit"],
                [["steady yaw rate", ideal.steady * hand / oracle.STEERING_RATIO, predicted.steady, measured.steady,
                  "deg/s"],
                 ["steady yaw gain r/δ_f (closed form §5; measured with SBW_Pinion / 15)", oracle.yaw_gain(u),
                  predicted.steady / (hand / oracle.STEERING_RATIO), measured.steady / (pinion / oracle.STEERING_RATIO),
                  "1/s"],
                 ["response time (90 %)", ideal.response_time, predicted.response_time, measured.response_time, "s"],
                 ["peak response time", ideal.peak_time, predicted.peak_time, measured.peak_time, "s"],
                 ["overshoot", ideal.overshoot * 100.0, predicted.overshoot * 100.0, measured.overshoot * 100.0, "%"]])

    # the vehicle in the loop: its yaw rate vs the 2-DOF model driven by the true pinion angle (the plant's own,
    # PLANT_SbwAngles: an SBW's measured value is 0.1° and 10 ms coarse, PLANT-IO-SBW-01)
    t_pin, r_pin, _ = predicted_yaw(bench, u, ("PLANT_SbwAngles", "PinionAngle"), RATIO)
    tm, yaw_truth = signal(bench, "PLANT_Motion", "YawRate")
    deviation = float(np.max(np.abs(np.interp(t_pin, tm, yaw_truth) - r_pin)))
    lim.at_most("max |PLANT_Motion.YawRate − 2-DOF model fed with PLANT_SbwAngles.PinionAngle / 15|",
                "model_yaw_rate_abs_tol",
                deviation, node="PLANT")   # the plant's check (PLANT-DYN-02), never the SBW's

    bench.check_cycle_times(["SBW_HandWheel", "SBW_Pinion", "IMU_Motion"])
    bench.expect_clean_bus()
    lim.report()
    plot_steering(bench, "step 50 km/h",
                  extra_yaw=[Series("2-DOF model, hand wheel / 15 (mechanical car)", t_pred.tolist(), r_pred.tolist()),
                             Series("2-DOF model, true pinion / 15", t_pin.tolist(), r_pin.tolist())],
                  extra_ay=[Series("2-DOF model, hand wheel / 15", t_pred.tolist(), ay_pred.tolist())])

