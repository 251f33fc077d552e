"""The DBCs against the contract (docs/spec/k-matrix.md).

The expected names, ids, senders, cycle times and units below are copied from docs/spec/k-matrix.md by hand,
not read back from the DBC: if the database drifts from the contract, these tests say where.
Real ECUs are built against chassis.dbc, so every structural rule is checked on every message.
"""

from __future__ import annotations

import math
import tomllib

import cantools
import pytest
from cantools.database.can import Database, Message, Signal
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.repo import BENCH_DBC, CHASSIS_DBC

WHEELS = ("FL", "FR", "RL", "RR")
MODES = {0: "NORMAL", 1: "LATERAL", 2: "ADAPTIVE", 3: "PIVOT"}
ENUM = None  # an enumeration: any unit will do (the DBC writes "-")

NODES = {"DRIVER", "VCU", "WHL_FL", "WHL_FR", "WHL_RL", "WHL_RR", "SBW", "ABS", "IMU", "TESTER"}
#: the diagnostic declaration (docs/contract/diagnostics.md DIAG-TP-01): its identifiers, read here independently
DECLARATION = tomllib.loads((CHASSIS_DBC.parent / "diagnostics.toml").read_text(encoding="utf-8"))

# id, name, sender, cycle ms, {contract signal: unit}
CONTRACT: list[tuple[int, str, str, int, dict[str, str | None]]] = [
    (0x100, "DRV_Steering", "DRIVER", 10, {"HandWheelAngle": "deg", "HandWheelRate": "deg/s", "DriverTorque": "Nm"}),
    (0x101, "DRV_Pedals", "DRIVER", 10, {"AccelPedal": "%", "BrakePedal": "%", "BrakePressure": "bar"}),
    (0x102, "DRV_MotionRequest", "DRIVER", 20,
     {"DriveMode": ENUM, "PivotX": "m", "PivotY": "m", "TargetSpeed": "m/s"}),
    *[(0x110 + i, f"VCU_WheelCmd_{w}", "VCU", 10, {"SteerAngleCmd": "deg", "WheelSpeedCmd": "rpm"})
      for i, w in enumerate(WHEELS)],
    *[(0x120 + i, f"WHL_Status_{w}", f"WHL_{w}", 10,
       {"SteerAngle": "deg", "WheelSpeed": "rpm", "SteerMotorCurrent": "A", "WheelFault": ENUM})
      for i, w in enumerate(WHEELS)],
    (0x130, "VCU_VehicleState", "VCU", 20,
     {"ActiveMode": ENUM, "VehicleSpeed": "m/s", "YawRateTarget": "deg/s", "CurvatureAngle": "deg"}),
    (0x131, "VCU_RotationCentre", "VCU", 20, {"RotationCentreX": "m", "RotationCentreY": "m"}),
    (0x140, "IMU_Motion", "IMU", 10, {"YawRate": "deg/s", "LatAccel": "m/s^2", "LongAccel": "m/s^2"}),
    (0x150, "SBW_HandWheel", "SBW", 10,
     {"HandWheelAngle": "deg", "DriverTorque": "Nm", "RoadFeelTorque": "Nm", "RoadFeelMotorCurrent": "A"}),
    (0x151, "SBW_Pinion", "SBW", 10,
     {"PinionAngle": "deg", "PinionAngleTarget": "deg", "SteerMotorCurrent": "A", "RackForce": "N"}),
    (0x160, "ABS_WheelSpeeds", "ABS", 10, {f"WheelSpeed{w}": "km/h" for w in WHEELS}),
    (0x161, "ABS_SteerState", "ABS", 10,
     {"TurnDirection": ENUM, "RefVehicleSpeed": "km/h", "FrontWheelAngleEst": "deg", "AbsActive": ENUM,
      **{f"PressureState{w}": ENUM for w in WHEELS}}),
]

