"""Every citation of the specification resolves inside the repository.

Why: code, DBC comments and docs cite the formulas, vehicles and papers hundreds of times; a user who clones
the repository must find each cited file and section in `docs/spec/` (or `docs/contract/`), and a renamed
section or a citation of a file outside the repository must fail here, not surprise a reader.

Checked in the tracked text files of the folders below: (a) a cited `docs/spec/<file>.md` exists; (b) a cited
`§N` / `§N.M` (or `section N` in DBC comments) is a numbered heading of that file, a cited `vehicles.md A` a
section letter; (c) a paper key `[PN]` is a heading of references.md; (d) no path outside the repository
(the old spec folder), no paper cited by its old file number, no spec file name without `docs/spec/`;
(e) a cited `docs/contract/<file>.md` exists.
"""
from __future__ import annotations

import re
import subprocess
from functools import cache
from pathlib import Path

import pytest

from tests import repo

ROOT = repo.ROOT
SCANNED = ("bench", "plant", "testcases", "tests", "examples", "benchmarks", "scripts", "dbc", "docs",
           "README.md", "bench.toml")
SUFFIXES = {".py", ".md", ".dbc", ".toml", ".j2"}
SELF = Path(__file__).resolve().relative_to(ROOT).as_posix()   # its own examples of bad citations are data

SPEC_FILE = re.compile(r"docs/spec/([\w.-]+?\.md)")
CONTRACT_FILE = re.compile(r"docs/contract/([\w.-]+?\.md)")
# "docs/spec/formulas.md §2", "... `§2.1`", "... section 5", and the chain after it: "§2 and §3", "§2, §3"
SECTION = re.compile(r"docs/spec/([\w.-]+?\.md)`?\s?(?:§\s?|section )(\d+(?:\.\d+)?)"
                     r"((?:\s?(?:,|and|or|/|–|-)\s?§\s?\d+(?:\.\d+)?)*)")
CHAINED = re.compile(r"§\s?(\d+(?:\.\d+)?)")
LETTER = re.compile(r"docs/spec/(vehicles\.md)`?\s(?:section )?([A-Z])\b")
PAPER = re.compile(r"(?<![\w\]])\[P(\d+)\]")
# Forbidden: the spec folder outside the repository, the papers' old file numbers, spec names without a path.
OUTSIDE = re.compile(r"shared/spec")
OLD_PAPER = re.compile(r"\bseeds?\s?0\d\d\b", re.IGNORECASE)
BARE = re.compile(r"(?<![/\w-])(formulas|vehicles|k-matrix|architecture)\.md\b")
NUMBERED_HEADING = re.compile(r"^#+\s+§(\d+(?:\.\d+)?)\b", re.MULTILINE)
LETTER_HEADING = re.compile(r"^##\s+([A-Z])\.\s", re.MULTILINE)
PAPER_HEADING = re.compile(r"^##\s+\[P(\d+)\]", re.MULTILINE)


def scanned_files() -> list[str]:
    """Tracked text files of the scanned folders (git's list, so build output and reports are left out)."""
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--", *SCANNED], cwd=ROOT, capture_output=True,
                             check=True).stdout.decode()
        names = [n for n in out.split("\0") if n]
    except (OSError, subprocess.CalledProcessError):   # no git (an unpacked archive): walk the folders
        names = [p.relative_to(ROOT).as_posix() for s in SCANNED for p in
                 ([ROOT / s] if (ROOT / s).is_file() else sorted((ROOT / s).rglob("*"))) if p.is_file()]
    return [n for n in names if n != SELF and (Path(n).suffix in SUFFIXES or n.startswith("scripts/"))
            and (ROOT / n).is_file()]


@cache
def _doc(folder: str, name: str) -> str | None:
    path = ROOT / "docs" / folder / name
    return path.read_text(encoding="utf-8") if path.is_file() else None


