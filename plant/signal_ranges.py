"""The DBC ranges of the signals the plant sends (minimum, maximum), mirrored: `plant` must not load the DBC.

Why: the restbus refuses (stops the sender on) a NaN or out-of-range value, so every behaviour clamps
to these bounds before `send_values` and flags a fault where its message has one.
`tests/plant/test_plant_ev.py` checks these against dbc/chassis.dbc and dbc/bench.dbc, so they cannot drift.
"""

from __future__ import annotations

import math

# (minimum, maximum) per signal, physical units of the DBC.
STEER_ANGLE_CMD = (-90.0, 90.0)             # VCU_WheelCmd_xx.SteerAngleCmd, deg
WHEEL_SPEED_CMD = (-3000.0, 3000.0)         # VCU_WheelCmd_xx.WheelSpeedCmd, rpm
STEER_ANGLE = (-100.0, 100.0)               # WHL_Status_xx.SteerAngle, deg
WHEEL_SPEED = (-3000.0, 3000.0)             # WHL_Status_xx.WheelSpeed, rpm
STEER_MOTOR_CURRENT = (-100.0, 100.0)       # WHL_Status_xx.SteerMotorCurrent, A
VEHICLE_SPEED = (-80.0, 80.0)               # VCU_VehicleState.VehicleSpeed, m/s
YAW_RATE_TARGET = (-300.0, 300.0)           # VCU_VehicleState.YawRateTarget, deg/s
CURVATURE_ANGLE = (-90.0, 90.0)             # VCU_VehicleState.CurvatureAngle, deg
ROTATION_CENTRE = (-5242.87, 5242.87)       # VCU_RotationCentre.RotationCentreX/Y, m
IMU_YAW_RATE = (-300.0, 300.0)              # IMU_Motion.YawRate, deg/s
IMU_ACCEL = (-30.0, 30.0)                   # IMU_Motion.LatAccel/LongAccel, m/s^2
PLANT_POS = (-8388.608, 8388.607)           # PLANT_Position.PosX/PosY, m
PLANT_HEADING = (-180.0, 180.0)             # PLANT_Motion.Heading, deg
PLANT_SPEED = (-81.92, 81.9175)             # PLANT_Motion.Speed, m/s
PLANT_YAW_RATE = (-327.68, 327.67)          # PLANT_Motion.YawRate, deg/s
PLANT_SIDESLIP = (-180.0, 180.0)            # PLANT_Dynamics.Sideslip, deg
PLANT_ACCEL = (-32.768, 32.767)             # PLANT_Dynamics.LatAccel/LongAccel, m/s^2
PLANT_TIME = (0.0, 100000.0)                # PLANT_Status.PlantTime, s
# the SBW ECU (dbc/chassis.dbc)
SBW_HAND_WHEEL_ANGLE = (-900.0, 900.0)      # SBW_HandWheel.HandWheelAngle, deg
SBW_DRIVER_TORQUE = (-50.0, 50.0)           # SBW_HandWheel.DriverTorque, N·m
SBW_ROAD_FEEL_TORQUE = (-20.0, 20.0)        # SBW_HandWheel.RoadFeelTorque, N·m
SBW_ROAD_FEEL_CURRENT = (-50.0, 50.0)       # SBW_HandWheel.RoadFeelMotorCurrent, A
SBW_PINION_ANGLE = (-900.0, 900.0)          # SBW_Pinion.PinionAngle and PinionAngleTarget, deg
SBW_STEER_MOTOR_CURRENT = (-60.0, 60.0)     # SBW_Pinion.SteerMotorCurrent, A
SBW_RACK_FORCE = (-12000.0, 12000.0)        # SBW_Pinion.RackForce, N
# the SBW's ground truth (dbc/bench.dbc)
PLANT_SBW_ANGLE = (-2000.0, 2000.0)         # PLANT_SbwAngles.HandWheelAngle/PinionAngle, deg
PLANT_SBW_TORQUE = (-65.0, 65.0)            # PLANT_SbwTorques.DriverTorque/RoadFeelTorque/AligningTorque, N·m
PLANT_SBW_SENSOR_ANGLE = (-3000.0, 3000.0)  # PLANT_SbwSensors.HandWheelSensor/PinionSensor, deg
# the SBW's bench I/O (dbc/bench.dbc, docs/contract/plant.md PLANT-IO-SBW-02; the currents as SBW_* above)
IO_SBW_ANGLE = (-3000.0, 3000.0)            # IO_SbwHandWheel.HandWheelSensor/ColumnAngle, IO_SbwPinion.*, deg
IO_SBW_TORSION_TORQUE = (-65.0, 65.0)       # IO_SbwHandWheel.TorsionBarTorque, N·m
# the ABS ECU (dbc/chassis.dbc)
ABS_WHEEL_SPEED = (0.0, 204.75)             # ABS_WheelSpeeds.WheelSpeedxx, km/h
ABS_REF_SPEED = (0.0, 250.0)                # ABS_SteerState.RefVehicleSpeed, km/h
ABS_ANGLE = (-90.0, 90.0)                   # ABS_SteerState.FrontWheelAngleEst, deg
# the braking car's ground truth of [P4] (dbc/bench.dbc)
PLANT_ABS_SPEED = (0.0, 250.0)              # PLANT_AbsVehicle.VehicleSpeed, km/h
PLANT_ABS_ANGLE = (-90.0, 90.0)             # PLANT_AbsVehicle.FrontWheelAngle, deg
PLANT_ABS_PRESSURE = (0.0, 400.0)           # PLANT_AbsVehicle.MasterPressure, PLANT_AbsWheel_xx.BrakePressure, bar
PLANT_ABS_WHEEL_SPEED = (0.0, 600.0)        # PLANT_AbsWheel_xx.WheelSpeed, km/h
IO_ABS_WHEEL_SENSOR = (0.0, 204.75)         # IO_AbsSensors.WheelSensorxx, km/h (the whole raw range)
IO_ABS_INLET_DUTY = (0.0, 1.0)              # IO_AbsValves.InletDutyxx
PLANT_ABS_SLIP = (-1.0, 1.0)                # PLANT_AbsWheel_xx.Slip
PLANT_ABS_LOAD = (0.0, 12750.0)             # PLANT_AbsWheel_xx.NormalLoad, N

