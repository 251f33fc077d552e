"""pytest plugin (entry point `pytest11`): the `bench` fixture and the run's log and reports.

A plain `pytest` on any folder of test cases works: options `--bench-interface`,
`--bench-channel`, `--bench-external`, `--bench-out`, `--bench-config`, `--bench-dut`. The run (bus,
plant, MCAP log) starts at the first case that asks for the `bench` fixture; at the end of the session
`report.html` and `junit.xml` are written next to `run.mcap`, marked aborted on Ctrl-C.

Conformance markers (bench.pytest.marks): `dut`, `req` and `reference_only` are checked against the databases'
nodes and the contract documents when a module is collected (a bad one is that module's collection
error, so nothing runs); reference-only cases are skipped at collection when their node is external;
`--bench-dut NODE` deselects every case that does not judge NODE.
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Generator, Iterator
from datetime import datetime
from pathlib import Path

import pytest
from pluggy import Result

from bench import compiled
from bench.case import Case
from bench.checks.steps import step_values
from bench.config import ProjectConfig, RunSettings, load_config
from bench.database.codec import load_codebook
from bench.errors import BenchError, Inconclusive, unknown_names
from bench.faults.plan import parse_fault
from bench.options import add_pytest_options
from bench.pytest import shard as shards
from bench.pytest.marks import (
    MARKER_HELP,
    CaseMarks,
    check_marks,
    missing_calibration,
    read_marks,
    skip_reason,
    split_names,
)
from bench.pytest.shard import apply_shard
from bench.report import prepare_html
from bench.report.junit import step_summary
from bench.results import store as results_io
from bench.results.model import SIMULATION_FAILED, CaseRef, RequirementInfo, RunResult, Step, Table
from bench.run import MCAP_NAME, BenchRun, default_out_dir, write_reports
from bench.session import resolve_external
from bench.sim.clock import settle_heap
from bench.stop import STOP
from bench.transport import EMBEDDED, check_channel, check_interface, is_embedded
from bench.transport.busopts import BusOptions

_RUN_KEY = pytest.StashKey["BenchRun | None"]()
_CASE_KEY = pytest.StashKey[Case]()
_WALL0_KEY = pytest.StashKey[float]()
_FACTS_KEY = pytest.StashKey["tuple[ProjectConfig, list[str]]"]()
_DESELECTED_KEY = pytest.StashKey[list[CaseRef]]()
_PENDING_KEY = pytest.StashKey[list[tuple[pytest.Item, pytest.TestReport, pytest.CallInfo[None]]]]()
_SELECTED_KEY = pytest.StashKey[list[str]]()   # the case ids this process (or its workers) was given
_last_finished: list[RunResult] = []
_LOG = logging.getLogger("bench.steps")   # failed steps of the bench's own simulation: findings (bench.checks.findings)
PARTS_DIR = "parts"   # where pytest-xdist workers leave their part of the run for the controller


def finished_run() -> RunResult | None:
    """The result of the last run this process finished (for `bench run`)."""
    return _last_finished[-1] if _last_finished else None


def pytest_addoption(parser: pytest.Parser) -> None:
    """The `--bench-*` options, built from the one table the command line is built from (bench.options)."""
    add_pytest_options(parser.getgroup("bench", "HIL CAN bench"))


@pytest.hookimpl(wrapper=True)
def pytest_cmdline_main(config: pytest.Config) -> Generator[None, int | pytest.ExitCode, int | pytest.ExitCode]:
    """`--bench-shard K/N` becomes pytest-split's --splits/--group (least-duration balancing, durations from
    `--bench-durations`, default .test_durations next to bench.toml); before pytest-split checks them."""
    try:
        apply_shard(config)
    except BenchError as exc:
        raise pytest.UsageError(str(exc)) from None
    return (yield)


def pytest_configure(config: pytest.Config) -> None:
    for name, text in MARKER_HELP.items():
        config.addinivalue_line("markers", f"{name}: {text}")
    if _worker_id(config) and config.getoption("--bench-out"):
        STOP.install()   # a worker of `bench run -n`: the controller forwards SIGINT/SIGTERM (bench.stop)
    elif not _worker_id(config):
        prepare_html()   # this process writes the report: its template compiled before any case runs
    config.stash[_RUN_KEY] = None
    config.stash[_DESELECTED_KEY] = []
    config.stash[_PENDING_KEY] = []
    try:
        check_interface(config.getoption("--bench-interface"), "--bench-interface")
        check_channel(config.getoption("--bench-interface"), config.getoption("--bench-channel"), "--bench-channel")
    except BenchError as exc:
        raise pytest.UsageError(str(exc)) from None
    if _xdist_controller(config):
        # Workers inherit the controller's options: decide the one output folder for all of them here.
        if not is_embedded(config.getoption("--bench-interface")):
            raise pytest.UsageError(f"-n (pytest-xdist) runs one embedded bus per worker (--bench-interface "
                                    f"{EMBEDDED}); another bus has one plant and cannot be shared by several runners")
        if not config.getoption("--bench-out"):
            try:   # no bench.toml here or above: one line, not a traceback
                project = load_config(_config_path(config))
            except BenchError as exc:
                raise pytest.UsageError(str(exc)) from None
            config.option.bench_out = str(default_out_dir(project.reports))
        config.stash[_WALL0_KEY] = time.monotonic()


def _xdist_controller(config: pytest.Config) -> bool:
    return bool(getattr(config.option, "numprocesses", None)) and not hasattr(config, "workerinput")


def _worker_id(config: pytest.Config) -> str | None:
    workerinput = getattr(config, "workerinput", None)
    return workerinput["workerid"] if workerinput else None


def _config_path(config: pytest.Config) -> Path | None:
    value = config.getoption("--bench-config")
    return Path(value) if value else None


def _facts(config: pytest.Config) -> tuple[ProjectConfig, list[str]]:
    """The project and the databases' nodes, loaded once per session and only when a case has markers
    (the bench's own tests have none and need no bench.toml)."""
    facts = config.stash.get(_FACTS_KEY, None)
    if facts is None:
        try:
            project = load_config(_config_path(config))
            nodes = load_codebook(project.databases, project.e2e, project.messages).nodes
        except BenchError as exc:
            raise pytest.UsageError(str(exc)) from None
        facts = config.stash[_FACTS_KEY] = (project, nodes)
    return facts


def _documents(project: ProjectConfig) -> str:
    return ", ".join(shown_path(p, project.path.parent) for p in project.contract)


#: What marks the top folder of a repository or project: a document outside the bench.toml's folder is shown
#: relative to the nearest folder above it that has one of these.
_PROJECT_MARKS = (".git", "bench.toml", "pyproject.toml")


def shown_path(path: Path, base: Path) -> str:
    """A contract document's path as the report shows it: relative to bench.toml's folder `base` when inside it,
    else relative to its own repository's top folder (issue 27: with --config elsewhere the conformance table
    showed `../repo/docs/...`), else as given. Never `..` and never this machine's absolute path when a
    repository holds the document."""
    resolved, root = path.resolve(), base.resolve()
    if resolved.is_relative_to(root):
        return resolved.relative_to(root).as_posix()
    for folder in resolved.parents:
        if any((folder / mark).exists() for mark in _PROJECT_MARKS):
            return resolved.relative_to(folder).as_posix()
    return str(path)


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector: pytest.Collector) -> Generator[None, Result[pytest.CollectReport], None]:
    """A collected case with a bad conformance marker makes its module (or class) a collection error that
    names the case and the value: pytest then runs no case at all."""
    outcome = yield
    report: pytest.CollectReport = outcome.get_result()
    if not report.passed:
        return
    problems: dict[tuple[str, str], list[str]] = {}   # (case without parameters, problem) -> node ids
    for item in report.result:
        if not isinstance(item, pytest.Item):
            continue
        marks = read_marks(item)
        if not marks.any:
            continue
        project, nodes = _facts(item.config)
        for problem in check_marks(marks, nodes, project.requirement_ids, _documents(project)):
            problems.setdefault((item.nodeid.partition("[")[0], problem), []).append(item.nodeid)
    if problems:
        lines = [f"{ids[0] if len(ids) == 1 else f'{base}[...] ({len(ids)} parametrized cases)'}: {problem}"
                 for (base, problem), ids in problems.items()]
        report.outcome = "failed"
        report.longrepr = "bad conformance markers:\n" + "\n".join(lines)
        report.result = []


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config, items: list[pytest.Item]) -> None:
    """Skip reference-only cases whose node is external, and in a project without a plant the cases whose DUT is
    not external (the bench would judge its own start values); with --bench-dut keep only the cases judging it."""
    marked = [(item, read_marks(item)) for item in items]
    if any(m.reference_only or m.duts for _, m in marked):
        project, nodes = _facts(config)
        external = _external(config, project)
        start_values_only = set(nodes) - set(project.stimulus) - external if project.plant is None else set()
        for item, marks in marked:
            reason = skip_reason(marks, external, start_values_only)
            if reason:
                item.add_marker(pytest.mark.skip(reason=reason))
    wanted = split_names(config.getoption("--bench-dut"))
    if wanted:
        _, nodes = _facts(config)
        unknown = [n for n in wanted if n not in nodes]
        if unknown:
            raise pytest.UsageError(unknown_names("--bench-dut", unknown, nodes))
        keep = [(item, marks) for item, marks in marked if set(marks.duts) & set(wanted)]
        if len(keep) != len(items):
            kept = {id(i) for i, _ in keep}
            config.hook.pytest_deselected(items=[i for i in items if id(i) not in kept])
            items[:] = [i for i, _ in keep]
            marked = keep
    _check_calibration(config, marked)


