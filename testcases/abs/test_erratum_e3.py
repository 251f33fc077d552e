"""Erratum E3 of [P4] eq. 13 (docs/spec/formulas.md §6), shown on the bench.

Printed: T = -1 if V_l0 < -dV1, -dV2 < V_l1 and -ddV < V_l2. With ddV = |dV1 - dV2| >= 0, "-ddV < V_l2" is
always true, so the right-turn branch never applies the axle-consistency check the left-turn branch applies.
Corrected (what the bench checks): ddV < V_l2 for both signs.

The bench drives tight steady turns both ways (hand wheel +/-810 deg: delta = 45 deg at i_w 18, 20 km/h held by
the drive robot), where ddV = B r (1 - cos delta) (eq. 8) exceeds V_l2 while dV1 and dV2 are well inside
(V_l0, V_l1). The oracle (testcases/abs/oracle.py) evaluates both versions of eq. 13 on the mean bus wheel
speeds (ABS_WheelSpeeds) of the settled window, with the ECU's thresholds (steps.thresholds: the reference's
limits [abs] ecu_v_l*, an external ABS's bench.toml [calibration.ABS]):
- the corrected rule gives 0 both ways, the printed rule gives 0 for the left turn but -1 for the right one
  (the erratum changes the result here: the scenario demonstrates it);
- the ECU's TurnDirection is the corrected rule's value, the same for both directions (>= 99 % of samples).
"""

from __future__ import annotations

import numpy as np
import pytest

from testcases.abs import oracle, steps

SPEED = 20.0         # km/h
HAND_WHEEL = 810.0   # deg: delta 45 deg
SETTLE, WINDOW = 3.0, 3.0


@steps.NEEDS_THRESHOLDS
@pytest.mark.dut("ABS")
@pytest.mark.req("ABS-TURN-01", "ABS-TURN-03", "ABS-OUT-01")
def test_abs_erratum_e3(bench) -> None:
    l0, l1, l2, calibration = steps.thresholds(bench)
    rows = []
    results = {}
    for side, hand_wheel in (("left", -HAND_WHEEL), ("right", HAND_WHEEL)):
        steps.start(bench, SPEED)
        steps.hold_speed(bench, SPEED)
        steps.steer(bench, hand_wheel)
        bench.run(SETTLE + WINDOW)
        d = steps.paired(bench, since=bench.start + SETTLE)
        means = [float(np.nanmean(d[f"ws_{w}"])) for w in steps.WHEELS]
        dv1, dv2, ddv = oracle.axle_differences(*means)
        printed = oracle.turn_printed(dv1, dv2, ddv, l0, l1, l2)
        corrected = oracle.turn_corrected(dv1, dv2, ddv, l0, l1, l2)
        share = float(np.mean(d["turn"] == corrected))
        results[side] = (printed, corrected)
        bench.expect_true(f"{side}: dV1, dV2 inside (V_l0, V_l1) and ddV >= V_l2 (the E3 situation)",
                          l0 < abs(dv1) < l1 and l0 < abs(dv2) < l1 and ddv >= l2 and dv1 * dv2 > 0,
                          measured=f"dV1 {dv1:+.2f}, dV2 {dv2:+.2f}, ddV {ddv:.2f} km/h",
                          expected=f"{l0:g} < |dV| < {l1:g}, ddV >= {l2:g}",
                          detail="eq. 6-8 on the mean ABS_WheelSpeeds of the settled window")
        bench.expect_between(f"{side}: share of TurnDirection = corrected eq. 13 ({corrected})", share,
                             steps.limit("steady_turn_correct_min"), 1.0,
                             detail=steps.source("steady_turn_correct_min"))
        rows.append([side, f"{hand_wheel:+g}", f"{dv1:+.2f}", f"{dv2:+.2f}", f"{ddv:.2f}", printed, corrected,
                     int(np.round(np.median(d["turn"])))])
        steps.plot_abs(bench, f"E3 {side} turn")
    bench.expect_true("the printed eq. 13 treats the mirrored turns differently (right -1, left 0)",
                      results["right"][0] == -1 and results["left"][0] == 0,
                      measured=f"left {results['left'][0]}, right {results['right'][0]}", expected="left 0, right -1")
    bench.expect_true("the corrected eq. 13 treats them alike", results["left"][1] == -results["right"][1],
                      measured=f"left {results['left'][1]}, right {results['right'][1]}", expected="mirror images")
    bench.table("Erratum E3 ([P4] eq. 13): printed vs corrected rule on the bus wheel speeds, and the bench",
                ["turn", "hand wheel deg", "dV1 km/h", "dV2 km/h", "ddV km/h", "T printed", "T corrected (checked)",
                 "TurnDirection (median)"], rows)
    bench.note(f"V_l0 {l0:g}, V_l1 {l1:g}, V_l2 {l2:g} km/h ({calibration}). In a tight turn "
               f"ddV = B r (1 - cos delta) grows beyond V_l2; the printed right-turn branch would still report a "
               f"right turn while the left-turn branch rejects the mirror image. docs/spec/formulas.md §6 erratum E3.")