# (message, signal): value table; docs/spec/k-matrix.md's enumerations plus the project's fault codes
PRESSURE = {0: "HOLD", 1: "INCREASE", 2: "DECREASE"}
ENUMS: dict[tuple[str, str], dict[int, str] | None] = {
    ("DRV_MotionRequest", "DriveMode"): MODES,
    ("VCU_VehicleState", "ActiveMode"): MODES,
    **{(f"WHL_Status_{w}", "WheelFault"):
       {0: "OK", 1: "SERVO_FAULT", 2: "MOTOR_FAULT", 3: "CMD_TIMEOUT", 4: "CMD_INVALID"} for w in WHEELS},
    ("ABS_SteerState", "TurnDirection"): {1: "LEFT", -1: "RIGHT", 0: "STRAIGHT"},
    ("ABS_SteerState", "AbsActive"): None,  # 0/1, names free
    **{("ABS_SteerState", f"PressureState{w}"): PRESSURE for w in WHEELS},
    ("VCU_VehicleState", "VcuFault"): {0: "OK", 1: "CENTRE_AT_ORIGIN", 2: "CENTRE_ON_WHEEL", 3: "ANGLE_OVER_90",
                                       4: "REQUEST_INVALID", 5: "REQUEST_TIMEOUT", 6: "WHEEL_FAULT"},
    ("SBW_Pinion", "SbwFault"): {0: "OK", 1: "HANDWHEEL_RANGE", 2: "HANDWHEEL_STUCK", 3: "PINION_RANGE",
                                 4: "INPUT_TIMEOUT"},
    ("ABS_SteerState", "AbsFault"): {0: "OK", 1: "WHEEL_SPEED_INVALID", 2: "INPUT_TIMEOUT"},
}

# ranges the contract names: (message, signal) -> (min, max)
RANGES = {
    ("DRV_Steering", "HandWheelAngle"): (-900.0, 900.0),
    ("SBW_HandWheel", "HandWheelAngle"): (-900.0, 900.0),
    **{(f"VCU_WheelCmd_{w}", "SteerAngleCmd"): (-90.0, 90.0) for w in WHEELS},
}

# resolution the checks need: (message, signal) -> largest allowed scale
RESOLUTION = {
    **{(f"VCU_WheelCmd_{w}", "SteerAngleCmd"): 0.01 for w in WHEELS},
    **{(f"WHL_Status_{w}", "SteerAngle"): 0.01 for w in WHEELS},
    ("ABS_SteerState", "FrontWheelAngleEst"): 0.01,
    ("VCU_VehicleState", "CurvatureAngle"): 0.01,
    **{(f"VCU_WheelCmd_{w}", "WheelSpeedCmd"): 0.1 for w in WHEELS},
    **{(f"WHL_Status_{w}", "WheelSpeed"): 0.1 for w in WHEELS},
    ("IMU_Motion", "YawRate"): 0.01,
    ("VCU_VehicleState", "YawRateTarget"): 0.01,
    **{("ABS_WheelSpeeds", f"WheelSpeed{w}"): 0.05 for w in WHEELS},  # 0.01 km/h does not fit four times
}

