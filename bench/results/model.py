"""The record of a run: test cases, their steps (every check), plots and run facts.

Filled by the pytest plugin, read by the HTML and JUnit writers; plain data so that
reporting never needs the bus or pytest.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

Verdict = Literal["pass", "fail"]
#: "inconclusive": the bench's own timing during the case was worse than its checks tolerate (a stimulus frame
#: late past its receivers' timeout, the watchdog, a history limit of the bench): its verdict cannot be
#: stood behind, and the DUT is not blamed (docs/reliability.md "The bench's own timing").
Outcome = Literal["passed", "failed", "skipped", "error", "aborted", "inconclusive"]
#: How CaseResult.inconclusive begins when a DUT's failure coincided with a failed step of a node the bench itself
#: simulates (the plant, a simulated ECU): the bench cannot stand behind that failure (docs/contract/README.md, "Steps
#: judge the node they name").
SIMULATION_FAILED = "the bench's own simulation failed a check in this case"


@dataclass
class Step:
    """One check: what was measured against what was expected, with which tolerance."""

    name: str
    measured: float | str | None
    expected: float | str | None
    tolerance: str
    verdict: Verdict
    time: float  # bench time of the check, s
    unit: str = ""
    detail: str = ""
    node: str = ""   # the node this step judges when it is not the case's DUT ("": the DUT): its failure is that
                     # node's, shown with its name, and never fails the case (CaseResult.failed_steps); several
                     # nodes comma-separated (a message with several senders, Case.check_cycle_times)

    @property
    def judges(self) -> tuple[str, ...]:
        """The nodes this step names (`node` split at its commas); () for a step of the case's DUT."""
        return tuple(n for n in self.node.split(",") if n)


@dataclass
class Series:
    name: str
    x: list[float]
    y: list[float]
    gap: float | None = None     # x step beyond which the line breaks (2.5 cycles of the message); None: never


@dataclass
class FaultRecord:
    """An injected fault as the reports show it: what, from where, when (bench time) and how much it did."""

    spec: str                    # KIND:TARGET[:PARAM]@[case+]START[-END], as the command line takes it
    source: str                  # "command line", or the node id of the case that injected it
    kind: str
    target: str
    start: float                 # s: bench time (relative "case": from each case's start)
    end: float | None            # s; None: to the end of the run (or of the case)
    frames: int = 0              # frames it acted on (dropped, delayed, duplicated, corrupted, babbled)
    relative: str = "run"        # "run" or "case"


@dataclass
class Plot:
    """A plot of signals a case looked at. kind "time": x is time in s; kind "xy": a top view (equal axes)."""

    title: str
    xlabel: str
    ylabel: str
    series: list[Series]
    kind: Literal["time", "xy"] = "time"
    x0: float | None = None      # bench time at x = 0 of a time plot (to shade fault windows); None: unknown


@dataclass
class Table:
    """A free table a case adds to the report (for example measured figures next to a paper's)."""

    title: str
    columns: list[str]
    rows: list[list[str]]


