"""Slalom at 40 km/h on a low-friction road, μ = 0.3 ([P3] §2, Fig. 8): 2WS, 4WS feedforward and 4WS
feedback side by side.

Course (slalom_cones in testcases/rear_steer_4ws/oracle.py): SLALOM_CONES cones on the course's centre line every
30 m (GB/T 6323-2014's spacing for passenger cars; [P3] gives no layout), the first one RUN_IN m after the driver's
take-over. Driver: PreviewDriver of testcases/rear_steer_4ws/path_driver.py (MacAdam's optimal preview, its internal
model of the car per law, docs/spec/formulas.md §5) on a sinusoid through ±AMPLITUDE at the cones (passing the first
cone on its right). The path asks a_y ≈ A (π/S)² u² = 2.0 m/s², 0.69 μ g: well beyond the tyres' linear range (0.5 μ g),
short of their limit. Road friction: BENCH_Control.RoadMu = 0.3. Speed held by the hub motors.

Pass: no cone ever inside the vehicle's footprint (1.255 m × 3.322 m, the tyres' outer rectangle) for each law
(issue 5: the three strategies side by side). [P3]'s claim that 4WS lowers the sideslip against 2WS is
checked on the peak |β| through the cones. Reported: peak |β|, |r|, |a_y| (also against μ g), the hand-wheel
work, the smallest cone clearance and the path error, side by side.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.results.model import Series
from testcases.rear_steer_4ws import oracle
from testcases.rear_steer_4ws.path_driver import Path, PreviewDriver, Transition
from testcases.rear_steer_4ws.steps import STRATEGIES, Run, driver_model, plot_side_by_side, start

pytestmark = [pytest.mark.dut("VCU"), pytest.mark.req("VCU-4WS-10", "VCU-4WS-14")]

SPEED_KMH = 40.0          # issue 5 / [P3] Fig. 8
MU = 0.3                  # issue 5 (low friction)
AMPLITUDE = 1.5           # m: lateral position of the centre at a cone (clearance 0.87 m to the tyres), chosen
RUN_IN = 35.0             # m from the take-over to the first cone (the path's entry transition is one spacing)
RUN_OUT = 35.0


def course(y0: float) -> tuple[list[tuple[float, float]], Path]:
    cones = oracle.slalom_cones(y0)
    spacing = oracle.SLALOM_SPACING
    transitions = [Transition(y0 - spacing, y0, AMPLITUDE)]
    side = AMPLITUDE
    for (_, previous), (_, y) in zip(cones, cones[1:], strict=False):
        side = -side
        transitions.append(Transition(previous, y, side))   # from the previous cone: y - spacing may round below it
    last = cones[-1][1]
    transitions.append(Transition(last, last + spacing, 0.0))
    return cones, Path(0.0, transitions)


def _min_clearance(run: Run, cones: list[tuple[float, float]]) -> float:
    heading = np.degrees(np.unwrap(np.radians(run.v["heading"])))
    h = np.interp(run.t["x"], run.t["heading"], heading)
    worst = math.inf
    for x, y, hd in zip(run.v["x"], run.v["y"], h):
        for cone in cones:
            if abs(cone[1] - y) < oracle.EV_LENGTH:
                worst = min(worst, oracle.clearance(cone, float(x), float(y), float(hd)))
    return worst


def test_slalom_40_kmh_low_friction(bench):
    runs, rows, peaks = [], [], {}
    cones0, path0 = course(0.0)
    for strategy in STRATEGIES:
        u = start(bench, SPEED_KMH, strategy, mu=MU)
        y0 = bench.value("PLANT_Position", "PosY") + RUN_IN
        cones, path = course(y0)
        driver = PreviewDriver(bench, path, driver_model(strategy, u))
        driver.engage()
        t_engage = bench.now
        end_y = cones[-1][1] + RUN_OUT
        done = bench.wait_until(lambda end_y=end_y: bench.value("PLANT_Position", "PosY") >= end_y,
                                (end_y - y0 + RUN_IN) / u + 2.0)
        driver.release()
        bench.expect_true(f"{strategy}: course completed", done, measured=round(bench.value("PLANT_Position", "PosY")
                                                                                 - y0, 2),
                          expected=f"≥ {end_y - y0:g} m", detail="y of the centre in the course frame")
        run = Run(bench, strategy, t_engage, t_engage)
        run.v["y"] = run.v["y"] - y0
        clearance = _min_clearance(run, cones0)
        bench.expect_between(f"{strategy}: smallest clearance between a cone and the footprint", clearance, 0.0,
                             math.inf, unit="m", detail=f"{len(cones0)} cones every {oracle.SLALOM_SPACING:g} m, "
                                                       f"footprint {oracle.EV_WIDTH:.3f} × {oracle.EV_LENGTH:.3f} m")
        through = (run.v["y"] >= cones0[0][1]) & (run.v["y"] <= cones0[-1][1])
        t_first = float(run.t["y"][through][0]) if through.any() else 0.0
        t_last = float(run.t["y"][through][-1]) if through.any() else 0.0
        peaks[strategy] = run.peak("beta", t_first, t_last)
        path_err = float(np.max(np.abs(run.v["x"][through] - np.array([path0.at(y)[0] for y in run.v["y"][through]]))))
        rows.append([strategy, clearance, peaks[strategy], run.peak("yaw", t_first, t_last),
                     run.peak("ay", t_first, t_last), run.peak("ay", t_first, t_last) / (MU * 9.81),
                     run.peak("hand_wheel", t_first, t_last), path_err, float(np.mean(run.v["speed"])) * 3.6])
        runs.append(run)
    for strategy in ("FEEDFORWARD", "FEEDBACK"):
        bench.expect_between(f"peak |β| through the cones: {strategy} ≤ 2WS", peaks[strategy], 0.0, peaks["2WS"],
                             unit="deg", detail="[P3] §2 / §3: 4WS lowers the sideslip angle against 2WS")
    bench.table(f"slalom {SPEED_KMH:g} km/h, μ = {MU:g}, cones every {oracle.SLALOM_SPACING:g} m, side by side",
                ["law", "min cone clearance m", "peak |β| °", "peak |r| °/s", "peak |a_y| m/s²", "peak |a_y| / μ g",
                 "peak |hand wheel| °", "max |path error| m", "mean speed km/h"], rows)
    cone_x = [c[0] for c in cones0]
    cone_y = [c[1] for c in cones0]
    ys = [-RUN_IN + 0.5 * i for i in range(int((cones0[-1][1] + RUN_OUT + RUN_IN) / 0.5) + 1)]
    top = [Series("cones", [x for c in cone_x for x in (c - 0.15, c + 0.15, math.nan)],
                  [y for c in cone_y for y in (c, c, math.nan)]),
           Series("driver's path", [path0.at(y)[0] for y in ys], ys)]
    top += [Series(f"{r.label} centre", r.v["x"].tolist(), r.v["y"].tolist()) for r in runs]
    bench.plot_series("top view: cones, the driver's path and the three trajectories (course frame)", top,
                      xlabel="x (right) [m]", ylabel="y (along the course) [m]", kind="xy")
    bench.plot_series("lateral position along the course (stretched)", [Series(s.name, s.y, s.x) for s in top],
                      xlabel="y (along the course) [m]", ylabel="x (right) [m]")
    plot_side_by_side(bench, runs, f"slalom {SPEED_KMH:g} km/h μ = {MU:g}",
                      xlabel="time since the driver took over [s]")
