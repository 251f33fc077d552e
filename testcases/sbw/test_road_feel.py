"""SBW road feel at 50 km/h: driver torque against lateral acceleration in a slow ramp, and the hand wheel's
return when the driver lets go ([P1] §2.3: the force-control / position-deviation structure gives the
driver the torque that steers the road wheels and "takes care of the return"; issue 4).

The robot turns the hand wheel slowly (constant rate) from 0 to the angle that gives the plain 15:1 car about
4 m/s² (docs/spec/formulas.md §5), holds it, then lets go (RobotMode OFF). Checks: the driver torque the SBW measures
(SBW_HandWheel.DriverTorque) grows monotonically with the lateral acceleration (IMU_Motion.LatAccel) — the
means of consecutive lateral-acceleration bins never fall by more than one LSB —; after `return_time` hands
off, the hand-wheel angle is at most `return_fraction_max` of the angle at release. Limits: testcases/sbw/limits.toml.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.results.model import Series
from testcases.sbw import oracle
from testcases.sbw.steps import Limits, plot_steering, robot_angle, signal, start

SPEED_KMH = 50.0
RAMP_LAT_ACCEL = 4.0     # m/s², end of the ramp for the plain car (docs/spec/formulas.md §5)
RAMP_TIME = 6.0          # s
HOLD = 1.0               # s at the end of the ramp before letting go


@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-CTL-01", "SBW-CTL-04", "COM-E2E-01", "COM-E2E-02", "COM-VAL-01")
def test_sbw_road_feel_50kmh(bench) -> None:
    lim = Limits(bench)
    u = start(bench, SPEED_KMH)
    end = oracle.hand_wheel_for_lat_accel(u, RAMP_LAT_ACCEL)
    bench.note(f"u = {u} m/s; ramp 0 → {end:.1f}° in {RAMP_TIME:g} s ({end / RAMP_TIME:.1f} °/s), hold {HOLD:g} s, "
               f"then hands off for {lim['return_time']:g} s")
    robot_angle(bench, 0.0)
    bench.run(0.3)
    ramp_start = bench.now
    steps = round(RAMP_TIME / 0.01)
    for k in range(1, steps + 1):
        robot_angle(bench, end * k / steps)
        bench.run(0.01)
    ramp_end = bench.now
    bench.run(HOLD)
    release = bench.now
    angle_at_release = bench.value("SBW_HandWheel", "HandWheelAngle")
    bench.set("BENCH_SteeringRobot", RobotMode="OFF")
    bench.run(lim["return_time"])
    angle_after = bench.value("SBW_HandWheel", "HandWheelAngle")

    # driver torque vs lateral acceleration during the ramp
    tt, torque = signal(bench, "SBW_HandWheel", "DriverTorque", ramp_start)
    ta, ay = signal(bench, "IMU_Motion", "LatAccel", ramp_start)
    in_ramp = tt <= ramp_end - bench.start
    tt, torque = tt[in_ramp], torque[in_ramp]
    ay_at = np.interp(tt, ta, ay)
    ok, means = oracle.is_monotonic_increasing(ay_at, torque, lim["road_feel_bin"], lim["road_feel_torque_slack"])
    drops = [b[1] - a[1] for a, b in zip(means, means[1:])]
    worst = min(drops) if drops else float("nan")
    bench.expect_true("driver torque grows monotonically with lateral acceleration (ramp)", ok,
                      measured=f"{len(means)} bins, smallest step {worst:+.3f} N·m",
                      expected=f"every step > −{lim['road_feel_torque_slack']:g} N·m (road_feel_torque_slack)",
                      detail=f"bins of {lim['road_feel_bin']:g} m/s² (road_feel_bin) over "
                             f"{ay_at.min():.2f} … {ay_at.max():.2f} m/s²")
    lim.rows.append(["driver torque monotonic in lateral acceleration (smallest step between bins)",
                     "sbw.road_feel_torque_slack, sbw.road_feel_bin",
                     f"> −{lim['road_feel_torque_slack']:g} N·m per {lim['road_feel_bin']:g} m/s² bin",
                     f"{worst:+.4g} N·m", "pass" if ok else "FAIL"])
    bench.table("driver torque per lateral-acceleration bin (ramp)",
                ["lateral acceleration [m/s²]", "mean driver torque [N·m]", "slope from the previous bin [N·m/(m/s²)]"],
                [[c, m, (m - means[i - 1][1]) / (c - means[i - 1][0]) if i else ""] for i, (c, m) in enumerate(means)])

    # return to centre hands off
    fraction = abs(angle_after) / abs(angle_at_release) if angle_at_release else float("nan")
    lim.at_most(f"hand-wheel angle {lim['return_time']:g} s after letting go, of the angle at release",
                "return_fraction_max", fraction,
                detail=f"{angle_at_release:.1f}° at release, {angle_after:.1f}° after (SBW_HandWheel.HandWheelAngle)")
    lim.condition("hands off for", "return_time", bench.now - release)

    bench.expect_clean_bus()
    lim.report()
    bench.plot_series("driver torque against lateral acceleration (ramp)",
                      [Series("SBW_HandWheel.DriverTorque", ay_at.tolist(), torque.tolist()),
                       Series("bin means", [c for c, _ in means], [m for _, m in means])],
                      xlabel="lateral acceleration (IMU_Motion.LatAccel) [m/s²]", ylabel="driver torque [N·m]")
    plot_steering(bench, f"ramp and release (hands off from {release - bench.start:.2f} s)")
