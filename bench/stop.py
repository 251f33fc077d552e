"""Stopping a run on SIGINT or SIGTERM within a second, whatever it is doing, with an ABORTED report.

While the cases run, either signal raises KeyboardInterrupt in the main thread: pytest ends the session as
interrupted, and the run closes its bus and log and writes its report marked ABORTED (bench.run.BenchRun.finish).
While the run finishes (`finishing`: closing the bus and the log, writing the reports), a signal raises nothing
(an exception there would cost the report, issue 27: Ctrl-C in the finishing phase left no report.html); it
marks the run aborted and starts the report's time budget: from then on the report leaves out the plots it has
not drawn yet (`keep_drawing`), the slow part of a large run's report (1.2-1.9 s of the 147-case campaign's
2.2 s), so that the process ends within a second of the signal.

Handlers are installed only over the defaults (Python's SIGINT handler, SIGTERM's default action): a program
that embeds the bench and set its own keeps it.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: s from the signal during which the report still starts drawing a case's plots. Measured on a run stopped as it
#: began its report (tests/integration/test_stop_signals.py): the case being drawn when the budget ends, then the
#: HTML without the remaining plots, JUnit, results.json without plot data and the interpreter's exit take about
#: 0.5 s more, so the process ends within a second of the signal.
DRAW_BUDGET = 0.25


class StopRequests:
    """The process's SIGINT/SIGTERM handling for a bench run (one per process: `STOP`)."""

    def __init__(self) -> None:
        self.signum: int | None = None     # the first stop signal received
        self.at: float | None = None       # time.monotonic() when it came
        self._finishing = 0
        self._helpers: list[int] = []      # processes that get the signal too (pytest-xdist's workers)

    @property
    def requested(self) -> bool:
        return self.signum is not None

    def install(self) -> None:
        """Our handler for SIGINT and SIGTERM where each still has its default (main thread only)."""
        if threading.current_thread() is not threading.main_thread():
            return
        for signum in SIGNALS:
            current = signal.getsignal(signum)
            if current in (signal.SIG_DFL, signal.default_int_handler, None) or current == self._handle:
                signal.signal(signum, self._handle)

    def forward_to(self, pid: int) -> None:
        """Send every stop signal on to this process too (a pytest-xdist worker: a signal to the controller
        alone left each worker in its case until xdist's shutdown ended it, 5 s after SIGTERM)."""
        self._helpers.append(pid)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is None:
            self.signum, self.at = signum, time.monotonic()
            for pid in self._helpers:
                try:
                    os.kill(pid, signum)
                except OSError:    # it ended already
                    pass
        if not self._finishing:
            raise KeyboardInterrupt(f"signal {signal.Signals(signum).name}")

    @contextmanager
    def finishing(self) -> Iterator[None]:
        """A stop signal in here marks the run aborted instead of raising (the report is being written)."""
        self._finishing += 1
        try:
            yield
        finally:
            self._finishing -= 1

    def exit_code(self) -> int:
        """A stopped run's exit code, by the shell's convention for a process a signal ended: 128 + the signal's
        number (SIGINT 130, SIGTERM 143); 130 when no signal came (a KeyboardInterrupt raised otherwise)."""
        return 128 + int(self.signum if self.signum is not None else signal.SIGINT)

    def keep_drawing(self) -> bool:
        """Whether the report may still draw plots: no stop signal, or one less than DRAW_BUDGET s ago."""
        return self.at is None or time.monotonic() - self.at < DRAW_BUDGET

    def reset(self) -> None:
        """Forget a received signal and the helpers (a process that runs the bench again, e.g. a test)."""
        self.signum = self.at = None
        self._helpers.clear()


STOP = StopRequests()
