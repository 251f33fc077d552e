"""The vehicles the plant can be, discovered from their declarations (`VEHICLE` in each module of plant/assemblies/).

Why discovered: a vehicle is declared in one place (plant/declaration.py); the factory, the network switch and the
stimulus lists the bench hands to test cases read this registry, so no second list can drift from the first.
"""

from __future__ import annotations

import difflib
import importlib
import pkgutil
from functools import cache

import plant.assemblies
from plant.declaration import Vehicle


@cache
def vehicles() -> dict[str, Vehicle]:
    """Every declared vehicle by name. ValueError when two declarations share a name or a code, or a module of
    plant/assemblies/ declares none."""
    found: dict[str, Vehicle] = {}
    codes: dict[int, str] = {}
    for module_info in sorted(pkgutil.iter_modules(plant.assemblies.__path__), key=lambda m: m.name):
        if module_info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{plant.assemblies.__name__}.{module_info.name}")
        vehicle = getattr(module, "VEHICLE", None)
        if not isinstance(vehicle, Vehicle):
            raise ValueError(f"{module.__name__}: no VEHICLE declaration (plant.declaration.Vehicle)")
        if vehicle.name in found or vehicle.code in codes:
            other = found.get(vehicle.name) or found[codes[vehicle.code]]
            raise ValueError(f"{module.__name__}: vehicle {vehicle.name} = {vehicle.code} clashes with "
                             f"{other.name} = {other.code}")
        found[vehicle.name] = vehicle
        codes[vehicle.code] = vehicle.name
    return found


def vehicle(name: str) -> Vehicle:
    """A declared vehicle by name (case-insensitive); ValueError naming the known ones."""
    known = vehicles()
    found = known.get(str(name).upper())
    if found is None:
        close = difflib.get_close_matches(str(name).upper(), known, n=1, cutoff=0.6)
        meant = f" (did you mean {close[0]}?)" if close else ""
        raise ValueError(f"no plant for vehicle {name!r}{meant} (available: {', '.join(sorted(known))})")
    return found


def by_code(code: int) -> Vehicle | None:
    """The vehicle with this DBC code (BENCH_Control.Vehicle), None when none is declared."""
    for declared in vehicles().values():
        if declared.code == code:
            return declared
    return None
