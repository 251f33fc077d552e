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
    from tests.repo import BENCH_DBC

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


# -- without FILE: the project's databases (bench.toml), not a path inside the package -----------------------
def _project(folder: Path, databases: list[str]) -> Path:
    """A bench project of its own: a bench.toml naming copies of the repository's databases."""
    import shutil

    from tests.repo import BENCH_DBC, CHASSIS_DBC

    folder.mkdir(parents=True, exist_ok=True)
    for source in (CHASSIS_DBC, BENCH_DBC):
        shutil.copy(source, folder / source.name)
    config = folder / "bench.toml"
    config.write_text('[bench]\ndatabases = [' + ", ".join(f'"{d}"' for d in databases) + ']\n'
                      'stimulus = ["TESTER"]\nplant = "chassis"\ntestcases = "t"\nreports = "r"\n', encoding="utf-8")
    return config


def test_default_is_the_configured_databases(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = _project(tmp_path / "p", ["bench.dbc"])            # only one of the two files the folder holds
    assert main(["dbc", "--config", str(config)]) == 0
    out = capsys.readouterr().out
    assert "bench.dbc" in out and "BENCH_Control" in out
    assert "chassis.dbc" not in out and "DRV_Steering" not in out


def test_default_config_is_found_from_the_working_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    _project(tmp_path / "p", ["chassis.dbc"])
    (tmp_path / "p" / "sub").mkdir()
    monkeypatch.chdir(tmp_path / "p" / "sub")                   # bench.toml is one folder up
    assert main(["dbc"]) == 0
    out = capsys.readouterr().out
    assert "chassis.dbc" in out and "DRV_Steering" in out and "BENCH_Control" not in out
    assert main(["dbc", "check"]) == 0
    assert "chassis.dbc" in capsys.readouterr().out


def test_check_takes_config_after_the_word(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = _project(tmp_path / "p", ["bench.dbc"])
    assert main(["dbc", "check", "--config", str(config)]) == 0
    out = capsys.readouterr().out
    assert "bench.dbc" in out and "chassis.dbc" not in out


def test_no_project_is_a_one_line_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)                                 # no bench.toml here or above (tmp is outside the repo)
    if any((folder / "bench.toml").is_file() for folder in (tmp_path, *tmp_path.parents)):
        pytest.skip("a bench.toml above the temporary folder")
    assert main(["dbc"]) == 2
    err = capsys.readouterr().err
    assert "bench.toml" in err and "--config" in err and "Traceback" not in err


# -- issue 27, finding 6: the value tables a case names (DriveMode="PIVOT", Vehicle="EV4WIS") ------------------
@pytest.mark.parametrize("argv", [["dbc", "--values"], ["dbc", "dbc/chassis.dbc", "dbc/bench.dbc", "--values"]])
def test_values_lists_ranges_and_value_tables(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
                                              argv: list[str]) -> None:
    from tests.repo import ROOT

    monkeypatch.chdir(ROOT)
    assert main(argv) == 0
    out = capsys.readouterr().out
    for text in ("DriveMode [-] 0..3: 0 NORMAL, 1 LATERAL, 2 ADAPTIVE, 3 PIVOT", "TargetSpeed [m/s] -80..80",
                 "Vehicle [-] 0..15: 0 EV4WIS, 1 ACLASS, 2 ACLASS_ABS", "RoadMu [-] 0..1.5"):
        assert text in out, text


def test_the_plain_list_shows_no_value_tables(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dbc"]) == 0
    out = capsys.readouterr().out
    assert "DriveMode [-]" in out and "PIVOT" not in out


@pytest.mark.parametrize("argv", [["dbc", "--values", "check"], ["dbc", "check", "--values"]])
def test_values_is_for_the_listing_only(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    assert main(argv) == 2
    assert capsys.readouterr().err.strip() == (
        "bench dbc: error: --values: only for the listing, 'bench dbc [FILE ...] --values'")
