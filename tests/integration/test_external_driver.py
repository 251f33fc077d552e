"""Issue: with the plant alone on udp_multicast, a stand-alone python-can + cantools driver
(examples/drive_pivot.py) gets wheel angles and speeds that match docs/spec/formulas.md §2."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from tests.child import Child
from tests.fakes import ipv4_group
from tests.repo import ROOT

# docs/spec/vehicles.md A ([P0] §3): 2K = 1.11 m, 2L = 2.76 m, r = 0.281 m
K, L, R = 1.11 / 2, 2.76 / 2, 0.281
WHEELS = {"FL": (-K, L), "FR": (K, L), "RL": (-K, -L), "RR": (K, -L)}


def expected(x: float, y: float, v_o: float) -> dict[str, tuple[float, float]]:
    """docs/spec/formulas.md §2 for the wheel at P: beta = atan((Py - y)/(x - Px)),
    n = 30 v_o (x - Px)/(pi r r_o cos beta)
    (FL: Px = -K gives atan((L - y)/(x + K)), as printed)."""
    r_o = math.hypot(x, y)
    out = {}
    for name, (px, py) in WHEELS.items():
        beta = math.atan((py - y) / (x - px))
        rpm = 30 * v_o * (x - px) / (math.pi * R * r_o * math.cos(beta))
        out[name] = (math.degrees(beta), rpm)
    return out


@pytest.mark.realtime
def test_plant_answers_a_foreign_driver_per_formulas() -> None:
    group = ipv4_group()
    plant = Child([sys.executable, "-m", "bench", "plant", "--interface", "udp_multicast", "--channel", group,
                   "--external", "DRIVER", "--duration", "60"], ROOT)
    try:
        plant.wait_for("simulating", 60)      # its bus is open: it hears the driver's first frame
        driver = subprocess.run([sys.executable, str(ROOT / "examples" / "drive_pivot.py"), "--interface",
                                 "udp_multicast", "--channel", group, "--pivot", "5", "-2", "--speed", "1.0",
                                 "--seconds", "4"], capture_output=True, text=True, timeout=60)
    finally:
        plant_output = plant.stop()
    assert driver.returncode == 0, driver.stderr
    status = json.loads(driver.stdout)
    for corner, (angle, rpm) in expected(5.0, -2.0, 1.0).items():
        got = status[f"WHL_Status_{corner}"]
        assert abs(got["SteerAngle"] - angle) <= 0.05, (corner, got, angle)
        assert abs(got["WheelSpeed"] - rpm) <= max(0.2, 0.005 * abs(rpm)), (corner, got, rpm)
        assert got["WheelFault"] == 0
    assert plant.returncode == 0, plant_output
