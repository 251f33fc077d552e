"""A parameter sweep for scale-out (issue 9, target 6): BENCH_SWEEP_N random rotation centres (default 200).

Each case asks the 4WIS EV for PIVOT about a random centre S = (x, y) (seeded; on the 0.02 m grid of
PivotX/PivotY; |x| ≥ 1.2 m, so that S is never between the wheels of an axle and no wheel folds) and checks
every wheel's reached angle and speed (WHL_Status_xx) against docs/spec/formulas.md §2 ([P0] eq. 1-4 and 7-10,
erratum E1 corrected), written out here. Vehicle: docs/spec/vehicles.md A / [P0] §3 (2K = 1.11 m, 2L = 2.76 m,
r = 0.281 m). Tolerances as the 4WIS issue: angle 0.05°, speed 0.5 % or 0.2 rpm (whichever is larger).
benchmarks/bench_scale_out.py runs it with 1 process and with `bench run -n 2`.
"""

import math
import os
import random

import pytest

K, L, R = 1.11 / 2, 2.76 / 2, 0.281     # half track, half wheelbase, wheel radius (m), docs/spec/vehicles.md A
WHEELS = {"FL": (-K, L), "FR": (K, L), "RL": (-K, -L), "RR": (K, -L)}   # docs/spec/formulas.md §1
ANGLE_TOL, SPEED_REL, SPEED_ABS = 0.05, 0.005, 0.2
GRID = 0.02          # m, PivotX/PivotY resolution
CONVERGE_S = 3.0     # s of bench time the wheels get (≤ 180° at 120 °/s plus the servo and hub-motor lags)


def _centres(n: int, seed: int) -> list[tuple[float, float]]:
    rng = random.Random(seed)
    out = []
    for _ in range(n):
        x = rng.choice((-1, 1)) * round(rng.uniform(1.2, 15.0) / GRID) * GRID
        y = round(rng.uniform(-10.0, 10.0) / GRID) * GRID
        out.append((round(x, 2), round(y, 2)))
    return out


def expected(x: float, y: float, v: float) -> dict[str, tuple[float, float]]:
    """docs/spec/formulas.md §2: β_i = atan((P_iy − y)/(x − P_ix)),
    n_i = 30 v (x − P_ix)/(π r r_o cos β_i) [deg, rpm]."""
    r_o = math.hypot(x, y)
    out = {}
    for wheel, (px, py) in WHEELS.items():
        beta = math.atan((py - y) / (x - px))
        out[wheel] = (math.degrees(beta), 30.0 * v * (x - px) / (math.pi * R * r_o * math.cos(beta)))
    return out


def speed_for(x: float, y: float) -> float:
    """Centre speed (0.01 m/s grid) with a yaw rate ≤ 0.75 rad/s, at most 2 m/s."""
    return max(0.05, math.floor(min(2.0, 0.75 * math.hypot(x, y)) * 100.0) / 100.0)


CENTRES = _centres(int(os.environ.get("BENCH_SWEEP_N", "200")), int(os.environ.get("BENCH_SWEEP_SEED", "9")))


@pytest.mark.parametrize("centre", CENTRES, ids=[f"S=({x:g},{y:g})" for x, y in CENTRES])
def test_rotation_centre(bench, centre):
    x, y = centre
    v = speed_for(x, y)
    targets = expected(x, y, v)
    bench.start_scenario(Vehicle="EV4WIS")
    bench.set("DRV_MotionRequest", DriveMode="PIVOT", PivotX=x, PivotY=y, TargetSpeed=v)

    def reached() -> bool:
        for wheel, (angle, rpm) in targets.items():
            if abs(bench.value(f"WHL_Status_{wheel}", "SteerAngle") - angle) > ANGLE_TOL:
                return False
            if abs(bench.value(f"WHL_Status_{wheel}", "WheelSpeed") - rpm) > max(SPEED_ABS, SPEED_REL * abs(rpm)):
                return False
        return True

    bench.eventually("every wheel at its §2 angle and speed", reached, CONVERGE_S)
    for wheel, (angle, rpm) in targets.items():
        bench.expect(f"{wheel} steering angle (§2 eq. 1-4)", bench.value(f"WHL_Status_{wheel}", "SteerAngle"), angle,
                     abs_tol=ANGLE_TOL, unit="deg")
        bench.expect(f"{wheel} wheel speed (§2 eq. 7-10)", bench.value(f"WHL_Status_{wheel}", "WheelSpeed"), rpm,
                     abs_tol=SPEED_ABS, rel_tol=SPEED_REL, unit="rpm")
    bench.plot(f"wheel angles, S = ({x:g}, {y:g}) m", [(f"WHL_Status_{w}", "SteerAngle", w) for w in WHEELS],
               ylabel="deg")
