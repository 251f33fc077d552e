"""The layers and their import rule (docs/architecture.md "The layers and their import rule").

bench/ is a generic bench: it knows no vehicle, so no message, signal or vehicle-specific node name of this
project's databases appears in it (code, docstrings, help text, report templates), not even the end-to-end
signals' (the bench finds the counter and the checksum by their places), nor the repository's file layout;
a project names what the bench needs in its bench.toml. The import direction holds: plant/ imports only the
bench's behaviour API (bench.sim.node), testcases/ never imports plant/, bench/ imports neither.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterator
from pathlib import Path

import cantools
import pytest

from tests.repo import BENCH_DBC, CHASSIS_DBC, ROOT

BENCH = ROOT / "bench"
TEXT_SUFFIXES = {".py", ".j2", ".html", ".css", ".js", ".toml", ".md", ".txt", ".json"}

#: Node names that are roles every bench project has (the stimulus and the plant), not parts of a vehicle.
ROLE_NODES = {"DRIVER", "TESTER", "PLANT"}


def _databases() -> list[cantools.database.can.Database]:
    return [cantools.database.load_file(str(path), strict=False) for path in (CHASSIS_DBC, BENCH_DBC)]


def project_names() -> dict[str, str]:
    """name -> what it is, for every name this project's databases give."""
    names: dict[str, str] = {}
    for database in _databases():
        for node in database.nodes:
            if node.name not in ROLE_NODES:
                names[node.name] = "node"
        for message in database.messages:
            names[message.name] = "message"
            for signal in message.signals:
                names.setdefault(signal.name, f"signal of {message.name}")
                for value in (signal.choices or {}).values():
                    text = str(value)
                    # the vehicle codes and coined value names; plain words (OK, LEFT, NORMAL, ...) are English
                    if signal.name == "Vehicle" or re.search(r"[_0-9]", text):
                        names.setdefault(text, f"value of {message.name}.{signal.name}")
    for path in (CHASSIS_DBC, BENCH_DBC):
        names[path.name] = "a database file of this repository"
    return names


def bench_files() -> Iterator[Path]:
    for path in sorted(BENCH.rglob("*")):
        if path.is_file() and path.suffix in TEXT_SUFFIXES and "__pycache__" not in path.parts:
            yield path


def occurrences(names: dict[str, str], files: list[Path]) -> list[str]:
    """'file:line: name (what) | text' for each whole-word occurrence (case-sensitive)."""
    wanted = sorted(names, key=len, reverse=True)
    pattern = re.compile(r"(?<![A-Za-z0-9_])(" + "|".join(re.escape(n) for n in wanted) + r")(?![A-Za-z0-9_])")
    found = []
    for path in files:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for match in pattern.finditer(line):
                where = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
                found.append(f"{where}:{number}: {match.group(1)} ({names[match.group(1)]}) "
                             f"| {line.strip()[:100]}")
    return found


def test_the_names_are_many() -> None:
    """The check is only as good as its list: both databases were read."""
    names = project_names()
    kinds = {what.split(" ")[0] for what in names.values()}
    assert {"node", "message", "signal", "value"} <= kinds
    assert sum(what == "message" for what in names.values()) > 30


def test_bench_names_no_message_signal_or_vehicle_of_this_project() -> None:
    found = occurrences(project_names(), list(bench_files()))
    assert not found, "bench/ names this project's databases (use a generic example or bench.toml):\n" + \
        "\n".join(found)


def test_the_grep_finds_a_planted_name(tmp_path: Path) -> None:
    """The search itself works: a message name in a docstring, a signal in an f-string, a vehicle code, and the
    end-to-end signals' names (the bench finds the counter and the checksum by their places, docs/spec/e2e.md)."""
    sample = tmp_path / "sample.py"
    sample.write_text('"""Sends BENCH_Control."""\nx = f"{a}.ScenarioIdAck"\ny = "EV4WIS"\n'
                      'z = "BENCH_ControlX"  # not a whole word\nw = ("AliveCounter", "Checksum")\n',
                      encoding="utf-8")
    found = occurrences(project_names(), [sample])
    assert [line.split(": ")[1].split(" ")[0] for line in found] == \
        ["BENCH_Control", "ScenarioIdAck", "EV4WIS", "AliveCounter", "Checksum"]


