"""pytest plugin (entry point `pytest11`): the `bench` fixture and the run's log and reports.

A plain `pytest` on any folder of test cases works: options `--bench-interface`,
`--bench-channel`, `--bench-external`, `--bench-out`, `--bench-config`. The run (bus, plant,
MCAP log) starts at the first case that asks for the `bench` fixture; at the end of the session
`report.html` and `junit.xml` are written next to `run.mcap`, marked aborted on Ctrl-C.
"""

from __future__ import annotations

import signal
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from bench.case import Case
from bench.config import RunSettings, load_config
from bench.faults import parse_fault
from bench.results import RunResult
from bench import results_io
from bench.run import MCAP_NAME, BenchRun, default_out_dir, write_reports

_RUN_KEY = pytest.StashKey["BenchRun | None"]()
_CASE_KEY = pytest.StashKey[Case]()
_WALL0_KEY = pytest.StashKey[float]()
_last_finished: list[RunResult] = []
PARTS_DIR = "parts"   # where pytest-xdist workers leave their part of the run for the controller


def finished_run() -> RunResult | None:
    """The result of the last run this process finished (for `bench run`)."""
    return _last_finished[-1] if _last_finished else None


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("bench", "HIL CAN bench")
    group.addoption("--bench-interface", default="virtual",
                    help="python-can interface, or 'virtual' for the in-process virtual-time bus (default)")
    group.addoption("--bench-channel", default=None, help="channel of the interface (e.g. vcan0)")
    group.addoption("--bench-external", action="append", default=[], metavar="NODE",
                    help="a node that is real (not simulated); 'all' = every node but the stimulus")
    group.addoption("--bench-fault", action="append", default=[], metavar="SPEC",
                    help="inject a fault for the whole run: KIND:TARGET[:PARAM]@START[-END] (bench.faults)")
    group.addoption("--bench-out", default=None, help="folder for report.html, run.mcap, junit.xml")
    group.addoption("--bench-config", default=None, help="bench.toml of the project")


def pytest_configure(config: pytest.Config) -> None:
    config.stash[_RUN_KEY] = None
    if _xdist_controller(config):
        # Workers inherit the controller's options: decide the one output folder for all of them here.
        if config.getoption("--bench-interface") not in ("virtual", "bench_virtual"):
            raise pytest.UsageError("-n (pytest-xdist) runs one in-process virtual bus per worker; a real bus "
                                    "has one plant and cannot be shared by several runners")
        if not config.getoption("--bench-out"):
            project = load_config(_config_path(config))
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


def _run(config: pytest.Config) -> BenchRun:
    run = config.stash[_RUN_KEY]
    if run is None:
        project = load_config(_config_path(config))
        settings = RunSettings(interface=config.getoption("--bench-interface"),
                               channel=config.getoption("--bench-channel"),
                               external=list(config.getoption("--bench-external")))
        out = config.getoption("--bench-out")
        out_dir = Path(out) if out else default_out_dir(project.reports)
        faults = [parse_fault(spec) for spec in config.getoption("--bench-fault")]
        worker = _worker_id(config)
        run = BenchRun(project, settings, out_dir, mcap_name=f"run-{worker}.mcap" if worker else MCAP_NAME)
        config.stash[_RUN_KEY] = run
        run.start()
        run.session.faults.extend(faults)
        if signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, None):
            signal.signal(signal.SIGTERM, _terminate)
    return run


def _terminate(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


@pytest.fixture
def bench(request: pytest.FixtureRequest) -> Iterator[Case]:
    """The bench for one test case: set signals, run, wait, check and plot (see bench.case.Case)."""
    run = _run(request.config)
    case = run.begin_case(request.node.nodeid, request.node.name)
    request.node.stash[_CASE_KEY] = case
    yield case
    case.close()


class FailedSteps(AssertionError):
    """A case whose code ran to its end with failed steps (expect, eventually, ... recorded False)."""


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    outcome = yield
    case = item.stash.get(_CASE_KEY, None)
    if case is not None and outcome.excinfo is None and case.result.failed_steps:
        lines = [f"{s.name}: measured {s.measured}, expected {s.expected} ({s.tolerance})"
                 for s in case.result.failed_steps]
        outcome.force_exception(FailedSteps("failed steps:\n" + "\n".join(lines)))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[None]:
    outcome = yield
    report: pytest.TestReport = outcome.get_result()
    if call.excinfo is not None and call.excinfo.errisinstance(FailedSteps):
        report.longrepr = str(call.excinfo.value)   # the steps say it all: no traceback through pytest's hooks
    run = item.config.stash.get(_RUN_KEY, None)
    if run is None or "bench" not in getattr(item, "fixturenames", ()):
        return
    run.record_report(item.nodeid, item.name, report, call)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    config = session.config
    aborted = exitstatus == pytest.ExitCode.INTERRUPTED
    if _xdist_controller(config):
        out_dir = Path(config.getoption("--bench-out"))
        result = _merge_parts(out_dir, time.monotonic() - config.stash.get(_WALL0_KEY, time.monotonic()), aborted)
        if result is None:
            return
    else:
        run = config.stash.get(_RUN_KEY, None)
        if run is None:
            return
        worker = _worker_id(config)
        part = run.out_dir / PARTS_DIR / f"{worker}.json" if worker else None
        result = run.finish(aborted=aborted, part_of=part)
        out_dir = run.out_dir
    _last_finished.append(result)
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line(f"bench: report in {out_dir}")


def _merge_parts(out_dir: Path, wall_time: float, aborted: bool) -> RunResult | None:
    """The controller's report: every worker's part of the run merged into one report.html/junit.xml."""
    folder = out_dir / PARTS_DIR
    paths = sorted(folder.glob("*.json")) if folder.is_dir() else []
    if not paths:
        return None
    result = results_io.merge([(p.stem, results_io.load(p)) for p in paths], wall_time)
    result.aborted = result.aborted or aborted
    write_reports(result, out_dir)
    for path in paths:
        path.unlink()
    folder.rmdir()
    return result