BENCH_NODES = {"TESTER", "PLANT"}
BENCH: list[tuple[int, str, str, int, dict[str, str | None]]] = [
    (0x680, "BENCH_Control", "TESTER", 20,
     {"Vehicle": ENUM, "ScenarioId": ENUM, "RoadMu": ENUM, "InitialSpeed": "m/s", "SensorNoise": "km/h"}),
    (0x681, "BENCH_SteeringRobot", "TESTER", 10, {"RobotMode": ENUM, "RobotAngle": "deg", "RobotTorque": "Nm"}),
    (0x690, "PLANT_Status", "PLANT", 20, {"ScenarioIdAck": ENUM, "Vehicle": ENUM, "PlantTime": "s"}),
    (0x691, "PLANT_Position", "PLANT", 10, {"PosX": "m", "PosY": "m"}),
    (0x692, "PLANT_Motion", "PLANT", 10, {"Heading": "deg", "Speed": "m/s", "YawRate": "deg/s"}),
    (0x693, "PLANT_Dynamics", "PLANT", 10, {"Sideslip": "deg", "LatAccel": "m/s^2", "LongAccel": "m/s^2"}),
]
# The SBW's bench I/O (docs/spec/k-matrix.md, "The bench's own messages"; docs/contract/plant.md PLANT-IO-SBW-02..04):
# id, name, sender, receiver, cycle ms, {signal: (unit, scale, minimum, maximum)}
BENCH_IO_SBW: list[tuple[int, str, str, str, int, dict[str, tuple[str, float, float, float]]]] = [
    (0x6E0, "IO_SbwHandWheel", "PLANT", "SBW", 5,
     {"HandWheelSensor": ("deg", 0.1, -3000, 3000), "ColumnAngle": ("deg", 0.1, -3000, 3000),
      "TorsionBarTorque": ("Nm", 0.002, -65, 65)}),
    (0x6E1, "IO_SbwPinion", "PLANT", "SBW", 5,
     {"PinionSensor": ("deg", 0.1, -3000, 3000), "ActuatorAngle": ("deg", 0.1, -3000, 3000)}),
    (0x6E2, "IO_SbwCurrents", "PLANT", "SBW", 5,
     {"RoadFeelMotorCurrent": ("A", 0.01, -50, 50), "SteerMotorCurrent": ("A", 0.01, -60, 60)}),
    (0x6E8, "IO_SbwActuators", "SBW", "PLANT", 5,
     {"PinionAngleRequest": ("deg", 0.1, -900, 900), "RoadFeelTorqueRequest": ("Nm", 0.002, -20, 20)}),
]
BENCH_ENUMS = {
    ("BENCH_SteeringRobot", "RobotMode"): {0: "OFF", 1: "ANGLE", 2: "TORQUE"},
}
#: The signals whose value table is the plant's vehicles: each declaration's code and name (plant/registry.py).
VEHICLE_ENUMS = (("BENCH_Control", "Vehicle"), ("PLANT_Status", "Vehicle"))

E2E = {"AliveCounter", "Checksum"}
#: docs/spec/e2e.md: AUTOSAR Profile 11 with its header at bit 48 (the CRC in byte 6, the counter in the low
#: nibble of byte 7); the upper nibble of byte 7 and bytes 0-5 carry the signals.
PAYLOAD_BITS = frozenset(range(0, 48)) | frozenset(range(60, 64))


def _load(path: object) -> Database:
    return cantools.database.load_file(str(path), database_format="dbc", strict=True)


CHASSIS = _load(CHASSIS_DBC)
BENCH_DB = _load(BENCH_DBC)
#: every periodic message of both databases (the diagnostic ones follow DIAG-TP-01, tested apart below)
ALL_MESSAGES = [(db_name, m) for db_name, db in (("chassis", CHASSIS), ("bench", BENCH_DB)) for m in db.messages
                if not m.name.startswith("DIAG_")]
DIAGNOSTIC = {f"DIAG_{node}_{kind}": (table[key], "TESTER" if kind == "Req" else node,
                                      "DiagRequest" if kind == "Req" else "DiagResponse")
              for node, table in DECLARATION["nodes"].items()
              for kind, key in (("Req", "request"), ("Resp", "response"))}
DIAGNOSTIC["DIAG_Functional"] = (DECLARATION["protocol"]["functional_request"], "TESTER", "DiagRequest")


def _bits(signal: Signal) -> set[int]:
    """Bit positions (DBC numbering) of a little-endian signal; start is its LSB."""
    assert signal.byte_order == "little_endian", signal.name
    return set(range(signal.start, signal.start + signal.length))


def _raw_limits(signal: Signal) -> tuple[int, int]:
    if signal.is_signed:
        return -(1 << (signal.length - 1)), (1 << (signal.length - 1)) - 1
    return 0, (1 << signal.length) - 1


def _phys(signal: Signal, raw: int) -> float:
    return raw * signal.scale + signal.offset


def _attr(obj: Message | Signal, name: str) -> object:
    attributes = obj.dbc.attributes if obj.dbc is not None else {}
    assert name in attributes, f"{obj.name}: no {name}"
    attribute = attributes[name]
    choices = attribute.definition.choices
    return choices[attribute.value] if choices and isinstance(attribute.value, int) else attribute.value


