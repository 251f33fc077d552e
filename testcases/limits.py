"""Acceptance limits of the campaigns: each campaign package keeps its own `limits.toml` (testcases/<campaign>/),
one table, every limit a { value, unit, source } so that a user can adapt them to a real ECU and the report cites
them. This loader is the one way every campaign reads them."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

#: name -> (value, unit, source)
LimitTable = dict[str, tuple[float, str, str]]


def limits_file(package_file: str) -> Path:
    """The limits.toml beside a campaign's module (pass its `__file__`)."""
    return Path(package_file).resolve().with_name("limits.toml")


def load_limits(path: Path, section: str) -> LimitTable:
    """name -> (value, unit, source) of one table of a limits file; ValueError naming file and key."""
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"{path}: cannot read the limits ({exc})") from None
    table = data.get(section)
    if not isinstance(table, dict):
        raise ValueError(f"{path}: no table [{section}]")
    out = {}
    for name, item in table.items():
        if not (isinstance(item, dict) and set(item) == {"value", "unit", "source"}
                and isinstance(item["value"], (int, float)) and not isinstance(item["value"], bool)
                and math.isfinite(item["value"])):
            raise ValueError(f"{path}: key '{section}.{name}' must be {{ value = <number>, unit, source }}")
        out[name] = (float(item["value"]), str(item["unit"]), str(item["source"]))
    return out


def limit_value(limits: LimitTable, name: str, path: Path, section: str) -> float:
    """The value of one limit; KeyError naming the file and the key when it is not there."""
    if name not in limits:
        raise KeyError(f"{path}: no limit '{section}.{name}'")
    return limits[name][0]
