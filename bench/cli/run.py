"""`bench run`: run the test cases, show progress, write report.html, run.mcap and junit.xml."""

from __future__ import annotations

import argparse
from pathlib import Path

import can
import pytest
from rich.console import Console
from rich.table import Table

from bench.bus import is_virtual
from bench.cli.common import add_bus_options
from bench.codec import load_codebook
from bench.config import ProjectConfig, load_config
from bench.errors import ConfigError
from bench.faults import parse_fault
from bench.marks import split_names
from bench.run import default_out_dir
from bench.session import resolve_external

OUTCOME_STYLE = {"passed": "green", "failed": "bold red", "error": "bold red", "skipped": "yellow",
                 "aborted": "bold magenta"}


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("run", help="run the test cases and write a report",
                            description="Run the test cases (default: testcases/ on the in-process "
                                        "virtual-time bus) and write report.html, run.mcap, junit.xml.")
    add_bus_options(parser, "virtual")
    parser.add_argument("-k", dest="keyword", default=None, help="only cases matching this pytest -k expression")
    parser.add_argument("--dut", nargs="+", action="extend", default=[], metavar="NODE",
                        help="only the cases that judge NODE (@pytest.mark.dut); the report's conformance section "
                             "lists the others as deselected")
    parser.add_argument("--out", default=None, help="output folder (default: a new folder under reports/)")
    parser.add_argument("-n", dest="workers", default=None, metavar="N",
                        help="run the cases in N processes (pytest-xdist; 'auto' = one per core), each with its own "
                             "in-process virtual bus and MCAP log; one merged report")
    parser.add_argument("paths", nargs="*", help="test files or folders (default: the project's testcases)")
    parser.set_defaults(handler=run)


class _Progress:
    """A pytest plugin that shows one line per case and a summary table at the end."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self.total = 0
        self.done = 0
        self.collect_errors: list[str] = []

    def pytest_collectreport(self, report: pytest.CollectReport) -> None:
        if report.failed:
            self.collect_errors.append(f"{report.nodeid}: {report.longreprtext}")
            self.console.print(f"[bold red]cannot collect {report.nodeid}[/]\n{report.longreprtext}",
                               highlight=False, markup=True)

    def pytest_collection_finish(self, session: pytest.Session) -> None:
        self.total = len(session.items)
        self.console.print(f"bench: {self.total} cases")

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when == "call" or (report.when == "setup" and not report.passed):
            self.done += 1
            outcome = "error" if (report.when == "setup" and report.failed) else report.outcome
            style = OUTCOME_STYLE.get(outcome, "")
            self.console.print(f"[{self.done:>3}/{self.total}] [{style}]{outcome:<7}[/] {report.nodeid} "
                               f"[dim]({report.duration:.2f} s)[/]", highlight=False)
            if report.failed:
                self.console.print(report.longreprtext, highlight=False, markup=False)


def _short(nodeid: str) -> str:
    """`testcases/test_x.py::test_y[p]` -> `test_x::test_y[p]`: what a reader needs in a narrow table."""
    path, sep, rest = nodeid.partition("::")
    return path.rsplit("/", 1)[-1].removesuffix(".py") + sep + rest


def _check_before_running(project: ProjectConfig, args: argparse.Namespace) -> None:
    """What the bench needs before any case starts: databases that load, known nodes and interface.
    A mistake here is one clear error (exit 2), not an error in every case."""
    codebook = load_codebook(project.databases)
    resolve_external(codebook, project.stimulus, args.external)
    unknown = [n for n in split_names(args.dut) if n not in codebook.nodes]
    if unknown:
        raise ConfigError(f"--dut: unknown node(s) {', '.join(unknown)} (nodes: {', '.join(codebook.nodes)})")
    if not is_virtual(args.interface) and args.interface not in can.interfaces.VALID_INTERFACES:
        raise ConfigError(f"--interface: unknown python-can interface {args.interface!r} "
                          f"(known: virtual, {', '.join(sorted(can.interfaces.VALID_INTERFACES))})")


def run(args: argparse.Namespace) -> int:
    from bench.pytest_plugin import finished_run

    console = Console()
    project = load_config(Path(args.config) if args.config else None)
    out_dir = Path(args.out) if args.out else default_out_dir(project.reports)
    pytest_args = [*(args.paths or [str(project.testcases)]), "-p", "no:terminal", "-p", "no:cacheprovider",
                   "--rootdir", str(project.path.parent), "--bench-out", str(out_dir),
                   "--bench-interface", args.interface, "--bench-config", str(project.path)]
    if args.channel:
        pytest_args += ["--bench-channel", args.channel]
    for node in args.external:
        pytest_args += ["--bench-external", node]
    for node in args.dut:
        pytest_args += ["--bench-dut", node]
    for spec in args.fault:
        parse_fault(spec)                      # a bad spec is a clear error before pytest starts
        pytest_args += ["--bench-fault", spec]
    if args.keyword:
        pytest_args += ["-k", args.keyword]
    if args.workers:
        if not is_virtual(args.interface):
            raise ConfigError("-n: parallel workers each need their own in-process virtual bus; "
                              f"--interface {args.interface} is one shared bus")
        pytest_args += ["-n", args.workers]
    _check_before_running(project, args)
    progress = _Progress(console)
    code = pytest.main(pytest_args, plugins=[progress])
    result = finished_run()
    if result is None:
        console.print(f"[bold red]bench run: no case ran[/] (pytest exit code {int(code)})")
        return int(code) or 1
    table = Table(title=f"bench run: {result.verdict}")
    for column in ("case", "outcome", "steps", "bench s", "wall s"):
        table.add_column(column)
    for case in result.cases:
        passed = sum(1 for s in case.steps if s.verdict == "pass")
        table.add_row(_short(case.nodeid), f"[{OUTCOME_STYLE.get(case.outcome, '')}]{case.outcome}[/]",
                      f"{passed}/{len(case.steps)}", f"{case.sim_time:.2f}", f"{case.wall_time:.2f}")
    console.print(table)
    counts = result.counts
    console.print(", ".join(f"{n} {k}" for k, n in counts.items() if n) +
                  f"; bench time {result.sim_time:.1f} s in {result.wall_time:.1f} s wall "
                  f"({result.sim_time / max(result.wall_time, 1e-9):.1f}× real time); "
                  f"{result.frames} frames, {result.invalid_frames} invalid", highlight=False)
    console.print(f"report: {out_dir}")
    if result.aborted:
        return 130
    return 0 if (int(code) == 0 and result.verdict == "PASS") else 1
