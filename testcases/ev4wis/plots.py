"""Plots every 4WIS case adds to the report: target vs reached steering angle and wheel speed of the four wheels."""

from __future__ import annotations

from bench.case import Case

WHEELS = ("FL", "FR", "RL", "RR")


def plot_wheels(bench: Case, label: str = "") -> None:
    """Two time plots since the case (or its last scenario) started: VCU_WheelCmd_xx (target) against
    WHL_Status_xx (reached), for the steering angle and for the wheel speed of the four wheels."""
    prefix = f"{label}: " if label else ""
    bench.plot(f"{prefix}steering angle, target (VCU_WheelCmd) vs reached (WHL_Status)",
               [item for w in WHEELS for item in (
                   (f"VCU_WheelCmd_{w}", "SteerAngleCmd", f"{w} target"),
                   (f"WHL_Status_{w}", "SteerAngle", f"{w} reached"))],
               ylabel="steering angle [deg]")
    bench.plot(f"{prefix}wheel speed, target (VCU_WheelCmd) vs reached (WHL_Status)",
               [item for w in WHEELS for item in (
                   (f"VCU_WheelCmd_{w}", "WheelSpeedCmd", f"{w} target"),
                   (f"WHL_Status_{w}", "WheelSpeed", f"{w} reached"))],
               ylabel="wheel speed [rpm]")


def plot_vcu_state(bench: Case, label: str = "") -> None:
    """VcuFault and ActiveMode over time (the bad-request cases)."""
    prefix = f"{label}: " if label else ""
    bench.plot(f"{prefix}VCU state", [("VCU_VehicleState", "VcuFault", "VcuFault"),
                                      ("VCU_VehicleState", "ActiveMode", "ActiveMode")], ylabel="value")
