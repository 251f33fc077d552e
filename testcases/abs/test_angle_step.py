"""ABS turning-state identification: hand-wheel angle step while braking under ABS on a dry road ([P4] §4,
Fig. 6-8; §3.2 the identification during ABS control; docs/spec/formulas.md §6).

Scenario (chosen: [P4] gives no speed or pressure): 60 km/h straight on a dry road (RoadMu 1.0), wheel-speed
noise on; at 0.3 s the driver brakes with 80 bar (DRV_Pedals.BrakePressure): the lightly loaded rear axle comes
under ABS control while the car still brakes straight; at 1.2 s (about 35 km/h) the hand wheel steps to 180 deg
(i_w 18: delta about 10 deg) left or right, and stays there until the car stops.

Checks: the ABS is active at the step; TurnDirection reaches the turn's value (1 left) within step_latency_max
and never the opposite value (the latency is reported); over the window from the first published
FrontWheelAngleEst after the identification ([P4] §4: delta-bar is computed after T is identified) until
the true speed falls below step_window_min_speed, RefVehicleSpeed - true CoG speed and FrontWheelAngleEst -
true angle against the paper's mean and max (limits [abs] step_*, the paper's table).
"""

from __future__ import annotations

import numpy as np
import pytest

from testcases.abs import steps

SPEED = 60.0            # km/h
PRESSURE = 80.0         # bar
T_BRAKE, T_STEP = 0.3, 1.2
HAND_WHEEL = 180.0      # deg ([P4] §4)
RUN_AFTER_STEP = 2.4    # s: the car stops
TEST = "angle step while braking under ABS (Fig. 6-8)"


@pytest.mark.parametrize("side", ["left", "right"])
@pytest.mark.dut("ABS")
@pytest.mark.req("ABS-TURN-01", "ABS-TURN-04", "ABS-EST-01", "ABS-EST-02", "ABS-FLT-01")
def test_abs_angle_step_under_abs(bench, side: str) -> None:
    hand_wheel = -HAND_WHEEL if side == "left" else HAND_WHEEL
    expected_turn = 1 if side == "left" else -1
    steps.start(bench, SPEED)
    bench.run(T_BRAKE)
    steps.brake(bench, PRESSURE)
    bench.run(T_STEP - T_BRAKE)
    bench.expect("ABS active before the step (AbsActive)", bench.value("ABS_SteerState", "AbsActive"), 1,
                 detail="[P4] §4: the angle step comes during straight-line ABS braking")
    bench.expect("TurnDirection straight before the step", bench.value("ABS_SteerState", "TurnDirection"), 0)
    steps.steer(bench, hand_wheel)
    t_step = bench.elapsed
    bench.run(RUN_AFTER_STEP)

    d = steps.paired(bench)
    after = d["t"] >= t_step
    hit = np.flatnonzero(after & (d["turn"] == expected_turn))
    wrong = np.flatnonzero(d["turn"] == -expected_turn)
    latency = float(d["t"][hit[0]] - t_step) if hit.size else float("nan")
    bench.expect_between(f"TurnDirection = {expected_turn} after the step: latency", latency, 0.0,
                         steps.limit("step_latency_max"), unit="s", detail=steps.source("step_latency_max"))
    bench.expect_true("TurnDirection never shows the opposite turn", wrong.size == 0, measured=int(wrong.size),
                      expected=0, detail=f"first at {d['t'][wrong[0]]:.2f} s" if wrong.size else "")
    published = np.flatnonzero(after & (d["turn"] == expected_turn) & (d["angle"] != 0.0))
    t0 = float(d["t"][published[0]]) if published.size else float("inf")
    window = (d["t"] >= t0) & (d["v_true"] >= steps.limit("step_window_min_speed")) & (d["active"] == 1)
    window &= np.isfinite(d["v_true"]) & np.isfinite(d["angle_true"])
    bench.expect_true("accuracy window has samples (delta-bar published, ABS active, above the window speed)",
                      int(window.sum()) >= 20, measured=int(window.sum()), expected=">= 20 frames",
                      detail=f"from {t0:.2f} s; {steps.source('step_window_min_speed')}")
    v_mean, v_max = steps.error_stats(d["ref"][window] - d["v_true"][window])
    a_mean, a_max = steps.error_stats(steps.paper_angle_error(d["angle"][window], d["angle_true"][window]))
    for what, value, name in (("RefVehicleSpeed error mean |.|", abs(v_mean), "step_ref_speed_mean_max"),
                              ("RefVehicleSpeed error max |.|", v_max, "step_ref_speed_abs_max"),
                              ("FrontWheelAngleEst error mean |.|", abs(a_mean), "step_angle_mean_max"),
                              ("FrontWheelAngleEst error max |.|", a_max, "step_angle_abs_max")):
        bench.expect_between(what, value, 0.0, steps.limit(name), unit=steps.LIMITS[name][1],
                             detail=steps.source(name))
    bench.expect_true("no AbsFault", bool(np.all(bench.history("ABS_SteerState", "AbsFault")[1] == 0)),
                      measured=int(np.max(bench.history("ABS_SteerState", "AbsFault")[1])), expected=0)
    steps.paper_table(bench, TEST, [(f"{side}", expected_turn if hit.size else 0, v_mean, v_max, a_mean, a_max)])
    bench.table("identification after the step", ["quantity", "value"],
                [["TurnDirection latency", f"{latency:.3f} s"],
                 ["FrontWheelAngleEst first published", f"{t0 - t_step:.3f} s after the step"],
                 ["speed at the step", f"{float(np.interp(t_step, d['t'], d['v_true'])):.1f} km/h"],
                 ["accuracy window", f"{int(window.sum())} frames, {t0:.2f} s .. speed < "
                                     f"{steps.limit('step_window_min_speed'):g} km/h"]])
    bench.note(f"{side} step of the hand wheel to {hand_wheel:+g} deg (bus sign) at {t_step:.2f} s while braking with "
               f"{PRESSURE:g} bar from {SPEED:g} km/h on RoadMu 1.0, SensorNoise {steps.NOMINAL_NOISE} km/h. The "
               f"reference ECU releases the rear axle once the turn is identified and takes delta from it (its "
               f"documented strategy for [P4] §3.2 step 3); delta errors in the paper's sign (left positive).")
    steps.plot_abs(bench)
