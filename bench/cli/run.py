"""`bench run`: run the test cases, show progress, write report.html, run.mcap and junit.xml."""

from __future__ import annotations

import argparse
import atexit
import gc
import itertools
import os
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import pytest
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from bench import compiled, options
from bench.cli.common import (
    BUS_OPTIONS,
    NODE_OPTIONS,
    add_bus_options,
    add_node_options,
    check_out_dir,
    given_bus_options,
)
from bench.config import ProjectConfig, load_config
from bench.database.codec import load_codebook
from bench.errors import BenchError, ConfigError, InputProblems, did_you_mean, unknown_names
from bench.faults.plan import validate as validate_faults
from bench.options import add_cli_options
from bench.plugins import load_plant
from bench.pytest import shard
from bench.pytest.marks import split_names
from bench.report.junit import step_summary
from bench.run import default_out_dir
from bench.session import resolve_bus_options, resolve_external, simulated_nodes
from bench.sim.clock import settle_heap
from bench.stop import STOP
from bench.transport import EMBEDDED, check_channel, check_interface, is_embedded, probe_bus
from bench.transport.busopts import BusOptions

OUTCOME_STYLE = {"passed": "green", "failed": "bold red", "error": "bold red", "skipped": "yellow",
                 "aborted": "bold magenta", "inconclusive": "bold yellow"}
#: `bench run`'s exit code when no case failed but one or more were inconclusive (the bench's own timing or a
#: limit of the bench: bench.errors.Inconclusive); 0: every case passed, 1: a case failed, 2: bad input; stopped by a
#: signal: 128 + its number (130 SIGINT, 143 SIGTERM: bench.stop.StopRequests.exit_code).
EXIT_INCONCLUSIVE = 3


#: `bench run`'s own options beyond the bus and node groups (declared in bench.options, like those).
RUN_OPTIONS = ("keyword", "dut", "shard", "durations", "out", "force", "workers")
#: Everything `bench run` hands to pytest (the plugin's --bench-* options and pytest's -k, -n).
HANDED_TO_PYTEST = (*BUS_OPTIONS, *NODE_OPTIONS, *RUN_OPTIONS)
#: pytest-xdist's distribution with -n. Its default ("load") hands out the cases in chunks in collection order, so
#: a long case late in the order (the 4WS slalom: a fifth of the campaign's recorded duration) ends the run with
#: one worker alone; "worksteal" lets an idle worker take half of the other's queue. Replayed with the campaign's
#: .test_durations through xdist's own schedulers (2 workers): load 12 % over an even split, worksteal 1 %.
DIST = "worksteal"


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = sub.add_parser("run", help="run the test cases and write a report",
                            description="Run the test cases (default: testcases/ on the embedded bus, in "
                                        "process and in virtual time) and write report.html, run.mcap, junit.xml.")
    add_bus_options(parser, EMBEDDED)
    add_node_options(parser)
    add_cli_options(parser, RUN_OPTIONS)
    parser.add_argument("paths", nargs="*", help="test files or folders (default: the project's testcases)")
    parser.set_defaults(handler=run)


