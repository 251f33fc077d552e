"""Shared steps of the 4WIS cases: send a request, wait for the wheels, check them against the oracle.

Tolerances come from testcases/ev4wis/limits.toml [4wis], each with its source (issue 3 and the contract:
steering angle 0.05°, wheel speed 0.5 % or 0.2 rpm, whichever is larger; the bus resolutions, 0.01° and 0.1 rpm,
are inside them). Only the bench's public API is used.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

from bench.case import Case
from testcases.ev4wis import oracle
from testcases.ev4wis.oracle import WHEELS, WheelTarget
from testcases.limits import limit_value, limits_file, load_limits
from testcases.stimulus import STIMULUS

VEHICLE = "EV4WIS"
#: the nodes a 4WIS case judges when it checks commanded (VCU_WheelCmd_xx) and reached (WHL_Status_xx) values
VCU_AND_WHEELS = ("VCU", "WHL_FL", "WHL_FR", "WHL_RL", "WHL_RR")
#: requirements every 4WIS case checks through bench.expect_clean_bus(): no out-of-range value, no E2E error, 8 bytes
CLEAN_BUS_REQS = ("COM-VAL-01", "COM-E2E-01", "COM-E2E-02", "COM-FRM-01")
LIMITS_FILE = limits_file(__file__)
LIMITS = load_limits(LIMITS_FILE, "4wis")


def limit(name: str) -> float:
    """One acceptance limit of testcases/ev4wis/limits.toml [4wis] (its source is cited there)."""
    return limit_value(LIMITS, name, LIMITS_FILE, "4wis")


ANGLE_TOL = limit("angle_tol")                # deg, commanded and reached steering angle
SPEED_REL_TOL = limit("speed_rel_tol")        # wheel speed, 0.5 % ...
SPEED_ABS_TOL = limit("speed_abs_tol")        # ... or 0.2 rpm (rpm), whichever is larger
YAW_ABS_TOL = limit("yaw_abs_tol")            # deg/s: one LSB of YawRateTarget / PLANT_Motion.YawRate
GROUND_TRUTH_YAW_ABS_TOL = limit("ground_truth_yaw_abs_tol")   # deg/s: the body's yaw rate (ground truth)
CENTRE_ABS_TOL = limit("centre_abs_tol")      # m: one LSB of VCU_RotationCentre
CONVERGE_S = limit("converge_time")           # s of bench time the wheels get to reach a request
WHEEL_SPEED_LIMIT = f"{SPEED_REL_TOL * 100:g} % or {SPEED_ABS_TOL:g} rpm"

MODE_VALUE = {"NORMAL": 0, "LATERAL": 1, "ADAPTIVE": 2, "PIVOT": 3}   # DRV_MotionRequest.DriveMode value table
FAULT_VALUE = {"OK": 0, "CENTRE_AT_ORIGIN": 1, "CENTRE_ON_WHEEL": 2, "ANGLE_OVER_90": 3,
               "REQUEST_INVALID": 4, "REQUEST_TIMEOUT": 5, "WHEEL_FAULT": 6}   # VCU_VehicleState.VcuFault


def start(bench: Case) -> None:
    """A fresh plant with the 4WIS EV, every stimulus at its start values (acknowledged by PLANT_Status)."""
    bench.start_scenario(Vehicle=VEHICLE, stimulus=STIMULUS[VEHICLE])


def speed_for(centre: tuple[float, float] | None, v_max: float = 2.0, yaw_max: float = 0.75) -> float:
    """A centre speed (m/s, on the 0.01 m/s grid of TargetSpeed) that keeps the yaw rate at or below yaw_max
    rad/s (43 °/s), so that no request of the campaign is refused for an excessive yaw rate or wheel speed."""
    if centre is None:
        return v_max
    return max(0.05, math.floor(min(v_max, yaw_max * math.hypot(*centre)) * 100.0) / 100.0)



def send_pivot(bench: Case, x: float, y: float, v: float) -> None:
    """DRV_MotionRequest in PIVOT mode; the centre must be exact on the bus (0.02 m grid)."""
    if not (oracle.on_grid(x, oracle.PIVOT_RESOLUTION) and oracle.on_grid(y, oracle.PIVOT_RESOLUTION)):
        raise ValueError(f"centre ({x}, {y}) is not on the 0.02 m grid of PivotX/PivotY: the oracle would "
                         f"not see what the VCU sees")
    bench.set("DRV_MotionRequest", DriveMode="PIVOT", PivotX=x, PivotY=y, TargetSpeed=v)


def send_car_mode(bench: Case, mode: str, hand_wheel: float, v: float) -> None:
    """NORMAL or ADAPTIVE: the hand-wheel angle (DRV_Steering) and the forward speed (DRV_MotionRequest)."""
    if not oracle.on_grid(hand_wheel, oracle.HAND_WHEEL_RESOLUTION):
        raise ValueError(f"hand-wheel angle {hand_wheel} is not on the 0.1° grid of HandWheelAngle")
    bench.set("DRV_Steering", HandWheelAngle=hand_wheel)
    bench.set("DRV_MotionRequest", DriveMode=mode, TargetSpeed=v)


def speed_within(measured: float, expected: float) -> bool:
    return math.isfinite(measured) and abs(measured - expected) <= max(SPEED_ABS_TOL, SPEED_REL_TOL * abs(expected))


def angle_within(measured: float, expected: float) -> bool:
    return math.isfinite(measured) and abs(measured - expected) <= ANGLE_TOL


def wheel_state(bench: Case, wheel: str) -> dict[str, float]:
    """Latest commanded and reached angle and speed of one wheel (NaN when its message is missing)."""
    return {"cmd_angle": bench.value(f"VCU_WheelCmd_{wheel}", "SteerAngleCmd"),
            "cmd_rpm": bench.value(f"VCU_WheelCmd_{wheel}", "WheelSpeedCmd"),
            "angle": bench.value(f"WHL_Status_{wheel}", "SteerAngle"),
            "rpm": bench.value(f"WHL_Status_{wheel}", "WheelSpeed")}


def at_targets(bench: Case, targets: Mapping[str, WheelTarget]) -> Callable[[], bool]:
    """Predicate: every wheel's commanded and reached angle and speed are within the tolerances."""
    value = bench.value
    checks = [(f"WHL_Status_{w}", f"VCU_WheelCmd_{w}", targets[w]) for w in WHEELS]

    def predicate() -> bool:   # evaluated every tick: stops at the first value that is not there yet
        for status, command, t in checks:
            if not (angle_within(value(status, "SteerAngle"), t.angle)
                    and speed_within(value(status, "WheelSpeed"), t.rpm)
                    and angle_within(value(command, "SteerAngleCmd"), t.angle)
                    and speed_within(value(command, "WheelSpeedCmd"), t.rpm)):
                return False
        return True
    return predicate


