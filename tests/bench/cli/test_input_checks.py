"""Bad input is stopped before the first case (issue 16, findings 1 and 2, and `--channel` on the embedded bus).

Each problem is one line naming the input (`bench run: error: ...`), exit 2, no traceback, and nothing of a
run is written: no case runs, no report appears, an existing folder keeps its contents.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bench.cli import main
from tests.repo import ROOT

MINI = ROOT / "tests" / "fixtures" / "cases" / "test_mini.py"


def errors(capsys: pytest.CaptureFixture[str], argv: list[str]) -> list[str]:
    """The error lines of an in-process `bench run` that must stop at the door (pytest is never started)."""
    assert main(["run", str(MINI), *argv]) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err and "AssertionError" not in captured.out + captured.err
    assert "cases" not in captured.out            # the progress plugin never announced a collection
    lines = captured.err.strip().splitlines()
    assert lines and all(line.startswith("bench run: error: ") for line in lines), lines
    return lines


# -- finding 1: a bus that cannot be opened ------------------------------------------------------------------
@pytest.mark.parametrize("interface", ["socketcan", "udp_multicast"])
def test_bus_that_cannot_be_opened_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                               interface: str) -> None:
    [line] = errors(capsys, ["--interface", interface, "--channel", "nonsense", "--out", str(tmp_path / "out")])
    assert "cannot open interface" in line and repr(interface) in line and "'nonsense'" in line, line
    assert not (tmp_path / "out" / "report.html").exists()


def test_plain_pytest_stops_once_when_the_bus_cannot_be_opened(tmp_path: Path) -> None:
    """The plugin's own path: one line and stop, not a traceback in the first case and an assertion in the rest."""
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(MINI),
                             "--bench-interface", "udp_multicast", "--bench-channel", "nonsense",
                             "--bench-out", str(tmp_path / "out")],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    output = result.stdout + result.stderr
    assert result.returncode == 4, output                 # pytest's usage error, not "tests failed"
    assert output.count("cannot open interface 'udp_multicast' channel 'nonsense'") == 1, output
    assert "assert self.session is not None" not in output and "passed" not in output


def test_channel_on_the_embedded_bus_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    [line] = errors(capsys, ["--channel", "vcan0", "--out", str(tmp_path / "out")])
    assert line.startswith("bench run: error: --channel vcan0:") and "embedded bus" in line
    assert main(["plant", "--channel", "x", "--interface", "embedded"]) == 2   # plant never takes the embedded bus


def test_channel_on_the_embedded_bus_in_plain_pytest(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(MINI),
                             "--bench-channel", "vcan0", "--bench-out", str(tmp_path / "out")],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 4 and "--bench-channel vcan0" in result.stderr, result.stdout + result.stderr


# -- finding 2: the output folder -------------------------------------------------------------------------
def test_out_is_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "notadir").write_text("mine")
    [line] = errors(capsys, ["--out", str(tmp_path / "notadir")])
    assert "--out" in line and "is a file" in line
    assert (tmp_path / "notadir").read_text() == "mine"


def test_out_below_a_file_cannot_be_written(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "notadir").write_text("mine")
    [line] = errors(capsys, ["--out", str(tmp_path / "notadir" / "sub")])
    assert "--out" in line and "cannot write there" in line


def test_out_on_a_read_only_file_system(capsys: pytest.CaptureFixture[str]) -> None:
    """/proc takes no new folders, even for root (these tests may run as root, where chmod stops nothing)."""
    [line] = errors(capsys, ["--out", "/proc/bench-report"])
    assert "--out /proc/bench-report" in line and "cannot write there" in line


