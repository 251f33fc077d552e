"""Report security end to end: a run against a DBC whose comments and value-table names carry markup
renders in headless Chromium with no script run and no injected element; the run writes only inside
its output folder."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.browser import IMG, SCRIPT, dump, problems
from tests.repo import BENCH_DBC, CHASSIS_DBC, ROOT

CASES = ROOT / "tests" / "fixtures" / "cases" / "test_mini.py"


def hostile_project(folder: Path) -> Path:
    """A project whose chassis DBC carries markup in message and signal comments and a value-table name."""
    text = CHASSIS_DBC.read_text(encoding="utf-8")
    marker = 'CM_ BO_ 256 '
    start = text.index(marker)
    end = text.index(";", start)
    comment = f'CM_ BO_ 256 "{SCRIPT.replace(chr(34), chr(39))} {IMG.replace(chr(34), chr(39))}"'
    text = text[:start] + comment + text[end:]
    text = text.replace('"NORMAL"', '"<b onmouseover=alert(1)>NORMAL</b>"', 1)
    dbc = folder / "chassis.dbc"
    dbc.write_text(text, encoding="utf-8")
    config = folder / "bench.toml"
    config.write_text(f'[bench]\ndatabases = ["{dbc}", "{BENCH_DBC}"]\nstimulus = ["DRIVER", "TESTER"]\n'
                      f'plant = "chassis"\ntestcases = "{ROOT / "testcases"}"\nreports = "{folder / "reports"}"\n'
                      '[scenario]\ncommand = "BENCH_Control.ScenarioId"\nack = "PLANT_Status.ScenarioIdAck"\n')
    return config


def test_hostile_dbc_text_is_inert_in_the_report(tmp_path: Path) -> None:
    config = hostile_project(tmp_path)
    out = tmp_path / "out"
    before = set(tmp_path.rglob("*"))
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(CASES), "-k", "pivot", "--config", str(config),
                             "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    html = (out / "report.html").read_text()
    assert "&lt;script&gt;" in html and html.count("<script") == 1   # the comment is there, escaped; the one
    assert html.count("<script>(function () {") == 1                    # script is the report's own
    dom, stderr = dump(tmp_path, out / "report.html")
    assert problems(dom, stderr) == []
    written = set(tmp_path.rglob("*")) - before
    outside = [p for p in written if out not in p.parents and p != out and "chromium-profile" not in str(p)]
    assert outside == [], f"the run wrote outside its output folder: {outside}"