@dataclass
class CaseResult:
    nodeid: str
    name: str
    outcome: Outcome
    wall_time: float = 0.0       # s
    sim_start: float = 0.0       # bench time at the start of the case, s
    sim_time: float = 0.0        # bench time the case took, s
    steps: list[Step] = field(default_factory=list)
    plots: list[Plot] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    message: str = ""            # failure or skip text
    duts: list[str] = field(default_factory=list)   # the nodes the case judges (@pytest.mark.dut)
    reqs: list[str] = field(default_factory=list)   # the requirement ids it checks (@pytest.mark.req)
    faults: list[FaultRecord] = field(default_factory=list)   # faults active during the case (windows clipped)
    invalid_frames: int = 0      # frames the monitor rejected during the case
    invalid: list[list[str]] = field(default_factory=list)    # [message, reason, count] of those frames
    # The bench's own timing during the case (real time only; bench.checks.timing.SelfTiming): one line per figure,
    # e.g. "stimulus MSG: late by 146.0 ms at 12.300 s, bound 20 ms", and the one line that made the
    # case inconclusive ("" when none did).
    bench_timing: list[str] = field(default_factory=list)
    inconclusive: str = ""

    @property
    def failed_steps(self) -> list[Step]:
        """The failed steps that judge the case's DUT (every failed step of a case without `dut` markers)."""
        return [s for s in self.steps if s.verdict == "fail" and (not s.node or not self.duts or s.node in self.duts)]

    @property
    def other_failed_steps(self) -> list[Step]:
        """Failed steps that judge another node than the case's DUT: that node's, not the case's."""
        return [s for s in self.steps if s.verdict == "fail" and s not in self.failed_steps]

    @property
    def other_nodes(self) -> list[str]:
        """The nodes the case's steps name that are not its DUTs, in the order the steps first name them (the case
        judges them too, each by its own steps; their verdicts are `outcome_of`)."""
        out: list[str] = []
        for step in self.steps:
            out.extend(n for n in step.judges if n not in self.duts and n not in out)
        return out

    def outcome_of(self, node: str) -> str:
        """The case's outcome for one node it judges. A DUT's (and every node's, in a case without `dut` markers): the
        case's outcome, made of the DUT's steps only. Another node named by steps (`other_nodes`): "failed" when one
        of its steps failed, else "passed"; a case that was skipped, errored or was aborted is so for every node, and
        one made inconclusive by the bench's timing or limits is inconclusive for every node (one made inconclusive
        by this node's failure, SIMULATION_FAILED, is "failed" for it). A node neither a DUT nor named by a step (a
        requirement the case names, owned by a node it has no step of): the case's outcome."""
        if not self.duts or node in self.duts or self.outcome not in ("passed", "failed", "inconclusive"):
            return self.outcome
        steps = [s for s in self.steps if node in s.judges]
        if not steps:
            return self.outcome
        failed = any(s.verdict == "fail" for s in steps)
        if self.outcome == "inconclusive" and not self.inconclusive.startswith(SIMULATION_FAILED):
            return "inconclusive"
        return "failed" if failed else "passed"


@dataclass
class RequirementInfo:
    """One requirement of the contract documents, as the report shows it."""

    id: str
    title: str
    document: str                # path of the contract document, as bench.toml resolved it
    line: int = 0


@dataclass
class CaseRef:
    """A case of the campaign that did not run in this process (deselected by --bench-dut or -k):
    the conformance section still lists it under the requirements it checks."""

    nodeid: str
    name: str
    duts: list[str] = field(default_factory=list)
    reqs: list[str] = field(default_factory=list)


@dataclass
class Finding:
    """Something that went wrong without stopping the run: a warning the bench or the plant logged
    (bench.checks.findings), e.g. frames the driver could not send."""

    source: str                  # the logger: "bench.sim.station", "bench.transport.periodic", "plant...."
    level: str                   # "warning", "error" or "critical"
    message: str
    time: float | None = None    # bench time of the first occurrence, s; None before the clock ran
    count: int = 1               # how often the same message came


@dataclass
class RunResult:
    started: str                 # ISO 8601 wall time
    interface: str
    channel: str
    time_mode: Literal["virtual", "real"]
    external: list[str] = field(default_factory=list)
    restbus_only: bool = False   # the project has no plant: each simulated node was its database's start values
    build: str = ""              # compiled (mypyc) or pure Python, and why (bench.compiled.status)
    cases: list[CaseResult] = field(default_factory=list)
    mcap_path: str = ""
    aborted: bool = False
    wall_time: float = 0.0
    sim_time: float = 0.0
    frames: int = 0
    invalid_frames: int = 0
    tables: list[Table] = field(default_factory=list)
    requirements: list[RequirementInfo] = field(default_factory=list)   # the contract's catalogue
    deselected: list[CaseRef] = field(default_factory=list)
    faults: list[FaultRecord] = field(default_factory=list)   # every fault injected in the run
    findings: list[Finding] = field(default_factory=list)     # warnings logged during the run (bench.checks.findings)
    not_run: int = 0             # cases this run was given that never started (an aborted run's rest)

    @property
    def counts(self) -> dict[str, int]:
        out = {"passed": 0, "failed": 0, "inconclusive": 0, "skipped": 0, "error": 0, "aborted": 0}
        for case in self.cases:
            out[case.outcome] += 1
        return out

    @property
    def verdict(self) -> Literal["PASS", "FAIL", "INCONCLUSIVE", "ABORTED"]:
        """FAIL when a case failed or errored; else INCONCLUSIVE when a case was (the bench could not stand behind
        its verdict); else PASS."""
        if self.aborted:
            return "ABORTED"
        c = self.counts
        if c["failed"] or c["error"] or not self.cases:
            return "FAIL"
        return "INCONCLUSIVE" if c["inconclusive"] else "PASS"
