"""Yaw-rate feedback with an ideal steering ratio ([P3] §1.1) and its combined yaw-rate and lateral-
acceleration variant (§1.2), at 40, 60, 80 and 100 km/h (docs/spec/formulas.md §5; issue 4).

An ideal steering ratio makes the steady yaw rate per hand-wheel angle a constant G_r at every speed (the SBW's
coding IdealYawGain, 0xFDC1, default 0.28 1/s; docs/contract/sbw.md SBW-DIAG-02). For each speed the robot holds
the hand wheel at a fixed angle; the steady r/θ_h (IMU_Motion.YawRate / SBW_HandWheel.HandWheelAngle) must be
within 5 % of G_r with the feedback. The plain 15:1 car (DIRECT) is run beside the §1.1 variant: its r/θ_h follows
the closed form (u/L)/(1 + K_s u²)/15 of docs/spec/formulas.md §5 and varies with speed by far more, as the tables
show (the §1.2 case lists the closed form of the plain car beside its own figures).
The feedback is optional for a real SBW (SBW-CTL-05): one without the variant refuses its SteeringMode coding
(NRC 0x31) and the case is skipped with that reason.
Limits: testcases/sbw/limits.toml [sbw].
"""

from __future__ import annotations

import math

import pytest

from bench.results.model import Series
from testcases.sbw import oracle
from testcases.sbw.steps import SBW_FAULT, Limits, plot_steering, robot_angle, start, steady

SPEEDS_KMH = (40.0, 60.0, 80.0, 100.0)
HAND_WHEEL = 30.0     # deg held at every speed (a_y from 1.3 to 4.1 m/s², inside the linear range)
SETTLE = 2.0          # s after the hand wheel reaches its angle; the feedback settles in about 1 s
VARIANTS = {"YAW_RATE": "[P3] §1.1", "YAW_RATE_LAT_ACCEL": "[P3] §1.2"}


def _steady_gain(bench, speed_kmh: float, mode: str, g_r: float) -> tuple[float, float, float]:
    """(u, steady r/θ_h 1/s, SbwFault) of one scenario."""
    u = start(bench, speed_kmh, mode, g_r)
    robot_angle(bench, HAND_WHEEL)
    bench.run(SETTLE + HAND_WHEEL / 400.0)
    gain = steady(bench, "IMU_Motion", "YawRate") / steady(bench, "SBW_HandWheel", "HandWheelAngle")
    return u, gain, bench.value("SBW_Pinion", "SbwFault")


@pytest.mark.parametrize("variant", sorted(VARIANTS))
@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-CTL-05", "COM-E2E-01", "COM-E2E-02", "COM-VAL-01")
def test_sbw_yaw_gain_across_speeds(bench, variant: str) -> None:
    lim = Limits(bench)
    g_r = lim["ideal_yaw_gain"]
    case_start = bench.now
    rows, plain_gains, fb_gains = [], [], []
    measure_plain = variant == "YAW_RATE"        # the plain car is measured once, beside the §1.1 variant
    for speed in SPEEDS_KMH:
        closed_form = oracle.plain_yaw_per_hand_wheel(round(speed / 3.6, 2))
        plain = math.nan
        if measure_plain:
            _, plain, _ = _steady_gain(bench, speed, "DIRECT", g_r)
            lim.relative(f"plain 15:1 car at {speed:g} km/h: r/θ_h vs (u/L)/(1 + K_s u²)/15", "plain_gain_rel_tol",
                         plain, closed_form, "1/s", detail="docs/spec/formulas.md §5")
        _, fb, fault = _steady_gain(bench, speed, variant, g_r)
        lim.relative(f"{variant} at {speed:g} km/h: r/θ_h vs G_r", "yaw_gain_rel_tol", fb, g_r, "1/s",
                     detail=f"{VARIANTS[variant]}; G_r coded in IdealYawGain (0xFDC1)")
        bench.expect(f"{variant} at {speed:g} km/h: SbwFault OK", fault, SBW_FAULT["OK"],
                     detail="SBW_Pinion.SbwFault value table")
        plain_gains.append(plain if measure_plain else closed_form)
        fb_gains.append(fb)
        rows.append([speed, closed_form, plain if measure_plain else "(see YAW_RATE case)",
                     f"{(plain_gains[-1] - g_r) / g_r:+.1%}", fb, f"{(fb - g_r) / g_r:+.1%}"])
    lim.condition("G_r coded in IdealYawGain (0xFDC1)", "ideal_yaw_gain", g_r)
    rows.append(["spread (max − min) / G_r", "", "", f"{(max(plain_gains) - min(plain_gains)) / g_r:.1%}", "",
                 f"{(max(fb_gains) - min(fb_gains)) / g_r:.1%}"])
    bench.table(f"steady yaw rate per hand-wheel angle r/θ_h [1/s]: plain 15:1 car vs {variant} (G_r = {g_r:g} 1/s)",
                ["speed [km/h]", "plain, docs/spec/formulas.md §5", "plain, measured", "plain vs G_r",
                 f"{variant}, measured",
                 f"{variant} vs G_r"], rows)
    speeds = list(SPEEDS_KMH)
    series = [Series("G_r (ideal steering ratio)", speeds, [g_r] * len(speeds)),
              Series("plain 15:1, docs/spec/formulas.md §5", speeds,
                     [oracle.plain_yaw_per_hand_wheel(round(s / 3.6, 2)) for s in speeds])]
    if measure_plain:
        series.append(Series("plain 15:1, measured", speeds, plain_gains))
    series.append(Series(f"{variant}, measured", speeds, fb_gains))
    bench.plot_series("steady r/θ_h against speed", series, xlabel="speed [km/h]", ylabel="r/θ_h [1/s]")
    bench.expect_clean_bus()
    lim.report()
    plot_steering(bench, f"all scenarios ({', '.join(f'{s:g}' for s in SPEEDS_KMH)} km/h"
                         f"{', plain then ' if measure_plain else ', '}{variant})",
                  since=case_start)
