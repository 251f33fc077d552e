"""Expectations and their tolerances; every check becomes a Step of the report and of the log."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from bench.results import Step

LOG_INFO, LOG_ERROR = 2, 4   # foxglove.Log levels


def within(measured: float, expected: float, abs_tol: float = 0.0, rel_tol: float = 0.0) -> bool:
    """|measured - expected| <= max(abs_tol, rel_tol * |expected|); NaN never passes."""
    if not (math.isfinite(measured) and math.isfinite(expected)):
        return False
    return abs(measured - expected) <= max(abs_tol, rel_tol * abs(expected))


def tolerance_text(abs_tol: float, rel_tol: float, unit: str = "") -> str:
    parts = []
    if abs_tol:
        parts.append(f"±{abs_tol:g}{(' ' + unit) if unit else ''}")
    if rel_tol:
        parts.append(f"±{rel_tol * 100:g} %")
    return " or ".join(parts) if parts else "exact"


def percentile(values: Sequence[float], q: float) -> float:
    """Percentile by linear interpolation (numpy's default), without needing numpy here."""
    if not values:
        return math.nan
    ordered = sorted(values)
    pos = (len(ordered) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(ordered) - 1)
    return ordered[lo] + (ordered[hi] - ordered[lo]) * (pos - lo)


class StepLog:
    """Collects the steps of one test case and forwards each to a listener (the MCAP log)."""

    def __init__(self, now: Callable[[], float], listener: Callable[[Step], None] | None = None) -> None:
        self.steps: list[Step] = []
        self._now = now
        self._listener = listener

    def record(self, name: str, passed: bool, measured: float | str | None, expected: float | str | None,
               tolerance: str = "", unit: str = "", detail: str = "", node: str = "") -> bool:
        step = Step(name=name, measured=measured, expected=expected, tolerance=tolerance,
                    verdict="pass" if passed else "fail", time=self._now(), unit=unit, detail=detail, node=node)
        self.steps.append(step)
        if self._listener is not None:
            self._listener(step)
        return passed
