"""A case with failed steps reports its steps, not a traceback through pytest's hooks."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.repo import ROOT


def test_failed_steps_are_reported_without_a_traceback(tmp_path: Path) -> None:
    case = ROOT / "tests" / "fixtures" / "cases" / "test_failing_step.py"
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(case), "--out", str(tmp_path)],
                            cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert "failed steps:\nthe answer: measured 41.0, expected 42.0 (±0.1)" in result.stdout
    junit = (tmp_path / "junit.xml").read_text()
    assert "the answer: measured 41.0" in junit
    for noise in ("pluggy", "_callers.py", "Traceback", "def pytest_runtest_call"):
        assert noise not in result.stdout and noise not in junit, noise
