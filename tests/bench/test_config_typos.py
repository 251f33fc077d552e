"""A newcomer's typo in bench.toml stops `bench run` before the first case, one line per typo, naming the file,
the table and the key, with the name most likely meant. Without these checks a mistyped table (`[scenaro]`) was
read as absent, and a mistyped signal of `[timing]` surfaced only as an error row at the end of the report."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.cli import main
from bench.config import load_config
from bench.database.codec import load_codebook
from bench.errors import ConfigError
from tests.repo import BENCH_DBC, CHASSIS_DBC, MINIMAL_PROJECT_TOML, ROOT

MINI_CASES = ROOT / "tests" / "fixtures" / "cases" / "test_mini.py"
GOOD = (MINIMAL_PROJECT_TOML.replace("db/chassis.dbc", str(CHASSIS_DBC)).replace("db/bench.dbc", str(BENCH_DBC))
        + '\n[timing]\nlatency = [{name = "FL", command = "VCU_WheelCmd_FL.SteerAngleCmd", '
          'status = "WHL_Status_FL.SteerAngle"}]\n')


def project_with(tmp_path: Path, old: str, new: str) -> Path:
    assert old in GOOD
    path = tmp_path / "bench.toml"
    path.write_text(GOOD.replace(old, new, 1), encoding="utf-8")
    return path


def test_the_good_file_has_no_problem(tmp_path: Path) -> None:
    project = load_config(project_with(tmp_path, "[bench]", "[bench]"))
    assert project.problems(load_codebook(project.databases)) == []


@pytest.mark.parametrize(("old", "new", "words"), [
    ("[scenario]", "[scenaro]", "unknown table(s) scenaro (did you mean scenario?)"),
    ("[timing]", "[timings]", "unknown table(s) timings (did you mean timing?)"),
    ("testcases =", "testcase =", "[bench] unknown key(s) testcase (did you mean testcases?)"),
    ('ack = "', 'akc = "', "[scenario] unknown key(s) akc (did you mean ack?)"),
    ("name =", "nam =", "unknown key(s) nam (did you mean name?)"),
], ids=["table-scenario", "table-timing", "bench-key", "scenario-key", "latency-key"])
def test_a_mistyped_key_or_table_is_refused_at_load(tmp_path: Path, old: str, new: str, words: str) -> None:
    path = project_with(tmp_path, old, new)
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert str(path) in str(error.value) and words in str(error.value), error.value


@pytest.mark.parametrize(("old", "new", "words"), [
    ('"TESTER"]', '"TESTR"]', "[bench] stimulus: node 'TESTR' (did you mean TESTER?) is in none of the databases"),
    ("ScenarioId\"", "ScenarioID\"", "[scenario] command: message BENCH_Control has no signal 'ScenarioID' "
                                     "(did you mean ScenarioId?)"),
    ("PLANT_Status.", "PLANT_Stat.", "[scenario] ack: no message 'PLANT_Stat' (did you mean PLANT_Status?)"),
    ("WHL_Status_FL.SteerAngle", "WHL_Status_FL.SteerAngel",
     "[timing] latency 'FL' status: message WHL_Status_FL has no signal 'SteerAngel' (did you mean SteerAngle?)"),
], ids=["stimulus", "scenario-signal", "scenario-message", "timing-signal"])
def test_a_name_the_databases_lack_stops_bench_run_before_any_case(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                   old: str, new: str, words: str) -> None:
    path = project_with(tmp_path, old, new)
    out = tmp_path / "out"
    assert main(["run", str(MINI_CASES), "--config", str(path), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err and "cases" not in captured.out
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"bench run: error: {path}: "), lines
    assert words in " ".join(captured.err.split()), captured.err
    assert not (out / "report.html").exists() and not (out / "run.mcap").exists()


def test_every_typo_is_its_own_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "bench.toml"
    path.write_text(GOOD.replace('"TESTER"]', '"TESTR"]').replace("WHL_Status_FL.SteerAngle", "WHL_Status_FL.Qwerty"),
                    encoding="utf-8")
    assert main(["run", str(MINI_CASES), "--config", str(path), "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 2, lines
    assert "'TESTR'" in lines[0] and "'Qwerty'" in lines[1] and "did you mean" not in lines[1], lines


# -- typos on the command line (issue 34, the front door): each names the name most likely meant -----------------
@pytest.mark.parametrize("argv, words", [
    (["--fault", "drop:VCU_WheelCmd_FLL@2-3"], "unknown message 'VCU_WheelCmd_FLL' (did you mean VCU_WheelCmd_FL?)"),
    (["--fault", "silence:VCUU@2-3"], "unknown node 'VCUU' (did you mean VCU?)"),
    (["--external", "VCUU"], "--external: unknown node(s) VCUU (did you mean VCU?)"),
    (["--dut", "ABX"], "--dut: unknown node(s) ABX (did you mean ABS?)"),
], ids=["fault-message", "fault-node", "external", "dut"])
def test_command_line_typos_name_what_was_meant(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str],
                                                words: str) -> None:
    assert main(["run", str(MINI_CASES), "--out", str(tmp_path / "out"), *argv]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert words in err, err
