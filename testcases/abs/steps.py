"""Shared steps of the ABS turning-state cases (testcases/abs/test_*.py, [P4]): scenario start, stimulus, samples of
the ECU's outputs paired with the plant's ground truth, the report's plots and the paper's table.

Only the bench's public API and DBC names: dbc/chassis.dbc (ABS_WheelSpeeds, ABS_SteerState, DRV_Steering,
DRV_Pedals) and dbc/bench.dbc (BENCH_Control, BENCH_AbsStimulus, PLANT_AbsVehicle, PLANT_AbsWheel_xx, PLANT_*).
Limits: testcases/abs/limits.toml [abs] (each also in docs/contract/abs.md); an external ABS's calibration:
bench.toml [calibration.ABS] (`thresholds`). Expected values: testcases/abs/oracle.py.

Pairing estimate and truth: the ABS updates its outputs every 10 ms and the plant samples its truth at the same
instants (both documented with dbc/bench.dbc's truth messages), and each message goes out within the same
10 ms; so every ABS_SteerState frame is paired with the PLANT_AbsVehicle frame nearest to it in receive time, at
most PAIR_WINDOW away. On the virtual bus that is the truth frame of the same tick (0 s away). On a real-time bus
(vcan, hardware) the truth frame of the same instant may arrive a little after the ECU's frame instead of before
it; pairing only with the frame received last before it then took the previous instant's truth, or none.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest

from bench.case import Case
from bench.results.model import Series
from testcases.abs import oracle
from testcases.limits import limit_value, limits_file, load_limits
from testcases.pairing import nearest
from testcases.stimulus import STIMULUS

VEHICLE = "ACLASS_ABS"
WHEELS = ("FL", "FR", "RL", "RR")
NOMINAL_NOISE = 0.1      # km/h, BENCH_Control.SensorNoise of the accuracy cases (issue 6: sensor noise on)
PAIR_WINDOW = 0.0095     # s: the truth frame paired with an ABS frame is at most this far from it in time


LIMITS_FILE = limits_file(__file__)
LIMITS = load_limits(LIMITS_FILE, "abs")


def limit(name: str) -> float:
    return limit_value(LIMITS, name, LIMITS_FILE, "abs")


def source(name: str) -> str:
    return f"limits.toml abs.{name}: {LIMITS[name][2]}"


#: The marker of a case that calls `thresholds`: bench.toml must give an external ABS's V_l0, V_l1, V_l2 (checked by
#: the bench before the first case).
NEEDS_THRESHOLDS = pytest.mark.calibration("ABS", v_l0="km/h", v_l1="km/h", v_l2="km/h")


def thresholds(bench: Case) -> tuple[float, float, float, str]:
    """(V_l0, V_l1, V_l2 in km/h, where they come from) of the ABS under test, with which the cases evaluate eq. 13
    (docs/contract/abs.md ABS-TURN-01): an external ABS's own calibration, bench.toml [calibration.ABS] v_l0, v_l1,
    v_l2 (the case carries NEEDS_THRESHOLDS, so the bench has checked them before the first case); the bench's own
    ABS's, limits.toml ecu_v_l*."""
    if "ABS" in bench.external:
        l0, l1, l2 = (bench.calibration("ABS", name, "km/h") for name in ("v_l0", "v_l1", "v_l2"))
        return l0, l1, l2, "the external ABS's calibration (bench.toml [calibration.ABS])"
    return (limit("ecu_v_l0"), limit("ecu_v_l1"), limit("ecu_v_l2"),
            "the reference ABS's calibration (limits.toml abs.ecu_v_l*)")


# -- scenario and stimulus ---------------------------------------------------------------------------------

def start(bench: Case, speed_kmh: float, *, mu: float = 1.0, noise: float = NOMINAL_NOISE) -> None:
    """A fresh ACLASS_ABS straight ahead at `speed_kmh` on a road of friction `mu`, wheel-speed noise `noise`."""
    bench.start_scenario(Vehicle=VEHICLE, stimulus=STIMULUS[VEHICLE], InitialSpeed=round(speed_kmh / oracle.KMH, 2),
                         RoadMu=mu,
                         SensorNoise=noise)


def hold_speed(bench: Case, speed_kmh: float) -> None:
    """The drive robot holds the speed while the brakes are released (BENCH_AbsStimulus.CruiseSpeed)."""
    bench.set("BENCH_AbsStimulus", CruiseSpeed=speed_kmh)


def steer(bench: Case, hand_wheel_deg: float) -> None:
    """Hand-wheel angle, bus sign (positive right, docs/spec/formulas.md §1)."""
    bench.set("DRV_Steering", HandWheelAngle=hand_wheel_deg)


def brake(bench: Case, pressure_bar: float) -> None:
    bench.set("DRV_Pedals", BrakePressure=pressure_bar)


# -- samples -----------------------------------------------------------------------------------------------

def samples(bench: Case, message: str, signals: Sequence[str], since: float | None = None, *,
            required: bool = False) -> dict[str, np.ndarray]:
    """{"t": times since the case start, signal: values} of every valid frame of `message`. `required`: a
    message the case is judged on (the ABS's own): without a frame since `since` (a silent external ABS) the case
    ends with one line naming it (`bench.received`), not with statistics of nothing."""
    out: dict[str, np.ndarray] = {}
    for signal in signals:
        t, v = bench.received(message, signal, since) if required else bench.history(message, signal, since)
        out["t"] = t - bench.start
        out[signal] = v
    return out


