"""Bad configuration files and command-line values: a one-line error naming the file and the key (exit 2),
never a traceback; hypothesis feeds the config loader random text and random structures."""

from __future__ import annotations

import atexit
import json
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from bench.cli import main
from bench.config import ProjectConfig, ScenarioProtocol, load_config
from bench.errors import ConfigError
from tests.repo import BENCH_DBC, CHASSIS_DBC, ROOT

BENCH = [sys.executable, "-m", "bench"]
MINI_CASES = ROOT / "tests" / "fixtures" / "cases" / "test_mini.py"
GOOD = {
    "databases": [str(CHASSIS_DBC), str(BENCH_DBC)],
    "stimulus": ["DRIVER", "TESTER"],
    "plant": "chassis",
    "testcases": "testcases",
    "reports": "reports",
}


def toml_value(value: Any) -> str:
    """A TOML literal (JSON's string escapes are TOML's; inline tables for dicts)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(value)


def toml(tables: dict[str, dict[str, Any]]) -> str:
    return "".join(f"[{name}]\n" + "".join(f"{json.dumps(k)} = {toml_value(v)}\n" for k, v in body.items())
                   for name, body in tables.items())


def write(tmp_path: Path, text: str | bytes, name: str = "bench.toml") -> Path:
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture(autouse=True)
def _wide_console(monkeypatch: pytest.MonkeyPatch) -> None:
    """Rich folds at 80 columns when not on a terminal; widen it so that one line stays one line."""
    monkeypatch.setenv("COLUMNS", "1000")


def one_line_error(path: Path, capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    """Run `bench ARGV --config PATH` in-process: exit 2 and one line of error without a traceback."""
    assert main([*argv, "--config", str(path)]) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err
    err = captured.err.strip()
    assert "\n" not in err and err.count("error:") == 1 and str(path) in err, err
    return err


# -- the loader ----------------------------------------------------------------------------------------------
def test_good_config(tmp_path: Path) -> None:
    project = load_config(write(tmp_path, toml({"bench": GOOD})))
    assert project.databases == (CHASSIS_DBC, BENCH_DBC)
    assert project.stimulus == ("DRIVER", "TESTER") and project.plant == "chassis"
    assert project.testcases == tmp_path / "testcases" and project.reports == tmp_path / "reports"


def test_repository_config_loads() -> None:
    assert isinstance(load_config(ROOT / "bench.toml"), ProjectConfig)


@pytest.mark.parametrize("body, words", [
    ('[bench]\ndatabases = ["a.dbc"\n', ["Unclosed array"]),
    ("[bench\n", ["line 1"]),
    ("[bench]\nplant = chassis\n", ["line 2"]),                          # bare word
    ('[bench]\nplant = "a"\nplant = "b"\n', ["line 3"]),                 # key twice
], ids=["unclosed-array", "unclosed-table", "bare-word", "duplicate-key"])
def test_malformed_toml(tmp_path: Path, body: str, words: list[str]) -> None:
    path = write(tmp_path, body)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(path) in str(info.value) and all(w in str(info.value) for w in words)


def test_missing_table(tmp_path: Path) -> None:
    path = write(tmp_path, toml({"bnech": GOOD}))
    with pytest.raises(ConfigError, match=r"missing table \[bench\]"):
        load_config(path)


@pytest.mark.parametrize("key, value", [
    ("databases", "dbc/chassis.dbc"), ("databases", []), ("databases", [1]), ("stimulus", [""]),
    ("stimulus", "DRIVER"), ("plant", 3), ("plant", ""), ("testcases", ["testcases"]), ("reports", True),
])
def test_wrong_types_name_the_key(tmp_path: Path, key: str, value: Any) -> None:
    path = write(tmp_path, toml({"bench": {**GOOD, key: value}}))
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert f"[bench] {key}" in str(info.value) and str(path) in str(info.value)


@pytest.mark.parametrize("key", ["databases", "stimulus", "testcases", "reports"])
def test_missing_key_names_it(tmp_path: Path, key: str) -> None:
    body = {k: v for k, v in GOOD.items() if k != key}
    with pytest.raises(ConfigError, match=rf"\[bench\] {key} must be"):
        load_config(write(tmp_path, toml({"bench": body})))


def test_a_project_without_a_plant(tmp_path: Path) -> None:
    """`plant` is optional: without it every simulated node is its database's restbus (README "A network without a
    plant"); an empty one is still an error."""
    body = {k: v for k, v in GOOD.items() if k != "plant"}
    assert load_config(write(tmp_path, toml({"bench": body}))).plant is None
    with pytest.raises(ConfigError, match=r"\[bench\] plant must be a non-empty string"):
        load_config(write(tmp_path, toml({"bench": {**body, "plant": ""}})))


