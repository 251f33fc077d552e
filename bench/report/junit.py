"""JUnit XML of a run, for CI systems that show test results (GitLab, Jenkins, GitHub).

A case's <failure> is made of its DUT's failed steps only; a step that judges another node (`node="PLANT"`) is that
node's: its verdict and failures are the properties `node_verdict` and `node_failure`, and its lines in
<system-out> carry the node ("FAIL [PLANT] ...").

Names follow pytest's own junitxml convention (classname from the module path) so the
bench's results line up with plain pytest runs. Strings pass through :func:`xml_safe`
because ECU texts and DBC comments may carry control characters that are illegal in
XML 1.0 and would make the whole file unreadable for the CI.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

from bench.checks.steps import step_values
from bench.results.model import CaseResult, FaultRecord, RunResult, Step

_ILLEGAL_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def xml_safe(text: object) -> str:
    """``text`` as a string without characters XML 1.0 forbids."""
    return _ILLEGAL_XML.sub("", "" if text is None else str(text))


def split_nodeid(nodeid: str, fallback: str = "") -> tuple[str, str]:
    """``testcases/test_x.py::TestA::test_y[p]`` → (``testcases.test_x.TestA``, ``test_y[p]``).

    Parameters may contain "::" or "/", so only the part before "[" is split.
    """
    head, bracket, param = nodeid.partition("[")
    parts = head.split("::")
    if len(parts) < 2:
        return "bench", (fallback or nodeid)
    module = parts[0].removesuffix(".py").replace("\\", "/").strip("/").replace("/", ".")
    classname = ".".join([module, *parts[1:-1]])
    return classname, parts[-1] + bracket + param


FAILED_STEPS_HEAD = "failed steps:"   # how the pytest plugin's message of a case with failed steps begins


def error_line(message: str) -> str:
    """The line of a case's failure message that says what went wrong: "" for the plugin's failed-steps message
    (the steps say it), else the exception pytest reports (its first `E   ` line, without the test's source
    lines before it), else a Python traceback's last line (the exception), else the message's first line."""
    if not message or message.startswith(FAILED_STEPS_HEAD):
        return ""
    lines = [ln for ln in message.splitlines() if ln.strip()]
    error = next((ln[1:].strip() for ln in lines if ln.startswith("E ") and ln[1:].strip()), "")
    if error or not lines:
        return error
    return (lines[-1] if lines[0].startswith("Traceback") else lines[0]).strip()


def step_summary(step: Step) -> str:
    """A failed step in a sentence: name, measured and expected (bench.checks.steps.format_value) and the tolerance."""
    measured, expected = step_values(step)
    return f"{step.name}: measured {measured}, expected {expected}" + (f" ({step.tolerance})" if step.tolerance else "")


def step_line(step: Step) -> str:
    """One step as a line of text: verdict, name, measured vs expected with tolerance."""
    unit = f" {step.unit}" if step.unit else ""
    tol = f" ({step.tolerance})" if step.tolerance else ""
    measured, expected = step_values(step)
    judges = f"[{step.node}] " if step.node else ""   # a step of another node than the DUT names it
    line = (f"{step.verdict.upper():4} {judges}{step.name}: measured {measured}{unit}, "
            f"expected {expected}{unit}{tol} at t={step.time:.3f} s")
    return line + (f" – {step.detail}" if step.detail else "")


def fault_text(fault: FaultRecord) -> str:
    """One fault as a property value: spec, where it came from, what it did (window in bench time)."""
    end = "end" if fault.end is None else f"{fault.end:.3f}"
    window = f"{fault.start:.3f}-{end} s" if fault.relative == "run" else "each case"
    return f"{fault.spec} from {fault.source}, {window}: {fault.frames} frames"


def _testcase(parent: ET.Element, case: CaseResult) -> None:
    classname, name = split_nodeid(case.nodeid, case.name)
    tc = ET.SubElement(parent, "testcase", classname=xml_safe(classname), name=xml_safe(name),
                       time=f"{case.wall_time:.3f}")
    others = case.other_nodes
    if case.duts or case.reqs or case.faults or case.bench_timing or others:   # what it judges, checks and suffered
        props = ET.SubElement(tc, "properties")
        # node_verdict: "PLANT: failed", the case's outcome for a node its steps judge besides its DUTs
        # (CaseResult.outcome_of); node_failure: "PLANT: <step>", each failed step of such a node
        node_verdicts = [f"{n}: {case.outcome_of(n)}" for n in others]
        node_failures = [f"{s.node}: {step_summary(s)}" for s in case.other_failed_steps]
        for key, values in (("dut", case.duts), ("req", case.reqs), ("fault", [fault_text(f) for f in case.faults]),
                            ("bench_timing", case.bench_timing), ("node_verdict", node_verdicts),
                            ("node_failure", node_failures)):
            for value in values:
                ET.SubElement(props, "property", name=key, value=xml_safe(value))
    failed = case.failed_steps
    if case.outcome == "failed":
        message = "; ".join(p for p in (*(step_summary(s) for s in failed), error_line(case.message)) if p)
        traceback = [case.message] if error_line(case.message) else []   # not the plugin's list of the steps again
        body = "\n".join([*(step_line(s) for s in failed), *traceback])
        el = ET.SubElement(tc, "failure", message=xml_safe(message or "failed"), type="failure")
        el.text = xml_safe(body)
    elif case.outcome == "skipped":
        ET.SubElement(tc, "skipped", message=xml_safe(case.message or "skipped"), type="skip")
    elif case.outcome == "inconclusive":   # not the DUT's failure: <skipped type="inconclusive"> with the figures
        el = ET.SubElement(tc, "skipped", message=xml_safe(f"inconclusive: {case.inconclusive or case.message}"),
                           type="inconclusive")
        el.text = xml_safe("\n".join([*case.bench_timing, *(step_line(s) for s in failed), case.message]))
    elif case.outcome in ("error", "aborted"):
        prefix = "aborted" if case.outcome == "aborted" else "error"
        first = error_line(case.message)
        el = ET.SubElement(tc, "error", message=xml_safe(f"{prefix}: {first}" if first else prefix),
                           type=prefix)
        el.text = xml_safe("\n".join([*(step_line(s) for s in failed), case.message]))
    lines = [step_line(s) for s in case.steps] + [f"NOTE {n}" for n in case.notes]
    if lines:
        ET.SubElement(tc, "system-out").text = xml_safe("\n".join(lines))


def build_junit(run: RunResult) -> ET.ElementTree:
    """The JUnit tree; an aborted run adds one erroring test case ``bench.run::aborted``."""
    counts = run.counts
    errors = counts["error"] + counts["aborted"] + (1 if run.aborted else 0)
    attrs = {
        "name": "bench",
        "tests": str(len(run.cases) + (1 if run.aborted else 0)),
        "failures": str(counts["failed"]),
        "errors": str(errors),
        "skipped": str(counts["skipped"] + counts["inconclusive"]),   # an inconclusive case is a <skipped>
        "time": f"{run.wall_time:.3f}",
    }
    root = ET.Element("testsuites", attrs)
    suite = ET.SubElement(root, "testsuite", {**attrs, "timestamp": xml_safe(run.started)})
    props = ET.SubElement(suite, "properties")
    for key, value in (("interface", run.interface), ("channel", run.channel),
                       ("time_mode", run.time_mode), ("external", ",".join(run.external)),
                       ("mcap", run.mcap_path), ("bench_time", f"{run.sim_time:.3f}"),
                       ("frames", str(run.frames)), ("invalid_frames", str(run.invalid_frames)),
                       ("aborted", str(run.aborted).lower()), ("inconclusive", str(counts["inconclusive"]))):
        ET.SubElement(props, "property", name=key, value=xml_safe(value))
    for fault in run.faults:
        ET.SubElement(props, "property", name="fault", value=xml_safe(fault_text(fault)))
    for finding in run.findings:   # warnings of the bench and the plant (bench.checks.findings), once each
        times = f" ({finding.count} times)" if finding.count > 1 else ""
        ET.SubElement(props, "property", name="finding",
                      value=xml_safe(f"{finding.level} {finding.source}: {finding.message}{times}"))
    for case in run.cases:
        _testcase(suite, case)
    if run.aborted:
        tc = ET.SubElement(suite, "testcase", classname="bench.run", name="aborted", time="0.000")
        never = f"; {run.not_run} of {len(run.cases) + run.not_run} cases never ran" if run.not_run else ""
        ET.SubElement(tc, "error", message=f"run aborted: results are incomplete{never}", type="aborted")
    ET.indent(root)
    return ET.ElementTree(root)


def write_junit(run: RunResult, path: Path) -> Path:
    """Write the JUnit XML of ``run`` to ``path`` (parent folders are created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    build_junit(run).write(path, encoding="utf-8", xml_declaration=True)
    return path