# -- the import rule ------------------------------------------------------------------------------------------
def imports(folder: Path) -> Iterator[tuple[str, int, str]]:
    """(file, line, module) for every import in the Python files of a folder, relative ones made absolute."""
    for path in sorted(folder.rglob("*.py")):
        package = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    yield str(path.relative_to(ROOT)), node.lineno, alias.name
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")
                    parts = parts[:len(parts) - node.level + 1]
                    base = ".".join([*parts, base] if base else parts)
                yield str(path.relative_to(ROOT)), node.lineno, base
                for alias in node.names:        # `from bench import node`: the module bench.sim.node
                    yield str(path.relative_to(ROOT)), node.lineno, f"{base}.{alias.name}"


def _top(module: str) -> str:
    return module.split(".")[0]


#: What plant/ may import of the bench: the behaviour API only (a plant is a plugin of the bench).
PLANT_MAY_IMPORT = {"bench", "bench.sim.node"}


@pytest.mark.parametrize("folder, forbidden", [
    ("bench", {"plant", "testcases", "tests", "examples", "benchmarks"}),
    ("testcases", {"plant", "tests"}),
    ("plant", {"testcases", "tests"}),
], ids=["bench", "testcases", "plant"])
def test_import_direction(folder: str, forbidden: set[str]) -> None:
    wrong = [f"{file}:{line}: {module}" for file, line, module in imports(ROOT / folder) if _top(module) in forbidden]
    assert not wrong, f"{folder}/ must not import {', '.join(sorted(forbidden))}:\n" + "\n".join(wrong)


def test_plant_uses_only_the_behaviour_api() -> None:
    wrong = [f"{file}:{line}: {module}" for file, line, module in imports(ROOT / "plant")
             if _top(module) == "bench" and module not in PLANT_MAY_IMPORT
             and not any(module.startswith(f"{allowed}.") for allowed in PLANT_MAY_IMPORT - {"bench"})]
    assert not wrong, "plant/ imports of the bench beyond bench.sim.node:\n" + "\n".join(wrong)


def test_the_import_scan_sees_relative_and_from_imports() -> None:
    """The scanner resolves `from . import x` and `from bench import node` (else the rule checks nothing)."""
    folder = ROOT / "plant"
    found = {module for _, _, module in imports(folder)}
    assert "bench.sim.node" in found
    assert any(module.startswith("plant.") for module in found)


# -- the log package ------------------------------------------------------------------------------------------
#: What bench/log/ may import of the bench besides itself: the frame checks it logs with, the errors, the version.
LOG_MAY_IMPORT = {"bench", "bench.version", "bench.errors", "bench.canid", "bench.database.codec",
                  "bench.checks.monitor", "bench.config", "bench.diag"}
#: The one module that may reach into mcap's private state (its bytes are compared with mcap's public writer's,
#: tests/bench/log/test_recorder.py).
MCAP_FAST_PATH = "bench/log/mcapfast.py"


def test_the_log_package_sits_below_the_session() -> None:
    """bench/log/ imports no part of the bench above it (session, station, run, cli, report, pytest plugin) and no
    pytest: a python-can tool loads it through its entry points without the bench's runner."""
    wrong = [f"{file}:{line}: {module}" for file, line, module in imports(BENCH / "log")
             if (_top(module) == "bench" and module not in LOG_MAY_IMPORT and not module.startswith("bench.log")
                 and not any(module.startswith(f"{allowed}.") for allowed in LOG_MAY_IMPORT - {"bench"}))
             or _top(module) in {"pytest", "_pytest"}]
    assert not wrong, "bench/log/ imports beyond " + ", ".join(sorted(LOG_MAY_IMPORT)) + ":\n" + "\n".join(wrong)


def _private_mcap(folder: Path) -> Iterator[str]:
    """'file:line: what' for each import of a `_` name from mcap, and each use of mcap's Writer's mangled names."""
    for file, line, module in imports(folder):
        if _top(module) == "mcap" and any(part.startswith("_") for part in module.split(".")):
            yield f"{file}:{line}: {module}"
    for path in sorted(folder.rglob("*.py")):
        if path == Path(__file__):   # this test names what it looks for
            continue
        for number, text in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if "_Writer__" in text:
                yield f"{path.relative_to(ROOT)}:{number}: {text.strip()[:80]}"


