"""Shared steps of the steer-by-wire cases (testcases/sbw/test_*.py): scenario start, steering robot, limits from
testcases/sbw/limits.toml cited next to what was measured, and the plots every SBW case shows.

Only the bench's public API and DBC names are used (dbc/chassis.dbc: SBW_*, IMU_Motion; dbc/bench.dbc:
BENCH_SteeringRobot, BENCH_SbwSensorFault, PLANT_*), and the SBW's coding SteeringMode and IdealYawGain
(dbc/diagnostics.toml, docs/contract/sbw.md SBW-DIAG-02), written at each scenario start (testcases/coding.py).
Expected values come from testcases/sbw/oracle.py, never from plant/.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from bench.case import Case
from bench.results.model import Series
from testcases.coding import code
from testcases.limits import limit_value, limits_file, load_limits
from testcases.sbw import oracle
from testcases.stimulus import STIMULUS

VEHICLE = "ACLASS"
LIMITS_FILE = limits_file(__file__)


def limit(name: str) -> float:
    """One acceptance limit of testcases/sbw/limits.toml [sbw]; a check that should appear in the case's limits
    table goes through `Limits` instead."""
    return limit_value(load_limits(LIMITS_FILE, "sbw"), name, LIMITS_FILE, "sbw")


SBW_FAULT = {"OK": 0, "HANDWHEEL_RANGE": 1, "HANDWHEEL_STUCK": 2, "PINION_RANGE": 3, "INPUT_TIMEOUT": 4}
STEADY_WINDOW = 0.5   # s averaged at the end of a hold for steady values


class Limits:
    """The [sbw] limits of one case: every check records a step and a row of the case's limits table."""

    def __init__(self, bench: Case, section: str = "sbw") -> None:
        self.bench = bench
        self.section = section
        self.table = load_limits(LIMITS_FILE, section)
        self.rows: list[list[object]] = []

    def __getitem__(self, name: str) -> float:
        return limit_value(self.table, name, LIMITS_FILE, self.section)

    def _row(self, name: str, limit: str, measured: float, unit: str, ok: bool, what: str) -> bool:
        unit = "" if unit == "1" else unit
        self.rows.append([what, f"{self.section}.{name}", limit, f"{measured:.4g} {unit}".strip(),
                          "pass" if ok else "FAIL"])
        return ok

    def at_most(self, what: str, name: str, measured: float, *, detail: str = "", node: str = "") -> bool:
        """measured ≤ limit `name`; `node`: the node the check judges when it is not the case's DUT (bench.expect)."""
        value, unit, source = self.table[name]
        ok = math.isfinite(measured) and measured <= value
        shown = "" if unit == "1" else f" {unit}"
        self.bench.expect_true(f"{what} ≤ {name}", ok, measured=round(measured, 6), expected=f"≤ {value:g}{shown}",
                               detail=f"{source}{'; ' + detail if detail else ''}", node=node)
        return self._row(name, f"≤ {value:g}{shown}", measured, unit, ok, f"{what} ({node}'s)" if node else what)

    def within(self, what: str, target: str, tol: str, measured: float, *, detail: str = "") -> bool:
        """|measured − limit `target`| ≤ limit `tol` (absolute, same unit)."""
        value, unit, _ = self.table[target]
        width = self.table[tol][0]
        ok = self.bench.expect(f"{what} = {target} ± {tol}", measured, value, abs_tol=width, unit=unit,
                               detail=f"{self.table[target][2]}; {self.table[tol][2]}{'; ' + detail if detail else ''}")
        return self._row(f"{target} ± {self.section}.{tol}", f"{value:g} ± {width:g} {unit}", measured, unit, ok, what)

    def relative(self, what: str, tol: str, measured: float, expected: float, unit: str, *, detail: str = "") -> bool:
        """|measured − expected| ≤ limit `tol` · |expected| (expected from the oracle)."""
        rel = self.table[tol][0]
        ok = self.bench.expect(f"{what} (± {tol})", measured, expected, rel_tol=rel, unit=unit,
                               detail=f"{self.table[tol][2]}{'; ' + detail if detail else ''}")
        deviation = (measured - expected) / expected if expected else math.nan
        return self._row(tol, f"± {rel:.1%} of {expected:.4g} {unit}", measured, unit, ok,
                         f"{what} (deviation {deviation:+.2%})")

    def condition(self, what: str, name: str, measured: float, unit: str = "") -> None:
        """A test condition from the limits file (speed, amplitude, G_r): cited with what the bench measured."""
        value, file_unit, _ = self.table[name]
        unit = unit or file_unit
        self._row(name, f"{value:g} {file_unit}", measured, unit, True, f"condition: {what}")
        self.rows[-1][-1] = "condition"

    def report(self, title: str = "limits (testcases/sbw/limits.toml) against what was measured") -> None:
        self.bench.table(title, ["check", "limit name", "limit", "measured", "verdict"], self.rows)