# --- contract content ------------------------------------------------------------------------

def test_chassis_nodes() -> None:
    assert {node.name for node in CHASSIS.nodes} == NODES


def test_chassis_has_exactly_the_contract_messages() -> None:
    assert {m.name for m in CHASSIS.messages} == {row[1] for row in CONTRACT} | set(DIAGNOSTIC)


@pytest.mark.parametrize("name", sorted(DIAGNOSTIC))
def test_diagnostic_message(name: str) -> None:
    """DIAG-TP-01: each declared identifier is a diagnostic message of its sender, marked with Vector's attribute,
    8 bytes, no signals, no cycle time and no E2E (ISO-TP carries it)."""
    frame_id, sender, attribute = DIAGNOSTIC[name]
    message = CHASSIS.get_message_by_name(name)
    assert (message.frame_id, message.senders, message.length, message.signals) == (frame_id, [sender], 8, [])
    assert not message.is_extended_frame and not message.is_fd and message.comment
    assert message.dbc.attributes[attribute].value == 1
    assert "GenMsgCycleTime" not in message.dbc.attributes and "E2E_Profile" not in message.dbc.attributes


@pytest.mark.parametrize("frame_id, name, sender, cycle, signals", CONTRACT, ids=[row[1] for row in CONTRACT])
def test_contract_message(frame_id: int, name: str, sender: str, cycle: int, signals: dict[str, str | None]) -> None:
    message = CHASSIS.get_message_by_name(name)
    assert message.frame_id == frame_id
    assert not message.is_extended_frame and not message.is_fd
    assert message.senders == [sender]
    assert _attr(message, "GenMsgCycleTime") == cycle
    assert _attr(message, "GenMsgSendType") == "Cyclic"
    for signal_name, unit in signals.items():
        signal = message.get_signal_by_name(signal_name)
        if unit is not None:
            assert signal.unit == unit, signal_name


@pytest.mark.parametrize("key", sorted(ENUMS), ids=lambda k: ".".join(k))
def test_chassis_value_tables(key: tuple[str, str]) -> None:
    signal = CHASSIS.get_message_by_name(key[0]).get_signal_by_name(key[1])
    assert signal.choices, f"{key}: no value table"
    table = {int(value): str(name) for value, name in signal.choices.items()}
    expected = ENUMS[key]
    if expected is None:
        assert set(table) == {0, 1}
    else:
        assert table == expected
    assert signal.minimum == min(table) and signal.maximum == max(table)


@pytest.mark.parametrize("key", sorted(RANGES), ids=lambda k: ".".join(k))
def test_contract_ranges(key: tuple[str, str]) -> None:
    signal = CHASSIS.get_message_by_name(key[0]).get_signal_by_name(key[1])
    assert (signal.minimum, signal.maximum) == RANGES[key]


@pytest.mark.parametrize("key", sorted(RESOLUTION), ids=lambda k: ".".join(k))
def test_resolution(key: tuple[str, str]) -> None:
    signal = CHASSIS.get_message_by_name(key[0]).get_signal_by_name(key[1])
    assert signal.scale <= RESOLUTION[key] * (1 + 1e-9)


def test_rotation_centre_infinity_is_inside_the_range() -> None:
    """'Straight' (centre at infinity) is sent as the range end, so a receiver must not reject it as
    out of range; the start value is straight, and the centre covers at least the pivot range."""
    message = CHASSIS.get_message_by_name("VCU_RotationCentre")
    pivot = CHASSIS.get_message_by_name("DRV_MotionRequest").get_signal_by_name("PivotX")
    for name in ("RotationCentreX", "RotationCentreY"):
        signal = message.get_signal_by_name(name)
        assert signal.minimum <= min(-1000.0, pivot.minimum) and signal.maximum >= max(1000.0, pivot.maximum)
        assert signal.maximum == -signal.minimum
    x = message.get_signal_by_name("RotationCentreX")
    assert x.conversion.raw_to_scaled(x.raw_initial) == x.maximum


