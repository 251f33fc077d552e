"""A reference ECU's link to its diagnostic side (the bench's UDS server and fault memory for the node).

The bench builds the diagnostic side from the project's declaration (dbc/diagnostics.toml); what only the ECU
knows it feeds here: each step the fault code it sends (the DTC of the same name failed, every other passed, as
docs/contract/diagnostics.md says), and once, where its live values come from and what its routines and an
ECUReset do.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from enum import IntEnum

from bench.sim.node import DiagnosticSide, NodeIO

#: s at the start of an operation cycle (power-up, ECUReset) in which the monitors give no result: the first frames
#: of the node's inputs are still on their way (docs/contract/diagnostics.md DIAG-OPC-01)
STARTUP_WINDOW = 0.1

Setup = Callable[[DiagnosticSide, NodeIO], None]


class EcuDiagnostics:
    """Feeds one node's fault code to its diagnostic side; a no-op when the project declares none."""

    def __init__(self, node: str, faults: type[IntEnum], setup: Setup | None = None) -> None:
        self.node = node
        # fault code on the bus -> the DTC names that failed (OK: none)
        self._failed: Mapping[int, tuple[str, ...]] = {int(f): (() if int(f) == 0 else (f.name,)) for f in faults}
        self._setup = setup
        self._side: DiagnosticSide | None = None
        self._looked = False
        self._results_from = STARTUP_WINDOW     # power-up at bench time 0

    def side(self, io: NodeIO) -> DiagnosticSide | None:
        """The node's diagnostic side, looked up once (the first step) and set up then."""
        if not self._looked:
            self._looked = True
            side = self._side = io.diagnostics(self.node)
            if side is not None:
                side.on_reset(lambda: self._cycle_starts(io))
                if self._setup is not None:
                    self._setup(side, io)
        return self._side

    def _cycle_starts(self, io: NodeIO) -> None:
        self._results_from = io.now + STARTUP_WINDOW

    def report(self, io: NodeIO, t: float, code: int) -> None:
        """The node's monitors ran at t and found `code` (the fault code it sends, 0 OK)."""
        side = self._side if self._looked else self.side(io)
        if side is not None and t >= self._results_from:
            side.report(t, *self._failed[code])
