"""ABS turning-state identification in steady-state circular driving ([P4] §4, Fig. 3-5; docs/spec/formulas.md §6).

Hand wheel 180 deg at i_w = 18 (delta about 10 deg), left and right, at two speeds, wheel-speed noise on
(BENCH_Control.SensorNoise 0.1 km/h); the drive robot holds the speed (BENCH_AbsStimulus.CruiseSpeed), no
braking: the ABS identifies the turn before braking ([P4] §3.1: eq. 5-13). After steady_settle s the
checks, over steady_window s of ABS_SteerState frames, each paired with the truth of the same instant:
TurnDirection correct (1 = left for a negative, i.e. left, hand-wheel angle; docs/spec/formulas.md §1) in at least
99 % of the samples; RefVehicleSpeed - true CoG speed and FrontWheelAngleEst - true front-wheel angle within
the paper's mean and max (limits [abs] steady_*, the paper's table). The paper's delta_f = theta / i_w is
checked against the plant's true angle too (the reference the paper used).
"""

from __future__ import annotations

import numpy as np
import pytest

from testcases.abs import oracle, steps

HAND_WHEEL = 180.0      # deg ([P4] §4)
SPEEDS = (25.0, 40.0)   # km/h (chosen: a_y about 2.6 and 6.6 m/s^2 at delta 10 deg)
WINDOW = 5.0            # s of samples after settling
CASES = [(v, side) for v in SPEEDS for side in ("left", "right")]
TEST = "steady-state circular (Fig. 3-5)"


@pytest.mark.parametrize("speed,side", CASES, ids=[f"{v:g} km/h {s}" for v, s in CASES])
@pytest.mark.dut("ABS")
@pytest.mark.req("ABS-TURN-01", "ABS-TURN-02", "ABS-EST-01", "ABS-EST-02", "ABS-OUT-02", "ABS-FLT-01")
def test_abs_steady_circular(bench, speed: float, side: str) -> None:
    hand_wheel = -HAND_WHEEL if side == "left" else HAND_WHEEL     # bus: positive right
    expected_turn = 1 if side == "left" else -1                   # TurnDirection: 1 = left ([P4])
    steps.start(bench, speed)
    steps.hold_speed(bench, speed)
    steps.steer(bench, hand_wheel)
    settle = steps.limit("steady_settle")
    bench.run(settle + WINDOW)
    d = steps.paired(bench, since=bench.start + settle)
    ok = np.isfinite(d["v_true"]) & np.isfinite(d["angle_true"])
    bench.expect_true("every ABS_SteerState frame paired with the truth of its instant", bool(ok.all()) and ok.size > 0,
                      measured=f"{int(ok.sum())} of {ok.size}", expected="all")
    d = {k: v[ok] for k, v in d.items()}

    correct = float(np.mean(d["turn"] == expected_turn))
    bench.expect_true(f"TurnDirection = {expected_turn} in >= 99 % of the samples",
                      correct >= steps.limit("steady_turn_correct_min"), measured=round(correct, 4),
                      expected=f">= {steps.limit('steady_turn_correct_min')}",
                      detail=steps.source("steady_turn_correct_min"))
    v_mean, v_max = steps.error_stats(d["ref"] - d["v_true"])
    a_mean, a_max = steps.error_stats(steps.paper_angle_error(d["angle"], d["angle_true"]))
    for what, value, name in (("RefVehicleSpeed error mean |.|", abs(v_mean), "steady_ref_speed_mean_max"),
                              ("RefVehicleSpeed error max |.|", v_max, "steady_ref_speed_abs_max"),
                              ("FrontWheelAngleEst error mean |.|", abs(a_mean), "steady_angle_mean_max"),
                              ("FrontWheelAngleEst error max |.|", a_max, "steady_angle_abs_max")):
        bench.expect_between(what, value, 0.0, steps.limit(name), unit=steps.LIMITS[name][1],
                             detail=steps.source(name))
    # the paper's reference angle theta / i_w against the plant's true angle (mechanical steering)
    reference = oracle.front_wheel_angle_from_hand_wheel(hand_wheel)
    bench.expect("true front-wheel angle = theta / i_w ([P4] §4)", float(np.mean(d["angle_true"])), reference,
                 abs_tol=0.01, unit="deg", detail="PLANT_AbsVehicle.FrontWheelAngle; 0.01 deg = its resolution")
    bench.expect_true("no AbsFault", bool(np.all(bench.history("ABS_SteerState", "AbsFault")[1] == 0)),
                      measured=int(np.max(bench.history("ABS_SteerState", "AbsFault")[1])), expected=0)
    steps.paper_table(bench, TEST, [(f"{side}, {speed:g} km/h", int(np.round(np.median(d["turn"]))),
                                      v_mean, v_max, a_mean, a_max)])
    bench.note(f"{side} turn, hand wheel {hand_wheel:+g} deg (bus sign), i_w 18, {speed:g} km/h held by the drive "
               f"robot, SensorNoise {steps.NOMINAL_NOISE} km/h; statistics over {WINDOW:g} s after {settle:g} s; "
               f"delta errors in the paper's sign (left positive).")
    steps.plot_abs(bench)