def settled(bench: Case) -> Callable[[], bool]:
    """Predicate: every wheel has reached its own command to the bus resolution (0.01°, 0.1 rpm).

    Used only to let the servos and hub motors finish their lag before the checks (a wheel within 0.05° of
    a 0.08° target may still be moving); it is never a verdict: the checks compare with the oracle."""
    def predicate() -> bool:
        for wheel in WHEELS:
            s = wheel_state(bench, wheel)
            if not (abs(s["angle"] - s["cmd_angle"]) <= 0.01 + 1e-9 and abs(s["rpm"] - s["cmd_rpm"]) <= 0.1 + 1e-9):
                return False
        return True
    return predicate


SETTLE_S = 0.5   # s at most of extra settling after the targets are reached (no verdict)


def wait_for_targets(bench: Case, targets: Mapping[str, WheelTarget], seconds: float = CONVERGE_S, *,
                     settle: bool = False) -> bool:
    """A step: the four wheels reach the targets (commanded and reached) within `seconds`; with `settle`, up
    to SETTLE_S more for the lags to settle to the bus resolution (not a check), for checks of quantities
    derived from the wheels' motion (ground truth, VehicleSpeed) that would still see the lag."""
    ok = bench.eventually("four wheels at target (commanded and reached)", at_targets(bench, targets), seconds)
    if not ok:   # a node that sent nothing (a silent external VCU) ends the case here, in one line
        for wheel in WHEELS:
            bench.received(f"VCU_WheelCmd_{wheel}", "SteerAngleCmd")
            bench.received(f"WHL_Status_{wheel}", "SteerAngle")
    if ok and settle:
        bench.wait_until(settled(bench), SETTLE_S)
    return ok


def expect_wheels(bench: Case, targets: Mapping[str, WheelTarget], source: str, *,
                  angles: bool = True, speeds: bool = True) -> None:
    """One step per wheel and quantity: commanded (VCU_WheelCmd_xx) and reached (WHL_Status_xx)."""
    for wheel in WHEELS:
        s, t = wheel_state(bench, wheel), targets[wheel]
        if angles:
            bench.expect(f"{wheel} commanded angle", s["cmd_angle"], t.angle, abs_tol=ANGLE_TOL, unit="deg",
                         detail=source)
            bench.expect(f"{wheel} reached angle", s["angle"], t.angle, abs_tol=ANGLE_TOL, unit="deg",
                         detail=source)
        if speeds:
            bench.expect(f"{wheel} commanded speed", s["cmd_rpm"], t.rpm, abs_tol=SPEED_ABS_TOL,
                         rel_tol=SPEED_REL_TOL, unit="rpm", detail=source)
            bench.expect(f"{wheel} reached speed", s["rpm"], t.rpm, abs_tol=SPEED_ABS_TOL,
                         rel_tol=SPEED_REL_TOL, unit="rpm", detail=source)


def expect_fault(bench: Case, fault: str) -> bool:
    return bench.expect(f"VcuFault = {fault}", bench.value("VCU_VehicleState", "VcuFault"), FAULT_VALUE[fault],
                        detail="VCU_VehicleState.VcuFault value table (dbc/chassis.dbc)")