def test_unknown_key(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"\[bench\] unknown key\(s\) colour"):
        load_config(write(tmp_path, toml({"bench": {**GOOD, "colour": "blue"}})))


def test_nonexistent_database(tmp_path: Path) -> None:
    path = write(tmp_path, toml({"bench": {**GOOD, "databases": [str(CHASSIS_DBC), "nope.dbc"]}}))
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert "[bench] databases" in str(info.value) and str(tmp_path / "nope.dbc") in str(info.value)


def test_database_paths_are_relative_to_the_file(tmp_path: Path) -> None:
    (tmp_path / "db").mkdir()
    (tmp_path / "db" / "x.dbc").write_text("")
    project = load_config(write(tmp_path, toml({"bench": {**GOOD, "databases": ["db/x.dbc"]}})))
    assert project.databases == (tmp_path / "db" / "x.dbc",)


@pytest.mark.parametrize("content", [b"\xff\xfe[\x00b\x00", b"[bench]\nplant = \"\xe9\"\n"], ids=["utf16", "latin1"])
def test_not_utf8(tmp_path: Path, content: bytes) -> None:
    with pytest.raises(ConfigError, match="not UTF-8"):
        load_config(write(tmp_path, content))


def test_deep_nesting(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="nested too deeply"):
        load_config(write(tmp_path, "[bench]\nplant = " + "[" * 5000 + "]" * 5000 + "\n"))


# -- [scenario]: the scenario protocol's names come from the project, not from the bench ----------------------
SCENARIO_GOOD = {"command": "BENCH_Control.ScenarioId", "ack": "PLANT_Status.ScenarioIdAck"}


def test_scenario_table(tmp_path: Path) -> None:
    project = load_config(write(tmp_path, toml({"bench": GOOD, "scenario": {**SCENARIO_GOOD, "timeout": 0.5}})))
    assert project.scenario == ScenarioProtocol(("BENCH_Control", "ScenarioId"), ("PLANT_Status", "ScenarioIdAck"),
                                                0.5)
    assert load_config(write(tmp_path, toml({"bench": GOOD, "scenario": SCENARIO_GOOD}))).scenario.timeout == 2.0
    assert load_config(write(tmp_path, toml({"bench": GOOD}))).scenario is None     # optional: no plant protocol


def test_repository_config_names_its_scenario_protocol() -> None:
    assert load_config(ROOT / "bench.toml").scenario is not None


@pytest.mark.parametrize("scenario, words", [
    ({"ack": "PLANT_Status.ScenarioIdAck"}, "needs command"),
    ({"command": "BENCH_Control.ScenarioId"}, "needs ack"),
    ({**SCENARIO_GOOD, "command": "BENCH_Control"}, 'command must be "Message.Signal"'),
    ({**SCENARIO_GOOD, "ack": 3}, 'ack must be "Message.Signal"'),
    ({**SCENARIO_GOOD, "timeout": -1}, "timeout must be a positive number"),
    ({**SCENARIO_GOOD, "id": "x"}, "unknown key(s) id"),
], ids=["no-command", "no-ack", "no-signal", "not-text", "negative-timeout", "unknown-key"])
def test_scenario_table_errors(tmp_path: Path, scenario: dict[str, Any], words: str) -> None:
    path = write(tmp_path, toml({"bench": GOOD, "scenario": scenario}))
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert str(path) in str(error.value) and "[scenario]" in str(error.value) and words in str(error.value)


