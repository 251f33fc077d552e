"""`bench log info`: shows a run log's state, span, frames and channel counts; bad files are a one-line error."""

from __future__ import annotations

import argparse
from pathlib import Path

import cantools
import pytest

from bench.cli import log as log_cli
from bench.errors import LogError
from bench.recorder import Recorder

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
