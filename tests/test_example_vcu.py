"""examples/vcu_ecu.py, the stand-alone VCU, as an external node: issue 7 acceptance 2 on udp_multicast.

Three processes on one host (udp_multicast, hop limit 0: nothing leaves the host): `bench plant --external VCU`
simulates every node but the VCU, the example plays the VCU, and `bench run --external all` runs the whole
4WIS campaign (testcases/test_4wis_*.py), whose expected values come from testcases/oracle.py. The vcan half
needs the campaign lane (scripts/vcan-lane --example-vcu), which this machine's emulated guest cannot run in
real time (docs/vcan-lane.md). A second test checks the example's kinematics without a bus against the
rigid-body definition of docs/spec/formulas.md §2 (independent of the paper's eq. 1-10 the example implements).
"""

from __future__ import annotations

import importlib.util
import math
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hypothesis import given, settings
from hypothesis import strategies as st

from bench.paths import ROOT

EXAMPLE = ROOT / "examples" / "vcu_ecu.py"
BENCH = [sys.executable, "-m", "bench"]
#: The whole 4WIS campaign (every testcases/test_4wis_*.py: 106 cases, about 2 minutes in real time) and the
#: bench's own mini campaign; expected values come from testcases/oracle.py (docs/spec/formulas.md), not from the example.
CASES = [ROOT / "tests" / "fixtures" / "cases" / "test_mini.py", *sorted((ROOT / "testcases").glob("test_4wis_*.py"))]


def _start(command: list[str]) -> subprocess.Popen:
    return subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _wait_for(process: subprocess.Popen, marker: str, seconds: float) -> str:
    """Lines of the process's output up to the one containing marker (fails when it never comes)."""
    assert process.stdout is not None
    seen = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            break
        seen.append(line)
        if marker in line:
            return "".join(seen)
    raise AssertionError(f"no {marker!r} within {seconds:g} s:\n{''.join(seen)}")


def _stop(process: subprocess.Popen) -> str:
    process.send_signal(signal.SIGINT)
    output, _ = process.communicate(timeout=30)
    return output


def test_campaign_passes_against_the_example_vcu(tmp_path: Path) -> None:
    group = f"239.255.{random.randint(1, 254)}.{random.randint(1, 254)}"
    bus = ["--interface", "udp_multicast", "--channel", group]
    plant = _start([*BENCH, "plant", *bus, "--external", "VCU", "--duration", "900"])
    vcu = None
    try:
        started = _wait_for(plant, "simulating", 60)
        simulated = started.split("simulating", 1)[1].split(" on ", 1)[0]
        assert "VCU" not in simulated.replace(",", " ").split(), started   # the bench leaves the VCU alone
        vcu = _start([sys.executable, str(EXAMPLE), *bus])
        _wait_for(vcu, "running", 60)
        run = subprocess.run([*BENCH, "run", *bus, "--external", "all", "--out", str(tmp_path),
                              *[str(c) for c in CASES]], cwd=ROOT, capture_output=True, text=True, timeout=900)
        assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-3000:]
        junit = (tmp_path / "junit.xml").read_text()
        assert 'failures="0"' in junit and 'errors="0"' in junit
        tests = int(junit.split('tests="', 1)[1].split('"', 1)[0])
        assert tests >= 100, f"only {tests} cases ran"
    finally:
        outputs = {"vcu": _stop(vcu) if vcu is not None else "", "plant": _stop(plant)}
    assert vcu.returncode == 0 and "stopped" in outputs["vcu"], outputs["vcu"]
    assert plant.returncode == 0, outputs["plant"]