# --- bench database --------------------------------------------------------------------------

def test_bench_nodes_and_messages() -> None:
    assert {node.name for node in BENCH_DB.nodes} >= BENCH_NODES
    names = {m.name for m in BENCH_DB.messages}
    assert names >= {row[1] for row in BENCH}


@pytest.mark.parametrize("frame_id, name, sender, cycle, signals", BENCH, ids=[row[1] for row in BENCH])
def test_bench_message(frame_id: int, name: str, sender: str, cycle: int, signals: dict[str, str | None]) -> None:
    message = BENCH_DB.get_message_by_name(name)
    assert message.frame_id == frame_id
    assert message.senders == [sender]
    assert _attr(message, "GenMsgCycleTime") == cycle
    assert _attr(message, "GenMsgSendType") == "Cyclic"
    for signal_name, unit in signals.items():
        signal = message.get_signal_by_name(signal_name)
        if unit is not None:
            assert signal.unit == unit, signal_name


@pytest.mark.parametrize("frame_id, name, sender, receiver, cycle, signals", BENCH_IO_SBW,
                         ids=[row[1] for row in BENCH_IO_SBW])
def test_bench_io_sbw(frame_id: int, name: str, sender: str, receiver: str, cycle: int,
                      signals: dict[str, tuple[str, float, float, float]]) -> None:
    message = BENCH_DB.get_message_by_name(name)
    assert message.frame_id == frame_id
    assert message.senders == [sender]
    assert _attr(message, "GenMsgCycleTime") == cycle
    assert _attr(message, "GenMsgSendType") == "Cyclic"
    assert _attr(message, "E2E_Profile") == "P11" and _attr(message, "E2E_DataID") == frame_id
    for signal in message.signals:
        assert signal.receivers == [receiver], signal.name
    for signal_name, (unit, scale, minimum, maximum) in signals.items():
        signal = message.get_signal_by_name(signal_name)
        assert (signal.unit, signal.scale, signal.minimum, signal.maximum) == (unit, scale, minimum, maximum)
        assert signal.is_signed and signal.length == 16
    assert {s.name for s in message.signals} == {*signals, "AliveCounter", "Checksum"}


@pytest.mark.parametrize("key", sorted(BENCH_ENUMS), ids=lambda k: ".".join(k))
def test_bench_value_tables(key: tuple[str, str]) -> None:
    signal = BENCH_DB.get_message_by_name(key[0]).get_signal_by_name(key[1])
    assert {int(v): str(n) for v, n in signal.choices.items()} == BENCH_ENUMS[key]


@pytest.mark.parametrize("key", VEHICLE_ENUMS, ids=lambda k: ".".join(k))
def test_vehicle_value_tables_are_the_declared_vehicles(key: tuple[str, str]) -> None:
    from plant.registry import vehicles

    signal = BENCH_DB.get_message_by_name(key[0]).get_signal_by_name(key[1])
    assert {int(v): str(n) for v, n in signal.choices.items()} == {v.code: v.name for v in vehicles().values()}


def test_bench_ids_are_private() -> None:
    for message in BENCH_DB.messages:
        assert 0x680 <= message.frame_id <= 0x6FF, message.name
    assert not {m.frame_id for m in BENCH_DB.messages} & {m.frame_id for m in CHASSIS.messages}
    assert not {m.name for m in BENCH_DB.messages} & {m.name for m in CHASSIS.messages}


# --- structure of every message of both databases ------------------------------------------

@pytest.mark.parametrize("db_name, message", ALL_MESSAGES, ids=[f"{d}:{m.name}" for d, m in ALL_MESSAGES])
def test_structure(db_name: str, message: Message) -> None:
    assert message.length == 8 and not message.is_extended_frame and not message.is_fd
    assert message.comment, f"{message.name}: no comment"
    counter = message.get_signal_by_name("AliveCounter")
    checksum = message.get_signal_by_name("Checksum")
    for signal, start, length in ((counter, 56, 4), (checksum, 48, 8)):
        assert (signal.start, signal.length, signal.byte_order, signal.is_signed) == \
            (start, length, "little_endian", False), signal.name
    used: set[int] = set()
    for signal in message.signals:
        bits = _bits(signal)
        assert not bits & used, f"{message.name}.{signal.name} overlaps"
        used |= bits
        if signal.name not in E2E:
            assert bits <= PAYLOAD_BITS, f"{message.name}.{signal.name} outside bits 0-47, 60-63"


