"""The bench works from a wheel: no path of this repository is needed once the package is installed.

The test builds the project's wheel offline (`pip wheel --no-deps --no-build-isolation`) from a copy of the
sources, installs it into a fresh virtual environment, and, in a temporary folder that holds only a
bench.toml, copies of the databases and one case file, runs `bench dbc`, `bench dbc check` and `bench run`.

The environment takes its dependencies from this interpreter's site-packages through a .pth file listing
that folder, not through `--system-site-packages`: the latter also runs the .pth files found there, and the
editable install's finder among them would import `bench` from the source tree again, which is exactly what
the test must rule out (it checks where `bench` and `plant` are imported from).

Deselect with `-m "not wheel"`; CI runs it (15 to 30 s).
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import sysconfig
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

from tests.repo import BENCH_DBC, CHASSIS_DBC, MINIMAL_PROJECT_TOML, ROOT

pytestmark = pytest.mark.wheel

#: What the wheel is built from (pyproject's packages and readme); nothing else of the repository is copied, setup.py
#: and any compiled module neither: a pure-Python wheel, built in seconds (tests/integration/test_compiled.py has the
#: compiled form).
SOURCES = ("pyproject.toml", "README.md", "bench", "plant")

BENCH_TOML = MINIMAL_PROJECT_TOML

# docs/spec/formulas.md §2, front-left wheel about a centre of rotation (x, y): atan((L - y) / (x + K)), with the
# 4WIS EV's half wheelbase L = 2.76 / 2 m and half track K = 1.11 / 2 m (docs/spec/vehicles.md A).
PIVOT_X, PIVOT_Y, L, K = 5.0, 0.0, 2.76 / 2, 1.11 / 2
EXPECTED_FL = math.degrees(math.atan((L - PIVOT_Y) / (PIVOT_X + K)))

CASE = f"""\
def test_pivot_from_the_wheel(bench):
    bench.start_scenario(Vehicle="EV4WIS")
    bench.set("DRV_MotionRequest", DriveMode="PIVOT", PivotX={PIVOT_X}, PivotY={PIVOT_Y}, TargetSpeed=0.5)
    bench.run(1.5)
    bench.expect("FL angle", bench.value("WHL_Status_FL", "SteerAngle"), {EXPECTED_FL!r}, abs_tol=0.05, unit="deg")
"""


def _run(command: list[str], cwd: Path, env: dict[str, str], timeout: float = 120) -> subprocess.CompletedProcess:
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"{command}: exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    """(the venv's bin folder, an environment that knows nothing of the source tree)."""
    top = tmp_path_factory.mktemp("wheel")
    source = top / "src"
    source.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.so"))
        else:
            shutil.copy(ROOT / name, source / name)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    dist = top / "dist"
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
          "-w", str(dist), str(source)], top, env)
    wheels = list(dist.glob("*.whl"))
    assert len(wheels) == 1, wheels
    with zipfile.ZipFile(wheels[0]) as archive:
        tops = {name.split("/")[0] for name in archive.namelist()}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"bench", "plant"}, tops

    venv = top / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], top, env)
    python = venv / "bin" / "python"
    purelib = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                   top, env).stdout.strip()
    here = dict.fromkeys([sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]])
    Path(purelib, "bench_deps.pth").write_text("".join(f"{p}\n" for p in here), encoding="utf-8")
    _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index", "-q",
          str(wheels[0])], top, env)
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return venv / "bin", env


@pytest.fixture(scope="module")
def project(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A bench project of its own: bench.toml, the databases, one case; no plant, no bench, no contract."""
    folder = tmp_path_factory.mktemp("project")
    (folder / "db").mkdir()
    for database in (CHASSIS_DBC, BENCH_DBC):
        shutil.copy(database, folder / "db" / database.name)
    (folder / "bench.toml").write_text(BENCH_TOML, encoding="utf-8")
    (folder / "cases").mkdir()
    (folder / "cases" / "test_tiny.py").write_text(CASE, encoding="utf-8")
    return folder


def test_imports_come_from_the_wheel(installed: tuple[Path, dict[str, str]], project: Path) -> None:
    bin_dir, env = installed
    done = _run([str(bin_dir / "python"), "-c", "import bench, plant; print(bench.__file__); print(plant.__file__)"],
                project, env)
    for line in done.stdout.split():
        assert Path(line).is_relative_to(bin_dir.parent), line
        assert not Path(line).is_relative_to(ROOT), line


def test_bench_dbc_lists_the_configured_databases(installed: tuple[Path, dict[str, str]], project: Path) -> None:
    bin_dir, env = installed
    env = {**env, "COLUMNS": "200"}
    listed = _run([str(bin_dir / "bench"), "dbc"], project / "cases", env).stdout    # bench.toml is one folder up
    assert "chassis.dbc" in listed and "bench.dbc" in listed and "BENCH_Control" in listed
    checked = _run([str(bin_dir / "bench"), "dbc", "check"], project, env).stdout
    assert "2 files: 2 accepted" in checked


def test_bench_run_of_a_case(installed: tuple[Path, dict[str, str]], project: Path) -> None:
    bin_dir, env = installed
    out = project / "reports" / "run"
    _run([str(bin_dir / "bench"), "run", "cases/test_tiny.py", "--out", str(out)], project, env)
    cases = list(ET.parse(out / "junit.xml").getroot().iter("testcase"))
    assert [c.get("name") for c in cases] == ["test_pivot_from_the_wheel"]
    assert not any(c.find(tag) is not None for c in cases for tag in ("failure", "error", "skipped"))
    assert (out / "report.html").stat().st_size > 0 and (out / "run.mcap").stat().st_size > 0