@pytest.mark.parametrize("scenario, words", [
    ({**SCENARIO_GOOD, "command": "NoSuch_Message.ScenarioId"}, "no message 'NoSuch_Message'"),
    ({**SCENARIO_GOOD, "ack": "PLANT_Status.NoSuchSignal"}, "has no signal 'NoSuchSignal'"),
    ({**SCENARIO_GOOD, "command": "PLANT_Status.ScenarioIdAck"}, "not by a stimulus node"),
], ids=["unknown-message", "unknown-signal", "not-stimulus"])
def test_scenario_names_are_checked_against_the_databases(tmp_path: Path, scenario: dict[str, Any],
                                                          words: str) -> None:
    """Checked when a session loads the databases: before any case starts, naming the file and the key."""
    from bench.config import RunSettings
    from bench.session import BenchSession

    path = write(tmp_path, toml({"bench": GOOD, "scenario": scenario}))
    with pytest.raises(ConfigError) as error:
        BenchSession(load_config(path), RunSettings())
    assert str(path) in str(error.value) and words in str(error.value)


# -- [calibration]: a real ECU's calibration the cases need --------------------------------------------------------
def test_calibration_table_is_read(tmp_path: Path) -> None:
    body = '[calibration.ABS]\nv_l0 = { value = 0.8, unit = "km/h" }\nv_l1 = { value = 7, unit = "km/h" }\n'
    project = load_config(write(tmp_path, toml({"bench": GOOD}) + body))
    assert project.calibration == {"ABS": {"v_l0": (0.8, "km/h"), "v_l1": (7.0, "km/h")}}
    assert load_config(write(tmp_path, toml({"bench": GOOD}))).calibration == {}


@pytest.mark.parametrize("body, words", [
    ('[calibration.ABS]\nv_l0 = 0.6\n', "[calibration.ABS] v_l0 must be { value = <number>"),
    ('[calibration.ABS]\nv_l0 = { value = "0.6", unit = "km/h" }\n', "[calibration.ABS] v_l0: value must be a finite"),
    ('[calibration.ABS]\nv_l0 = { value = nan, unit = "km/h" }\n', "[calibration.ABS] v_l0: value must be a finite"),
    ('[calibration.ABS]\nv_l0 = { value = 0.6 }\n', "[calibration.ABS] v_l0: unit must be a non-empty string"),
    ('[calibration.ABS]\nv_l0 = { value = 0.6, unit = "km/h", units = "x" }\n', "unknown key(s) units"),
    ('[calibration]\nABS = 3\n', "give a node's calibration as a table [calibration.ABS]"),
    ('[calibraton.ABS]\n', "unknown table(s) calibraton (did you mean calibration?)"),
], ids=["bare-number", "text", "nan", "no-unit", "extra-key", "not-a-table", "typo"])
def test_calibration_errors_are_one_line(tmp_path: Path, body: str, words: str) -> None:
    path = write(tmp_path, toml({"bench": GOOD}) + body)
    with pytest.raises(ConfigError) as error:
        load_config(path)
    text = str(error.value)
    assert text.startswith(f"{path}") and words in text and "\n" not in text, text


def test_calibration_of_an_unknown_node_is_a_problem(tmp_path: Path) -> None:
    from bench.database.codec import load_codebook

    project = load_config(write(tmp_path, toml({"bench": GOOD}) + '[calibration.ABX]\nx = { value = 1, unit = "-" }\n'))
    problems = project.problems(load_codebook(project.databases))
    assert len(problems) == 1 and "[calibration.ABX]: node 'ABX' (did you mean ABS?)" in problems[0], problems


# -- [e2e]: a message's AUTOSAR E2E parameters over its database's own ------------------------------------------
def test_e2e_table_is_read_by_autosar_names(tmp_path: Path) -> None:
    project = load_config(write(tmp_path, toml({"bench": GOOD}) + "[e2e.DRV_Steering]\nMaxDeltaCounter = 3\n"
                                '[e2e.DRV_Pedals]\nProfile = "P02"\nDataIDList = [' + ", ".join(map(str, range(16)))
                                + "]\n"))
    assert project.e2e == {"DRV_Steering": {"MaxDeltaCounter": 3},
                           "DRV_Pedals": {"Profile": "P02", "DataIDList": " ".join(f"{i:02X}" for i in range(16))}}
    assert load_config(write(tmp_path, toml({"bench": GOOD}))).e2e == {}


