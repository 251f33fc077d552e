"""Loop latency (issue 9, target 4): the four wheels' steering commands step BENCH_WHEEL_STEPS times.

Each step asks the 4WIS EV for a new PIVOT centre (seeded, on the 0.02 m grid of PivotX/PivotY, to the
right of the right wheels so that no wheel folds, docs/spec/formulas.md §2), so every VCU_WheelCmd_xx.SteerAngleCmd
changes at once; the case waits until every WHL_Status_xx.SteerAngle has reached its command (within 0.05°,
the 4WIS issue's angle tolerance) and lets it rest, so that the next change starts from a status at rest
(what bench/checks/timing.py times). The latency itself is measured by the run's timing section (bench.toml
[timing] pairs "wheel XX steering") and read by benchmarks/bench_loop_latency.py; this case checks that
each wheel follows its command on the bus (expected = the command frame's value, not a plant figure).
Runs on the embedded default and over udp_multicast against `bench plant` (--external all).
"""

import os
import random

WHEELS = ("FL", "FR", "RL", "RR")
ANGLE_TOL = 0.05      # deg (4WIS issue)
SETTLE_S = 2.0        # s a step may take: ≤ 120° at the 120 °/s servo rate limit plus the 50 ms lag
REST_S = 0.08         # s at rest after each step (bench/checks/timing.py needs 3 status frames at rest)
GRID = 0.02           # m, PivotX/PivotY resolution


def _centre(rng: random.Random) -> tuple[float, float]:
    x = round(rng.uniform(1.5, 12.0) / GRID) * GRID
    y = round(rng.uniform(-6.0, 6.0) / GRID) * GRID
    return round(x, 2), round(y, 2)


def test_wheel_command_steps(bench):
    steps = int(os.environ.get("BENCH_WHEEL_STEPS", "30"))
    rng = random.Random(int(os.environ.get("BENCH_WHEEL_SEED", "9")))
    bench.start_scenario(Vehicle="EV4WIS")

    def worst_error() -> float:
        return max(abs(bench.value(f"WHL_Status_{w}", "SteerAngle") - bench.value(f"VCU_WheelCmd_{w}", "SteerAngleCmd"))
                   for w in WHEELS)

    def commands() -> tuple[float, ...]:
        return tuple(bench.value(f"VCU_WheelCmd_{w}", "SteerAngleCmd") for w in WHEELS)

    for i in range(steps):
        x, y = _centre(rng)
        before = commands()
        bench.set("DRV_MotionRequest", DriveMode="PIVOT", PivotX=x, PivotY=y, TargetSpeed=0.3)
        # the VCU's commands changed on the bus (before bound now: B023)
        bench.wait_until(lambda before=before: commands() != before, 0.1)
        bench.eventually(f"step {i + 1}: centre ({x:g}, {y:g}) m, every wheel within {ANGLE_TOL}° of its command",
                         lambda: worst_error() <= ANGLE_TOL, SETTLE_S)
        bench.run(REST_S)
    bench.expect("worst wheel angle error after the last step", worst_error(), 0.0, abs_tol=ANGLE_TOL, unit="deg")
    bench.expect("invalid frames", len(bench.invalid_log()), 0)
    bench.check_cycle_times([f"VCU_WheelCmd_{w}" for w in WHEELS] + [f"WHL_Status_{w}" for w in WHEELS])
    bench.plot("FL steering: command and status", [("VCU_WheelCmd_FL", "SteerAngleCmd", "command"),
                                                    ("WHL_Status_FL", "SteerAngle", "status")], ylabel="deg")
    bench.plot("RR steering: command and status", [("VCU_WheelCmd_RR", "SteerAngleCmd", "command"),
                                                    ("WHL_Status_RR", "SteerAngle", "status")], ylabel="deg")