def _load_example():
    spec = importlib.util.spec_from_file_location("vcu_ecu", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


VCU = _load_example()
WHEELS = {"FL": (-0.555, 1.38), "FR": (0.555, 1.38), "RL": (-0.555, -1.38), "RR": (0.555, -1.38)}  # docs/spec/vehicles.md A
RADIUS = 0.281


@settings(max_examples=300, deadline=None)
@given(x=st.floats(-50, 50), y=st.floats(-50, 50), v=st.floats(-2, 2))
def test_example_kinematics_are_a_rigid_rotation(x: float, y: float, v: float) -> None:
    """docs/spec/formulas.md §2 without the paper: each wheel's velocity is ω × (P - S) with ω = v_o / r_o (clockwise);
    its heading must be perpendicular to P - S (angle in (-90°, 90°]) and its speed the projection."""
    fault, plan = VCU.plan_for(VCU.PIVOT, x, y, v, 0.0)
    r_o = math.hypot(x, y)
    near_wheel = any(math.hypot(x - px, y - py) < 0.01 for px, py in WHEELS.values())
    if near_wheel:
        assert fault == VCU.ON_WHEEL
        return
    if r_o < 0.01 and v != 0.0:
        assert fault == VCU.AT_ORIGIN
        return
    omega = v / r_o if r_o > 0 else 0.0
    speeds = []
    for px, py in WHEELS.values():
        vx, vy = omega * (py - y), omega * (x - px)                # ω × (P - S), ω clockwise
        speeds.append((vx, vy))
    if fault == VCU.INVALID:                                     # beyond the hub motors or the yaw limit
        worst = max(math.hypot(*s) for s in speeds) * 30 / (math.pi * RADIUS)
        assert worst > 1500 - 1e-6 or abs(math.degrees(omega)) > 120 - 1e-6
        return
    assert fault == VCU.OK
    for (name, (px, py)), angle, rpm, (vx, vy) in zip(WHEELS.items(), plan.angles, plan.rpm, speeds):
        assert -90.0 < angle <= 90.0, (name, angle)
        heading = (math.sin(math.radians(angle)), math.cos(math.radians(angle)))
        radius = (px - x, py - y)
        assert abs(heading[0] * radius[0] + heading[1] * radius[1]) <= 1e-9 * max(1.0, math.hypot(*radius)), name
        projected = (vx * heading[0] + vy * heading[1]) * 30 / (math.pi * RADIUS)
        assert math.isclose(rpm, projected, rel_tol=1e-9, abs_tol=1e-9), (name, rpm, projected)
    assert math.isclose(plan.yaw, math.degrees(omega), rel_tol=1e-12, abs_tol=1e-12)


def test_example_car_modes_put_the_centre_where_vehicles_md_says() -> None:
    """NORMAL: X = HandWheelAngle / 15 and S on y = -L; ADAPTIVE below 20 km/h: S on y = 0; LATERAL: +90° with
    signed rpm (docs/contract/vcu.md VCU-MODE-08)."""
    for mode, y_centre, factor in ((VCU.NORMAL, -1.38, 2.0), (VCU.ADAPTIVE, 0.0, 1.0)):
        fault, plan = VCU.plan_for(mode, 0.0, 0.0, 1.0, 300.0)
        x_deg = 300.0 / 15.0
        assert fault == VCU.OK and plan.curvature == x_deg
        cx, cy = plan.centre
        assert math.isclose(cy, y_centre) and math.isclose(cx, factor * 1.38 / math.tan(math.radians(x_deg)))
        # the front-axle centre (0, L) heads at X about S ([P2]'s curvature angle)
        assert math.isclose(math.degrees(math.atan((1.38 - cy) / cx)), x_deg)
        assert all(n > 0 for n in plan.rpm)                     # forward: every wheel rolls forward
    assert VCU.plan_for(VCU.ADAPTIVE, 0.0, 0.0, 6.0, 300.0)[0] == VCU.INVALID     # above 20 km/h: not here
    fault, plan = VCU.plan_for(VCU.LATERAL, 0.0, 0.0, -1.5, 0.0)
    assert fault == VCU.OK and plan.angles == [90.0] * 4
    assert all(math.isclose(n, -1.5 * 30 / (math.pi * RADIUS)) for n in plan.rpm)


def test_example_checksum_is_the_contracts() -> None:
    """docs/spec/k-matrix.md: CRC-8/SAE-J1850, check value 0x4B over '123456789' (init 0xFF, final XOR 0xFF)."""
    crc = 0xFF
    for byte in b"123456789":
        crc = VCU.CRC_TABLE[crc ^ byte]
    assert crc ^ 0xFF == 0x4B
