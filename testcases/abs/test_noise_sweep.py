"""What eq. 13's thresholds buy: false turn detections per minute against the wheel-speed noise ([P4]
§3.1: "wheel speeds are disturbed by road roughness, braking and driving; the identification uses
anti-interference thresholds").

Straight driving at 60 km/h (drive robot, no steering, no braking) for SWEEP_TIME s per noise level
(BENCH_Control.SensorNoise; the plant adds road roughness in proportion). A false detection is a change of the
turning state from 0 to +/-1 (10 ms frames). Three detectors, the last two evaluated by the oracle on the same
ABS_WheelSpeeds frames:
- the ECU's TurnDirection (eq. 13 with V_l0, V_l1, V_l2, low-pass filtered speeds and the hold time t1);
- eq. 13 with the ECU's thresholds on the raw 10 ms frames (no filter, no hold);
- the sign of the axle differences alone (eq. 13 with V_l0 = 0 and no upper limits: no thresholds).
Checks: the ECU makes no false detection up to sweep_quiet_noise_max; at every level it makes no more than
either detector without its measures. The thresholds are the ECU's own (steps.thresholds). An external ABS reads
the noisy sensors through the bench I/O (IO_AbsSensors, docs/contract/plant.md PLANT-IO-ABS-01), as the bench's own
ABS reads them through its wires, so the case judges either.
"""

from __future__ import annotations

import numpy as np
import pytest

from testcases.abs import oracle, steps

SPEED = 60.0                                   # km/h
LEVELS = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0)       # km/h, BENCH_Control.SensorNoise (range 0..2.5)
SETTLE, SWEEP_TIME = 0.5, 10.0                 # s


def _rising(turns: np.ndarray) -> int:
    """Number of changes from 0 to a non-zero turning state."""
    t = np.asarray(turns)
    return int(np.count_nonzero((t[1:] != 0) & (t[:-1] == 0)) + (1 if t.size and t[0] != 0 else 0))


@steps.NEEDS_THRESHOLDS
@pytest.mark.dut("ABS")
@pytest.mark.req("ABS-TURN-01", "ABS-TURN-05", "ABS-OUT-01")
def test_abs_noise_sweep(bench) -> None:
    l0, l1, l2, calibration = steps.thresholds(bench)
    quiet = steps.limit("sweep_quiet_noise_max")
    rows, ecu_rate, raw_rate, sign_rate = [], [], [], []
    for noise in LEVELS:
        steps.start(bench, SPEED, noise=noise)
        steps.hold_speed(bench, SPEED)
        bench.run(SETTLE + SWEEP_TIME)
        d = steps.paired(bench, since=bench.start + SETTLE)
        minutes = SWEEP_TIME / 60.0
        raw, sign = [], []
        for fl, fr, rl, rr in zip(d["ws_FL"], d["ws_FR"], d["ws_RL"], d["ws_RR"]):
            dv1, dv2, ddv = oracle.axle_differences(fl, fr, rl, rr)
            raw.append(oracle.turn_corrected(dv1, dv2, ddv, l0, l1, l2))
            sign.append(oracle.turn_corrected(dv1, dv2, ddv, 0.0, float("inf"), float("inf")))
        ecu_rate.append(_rising(d["turn"]) / minutes)
        raw_rate.append(_rising(np.array(raw)) / minutes)
        sign_rate.append(_rising(np.array(sign)) / minutes)
        share = float(np.mean(d["turn"] != 0))
        rows.append([f"{noise:g}", f"{ecu_rate[-1]:.1f}", f"{share:.2%}", f"{raw_rate[-1]:.1f}",
                     f"{sign_rate[-1]:.1f}"])
        if noise <= quiet:
            bench.expect(f"noise {noise:g} km/h: ECU false turn detections per minute", ecu_rate[-1], 0.0,
                         detail=steps.source("sweep_quiet_noise_max"))
        bench.expect_true(f"noise {noise:g} km/h: ECU <= eq. 13 on raw frames <= sign alone (per minute)",
                          ecu_rate[-1] <= raw_rate[-1] <= sign_rate[-1],
                          measured=f"{ecu_rate[-1]:.1f} / {raw_rate[-1]:.1f} / {sign_rate[-1]:.1f}",
                          expected="non-decreasing")
    bench.table(f"false turn detections per minute, straight at {SPEED:g} km/h ({SWEEP_TIME:g} s per level)",
                ["SensorNoise km/h", "ECU (thresholds + filter + hold)", "ECU time with T != 0",
                 "eq. 13 thresholds on raw frames", "sign of dV1, dV2 alone"], rows)
    bench.plot_series("false turn detections per minute vs wheel-speed noise", [
        steps.xy_series("ECU TurnDirection", LEVELS, ecu_rate),
        steps.xy_series("eq. 13 thresholds, raw frames", LEVELS, raw_rate),
        steps.xy_series("sign alone (no thresholds)", LEVELS, sign_rate)],
        xlabel="BENCH_Control.SensorNoise [km/h]", ylabel="false detections per minute")
    bench.note(f"V_l0 {l0:g}, V_l1 {l1:g}, V_l2 {l2:g} km/h ({calibration}). Road roughness grows with SensorNoise "
               f"(the plant's sensor model), so the higher levels also carry slow disturbances the filter cannot "
               f"remove.")
    steps.plot_abs(bench, f"last level (SensorNoise {LEVELS[-1]:g} km/h)")
