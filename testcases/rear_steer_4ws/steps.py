"""Shared steps of the four-wheel-steering cases (testcases/rear_steer_4ws/test_*.py, [P3] §2 on the 4WIS EV of
docs/spec/vehicles.md A).

Stimulus: BENCH_Control (Vehicle EV4WIS, InitialSpeed, RoadMu), DRV_MotionRequest (ADAPTIVE, TargetSpeed = the
speed held) and DRV_Steering.HandWheelAngle; the VCU's law in ADAPTIVE above 20 km/h is coded in RearSteerLaw
(docs/contract/vcu.md VCU-DIAG-02) with WriteDataByIdentifier at each scenario start (testcases/coding.py).
Observed: ground truth PLANT_* (dbc/bench.dbc), VCU_WheelCmd_xx, WHL_Status_xx, VCU_RotationCentre,
VCU_VehicleState. Expected values come from testcases/rear_steer_4ws/oracle.py, never from
plant/.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from bench.case import Case
from bench.results.model import Series
from testcases.coding import code
from testcases.ev4wis.oracle import rpm_from_speed
from testcases.limits import limit_value, limits_file, load_limits
from testcases.pairing import nearest_values
from testcases.rear_steer_4ws import oracle
from testcases.rear_steer_4ws.path_driver import CarModel
from testcases.stimulus import STIMULUS

LIMITS_FILE = limits_file(__file__)
LIMITS = load_limits(LIMITS_FILE, "4ws")


def limit(name: str) -> float:
    """One acceptance limit of testcases/rear_steer_4ws/limits.toml [4ws] (its source is cited there)."""
    return limit_value(LIMITS, name, LIMITS_FILE, "4ws")


VEHICLE = "EV4WIS"
STRATEGIES = ("2WS", "FEEDFORWARD", "FEEDBACK")
#: strategy -> the VCU's coding RearSteerLaw (docs/contract/vcu.md VCU-DIAG-02, dbc/diagnostics.toml)
LAW = {"2WS": "OFF", "FEEDFORWARD": "FEEDFORWARD", "FEEDBACK": "FEEDBACK"}
WHEELS = ("FL", "FR", "RL", "RR")
SPEED_SETTLE_S = 3.0        # s the hub motors get to bring the speed back after the scenario start
SPEED_TOL = limit("speed_settled_rel_tol")   # relative: the speed counts as settled within 0.3 % of the target
#: a wheel command is the request's within 0.5 % or 0.2 rpm (docs/contract/vcu.md VCU-MODE-01's tolerance)
WHEEL_RPM_REL_TOL, WHEEL_RPM_ABS_TOL = 0.005, 0.2
#: s: the driver's model of servo lag (50 ms, docs/spec/vehicles.md A) + network delay, chosen
DRIVER_LAG = 0.07


def start(bench: Case, speed_kmh: float, strategy: str, mu: float = 1.0) -> float:
    """Fresh EV at `speed_kmh` (on the 0.01 m/s grid of InitialSpeed/TargetSpeed), ADAPTIVE with the
    strategy's rear-steering law, hand wheel 0, road friction mu; returns at the moment of docs/contract/vcu-4ws.md
    VCU-4WS-01 from which every 4WS law is judged: the VCU executes the case's request (VcuFault 0, every
    VCU_WheelCmd_xx at the straight-ahead wheel speed 30 u/(π r) of vcu.md VCU-MODE-07) and the car runs at it
    (PLANT_Motion.Speed within SPEED_TOL). Not at the restart itself: the car then still rolls at InitialSpeed
    while the VCU executes the scenario's first frames (standstill, 0 rpm; plant.md PLANT-SCN-04), so the hub
    motors first brake it a little. Returns the speed as the bus carries it, m/s (the oracle uses this value)."""
    u = round(oracle.mps(speed_kmh), 2)
    bench.start_scenario(Vehicle=VEHICLE, stimulus=STIMULUS[VEHICLE], InitialSpeed=u, RoadMu=mu)
    code(bench, "VCU", RearSteerLaw=LAW[strategy])
    bench.set("DRV_Steering", HandWheelAngle=0.0)
    bench.set("DRV_MotionRequest", DriveMode="ADAPTIVE", TargetSpeed=u)
    rpm = rpm_from_speed(u)
    rpm_tol = max(WHEEL_RPM_REL_TOL * rpm, WHEEL_RPM_ABS_TOL)

    def steady() -> bool:
        return (bench.value("VCU_VehicleState", "VcuFault") == 0
                and all(abs(bench.value(f"VCU_WheelCmd_{w}", "WheelSpeedCmd") - rpm) <= rpm_tol for w in WHEELS)
                and abs(bench.value("PLANT_Motion", "Speed") - u) <= SPEED_TOL * u)

    if not bench.wait_until(steady, SPEED_SETTLE_S):
        bench.received("VCU_VehicleState", "VcuFault")   # a silent VCU ends the case here, in one line
        bench.expect_true(f"speed settles at {speed_kmh:g} km/h with VcuFault 0", False,
                          measured=bench.value("PLANT_Motion", "Speed"), expected=u)
    return u


def driver_model(strategy: str, u: float, v: oracle.Vehicle = oracle.EV, lag: float = DRIVER_LAG) -> CarModel:
    """The path driver's internal model of the car under a law (the driver knows the car, as a trained test
    driver does): docs/spec/formulas.md §5 with docs/spec/vehicles.md A's numbers and the law's rear angle (oracle)."""
    rear = {"2WS": (0.0, 0.0), "FEEDFORWARD": (oracle.zero_sideslip_ratio(v, u), 0.0),
            "FEEDBACK": (-oracle.C1, oracle.c2(v) * u)}[strategy]
    return CarModel(v.m, v.iz, v.a, v.b, v.cf, v.cr, v.ratio, u, rear, lag)


def axle_angles(bench: Case, source: str = "VCU_WheelCmd") -> tuple[float, float]:
    """(front, rear) axle angles, deg: the mean of the two wheels of each axle, commanded (VCU_WheelCmd_xx) or
    reached (WHL_Status_xx)."""
    signal = "SteerAngleCmd" if source == "VCU_WheelCmd" else "SteerAngle"
    a = [bench.value(f"{source}_{w}", signal) for w in WHEELS]
    return 0.5 * (a[0] + a[1]), 0.5 * (a[2] + a[3])


def commanded_axles(bench: Case, since: float, until: float = math.inf
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, front, rear): at each VCU_WheelCmd_FL frame received in [since, until], the commanded axle angles, deg
    (mean of the two wheels of an axle), each wheel's angle from its frame of the same cycle (the nearest in
    receive time: testcases/pairing.py)."""
    t, fl = bench.received("VCU_WheelCmd_FL", "SteerAngleCmd", since)
    keep = t <= until
    t, fl = t[keep], fl[keep]
    fr, rl, rr = (nearest_values(t, *bench.received(f"VCU_WheelCmd_{w}", "SteerAngleCmd", since))
                  for w in WHEELS[1:])
    return t, 0.5 * (fl + fr), 0.5 * (rl + rr)


