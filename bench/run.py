"""A bench run: one session, its MCAP log, the record of its cases and, at the end, the reports."""

from __future__ import annotations

import dataclasses
import logging
import time
from datetime import datetime
from pathlib import Path

import pytest

from bench import canid, compiled, e2e
from bench.case import Case
from bench.checks.findings import FindingCollector
from bench.checks.monitor import CheckedFrame, DuplicateSender, Monitor
from bench.checks.steps import LOG_ERROR, LOG_INFO, StepLog, step_values
from bench.checks.timing import TimingCollector
from bench.config import ProjectConfig, RunSettings
from bench.database.codec import Codebook
from bench.errors import BenchError, Inconclusive
from bench.faults.plan import Fault
from bench.log.logproc import LogProcess
from bench.results import store as results_io
from bench.results.model import CaseRef, CaseResult, RequirementInfo, RunResult, Step, Table
from bench.session import BenchSession
from bench.stop import STOP

log = logging.getLogger(__name__)

MCAP_NAME, HTML_NAME, JUNIT_NAME = "run.mcap", "report.html", "junit.xml"
RESULTS_NAME = "results.json"   # the run's record, machine-readable: `bench report merge` renders from it


def default_out_dir(reports: Path) -> Path:
    """A new folder under reports/ named by the start time (never reuses one)."""
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    candidate, n = reports / stamp, 1
    while candidate.exists():
        n += 1
        candidate = reports / f"{stamp}-{n}"
    return candidate