def test_every_message_declares_profile_11_with_a_data_id_of_its_own() -> None:
    """docs/spec/e2e.md: every message of both databases is protected by Profile 11, DataIDMode BOTH, its
    header at bit 48, with its own Data ID (the CAN identifier), written in the database."""
    data_ids: dict[int, str] = {}
    for db in (CHASSIS, BENCH_DB):
        definitions = db.dbc.attribute_definitions
        assert definitions["E2E_Offset"].default_value == 48 and definitions["E2E_DataIDMode"].default_value == "BOTH"
        for message in db.messages:
            if message.name in DIAGNOSTIC:
                continue   # ISO-TP (test_diagnostic_message)
            attributes = message.dbc.attributes
            profile = definitions["E2E_Profile"].choices[attributes["E2E_Profile"].value]
            data_id = attributes["E2E_DataID"].value
            assert profile == "P11" and data_id == message.frame_id, message.name
            assert data_id not in data_ids, f"{message.name} shares Data ID {data_id:#x} with {data_ids.get(data_id)}"
            data_ids[data_id] = message.name


@pytest.mark.parametrize("db_name, message", ALL_MESSAGES, ids=[f"{d}:{m.name}" for d, m in ALL_MESSAGES])
def test_signal_metadata(db_name: str, message: Message) -> None:
    for signal in message.signals:
        where = f"{message.name}.{signal.name}"
        assert signal.comment, f"{where}: no comment"
        assert signal.unit, f"{where}: no unit"
        assert signal.minimum is not None and signal.maximum is not None and signal.minimum < signal.maximum, where
        raw_lo, raw_hi = _raw_limits(signal)
        lo, hi = sorted((_phys(signal, raw_lo), _phys(signal, raw_hi)))
        tolerance = abs(signal.scale) * 1e-6
        assert lo - tolerance <= signal.minimum and signal.maximum <= hi + tolerance, \
            f"{where}: range not representable"
        raw_start = _attr(signal, "GenSigStartValue")
        assert isinstance(raw_start, int) and raw_lo <= raw_start <= raw_hi, where
        start = signal.conversion.raw_to_scaled(raw_start, decode_choices=False)
        assert signal.minimum <= start <= signal.maximum, f"{where}: start value {start} outside the range"


# --- encode/decode round trip ---------------------------------------------------------------

def _values(message: Message) -> st.SearchStrategy[dict[str, float]]:
    """Random physical values inside each signal's range, as multiples of its scale."""
    fields = {}
    for signal in message.signals:
        raw_lo, raw_hi = _raw_limits(signal)
        k_lo = max(raw_lo, math.ceil((signal.minimum - signal.offset) / signal.scale - 1e-9))
        k_hi = min(raw_hi, math.floor((signal.maximum - signal.offset) / signal.scale + 1e-9))
        fields[signal.name] = st.integers(k_lo, k_hi).map(lambda k, s=signal: k * s.scale + s.offset)
    return st.fixed_dictionaries(fields)


@pytest.mark.parametrize("db_name, message", ALL_MESSAGES, ids=[f"{d}:{m.name}" for d, m in ALL_MESSAGES])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_round_trip(db_name: str, message: Message, data: st.DataObject) -> None:
    values = data.draw(_values(message))
    frame = message.encode(values, strict=True)
    assert len(frame) == 8
    decoded = message.decode(frame, decode_choices=False, scaling=True)
    for signal in message.signals:
        assert math.isclose(decoded[signal.name], values[signal.name], rel_tol=1e-12,
                            abs_tol=abs(signal.scale) * 1e-6), signal.name