class _Progress:
    """A pytest plugin that shows one line per case and a summary table at the end.

    Case ids are printed escaped (a parameter id like `[left]` is text, not rich markup); with -n the
    controller collects nothing itself, so the total comes from the first worker's collection."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self.total = 0
        self.done = 0
        self.collect_errors: list[str] = []
        self.deselected = 0   # cases -k or --dut left out (this process's collection; none on an xdist controller)

    def pytest_collectreport(self, report: pytest.CollectReport) -> None:
        if report.failed:
            self.collect_errors.append(f"{report.nodeid}: {report.longreprtext}")
            self.console.print(f"[bold red]cannot collect {escape(report.nodeid)}[/]", highlight=False)
            self.console.print(report.longreprtext, highlight=False, markup=False)

    def pytest_keyboard_interrupt(self, excinfo: pytest.ExceptionInfo[BaseException]) -> None:
        """pytest.exit (the plugin stops a run that cannot go on) is reported here too; without pytest's
        terminal its reason would be lost and the run would end as a bare FAIL."""
        if isinstance(excinfo.value, pytest.exit.Exception):
            reason = str(excinfo.value.msg).removeprefix("bench: ")
            self.console.print(f"[bold red]bench run: error:[/] {escape(reason)}", highlight=False)

    def pytest_deselected(self, items: list[pytest.Item]) -> None:
        self.deselected += len(items)

    def pytest_collection_finish(self, session: pytest.Session) -> None:
        if getattr(session.config.option, "numprocesses", None):
            return                                  # the xdist controller: the workers collect
        self._announce(len(session.items))

    @pytest.hookimpl(optionalhook=True)
    def pytest_xdist_node_collection_finished(self, node: object, ids: list[str]) -> None:
        if not self.total:
            self._announce(len(ids))

    def _announce(self, total: int) -> None:
        self.total = total
        if total:   # none: `run` says why, in one line
            self.console.print(f"bench: {self.total} cases; the bench's core: {compiled.status()}", highlight=False)

    @pytest.hookimpl(trylast=True)
    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        """After the reports (the bench plugin's sessionfinish): collect once, then keep the finished run's heap
        out of the collector's view, so that pytest's unraisable-exception cleanup does not run five full
        collections over it (about 0.3 s of CPU in a 200-case run). `run` gives the heap back when pytest is done.
        After a stop signal only the freeze: the process must end within a second of it (bench.stop)."""
        if STOP.requested:
            gc.freeze()
        else:
            settle_heap()

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when == "call" or (report.when == "setup" and not report.passed):
            self.done += 1
            outcome = "error" if (report.when == "setup" and report.failed) else str(
                dict(report.user_properties).get("bench_outcome", report.outcome))   # "inconclusive" (the plugin)
            style = OUTCOME_STYLE.get(outcome, "")
            self.console.print(f"\\[{self.done:>3}/{self.total}] [{style}]{outcome:<7}[/] "
                               f"{escape(report.nodeid)} [dim]({report.duration:.2f} s)[/]", highlight=False)
            if report.failed:
                self.console.print(report.longreprtext, highlight=False, markup=False)


def _settle_at_exit() -> None:
    """Once per process: when the interpreter exits, collect once and freeze what is left (bench.sim.clock.settle_heap).
    Python's shutdown otherwise runs several full collections over a heap that a run made large (a long pause after
    the report is out: docs/performance.md); the garbage present at exit is still collected, except after a
    stop signal (then only the freeze: the process ends within a second of the signal, bench.stop)."""
    atexit.unregister(settle_heap)   # registered once however often run() is called
    atexit.unregister(gc.freeze)
    atexit.register(gc.freeze if STOP.requested else settle_heap)


def _short(nodeid: str) -> str:
    """`testcases/test_x.py::test_y[p]` -> `test_x::test_y[p]`: what a reader needs in a narrow table."""
    path, sep, rest = nodeid.partition("::")
    return path.rsplit("/", 1)[-1].removesuffix(".py") + sep + rest


def _check_before_running(project: ProjectConfig, args: argparse.Namespace, out_dir: Path) -> None:
    """Every input, before pytest starts: databases, nodes, interface and channel, bus settings, faults,
    the report folder and, last, the bus itself (opened once and closed). Each problem is one line and
    the run does not start (exit 2), rather than an error in every case."""
    problems: list[str] = []

    def check(action: Callable[..., object], *arguments: object) -> object:
        try:
            return action(*arguments)
        except BenchError as exc:
            problems.extend(getattr(exc, "problems", None) or [str(exc)])
            return None

    # a database that does not load makes every other check moot
    codebook = load_codebook(project.databases, project.e2e, project.messages)
    problems.extend(project.problems(codebook))
    for path in args.paths:
        if not Path(path.partition("::")[0]).exists():
            problems.append(f"{path}: no such test file or folder")
    if not args.paths:
        problems.extend(_testcases_problems(project))
    external = check(resolve_external, codebook, project.stimulus, args.external)
    if (project.plant is not None and isinstance(external, set)
            and set(codebook.nodes) - set(project.stimulus) - external):   # the plant is needed
        try:
            load_plant(project.plant)
        except BenchError as exc:
            problems.append(f"{project.path}: [bench] plant: {exc}")
    unknown = [n for n in split_names(args.dut) if n not in codebook.nodes]
    if unknown:
        problems.append(unknown_names("--dut", unknown, codebook.nodes))
    before = len(problems)
    check(check_interface, args.interface)
    interface_known = len(problems) == before
    check(check_channel, args.interface, args.channel)
    if args.workers is not None and not _workers_ok(args.workers):
        problems.append(f"-n {args.workers}: not a number of worker processes (a whole number, or auto: one "
                        "per core)")
    elif args.workers and not is_embedded(args.interface):
        problems.append(f"-n: parallel workers each run their own embedded bus (--interface {EMBEDDED}, virtual "
                        f"time); --interface {args.interface} is not it")
    options = check(resolve_bus_options, project, given_bus_options(args), codebook)
    simulated = simulated_nodes(codebook, project.stimulus, external, "runner") if isinstance(external, set) else None
    problems.extend(validate_faults(args.fault, codebook, simulated))
    problems.extend(shard.check(args.shard, args.durations, project.path.parent))
    check(check_out_dir, out_dir, args.force)
    if not problems and interface_known:
        assert isinstance(options, BusOptions)
        check(probe_bus, args.interface, args.channel, options)
    if problems:
        raise InputProblems(problems)


def _testcases_problems(project: ProjectConfig) -> list[str]:
    """bench.toml's `testcases` names a file or folder that exists (else pytest would say "file or directory not
    found" after the bench has started), with the folder beside it that was most likely meant."""
    if project.testcases.exists():
        return []
    base = project.path.parent
    shown = project.testcases.relative_to(base) if project.testcases.is_relative_to(base) else project.testcases
    parent = project.testcases.parent
    beside = [p.name for p in parent.iterdir() if p.is_dir() and not p.name.startswith(".")] if parent.is_dir() else []
    return [f"{project.path}: [bench] testcases: no such file or folder {str(shown)!r}"
            f"{did_you_mean(project.testcases.name, beside)} (relative to {base})"]


