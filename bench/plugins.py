"""Plants are found by name through the entry-point group `bench.plants`, so that the bench
never imports a vehicle: a plant package registers `name = module:function`, where the function
is `build(external: Collection[str], vehicle: str | None) -> list[Behaviour]`."""

from __future__ import annotations

from collections.abc import Callable, Collection
from importlib.metadata import entry_points

from bench.errors import ConfigError
from bench.node import Behaviour

PLANT_GROUP = "bench.plants"

PlantFactory = Callable[[Collection[str], "str | None"], list[Behaviour]]


def load_plant(name: str) -> PlantFactory:
    found = {ep.name: ep for ep in entry_points(group=PLANT_GROUP)}
    if name not in found:
        raise ConfigError(f"no plant {name!r} is registered in the entry-point group {PLANT_GROUP!r} "
                          f"(registered: {', '.join(sorted(found)) or 'none'}; is the project installed?)")
    return found[name].load()
