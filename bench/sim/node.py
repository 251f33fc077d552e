"""What a simulated node's behaviour sees of the bus, and what it must provide.

A behaviour (a plant model or a reference ECU) plays one or more DBC nodes. The restbus sends the
messages of those nodes at their DBC cycle times with whatever values the behaviour last set,
so a behaviour never deals with frames, counters or checksums.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol, runtime_checkable


class DiagnosticSide(Protocol):
    """The diagnostic side of a simulated node (UDS server and fault memory, bench.diag.server), built by the bench
    from the project's diagnostic declaration. The behaviour feeds it what only the ECU knows: its monitors'
    results, its live values, its coding and routines."""

    def report(self, t: float, *failed: str) -> None:
        """The node's fault monitors ran at bench time t: the DTCs named (by DTC name) failed, all others passed.
        Cheap when nothing changed: call it every step."""

    def provide(self, name: str, source: Callable[[], float | str]) -> None:
        """Where a DID's value comes from (by DID name): read on ReadDataByIdentifier and into snapshots."""

    def coding(self, name: str) -> float:
        """A coding DID's current value (its default until a tester writes it)."""

    def on_routine(self, name: str, start: Callable[[], None]) -> None:
        """Called when a tester starts the routine."""

    def on_reset(self, callback: Callable[[], None]) -> None:
        """Called when an ECUReset takes effect (the node starts again as after power-up; coding and fault memory
        are kept)."""


class NodeIO(Protocol):
    """The bus as a behaviour sees it."""

    @property
    def now(self) -> float:
        """Bench time, s."""

    def send_values(self, message: str, **signals: float) -> None:
        """Set signal values of a message this node sends; sent from its next cycle on.
        Enumerations may be given by their value-table name or number."""

    def reset_outputs(self) -> None:
        """Every message this station sends back to its DBC start values (a plant switching vehicle)."""

    def stop_sending(self, message: str) -> None:
        """Stop sending a message of this station until `resume_sending` (a plant whose vehicle has no such
        ECU or signal stops it: the bus then carries what that vehicle's network carries). A message this
        station does not send (its node is external) is left alone. The same verb pair as the restbus's and
        the `bench` fixture's."""

    def resume_sending(self, message: str) -> None:
        """Send a message of this station again after `stop_sending` (left alone when its node is external)."""

    def latest(self, message: str) -> Mapping[str, float] | None:
        """The latest valid values of a message (enumerations as numbers); None when never
        received or timed out (3 x cycle time)."""

    def timed_out(self, message: str) -> bool:
        """True when the message was never received or not for 3 x its cycle time."""

    def invalid(self, message: str) -> bool:
        """True when the last frame of the message failed an end-to-end, length or range check."""

    def diagnostics(self, node: str) -> DiagnosticSide | None:
        """The diagnostic side the bench simulates for `node` (one this station plays); None when the project
        declares no diagnostics for it."""


@runtime_checkable
class Behaviour(Protocol):
    """A model that plays DBC nodes. `step` is called every plant tick (1 ms or finer)."""

    nodes: tuple[str, ...]

    def reset(self) -> None:
        """Back to the initial state (called when a test case starts a new scenario)."""

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        """Advance by dt to bench time t; read inputs with io.latest, write outputs with io.send_values."""
