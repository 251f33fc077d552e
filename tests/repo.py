"""Where this repository keeps its project files, for the bench's own tests (the package itself knows no
repository layout: it finds a project through its bench.toml)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DBC_DIR = ROOT / "dbc"
CHASSIS_DBC = DBC_DIR / "chassis.dbc"
BENCH_DBC = DBC_DIR / "bench.dbc"
