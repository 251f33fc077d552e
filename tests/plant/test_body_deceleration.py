"""The EV's body at speed never decelerates (or accelerates) faster than its tyres can give (issue 13, item 11).

Physics, independent of the plant's code: four driven and braked wheels on a road of friction μ give at most
Σ|F_x| ≤ μ Σ F_z = μ m g, so |u̇| ≤ μ g whatever the hub motors ask for (docs/contract/plant.md PLANT-DYN-03).
Stimulus: the reference VCU in ADAPTIVE (docs/contract/vcu-4ws.md), a TargetSpeed step as in
testcases/rear_steer_4ws/test_speed_step.py (100 → 30 km/h on a dry road) and harder ones (100 → 20 km/h and
30 → 100 km/h on μ = 0.3), with front steer so the rear-steer law acts (3° dry; 0.67° on μ = 0.3, where 3° at 100 km/h
would ask more lateral grip than the road has).

Margin: 2 % of μ g. The limit is exact for this tyre (its peak is μ F_z; a Magic-Formula tyre's peak D = μ,
docs/spec/vehicles.md B, is the same bound); the 2 % covers the body-frame term ω·w that PLANT_Dynamics.LongAccel
carries besides u̇ (below 0.05 m/s² in these runs) and the finite differences. The old plant broke it by 11 g.
"""

from __future__ import annotations

import math

import pytest

from bench.sim.testing import MemoryIO
from plant import signal_ranges as ranges
from plant.assemblies.ev4wis import build

DT = 0.001
G = 9.81
MARGIN = 0.02          # relative to μ g (module docstring)


def _drive(v0_kmh: float, v1_kmh: float, mu: float, hand_wheel: float, seconds: float = 6.0) -> dict[str, list[float]]:
    """The EV at v0 (ADAPTIVE, hand wheel in deg, ratio 15), TargetSpeed stepped to v1 after 1 s; per tick the body's
    forward speed u, its longitudinal acceleration (PLANT_Dynamics.LongAccel) and the wheels' mean speed."""
    io = MemoryIO(ranges.BY_SIGNAL)
    behaviours = build(())
    plant = next(b for b in behaviours if b.nodes == ("PLANT",))
    body = plant.body
    v0, v1 = v0_kmh / 3.6, v1_kmh / 3.6
    io.values["BENCH_Control"] = {"ScenarioId": 1, "Vehicle": 0, "InitialSpeed": v0, "RoadMu": mu,
                                  "SensorNoise": 0}
    io.values["DRV_Steering"] = {"HandWheelAngle": hand_wheel, "HandWheelRate": 0.0, "DriverTorque": 0.0}
    io.values["DRV_MotionRequest"] = {"DriveMode": 2, "PivotX": 0.0, "PivotY": 0.0, "TargetSpeed": v0}
    out: dict[str, list[float]] = {"t": [], "u": [], "long": [], "wheels": [], "dynamic": []}
    rpm_per_mps = 30.0 / (math.pi * 0.281)
    for i in range(1, round(seconds / DT) + 1):
        t = i * DT
        if abs(t - 1.0) < 0.5 * DT:
            io.values["DRV_MotionRequest"]["TargetSpeed"] = v1
        for b in behaviours:
            b.step(io, t, DT)
        out["t"].append(t)
        out["u"].append(body.vy)
        out["long"].append(io.values["PLANT_Dynamics"]["LongAccel"])
        out["wheels"].append(sum(io.values[f"WHL_Status_{c}"]["WheelSpeed"] for c in ("FL", "FR", "RL", "RR"))
                             / 4.0 / rpm_per_mps)
        out["dynamic"].append(float(body.dynamic))
    return out


@pytest.mark.parametrize(("v0", "v1", "mu", "hand_wheel"),
                         [(100.0, 30.0, 1.0, 45.0), (100.0, 20.0, 0.3, 10.0), (30.0, 100.0, 0.3, 10.0)],
                         ids=["100-30kmh-dry", "100-20kmh-mu0.3", "30-100kmh-mu0.3"])
def test_longitudinal_acceleration_within_tyre_limit(v0: float, v1: float, mu: float, hand_wheel: float) -> None:
    t_min = abs(v1 - v0) / 3.6 / (mu * G)        # s: the fastest change the tyres allow
    run = _drive(v0, v1, mu, hand_wheel, seconds=t_min + 2.5)
    limit = mu * G * (1.0 + MARGIN)
    t, u = run["t"], run["u"]
    assert all(run["dynamic"][500:]), "the body must stay in the dynamic regime for this check"
    du = [(u[i] - u[i - 1]) / DT for i in range(1, len(u))]
    worst_du = max(abs(a) for a in du)
    worst_long = max(abs(a) for a in run["long"][1:])
    assert worst_du <= limit, f"|du/dt| reached {worst_du:.2f} m/s² > μ g (1 + {MARGIN}) = {limit:.2f}"
    assert worst_long <= limit, f"|LongAccel| reached {worst_long:.2f} m/s² > {limit:.2f}"
    # not trivially slow: the car changes speed about as fast as the tyres allow and arrives at the target
    v1_mps = v1 / 3.6
    arrive = next((ti for ti, ui in zip(t, u) if abs(ui - v1_mps) < 0.05), math.inf) - 1.0
    assert t_min - 0.05 / (mu * G) - 2 * DT <= arrive <= t_min + 0.5, \
        f"reached {v1:g} km/h {arrive:.2f} s after the step, tyre limit {t_min:.2f} s"
    assert abs(u[-1] - v1_mps) < 0.01


def test_wheels_slide_while_the_body_brakes_at_the_limit() -> None:
    """The hub motors' 100 ms lag brings the wheels to 30 km/h long before the body: the wheels slide (what
    a wheel-speed-only speed estimate cannot see; docs/contract/vcu-4ws.md VCU-4WS-01)."""
    run = _drive(100.0, 30.0, 1.0, 45.0, seconds=2.0)
    i = run["t"].index(1.5)
    assert run["wheels"][i] < 10.0 < 20.0 < run["u"][i]
