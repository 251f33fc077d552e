"""`bench log info`: shows a run log's state, span, frames and channel counts; bad files are a one-line error."""

from __future__ import annotations

import argparse
from pathlib import Path

import cantools
import pytest

from bench.cli import log as log_cli
from bench.errors import LogError
from bench.log.recorder import Recorder

DBC = """VERSION ""
NS_ :
BS_:
BU_: ECU
BO_ 256 SteerCmd: 8 ECU
 SG_ SteerAngle : 0|16@1- (0.1,0) [-780|780] "deg" ECU
BO_ 257 Unused: 8 ECU
 SG_ Nothing : 0|8@1+ (1,0) [0|255] "" ECU
"""


@pytest.fixture(autouse=True)
def _wide_console(monkeypatch: pytest.MonkeyPatch) -> None:
    """Rich wraps at 80 columns when not on a terminal; widen it so lines are not folded."""
    monkeypatch.setenv("COLUMNS", "200")


@pytest.fixture()
def run_log(tmp_path: Path) -> Path:
    path = tmp_path / "run.mcap"
    dbc = tmp_path / "steer.dbc"
    dbc.write_text(DBC)
    with Recorder(path, [cantools.database.load_string(DBC, "dbc")], [dbc]) as recorder:
        for i in range(40):
            recorder.frame(1.0 + i * 0.01, 0x100, bytes(8), channel="can0", direction="rx", valid=i != 3,
                           error="" if i != 3 else "bad counter")
            recorder.decoded(1.0 + i * 0.01, "SteerCmd", {"SteerAngle": i * 0.1})
        recorder.step(1.5, 2, "case", "passed")
    return path


def info(path: Path) -> int:
    """Through the real parser when every subcommand module is there, else through ours alone."""
    try:
        from bench.cli import main
        return main(["log", "info", str(path)])
    except ImportError:
        parser = argparse.ArgumentParser(prog="bench")
        sub = parser.add_subparsers(dest="command", required=True)
        log_cli.register(sub)
        args = parser.parse_args(["log", "info", str(path)])
        try:
            return args.handler(args)
        except LogError:
            return 2


def test_info_prints_channels_and_counts(run_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert info(run_log) == 0
    out = capsys.readouterr().out
    for text in ("complete", "run.mcap", "steer.dbc", "1.000000 s", "1.500000 s", "40 (1 invalid)"):
        assert text in out, text
    lines = {line.split()[1]: line.split()[3] for line in out.splitlines() if line.startswith("│ /")}
    assert lines == {"/can/frames": "40", "/can/decoded/SteerCmd": "40", "/can/decoded/Unused": "0",
                     "/bench/steps": "1"}


def test_info_of_a_cut_log_says_truncated(run_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(run_log.read_bytes()[:-40])
    assert info(cut) == 0
    assert "truncated" in capsys.readouterr().out


def test_info_of_a_bad_file_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "notes.txt").write_text("hello")
    assert info(tmp_path / "notes.txt") == 2
    assert info(tmp_path / "missing.mcap") == 2
    with pytest.raises(LogError, match="notes.txt"):
        log_cli.info_handler(argparse.Namespace(file=tmp_path / "notes.txt"))


def test_info_of_a_run_shows_dates_and_bench_time(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 27, finding 8: a bench run logs Unix times (its start + bench time); info printed them as seconds
    since 1970 ("1764250000.123000 s"). Now ISO 8601 dates in UTC, and the bench time beside them."""
    path = tmp_path / "run.mcap"
    with Recorder(path, []) as recorder:
        recorder.set_origin(1_732_482_000_000_000_000, "virtual")           # 2024-11-24T21:00:00Z
        for i in range(11):
            recorder.frame(0.25 + i * 0.1, 0x100, bytes(8), channel="virtual:bench", direction="rx")
    assert info(path) == 0
    out = capsys.readouterr().out
    assert ("2024-11-24T21:00:00.250000+00:00 … 2024-11-24T21:00:01.250000+00:00 (duration 1.000000 s); bench time "
            "0.250000 s … 1.250000 s, bench time 0 at 2024-11-24T21:00:00.000000+00:00") in out, out
    assert "17324" not in out


def test_info_of_a_python_can_log_shows_dates(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Unix times without the bench's clock (python-can's logger): dates, no bench time."""
    path = tmp_path / "unix.mcap"
    with Recorder(path, []) as recorder:
        recorder.frame(1_763_700_000.5, 0x100, bytes(8), channel="vcan0", direction="rx")
    assert info(path) == 0
    out = capsys.readouterr().out
    assert "2025-11-21T04:40:00.500000+00:00 … 2025-11-21T04:40:00.500000+00:00 (duration 0.000000 s)" in out, out
    assert "bench time" not in out
