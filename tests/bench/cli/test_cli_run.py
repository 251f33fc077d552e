"""`bench run`'s terminal output and case names (issue 16, finding 5 and the smaller ones of 11).

The cases live in a file outside the repository, as a user's would, with parameter ids that look like rich
markup (`[left]`, `[dry]`, `[drop:…]`) and one longer than a CI log's 80 columns; stdout is a pipe (not a
terminal), as in CI.
"""

from __future__ import annotations

import getpass
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tests.repo import ROOT

LONG = "a_parameter_identifier_long_enough_that_the_whole_case_name_is_wider_than_eighty_columns"
PARAMS = ["left", "dry", "drop:VCU_WheelCmd_FL", "bold red", LONG]
CASES = f'''
import pytest


@pytest.mark.parametrize("which", {PARAMS!r}, ids={PARAMS!r})
def test_side(bench, which):
    bench.run(0.02)
    bench.expect_true("ran " + which, True)
'''


def bench_run(folder: Path, *argv: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES", "FORCE_COLOR", "TERM")}
    return subprocess.run([sys.executable, "-m", "bench", "run", str(folder / "test_user.py"), "--out",
                           str(folder / "out"), *argv], cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)


@pytest.fixture(scope="module")
def user_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, subprocess.CompletedProcess]:
    folder = tmp_path_factory.mktemp("user")
    (folder / "test_user.py").write_text(CASES, encoding="utf-8")
    result = bench_run(folder)
    assert result.returncode == 0, result.stdout + result.stderr
    return folder, result


def test_parameter_ids_are_shown_as_text(user_run: tuple[Path, subprocess.CompletedProcess]) -> None:
    """Finding 5: every id in the progress lines and once per row of the summary table, whole."""
    _, result = user_run
    for param in PARAMS:
        progress = [line for line in result.stdout.splitlines() if line.endswith(")") and f"test_side[{param}]" in line]
        assert len(progress) == 1, (param, result.stdout)
        rows = [line for line in result.stdout.splitlines() if f"test_user::test_side[{param}]" in line]
        assert len(rows) == 1, (param, result.stdout)
    assert "…" not in result.stdout


def test_lines_are_not_cut_at_80_columns(user_run: tuple[Path, subprocess.CompletedProcess]) -> None:
    _, result = user_run
    [line] = [line for line in result.stdout.splitlines() if line.startswith("[") and LONG in line]
    assert len(line) > 80 and line.endswith(" s)")
    summary = [line for line in result.stdout.splitlines() if "bench time" in line]
    assert len(summary) == 1 and summary[0].endswith("invalid")


def test_a_file_outside_the_project_keeps_its_name(user_run: tuple[Path, subprocess.CompletedProcess]) -> None:
    """Finding 11: the node id is `test_user.py::...`, not `::...`, and JUnit's classname is not empty."""
    folder, result = user_run
    assert "] passed  test_user.py::test_side[left]" in result.stdout
    assert "  ::test_side" not in result.stdout
    cases = ET.parse(folder / "out" / "junit.xml").getroot().iter("testcase")
    assert {case.get("classname") for case in cases} == {"test_user"}


def test_header_without_a_channel_names_only_the_interface(
        user_run: tuple[Path, subprocess.CompletedProcess]) -> None:
    folder, _ = user_run
    html = (folder / "out" / "report.html").read_text(encoding="utf-8")
    header = re.search(r"<dt>Interface</dt><dd>(.*?)</dd>", html, re.S)
    assert header is not None and "embedded" in header.group(1) and "channel" not in header.group(1)


def test_progress_counts_the_cases_with_workers(tmp_path: Path) -> None:
    """Finding 11: with -n the controller collects nothing itself; the total is the workers' collection."""
    pytest.importorskip("xdist")
    (tmp_path / "test_user.py").write_text(CASES, encoding="utf-8")
    result = bench_run(tmp_path, "-n", "2", "-k", "left or dry or bold")
    assert result.returncode == 0, result.stdout + result.stderr
    counters = re.findall(r"^\[\s*(\d+)/(\d+)\]", result.stdout, re.M)
    assert sorted(int(done) for done, _ in counters) == [1, 2, 3], result.stdout
    assert {total for _, total in counters} == {"3"}
    assert "bench: 3 cases" in result.stdout


def test_workers_leave_other_pytest_folders_alone(tmp_path: Path) -> None:
    """`bench run -n` keeps its workers' scratch in a folder of its own and removes it: pytest-xdist's default
    (/tmp/pytest-of-<user>/pytest-N) deleted the older numbered folders of other sessions as the run exited, which
    made a stopped run late by a second (tests/integration/test_stop_signals.py)."""
    pytest.importorskip("xdist")
    (tmp_path / "test_user.py").write_text(CASES, encoding="utf-8")
    scratch_root = tmp_path / "tmp"
    others = [scratch_root / f"pytest-of-{getpass.getuser()}" / f"pytest-{n}" for n in range(1, 6)]
    for folder in others:
        (folder / "kept").mkdir(parents=True)
    env = {**os.environ, "TMPDIR": str(scratch_root)}
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(tmp_path / "test_user.py"), "--out",
                             str(tmp_path / "out"), "-n", "2", "-k", "left or dry"], cwd=ROOT, capture_output=True,
                            text=True, timeout=300, env=env)
    assert result.returncode == 0, result.stdout + result.stderr
    assert all((folder / "kept").is_dir() for folder in others)
    assert sorted(p.name for p in scratch_root.iterdir()) == [others[0].parent.name]   # no scratch left behind


