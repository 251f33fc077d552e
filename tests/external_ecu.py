"""An example ECU of examples/ (written from the contract documents alone) judged as an external node, the way
docs/contract/README.md tells a supplier to judge a real one: three processes on one host over udp_multicast (hop
limit 0: nothing leaves the host): `bench plant --external NODE` simulates every node but NODE, the example plays
NODE, and `bench run --external all --dut NODE` runs every case that judges NODE.

What a passing example must show: `bench run` exits 0 (or 3: inconclusive) with no failure or error (at most
MAX_RERUNS failed cases that pass when run once more: the example shares the host with the bench); at most
MAX_INCONCLUSIVE cases inconclusive, each for the bench's or the plant's own lateness (a stall of the host: the
bench cannot judge the DUT then, docs/reliability.md), the others passed; at least `min_ran` cases ran or were
inconclusive; every case names NODE as its DUT; only reference-only cases, and cases whose coding selects an
optional function the node refuses (NRC 0x31, testcases/coding.py), are skipped, each with its reason; the
report's conformance table shows NODE as the real ECU; no invalid frame outside the cases that inject
a fault (results.json, the monitor's count per case); the example and the plant end cleanly on Ctrl-C.

The three processes run at real-time priority where the host allows it (`chrt -f 50`), as the README tells users to
on a loaded host: without it a descheduled process makes the bench late (inconclusive) or the ECU late.
"""

from __future__ import annotations

import ast
import json
import re
import shutil
import subprocess
import sys
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from bench.cli.run import EXIT_INCONCLUSIVE
from tests.child import Child
from tests.fakes import ipv4_group
from tests.repo import ROOT

BENCH = [sys.executable, "-m", "bench"]


#: failed cases of an example's campaign that are run once more (a second `bench run` of just those), and then must
#: pass: the example is a Python process on the same shared host as the bench, and a host that deschedules it makes
#: it late or off its control loop where a real ECU would not be, unseen by the bench when the bench's own processes
#: were not stalled too (CI, 2026-11-29: the SBW example's 1 Hz sine peaked 3.32 against 3°, its frames 31 ms apart).
#: A defect of the example fails the second run too; the first run's failures are shown as a warning.
MAX_RERUNS = 2

#: inconclusive cases an example's campaign may have (the bench or the plant stalled by the host, about one in a
#: campaign on this project's 2-core VM in the real-time step, 2026-11-29): more is a bench to look at (issue 34)
MAX_INCONCLUSIVE = 2


def _realtime_priority() -> list[str]:
    """`chrt -f 50` where this host lets the test use it (root, CAP_SYS_NICE or an rtprio limit), else nothing."""
    chrt = shutil.which("chrt")
    if chrt is None or subprocess.run([chrt, "-f", "50", "true"], capture_output=True).returncode != 0:
        return []
    return [chrt, "-f", "50"]


@dataclass
class Campaign:
    """What `bench run` left: its JUnit cases (ran and skipped) and results.json's cases."""

    ran: list[str]
    skipped: list[str]
    results: list[dict]


