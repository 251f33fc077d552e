"""Warnings of the bench and the plant become findings of the run's report.

The bench logs through the standard `logging` module (a logger per module, under "bench." and "plant.").
Something that goes wrong without stopping the run (a frame the driver could not send, the kernel's periodic
sending given up for the restbus's own) is a warning record; while a run has a report, `FindingCollector`
takes every such record of those loggers and the report lists it, so a silent failure is never silent.
Records of one message are counted, not repeated: a full send queue may fail thousands of frames.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from bench.results.model import Finding

#: The loggers whose warnings are findings: the bench's own and its plant's.
SOURCES = ("bench", "plant")
#: Distinct findings kept per run; further ones are counted in the last (a runaway cannot bloat the report).
MAX_FINDINGS = 200


class FindingCollector(logging.Handler):
    """A logging handler that keeps WARNING and worse of `SOURCES` as findings, with the bench time of the
    first occurrence (`now`, when the run has a clock yet) and how often the same message came."""

    def __init__(self, now: Callable[[], float | None] | None = None) -> None:
        super().__init__(logging.WARNING)
        self.now = now
        self.findings: list[Finding] = []
        self._by_key: dict[tuple[str, str], Finding] = {}
        self._attached: list[logging.Logger] = []

    def emit(self, record: logging.LogRecord) -> None:
        try:
            message = record.getMessage()
        except Exception:   # a bad format string in a log call must not break the run
            message = str(record.msg)
        key = (record.name, message)
        same = self._by_key.get(key)
        if same is not None:
            same.count += 1
            return
        if len(self.findings) >= MAX_FINDINGS:
            self.findings[-1].count += 1
            return
        try:
            t = self.now() if self.now is not None else None
        except Exception:   # the clock may be gone at the end of a run
            t = None
        finding = Finding(source=record.name, level=record.levelname.lower(), message=message, time=t)
        self._by_key[key] = finding
        self.findings.append(finding)

    def attach(self) -> FindingCollector:
        """Collect from now on (the loggers pass at least WARNING: a quieter default would hide the findings)."""
        for name in SOURCES:
            logger = logging.getLogger(name)
            if logger.getEffectiveLevel() > logging.WARNING:
                logger.setLevel(logging.WARNING)
            logger.addHandler(self)
            self._attached.append(logger)
        return self

    def detach(self) -> list[Finding]:
        """Stop collecting; the findings so far."""
        for logger in self._attached:
            logger.removeHandler(self)
        self._attached.clear()
        return self.findings