def test_workers_steal_work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """-n hands pytest-xdist --dist worksteal (an idle worker takes from the other's queue; bench.cli.run.DIST);
    without -n no --dist at all."""
    from bench.cli import build_parser
    from bench.cli import run as cli_run

    (tmp_path / "test_user.py").write_text(CASES, encoding="utf-8")
    handed: list[list[str]] = []
    monkeypatch.setattr(cli_run.pytest, "main", lambda args, plugins: handed.append(list(args)) or 0)
    for workers in (["-n", "2"], []):
        args = build_parser().parse_args(["run", str(tmp_path / "test_user.py"), "--out", str(tmp_path / "out"),
                                          *workers])
        cli_run.run(args)
    with_n, without = handed
    assert with_n[with_n.index("-n") + 1] == "2" and with_n[with_n.index("--dist") + 1] == "worksteal"
    assert "--dist" not in without and "-n" not in without


# -- each run option declared once (issue 17): bench.options builds both sides ----------------------------------
class _PytestGroup:
    """pytest's option group is argparse underneath: the plugin's declarations, onto a plain parser."""

    def __init__(self) -> None:
        import argparse

        self.parser = argparse.ArgumentParser()

    def addoption(self, *flags: str, **kwargs: object) -> None:
        self.parser.add_argument(*flags, **kwargs)  # type: ignore[arg-type]


def test_every_option_bench_run_hands_on_reaches_the_plugin_unchanged() -> None:
    """Each option given on `bench run`'s command line arrives with the same value in the plugin's options."""
    from bench import options
    from bench.cli import build_parser
    from bench.cli.run import HANDED_TO_PYTEST

    argv = ["run", "--interface", "udp_multicast", "--channel", "239.0.0.1", "--bitrate", "250000", "--no-fd",
            "--data-bitrate", "2000000", "--config", "x/bench.toml", "--external", "VCU", "SBW", "--fault",
            "drop:MESSAGE@1-2", "--fault", "silence:NODE@case+0.5-", "--dut", "VCU", "--shard", "2/3",
            "--durations", "d.json", "--out", "o"]
    args = build_parser().parse_args(argv)
    group = _PytestGroup()
    options.add_pytest_options(group)
    plugin, rest = group.parser.parse_known_args(options.pytest_args(args, HANDED_TO_PYTEST))
    assert rest == []
    for spec in options.OPTIONS:
        if spec.plugin:
            assert getattr(plugin, spec.pytest_dest) == getattr(args, spec.dest), spec.name
    assert plugin.bench_fd is False and plugin.bench_shard == (2, 3) and plugin.bench_external == ["VCU", "SBW"]


def test_pytest_only_options_are_handed_to_pytest_itself() -> None:
    from bench import options
    from bench.cli import build_parser
    from bench.cli.run import HANDED_TO_PYTEST

    args = build_parser().parse_args(["run", "-k", "pivot and not slow", "-n", "2", "--force"])
    handed = options.pytest_args(args, HANDED_TO_PYTEST)
    assert handed[-4:] == ["-k", "pivot and not slow", "-n", "2"]
    assert handed[:2] == ["--bench-interface", "embedded"] and "--force" not in handed


@pytest.mark.parametrize("command", ["plant", "monitor", "replay"])
def test_bus_options_of_the_other_commands_come_from_the_same_table(command: str) -> None:
    """plant, monitor and replay share the table's bus options (their default interface is udp_multicast)."""
    from bench.cli import build_parser

    extra = ["log.mcap"] if command == "replay" else []
    args = build_parser().parse_args([command, *extra, "-c", "239.0.0.1", "--bitrate", "125000", "--fd"])
    assert (args.interface, args.channel, args.bitrate, args.fd) == ("udp_multicast", "239.0.0.1", 125000, True)
    with pytest.raises(SystemExit):
        build_parser().parse_args([command, *extra, "--bitrate", "fast"])


def test_a_subcommand_loads_only_its_own_module() -> None:
    """`bench run ...` builds only run's parser (the other subcommands' modules stay unimported); a command line
    that names no subcommand first gets the whole parser, so its help and its typo hints list them all."""
    from bench.cli import SUBCOMMANDS, _subcommand

    assert _subcommand(["run", "-n", "2"]) == "run" and _subcommand(["log", "x"]) == "log"
    assert _subcommand(["--help"]) is None and _subcommand(["rn"]) is None and _subcommand([]) is None
    code = ("import sys; from bench.cli import build_parser; build_parser('run'); "
            "print(sorted(m for m in sys.modules if m.startswith('bench.cli.')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.stdout.split("\n")[0] == str(["bench.cli.common", "bench.cli.run"]), out.stdout + out.stderr
    assert len(SUBCOMMANDS) > 2