# -- scenario and stimulus -------------------------------------------------------------------------------

def start(bench: Case, speed_kmh: float, mode: str = "DIRECT", ideal_gain: float | None = None, *,
          or_direct: bool = False) -> float:
    """Fresh ACLASS at `speed_kmh`, the SBW coded to `mode`, the robot holding the hand wheel at 0°. `or_direct`: an
    SBW that refuses `mode` (an optional feedback it does not have) runs DIRECT instead of skipping the case.
    Returns the speed as the bus carries it (BENCH_Control.InitialSpeed, 0.01 m/s), for the oracle."""
    u = round(speed_kmh / 3.6, 2)
    bench.start_scenario(Vehicle=VEHICLE, stimulus=STIMULUS[VEHICLE], InitialSpeed=u)
    declared = bench.diagnostics("SBW").did("IdealYawGain").default
    gain = declared if ideal_gain is None else ideal_gain
    code(bench, "SBW", {"SteeringMode": "DIRECT", "IdealYawGain": gain} if or_direct else None, SteeringMode=mode,
         IdealYawGain=gain)
    bench.set("BENCH_SteeringRobot", RobotMode="ANGLE", RobotAngle=0.0, RobotTorque=0.0)
    return u


def robot_angle(bench: Case, angle: float) -> None:
    """The robot steers the hand wheel to `angle` (deg, 0.01° on the bus)."""
    bench.set("BENCH_SteeringRobot", RobotMode="ANGLE", RobotAngle=round(angle, 2))


def robot_sine(bench: Case, amplitude: float, frequency: float, duration: float, period: float = 0.01) -> None:
    """Steer a sine (deg, Hz) for `duration` s, updating RobotAngle every `period` s (its cycle time)."""
    t0 = bench.now
    for _ in range(round(duration / period)):
        bench.set("BENCH_SteeringRobot", RobotMode="ANGLE",
                  RobotAngle=round(amplitude * math.sin(2.0 * math.pi * frequency * (bench.now - t0)), 2))
        bench.run(period)


# -- observations ----------------------------------------------------------------------------------------

