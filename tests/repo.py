"""Where this repository keeps its project files, for the bench's own tests (the package itself knows no
repository layout: it finds a project through its bench.toml)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DBC_DIR = ROOT / "dbc"
CHASSIS_DBC = DBC_DIR / "chassis.dbc"
BENCH_DBC = DBC_DIR / "bench.dbc"

#: bench.toml of a minimal project outside this repository: the two databases copied into its db/ folder, its
#: cases in cases/ (tests/integration/test_toy_vehicle.py, tests/integration/test_wheel_install.py)
MINIMAL_PROJECT_TOML = """\
[bench]
databases = ["db/chassis.dbc", "db/bench.dbc"]
stimulus = ["DRIVER", "TESTER"]
plant = "chassis"
testcases = "cases"
reports = "reports"

[scenario]
command = "BENCH_Control.ScenarioId"
ack = "PLANT_Status.ScenarioIdAck"
"""