def _check_calibration(config: pytest.Config, marked: list[tuple[pytest.Item, CaseMarks]]) -> None:
    """The calibration the selected cases need of their external nodes is in bench.toml, before the first case
    (one line naming the file and the key; a case never learns it too late)."""
    needed = [(item, marks) for item, marks in marked if marks.calibration and not item.get_closest_marker("skip")]
    if not needed:
        return
    project, _ = _facts(config)
    external = _external(config, project)
    problems: dict[str, None] = {}
    for _, marks in needed:
        problems.update(dict.fromkeys(missing_calibration(marks, external, project.calibration)))
    if problems:
        raise pytest.UsageError("; ".join(f"{project.path}: {p}" for p in problems))


def _external(config: pytest.Config, project: ProjectConfig) -> set[str]:
    try:
        return resolve_external(load_codebook(project.databases, project.e2e, project.messages), project.stimulus,
                                config.getoption("--bench-external"))
    except BenchError as exc:
        raise pytest.UsageError(str(exc)) from None


def pytest_collection_finish(session: pytest.Session) -> None:
    session.config.stash[_SELECTED_KEY] = [item.nodeid for item in session.items]


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_newgateway(gateway: object) -> None:
    """A worker process started (`bench run -n`): the controller's stop signals go on to it (bench.stop)."""
    popen = getattr(getattr(gateway, "_io", None), "popen", None)
    pid = getattr(popen, "pid", None)
    if isinstance(pid, int):
        STOP.forward_to(pid)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node: object, ids: list[str]) -> None:
    """The xdist controller collects nothing: its workers' collection (all alike) is the shard's."""
    config = getattr(node, "config", None)
    if config is not None and not config.stash.get(_SELECTED_KEY, None):
        config.stash[_SELECTED_KEY] = list(ids)