@pytest.mark.parametrize("body, words", [
    ("[e2e.DRV_Steering]\nMaxDeltaCountr = 3\n",
     "[e2e.DRV_Steering] unknown key(s) MaxDeltaCountr (did you mean MaxDeltaCounter?)"),
    ("[e2e.DRV_Steering]\nE2E_DataID = 3\n", "[e2e.DRV_Steering] unknown key(s) E2E_DataID (did you mean DataID?)"),
    ("[e2e]\nDRV_Steering = 3\n", "give a message's settings as a table [e2e.DRV_Steering]"),
    ("[e2e.DRV_Steering]\nProfile = 11\n", "[e2e.DRV_Steering] Profile must be a name"),
    ('[e2e.DRV_Steering]\nDataID = "0x100"\n', "[e2e.DRV_Steering] DataID must be a whole number"),
    ("[e2e.DRV_Steering]\nDataIDList = [1, 256]\n", "[e2e.DRV_Steering] DataIDList must be 16 bytes"),
    ("[e2e.DRV_Steering]\nWindowSize = true\n", "[e2e.DRV_Steering] WindowSize must be a whole number"),
    # [messages.MESSAGE] (bench.database.overrides)
    ("[messages.DRV_Steering]\ncycle_time = 20\n",
     "[messages.DRV_Steering] unknown key(s) cycle_time (did you mean cycle_time_ms?)"),
    ("[messages]\nDRV_Steering = 20\n", "give a message's settings as a table [messages.DRV_Steering]"),
    ("[messages.DRV_Steering]\ncycle_time_ms = 0\n", "cycle_time_ms must be a positive number of milliseconds"),
    ("[messages.DRV_Steering]\ncycle_time_ms = true\n", "cycle_time_ms must be a positive number of milliseconds"),
    ('[messages.DRV_Steering]\ncycle_time_ms = "10"\n', "cycle_time_ms must be a positive number of milliseconds"),
    ('[messages.DRV_Steering]\nsend_type = "OnChange"\n', "is no send type the bench knows (did you mean 'on_change'"),
], ids=["typo", "prefix", "not-a-table", "profile-number", "id-text", "list-byte", "bool",
       "messages-typo", "messages-not-a-table", "messages-zero", "messages-bool", "messages-text",
       "messages-send-type"])
def test_message_table_errors_are_one_line(tmp_path: Path, body: str, words: str) -> None:
    path = write(tmp_path, toml({"bench": GOOD}) + body)
    with pytest.raises(ConfigError) as error:
        load_config(path)
    text = str(error.value)
    assert text.startswith(f"{path}: ") and words in text and "\n" not in text, text


