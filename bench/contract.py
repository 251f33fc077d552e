"""Requirement ids from contract documents: markdown whose level-3 headings start with an id.

The bench knows no vehicle; it learns which requirement ids exist from the documents that
bench.toml names (`[contract] documents`). A requirement is a heading
``### ECU-FLT-03 — Priority between faults``: the id, an em dash, a title. Headings inside
fenced code blocks are examples, not requirements. A level-3 heading that starts with an id but
lacks the " — title" part is an error (a typo there would otherwise drop the requirement silently).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from bench.errors import ConfigError

ID_PATTERN = r"[A-Z][A-Z0-9]*(?:-[A-Z0-9]+)*-[0-9]{2}"   # ASCII digits only (\d would take any script's)
ID_RE = re.compile(rf"{ID_PATTERN}\Z")
SEPARATOR = " — "
_HEADING = re.compile(r" {0,3}### +(?P<text>.*?)(?: +#+)? *\Z")       # CommonMark ATX, optional closing #s
_LEADING_ID = re.compile(rf"(?P<id>{ID_PATTERN})(?![A-Za-z0-9_-])(?P<rest>.*)\Z")
_FENCE = re.compile(r" {0,3}(?P<fence>`{3,}|~{3,})")


class ContractError(ConfigError):
    """A contract document that cannot be read or has a malformed or duplicate requirement."""


@dataclass(frozen=True)
class Requirement:
    id: str
    title: str
    path: Path
    line: int          # 1-based line of the heading


def is_requirement_id(text: str) -> bool:
    return bool(ID_RE.match(text))


def parse_requirements(text: str, path: Path) -> list[Requirement]:
    """The requirements of one document in the order they appear."""
    found: list[Requirement] = []
    fence = ""
    for number, line in enumerate(text.splitlines(), 1):
        opening = _FENCE.match(line)
        if fence:
            if opening and opening["fence"][0] == fence[0] and len(opening["fence"]) >= len(fence) \
                    and not line.strip().lstrip(fence[0]):
                fence = ""
            continue
        if opening:
            fence = opening["fence"]
            continue
        heading = _HEADING.match(line)
        if heading is None:
            continue
        lead = _LEADING_ID.match(heading["text"])
        if lead is None:
            continue
        rest = lead["rest"]
        title = rest[len(SEPARATOR):].strip() if rest.startswith(SEPARATOR) else ""
        if not title:
            raise ContractError(f"{path}:{number}: requirement heading must read "
                                f"'### {lead['id']}{SEPARATOR}<title>', got {line.strip()!r}")
        found.append(Requirement(lead["id"], title, path, number))
    return found


def load_requirements(paths: Iterable[Path]) -> dict[str, Requirement]:
    """Every requirement of the documents by id; an id defined twice is an error naming both places."""
    out: dict[str, Requirement] = {}
    for path in paths:
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as exc:
            raise ContractError(f"{path}: cannot read: {exc.strerror or exc}") from None
        except UnicodeDecodeError as exc:
            raise ContractError(f"{path}: not UTF-8 text (byte {exc.start})") from None
        for req in parse_requirements(text, Path(path)):
            first = out.get(req.id)
            if first is not None:
                raise ContractError(f"{req.path}:{req.line}: duplicate requirement id {req.id} "
                                    f"(first defined at {first.path}:{first.line})")
            out[req.id] = req
    return out


def owner_prefix(requirement_id: str) -> str:
    """The part of an id before its first dash: "ECU" for ECU-FLT-03, "MOTOR" for MOTOR-STS-01."""
    return requirement_id.split("-", 1)[0]


def node_prefix(node: str) -> str:
    """The part of a node name before its first underscore: "MOTOR" for MOTOR_FL, "ECU" for ECU.
    A requirement belongs to the nodes whose prefix equals its own (bench.report.conformance)."""
    return node.split("_", 1)[0]
