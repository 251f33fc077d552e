"""The limits file of the test cases (testcases/limits.toml): one table per paper, every limit a
{ value, unit, source } so that a user can adapt them to a real ECU and the report cites them."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

LIMITS_FILE = Path(__file__).resolve().parent / "limits.toml"


def load_limits(section: str, path: Path = LIMITS_FILE) -> dict[str, tuple[float, str, str]]:
    """name -> (value, unit, source) of one table of limits.toml; ValueError naming file and key."""
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
