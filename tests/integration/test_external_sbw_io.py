"""Issue 26: an external SBW on the bench's I/O, end to end in virtual time. tests/fixtures/doc_sbw.py is an SBW
written from the documents only (sbw.md, plant.md "Bench I/O — SBW", the DBCs): it reads IO_SbwHandWheel,
IO_SbwPinion, IO_SbwCurrents and sends IO_SbwActuators, SBW_HandWheel and SBW_Pinion, as a station of its own on
the bench's virtual bus (its pytest plugin adds it whenever SBW is declared external). With it, the real cases
run as a supplier runs them, `bench run --external SBW --dut SBW`:

- every case that is not reference-only passes (step, sine, road feel, the three angle-sensor faults through
  BENCH_SbwSensorFault and the I/O), with no invalid frame and nothing inconclusive (tests/external_ecu.py's
  checks of a passing campaign);
- the skipped cases are exactly those docs/contract/README.md lists as reference-only for SBW, with their reasons;
- the plant's own case on the A-class car (rear_steer_4ws/test_aclass.py), which reads the true pinion angle,
  runs and passes with the SBW external too (PLANT_SbwAngles exists whoever steers).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from tests.external_ecu import _check_report
from tests.repo import ROOT

BENCH = [sys.executable, "-m", "bench"]
PLUGIN = "tests.fixtures.doc_sbw"


def _run(out: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTEST_ADDOPTS": f"-p {PLUGIN}", "PYTHONPATH": str(ROOT)}
    return subprocess.run([*BENCH, "run", *args, "--out", str(out)], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=600)


def _reference_only_cases_of_the_readme(node: str) -> set[str]:
    """The `case` column of docs/contract/README.md's reference-only table, for `node`'s cases (sbw/...)."""
    text = (ROOT / "docs" / "contract" / "README.md").read_text(encoding="utf-8")
    section = text.split("## Reference-only cases", 1)[1].split("\n## ", 1)[0]
    cases = set()
    for line in section.splitlines():
        m = re.match(rf"\| `{node.lower()}/[^`]+::([^`]+)`", line)
        if m:
            cases.add(m.group(1))
    return cases


def test_the_sbw_campaign_judges_an_external_sbw_on_the_io(tmp_path: Path) -> None:
    run = _run(tmp_path / "sbw", "--external", "SBW", "--dut", "SBW")
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-3000:]
    campaign = _check_report(tmp_path / "sbw", "SBW", min_ran=7)
    for name in ("test_sbw_step_50kmh", "test_sbw_road_feel_50kmh", "test_sbw_handwheel_out_of_range",
                 "test_sbw_handwheel_stuck", "test_sbw_pinion_sensor_implausible"):
        assert name in campaign.ran, campaign.ran
    # reference-only (docs/contract/README.md), or coding the yaw-rate feedback this SBW does not have (NRC 0x31)
    feedback = {n for n in campaign.skipped if n.startswith(("test_sbw_yaw_gain_across_speeds",
                                                             "test_sbw_input_timeout"))}
    assert set(campaign.skipped) - feedback == _reference_only_cases_of_the_readme("SBW")
    assert feedback == {n for n in campaign.skipped if n not in _reference_only_cases_of_the_readme("SBW")}


def test_the_plants_aclass_case_runs_with_an_external_sbw(tmp_path: Path) -> None:
    run = _run(tmp_path / "aclass", "testcases/rear_steer_4ws/test_aclass.py", "--external", "SBW")
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-3000:]
    assert re.search(r"\b1 passed\b", run.stdout), run.stdout[-3000:]