def pytest_deselected(items: list[pytest.Item]) -> None:
    """Every deselected bench case (--bench-dut, -k, -m): the conformance section lists it as not run."""
    for item in items:
        if "bench" in getattr(item, "fixturenames", ()):
            marks = read_marks(item)
            item.config.stash[_DESELECTED_KEY].append(CaseRef(item.nodeid, item.name, marks.duts, marks.reqs))


def _catalogue(project: ProjectConfig) -> list[RequirementInfo]:
    base = project.path.parent
    return [RequirementInfo(r.id, r.title, shown_path(r.path, base), r.line) for r in project.requirements]


def _run(config: pytest.Config, start: bool = True) -> BenchRun:
    """The run of this session, created at its first case (and its bus opened, unless `start` is False: a run
    stopped before its first case still writes its report and log)."""
    run = config.stash[_RUN_KEY]
    if run is None:
        project = load_config(_config_path(config))
        settings = RunSettings(interface=config.getoption("--bench-interface"),
                               channel=config.getoption("--bench-channel"),
                               external=list(config.getoption("--bench-external")),
                               bus=BusOptions(bitrate=config.getoption("--bench-bitrate"),
                                              fd=config.getoption("bench_fd"),
                                              data_bitrate=config.getoption("--bench-data-bitrate")))
        out = config.getoption("--bench-out")
        out_dir = Path(out) if out else default_out_dir(project.reports)
        faults = [parse_fault(spec) for spec in config.getoption("--bench-fault")]
        worker = _worker_id(config)
        run = BenchRun(project, settings, out_dir, mcap_name=f"run-{worker}.mcap" if worker else MCAP_NAME)
        run.requirements = _catalogue(project)
        run.deselected = config.stash[_DESELECTED_KEY]
        config.stash[_RUN_KEY] = run
        for item, report, call in config.stash[_PENDING_KEY]:   # cases skipped before the run started
            _record(run, item, report, call)
        config.stash[_PENDING_KEY].clear()
        STOP.install()   # SIGINT and SIGTERM: an ABORTED report within a second (bench.stop)
        if not start:
            return run
        try:
            run.start()
        except BenchError as exc:   # a bus that cannot be opened: one line and stop, not an error per case
            pytest.exit(f"bench: {exc}", returncode=pytest.ExitCode.USAGE_ERROR)
        assert run.session is not None   # started just above (or pytest.exit)
        run.session.faults.extend(faults)
    return run