def line_problems(line: str) -> list[str]:
    """What is wrong with the citations in one line of text (empty: nothing)."""
    found: list[str] = []
    for m in SPEC_FILE.finditer(line):
        if _doc("spec", m.group(1)) is None:
            found.append(f"{m.group(0)}: no such file")
    for m in CONTRACT_FILE.finditer(line):
        if (ROOT / "docs" / "contract").is_dir() and _doc("contract", m.group(1)) is None:
            found.append(f"{m.group(0)}: no such file")
    for m in SECTION.finditer(line):
        text = _doc("spec", m.group(1))
        if text is None:
            continue   # reported above
        have = set(NUMBERED_HEADING.findall(text))
        for number in [m.group(2), *CHAINED.findall(m.group(3))]:
            if number not in have:
                found.append(f"{m.group(0)}: docs/spec/{m.group(1)} has no heading §{number}")
    for m in LETTER.finditer(line):
        text = _doc("spec", m.group(1))
        if text is not None and m.group(2) not in LETTER_HEADING.findall(text):
            found.append(f"{m.group(0)}: docs/spec/{m.group(1)} has no section {m.group(2)}")
    papers = set(PAPER_HEADING.findall(_doc("spec", "references.md") or ""))
    for m in PAPER.finditer(line):
        if m.group(1) not in papers:
            found.append(f"{m.group(0)}: no such paper in docs/spec/references.md")
    for pattern, why in ((OUTSIDE, "points outside the repository (use docs/spec/...)"),
                         (OLD_PAPER, "cites a paper by its old file number (use [P0]..[P4])"),
                         (BARE, "spec file without its path (use docs/spec/...)")):
        found += [f"{m.group(0)}: {why}" for m in pattern.finditer(line)]
    return found


def test_spec_files_exist() -> None:
    """The index and the documents everything cites are there, with the numbered sections and keys."""
    for name in ("README.md", "formulas.md", "vehicles.md", "k-matrix.md", "references.md"):
        assert _doc("spec", name) is not None, f"docs/spec/{name} is missing"
    assert {"1", "2", "3", "4", "5", "6"} <= set(NUMBERED_HEADING.findall(_doc("spec", "formulas.md") or ""))
    assert {"A", "B"} <= set(LETTER_HEADING.findall(_doc("spec", "vehicles.md") or ""))
    assert set(PAPER_HEADING.findall(_doc("spec", "references.md") or "")) == {"0", "1", "2", "3", "4"}


def test_every_citation_resolves() -> None:
    files = scanned_files()
    assert len(files) > 50, f"only {len(files)} files found to scan: is this the repository root?"
    problems = []
    for name in files:
        try:
            text = (ROOT / name).read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue   # not text
        for number, line in enumerate(text.splitlines(), 1):
            problems += [f"{name}:{number}: {p}" for p in line_problems(line)]
    assert not problems, f"{len(problems)} citation(s) do not resolve:\n" + "\n".join(problems)


@pytest.mark.parametrize("line, expected", [
    ("see docs/spec/formulas.md §9 for it", "has no heading §9"),
    ("docs/spec/formulas.md §2 and §8", "has no heading §8"),
    ("docs/spec/formulas.md §2.7", "has no heading §2.7"),
    ("(clockwise seen from above, docs/spec/formulas.md section 7)", "has no heading §7"),
    ("docs/spec/vehicles.md D", "has no section D"),
    ("docs/spec/nothing.md", "no such file"),
    ("[P7] eq. 3", "no such paper"),
    ("the spec in ../shared/" + "spec/formulas.md", "points outside the repository"),
    ("Seed 0" + "03 §2", "old file number"),
    ("as formulas" + ".md §2 says", "spec file without its path"),
])
def test_a_broken_citation_is_reported(line: str, expected: str) -> None:
    """The checker catches each kind of broken citation (so a clean scan means something)."""
    assert any(expected in p for p in line_problems(line)), line_problems(line)


@pytest.mark.parametrize("line", [
    "docs/spec/formulas.md §2 (rotation about S), §3 and [P0] eq. 1-10",
    "`docs/spec/formulas.md` §1, docs/spec/formulas.md §5.3, docs/spec/vehicles.md B",
    "CM_ SG_ 256 X \"positive to the right (docs/spec/formulas.md section 1).\";",
    "test data in ../shared/corpus/dbc",
    "rng = random.Random(seed)",
])
def test_a_good_citation_passes(line: str) -> None:
    assert line_problems(line) == []
