"""Expectations and their tolerances; every check becomes a Step of the report and of the log."""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence

import numpy as np

from bench.results.model import Step

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


_TOLERANCE = re.compile(r"±\s*([0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)?)\s*(%?)")
_SIGNIFICANT = 4        # digits of a number without a tolerance (a time, a table cell)
_MAX_DECIMALS = 12


def resolution(tolerance: str, expected: float | str | None = None) -> float | None:
    """The tolerance a step's text states, as an absolute amount: the larger of its `±X` and its `±Y %` of
    |expected| (as `within` judges); None when it states none ("exact", "range", "eventually", "")."""
    amounts = []
    for match in _TOLERANCE.finditer(tolerance):
        amount = float(match.group(1))
        if match.group(2):
            if not isinstance(expected, int | float) or not math.isfinite(expected):
                continue
            amount = amount / 100.0 * abs(expected)
        amounts.append(amount)
    best = max(amounts, default=0.0)
    return best if best > 0 and math.isfinite(best) else None


def format_value(value: float | int | str | None, tolerance: str = "", expected: float | str | None = None) -> str:
    """A measured or expected value as every report shows it (HTML, JUnit, console, the MCAP log's steps): with a
    tolerance, to one decimal place below the tolerance's first digit (±0.05: -4.886; ±2 % of 300: 301.2), so
    that a difference the check can see is seen and no more; an exact check in full (repr); otherwise 4
    significant digits. Integers and texts as they are; None as "–"."""
    if value is None or value == "":
        return "–"
    if isinstance(value, bool) or not isinstance(value, float):
        return str(value)
    if not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    tol = resolution(tolerance, expected if expected is not None else value)
    if tol is not None:
        decimals = min(_MAX_DECIMALS, max(0, 1 - math.floor(math.log10(tol))))
        text = f"{value:.{decimals}f}"
    elif tolerance == "exact":
        text = repr(value)
    else:
        text = f"{value:.{_SIGNIFICANT}g}"
    return text[1:] if text.startswith("-") and not text.strip("-0.") else text   # no "-0.000"


def step_values(step: Step) -> tuple[str, str]:
    """(measured, expected) of a step, formatted by `format_value` with the step's tolerance."""
    return (format_value(step.measured, step.tolerance, step.expected),
            format_value(step.expected, step.tolerance, step.expected))


def percentile(values: Sequence[float], q: float) -> float:
    """The q-th percentile by linear interpolation between order statistics: numpy's, the bench's one percentile
    (bench.checks.timing's histograms use it too); NaN of no values."""
    if not len(values):
        return math.nan
    return float(np.percentile(values, q))


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
