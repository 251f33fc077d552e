"""What declares a vehicle: one `Vehicle` object, `VEHICLE` in a module of plant/assemblies/.

Why one object: the plant's factory, the registry of vehicles, the network a vehicle's bus carries and the
stimulus a scenario of it sends are all derived from it (plant/registry.py), so adding a vehicle is one module
with its parameter file, plus its name and code in the DBC's value table of BENCH_Control.Vehicle and
PLANT_Status.Vehicle (tests/integration/test_dbc_contract.py checks that the declarations and the tables agree).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from bench.sim.node import Behaviour
from plant.vehicles import ParameterFile


@dataclass(frozen=True)
class Vehicle:
    """One vehicle the plant can be.

    name: its entry in the value table of BENCH_Control.Vehicle / PLANT_Status.Vehicle, the name a scenario
        selects it by (`start_scenario(Vehicle=name)`); code: that entry's value.
    build: `build(external) -> [Behaviour]`, the behaviours of its nodes not in `external`, in step order.
    parameters: the parameter files its behaviours are built from (plant/vehicles/*.toml, or beside the module).
    messages: its network: every message the plant side of this vehicle sends; the factory stops the others.
    stimulus: the stimulus messages its behaviours read, i.e. what a scenario of it sends besides
        BENCH_Control (the bench's public `bench.plugins.plant_stimulus` answers from it).
    io: its bench I/O (docs/contract/plant.md, "Bench I/O"): per ECU node, the IO_* messages the plant sends to it
        or reads from it, on the bus only while that node is external (the factory stops them otherwise, so a
        simulated ECU, which keeps its direct wires, sends none either). Not part of `messages`.
    """

    name: str
    code: int
    build: Callable[[frozenset[str]], list[Behaviour]]
    parameters: tuple[ParameterFile, ...]
    messages: frozenset[str]
    stimulus: tuple[str, ...]
    io: Mapping[str, frozenset[str]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.name.isidentifier() or self.name != self.name.upper():
            raise ValueError(f"vehicle name {self.name!r}: an upper-case DBC value name is needed")
        if self.code < 0:
            raise ValueError(f"vehicle {self.name}: code {self.code} must be a DBC value (>= 0)")
        if not self.messages:
            raise ValueError(f"vehicle {self.name}: its network (messages) is empty")
