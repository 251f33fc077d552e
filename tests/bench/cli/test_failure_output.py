"""A case with failed steps reports its steps, not a traceback through pytest's hooks."""

from __future__ import annotations

import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from tests.repo import ROOT


def test_failed_steps_are_reported_without_a_traceback(tmp_path: Path) -> None:
    case = ROOT / "tests" / "fixtures" / "cases" / "test_failing_step.py"
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(case), "--out", str(tmp_path)],
                            cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert "failed steps:\nthe answer: measured 41.00, expected 42.00 (±0.1)" in result.stdout
    junit = (tmp_path / "junit.xml").read_text()
    assert "the answer: measured 41.00" in junit
    for noise in ("pluggy", "_callers.py", "Traceback", "def pytest_runtest_call"):
        assert noise not in result.stdout and noise not in junit, noise


BAD_VALUES = '''
def test_speed(bench):
    bench.start_scenario(Vehicle="EV4WIS")
    bench.set("DRV_MotionRequest", DriveMode="PIVOT", PivotX=5.0, PivotY=0.0, TargetSpeed=100)


def test_pivot(bench):
    bench.start_scenario(Vehicle="EV4WIS")
    bench.set("DRV_MotionRequest", DriveMode="PIVOT", PivotX="5 m", PivotY=0.0, TargetSpeed=1)
'''


def test_a_bench_error_in_a_case_is_one_line_at_its_call(tmp_path: Path) -> None:
    """Issue 27, finding 3: `bench.set(..., TargetSpeed=100)` printed a 25-line traceback through codec.py and
    restbus.py before its good last line; now that line, at the case's own call, in the console and in JUnit."""
    (tmp_path / "test_user.py").write_text(BAD_VALUES, encoding="utf-8")
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(tmp_path / "test_user.py"), "--out",
                             str(tmp_path / "out")], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 1, result.stdout + result.stderr
    speed = (f"{tmp_path / 'test_user.py'}:4: SignalError: DRV_MotionRequest.TargetSpeed: 100 m/s is outside the "
             "DBC range [-80, 80]")
    pivot = (f"{tmp_path / 'test_user.py'}:9: SignalError: DRV_MotionRequest.PivotX: '5 m' is not a number (give a "
             "number in m; the signal has no value table)")
    lines = result.stdout.splitlines()
    for expected in (speed, pivot):
        assert lines[lines.index(expected) - 1].split()[2] == "failed", result.stdout   # its progress line
    junit = (tmp_path / "out" / "junit.xml").read_text()
    for noise in ("codec.py", "restbus.py", "case.py", "def test_speed", "Traceback"):
        assert noise not in result.stdout and noise not in junit, noise


def test_plain_pytest_with_tb_long_keeps_the_traceback(tmp_path: Path) -> None:
    """--tb=long asks for every frame (the bench's own bugs): the plugin leaves the report as pytest made it."""
    (tmp_path / "test_user.py").write_text(BAD_VALUES, encoding="utf-8")
    result = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "--tb=long",
                             str(tmp_path / "test_user.py"), "-k", "speed", "--bench-config", str(ROOT / "bench.toml"),
                             "--bench-out", str(tmp_path / "out")], cwd=ROOT, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 1 and "restbus.py" in result.stdout, result.stdout + result.stderr


NUMBERS = """
import pytest


def test_an_angle(bench):
    bench.expect("FL angle", -4.9, -4.8862962808010275, abs_tol=0.005, unit="deg")
    bench.expect("FR angle", 1.0, 1.0, abs_tol=0.05, unit="deg")


def test_raises(bench):
    marker = "the source of the test"
    raise ValueError("the plant said no")


@pytest.mark.skip(reason="not today")
def test_skipped(bench):
    pass
"""


def test_one_number_format_in_console_junit_and_html(tmp_path: Path) -> None:
    """Issue 27 finding 7: an expected value was -4.886 (HTML), -4.8863 (JUnit) and -4.8862962808010275 (console);
    the JUnit message ended in a dangling "; failed steps:" and showed the test's source; a skipped case showed
    "-0.00 s". Now one function (bench.checks.steps.format_value) gives the digits the tolerance (±0.005) resolves."""
    (tmp_path / "test_numbers.py").write_text(NUMBERS)
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(tmp_path / "test_numbers.py"), "--out",
                             str(tmp_path / "out")], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 1, result.stdout + result.stderr
    line = "FL angle: measured -4.9000, expected -4.8863 (±0.005 deg)"
    assert line in result.stdout and "4.886296" not in result.stdout
    html = (tmp_path / "out" / "report.html").read_text()
    assert ">-4.9000</td><td class=\"n\">-4.8863</td>" in html and "4.886296" not in html
    suite = ET.parse(tmp_path / "out" / "junit.xml").getroot().find("testsuite")
    assert suite is not None
    failure = suite.find("testcase[@name='test_an_angle']/failure")
    assert failure is not None and failure.get("message") == line          # nothing dangling after it
    error = suite.find("testcase[@name='test_raises']/failure")
    assert error is not None and error.get("message") == "ValueError: the plant said no"   # no source line
    assert "the source of the test" in (error.text or "")                   # the traceback stays in the body
    skipped = [ln for ln in result.stdout.splitlines() if "test_skipped" in ln and "│" in ln]
    assert skipped and "-0.00" not in skipped[0] and re.search(r"│ –\s+│ –\s+│", skipped[0]), skipped