def mean_since(bench: Case, message: str, signal: str, since: float) -> float:
    _, v = bench.history(message, signal, since)
    return float(np.mean(v)) if len(v) else math.nan


class Run:
    """The signals of one scenario, kept for the side-by-side plots (times from `origin`, s)."""

    SIGNALS = {"x": ("PLANT_Position", "PosX"), "y": ("PLANT_Position", "PosY"),
               "heading": ("PLANT_Motion", "Heading"), "yaw": ("PLANT_Motion", "YawRate"),
               "speed": ("PLANT_Motion", "Speed"), "beta": ("PLANT_Dynamics", "Sideslip"),
               "ay": ("PLANT_Dynamics", "LatAccel"),
               **{w: (f"WHL_Status_{w}", "SteerAngle") for w in WHEELS},
               "hand_wheel": ("DRV_Steering", "HandWheelAngle")}

    def __init__(self, bench: Case, label: str, since: float, origin: float) -> None:
        self.label = label
        self.t: dict[str, np.ndarray] = {}
        self.v: dict[str, np.ndarray] = {}
        for key, (message, signal) in self.SIGNALS.items():
            t, v = bench.history(message, signal, since)
            self.t[key], self.v[key] = t - origin, v

    def peak(self, key: str, t_from: float = -math.inf, t_to: float = math.inf) -> float:
        """max |value| over the window."""
        keep = (self.t[key] >= t_from) & (self.t[key] <= t_to)
        return float(np.max(np.abs(self.v[key][keep]))) if keep.any() else math.nan

    def series(self, key: str, name: str | None = None) -> Series:
        return Series(name or self.label, self.t[key].tolist(), self.v[key].tolist())


def plot_side_by_side(bench: Case, runs: Sequence[Run], title: str, *, t_from: float = 0.0,
                      t_to: float = math.inf, xlabel: str = "time [s]") -> None:
    """β(t), r(t), a_y(t), the driver's hand-wheel angle and the four wheel angles (front pair, rear pair) of every
    run on the same axes."""
    def window(run: Run, key: str, name: str) -> Series:
        keep = (run.t[key] >= t_from) & (run.t[key] <= t_to)
        return Series(name, run.t[key][keep].tolist(), run.v[key][keep].tolist())

    for key, what, unit in (("beta", "sideslip β (PLANT_Dynamics.Sideslip)", "deg"),
                            ("yaw", "yaw rate r (PLANT_Motion.YawRate)", "deg/s"),
                            ("ay", "lateral acceleration a_y (PLANT_Dynamics.LatAccel)", "m/s²"),
                            ("hand_wheel", "hand-wheel angle (DRV_Steering, the driver)", "deg")):
        bench.plot_series(f"{title}: {what}", [window(r, key, r.label) for r in runs],
                          xlabel=xlabel, ylabel=f"{key} [{unit}]")
    for axle, wheels in (("front", WHEELS[:2]), ("rear", WHEELS[2:])):
        bench.plot_series(f"{title}: {axle} wheel angles {' and '.join(wheels)} (WHL_Status_xx.SteerAngle)",
                          [window(r, w, f"{r.label} {w}") for r in runs for w in wheels],
                          xlabel=xlabel, ylabel="steering angle [deg]")