def test_existing_report_folder_is_not_overwritten(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.html").write_text("the previous run's report")
    [line] = errors(capsys, ["--out", str(out)])
    assert "not empty" in line and "--force" in line
    assert (out / "report.html").read_text() == "the previous run's report"


def test_force_writes_into_an_existing_folder(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.html").write_text("the previous run's report")
    (out / "notes.txt").write_text("mine")
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(MINI), "-k", "normal_mode", "--out", str(out),
                             "--force"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "test_normal_mode_drives_straight" in (out / "report.html").read_text()
    assert (out / "notes.txt").read_text() == "mine"         # replaced: the reports; kept: anything else


def test_empty_existing_folder_is_fine(tmp_path: Path) -> None:
    """An empty folder (e.g. made by a CI step) is no previous report."""
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(MINI), "-k", "normal_mode", "--out",
                             str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr


# -- every problem at once, one line each ------------------------------------------------------------------
def test_every_problem_is_its_own_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "notadir").write_text("")
    lines = errors(capsys, ["--external", "BOGUS", "--dut", "NOPE", "--fault", "drop:NoSuchMsg@1-2",
                            "--fault", "drop:VCU_WheelCmd_FL@3-2", "--out", str(tmp_path / "notadir")])
    assert len(lines) == 5, lines
    for needle in ("--external", "--dut", "NoSuchMsg", "VCU_WheelCmd_FL@3-2", "--out"):
        assert sum(needle in line for line in lines) == 1, (needle, lines)


def test_a_fault_on_an_external_nodes_frames(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The bench changes only frames it sends: a fault on an external node's message would act on nothing."""
    [line] = errors(capsys, ["--external", "VCU", "--fault", "drop:VCU_WheelCmd_FL@1-2", "--fault",
                             "drop:WHL_Status_FL@1-2", "--out", str(tmp_path / "out")])
    assert "drop:VCU_WheelCmd_FL@1-2" in line and "sent by VCU, which the bench does not simulate" in line, line


def test_a_fault_on_the_stimulus_named_external_is_taken(tmp_path: Path) -> None:
    """bench run's process sends the stimulus even when it is named external: the check before the first case
    and the session agree (bench.session.simulated_nodes), so the fault is not refused at the door."""
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(MINI), "-k", "normal_mode", "--external",
                             "DRIVER", "--fault", "drop:DRV_Steering@1-2", "--out", str(tmp_path / "out")],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr


def test_missing_test_path(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", str(tmp_path / "nowhere.py"), "--out", str(tmp_path / "out")]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert line == f"bench run: error: {tmp_path / 'nowhere.py'}: no such test file or folder"


def test_data_bitrate_without_fd(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    [line] = errors(capsys, ["--interface", "udp_multicast", "--data-bitrate", "2000000",
                             "--out", str(tmp_path / "out")])
    assert "--data-bitrate 2000000" in line and "--fd" in line


def test_bad_config_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = tmp_path / "bench.toml"
    config.write_text(f'[bench]\ndatabases = ["{ROOT}/dbc/chassis.dbc", "{ROOT}/dbc/bench.dbc"]\n'
                      'stimulus = ["DRIVER", "TESTER"]\nplant = "chassis"\ntestcases = "."\nreports = "r"\n'
                      '[bus]\nbitrate = -5\n')
    [line] = errors(capsys, ["--config", str(config), "--out", str(tmp_path / "out")])
    assert str(config) in line and "[bus] bitrate" in line


# -- --shard and --durations (issue 18) ------------------------------------------------------------------------
def test_durations_without_shard(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    [line] = errors(capsys, ["--durations", str(tmp_path / "d.json"), "--out", str(tmp_path / "out")])
    assert "--durations: only with --shard K/N" in line


def test_missing_durations_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    [line] = errors(capsys, ["--shard", "1/2", "--durations", str(tmp_path / "d.json"), "--out", str(tmp_path / "o")])
    assert f"--durations {tmp_path / 'd.json'}: no such file" in line


def test_durations_file_that_is_not_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "d.json").write_text("testcases/x.py::test_y 1.5\n")
    [line] = errors(capsys, ["--shard", "1/2", "--durations", str(tmp_path / "d.json"), "--out", str(tmp_path / "o")])
    assert "not a durations file" in line


# -- issue 27, findings 3 and 4: more bad input at the door, and nothing left behind ------------------------------
def project(tmp_path: Path, **bench: str) -> Path:
    """A bench.toml in tmp_path on this repository's databases, with its [bench] keys replaced by `bench`."""
    keys = {"plant": "chassis", "testcases": "testcases", "reports": "reports", **bench}
    (tmp_path / "testcases").mkdir(parents=True, exist_ok=True)
    config = tmp_path / "bench.toml"
    config.write_text(f'[bench]\ndatabases = ["{ROOT}/dbc/chassis.dbc", "{ROOT}/dbc/bench.dbc"]\n'
                      'stimulus = ["DRIVER", "TESTER"]\n' + "".join(f'{k} = "{v}"\n' for k, v in keys.items()))
    return config


def test_a_mistyped_plant_is_found_before_collection(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = project(tmp_path, plant="chasis")
    [line] = errors(capsys, ["--config", str(config)])
    assert line.startswith(f"bench run: error: {config}: [bench] plant: no plant 'chasis' (did you mean chassis?)")
    assert not (tmp_path / "reports").exists()


def test_no_plant_is_needed_when_every_node_is_external(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--external all`: the plant is another process, so a name this one cannot load is no problem of the run."""
    config = project(tmp_path, plant="elsewhere")
    [line] = errors(capsys, ["--config", str(config), "--external", "all", "--interface", "udp_multicast",
                             "--channel", "nonsense"])
    assert "plant" not in line and "cannot open interface" in line


def test_testcases_that_do_not_exist(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = project(tmp_path, testcases="testcase")
    assert main(["run", "--config", str(config)]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert line == (f"bench run: error: {config}: [bench] testcases: no such file or folder 'testcase' "
                    f"(did you mean testcases?) (relative to {tmp_path})")
    assert not (tmp_path / "reports").exists()


@pytest.mark.parametrize("workers", ["abc", "-1", "2.5"])
def test_workers_that_are_not_a_number(tmp_path: Path, capsys: pytest.CaptureFixture[str], workers: str) -> None:
    [line] = errors(capsys, ["-n", workers, "--out", str(tmp_path / "out")])
    assert line == f"bench run: error: -n {workers}: not a number of worker processes (a whole number, or auto: one " \
                   "per core)"


def test_a_rejected_run_leaves_no_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Finding 4: --out (and the folders above it) were created by the check of the folder and left empty."""
    errors(capsys, ["--dut", "NOPE", "--out", str(tmp_path / "new" / "out")])
    assert list(tmp_path.iterdir()) == []
    config = project(tmp_path / "p", plant="chasis")
    errors(capsys, ["--config", str(config)])
    assert sorted(p.name for p in config.parent.iterdir()) == ["bench.toml", "testcases"]   # no reports/<stamp>/


def test_a_rejected_run_keeps_an_existing_empty_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An empty --out a CI step made is the user's: a rejected run leaves it as it was."""
    errors(capsys, ["--dut", "NOPE", "--out", str(tmp_path)])
    assert tmp_path.is_dir()


@pytest.mark.parametrize(("argv", "says"), [
    (["-k", "nothing_matches_this"], "-k 'nothing_matches_this': selects none of the 3 cases in "),
    (["-k", "nothing_matches_this", "-n", "2"], "-k 'nothing_matches_this': selects no case in "),
])
def test_a_keyword_that_selects_nothing(tmp_path: Path, argv: list[str], says: str) -> None:
    """Finding 3: "no case ran (pytest exit code 5)", exit 5, the -k not named; and an empty --out left behind."""
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(MINI), *argv, "--out", str(out)],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stdout == "" and "Traceback" not in result.stderr
    # (pytest-benchmark, where installed, warns on stderr that xdist disables it: not the bench's line)
    assert [line for line in result.stderr.splitlines() if "Warning" not in line and not line.startswith(" ")] == [
        f"bench run: error: {says}{MINI}"]
    assert not out.exists()


def test_an_empty_folder_of_cases(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "cases").mkdir()
    assert main(["run", str(tmp_path / "cases"), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == (f"bench run: error: {tmp_path / 'cases'}: no test case there (pytest collects test_*.py "
                            "files and their test_ functions)\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cases"]


def test_collect_only_with_a_shard_writes_no_report(tmp_path: Path) -> None:
    """docs/ci.md's `pytest testcases --collect-only -q --bench-shard 2/3` printed the shard and wrote a report."""
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", str(MINI), "--collect-only",
                             "-q", "--bench-shard", "2/3", "--bench-out", str(out)],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "test_mini.py::" in result.stdout and not out.exists()