def test_no_private_mcap_name_outside_the_fast_path() -> None:
    found = [hit for folder in ("bench", "plant", "tests", "benchmarks", "scripts", "testcases")
             for hit in _private_mcap(ROOT / folder)]
    outside = [hit for hit in found if not hit.startswith(MCAP_FAST_PATH + ":")]
    assert not outside, f"mcap's private names outside {MCAP_FAST_PATH}:\n" + "\n".join(outside)
    # the scan sees the fast path's own import and mangled names (else it checks nothing)
    assert any("mcap._chunk_builder" in hit for hit in found)
    assert any("_Writer__chunk_builder" in hit for hit in found)


# -- the transport package ------------------------------------------------------------------------------------
#: What bench/transport/ may import of the bench besides itself: the errors, a frame's identity (bench.canid), and,
#: for its types and the kernel's periodic sending, the restbus it sends and the E2E protection of its frames.
TRANSPORT_MAY_IMPORT = {"bench", "bench.errors", "bench.canid", "bench.sim.restbus", "bench.e2e"}


def test_the_transport_package_sits_below_the_station() -> None:
    """bench/transport/ imports no part of the bench above it (station, session, clock, run, cli, report, pytest
    plugin) and no pytest: the station reaches its bus through it, never the other way round."""
    wrong = [f"{file}:{line}: {module}" for file, line, module in imports(BENCH / "transport")
             if (_top(module) == "bench" and module not in TRANSPORT_MAY_IMPORT
                 and not module.startswith("bench.transport")
                 and not any(module.startswith(f"{allowed}.") for allowed in TRANSPORT_MAY_IMPORT - {"bench"}))
             or _top(module) in {"pytest", "_pytest"}]
    assert not wrong, ("bench/transport/ imports beyond " + ", ".join(sorted(TRANSPORT_MAY_IMPORT)) + ":\n"
                       + "\n".join(wrong))
    assert any(module == "bench.sim.restbus" for _, _, module in imports(BENCH / "transport"))   # the scan sees it


def test_only_the_transport_asks_a_bus_what_it_is() -> None:
    """The station picks its transport once (bench.transport.transport_for): no `getattr(bus, ...)` probing of a
    bus outside bench/transport/ (issue 28, acceptance 2)."""
    probing = re.compile(r"getattr\(.*bus")
    found = [f"{path.relative_to(ROOT)}:{number}: {text.strip()[:80]}"
             for path in sorted(BENCH.rglob("*.py")) if "transport" not in path.relative_to(BENCH).parts
             for number, text in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if probing.search(text)]
    assert not found, "bus probing outside bench/transport/:\n" + "\n".join(found)
    assert any(probing.search(path.read_text(encoding="utf-8")) for path in (BENCH / "transport").rglob("*.py"))


# -- the packages of bench/ ------------------------------------------------------------------------------------
#: The packages below the session: what a run is built of. None imports the session, the case, the runner, the
#: command line, the reports or the pytest plugin, and none imports pytest (they run without a test runner).
BELOW_THE_SESSION = ("transport", "log", "sim", "checks", "faults", "database", "e2e", "diag", "results")
ABOVE = ("bench.session", "bench.case", "bench.run", "bench.cli", "bench.report", "bench.pytest", "bench.stop")
#: At most this many modules at bench/'s top level (issue 28): the rest lives in packages named for what they hold.
#: bench/compiled.py is the thirteenth: bench/__init__.py installs its finder before any package is imported.
TOP_LEVEL_MAX = 13


def test_bench_is_grouped_into_packages() -> None:
    top = sorted(p.name for p in BENCH.glob("*.py"))
    assert len(top) <= TOP_LEVEL_MAX, f"{len(top)} modules at bench/'s top level: {top}"
    for package in BELOW_THE_SESSION:
        assert (BENCH / package / "__init__.py").is_file(), package


@pytest.mark.parametrize("package", BELOW_THE_SESSION)
def test_the_packages_below_the_session_import_nothing_above_it(package: str) -> None:
    wrong = [f"{file}:{line}: {module}" for file, line, module in imports(BENCH / package)
             if any(module == above or module.startswith(f"{above}.") for above in ABOVE)
             or _top(module) in {"pytest", "_pytest"}]
    assert not wrong, f"bench/{package}/ imports the session's layer or pytest:\n" + "\n".join(wrong)
