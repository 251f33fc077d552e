"""The SBW sine cases can fail when nothing moves (testcases/sbw/test_sine.py; docs/contract/sbw.md SBW-CTL-03).
Before, an SBW whose frames carried every angle at 0 passed them: a phase lag, an RMS and a peak error of two zero
signals are 0. Now, in virtual time with tests/fixtures/zero_sbw.py as the external SBW (on the bus, every angle 0):
- the plant turns the hand wheel: the SBW's step (SBW_HandWheel's amplitude against the robot's documented
  dynamics) fails, the plant's passes: the case failed (exit 1);
- the robot's frames dropped as well (the hand wheel stays put, as a plant that does not move): the plant's step
  fails too, and the case is inconclusive (exit 3), not passed."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from bench.cli.run import EXIT_INCONCLUSIVE
from tests.repo import ROOT

PLUGIN = "tests.fixtures.zero_sbw"


def _run(out: Path, *args: str) -> tuple[int, dict[str, str]]:
    """`bench run --external SBW --dut SBW -k 'sine and 1Hz'` with the zero SBW: (exit code, step name -> verdict
    with its node)."""
    env = {**os.environ, "PYTEST_ADDOPTS": f"-p {PLUGIN}", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", "bench", "run", "--external", "SBW", "--dut", "SBW",
                           "-k", "sine and 1Hz", "--out", str(out), *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    (case,) = json.loads((out / "results.json").read_text(encoding="utf-8"))["cases"]
    return done.returncode, {s["name"].split(":")[0]: f"{s['node'] or 'SBW'} {s['verdict']}" for s in case["steps"]}


def test_an_sbw_reading_zero_fails_the_sine(tmp_path: Path) -> None:
    code, steps = _run(tmp_path / "zero")
    assert code == 1, steps
    assert steps["SBW_HandWheel.HandWheelAngle follows the hand wheel"] == "SBW fail"
    assert steps["hand wheel turned as the robot's documented dynamics"] == "PLANT pass"


def test_a_hand_wheel_that_does_not_move_is_inconclusive_not_passed(tmp_path: Path) -> None:
    code, steps = _run(tmp_path / "still", "--fault", "drop:BENCH_SteeringRobot@case+0-")
    assert code == EXIT_INCONCLUSIVE, steps
    assert steps["hand wheel turned as the robot's documented dynamics"] == "PLANT fail"
    assert steps["SBW_HandWheel.HandWheelAngle follows the hand wheel"] == "SBW fail"
