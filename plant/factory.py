"""The plant's entry point (`bench.plants: chassis = plant.factory:build`).

The bench asks for the plant once; the plant then becomes whichever vehicle `BENCH_Control.Vehicle`
asks for (a test campaign mixes vehicles), through a host behaviour that builds that vehicle's
behaviours (plant/assemblies/) and steps them in their order.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Collection
from types import ModuleType

from bench.node import Behaviour, NodeIO
from plant.vehicles import VEHICLE_CODES

DEFAULT_VEHICLE = "EV4WIS"

#: vehicle name (BENCH_Control.Vehicle value table) -> module in plant/assemblies with build(external)
ASSEMBLIES = {"EV4WIS": "plant.assemblies.ev4wis",
              "ACLASS_ABS": "plant.assemblies.aclass_abs",
              "ACLASS": "plant.assemblies.aclass",
              }

_BY_CODE = {code: name for name, code in VEHICLE_CODES.items()}


def _assembly(vehicle: str) -> ModuleType:
    module = ASSEMBLIES.get(vehicle.upper())
    if module is None:
        raise ValueError(f"no plant for vehicle {vehicle!r} (available: {', '.join(sorted(ASSEMBLIES))})")
    return importlib.import_module(module)


def assemble(vehicle: str, external: Collection[str]) -> list[Behaviour]:
    """The behaviours of one vehicle; ValueError naming the vehicle when there is no such plant."""
    builder: Callable[[Collection[str]], list[Behaviour]] = _assembly(vehicle).build
    return builder(frozenset(external))


def messages_of(vehicle: str) -> frozenset[str]:
    """The plant-side messages the vehicle's network carries (its assembly's MESSAGES)."""
    return _assembly(vehicle).MESSAGES


class PlantHost:
    """Plays the plant's nodes as the vehicle BENCH_Control.Vehicle names (default at start)."""

    def __init__(self, external: Collection[str], vehicle: str) -> None:
        self.external = frozenset(external)
        self.vehicle = vehicle.upper()
        self.inner = assemble(self.vehicle, self.external)
        self.nodes = tuple(dict.fromkeys(n for b in self.inner for n in b.nodes))
        self.unavailable: str | None = None   # a vehicle asked for that has no plant
        self._network: str | None = None   # the vehicle whose network the bus carries (None: not set yet)

    def reset(self) -> None:
        for behaviour in self.inner:
            behaviour.reset()

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        control = io.latest("BENCH_Control")
        if control is not None:
            wanted = _BY_CODE.get(int(control["Vehicle"]))
            if wanted is not None and wanted != self.vehicle and wanted in ASSEMBLIES:
                self.vehicle = wanted
                self.inner = assemble(wanted, self.external)
                io.reset_outputs()          # nothing of the previous vehicle stays on the bus
            self.unavailable = wanted if wanted not in ASSEMBLIES else None
        if self._network != self.vehicle:
            self._set_network(io)
        for behaviour in self.inner:
            behaviour.step(io, t, dt)

    def _set_network(self, io: NodeIO) -> None:
        """Send the messages of this vehicle's network, and none of the other vehicles' (a 4WIS EV has no
        SBW ECU: its bus carries no SBW frames). Messages no vehicle claims are left as they are."""
        mine = messages_of(self.vehicle)
        others = frozenset().union(*(messages_of(vehicle) for vehicle in ASSEMBLIES)) - mine
        for message in others:
            io.stop_sending(message)
        for message in mine:
            io.resume_sending(message)
        self._network = self.vehicle


def build(external: Collection[str] = (), vehicle: str | None = None) -> list[Behaviour]:
    """The signature of the entry-point group bench.plants (bench/plugins.py): every plant node not
    in `external`, starting as `vehicle` (None: DEFAULT_VEHICLE)."""
    return [PlantHost(external, vehicle or DEFAULT_VEHICLE)]
