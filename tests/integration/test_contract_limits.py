"""Every acceptance limit of the SBW and ABS cases is written in their contract (issue 26, acceptance 5).

Why: a supplier builds an ECU from docs/ and the DBCs only. The cases read their limits from their campaign's
limits file (testcases/sbw/limits.toml [sbw], testcases/abs/limits.toml [abs]); the contract must state the same
numbers, each in the requirement it belongs to, or a supplier meets limits nobody told him (issue 26: sbw.md and
abs.md pointed to the limits file instead).

What is checked:
- each limit `name` of a campaign appears in its contract document as `<section>.<name>` (the name the report
  prints next to each measured value) inside a requirement (a `### ID — title` section), and every place that
  names it states its value: in a table row the cell after the name, elsewhere the line, must hold a number
  equal to the value (compared as floats; "2 %" is 0.02; 1.2·10⁻⁴ is 0.00012) followed by the limit's unit;
- no contract document (docs/contract/*.md) names the limits file, or testcases/ in a sentence about a limit,
  as the place where a limit is stated.
The checker is tried on the real documents with a value deleted and changed, so a pass means something.
"""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path

import pytest

from tests.repo import ROOT

#: limits section -> (limits file, contract document)
CAMPAIGNS = {
    "sbw": (ROOT / "testcases" / "sbw" / "limits.toml", ROOT / "docs" / "contract" / "sbw.md"),
    "abs": (ROOT / "testcases" / "abs" / "limits.toml", ROOT / "docs" / "contract" / "abs.md"),
}
CONTRACT = ROOT / "docs" / "contract"

#: a limit's unit in the limits file -> how the documents may write it right after the number
UNITS = {
    "km/h": ("km/h",),
    "m/s^2": ("m/s²", "m/s^2"),
    "deg": ("°", "deg"),
    "deg/s": ("deg/s", "°/s"),
    "s": ("s",),
    "N*m": ("N·m", "N*m", "Nm"),
    "1/s": ("1/s",),
    "bar": ("bar",),
    "1": (),
}
_SUPERSCRIPT = str.maketrans("⁻⁺⁰¹²³⁴⁵⁶⁷⁸⁹", "-+0123456789")
NUMBER = re.compile(r"(?<![\w.·])([-+−]?\d+(?:\.\d+)?)(?:\s?·\s?10([⁻⁺]?[⁰¹²³⁴⁵⁶⁷⁸⁹]+))?")
HEADING = re.compile(r"^(#{1,3})\s")
REQUIREMENT = re.compile(r"^###\s+([A-Z][A-Z0-9]*(?:-[A-Z0-9]+)*-\d{2})\s+—\s")


def load(path: Path, section: str) -> dict[str, tuple[float, str]]:
    """name -> (value, unit) of one table of a limits file."""
    table = tomllib.loads(path.read_text(encoding="utf-8"))[section]
    return {name: (float(item["value"]), str(item["unit"])) for name, item in table.items()}


def numbers(text: str) -> list[tuple[float, str]]:
    """(value, the text right after it) of every number in `text`; "n %" gives n / 100."""
    found = []
    for m in NUMBER.finditer(text):
        value = float(m.group(1).replace("−", "-"))
        if m.group(2):
            value *= 10.0 ** int(m.group(2).translate(_SUPERSCRIPT))
        after = text[m.end():].lstrip(" \u00a0")
        if after.startswith("%"):
            found.append((value / 100.0, after[1:]))
        found.append((value, after))
    return found


def states(text: str, value: float, unit: str) -> bool:
    """Does `text` hold `value` followed by `unit` (any spelling of UNITS)?"""
    spellings = UNITS.get(unit)
    if spellings is None:
        raise ValueError(f"unit {unit!r} unknown to this test: add its spellings to UNITS")
    for number, after in numbers(text):
        if not math.isclose(number, value, rel_tol=1e-9, abs_tol=1e-12):
            continue
        if not spellings:
            return True
        for spelling in spellings:
            if after.startswith(spelling) and not (spelling[-1].isalpha() and after[len(spelling):][:1].isalpha()):
                return True
    return False


def cells(line: str) -> list[str]:
    """The cells of a markdown table row (an escaped `\\|` stays inside its cell)."""
    parts = re.split(r"(?<!\\)\|", line.strip())
    return [p.strip() for p in parts[1:-1]] if len(parts) > 2 else []


def requirement_of_each_line(text: str) -> list[str | None]:
    """For every line, the id of the requirement it belongs to (None outside any)."""
    out: list[str | None] = []
    current = None
    for line in text.splitlines():
        if HEADING.match(line):
            req = REQUIREMENT.match(line)
            current = req.group(1) if req else None
        out.append(current)
    return out


def problems(text: str, limits: dict[str, tuple[float, str]], section: str, where: str = "") -> list[str]:
    """What the document `text` gets wrong about the limits (empty: every one stated right)."""
    lines = text.splitlines()
    owners = requirement_of_each_line(text)
    found = []
    for name, (value, unit) in limits.items():
        key = f"`{section}.{name}`"
        shown = f"{value:g} {'' if unit == '1' else unit}".strip()
        places = [i for i, line in enumerate(lines) if key in line]
        if not places:
            found.append(f"{where}{section}.{name} = {shown}: not in the document")
            continue
        if not any(owners[i] for i in places):
            found.append(f"{where}{section}.{name}: named only outside a requirement (line {places[0] + 1})")
        for i in places:
            row = cells(lines[i])
            holder = next((c for c, cell in enumerate(row) if key in cell), None)
            text_to_check = row[holder + 1] if holder is not None and holder + 1 < len(row) else lines[i]
            if not states(text_to_check, value, unit):
                found.append(f"{where}line {i + 1}: {section}.{name} is {shown}, the document says "
                             f"{text_to_check.strip()!r}")
    return found