@pytest.fixture
def bench(request: pytest.FixtureRequest) -> Iterator[Case]:
    """The bench for one test case: set signals, run, wait, check and plot (see bench.case.Case)."""
    run = _run(request.config)
    case = run.begin_case(request.node.nodeid, request.node.name)
    marks = read_marks(request.node)
    case.result.duts, case.result.reqs = marks.duts, marks.reqs
    request.node.stash[_CASE_KEY] = case
    yield case
    case.close()


class FailedSteps(AssertionError):
    """A case whose code ran to its end with failed steps (expect, eventually, ... recorded False)."""


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Generator[None, Result[None], None]:
    """A case fails when a step judging its DUT failed (steps of other nodes are theirs: CaseResult.failed_steps)
    or its code raised; it is inconclusive instead when the bench raised Inconclusive (the watchdog, a limit of
    the bench), when its own timing during the case was past what the checks tolerate (Case.bench_verdict), or when
    its DUT failed while a step of a node the bench simulates (the plant) failed too. A failed step of a node the
    bench simulates is a finding of the run (a warning of the bench) whatever the case's outcome."""
    outcome = yield
    case = item.stash.get(_CASE_KEY, None)
    if case is None:
        return
    excinfo = outcome.excinfo
    if excinfo is not None and (not isinstance(excinfo[1], Exception)
                                or isinstance(excinfo[1], (pytest.skip.Exception, pytest.xfail.Exception))):
        return   # a skip, an xfail, an interrupt: pytest's own
    failed = case.result.failed_steps
    lines = [f"{s.name}: measured {m}, expected {e}" + (f" ({s.tolerance})" if s.tolerance else "")
             for s in failed for m, e in [step_values(s)]]
    if excinfo is not None and isinstance(excinfo[1], Inconclusive):
        case.bench_verdict()
        case.result.inconclusive = str(excinfo[1])
        return
    late = case.bench_verdict()
    simulated = _simulation_failures(case)
    if late and (excinfo is not None or failed):
        case.result.inconclusive = late
        what = "\n".join(lines) if excinfo is None else f"{excinfo[0].__name__}: {excinfo[1]}".splitlines()[0]
        outcome.force_exception(Inconclusive(f"inconclusive: {late}\nwhat failed under it (not the DUT's fault "
                                             f"until shown otherwise):\n{what}"))
    elif excinfo is None and failed and simulated:
        # the DUT failed in a case where the bench's own simulation failed its check too: the DUT's failure may be the
        # simulation's doing, so the bench cannot stand behind it (as with its own lateness)
        nodes = ", ".join(dict.fromkeys(n for s in simulated for n in s.judges))
        case.result.inconclusive = f"{SIMULATION_FAILED} ({nodes}: {step_summary(simulated[0])})"
        outcome.force_exception(Inconclusive(f"inconclusive: {case.result.inconclusive}\nwhat failed under it (not "
                                             f"the DUT's fault until shown otherwise):\n" + "\n".join(lines)))
    elif excinfo is None and failed:
        outcome.force_exception(FailedSteps("failed steps:\n" + "\n".join(lines)))
    for step in simulated:   # a problem of the bench (its plant, a node it simulates): a finding of the run
        _LOG.warning("%s failed a step of %s (the bench's own simulation, not the DUT): %s", step.node,
                     item.nodeid, step_summary(step))


