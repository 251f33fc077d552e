"""Plants are found by name through the entry-point group `bench.plants`, so that the bench
never imports a vehicle: a plant package registers `name = module:function`, where the function
is `build(external: Collection[str], vehicle: str | None) -> list[Behaviour]`; `external` holds
every node the plant must not simulate. The build function's module may also provide `vehicles()` and
`stimulus(vehicle)`, which `plant_vehicles` and `plant_stimulus` pass on to test cases."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Collection
from functools import cache
from importlib.metadata import entry_points
from types import ModuleType

from bench.errors import ConfigError, did_you_mean
from bench.sim.node import Behaviour

PLANT_GROUP = "bench.plants"

PlantFactory = Callable[[Collection[str], "str | None"], list[Behaviour]]


def load_plant(name: str) -> PlantFactory:
    """A registered plant by name, or `package.module:function` directly (for a user's own plant)."""
    if ":" in name:
        module, _, attr = name.partition(":")
        try:
            factory: PlantFactory = getattr(importlib.import_module(module), attr)
            return factory
        except (ImportError, AttributeError) as exc:
            raise ConfigError(f"plant {name!r}: cannot load: {exc}") from None
    found = {ep.name: ep for ep in entry_points(group=PLANT_GROUP)}
    if name not in found:
        raise ConfigError(f"no plant {name!r}{did_you_mean(name, found)} is registered in the entry-point group "
                          f"{PLANT_GROUP!r} (registered: {', '.join(sorted(found)) or 'none'}; is the project "
                          "installed?)")
    try:
        loaded: PlantFactory = found[name].load()
    except (ImportError, AttributeError) as exc:   # registered, but its package is broken or gone
        raise ConfigError(f"plant {name!r}: cannot load {found[name].value}: {exc}") from None
    return loaded


@cache
def plant_module(name: str) -> ModuleType:
    """The module that holds a plant's build function: it may also answer what a test case asks of the plant.
    Looked up once per process (entry points and the plant's import are slow: not at each case's start)."""
    return importlib.import_module(load_plant(name).__module__)


def plant_vehicles(name: str) -> tuple[str, ...]:
    """The vehicles a plant can be (its module's `vehicles()`); () when the plant names none."""
    vehicles = getattr(plant_module(name), "vehicles", None)
    return tuple(vehicles()) if callable(vehicles) else ()


def plant_stimulus(name: str, vehicle: str) -> tuple[str, ...]:
    """The stimulus messages a scenario of the plant's `vehicle` sends (`start_scenario(stimulus=...)`), from the
    plant module's `stimulus(vehicle)`: test cases learn them here, never by importing the plant. ConfigError when
    the plant declares no stimulus or knows no such vehicle."""
    stimulus = getattr(plant_module(name), "stimulus", None)
    if not callable(stimulus):
        raise ConfigError(f"plant {name!r} declares no stimulus(vehicle) beside its build function")
    try:
        return tuple(stimulus(vehicle))
    except ValueError as exc:
        raise ConfigError(f"plant {name!r}: {exc}") from None


def prepare_plant(name: str) -> None:
    """Ask now what a test case may ask of the plant (`plant_vehicles`, `plant_stimulus`): the plant's import and
    the tables it builds when first asked then cost a case nothing, where in real time they stall the tick loop."""
    if callable(getattr(plant_module(name), "stimulus", None)):
        for vehicle in plant_vehicles(name):
            plant_stimulus(name, vehicle)
