"""Where this repository keeps its project files, for the bench's own tests (the package itself knows no
repository layout: it finds a project through its bench.toml)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DBC_DIR = ROOT / "dbc"
CHASSIS_DBC = DBC_DIR / "chassis.dbc"
BENCH_DBC = DBC_DIR / "bench.dbc"
#: The E2E_* attribute definitions as the contract's database defines them (BA_DEF_ lines), for test databases of
#: their own that declare protection with the same attributes (docs/spec/e2e.md).
#: Vector's frame format attribute (cantools reads 29-bit and CAN FD from it): 1 ExtendedCAN, 14 StandardCAN_FD,
#: 15 ExtendedCAN_FD; for test databases of CAN FD and 29-bit messages.
VFRAMEFORMAT_DEFINITION = ('BA_DEF_ BO_ "VFrameFormat" ENUM "StandardCAN","ExtendedCAN",' + '"reserved",' * 12
                           + '"StandardCAN_FD","ExtendedCAN_FD";')
E2E_ATTRIBUTE_DEFINITIONS = "\n".join(line for line in CHASSIS_DBC.read_text(encoding="utf-8").splitlines()
                                      if line.startswith('BA_DEF_ BO_  "E2E_'))

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
