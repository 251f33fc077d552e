"""Parameter sets: one TOML file per set (a vehicle or a subsystem of one), every value with its unit and its source.

Why a file per set and a strict loader: docs/spec/vehicles.md asks that chosen values live in one data
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
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar, Protocol, TypeVar

from plant.kinematics import Geometry

HERE = Path(__file__).resolve().parent


def param(unit: str) -> Any:
    """A parameter field of a parameter class: its unit is checked against the file's."""
    return field(metadata={"unit": unit})


class ParameterSet(Protocol):
    """What `load_file` builds: a frozen dataclass of `param` fields that also takes each value's source."""

    __dataclass_fields__: ClassVar[dict[str, Any]]

    def __init__(self, *, sources: Mapping[str, str], **values: float) -> None: ...


def require_positive(params: ParameterSet, signed: frozenset[str] = frozenset()) -> None:
    """ValueError naming the first parameter field (other than `signed`) that is not > 0."""
    for f in fields(params):
        if "unit" in f.metadata and f.name not in signed and not getattr(params, f.name) > 0.0:
            raise ValueError(f"key 'parameters.{f.name}' must be positive, got {getattr(params, f.name)!r}")


@dataclass(frozen=True)
class Ev4wisParams:
    """docs/spec/vehicles.md A: the 4WIS steer-by-wire EV of [P0] (SI units unless the name says so)."""

    track: float = param("m")
    wheelbase: float = param("m")
    wheel_radius: float = param("m")
    steer_limit: float = param("deg")
    mass: float = param("kg")
    cog_to_front_axle: float = param("m")
    cog_to_rear_axle: float = param("m")
    yaw_inertia: float = param("kg*m^2")
    cornering_stiffness_front: float = param("N/rad")
    cornering_stiffness_rear: float = param("N/rad")
    hand_wheel_ratio: float = param("1")
    servo_rate_limit: float = param("deg/s")
    servo_lag: float = param("s")
    hub_motor_lag: float = param("s")
    hub_motor_max_speed: float = param("rpm")
    timeout_speed_ramp: float = param("rpm/s")
    servo_current_per_rate: float = param("A*s/deg")
    servo_twist_current: float = param("A")
    adaptive_low_speed_limit: float = param("km/h")
    max_yaw_rate: float = param("deg/s")
    #: parameter name -> source text, from the file (not compared).
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        require_positive(self)

    @property
    def geometry(self) -> Geometry:
        """docs/spec/formulas.md §1: K = track/2, L = wheelbase/2."""
        return Geometry(self.track / 2.0, self.wheelbase / 2.0, self.wheel_radius)


@dataclass(frozen=True)
class AclassParams:
    """docs/spec/vehicles.md B: the A-class car of [P1] and [P4] (SI units unless the name says so)."""

    mass: float = param("kg")
    yaw_inertia: float = param("kg*m^2")
    cog_to_front_axle: float = param("m")
    cog_to_rear_axle: float = param("m")
    cornering_stiffness_front: float = param("N/rad")
    cornering_stiffness_rear: float = param("N/rad")
    track: float = param("m")
    wheel_radius: float = param("m")
    hand_wheel_ratio: float = param("1")
    cog_height: float = param("m")
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False)

    @property
    def wheelbase(self) -> float:
        """L = a + b (docs/spec/formulas.md §5)."""
        return self.cog_to_front_axle + self.cog_to_rear_axle


