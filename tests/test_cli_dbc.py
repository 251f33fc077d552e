"""`bench dbc`: lists both databases, and a bad file is a one-line error (exit 2), never a traceback."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.cli import main


@pytest.fixture(autouse=True)
def _wide_console(monkeypatch: pytest.MonkeyPatch) -> None:
    """Rich wraps at 80 columns when not on a terminal; widen it so names are not folded."""
    monkeypatch.setenv("COLUMNS", "200")


def test_lists_both_databases(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dbc"]) == 0
    out = capsys.readouterr().out
    for text in ("chassis.dbc", "bench.dbc", "0x100", "DRV_Steering", "HandWheelAngle [deg]",
                 "0x161", "ABS_SteerState", "0x680", "BENCH_Control", "PLANT_Dynamics", "TESTER"):
        assert text in out, text


def test_one_file(capsys: pytest.CaptureFixture[str]) -> None:
    from bench.paths import BENCH_DBC

    assert main(["dbc", str(BENCH_DBC)]) == 0
    out = capsys.readouterr().out
    assert "BENCH_SteeringRobot" in out and "DRV_Steering" not in out


def test_malformed_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "broken.dbc"
    bad.write_text('VERSION ""\nBU_: A\nBO_ 1 X: 8 A\n SG_ S 0|8@1+ (1,0) [0|1] "" A\n')
    assert main(["dbc", str(bad)]) == 2
    err = capsys.readouterr().err.replace("\n", "")
    assert "broken.dbc" in err and "line 4" in err
    assert "Traceback" not in err


def test_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dbc", str(tmp_path / "nowhere.dbc")]) == 2
    assert "nowhere.dbc" in capsys.readouterr().err.replace("\n", "")
