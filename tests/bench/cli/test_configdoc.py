"""The bench.toml reference (docs/reference/bench-toml.md) is current, its examples are what the loader accepts, and
the loader refuses every key the reference does not list (bench.config.SCHEMA is the one list both read)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from bench.cli import configdoc
from bench.config import SCHEMA, TABLES, load_config
from bench.errors import ConfigError
from tests.repo import ROOT


def test_the_page_is_current() -> None:
    assert configdoc.main([str(ROOT / configdoc.TARGET), "--check"]) == 0, "run `python -m bench.cli.configdoc`"


def _project(tmp_path: Path, text: str) -> Path:
    shutil.copytree(ROOT / "dbc", tmp_path / "dbc")
    for name, example in (("chassis.dbc", "network.dbc"), ("bench.dbc", "hil.dbc")):   # the page's generic names
        shutil.copy(ROOT / "dbc" / name, tmp_path / "dbc" / example)
    shutil.copytree(ROOT / "docs" / "contract", tmp_path / "docs" / "contract")
    (tmp_path / "my_keys.py").write_text("def ecu_key(level, seed, params=None):\n    return seed\n")
    path = tmp_path / "bench.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_the_pages_examples_load(tmp_path: Path) -> None:
    page = (ROOT / configdoc.TARGET).read_text(encoding="utf-8")
    examples = re.findall(r"```toml\n(.*?)```", page, re.S)
    assert len(examples) == len([n for n in SCHEMA if "latency" not in n])
    project = load_config(_project(tmp_path, "\n".join(examples).replace('"0A 0B 0C ..."', '"' + "0A " * 16 + '"')))
    assert project.plant == "my_plant" and project.scenario is not None and project.bus.fd is True
    assert project.e2e == {"ECU_Status": {"Profile": "P11", "DataID": 0x0222, "MaxDeltaCounter": 2}}
    assert project.messages == {"BREMSE_33": {"cycle_time_ms": 100, "send_type": "cyclic"}}
    assert project.calibration == {"ECU": {"v_l0": (0.6, "km/h")}}
    assert project.security == {"ECU": "my_keys:ecu_key"} and len(project.latency) == 1


BASE = '[bench]\ndatabases = ["dbc/chassis.dbc"]\nstimulus = ["DRIVER"]\ntestcases = "t"\nreports = "r"\n'
#: a minimal table of each, with one key the reference does not list
BOGUS = {
    "bench": BASE.replace("[bench]\n", "[bench]\nbogus = 1\n"),
    "scenario": BASE + '[scenario]\ncommand = "A.B"\nack = "C.D"\nbogus = 1\n',
    "contract": BASE + "[contract]\nbogus = 1\n",
    "timing": BASE + "[timing]\nbogus = 1\n",
    "timing.latency": BASE + '[timing]\nlatency = [{command = "A.B", status = "C.D", bogus = 1}]\n',
    "e2e": BASE + "[e2e.VCU_Status]\nbogus = 1\n",
    "messages": BASE + "[messages.VCU_Status]\nbogus = 1\n",
    "calibration": BASE + "[calibration.ABS]\nv = { value = 1, unit = \"m\", bogus = 1 }\n",
    "diagnostics": BASE + "[diagnostics]\nbogus = 1\n",
    "<tables>": BASE + "[bogus]\nx = 1\n",
}


@pytest.mark.parametrize("table", [name for name in SCHEMA if not SCHEMA[name].others] + ["<tables>"])
def test_a_key_the_reference_does_not_list_is_refused(tmp_path: Path, table: str) -> None:
    with pytest.raises(ConfigError, match=r"unknown (key|table)\(s\) bogus .*\(known: ") as caught:
        load_config(_project(tmp_path, BOGUS[table]))
    known = TABLES if table == "<tables>" else tuple(SCHEMA[table].keys)
    assert f"(known: {', '.join(known)})" in str(caught.value)


def test_bus_passes_other_keys_on(tmp_path: Path) -> None:
    assert SCHEMA["bus"].others
    assert load_config(_project(tmp_path, BASE + "[bus]\napp_name = \"bench\"\n")).bus.extra == {"app_name": "bench"}
