"""Straight-line ABS braking on dry and wet asphalt (issue 6; docs/spec/vehicles.md B tyres): TurnDirection stays 0, the
slip stays in the documented band, and the stop is compared with locked wheels.

Each case brakes twice from 80 km/h with 150 bar (DRV_Pedals.BrakePressure), wheel-speed noise on: once with
the ABS, once with the hydraulic unit bypassed (BENCH_AbsStimulus.ValveBypass: the wheels lock; the locked-wheel
reference run). Checks:
- TurnDirection = 0 in every ABS_SteerState frame of both runs (a straight stop is no turn);
- ABS run, while AbsActive and above 15 km/h: the true slip of each wheel (PLANT_AbsWheel_xx.Slip) is inside
  [slip_band_low, slip_band_high] for at least slip_band_fraction_min of the samples, and no wheel stays
  beyond 0.5 (near locked) for longer than lock_time_max;
- adhesion utilisation epsilon = mean deceleration from 70 to 20 km/h / (mu_peak g) >= 0.75 (UN R13-H Annex 6),
  mu_peak of docs/spec/vehicles.md B's Magic Formula (testcases/abs/oracle.py);
- locked run: with all four wheels locked the deceleration is mu_locked g (the Magic Formula at slip 1);
- the ABS stop is not longer than the locked one (reported beside the oracle's v^2 / (2 g mu_locked)).
The locked run's deceleration and stop check the plant (PLANT-DYN-04): their steps name PLANT, so they are the
plant's verdict, never the ABS's (docs/contract/README.md).
"""

from __future__ import annotations

import numpy as np
import pytest

from testcases.abs import oracle, steps

SPEED = 80.0           # km/h
PRESSURE = 150.0       # bar: far beyond locking on any road
T_BRAKE = 0.3          # s
STOP_TIME = 5.0        # s after the brake application: the car has stopped
BAND_MIN_SPEED = 15.0  # km/h
ROADS = {"dry": (1.0, oracle.TYRE_DRY), "wet": (0.82, oracle.TYRE_WET)}


def _stop(bench, mu: float, bypass: bool) -> dict[str, np.ndarray | float]:
    """One stop; returns the samples since the brake application and the distance."""
    steps.start(bench, SPEED, mu=mu)
    bench.set("BENCH_AbsStimulus", ValveBypass=1 if bypass else 0)
    bench.run(T_BRAKE)
    y0 = bench.value("PLANT_Position", "PosY")
    t_brake = bench.now
    steps.brake(bench, PRESSURE)
    bench.run(STOP_TIME)
    d = steps.paired(bench, since=t_brake)
    t, ax = bench.history("PLANT_Dynamics", "LongAccel", since=t_brake)
    return {**d, "distance": bench.value("PLANT_Position", "PosY") - y0, "t_ax": t - bench.start, "ax": ax,
            "v_end": bench.value("PLANT_AbsVehicle", "VehicleSpeed"),
            "turns": bench.history("ABS_SteerState", "TurnDirection")[1]}


def _mean_decel(d: dict, v_hi: float, v_lo: float) -> float:
    """Mean deceleration (m/s^2) between the crossings of v_hi and v_lo km/h (true speed)."""
    t, v = d["t"], d["v_true"]
    i_hi = np.flatnonzero(v <= v_hi)
    i_lo = np.flatnonzero(v <= v_lo)
    if not i_hi.size or not i_lo.size or t[i_lo[0]] <= t[i_hi[0]]:
        return float("nan")
    return (v[i_hi[0]] - v[i_lo[0]]) / oracle.KMH / (t[i_lo[0]] - t[i_hi[0]])