def _workers_ok(text: str) -> bool:
    """-n as pytest-xdist takes it: a whole number of processes (0: none), `auto` or `logical`."""
    return text in ("auto", "logical") or (text.isascii() and text.isdigit())


def _new_folders(folder: Path) -> list[Path]:
    """The folders on the way to `folder` that do not exist yet, deepest first: what the run creates, and
    removes again (if still empty) when it is rejected or no case runs."""
    return list(itertools.takewhile(lambda f: not f.exists(), (folder, *folder.parents)))


def _remove_empty(folders: list[Path]) -> None:
    for folder in folders:
        try:
            folder.rmdir()   # only an empty folder: whatever a run wrote stays
        except OSError:
            return


def _nothing_selected(args: argparse.Namespace, paths: list[str], progress: _Progress) -> ConfigError:
    """No case to run: the selection that left none (-k, --dut) named, or the paths that hold none."""
    where = " ".join(paths)
    chosen = [f"-k {args.keyword!r}"] if args.keyword else []
    chosen += [f"--dut {' '.join(args.dut)}"] if args.dut else []
    if chosen:
        of = f"none of the {progress.deselected} cases" if progress.deselected else "no case"
        return ConfigError(f"{' and '.join(chosen)}: selects {of} in {where}")
    return ConfigError(f"{where}: no test case there (pytest collects test_*.py files and their test_ functions)")


def _rootdir(project: ProjectConfig, paths: list[str]) -> Path:
    """The folder case ids are relative to: the project's, or for cases outside it the cases' own common
    folder (so that a single file elsewhere keeps its name in the ids and the JUnit class names)."""
    base = project.path.parent.resolve()
    folders = [p if p.is_dir() else p.parent for p in (Path(x.partition("::")[0]).resolve() for x in paths)]
    if all(f.is_relative_to(base) for f in folders):
        return base
    return Path(os.path.commonpath(folders))