def judge_example(example: Path, node: str, out: Path, *, min_ran: int, seconds: float = 1200.0) -> Campaign:
    """Run the campaign of `node` against `example` (module docstring) and check what a passing example shows."""
    group = ipv4_group()
    bus = ["--interface", "udp_multicast", "--channel", group]
    priority = _realtime_priority()
    plant = Child([*priority, *BENCH, "plant", *bus, "--external", node, "--duration", str(int(seconds) + 60)], ROOT)
    ecu = None
    try:
        started = plant.wait_for("simulating", 60)
        simulated = started.split("simulating", 1)[1].split(" on ", 1)[0]
        assert node not in simulated.replace(",", " ").split(), started     # the bench leaves the node alone
        ecu = Child([*priority, sys.executable, str(example), *bus], ROOT)
        ecu.wait_for("running", 60)
        command = [*priority, *BENCH, "run", *bus, "--external", "all", "--dut", node]
        run = subprocess.run([*command, "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=seconds)
        rerun = _failed(out) if run.returncode not in (0, EXIT_INCONCLUSIVE) else []
        if 0 < len(rerun) <= MAX_RERUNS:   # the example's own process may have been descheduled: once more
            again = subprocess.run([*command, "--out", str(out / "rerun"), *rerun], cwd=ROOT, capture_output=True,
                                   text=True, timeout=seconds)
            assert again.returncode in (0, EXIT_INCONCLUSIVE), \
                _failures(out) + "run again:\n" + _failures(out / "rerun") + again.stdout[-2000:] + again.stderr[-2000:]
            warnings.warn(f"the {node} example failed {len(rerun)} case(s) and passed them when run again (a "
                          f"descheduled example process?): " + _failures(out).replace("\n", " | ")[:1500], stacklevel=1)
        else:
            assert run.returncode in (0, EXIT_INCONCLUSIVE), _failures(out) + run.stdout[-3000:] + run.stderr[-3000:]
        campaign = _check_report(out, node, min_ran, len(rerun))
    finally:
        outputs = {"ecu": ecu.stop() if ecu is not None else "", "plant": plant.stop()}
    assert ecu is not None and ecu.process.returncode == 0 and "stopped" in outputs["ecu"], outputs["ecu"]
    assert plant.process.returncode == 0, outputs["plant"]
    return campaign


def _failures(out: Path) -> str:
    """What a failed campaign's results.json says about each case that did not pass or skip: its failed steps
    (measured, expected, when), its invalid frames and the bench's timing figures. The console table's tail alone
    names the case, not the step, and a real-time failure on another host is seen only once."""
    path = out / "results.json"
    if not path.exists():
        return "no results.json\n"
    lines = []
    cases = [c for c in json.loads(path.read_text())["cases"] if c["outcome"] not in ("passed", "skipped")]
    for case in sorted(cases, key=lambda c: c["outcome"] == "inconclusive"):   # the failed ones first: CI cuts
        lines.append(f"{case['outcome']}: {case['nodeid']} {case.get('inconclusive') or ''}")
        lines += [f"  step {s['name']!r}: measured {s['measured']!r}, expected {s['expected']!r} {s['tolerance']}"
                  f" at {s['time']:.3f} s {s['detail']}" for s in case["steps"] if s["verdict"] == "fail"]
        lines += [f"  invalid: {entry}" for entry in case.get("invalid", [])[:5]]
        lines += [f"  bench timing: {entry}" for entry in case.get("bench_timing", [])[:5]]
        lines += [f"  message: {case['message'][:300]}"] if case.get("message") else []
    return "\n".join(lines) + "\n"


def _failed(out: Path) -> list[str]:
    """The node ids of the cases a campaign failed (results.json)."""
    path = out / "results.json"
    if not path.exists():
        return []
    return [c["nodeid"] for c in json.loads(path.read_text())["cases"] if c["outcome"] == "failed"]


def _check_report(out: Path, node: str, min_ran: int, passed_again: int = 0) -> Campaign:
    suite = ET.parse(out / "junit.xml").getroot()
    suite = suite if suite.tag == "testsuite" else suite.find("testsuite")
    assert suite is not None
    assert int(suite.get("failures", "1")) == passed_again and int(suite.get("errors", "1")) == 0
    ran, skipped, inconclusive = [], [], []
    for case in suite.findall("testcase"):
        name = case.get("name", "")
        duts = [p.get("value") for p in case.iter("property") if p.get("name") == "dut"]
        assert node in duts, (name, duts)                              # --dut NODE: only NODE's cases
        skip = case.find("skipped")
        if skip is None:
            ran.append(name)
            continue
        if skip.get("type") == "inconclusive":
            why = skip.get("message") or ""
            assert re.match(r"inconclusive: (bench|a sender other than the DUT) late by ", why), (name, why)
            inconclusive.append(f"{name}: {why}")
            continue
        reason = (skip.get("message") or "") + (skip.text or "")       # reference-only, or an optional function
        assert re.search(r"reference_only: .+ \(.+ (is|are) external\)|refuses the coding .+ \(NRC 0x31\)",
                         reason), (name, reason)
        skipped.append(name)
    assert len(inconclusive) <= MAX_INCONCLUSIVE, "the bench was late in too many cases:\n" + "\n".join(inconclusive)
    assert len(ran) + len(inconclusive) >= min_ran, f"only {len(ran)} cases ran: {ran}"
    report = (out / "report.html").read_text()                  # NODE's conformance table, as the real ECU
    assert re.search(rf'<h2 id="node-{node}">{node} <span class="node-kind">external \(the real ECU\)', report)
    results = json.loads((out / "results.json").read_text())["cases"]
    invalid = {c["nodeid"]: (c["invalid_frames"], c["invalid"][:3]) for c in results
               if c.get("invalid_frames") and not c.get("faults")}
    assert not invalid, f"invalid frames outside the fault cases: {invalid}"
    return Campaign(ran, skipped, results)


def third_party_imports(example: Path) -> set[str]:
    """The top-level packages an example imports beyond the standard library: what a supplier writes from the
    documents needs python-can, cantools and autosar-e2e (`e2e`), nothing of bench or plant."""
    imported = set()
    for node in ast.walk(ast.parse(example.read_text())):
        if isinstance(node, ast.Import):
            imported |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            imported.add(node.module.split(".")[0])
    return imported - set(sys.stdlib_module_names)
