"""A bus-less NodeIO for unit tests and benchmarks of behaviours (ECU models, plant models).

Why in the package: an engineer who writes a behaviour wants to step it tick by tick without a bus, a codec
or a clock, and to be told at once when it sends a NaN or a value outside its signal's range. One double,
here, instead of one per test file.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

from bench.sim.node import DiagnosticSide

#: (message, signal) -> (minimum, maximum) of the signal's range
Bounds = Mapping[tuple[str, str], tuple[float, float]]


class MemoryIO:
    """The bus reduced to a dict of the latest values of each message (bench.sim.node.NodeIO).

    `values` is what the behaviours read (set a stimulus by assigning `values[message] = {...}`); `sent` holds
    the latest values each message was sent with. With `loopback` (the default) a sent message is also read
    back by every behaviour, as on a bus where all nodes share one process; without it, only what the test
    puts in `values` is read. With `bounds`, every value sent must be finite and inside its signal's range
    (ValueError naming message, signal and value); without, nothing is checked (the cheapest double, for
    benchmarks). `silenced` messages read as timed out; `invalid_set` messages read as invalid.
    """

    def __init__(self, bounds: Bounds | None = None, *, loopback: bool = True) -> None:
        self.t = 0.0
        self.bounds = bounds
        self.loopback = loopback
        self.values: dict[str, dict[str, float]] = {}
        self.sent: dict[str, dict[str, float]] = {}
        self.silenced: set[str] = set()
        self.invalid_set: set[str] = set()
        self.stopped: set[str] = set()
        #: the diagnostic side of each node (a test puts a bench.diag.server.UdsServer here); none by default
        self.diagnostic_sides: dict[str, DiagnosticSide] = {}

    @property
    def now(self) -> float:
        return self.t

    def send_values(self, message: str, **signals: float) -> None:
        if self.bounds is not None:
            for name, value in signals.items():
                if not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise ValueError(f"{message}.{name} = {value!r}: not a finite number")
                low, high = self.bounds.get((message, name), (-math.inf, math.inf))
                if not low <= value <= high:
                    raise ValueError(f"{message}.{name} = {value}: outside its range [{low}, {high}]")
        self.sent.setdefault(message, {}).update(signals)
        if self.loopback and message not in self.stopped:
            self.values.setdefault(message, {}).update(signals)

    def reset_outputs(self) -> None:
        self.sent.clear()

    def stop_sending(self, message: str) -> None:
        self.stopped.add(message)

    def resume_sending(self, message: str) -> None:
        self.stopped.discard(message)

    def latest(self, message: str) -> Mapping[str, float] | None:
        return None if message in self.silenced else self.values.get(message)

    def timed_out(self, message: str) -> bool:
        return self.latest(message) is None

    def invalid(self, message: str) -> bool:
        return message in self.invalid_set

    def diagnostics(self, node: str) -> DiagnosticSide | None:
        return self.diagnostic_sides.get(node)


class CodedSide:
    """A diagnostic side reduced to its coding (bench.sim.node.DiagnosticSide), for a behaviour stepped on a
    MemoryIO: `MemoryIO.diagnostic_sides[node] = CodedSide({"SomeCoding": 1})`. Reports, providers, routines and
    resets are taken and forgotten; `failed` keeps the DTC names of the latest report."""

    def __init__(self, coding: Mapping[str, float]) -> None:
        self.values = dict(coding)
        self.failed: tuple[str, ...] = ()

    def report(self, t: float, *failed: str) -> None:
        self.failed = failed

    def provide(self, name: str, source: Callable[[], float | str]) -> None:
        pass

    def coding(self, name: str) -> float:
        return self.values[name]

    def on_routine(self, name: str, start: Callable[[], None]) -> None:
        pass

    def on_reset(self, callback: Callable[[], None]) -> None:
        pass