def run(args: argparse.Namespace) -> int:
    from bench.pytest.plugin import finished_run

    console = Console(soft_wrap=not sys.stdout.isatty())   # a CI log keeps whole lines, never cut at 80 columns
    STOP.reset()
    STOP.install()   # from here SIGINT and SIGTERM end the run within a second with an ABORTED report (bench.stop)
    project = load_config(Path(args.config) if args.config else None)
    out_dir = Path(args.out) if args.out else default_out_dir(project.reports)
    made = _new_folders(out_dir)
    try:
        _check_before_running(project, args, out_dir)
    except BenchError:
        _remove_empty(made)   # a rejected run leaves no empty report folder behind
        raise
    paths = args.paths or [str(project.testcases)]
    args.config, args.out = str(project.path), str(out_dir)   # as resolved here, for the plugin
    pytest_args = [*paths, "-p", "no:terminal", "-p", "no:cacheprovider",
                   "--rootdir", str(_rootdir(project, paths)), *options.pytest_args(args, HANDED_TO_PYTEST)]
    scratch = None
    if args.workers:
        # pytest-xdist's controller makes a numbered /tmp/pytest-of-<user>/pytest-N for its workers and, as it
        # exits, deletes the old ones beyond the last three: other pytest sessions' folders, hundreds of MB after
        # a test suite, which kept a stopped run busy for more than a second after its report. A folder of our own
        # instead, removed after the run.
        scratch = tempfile.mkdtemp(prefix="bench-run-")
        pytest_args += ["--dist", DIST, "--basetemp", scratch]
    progress = _Progress(console)
    try:
        code = pytest.main(pytest_args, plugins=[progress])
    finally:
        gc.unfreeze()   # what _Progress froze at the session's end: collectable again for whoever called run()
        _settle_at_exit()
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
    result = finished_run()
    if result is None:
        _remove_empty(made)
        if code == pytest.ExitCode.NO_TESTS_COLLECTED:
            raise _nothing_selected(args, paths, progress)
        console.print(f"[bold red]bench run: no case ran[/] (pytest exit code {int(code)})", highlight=False)
        return int(code) or 1
    if args.shard and not result.cases and not result.aborted:   # more shards than cases: nothing to fail
        console.print(f"bench run: no case fell to shard {args.shard[0]}/{args.shard[1]}; report: {out_dir}",
                      highlight=False)
        return 0 if int(code) in (pytest.ExitCode.OK, pytest.ExitCode.NO_TESTS_COLLECTED) else int(code)
    table = Table(title=f"bench run: {result.verdict}")
    table.add_column("case", overflow="fold")   # whole names: parametrized cases differ only at the end
    for column in ("outcome", "steps", "bench s", "wall s"):
        table.add_column(column, no_wrap=True)
    for case in result.cases:
        passed = sum(1 for s in case.steps if s.verdict == "pass")
        table.add_row(escape(_short(case.nodeid)), f"[{OUTCOME_STYLE.get(case.outcome, '')}]{case.outcome}[/]",
                      f"{passed}/{len(case.steps)}", *(("–", "–") if case.outcome == "skipped"   # it never ran
                                                          else (f"{case.sim_time:.2f}", f"{case.wall_time:.2f}")))
    # Not a terminal (a CI log): as wide as the longest row, so no name is folded or cut.
    names = max((len(_short(c.nodeid)) for c in result.cases), default=0)
    if not console.is_terminal:
        console.width = max(console.width, names + 48)
    console.print(table)
    counts = result.counts
    never = [f"{result.not_run} never ran"] if result.not_run else []
    console.print(", ".join([*(f"{n} {k}" for k, n in counts.items() if n), *never]) +
                  f"; bench time {result.sim_time:.1f} s in {result.wall_time:.1f} s wall "
                  f"({result.sim_time / max(result.wall_time, 1e-9):.1f}× real time); "
                  f"{result.frames} frames, {result.invalid_frames} invalid", highlight=False)
    for case in result.cases:   # what made each inconclusive case so, with its figures
        if case.outcome == "inconclusive":
            console.print(f"[bold yellow]inconclusive[/] {escape(_short(case.nodeid))}: "
                          f"{escape(case.inconclusive or case.message.splitlines()[0])}", highlight=False)
    for case in result.cases:   # failed steps of other nodes than the DUT: theirs, never the case's (results.Step.node)
        for node in case.other_nodes:
            steps = [s for s in case.other_failed_steps if node in s.judges]
            if steps:
                more = f" (and {len(steps) - 1} more)" if len(steps) > 1 else ""
                console.print(f"[bold yellow]{escape(node)} failed[/] in {escape(_short(case.nodeid))}, not the DUT's "
                              f"verdict: {escape(step_summary(steps[0]))}{more}", highlight=False)
    console.print(f"report: {out_dir}")
    if result.aborted:
        return STOP.exit_code()
    if int(code) not in (pytest.ExitCode.OK, pytest.ExitCode.TESTS_FAILED):
        return 1
    return {"PASS": 0, "INCONCLUSIVE": EXIT_INCONCLUSIVE}.get(result.verdict, 1)