class BenchRun:
    def __init__(self, project: ProjectConfig, settings: RunSettings, out_dir: Path,
                 mcap_name: str = MCAP_NAME) -> None:
        self.out_dir = out_dir
        out_dir.mkdir(parents=True, exist_ok=True)
        self.mcap_path = out_dir / mcap_name
        self.started = datetime.now().astimezone().isoformat(timespec="seconds")
        self._wall0 = time.monotonic()
        self.settings = settings
        self.cases: dict[str, CaseResult] = {}
        self._case_wall0: dict[str, float] = {}
        self.recorder: LogProcess | None = None
        self.session: BenchSession | None = None
        self.finished: RunResult | None = None
        self.requirements: list[RequirementInfo] = []   # the contract's catalogue (set by the pytest plugin)
        self.deselected: list[CaseRef] = []             # cases of the campaign this process did not run
        # warnings of the bench and the plant from here to the end become the report's findings
        self.findings = FindingCollector(lambda: self.session.now() if self.session is not None else None)
        self.findings.attach()
        label = f"{settings.interface}:{settings.channel or 'default'}"
        self.recorder = log = LogProcess(self.mcap_path, project.databases, label, project.e2e,
                                         project.diagnostics)
        self.timing = timing = TimingCollector(project.latency)   # the report's timing section, whole run

        def sink(frame: CheckedFrame) -> None:
            log.frame(frame.t, frame.frame_id, frame.data, frame.direction, frame.valid, frame.reason)
            timing(frame)

        self._project, self._sink = project, sink

    def start(self) -> None:
        """Open the bus and start the plant (separate from __init__ so that an interrupt during
        start-up still finds the run and writes an aborted report)."""
        self.session = BenchSession(self._project, self.settings, sink=self._sink)
        self.session.start()
        if self.session.self_timing is not None:   # the bench's own timing counts during the cases (Case resumes it)
            self.session.self_timing.pause()
        if self.recorder is not None:   # MCAP log time = the clock's epoch at bench time 0 + bench time
            self.recorder.origin(self.session.clock.epoch_ns, self.session.clock.realtime)
            self.session.faults.listener = self._log_fault

    # -- cases ---------------------------------------------------------------------------------------
    def begin_case(self, nodeid: str, name: str) -> Case:
        assert self.session is not None
        self.session.clock.between_cases()   # real time: the garbage collector's full scans here, not in the case
        # "aborted" until the call phase reports: a case cut short by Ctrl-C stays aborted.
        result = CaseResult(nodeid=nodeid, name=name, outcome="aborted", sim_start=self.session.now(),
                            message="the run was interrupted during this case")
        self.cases[nodeid] = result
        self._case_wall0[nodeid] = time.monotonic()
        self._log(LOG_INFO, "case", f"start {nodeid}")
        steps = StepLog(self.session.now, self._step_listener)
        result.steps = steps.steps
        return Case(self.session, result, steps)

    def _log_fault(self, fault: Fault) -> None:
        """Every injected fault into the MCAP log's metadata, as it is added (a killed run still has it)."""
        if self.recorder is not None:
            record = fault.record()
            self.recorder.metadata("bench.fault", {
                "spec": record.spec, "source": record.source, "kind": record.kind, "target": record.target,
                "window": "case" if record.relative == "case" else "run",
                "start_s": f"{record.start:g}", "end_s": "" if record.end is None else f"{record.end:g}"})

    def _step_listener(self, step: Step) -> None:
        level = LOG_INFO if step.verdict == "pass" else LOG_ERROR
        measured, expected = step_values(step)
        self._log(level, step.name, f"{step.verdict.upper()}: measured {measured}, expected "
                                    f"{expected} ({step.tolerance}) {step.unit}".rstrip())

    def _log(self, level: int, name: str, message: str) -> None:
        if self.recorder is not None and self.session is not None:
            self.recorder.step(self.session.now(), level, name, message)

    def record_report(self, nodeid: str, name: str, report: pytest.TestReport, call: pytest.CallInfo[None]) -> None:
        result = self.cases.get(nodeid)
        if result is None:   # skipped or errored before the fixture ran
            now = self.session.now() if self.session else 0.0
            result = self.cases[nodeid] = CaseResult(nodeid=nodeid, name=name, outcome="passed", sim_start=now)
        if report.when == "call" and report.passed:
            result.outcome, result.message = "passed", ""
        elif report.skipped:
            result.outcome = "skipped"
            result.message = _longrepr(report)
        elif report.failed and report.when == "call" and call.excinfo is not None \
                and call.excinfo.errisinstance(Inconclusive):
            result.outcome = "inconclusive"   # the bench's own timing or limit: not a failure of the DUT
            result.message = _longrepr(report)
            result.inconclusive = result.inconclusive or result.message.splitlines()[0]
        elif report.failed:
            result.outcome = "failed" if report.when == "call" else "error"
            result.message = _longrepr(report)
        if report.when in ("call", "teardown") and self.session is not None:
            result.sim_time = self.session.now() - result.sim_start
            result.wall_time = self._wall_since(nodeid)
        if report.when == "teardown":
            self._log(LOG_INFO if result.outcome in ("passed", "skipped") else LOG_ERROR, "case",
                      f"{result.outcome} {nodeid}")

    def _wall_since(self, nodeid: str) -> float:
        """Wall time since the case began (0 for one that never did; one clock read, so never -0.00)."""
        now = time.monotonic()
        return now - self._case_wall0.get(nodeid, now)

    # -- end -----------------------------------------------------------------------------------------
    def finish(self, aborted: bool = False, part_of: Path | None = None, given: list[str] | None = None) -> RunResult:
        """Close the bus and the log, then write the reports (or, for a pytest-xdist worker, its part
        of the run into `part_of` for the controller to merge); safe to call twice. `given`: the ids of the
        cases this run was to run (an aborted report counts those that never started). A stop signal before
        the reports are written marks the run aborted (bench.stop)."""
        if self.finished is not None:
            return self.finished

        session = self.session
        for nodeid, result in self.cases.items():
            if result.outcome == "aborted" and session is not None:
                result.sim_time = session.now() - result.sim_start
                result.wall_time = self._wall_since(nodeid)
        monitor = session.monitor if session else None
        run = RunResult(
            started=self.started, interface=self.settings.interface, channel=self.settings.channel or "",
            time_mode="virtual" if self.settings.virtual_time else "real",
            external=sorted(session.external) if session else [], restbus_only=self._project.plant is None,
            build=compiled.status(), cases=list(self.cases.values()),
            mcap_path=self.mcap_path.name if self.mcap_path.parent == self.out_dir else str(self.mcap_path),
            aborted=aborted, wall_time=time.monotonic() - self._wall0,
            sim_time=session.now() if session else 0.0,
            frames=monitor.frames if monitor else 0, invalid_frames=monitor.invalid_frames if monitor else 0,
            requirements=list(self.requirements), deselected=list(self.deselected),
            faults=session.faults.records() if session else [])
        if session is not None:   # the report's timing section (bench.checks.timing); never raises
            run.tables.extend(self.timing.tables(session.codebook))
            if session.self_timing is not None:   # real time: the bench's own lateness (what it really sent)
                run.tables.append(session.self_timing.table())
            if session.runner is not None:
                run.tables.append(e2e_table(session.runner.monitor))
            run.tables.append(database_table(session.codebook))
            found = duplicates_table([s.monitor for s in (session.runner, session.plant) if s is not None])
            if found is not None:   # a finding of its own, first among the tables
                run.tables.insert(0, found)
        try:
            if session is not None:
                for station in session.stations:   # counted per frame by the station; said once here
                    if station.send_errors:
                        log.warning("%s station: %d frames could not be sent (the bus driver refused them: a "
                                    "full transmit queue or bus-off)", station.name, station.send_errors)
                session.close()
        finally:
            run.findings = self.findings.detach()
            if self.recorder is not None:
                try:
                    if run.faults:   # what each fault did, for tools that read the log without the report
                        self.recorder.metadata("bench.faults", {
                            f"{i}": f"{f.spec} from {f.source}: {f.frames} frames" for i, f in enumerate(run.faults)})
                    self.recorder.close()
                except BenchError as exc:   # the report must still be written, and say what happened
                    run.tables.insert(0, Table("Run log problem", ["problem"], [[str(exc)]]))
            run.aborted = run.aborted or STOP.requested   # a signal while the bus and the log closed
            if run.aborted and given is not None:
                run.not_run = len(set(given) - set(self.cases))
            if part_of is not None:
                results_io.dump(_without_plots(run) if STOP.requested else run, part_of)
            else:
                write_reports(run, self.out_dir)
            self.finished = run
        return run


