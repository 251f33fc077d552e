"""`bench run` parses each database once in its process (issue 28): its input checks, the pytest plugin and the
session all ask for the project's databases, and before they were parsed 2 to 5 times a run (the mini campaign
below: chassis.dbc and bench.dbc twice each). The run's own process is counted, with cantools' loader patched;
the log process, a program of its own, parses them once in its own."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from tests.repo import ROOT

COUNTING_RUN = """
import collections, sys
import cantools.database
import bench.cli
counts = collections.Counter()
original = cantools.database.load_file
def counting(filename, *args, **kwargs):
    counts[filename.replace("\\\\", "/").rsplit("/", 1)[-1]] += 1
    return original(filename, *args, **kwargs)
cantools.database.load_file = counting
code = bench.cli.main(["run", *sys.argv[1:]])
print("LOADS", dict(counts))
sys.exit(code)
"""


def test_a_run_parses_each_database_once(tmp_path: Path) -> None:
    case = ROOT / "tests" / "fixtures" / "cases" / "test_mini.py"
    done = subprocess.run([sys.executable, "-c", COUNTING_RUN, str(case), "--out", str(tmp_path / "out")], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    line = next(line for line in done.stdout.splitlines() if line.startswith("LOADS "))
    assert ast.literal_eval(line.removeprefix("LOADS ")) == {"chassis.dbc": 1, "bench.dbc": 1}
