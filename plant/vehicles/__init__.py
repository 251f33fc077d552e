"""Vehicle parameter sets: one TOML file per vehicle, every value with its unit and its source.

Why a file per vehicle and a strict loader: vehicles.md asks that chosen values live in one data
file with their source, and a typo in a key or a unit must fail loudly (naming file and key) rather
than run a campaign on a default.

File layout (see ev4wis.toml)::

    name = "EV4WIS"
    [parameters]
    track = { value = 1.11, unit = "m", source = "seed 000 §3" }
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, TypeVar

from plant.kinematics import Geometry

HERE = Path(__file__).resolve().parent

#: BENCH_Control.Vehicle / PLANT_Status.Vehicle value table (dbc/bench.dbc).
VEHICLE_CODES = {"EV4WIS": 0, "ACLASS": 1, "ACLASS_ABS": 2}


def _p(unit: str) -> Any:
    """A parameter field: its unit is checked against the file's."""
    return field(metadata={"unit": unit})


@dataclass(frozen=True)
class Ev4wisParams:
    """vehicles.md A: the 4WIS steer-by-wire EV of seed 000 (SI units unless the name says so)."""

    track: float = _p("m")
    wheelbase: float = _p("m")
    wheel_radius: float = _p("m")
    steer_limit: float = _p("deg")
    mass: float = _p("kg")
    cog_to_front_axle: float = _p("m")
    cog_to_rear_axle: float = _p("m")
    yaw_inertia: float = _p("kg*m^2")
    cornering_stiffness_front: float = _p("N/rad")
    cornering_stiffness_rear: float = _p("N/rad")
    hand_wheel_ratio: float = _p("1")
    servo_rate_limit: float = _p("deg/s")
    servo_lag: float = _p("s")
    hub_motor_lag: float = _p("s")
    hub_motor_max_speed: float = _p("rpm")
    timeout_speed_ramp: float = _p("rpm/s")
    servo_current_per_rate: float = _p("A*s/deg")
    servo_twist_current: float = _p("A")
    adaptive_low_speed_limit: float = _p("km/h")
    max_yaw_rate: float = _p("deg/s")
    #: parameter name -> source text, from the file (not compared).
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        for f in fields(self):
            if "unit" in f.metadata and not getattr(self, f.name) > 0.0:
                raise ValueError(f"key 'parameters.{f.name}' must be positive, got {getattr(self, f.name)!r}")

    @property
    def geometry(self) -> Geometry:
        """formulas.md §1: K = track/2, L = wheelbase/2."""
        return Geometry(self.track / 2.0, self.wheelbase / 2.0, self.wheel_radius)


@dataclass(frozen=True)
class AclassParams:
    """vehicles.md B: the A-class car of seeds 001 and 004 (SI units unless the name says so)."""

    mass: float = _p("kg")
    yaw_inertia: float = _p("kg*m^2")
    cog_to_front_axle: float = _p("m")
    cog_to_rear_axle: float = _p("m")
    cornering_stiffness_front: float = _p("N/rad")
    cornering_stiffness_rear: float = _p("N/rad")
    track: float = _p("m")
    wheel_radius: float = _p("m")
    hand_wheel_ratio: float = _p("1")
    cog_height: float = _p("m")
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False)

    @property
    def wheelbase(self) -> float:
        """L = a + b (formulas.md §5)."""
        return self.cog_to_front_axle + self.cog_to_rear_axle


P = TypeVar("P")

#: vehicle name (as on the bus, BENCH_Control.Vehicle) -> (file, parameter class)
VEHICLES: dict[str, tuple[str, type]] = {
    "EV4WIS": ("ev4wis.toml", Ev4wisParams),
    "ACLASS": ("aclass.toml", AclassParams),
}


def load_vehicle(name: str) -> Any:
    """The parameter set of a vehicle by its bus name (case-insensitive), e.g. "EV4WIS".

    Raises ValueError naming the file and key for an unknown vehicle or a missing, extra or ill-typed key.
    """
    entry = VEHICLES.get(str(name).upper())
    if entry is None:
        raise ValueError(f"unknown vehicle {name!r}: no parameter file for it in {HERE} "
                         f"(known: {', '.join(sorted(VEHICLES))})")
    file_name, cls = entry
    return load_file(HERE / file_name, cls)


def load_file(path: Path, cls: type[P]) -> P:
    """Load and check one parameter file into the frozen dataclass `cls`."""
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the vehicle file ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from None
    table = data.get("parameters")
    if not isinstance(table, dict):
        raise ValueError(f"{path}: key 'parameters' is missing or not a table")
    wanted = {f.name: f.metadata["unit"] for f in fields(cls) if "unit" in f.metadata}  # type: ignore[arg-type]
    extra = sorted(set(table) - set(wanted))
    if extra:
        raise ValueError(f"{path}: unknown key 'parameters.{extra[0]}' (expected: {', '.join(wanted)})")
    values: dict[str, float] = {}
    sources: dict[str, str] = {}
    for key, unit in wanted.items():
        where = f"{path}: key 'parameters.{key}'"
        item = table.get(key)
        if item is None:
            raise ValueError(f"{where} is missing")
        if not isinstance(item, dict):
            raise ValueError(f"{where} must be a table {{ value, unit, source }}, got {item!r}")
        value = item.get("value")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"{where}: value must be a finite number, got {value!r}")
        if item.get("unit") != unit:
            raise ValueError(f"{where}: unit must be {unit!r}, got {item.get('unit')!r}")
        source = item.get("source")
        if not isinstance(source, str) or not source.strip():
            raise ValueError(f"{where}: source must be a non-empty string")
        extra_fields = set(item) - {"value", "unit", "source"}
        if extra_fields:
            raise ValueError(f"{where}: unknown field(s) {', '.join(sorted(extra_fields))}")
        values[key] = float(value)
        sources[key] = source
    try:
        return cls(**values, sources=MappingProxyType(sources))  # type: ignore[call-arg]
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
