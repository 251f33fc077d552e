"""Plants are found by name through the entry-point group `bench.plants`, so that the bench
never imports a vehicle: a plant package registers `name = module:function`, where the function
is `build(external: Collection[str], vehicle: str | None) -> list[Behaviour]`; `external` holds
every node the plant must not simulate."""

from __future__ import annotations

from collections.abc import Callable, Collection
import importlib
from importlib.metadata import entry_points

from bench.errors import ConfigError
from bench.node import Behaviour

PLANT_GROUP = "bench.plants"

PlantFactory = Callable[[Collection[str], "str | None"], list[Behaviour]]


def load_plant(name: str) -> PlantFactory:
    """A registered plant by name, or `package.module:function` directly (for a user's own plant)."""
    if ":" in name:
        module, _, attr = name.partition(":")
        try:
            return getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as exc:
            raise ConfigError(f"plant {name!r}: cannot load: {exc}") from None
    found = {ep.name: ep for ep in entry_points(group=PLANT_GROUP)}
    if name not in found:
        raise ConfigError(f"no plant {name!r} is registered in the entry-point group {PLANT_GROUP!r} "
                          f"(registered: {', '.join(sorted(found)) or 'none'}; is the project installed?)")
    return found[name].load()
