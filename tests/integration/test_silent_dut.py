"""Issue 25, acceptance 5: a run with an external node that never sends. Each of its cases fails with one line
naming the silent message ("no SBW_HandWheel from the external SBW in 2.0 s"), and no traceback.

Before: `bench run --external SBW --dut SBW` ended every SBW case in a traceback of the case's arithmetic on empty
arrays (testcases/sbw/oracle.py:130: IndexError), and `--external ABS --dut ABS` passed the noise sweep of an ABS
that sent nothing. Here nothing plays the node: the embedded bus, the node declared external.
"""

from __future__ import annotations

import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tests.repo import ROOT


@pytest.mark.parametrize("node", ["SBW", "ABS"])
def test_every_case_of_a_silent_node_fails_in_one_line(node: str, tmp_path: Path) -> None:
    run = subprocess.run([sys.executable, "-m", "bench", "run", "--external", node, "--dut", node, "--out",
                          str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    output = run.stdout + run.stderr
    assert run.returncode == 1, output
    assert not re.search(r"Traceback|Error\b|^E ", output, re.MULTILINE), output
    # a periodic message, or the node's diagnostic response to a request (the request named after the colon)
    silent = re.compile(rf"no ({node}_\w+ from the external {node} in \d+\.\d s"
                        rf"|DIAG_{node}_Resp from the external {node} in \d+\.\d s: .+)")
    lines = output.splitlines()
    failed = [i for i, line in enumerate(lines) if re.match(r"\[ *\d+/\d+\] failed ", line)]
    assert failed, output
    for i in failed:   # the case's line, then its one line of why, then the next case or the summary
        assert silent.fullmatch(lines[i + 1]), lines[i:i + 3]
        assert lines[i + 2].startswith("[") or lines[i + 2].startswith("bench run:"), lines[i:i + 3]
    cases = ET.parse(tmp_path / "junit.xml").getroot().iter("testcase")
    outcomes = []
    for case in cases:
        failure = case.find("failure")
        if failure is not None:
            assert silent.search(failure.get("message", "")), failure.get("message")
            assert "Traceback" not in (failure.text or "") and "Error" not in (failure.text or ""), failure.text
        outcomes.append("failed" if failure is not None else "skipped" if case.find("skipped") is not None
                        else "passed")
    assert "passed" not in outcomes, outcomes   # a node that sent nothing passes nothing
    assert outcomes.count("failed") == len(failed)