@dataclass(frozen=True)
class AbsParams:
    """The ABS set (docs/spec/vehicles.md B with [P4]'s brakes, tyres, sensors and ABS ECU): what braking adds to
    AclassParams (aclass.toml), from abs.toml. Units in the field metadata, sources in the file."""

    hand_wheel_ratio: float = param("1")
    wheel_inertia: float = param("kg*m^2")
    lateral_c: float = param("1")
    lateral_e: float = param("1")
    slip_speed_floor: float = param("m/s")
    load_transfer_lag: float = param("s")
    stop_speed: float = param("m/s")
    brake_gain_front: float = param("N*m/bar")
    brake_gain_rear: float = param("N*m/bar")
    inlet_flow: float = param("bar^0.5/s")
    outlet_flow: float = param("bar^0.5/s")
    master_rate: float = param("bar/s")
    pedal_to_pressure: float = param("bar/%")
    max_pressure: float = param("bar")
    max_drive_torque: float = param("N*m")
    cruise_gain: float = param("N*m/(km/h)")
    sensor_quantum: float = param("km/h")
    roughness_ratio: float = param("1")
    roughness_time: float = param("s")
    noise_seed: float = param("1")
    control_period: float = param("s")
    decel_threshold: float = param("m/s^2")
    accel_threshold: float = param("m/s^2")
    slip_threshold: float = param("1")
    slip_max: float = param("1")
    turn_front_slip_threshold: float = param("1")
    fast_reapply_time: float = param("s")
    step_duty: float = param("1")
    abs_min_speed: float = param("km/h")
    brake_switch_pressure: float = param("bar")
    stability_factor: float = param("s^2/m^2")
    v_l0: float = param("km/h")
    v_l1: float = param("km/h")
    v_l2: float = param("km/h")
    t0: float = param("s")
    t1: float = param("s")
    speed_filter_time: float = param("s")
    min_turn_speed: float = param("km/h")
    delta_average_points: float = param("1")
    rear_release_time: float = param("s")
    min_delta_speed: float = param("km/h")
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        require_positive(self, signed=frozenset({"lateral_e"}))    # the only field that may be zero or negative
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
    hand_wheel_inertia: float = param("kg*m^2")
    hand_wheel_damping: float = param("N*m*s/rad")
    torsion_bar_stiffness: float = param("N*m/rad")
    # road-feel motor with its worm gear (eq. 3-5)
    road_feel_inertia: float = param("kg*m^2")
    road_feel_damping: float = param("N*m*s/rad")
    road_feel_torque_constant: float = param("N*m/A")
    road_feel_resistance: float = param("ohm")
    road_feel_inductance: float = param("H")
    road_feel_gear_ratio: float = param("1")
    road_feel_current_limit: float = param("A")
    # steering actuator motor with its reduction to the pinion (eq. 6-8)
    steer_motor_inertia: float = param("kg*m^2")
    steer_motor_damping: float = param("N*m*s/rad")
    steer_motor_torque_constant: float = param("N*m/A")
    steer_motor_resistance: float = param("ohm")
    steer_motor_inductance: float = param("H")
    steer_motor_gear_ratio: float = param("1")
    steer_motor_current_limit: float = param("A")
    supply_voltage: float = param("V")
    # rack and pinion with dry friction and the aligning torque (eq. 9-10)
    pinion_inertia: float = param("kg*m^2")
    pinion_damping: float = param("N*m*s/rad")
    dry_friction: float = param("N*m")
    pinion_radius: float = param("m")
    steering_ratio: float = param("1")
    tyre_trail: float = param("m")
    pinion_travel: float = param("deg")
    # steering robot (plant/driver.py)
    robot_rate_limit: float = param("deg/s")
    robot_bandwidth: float = param("rad/s")
    robot_torque_lag: float = param("s")
    # the rig's actuator emulation for an external SBW (plant/sbw.py ActuatorEmulation; docs/contract/plant.md
    # PLANT-IO-SBW-03, -04)
    rig_servo_frequency: float = param("rad/s")
    rig_servo_damping: float = param("1")
    rig_current_time_constant: float = param("s")
    # reference ECU: bilateral control (plant/ecus/sbw.py)
    control_rate: float = param("Hz")
    assist_gain: float = param("1")
    torque_rate_gain: float = param("s")
    pinion_damping_gain: float = param("N*m*s/rad")
    position_gain: float = param("1/s")
    speed_kp: float = param("N*m*s/rad")
    speed_ki: float = param("N*m/rad")
    road_feel_current_kp: float = param("V/A")
    road_feel_current_ki: float = param("V/(A*s)")
    road_feel_current_kd: float = param("V*s/A")
    steer_current_kp: float = param("V/A")
    steer_current_ki: float = param("V/(A*s)")
    steer_current_kd: float = param("V*s/A")
    rack_force_filter: float = param("s")
    # reference ECU: yaw-rate feedback with an ideal steering ratio ([P3] §1.1, §1.2)
    ideal_yaw_gain: float = param("1/s")
    yaw_reference_lag: float = param("s")
    yaw_feedback_kp: float = param("s")
    yaw_feedback_ki: float = param("1")
    lat_accel_weight: float = param("1")
    feedback_min_speed: float = param("km/h")
    additional_angle_limit: float = param("deg")
    additional_angle_rate: float = param("deg/s")
    # reference ECU: sensor plausibility (SBW_Pinion.SbwFault)
    hand_wheel_range: float = param("deg")
    pinion_range: float = param("deg")
    plausibility_limit: float = param("deg")
    stuck_motion: float = param("deg")
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        require_positive(self)
        if self.control_rate < 1000.0:
            raise ValueError(f"key 'parameters.control_rate' must be at least 1000 Hz (issue 4), "
                             f"got {self.control_rate!r}")
        if self.lat_accel_weight > 1.0:
            raise ValueError(f"key 'parameters.lat_accel_weight' must be at most 1, got {self.lat_accel_weight!r}")


P = TypeVar("P", bound=ParameterSet)


@dataclass(frozen=True)
class ParameterFile:
    """A parameter file and the frozen dataclass it loads into (a vehicle's declaration names its files)."""

    path: Path
    cls: type[ParameterSet]

    def load(self) -> Any:
        """The checked parameter set (ValueError naming the file and key, see `load_file`)."""
        return load_file(self.path, self.cls)


#: The parameter files of this folder by name. They are parameter sets, not vehicles: the A-class car uses
#: ACLASS with SBW (its front steer-by-wire) or with ABS (what braking adds).
PARAMETER_FILES: dict[str, ParameterFile] = {
    "EV4WIS": ParameterFile(HERE / "ev4wis.toml", Ev4wisParams),
    "ACLASS": ParameterFile(HERE / "aclass.toml", AclassParams),
    "ABS": ParameterFile(HERE / "abs.toml", AbsParams),
    "SBW": ParameterFile(HERE / "sbw.toml", SbwParams),
}


def load_parameters(name: str) -> Any:
    """A parameter set of this folder by name (case-insensitive), e.g. "EV4WIS", "SBW".

    Raises ValueError naming the file and key for an unknown set or a missing, extra or ill-typed key.
    """
    entry = PARAMETER_FILES.get(str(name).upper())
    if entry is None:
        raise ValueError(f"unknown parameter set {name!r}: no parameter file for it in {HERE} "
                         f"(known: {', '.join(sorted(PARAMETER_FILES))})")
    return entry.load()


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
    wanted = {f.name: f.metadata["unit"] for f in fields(cls) if "unit" in f.metadata}
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
        return cls(**values, sources=MappingProxyType(sources))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