def _diagnostic_errors() -> tuple[type[BaseException], ...]:
    """The tester's one-line failures, when a case has loaded the tester (udsoncan costs 0.3 s of import)."""
    tester = sys.modules.get("bench.diag.tester")
    return (tester.DiagnosticError,) if tester is not None else ()


def _simulation_failures(case: Case) -> list[Step]:
    """The failed steps of other nodes than the case's DUT that the bench itself simulates (none of them external)."""
    external = case.session.external
    return [s for s in case.result.other_failed_steps if not set(s.judges) & external]


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]
                              ) -> Generator[None, Result[pytest.TestReport], None]:
    outcome = yield
    report: pytest.TestReport = outcome.get_result()
    if call.excinfo is not None and call.excinfo.errisinstance((FailedSteps, Inconclusive, *_diagnostic_errors())):
        report.longrepr = str(call.excinfo.value)   # the steps say it all: no traceback through pytest's hooks
        if call.excinfo.errisinstance(Inconclusive):
            # pytest's own outcome stays "failed" (a plain pytest run must not pass it); the bench's records and
            # `bench run` say "inconclusive"
            report.user_properties.append(("bench_outcome", "inconclusive"))
    elif call.excinfo is not None and call.excinfo.errisinstance(BenchError) and getattr(
            item.config.option, "tbstyle", "auto") in ("auto", "short", "line"):   # --tb=long shows it all
        report.longrepr = call_site_error(call.excinfo)
    if "bench" not in getattr(item, "fixturenames", ()):
        return
    run = item.config.stash.get(_RUN_KEY, None)
    if run is None:   # skipped (e.g. reference_only) before any case started the run: recorded once it starts
        item.config.stash[_PENDING_KEY].append((item, report, call))
        return
    _record(run, item, report, call)


def call_site_error(excinfo: pytest.ExceptionInfo[BaseException]) -> str:
    """A BenchError a case's call raised (a value outside the DBC range, an unknown signal, a bad scenario) as one
    line at the case's own call: `test_x.py:12: SignalError: Brake_Request.Pressure: 300 bar is outside
    ...`. The error names the input and what is wrong; the bench's frames below the call add nothing for the
    case's author."""
    entries = [e for e in excinfo.traceback if not Path(str(e.path)).is_relative_to(_PACKAGE)]
    where = ""
    if entries:
        path, here = Path(str(entries[-1].path)), Path.cwd()
        where = f"{path.relative_to(here) if path.is_relative_to(here) else path}:{entries[-1].lineno + 1}: "
    return f"{where}{excinfo.typename}: {excinfo.value}"


_PACKAGE = Path(__file__).resolve().parents[1]   # bench/


def _record(run: BenchRun, item: pytest.Item, report: pytest.TestReport, call: pytest.CallInfo[None]) -> None:
    run.record_report(item.nodeid, item.name, report, call)
    result = run.cases.get(item.nodeid)
    if result is not None and not (result.duts or result.reqs):
        marks: CaseMarks = read_marks(item)
        result.duts, result.reqs = marks.duts, marks.reqs


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """The run's reports. A stop signal from here on raises nothing: it marks the run aborted (bench.stop)."""
    with STOP.finishing():
        _finish_session(session, exitstatus)


def _finish_session(session: pytest.Session, exitstatus: int) -> None:
    config = session.config
    aborted = exitstatus == pytest.ExitCode.INTERRUPTED or STOP.requested
    given = config.stash.get(_SELECTED_KEY, [])
    if _xdist_controller(config):
        out_dir = Path(config.getoption("--bench-out"))
        result = _merge_parts(out_dir, time.monotonic() - config.stash.get(_WALL0_KEY, time.monotonic()), aborted,
                              given)
        if result is None:
            result = _empty_shard(config, out_dir, aborted)
            if result is None:
                return
    else:
        run = config.stash.get(_RUN_KEY, None)
        if run is None and config.stash[_PENDING_KEY] and not aborted:
            run = _run_for_skipped_cases(config)
        worker = _worker_id(config)
        if run is None and STOP.requested and worker is None and shards.current(config) is None:
            # stopped by a signal before its first case (not a collection error): an ABORTED report all the same
            run = _run_for_an_aborted_start(config)
        if run is None:
            out = config.getoption("--bench-out")
            empty = _empty_shard(config, Path(out) if out else None, aborted, worker)
            if empty is None or worker:   # a worker's empty part is for the controller to merge
                return
            result, out_dir = empty, Path(config.getoption("--bench-out"))
        else:
            part = run.out_dir / PARTS_DIR / f"{worker}.json" if worker else None
            result = run.finish(aborted=aborted, part_of=part, given=None if worker else given)
            out_dir = run.out_dir
    _last_finished.append(result)
    _record_shard(config, out_dir)
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line(f"bench: report in {out_dir}")
    if _worker_id(config):
        # A pytest-xdist worker ends with its session. pytest's unraisable-exception cleanup then runs five full
        # collections over the finished run's heap (about 0.25 s of CPU per worker, while the controller merges):
        # one collection here, then the survivors leave the collector's view, so those five see only what is new.
        settle_heap()


