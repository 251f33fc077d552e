"""Vehicle parameter sets: one TOML file per vehicle, every value with its unit and its source.

Why a file per vehicle and a strict loader: docs/spec/vehicles.md asks that chosen values live in one data
file with their source, and a typo in a key or a unit must fail loudly (naming file and key) rather
than run a campaign on a default.

File layout (see ev4wis.toml)::

    name = "EV4WIS"
    [parameters]
    track = { value = 1.11, unit = "m", source = "[P0] §3" }
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
    """docs/spec/vehicles.md A: the 4WIS steer-by-wire EV of [P0] (SI units unless the name says so)."""

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
        """docs/spec/formulas.md §1: K = track/2, L = wheelbase/2."""
        return Geometry(self.track / 2.0, self.wheelbase / 2.0, self.wheel_radius)


@dataclass(frozen=True)
class AclassParams:
    """docs/spec/vehicles.md B: the A-class car of [P1] and [P4] (SI units unless the name says so)."""

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
        """L = a + b (docs/spec/formulas.md §5)."""
        return self.cog_to_front_axle + self.cog_to_rear_axle


@dataclass(frozen=True)
class AbsParams:
    """ACLASS_ABS (docs/spec/vehicles.md B with [P4]'s brakes, tyres, sensors and ABS ECU): what braking adds to
    AclassParams (aclass.toml), from abs.toml. Units in the field metadata, sources in the file."""

    hand_wheel_ratio: float = _p("1")
    wheel_inertia: float = _p("kg*m^2")
    lateral_c: float = _p("1")
    lateral_e: float = _p("1")
    slip_speed_floor: float = _p("m/s")
    load_transfer_lag: float = _p("s")
    stop_speed: float = _p("m/s")
    brake_gain_front: float = _p("N*m/bar")
    brake_gain_rear: float = _p("N*m/bar")
    inlet_flow: float = _p("bar^0.5/s")
    outlet_flow: float = _p("bar^0.5/s")
    master_rate: float = _p("bar/s")
    pedal_to_pressure: float = _p("bar/%")
    max_pressure: float = _p("bar")
    max_drive_torque: float = _p("N*m")
    cruise_gain: float = _p("N*m/(km/h)")
    sensor_quantum: float = _p("km/h")
    roughness_ratio: float = _p("1")
    roughness_time: float = _p("s")
    noise_seed: float = _p("1")
    control_period: float = _p("s")
    decel_threshold: float = _p("m/s^2")
    accel_threshold: float = _p("m/s^2")
    slip_threshold: float = _p("1")
    slip_max: float = _p("1")
    turn_front_slip_threshold: float = _p("1")
    fast_reapply_time: float = _p("s")
    step_duty: float = _p("1")
    abs_min_speed: float = _p("km/h")
    brake_switch_pressure: float = _p("bar")
    stability_factor: float = _p("s^2/m^2")
    v_l0: float = _p("km/h")
    v_l1: float = _p("km/h")
    v_l2: float = _p("km/h")
    t0: float = _p("s")
    t1: float = _p("s")
    speed_filter_time: float = _p("s")
    min_turn_speed: float = _p("km/h")
    delta_average_points: float = _p("1")
    rear_release_time: float = _p("s")
    min_delta_speed: float = _p("km/h")
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        signed = {"lateral_e"}    # the only field that may be zero or negative
        for f in fields(self):
            if "unit" in f.metadata and f.name not in signed and not getattr(self, f.name) > 0.0:
                raise ValueError(f"key 'parameters.{f.name}' must be positive, got {getattr(self, f.name)!r}")
        if self.lateral_e > 1.0:
            raise ValueError(f"key 'parameters.lateral_e' must be at most 1 (Magic Formula E), got {self.lateral_e!r}")
        if not self.v_l0 < self.v_l1:
            raise ValueError(f"key 'parameters.v_l0' ({self.v_l0}) must be below 'parameters.v_l1' ({self.v_l1})")
        lam = max(self.slip_threshold, self.turn_front_slip_threshold)
        if not (self.step_duty <= 1.0 and lam < self.slip_max < 1.0):
            raise ValueError("keys 'parameters.step_duty' <= 1 and 'parameters.slip_threshold', "
                             "'turn_front_slip_threshold' < 'slip_max' < 1 needed")
        if self.delta_average_points != int(self.delta_average_points):
            raise ValueError(f"key 'parameters.delta_average_points' must be a whole number, "
                             f"got {self.delta_average_points!r}")


@dataclass(frozen=True)
class SbwParams:
    """The front steer-by-wire system of the A-class car ([P1] eq. 1-10, docs/spec/formulas.md §4), its steering
    robot and its reference ECU (bilateral control, [P1] §2.3-3; yaw-rate feedback, [P3] §1), from
    sbw.toml. Angles of the hand wheel, column and pinion are hand-wheel angles (the pinion turns
    `steering_ratio` times the road wheels). Units in the field metadata, sources in the file."""

    # hand-wheel module ([P1] eq. 1-2)
    hand_wheel_inertia: float = _p("kg*m^2")
    hand_wheel_damping: float = _p("N*m*s/rad")
    torsion_bar_stiffness: float = _p("N*m/rad")
    # road-feel motor with its worm gear (eq. 3-5)
    road_feel_inertia: float = _p("kg*m^2")
    road_feel_damping: float = _p("N*m*s/rad")
    road_feel_torque_constant: float = _p("N*m/A")
    road_feel_resistance: float = _p("ohm")
    road_feel_inductance: float = _p("H")
    road_feel_gear_ratio: float = _p("1")
    road_feel_current_limit: float = _p("A")
    # steering actuator motor with its reduction to the pinion (eq. 6-8)
    steer_motor_inertia: float = _p("kg*m^2")
    steer_motor_damping: float = _p("N*m*s/rad")
    steer_motor_torque_constant: float = _p("N*m/A")
    steer_motor_resistance: float = _p("ohm")
    steer_motor_inductance: float = _p("H")
    steer_motor_gear_ratio: float = _p("1")
    steer_motor_current_limit: float = _p("A")
    supply_voltage: float = _p("V")
    # rack and pinion with dry friction and the aligning torque (eq. 9-10)
    pinion_inertia: float = _p("kg*m^2")
    pinion_damping: float = _p("N*m*s/rad")
    dry_friction: float = _p("N*m")
    pinion_radius: float = _p("m")
    steering_ratio: float = _p("1")
    tyre_trail: float = _p("m")
    pinion_travel: float = _p("deg")
    # steering robot (plant/driver.py)
    robot_rate_limit: float = _p("deg/s")
    robot_bandwidth: float = _p("rad/s")
    robot_torque_lag: float = _p("s")
    # reference ECU: bilateral control (plant/ecus/sbw.py)
    control_rate: float = _p("Hz")
    assist_gain: float = _p("1")
    torque_rate_gain: float = _p("s")
    pinion_damping_gain: float = _p("N*m*s/rad")
    position_gain: float = _p("1/s")
    speed_kp: float = _p("N*m*s/rad")
    speed_ki: float = _p("N*m/rad")
    road_feel_current_kp: float = _p("V/A")
    road_feel_current_ki: float = _p("V/(A*s)")
    road_feel_current_kd: float = _p("V*s/A")
    steer_current_kp: float = _p("V/A")
    steer_current_ki: float = _p("V/(A*s)")
    steer_current_kd: float = _p("V*s/A")
    rack_force_filter: float = _p("s")
    # reference ECU: yaw-rate feedback with an ideal steering ratio ([P3] §1.1, §1.2)
    ideal_yaw_gain: float = _p("1/s")
    yaw_reference_lag: float = _p("s")
    yaw_feedback_kp: float = _p("s")
    yaw_feedback_ki: float = _p("1")
    lat_accel_weight: float = _p("1")
    feedback_min_speed: float = _p("km/h")
    additional_angle_limit: float = _p("deg")
    additional_angle_rate: float = _p("deg/s")
    # reference ECU: sensor plausibility (SBW_Pinion.SbwFault)
    hand_wheel_range: float = _p("deg")
    pinion_range: float = _p("deg")
    plausibility_limit: float = _p("deg")
    stuck_motion: float = _p("deg")
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        for f in fields(self):
            if "unit" in f.metadata and not getattr(self, f.name) > 0.0:
                raise ValueError(f"key 'parameters.{f.name}' must be positive, got {getattr(self, f.name)!r}")
        if self.control_rate < 1000.0:
            raise ValueError(f"key 'parameters.control_rate' must be at least 1000 Hz (issue 4), got {self.control_rate!r}")
        if self.lat_accel_weight > 1.0:
            raise ValueError(f"key 'parameters.lat_accel_weight' must be at most 1, got {self.lat_accel_weight!r}")


P = TypeVar("P")

#: vehicle name (as on the bus, BENCH_Control.Vehicle) -> (file, parameter class)
VEHICLES: dict[str, tuple[str, type]] = {
    "EV4WIS": ("ev4wis.toml", Ev4wisParams),
    "ACLASS": ("aclass.toml", AclassParams),
    "ACLASS_ABS": ("abs.toml", AbsParams),
    "SBW": ("sbw.toml", SbwParams),
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
