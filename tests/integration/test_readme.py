"""The README's code runs (issue 16, finding 8).

Every ```python block of README.md runs as written: a block that defines `test_*` functions is a test case, saved
in a folder outside the repository and run with `bench run FILE` on the embedded default (what a newcomer does);
any other block runs as a script. Every `bench ...` command the README shows (shell blocks and the commands
table) names a subcommand that exists and only options that subcommand's `--help` lists; nothing is run on a bus.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from bench.cli import main
from tests.repo import ROOT

README = ROOT / "README.md"
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)


def blocks(language: str) -> list[str]:
    return [body for lang, body in FENCE.findall(README.read_text(encoding="utf-8")) if lang == language]


PYTHON = blocks("python")


def test_the_readme_has_a_test_case() -> None:
    assert any(re.search(r"^def test_\w+\(bench\)", b, re.M) for b in PYTHON)


@pytest.mark.parametrize("index", range(len(PYTHON)))
def test_python_block_runs(index: int, tmp_path: Path) -> None:
    code = PYTHON[index]
    if re.search(r"^def test_\w+\(", code, re.M):
        case = tmp_path / "cases" / f"test_readme_{index}.py"
        case.parent.mkdir()
        case.write_text(code, encoding="utf-8")
        out = tmp_path / "report"
        done = subprocess.run([sys.executable, "-m", "bench", "run", case.name, "--out", str(out),
                               "--config", str(ROOT / "bench.toml")],
                              cwd=case.parent, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        cases = ET.parse(out / "junit.xml").getroot().iter("testcase")
        names = {c.get("name") for c in cases}
        defined = set(re.findall(r"^def (test_\w+)\(", code, re.M))
        assert defined <= names, (defined, names)   # every case of the block ran (and passed: exit 0)
    else:
        script = tmp_path / f"readme_{index}.py"
        script.write_text(code, encoding="utf-8")
        done = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]


# -- the bench commands the README shows ----------------------------------------------------------------------
def _commands() -> list[str]:
    """Every `bench ...` command of the README: shell blocks (split at &&, ;, |, &) and inline code."""
    found = []
    for body in blocks("sh"):
        for line in body.splitlines():
            line = line.split("#", 1)[0]
            found += [part.strip() for part in re.split(r"&&|\|\||;|\s&\s|\s&$|\|(?!\w)", line)]
    found += re.findall(r"`(bench [^`]+)`", README.read_text(encoding="utf-8"))
    return sorted({c for c in found if c.startswith("bench ")})


COMMANDS = _commands()


def _help(words: list[str], capsys: pytest.CaptureFixture[str]) -> str | None:
    """`bench WORDS --help` in process: its text, or None when argparse rejects the words."""
    with pytest.raises(SystemExit) as exit_:
        main([*words, "--help"])
    out = capsys.readouterr().out
    return out if exit_.value.code == 0 else None


def test_the_readme_shows_commands() -> None:
    assert {"bench run", "bench plant", "bench monitor", "bench replay"} <= {" ".join(c.split()[:2]) for c in COMMANDS}


@pytest.mark.parametrize("command", COMMANDS)
def test_command_exists_with_its_options(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    tokens = shlex.split(command.replace("[", " ").replace("]", " ").replace("\\|", "|"))[1:]
    words = []
    for token in tokens:                       # `bench log export FILE ...`: the subcommand is `log export`
        if not re.fullmatch(r"[a-z][a-z-]*", token):
            break
        words.append(token)
    text = None
    while words and text is None:              # a trailing lower-case word may be a value: drop it and retry
        text = _help(words, capsys)
        if text is None:
            words.pop()
    if text is None:
        pytest.fail(f"{command}: no such subcommand")
    options = [t.split("=", 1)[0] for t in tokens if re.fullmatch(r"--?[a-zA-Z][\w-]*(=.*)?", t)]
    missing = [o for o in options if not re.search(rf"(^|[\s,\[]){re.escape(o)}($|[\s,=\]])", text, re.M)]
    assert not missing, f"{command}: `bench {' '.join(words)} --help` lists no {', '.join(missing)}"


# -- the fixture reference (docs/reference/fixture.md, mkdocs + mkdocstrings) ------------------------------------
def test_every_public_method_of_the_fixture_says_what_it_records() -> None:
    """The reference is generated from the docstrings: every public method and property of Case has one, and
    it says whether the call records a step in the report."""
    import inspect

    from bench.case import Case

    assert "Generated by `python -m bench.pytest.fixturedoc`" in (ROOT / "docs" / "reference" / "fixture.md").read_text(
        encoding="utf-8")
    members = [name for name, _ in inspect.getmembers(Case) if not name.startswith("_")]
    assert {"start_scenario", "set", "run", "wait_until", "eventually", "always", "inject", "expect",
            "expect_between", "history", "value", "plot", "table", "check_cycle_times"} <= set(members)
    for name in members:
        doc = inspect.getdoc(getattr(Case, name)) or ""
        assert re.search(r"[Rr]ecords? (no|one) step", doc), f"Case.{name}: its docstring says no step"


def test_the_reference_builds_strictly(tmp_path: Path) -> None:
    """`mkdocs build --strict` (CI runs it too, after installing the docs extras)."""
    pytest.importorskip("mkdocstrings_handlers.python", reason="pip install -e '.[docs]'")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    page = (tmp_path / "site" / "fixture" / "index.html").read_text(encoding="utf-8")
    for method in ("eventually", "always", "inject", "expect_between", "history"):
        assert f"<code>{method}(" in page, method