def paired(bench: Case, since: float | None = None) -> dict[str, np.ndarray]:
    """ABS_SteerState and ABS_WheelSpeeds with the ground truth of the same instant (module doc).

    Keys: t, ref, angle, turn, active, ps_FL..ps_RR (ABS_SteerState); ws_FL..ws_RR (ABS_WheelSpeeds);
    v_true, angle_true (PLANT_AbsVehicle); slip_FL..slip_RR (PLANT_AbsWheel_xx)."""
    est = samples(bench, "ABS_SteerState", ["RefVehicleSpeed", "FrontWheelAngleEst", "TurnDirection", "AbsActive",
                                            *[f"PressureState{w}" for w in WHEELS]], since, required=True)
    out = {"t": est["t"], "ref": est["RefVehicleSpeed"], "angle": est["FrontWheelAngleEst"],
           "turn": est["TurnDirection"], "active": est["AbsActive"]}
    for w in WHEELS:
        out[f"ps_{w}"] = est[f"PressureState{w}"]

    def take(message: str, signals: Sequence[str], required: bool = False) -> dict[str, np.ndarray]:
        s = samples(bench, message, signals, since, required=required)
        if s["t"].size == 0:
            return {k: np.full(out["t"].shape, np.nan) for k in signals}
        idx, ok = nearest(out["t"], s["t"], PAIR_WINDOW)
        return {k: np.where(ok, s[k][idx], np.nan) for k in signals}

    wheel = take("ABS_WheelSpeeds", [f"WheelSpeed{w}" for w in WHEELS], required=True)
    truth = take("PLANT_AbsVehicle", ["VehicleSpeed", "FrontWheelAngle"])
    for w in WHEELS:
        out[f"ws_{w}"] = wheel[f"WheelSpeed{w}"]
        out[f"slip_{w}"] = take(f"PLANT_AbsWheel_{w}", ["Slip"])["Slip"]
    out["v_true"], out["angle_true"] = truth["VehicleSpeed"], truth["FrontWheelAngle"]
    return out


def error_stats(errors: np.ndarray) -> tuple[float, float]:
    """(mean of the signed error, max of the absolute error)."""
    errors = np.asarray(errors, dtype=float)
    if errors.size == 0 or not np.all(np.isfinite(errors)):
        return math.nan, math.nan
    return float(np.mean(errors)), float(np.max(np.abs(errors)))


def paper_angle_error(angle_est_bus: np.ndarray, angle_true_bus: np.ndarray) -> np.ndarray:
    """delta error in the paper's sign (left positive; docs/spec/formulas.md §1 has the bus positive right)."""
    return -(np.asarray(angle_est_bus) - np.asarray(angle_true_bus))


# -- report ------------------------------------------------------------------------------------------------

def plot_abs(bench: Case, label: str = "") -> None:
    """What the issue asks the report to show: the four wheel speeds (sensor and truth), true and estimated
    vehicle speed, true and estimated front-wheel angle, the TurnDirection timeline and the pressure states."""
    prefix = f"{label}: " if label else ""
    bench.plot(f"{prefix}wheel speeds, ABS sensors (ABS_WheelSpeeds) and truth (PLANT_AbsWheel_xx)",
               [item for w in WHEELS for item in (("ABS_WheelSpeeds", f"WheelSpeed{w}", f"{w} sensor"),
                                                  (f"PLANT_AbsWheel_{w}", "WheelSpeed", f"{w} true"))],
               ylabel="km/h")
    bench.plot(f"{prefix}vehicle speed: estimate (RefVehicleSpeed) vs truth (PLANT_AbsVehicle)",
               [("ABS_SteerState", "RefVehicleSpeed", "RefVehicleSpeed"),
                ("PLANT_AbsVehicle", "VehicleSpeed", "true CoG speed")], ylabel="km/h")
    bench.plot(f"{prefix}front-wheel angle: estimate vs truth (positive right)",
               [("ABS_SteerState", "FrontWheelAngleEst", "FrontWheelAngleEst"),
                ("PLANT_AbsVehicle", "FrontWheelAngle", "true front-wheel angle")], ylabel="deg")
    bench.plot(f"{prefix}turning state (TurnDirection 1 = left, -1 = right) and ABS activity",
               [("ABS_SteerState", "TurnDirection", "TurnDirection"), ("ABS_SteerState", "AbsActive", "AbsActive")],
               ylabel="-")
    bench.plot(f"{prefix}pressure states (0 HOLD, 1 INCREASE, 2 DECREASE)",
               [("ABS_SteerState", f"PressureState{w}", w) for w in WHEELS], ylabel="-")
    bench.plot(f"{prefix}wheel brake pressures (truth) and master cylinder",
               [*[(f"PLANT_AbsWheel_{w}", "BrakePressure", w) for w in WHEELS],
                ("PLANT_AbsVehicle", "MasterPressure", "master")], ylabel="bar")


def paper_table(bench: Case, test: str, rows: Sequence[tuple[str, int, float, float, float, float]]) -> None:
    """The paper's row of `test` and the bench's rows beside it ([P4] §4; delta errors in the paper's sign)."""
    t, vm, vx, am, ax = oracle.PAPER_TABLE[test]
    table = [["[P4] (paper)", test, t, f"{vm:.2f}", f"{vx:.2f}", f"{am:+.2f}", f"{ax:.2f}"]]
    for name, turn, b_vm, b_vx, b_am, b_ax in rows:
        table.append([f"bench: {name}", test, turn, f"{b_vm:+.3f}", f"{b_vx:.3f}", f"{b_am:+.3f}", f"{b_ax:.3f}"])
    bench.table(f"[P4] accuracy table: the paper beside the bench ({test})",
                ["source", "test", "T", "V_f error mean km/h", "V_f max abs km/h", "delta error mean deg",
                 "delta max abs deg"], table)


def xy_series(name: str, x: Sequence[float], y: Sequence[float]) -> Series:
    return Series(name, [float(v) for v in x], [float(v) for v in y])
