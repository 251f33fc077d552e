"""The plant's entry point (`bench.plants: chassis = plant.factory:build`), with what the bench may ask of it.

The bench asks for the plant once; the plant then becomes whichever vehicle `BENCH_Control.Vehicle`
asks for (a test campaign mixes vehicles), through a host behaviour that builds that vehicle's
behaviours (its declaration, plant/registry.py) and steps them in their order. `stimulus(vehicle)` answers
`bench.plugins.plant_stimulus`: which stimulus messages a scenario of that vehicle sends.
"""

from __future__ import annotations

import logging
from collections.abc import Collection

from bench.sim.node import Behaviour, NodeIO
from plant import registry

log = logging.getLogger(__name__)

DEFAULT_VEHICLE = "EV4WIS"
CONTROL = "BENCH_Control"     # its signal Vehicle selects the vehicle (dbc/bench.dbc)


def assemble(vehicle: str, external: Collection[str]) -> list[Behaviour]:
    """The behaviours of one vehicle; ValueError naming the vehicle when there is no such plant."""
    return registry.vehicle(vehicle).build(frozenset(external))


def messages_of(vehicle: str) -> frozenset[str]:
    """The plant-side messages the vehicle's network carries (its declaration's messages)."""
    return registry.vehicle(vehicle).messages


def io_of(vehicle: str) -> dict[str, frozenset[str]]:
    """The vehicle's bench I/O: {ECU node: its IO_* messages}, on the bus only while that node is external."""
    return dict(registry.vehicle(vehicle).io)


def stimulus(vehicle: str) -> tuple[str, ...]:
    """The stimulus messages the vehicle's behaviours read: what a scenario of it sends besides BENCH_Control."""
    return registry.vehicle(vehicle).stimulus


def vehicles() -> tuple[str, ...]:
    """The names of every declared vehicle (the BENCH_Control.Vehicle values this plant can be)."""
    return tuple(registry.vehicles())


class PlantHost:
    """Plays the plant's nodes as the vehicle BENCH_Control.Vehicle names (default at start)."""

    def __init__(self, external: Collection[str], vehicle: str) -> None:
        self.external = frozenset(external)
        declaration = registry.vehicle(vehicle)
        self.vehicle = declaration.name
        self._code = declaration.code       # BENCH_Control.Vehicle of self.vehicle (most ticks ask for it again)
        self.inner = assemble(self.vehicle, self.external)
        self.nodes = tuple(dict.fromkeys(n for b in self.inner for n in b.nodes))
        self.unavailable: int | None = None   # the code of a vehicle asked for that has no plant
        self._network: str | None = None   # the vehicle whose network the bus carries (None: not set yet)

    def reset(self) -> None:
        for behaviour in self.inner:
            behaviour.reset()

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        control = io.latest(CONTROL)
        if control is not None and (code := int(control["Vehicle"])) != self._code:
            wanted = registry.by_code(code)
            if wanted is not None and wanted.name != self.vehicle:
                self.vehicle, self._code = wanted.name, wanted.code
                self.inner = wanted.build(self.external)
                io.reset_outputs()          # nothing of the previous vehicle stays on the bus
            if wanted is None and self.unavailable != code:
                log.warning("BENCH_Control.Vehicle = %d names no declared vehicle (%s): the plant stays %s",
                            code, ", ".join(vehicles()), self.vehicle)
            self.unavailable = code if wanted is None else None
        elif control is not None:
            self.unavailable = None
        if self._network != self.vehicle:
            self._set_network(io)
        for behaviour in self.inner:
            behaviour.step(io, t, dt)

    def _set_network(self, io: NodeIO) -> None:
        """Send the messages of this vehicle's network, and none of the other vehicles' (a 4WIS EV has no
        SBW ECU: its bus carries no SBW frames). A bench I/O message (`Vehicle.io`) is sent only while its ECU is
        external: stopped otherwise (a simulated ECU keeps its direct wires), and on every other vehicle.
        Messages no vehicle claims are left as they are."""
        mine = set(messages_of(self.vehicle))
        for node, messages in io_of(self.vehicle).items():
            if node in self.external:
                mine.update(messages)
        declared = registry.vehicles().values()
        claimed = frozenset().union(*(v.messages for v in declared), *(m for v in declared for m in v.io.values()))
        for message in claimed - mine:
            io.stop_sending(message)
        for message in mine:
            io.resume_sending(message)
        self._network = self.vehicle


def build(external: Collection[str] = (), vehicle: str | None = None) -> list[Behaviour]:
    """The signature of the entry-point group bench.plants (bench/plugins.py): every plant node not
    in `external`, starting as `vehicle` (None: DEFAULT_VEHICLE)."""
    return [PlantHost(external, vehicle or DEFAULT_VEHICLE)]