@pytest.mark.parametrize("section", sorted(CAMPAIGNS))
def test_every_limit_is_stated_in_its_requirement(section: str) -> None:
    limits_path, document = CAMPAIGNS[section]
    limits = load(limits_path, section)
    assert len(limits) > 10, f"{limits_path}: too few limits read ({len(limits)})"
    found = problems(document.read_text(encoding="utf-8"), limits, section, f"{document.relative_to(ROOT)}: ")
    assert not found, f"{len(found)} limit(s) of {limits_path.relative_to(ROOT)} not stated right:\n" + "\n".join(found)


def _first_row(text: str, section: str) -> tuple[str, str]:
    """The first limits-table row of the document and the name it states."""
    for line in text.splitlines():
        m = re.match(rf"\|\s*`{section}\.(\w+)`\s*\|", line)
        if m:
            return line, m.group(1)
    raise AssertionError(f"no limits table row of [{section}] found")


@pytest.mark.parametrize("section", sorted(CAMPAIGNS))
def test_a_missing_or_wrong_value_is_reported(section: str) -> None:
    """The checker on the real document with one value deleted, then changed: each is reported."""
    limits_path, document = CAMPAIGNS[section]
    limits = load(limits_path, section)
    text = document.read_text(encoding="utf-8")
    row, name = _first_row(text, section)
    value_cell = cells(row)[1]
    deleted = text.replace(row, row.replace(value_cell, "", 1), 1)
    assert any(f"{section}.{name} is" in p for p in problems(deleted, limits, section)), name
    changed = text.replace(row, row.replace(value_cell, value_cell.replace(value_cell.split()[0], "123.4", 1), 1), 1)
    assert any(f"{section}.{name} is" in p for p in problems(changed, limits, section)), name
    gone = "\n".join(line for line in text.splitlines() if f"`{section}.{name}`" not in line)
    assert any("not in the document" in p for p in problems(gone, limits, section)), name


@pytest.mark.parametrize("text, value, unit, expected", [
    ("| `abs.x` | 0.16 km/h | mean |", 0.16, "km/h", True),
    ("0.30", 0.3, "1", True),
    ("0.99 (99 %)", 0.99, "1", True),
    ("within ±2 % of", 0.02, "1", True),
    ("1.2·10⁻⁴ kg·m²", 1.2e-4, "1", True),
    ("0.5°", 0.5, "deg", True),
    ("0.1 deg/s", 0.1, "deg/s", True),
    ("0.05 s", 0.05, "s", True),
    ("0.05 sbw", 0.05, "s", False),
    ("0.5 km/h", 0.5, "deg", False),
    ("`abs.ecu_v_l0` is", 0.0, "1", False),
    ("3.0 m/s²", 3.0, "m/s^2", True),
    ("0.025 N·m", 0.025, "N*m", True),
])
def test_numbers_are_compared_as_numbers_with_their_unit(text: str, value: float, unit: str, expected: bool) -> None:
    assert states(text, value, unit) is expected


# -- no contract document sends a reader to testcases/ for a limit ----------------------------------------------

def sentences(text: str) -> list[tuple[int, str]]:
    """(first line, sentence) of every sentence of the document's paragraphs (a table row is one sentence)."""
    out: list[tuple[int, str]] = []
    paragraph: list[str] = []
    start = 0
    for number, line in enumerate(text.splitlines() + [""], 1):
        if not line.strip() or line.lstrip().startswith(("|", "#", "```")):
            if paragraph:
                out += [(start, s) for s in re.split(r"(?<=[.;])\s+", " ".join(paragraph)) if s]
                paragraph = []
            if line.strip():
                out.append((number, line))
            continue
        if not paragraph:
            start = number
        paragraph.append(line.strip())
    return out


def source_problems(text: str) -> list[str]:
    """Sentences that name the limits file, or testcases/ together with a limit."""
    found = []
    for number, sentence in sentences(text):
        if "limits.toml" in sentence or ("testcases/" in sentence and re.search(r"\blimit", sentence, re.I)):
            found.append(f"line {number}: {sentence[:160]}")
    return found


def test_no_contract_document_points_to_testcases_for_a_limit() -> None:
    documents = sorted(CONTRACT.glob("*.md"))
    assert len(documents) >= 5
    found = [f"{d.relative_to(ROOT)}: {p}" for d in documents for p in source_problems(d.read_text(encoding="utf-8"))]
    assert not found, "contract documents that send the reader to testcases/ for a limit:\n" + "\n".join(found)


@pytest.mark.parametrize("text, bad", [
    ("The limits below are those of\n`testcases/sbw/limits.toml` `[sbw]`, which cites each one's source.", True),
    ("See the limits file limits.toml.", True),
    ("Derived values (the cases compute them, `testcases/x/oracle.py`).", False),
    ("Each case in `testcases/` says which node it judges. The limits are in each requirement.", False),
])
def test_a_pointer_to_testcases_for_a_limit_is_found(text: str, bad: bool) -> None:
    assert bool(source_problems(text)) is bad