_WHEELS = ("FL", "FR", "RL", "RR")

#: (message, signal) -> bounds, for the cross-check against the DBC.
BY_SIGNAL: dict[tuple[str, str], tuple[float, float]] = {
    **{(f"VCU_WheelCmd_{c}", "SteerAngleCmd"): STEER_ANGLE_CMD for c in _WHEELS},
    **{(f"VCU_WheelCmd_{c}", "WheelSpeedCmd"): WHEEL_SPEED_CMD for c in _WHEELS},
    **{(f"WHL_Status_{c}", "SteerAngle"): STEER_ANGLE for c in _WHEELS},
    **{(f"WHL_Status_{c}", "WheelSpeed"): WHEEL_SPEED for c in _WHEELS},
    **{(f"WHL_Status_{c}", "SteerMotorCurrent"): STEER_MOTOR_CURRENT for c in _WHEELS},
    ("VCU_VehicleState", "VehicleSpeed"): VEHICLE_SPEED,
    ("VCU_VehicleState", "YawRateTarget"): YAW_RATE_TARGET,
    ("VCU_VehicleState", "CurvatureAngle"): CURVATURE_ANGLE,
    ("VCU_RotationCentre", "RotationCentreX"): ROTATION_CENTRE,
    ("VCU_RotationCentre", "RotationCentreY"): ROTATION_CENTRE,
    ("IMU_Motion", "YawRate"): IMU_YAW_RATE,
    ("IMU_Motion", "LatAccel"): IMU_ACCEL,
    ("IMU_Motion", "LongAccel"): IMU_ACCEL,
    ("PLANT_Position", "PosX"): PLANT_POS,
    ("PLANT_Position", "PosY"): PLANT_POS,
    ("PLANT_Motion", "Heading"): PLANT_HEADING,
    ("PLANT_Motion", "Speed"): PLANT_SPEED,
    ("PLANT_Motion", "YawRate"): PLANT_YAW_RATE,
    ("PLANT_Dynamics", "Sideslip"): PLANT_SIDESLIP,
    ("PLANT_Dynamics", "LatAccel"): PLANT_ACCEL,
    ("PLANT_Dynamics", "LongAccel"): PLANT_ACCEL,
    ("PLANT_Status", "PlantTime"): PLANT_TIME,
    ("SBW_HandWheel", "HandWheelAngle"): SBW_HAND_WHEEL_ANGLE,
    ("SBW_HandWheel", "DriverTorque"): SBW_DRIVER_TORQUE,
    ("SBW_HandWheel", "RoadFeelTorque"): SBW_ROAD_FEEL_TORQUE,
    ("SBW_HandWheel", "RoadFeelMotorCurrent"): SBW_ROAD_FEEL_CURRENT,
    ("SBW_Pinion", "PinionAngle"): SBW_PINION_ANGLE,
    ("SBW_Pinion", "PinionAngleTarget"): SBW_PINION_ANGLE,
    ("SBW_Pinion", "SteerMotorCurrent"): SBW_STEER_MOTOR_CURRENT,
    ("SBW_Pinion", "RackForce"): SBW_RACK_FORCE,
    ("PLANT_SbwAngles", "HandWheelAngle"): PLANT_SBW_ANGLE,
    ("PLANT_SbwAngles", "PinionAngle"): PLANT_SBW_ANGLE,
    ("PLANT_SbwTorques", "DriverTorque"): PLANT_SBW_TORQUE,
    ("PLANT_SbwTorques", "RoadFeelTorque"): PLANT_SBW_TORQUE,
    ("PLANT_SbwTorques", "AligningTorque"): PLANT_SBW_TORQUE,
    ("PLANT_SbwSensors", "HandWheelSensor"): PLANT_SBW_SENSOR_ANGLE,
    ("PLANT_SbwSensors", "PinionSensor"): PLANT_SBW_SENSOR_ANGLE,
    ("IO_SbwHandWheel", "HandWheelSensor"): IO_SBW_ANGLE,
    ("IO_SbwHandWheel", "ColumnAngle"): IO_SBW_ANGLE,
    ("IO_SbwHandWheel", "TorsionBarTorque"): IO_SBW_TORSION_TORQUE,
    ("IO_SbwPinion", "PinionSensor"): IO_SBW_ANGLE,
    ("IO_SbwPinion", "ActuatorAngle"): IO_SBW_ANGLE,
    ("IO_SbwCurrents", "RoadFeelMotorCurrent"): SBW_ROAD_FEEL_CURRENT,
    ("IO_SbwCurrents", "SteerMotorCurrent"): SBW_STEER_MOTOR_CURRENT,
    **{("ABS_WheelSpeeds", f"WheelSpeed{w}"): ABS_WHEEL_SPEED for w in _WHEELS},
    ("ABS_SteerState", "RefVehicleSpeed"): ABS_REF_SPEED,
    ("ABS_SteerState", "FrontWheelAngleEst"): ABS_ANGLE,
    ("PLANT_AbsVehicle", "VehicleSpeed"): PLANT_ABS_SPEED,
    ("PLANT_AbsVehicle", "FrontWheelAngle"): PLANT_ABS_ANGLE,
    ("PLANT_AbsVehicle", "MasterPressure"): PLANT_ABS_PRESSURE,
    **{(f"PLANT_AbsWheel_{w}", "WheelSpeed"): PLANT_ABS_WHEEL_SPEED for w in _WHEELS},
    **{(f"PLANT_AbsWheel_{w}", "Slip"): PLANT_ABS_SLIP for w in _WHEELS},
    **{(f"PLANT_AbsWheel_{w}", "BrakePressure"): PLANT_ABS_PRESSURE for w in _WHEELS},
    **{(f"PLANT_AbsWheel_{w}", "NormalLoad"): PLANT_ABS_LOAD for w in _WHEELS},
    **{("IO_AbsSensors", f"WheelSensor{w}"): IO_ABS_WHEEL_SENSOR for w in _WHEELS},
    **{("IO_AbsValves", f"InletDuty{w}"): IO_ABS_INLET_DUTY for w in _WHEELS},
}


def clamp(value: float, bounds: tuple[float, float]) -> float:
    """value limited to bounds; a NaN (a bug upstream, never expected) becomes 0 so the bus never sees it."""
    lo, hi = bounds
    if value != value:
        return 0.0
    return lo if value < lo else hi if value > hi else value


def finite(*values: float) -> bool:
    """True when every value is a finite number."""
    isfinite = math.isfinite
    try:
        for v in values:
            if not isfinite(v):
                return False
    except TypeError:
        return False
    return True
