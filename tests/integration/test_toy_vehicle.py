"""Acceptance 1 of issue 17: a vehicle is added by its declaration, its parameter file and the DBC's value table.

The toy vehicle TOY (code 3) is a car that coasts down from BENCH_Control.InitialSpeed with a time constant from its
toml: one behaviour (node PLANT) and one network message (PLANT_Motion, besides the scenario protocol's
PLANT_Status). A temporary project holds a copy of the plant package (as a project holds its own plant; the bench
finds it through the entry point `bench.plants: chassis = plant.factory:build`, the project's copy first on the
import path) and what the recipe in docs/architecture.md ("Adding a vehicle") adds to it: `plant/assemblies/toy.py`
with `toy.toml` beside it, copies of the databases whose two `VAL_ ... Vehicle` lines gain `3 "TOY"`, a bench.toml
and one case. Nothing of the repository is changed. `bench run` then runs the case on the virtual bus; the case
judges the coast-down against the closed form v0·exp(−t/τ), so it fails when the toy, its parameters or the plumbing
are wrong.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tests.repo import BENCH_DBC, CHASSIS_DBC, MINIMAL_PROJECT_TOML, ROOT

TOY_CODE = 3
COAST_TIME = 2.0          # s, toy.toml; the case's expectation is computed from it, not read from the plant

DECLARATION = '''\
"""Vehicle TOY: a car that coasts down from InitialSpeed, v(t) = v0 exp(-t / coast_time)."""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from bench.sim.node import Behaviour, NodeIO
from plant.declaration import Vehicle
from plant.scenario import ScenarioTracker
from plant.vehicles import ParameterFile, param

NAME, CODE = "TOY", 3


@dataclass(frozen=True)
class ToyParams:
    coast_time: float = param("s")
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False)


PARAMETERS = ParameterFile(Path(__file__).with_name("toy.toml"), ToyParams)


class CoastingCar:
    nodes: tuple[str, ...] = ("PLANT",)

    def __init__(self, params: ToyParams) -> None:
        self.tau = params.coast_time
        self.scenario = ScenarioTracker(CODE)
        self.speed = 0.0

    def reset(self) -> None:
        self.scenario.reset()
        self.speed = 0.0

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        if self.scenario.poll(io, t, dt):
            self.speed = self.scenario.setting("InitialSpeed", 0.0)
        self.speed *= math.exp(-dt / self.tau)
        io.send_values("PLANT_Motion", Heading=0.0, Speed=self.speed, YawRate=0.0)
        self.scenario.acknowledge(io, t)


def build(external: Collection[str]) -> list[Behaviour]:
    return [] if "PLANT" in external else [CoastingCar(PARAMETERS.load())]


VEHICLE = Vehicle(name=NAME, code=CODE, build=build, parameters=(PARAMETERS,),
                  messages=frozenset({"PLANT_Status", "PLANT_Motion"}), stimulus=())
'''

PARAMETERS = f'''\
name = "TOY"
[parameters]
coast_time = {{ value = {COAST_TIME}, unit = "s", source = "chosen (tests/integration/test_toy_vehicle.py)" }}
'''

BENCH_TOML = MINIMAL_PROJECT_TOML

CASE = f'''\
import math

from bench.config import load_config
from bench.plugins import plant_stimulus

V0, TAU = 10.0, {COAST_TIME}


def test_toy_coasts_down(bench):
    stimulus = plant_stimulus(load_config().plant, "TOY")
    bench.expect("stimulus messages the toy reads", len(stimulus), 0)
    bench.start_scenario(Vehicle="TOY", InitialSpeed=V0, stimulus=stimulus)
    bench.run(1.0)
    bench.expect("PLANT_Status.Vehicle", bench.value("PLANT_Status", "Vehicle"), {TOY_CODE})
    t_status, plant_time = bench.history("PLANT_Status", "PlantTime")
    t_start = t_status[-1] - plant_time[-1]           # the plant's scenario start, bench time
    t_motion, speed = bench.history("PLANT_Motion", "Speed")
    for i in (len(speed) // 2, -1):
        expected = V0 * math.exp(-(t_motion[i] - t_start) / TAU)
        bench.expect(f"speed at {{t_motion[i] - t_start:.3f}} s", speed[i], expected, abs_tol=0.02, unit="m/s")
    others = (("VCU_WheelCmd_FL", "SteerAngleCmd"), ("SBW_Pinion", "PinionAngle"),      # other vehicles' networks
              ("PLANT_AbsVehicle", "VehicleSpeed"), ("DRV_MotionRequest", "TargetSpeed"))  # and a stimulus it reads not
    for message, signal in others:
        bench.expect(f"frames of {{message}} since the scenario started", len(bench.history(message, signal)[0]), 0)
'''


def _with_toy(dbc_text: str) -> str:
    """The two Vehicle value tables with the toy's entry first (the DBC lists values high to low)."""
    new, count = re.subn(r"^(VAL_ \d+ Vehicle )", rf'\g<1>{TOY_CODE} "TOY" ', dbc_text, flags=re.MULTILINE)
    assert count == 2, "bench.dbc has two Vehicle value tables (BENCH_Control, PLANT_Status)"
    return new


@pytest.fixture
def project(tmp_path: Path) -> Path:
    (tmp_path / "db").mkdir()
    (tmp_path / "db" / "chassis.dbc").write_bytes(CHASSIS_DBC.read_bytes())
    (tmp_path / "db" / "bench.dbc").write_text(_with_toy(BENCH_DBC.read_text(encoding="utf-8")), encoding="utf-8")
    shutil.copytree(ROOT / "plant", tmp_path / "plant", ignore=shutil.ignore_patterns("__pycache__"))
    vehicle = tmp_path / "plant" / "assemblies"
    (vehicle / "toy.py").write_text(DECLARATION, encoding="utf-8")
    (vehicle / "toy.toml").write_text(PARAMETERS, encoding="utf-8")
    (tmp_path / "bench.toml").write_text(BENCH_TOML, encoding="utf-8")
    (tmp_path / "cases").mkdir()
    (tmp_path / "cases" / "test_toy.py").write_text(CASE, encoding="utf-8")
    return tmp_path


def test_a_toy_vehicle_runs_a_case_through_the_bench(project: Path) -> None:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(project), str(ROOT)])}
    out = project / "reports" / "run"
    done = subprocess.run([sys.executable, "-m", "bench", "run", "cases/test_toy.py", "--out", str(out)],
                          cwd=project, env=env, capture_output=True, text=True, timeout=300)
    cases = list(ET.parse(out / "junit.xml").getroot().iter("testcase")) if (out / "junit.xml").exists() else []
    assert [c.get("name") for c in cases] == ["test_toy_coasts_down"], done.stdout + done.stderr
    failed = [c for c in cases if any(c.find(tag) is not None for tag in ("failure", "error", "skipped"))]
    assert not failed and done.returncode == 0, done.stdout + done.stderr