def signal(bench: Case, message: str, name: str, since: float | None = None,
           origin: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(time s since `origin`, values) of every valid frame since `since` (bench times; both default to
    the start of the case or of its last scenario). A case computes figures from these: a message without a
    frame since `since` (a silent external SBW) ends the case with one line naming it (`bench.received`)."""
    t, v = bench.received(message, name, since)
    return t - (bench.start if origin is None else origin), v


def plotted(bench: Case, message: str, name: str, since: float | None = None,
            origin: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """As `signal`, for a plot only: a message without frames is an empty line (PLANT_SbwAngles, for one, has
    none when the SBW is external)."""
    t, v = bench.history(message, name, since)
    return t - (bench.start if origin is None else origin), v


def steady(bench: Case, message: str, name: str, window: float = STEADY_WINDOW) -> float:
    """Mean of a signal over the last `window` s (a message without a frame then ends the case, as `signal`)."""
    _, v = bench.received(message, name, bench.now - window)
    return float(np.mean(v))


def tracking_error(bench: Case, since: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Hand-wheel minus pinion angle (SBW_HandWheel, SBW_Pinion), the pinion interpolated onto the
    hand-wheel frames (the two messages are sent 1 ms apart), deg."""
    th, hw = signal(bench, "SBW_HandWheel", "HandWheelAngle", since)
    tp, pin = signal(bench, "SBW_Pinion", "PinionAngle", since)
    keep = (th >= tp[0]) & (th <= tp[-1]) if len(tp) else th < -1.0
    return th[keep], hw[keep] - np.interp(th[keep], tp, pin)


def predicted_yaw(bench: Case, u: float, source: tuple[str, str], scale: float,
                  since: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The §5 model's yaw rate and lateral acceleration (deg/s, m/s²; bus signs) driven by a steering signal
    (deg) times `scale` as the road-wheel angle, at the signal's frame times."""
    t, angle = signal(bench, *source, since)
    r, ay = oracle.simulate(u, t, np.radians(angle) * scale)
    return t, np.degrees(r), ay


# -- report ------------------------------------------------------------------------------------------------

def plot_steering(bench: Case, label: str = "", extra_yaw: Sequence[Series] = (), extra_ay: Sequence[Series] = (),
                  since: float | None = None) -> None:
    """The plots every SBW case shows: hand wheel vs pinion, tracking error, driver and road-feel torque,
    yaw rate and lateral acceleration (with the oracle's predictions passed in, timed from `since`), from
    `since` (bench time; default the start of the case or of its last scenario)."""
    prefix = f"{label}: " if label else ""
    origin = bench.start if since is None else since
    xlabel = "time since case start [s]" if since is None else "time [s]"

    def series(items: Sequence[tuple[str, str, str]]) -> list[Series]:
        return [Series(text, *(x.tolist() for x in plotted(bench, m, s, origin, origin))) for m, s, text in items]

    bench.plot_series(f"{prefix}hand-wheel vs pinion angle", series([
        ("SBW_HandWheel", "HandWheelAngle", "hand wheel (SBW_HandWheel)"),
        ("SBW_Pinion", "PinionAngle", "pinion (SBW_Pinion)"),
        ("SBW_Pinion", "PinionAngleTarget", "pinion target (SBW_Pinion)"),
        ("PLANT_SbwAngles", "HandWheelAngle", "hand wheel, truth"),
        ("PLANT_SbwAngles", "PinionAngle", "pinion, truth")]), xlabel=xlabel, ylabel="angle [deg]")
    t, e = tracking_error(bench, origin)
    tt, hw = plotted(bench, "PLANT_SbwAngles", "HandWheelAngle", origin, origin)
    _, pin = plotted(bench, "PLANT_SbwAngles", "PinionAngle", origin, origin)
    tp, target = plotted(bench, "SBW_Pinion", "PinionAngleTarget", origin, origin)
    _, pinion = plotted(bench, "SBW_Pinion", "PinionAngle", origin, origin)
    bench.plot_series(f"{prefix}tracking error (hand wheel − pinion; pinion target − pinion)",
                      [Series("SBW_HandWheel − SBW_Pinion", (t + bench.start - origin).tolist(), e.tolist()),
                       Series("hand wheel − pinion, truth (PLANT_SbwAngles)", tt.tolist(), (hw - pin).tolist()),
                       Series("PinionAngleTarget − PinionAngle (SBW_Pinion)", tp.tolist(), (target - pinion).tolist())],
                      xlabel=xlabel, ylabel="error [deg]")
    bench.plot_series(f"{prefix}driver and road-feel torque", series([
        ("SBW_HandWheel", "DriverTorque", "driver torque, torsion bar (SBW_HandWheel)"),
        ("SBW_HandWheel", "RoadFeelTorque", "road-feel motor (SBW_HandWheel)"),
        ("PLANT_SbwTorques", "DriverTorque", "driver torque at the rim, truth"),
        ("PLANT_SbwTorques", "AligningTorque", "aligning torque at the pinion, truth")]),
        xlabel=xlabel, ylabel="torque [N·m]")
    bench.plot_series(f"{prefix}yaw rate", series([
        ("IMU_Motion", "YawRate", "IMU_Motion.YawRate"), ("PLANT_Motion", "YawRate", "PLANT_Motion.YawRate")])
        + list(extra_yaw), xlabel=xlabel, ylabel="yaw rate [deg/s]")
    bench.plot_series(f"{prefix}lateral acceleration", series([
        ("IMU_Motion", "LatAccel", "IMU_Motion.LatAccel"), ("PLANT_Dynamics", "LatAccel", "PLANT_Dynamics.LatAccel")])
        + list(extra_ay), xlabel=xlabel, ylabel="lateral acceleration [m/s²]")


