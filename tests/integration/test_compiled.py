"""The compiled core and its source give the same run (bench/compiled.py, setup.py): the same cases of the campaign,
once with the modules mypyc compiled and once with BENCH_COMPILED=0, put the same frames on the bus, bit for bit and
at the same bench times, and reach the same verdicts; `bench run` says which form ran.

The frames are read back with python-can's reader, not the bench's. Where nothing was compiled (no C compiler at
install) there is nothing to compare and the comparison is skipped, saying so; CI installs with a compiler.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import can
import pytest

from bench import compiled
from tests.repo import ROOT

#: one file per vehicle and law: the SBW's step (A-class), the 4WIS EV's U-turn (E2E-protected wheel commands),
#: the ABS's straight-line braking (its estimator and valves)
CASES = ["testcases/sbw/test_step.py", "testcases/ev4wis/test_uturn.py", "testcases/abs/test_straight.py"]


def _run(out: Path, pure: bool) -> tuple[str, list[tuple[int, int, bool, bool, bytes]], dict[str, str]]:
    env = {k: v for k, v in os.environ.items() if k != compiled.ENV}
    if pure:
        env[compiled.ENV] = "0"
    done = subprocess.run([sys.executable, "-m", "bench", "run", "--out", str(out), *CASES], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    frames, origin = [], None
    for message in can.LogReader(out / "run.mcap"):
        origin = message.timestamp if origin is None else origin
        frames.append((round((message.timestamp - origin) * 1e6), message.arbitration_id, message.is_extended_id,
                       message.is_fd, bytes(message.data)))
    outcomes = {case["nodeid"]: case["outcome"] for case in json.loads((out / "results.json").read_text())["cases"]}
    return done.stdout, frames, outcomes


def test_compiled_and_pure_python_put_the_same_frames_on_the_bus(tmp_path: Path) -> None:
    if not compiled.modules():
        pytest.skip("no module was compiled at install (no C compiler here): nothing to compare")
    out_compiled, frames_compiled, verdicts_compiled = _run(tmp_path / "compiled", pure=False)
    out_pure, frames_pure, verdicts_pure = _run(tmp_path / "pure", pure=True)
    for folder, output, said in ((tmp_path / "compiled", out_compiled, f"compiled (mypyc): {len(compiled.modules())}"),
                                 (tmp_path / "pure", out_pure, "pure Python (BENCH_COMPILED=0")):
        assert said in output                                                 # bench run's first lines
        assert said in (folder / "report.html").read_text(encoding="utf-8")   # and the report's header
    assert len(frames_compiled) > 10_000
    assert frames_compiled == frames_pure
    assert verdicts_compiled == verdicts_pure and set(verdicts_pure.values()) == {"passed"}