def test_e2e_table_reaches_the_session_and_bench_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The override is what the run loads (bench.session, bench run's checks before any case)."""
    from bench.config import RunSettings
    from bench.session import BenchSession

    path = write(tmp_path, toml({"bench": GOOD}) + "[e2e.DRV_Steering]\nMaxDeltaCounter = 3\nWindowSize = 4\n")
    session = BenchSession(load_config(path), RunSettings())
    try:
        protection = session.codebook["DRV_Steering"].protection
        assert protection is not None and protection.max_delta_counter == 3 and protection.sm.window_size == 4
        assert "bench.toml [e2e]" in protection.source
        other = session.codebook["DRV_Pedals"].protection
        assert other is not None and other.max_delta_counter == 2 and other.source == "DBC attributes"
    finally:
        session.close()
    bad = write(tmp_path, toml({"bench": GOOD}) + "[e2e.DRV_Steering]\nOffset = 44\n", "bad.toml")
    assert main(["run", str(MINI_CASES), "--config", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "bench.toml [e2e.DRV_Steering]" in err and "Offset 44 is not a multiple of 8" in err, err
    unknown = write(tmp_path, toml({"bench": GOOD}) + "[e2e.DRV_Steerin]\nMaxDeltaCounter = 3\n", "unknown.toml")
    assert main(["run", str(MINI_CASES), "--config", str(unknown), "--out", str(tmp_path / "out")]) == 2
    assert "[e2e] DRV_Steerin: no such message (did you mean DRV_Steering?)" in capsys.readouterr().err


# -- [messages]: what a database lacks for one message (bench.database.overrides) -------------------------------
def test_messages_table_is_read(tmp_path: Path) -> None:
    project = load_config(write(tmp_path, toml({"bench": GOOD}) + "[messages.DRV_Steering]\ncycle_time_ms = 20\n"
                                '[messages.DRV_Pedals]\nsend_type = "cyclic"\ncycle_time_ms = 12.5\n'))
    assert project.messages == {"DRV_Steering": {"cycle_time_ms": 20},
                                "DRV_Pedals": {"send_type": "cyclic", "cycle_time_ms": 12.5}}
    assert load_config(write(tmp_path, toml({"bench": GOOD}))).messages == {}


def test_messages_table_reaches_the_restbus_and_bench_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The restbus sends at bench.toml's cycle time, and the monitor judges by it; a message no database has
    stops `bench run` at the door."""
    from dataclasses import replace

    from bench.config import RunSettings
    from bench.session import BenchSession

    path = write(tmp_path, toml({"bench": GOOD}) + "[messages.DRV_Steering]\ncycle_time_ms = 25\n")
    project = replace(load_config(path), plant="tests.fixtures.echo_plant:build")
    session = BenchSession(project, RunSettings())
    try:
        session.start()
        session.run_until(1.0)
        steering = session.runner.monitor.state("DRV_Steering")
        pedals = session.runner.monitor.state("DRV_Pedals")     # the database's 10 ms, untouched
        assert steering.intervals and all(abs(i - 0.025) < 1e-9 for i in steering.intervals), steering.intervals[:5]
        assert pedals.intervals and all(abs(i - 0.010) < 1e-9 for i in pedals.intervals)
        assert session.codebook["DRV_Steering"].cycle_time == 0.025
    finally:
        session.close()
    unknown = write(tmp_path, toml({"bench": GOOD}) + "[messages.DRV_Steerin]\ncycle_time_ms = 25\n", "unknown.toml")
    assert main(["run", str(MINI_CASES), "--config", str(unknown), "--out", str(tmp_path / "out")]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "[messages.DRV_Steerin]: no such message in the databases (did you mean DRV_Steering?)" in err, err


def test_config_is_a_folder_or_missing(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path)
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "nowhere.toml")


# -- through the command line --------------------------------------------------------------------------------
@pytest.mark.parametrize("command", ["run", "plant"])
@pytest.mark.parametrize("body, key", [
    ("[bench]\nplant = chassis\n", "line 2"),
    ("[other]\nx = 1\n", "[bench]"),
    (toml({"bench": {**GOOD, "plant": 3}}), "[bench] plant"),
    (toml({"bench": {**GOOD, "colour": "blue"}}), "colour"),
    (toml({"bench": {**GOOD, "databases": ["nope.dbc"]}}), "[bench] databases"),
], ids=["toml", "table", "type", "unknown", "database"])
def test_cli_bad_config(tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, body: str,
                        key: str) -> None:
    path = write(tmp_path, body, "bad.toml")
    extra = ["--duration", "0.1"] if command == "plant" else ["--out", str(tmp_path / "out")]
    err = one_line_error(path, capsys, command, *extra)
    assert key in err
    assert not (tmp_path / "out").exists(), "no report folder for a run that never started"


def test_cli_missing_config_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert "cannot read" in one_line_error(tmp_path / "nowhere.toml", capsys, "run")


@pytest.mark.parametrize("duration", ["-1", "0", "nan", "inf", "-inf"])
def test_plant_bad_duration(capsys: pytest.CaptureFixture[str], duration: str) -> None:
    assert main(["plant", f"--duration={duration}"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--duration" in err and "positive number of seconds" in err and "Traceback" not in err


def test_plant_duration_not_a_number(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:     # argparse's own one-line usage error
        main(["plant", "--duration", "abc"])
    assert info.value.code == 2
    assert "invalid float value: 'abc'" in capsys.readouterr().err


@pytest.mark.parametrize("argv, words", [
    (["--interface", "embedded"], ["--interface embedded", "another process"]),
    (["--interface", "virtual"], ["--interface virtual", "python-can's virtual bus", "another process"]),
    (["--interface", "bench_virtual"], ["--interface bench_virtual", "renamed to embedded"]),
    (["--interface", "no_such_interface", "--channel", "x"], ["no_such_interface"]),
    (["--external", "BOGUS"], ["--external", "BOGUS", "nodes:"]),
    (["--external", "VCU,NOPE"], ["--external", "NOPE"]),
    (["--vehicle", "NOPE"], ["NOPE", "EV4WIS"]),
], ids=["embedded", "python-can-virtual", "old-name", "unknown-interface", "unknown-node", "unknown-node-in-list",
        "unknown-vehicle"])
def test_plant_bad_values(capsys: pytest.CaptureFixture[str], argv: list[str], words: list[str]) -> None:
    assert main(["plant", *argv, "--duration", "0.1"]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert "Traceback" not in captured.out + captured.err and "\n" not in err
    assert err.startswith("bench plant: error:") and all(w in err for w in words), err


@pytest.mark.parametrize("argv", [["--external", "BOGUS"], ["--interface", "no_such_interface", "--channel", "x"]],
                         ids=["unknown-node", "unknown-interface"])
def test_run_bad_values(tmp_path: Path, argv: list[str]) -> None:
    result = subprocess.run([*BENCH, "run", str(MINI_CASES), "--out", str(tmp_path / "out"), *argv],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2, result.stdout + result.stderr
    assert "bench run: error:" in result.stderr


# -- fuzzing -------------------------------------------------------------------------------------------------
_FUZZ_DIR = Path(tempfile.mkdtemp(prefix="bench-config-fuzz-"))
atexit.register(shutil.rmtree, _FUZZ_DIR, ignore_errors=True)
KEYS = [*GOOD, "colour", "", "databases ", "Databases"]
SCALARS = st.one_of(st.text(max_size=20), st.integers(), st.floats(), st.booleans(),
                    st.sampled_from([str(CHASSIS_DBC), str(BENCH_DBC), "DRIVER", "TESTER", "chassis", "nope.dbc"]))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=8), inner, max_size=3)),
                      max_leaves=10)
TIMING = st.dictionaries(st.sampled_from(["latency", "other"]), st.one_of(
    VALUES, st.lists(st.dictionaries(st.sampled_from(["command", "status", "name", "threshold", "window", "x"]),
                                     st.one_of(SCALARS, st.sampled_from(["A.b", "A.", ".b", "A.b.c"])),
                                     max_size=6), max_size=3)), max_size=2)


def _load(text: str | bytes) -> None:
    """load_config either succeeds or raises ConfigError; anything else fails the test."""
    path = _FUZZ_DIR / "bench.toml"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        project = load_config(path)
    except ConfigError as exc:
        assert str(path) in str(exc)
        event("ConfigError")
        return
    event("loaded")
    assert isinstance(project, ProjectConfig) and project.databases


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(st.text(max_size=300), st.binary(max_size=300)))
def test_fuzz_config_random_text(text: str | bytes) -> None:
    _load(text)


FRAGMENTS = st.sampled_from([
    "[bench]", "[timing]", "[[bench]]", "[bench.x]", "databases = ", "stimulus = ", "plant = ", "testcases = ",
    "reports = ", "latency = ", "colour = ", '"chassis"', f'["{CHASSIS_DBC}"]', '["DRIVER", "TESTER"]', "[", "]",
    "{", "}", ",", '"', "'", "=", "\n", " ", "#", "1", "1.5", "nan", "true", "1979-05-27", '{command = "A.b"}',
    '"""', "'''", "\\", "\x00", "é",
])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(FRAGMENTS, max_size=40))
def test_fuzz_config_tomlish_text(fragments: list[str]) -> None:
    _load("".join(fragments))


SCENARIO = st.dictionaries(st.sampled_from(["command", "ack", "timeout", "x"]),
                           st.one_of(SCALARS, st.sampled_from(["A.b", "A.", ".b", "A.b.c"])), max_size=4)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(bench=st.one_of(st.dictionaries(st.sampled_from(KEYS), VALUES, max_size=7),
                       # mostly good values, so that the success path and [timing] are reached too
                       st.fixed_dictionaries({k: st.one_of(st.just(v), st.just(v), st.just(v), VALUES)
                                              for k, v in GOOD.items()})),
       timing=st.one_of(st.none(), st.none(), TIMING), table=st.sampled_from(["bench", "bench", "bench", "bnech"]),
       scenario=st.one_of(st.none(), SCENARIO))
def test_fuzz_config_random_structures(bench: dict[str, Any], timing: dict[str, Any] | None, table: str,
                                       scenario: dict[str, Any] | None) -> None:
    tables = {table: bench}
    if timing is not None:
        tables["timing"] = timing
    if scenario is not None:
        tables["scenario"] = scenario
    _load(toml(tables))
