"""`bench dbc`: lists both databases with the protection of each message, and a bad file is a one-line error
(exit 2), never a traceback."""

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


def test_the_table_shows_each_message_protection(capsys: pytest.CaptureFixture[str]) -> None:
    from tests.repo import ROOT

    assert main(["dbc", str(ROOT / "tests" / "fixtures" / "e2e_profiles.dbc")]) == 0
    out = capsys.readouterr().out
    assert "E2E" in out
    for text in ("P01 DataID 0x1234 ALT", "P02 DataIDList 10 11 12", "P05 DataID 0x1235", "P11 DataID 0x0111 NIBBLE",
                 "CRC bits 48-55", "counter bits 56-59 (0-14)", "window 2 (init 1/0, valid 2/0, invalid 2/0)",
                 "unprotected"):
        assert text in out, text


def test_arxml_file_is_listed_with_its_profiles(capsys: pytest.CaptureFixture[str]) -> None:
    from tests.repo import ROOT

    arxml = ROOT.parent / "shared" / "corpus" / "arxml" / "system-4.2.arxml"   # the CI's shared/ beside the clone
    if not arxml.is_file():
        pytest.skip(f"no shared corpus beside the repository ({arxml})")
    assert main(["dbc", str(arxml)]) == 0
    out = capsys.readouterr().out
    assert "Message1" in out and "P02 DataIDList 7B 7C" in out and "P05 DataID 0x0141" in out


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


def test_the_project_e2e_table_applies(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Without FILE the databases are the project's, with its bench.toml [e2e] over them, for listing and check."""
    config = _project(tmp_path / "p", ["chassis.dbc"])
    config.write_text(config.read_text(encoding="utf-8") + "\n[e2e.DRV_Steering]\nMaxDeltaCounter = 5\n",
                      encoding="utf-8")
    assert main(["dbc", "--config", str(config)]) == 0
    assert "MaxDeltaCounter 5" in capsys.readouterr().out
    assert main(["dbc", "check", "--config", str(config)]) == 0
    out = capsys.readouterr().out
    assert "DRV_Steering 0x100: P11 DataID 0x0100 BOTH" in out and "MaxDeltaCounter 5" in out
    assert "[DBC attributes, bench.toml [e2e]]" in out
    config.write_text(config.read_text(encoding="utf-8").replace("[e2e.DRV_Steering]", "[e2e.DRV_Steerin]"),
                      encoding="utf-8")
    assert main(["dbc", "check", "--config", str(config)]) == 1
    assert ("bench.toml: error [e2e] DRV_Steerin: no such message in the databases (did you mean DRV_Steering?)"
            in capsys.readouterr().out)


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