@pytest.mark.parametrize("road", list(ROADS))
@pytest.mark.dut("ABS")
@pytest.mark.req("ABS-BRK-01", "ABS-TURN-01", "PLANT-DYN-04")
def test_abs_straight_braking(bench, road: str) -> None:
    mu, tyre = ROADS[road]
    locked = _stop(bench, mu, bypass=True)
    abs_run = _stop(bench, mu, bypass=False)
    for name, d, judged in (("ABS", abs_run, ""), ("locked", locked, "PLANT")):
        bench.expect_true(f"{name}: TurnDirection 0 in every frame", bool(np.all(d["turns"] == 0)),
                          measured=f"{int(np.count_nonzero(d['turns']))} of {d['turns'].size} non-zero", expected=0)
        # the locked run's stop is the plant's (its valves bypassed, the ABS does not brake); the ABS run's, the ABS's
        bench.expect(f"{name}: stopped (true speed)", d["v_end"], 0.0, unit="km/h", node=judged)

    # slip band while the ABS controls
    sel = (abs_run["active"] == 1) & (abs_run["v_true"] > BAND_MIN_SPEED)
    slips = np.concatenate([abs_run[f"slip_{w}"][sel] for w in steps.WHEELS])
    lo, hi = steps.limit("slip_band_low"), steps.limit("slip_band_high")
    fraction = float(np.mean((slips >= lo) & (slips <= hi))) if slips.size else float("nan")
    bench.expect_between(f"ABS: share of slip samples in [{lo:g}, {hi:g}]", fraction,
                         steps.limit("slip_band_fraction_min"), 1.0,
                         detail=f"{slips.size} samples; {steps.source('slip_band_high')}")
    longest = 0.0
    for w in steps.WHEELS:
        run = 0
        for s in abs_run[f"slip_{w}"][sel]:
            run = run + 1 if s > 0.5 else 0
            longest = max(longest, run * 0.01)
    bench.expect_between("ABS: longest near-locked stretch (slip > 0.5) of a wheel", longest, 0.0,
                         steps.limit("lock_time_max"), unit="s", detail=steps.source("lock_time_max"))

    # adhesion utilisation (UN R13-H Annex 6) and the locked-wheel physics
    peak, sliding = oracle.mu_peak(tyre), oracle.mu_locked(tyre)
    z = _mean_decel(abs_run, 70.0, 20.0)
    epsilon = z / (peak * oracle.G)
    bench.expect_between("ABS: adhesion utilisation epsilon = z / (mu_peak g)", epsilon,
                         steps.limit("adhesion_utilisation_min"), 1.0,
                         detail=f"mean deceleration 70 -> 20 km/h {z:.2f} m/s^2, mu_peak {peak:.3f} "
                                f"(docs/spec/vehicles.md B); {steps.source('adhesion_utilisation_min')}")
    all_locked = np.ones_like(locked["t"], dtype=bool)
    for w in steps.WHEELS:
        all_locked &= locked[f"slip_{w}"] >= 0.999
    all_locked &= locked["v_true"] > 10.0
    t_locked = locked["t"][all_locked]
    idx = np.searchsorted(locked["t_ax"], t_locked)
    idx = idx[idx < locked["ax"].size]
    decel = -float(np.mean(locked["ax"][idx])) if idx.size else float("nan")
    bench.expect("locked: deceleration with four locked wheels = mu_locked g", decel, sliding * oracle.G,
                 rel_tol=steps.limit("locked_decel_rel_tol"), unit="m/s^2",
                 detail=f"{idx.size} samples; mu_locked {sliding:.4f} (Magic Formula at slip 1, "
                        "docs/spec/vehicles.md B); "
                        f"{steps.source('locked_decel_rel_tol')}", node="PLANT")   # PLANT-DYN-04, not the ABS
    bench.expect_true("ABS stop not longer than the locked-wheel stop", abs_run["distance"] <= locked["distance"],
                      measured=round(float(abs_run["distance"]), 2), expected=f"<= {locked['distance']:.2f} m")
    ideal = oracle.locked_stopping_distance(SPEED / oracle.KMH, tyre)
    bench.table(f"{road} road (RoadMu {mu:g}): stopping from {SPEED:g} km/h with {PRESSURE:g} bar",
                ["run", "stopping distance m", "mean decel 70->20 km/h m/s^2", "note"],
                [["ABS", f"{abs_run['distance']:.2f}", f"{z:.2f}", f"epsilon {epsilon:.3f} (>= 0.75)"],
                 ["locked wheels (valves bypassed)", f"{locked['distance']:.2f}",
                  f"{_mean_decel(locked, 70.0, 20.0):.2f}", f"with locked wheels {decel:.2f} m/s^2"],
                 ["oracle: locked from the start", f"{ideal:.2f}", f"{sliding * oracle.G:.2f}",
                  "v^2 / (2 g mu_locked), no pressure build-up"],
                 ["oracle: ideal ABS at mu_peak", f"{(SPEED / oracle.KMH) ** 2 / (2 * oracle.G * peak):.2f}",
                  f"{peak * oracle.G:.2f}", f"mu_locked / mu_peak = {sliding / peak:.3f}"]])
    steps.plot_abs(bench, f"{road}, ABS run")
    bench.plot_series(f"{road}: true slips of the ABS run", [
        steps.xy_series(w, abs_run["t"], abs_run[f"slip_{w}"]) for w in steps.WHEELS],
        xlabel="time since the brake application [s]", ylabel="slip (positive braking)")