def write_reports(run: RunResult, out_dir: Path) -> None:
    """report.html, junit.xml and results.json. After a stop signal (bench.stop) the HTML draws plots only within
    the signal's budget and results.json leaves the plot data out: the process ends within a second."""
    from bench.report import write_html, write_junit  # jinja2 only when a report is written

    write_html(run, out_dir / HTML_NAME, STOP.keep_drawing)
    write_junit(run, out_dir / JUNIT_NAME)
    results_io.dump(_without_plots(run) if STOP.requested else run, out_dir / RESULTS_NAME)


def _without_plots(run: RunResult) -> RunResult:
    """The run without its cases' plot data (0.5 s of JSON for the 147-case campaign; the rest 0.02 s)."""
    return dataclasses.replace(run, cases=[dataclasses.replace(c, plots=[]) for c in run.cases])


def duplicates_table(monitors: list[Monitor]) -> Table | None:
    """Identifiers with two senders (bench.checks.monitor.DuplicateSender), one row each, with the evidence; the
    first monitor's finding of an identifier wins. None when there is none."""
    found: dict[int, DuplicateSender] = {}
    for monitor in monitors:
        for frame_id, finding in monitor.duplicates.items():
            found.setdefault(frame_id, finding)
    if not found:
        return None
    rows = [[canid.text(f.frame_id), f.message, f.describe(), f"{f.t:.3f}", str(f.frames)]
            for _, f in sorted(found.items())]
    return Table("Findings: two senders of one identifier", ["id", "message", "finding", "from [s]", "frames"], rows)


def database_table(codebook: Codebook) -> Table:
    """What the run was checked against: every message of the databases with its E2E protection and its comment
    (DBC text: the report escapes it like every other string)."""
    rows = [[db_name, canid.text(m.frame_id), m.name, ", ".join(m.senders),
             f"{m.cycle_time * 1000:g}" if m.cycle_time else "–",
             m.protection.describe() if m.protection is not None else "unprotected", m.message.comment or ""]
            for db_name, m in sorted(((c.database, c) for c in codebook.by_id.values()), key=lambda x: x[1].frame_id)]
    return Table("Databases: the messages this run checked", ["database", "id", "message", "sender", "cycle [ms]",
                                                                "E2E protection", "comment"], rows)


#: The AUTOSAR check statuses, in the order the E2E table shows them.
E2E_STATUSES = [status.value for status in e2e.Status]


def e2e_table(monitor: Monitor) -> Table:
    """AUTOSAR E2E per message over the whole run, as the test runner's receiver judged it: frames per check
    status and the E2E state machine's state at the end (unprotected messages say so)."""
    rows = []
    for state in sorted(monitor.states.values(), key=lambda s: s.codec.frame_id):
        if not state.frames:
            continue
        protection = state.codec.protection
        if state.rx is None or protection is None:
            rows.append([state.codec.name, "unprotected", *["–"] * len(E2E_STATUSES), "–"])
            continue
        rows.append([state.codec.name, protection.profile,
                     *[str(state.e2e_status.get(name, 0)) for name in E2E_STATUSES], state.rx.state.value])
    return Table("E2E: AUTOSAR check status per message over the whole run (frames the test runner received; a frame "
                 "is applied when its status is OK or OKSOMELOST and the state machine is VALID, docs/spec/e2e.md)",
                 ["Message", "Profile", *E2E_STATUSES, "state at the end"], rows)


def _longrepr(report: pytest.TestReport) -> str:
    if report.skipped and isinstance(report.longrepr, tuple):
        return str(report.longrepr[2])
    return str(report.longreprtext or "")
