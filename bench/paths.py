"""Where the bench finds its databases and writes its artefacts."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DBC_DIR = ROOT / "dbc"
CHASSIS_DBC = DBC_DIR / "chassis.dbc"
BENCH_DBC = DBC_DIR / "bench.dbc"
REPORTS_DIR = ROOT / "reports"
TESTCASES_DIR = ROOT / "testcases"