def _empty_shard(config: pytest.Config, out_dir: Path | None, aborted: bool,
                 worker: str | None = None) -> RunResult | None:
    """A shard that no case fell to (more shards than cases, or a narrow -k) still writes its report folder
    (a pytest-xdist worker: its part of it), so that `bench report merge` gets all N and the campaign they
    deselected; no bus is opened. None when this run is no shard."""
    which = shards.current(config)
    if which is None or aborted or config.option.collectonly:   # --collect-only lists the shard's cases, no more
        return None
    project, _ = _facts(config)
    folder = out_dir or default_out_dir(project.reports)
    folder.mkdir(parents=True, exist_ok=True)
    config.option.bench_out = str(folder)
    settings = RunSettings(interface=config.getoption("--bench-interface"), channel=config.getoption("--bench-channel"))
    result = RunResult(started=datetime.now().astimezone().isoformat(timespec="seconds"),
                       interface=settings.interface, channel=settings.channel or "",
                       time_mode="virtual" if settings.virtual_time else "real", requirements=_catalogue(project),
                       restbus_only=project.plant is None, build=compiled.status(),
                       deselected=[*config.stash[_DESELECTED_KEY]])
    result.tables.append(Table("Shard", ["shard", "cases"], [[f"{which[0]}/{which[1]}", "none fell to this shard"]]))
    if worker:
        results_io.dump(result, folder / PARTS_DIR / f"{worker}.json")
    else:
        write_reports(result, folder)
    return result


def _record_shard(config: pytest.Config, out_dir: Path) -> None:
    """A shard's report folder gets its shard.json (what `bench report merge` checks the shards with)."""
    if shards.current(config) is None:
        return
    project, _ = _facts(config)
    record = shards.record(config, project.databases, config.stash.get(_SELECTED_KEY, []))
    if record is not None:
        record.dump(out_dir)


def _run_for_an_aborted_start(config: pytest.Config) -> BenchRun | None:
    """A run stopped before its first case (SIGINT or SIGTERM while pytest collected): its log and report are
    written all the same, with no bus opened; the report counts the cases that never ran."""
    try:
        return _run(config, start=False)
    except (BenchError, OSError):
        return config.stash.get(_RUN_KEY, None)


def _run_for_skipped_cases(config: pytest.Config) -> BenchRun | None:
    """Every bench case was skipped (e.g. reference_only with its node external): the run starts only now,
    so that the report still says which cases were skipped and why."""
    try:
        return _run(config)
    except (BenchError, OSError) as exc:
        reporter = config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            reporter.write_line(f"bench: every case was skipped and the run could not start: {exc}")
        return config.stash.get(_RUN_KEY, None)   # created but not started: finish() still closes its log


def _merge_parts(out_dir: Path, wall_time: float, aborted: bool, given: list[str]) -> RunResult | None:
    """The controller's report: every worker's part of the run merged into one report.html/junit.xml."""
    folder = out_dir / PARTS_DIR
    paths = sorted(folder.glob("*.json")) if folder.is_dir() else []
    if not paths:
        return None
    result = results_io.merge([(p.stem, results_io.load(p)) for p in paths], wall_time)
    result.aborted = result.aborted or aborted or STOP.requested
    if result.aborted:
        result.not_run = len(set(given) - {c.nodeid for c in result.cases})
    write_reports(result, out_dir)
    for path in paths:
        path.unlink()
    folder.rmdir()
    return result
