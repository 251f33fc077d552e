"""Vehicle "ACLASS": the A-class car of docs/spec/vehicles.md B with front steer-by-wire ([P1]) on the linear
single-track model (docs/spec/formulas.md §5), as bus nodes.

Behaviours, stepped in this order every plant tick:
1. PLANT (`AclassPlant`): the physical world. It takes the steering robot's command (BENCH_SteeringRobot)
   and the injected sensor faults (BENCH_SbwSensorFault), moves the SBW mechanics (plant/sbw.py) in
   substeps during which the motor controller runs: the SBW ECU's fast loops (plant/ecus/sbw.py, `control`),
   or with an external SBW the rig's actuator emulation driven by IO_SbwActuators (plant/sbw.py,
   `ActuatorEmulation`), then the vehicle with the road-wheel angle pinion/15 (plant/single_track.py; ISO
   inside, bus signs outside), and publishes ground truth: PLANT_Position/Motion/Dynamics/Status and
   PLANT_SbwAngles/Torques/Sensors; with an external SBW also its sensor I/O, IO_SbwHandWheel/Pinion/Currents,
   sampled every 5 ms (docs/contract/plant.md PLANT-IO-SBW-02).
2. SBW (`SbwEcu`): reads its bus inputs, runs the yaw-rate feedback, publishes SBW_HandWheel/SBW_Pinion.
3. IMU (plant/ecus/imu.py): IMU_Motion from the vehicle's true motion.
4. ABS (`WheelSpeedSensors`): ABS_WheelSpeeds from the vehicle's motion (this car has no ABS function;
   its ABS node reports the wheel speeds, which the SBW ECU needs for the vehicle speed). ABS_SteerState
   stays at its start values.

Scenario: whenever BENCH_Control.ScenarioId changes (the first one seen included) everything resets and
the car drives straight at BENCH_Control.InitialSpeed, which this model holds constant (no longitudinal
dynamics: LongAccel is 0); PLANT_Status.ScenarioIdAck echoes the id (the scenario protocol,
plant/scenario.py). RoadMu and SensorNoise do not affect the linear model.

External nodes: with SBW external the mechanics are simulated as with the reference SBW and the real ECU drives
them through the bench I/O (docs/contract/plant.md, "Bench I/O — SBW"): it reads the sensors and sends a position
request to the steering actuator and a torque request to the road-feel motor. With PLANT external
nothing of the physics runs here: the simulated SBW ECU, whose loops run inside the plant's time step, is
left out too. IMU and ABS external: not built.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence

from bench.sim.node import Behaviour, NodeIO
from plant import signal_ranges as ranges
from plant.declaration import Vehicle
from plant.driver import SteeringRobot
from plant.ecus.imu import Imu
from plant.ecus.sbw import SbwEcu
from plant.sbw import IO_CYCLE, ActuatorEmulation, SbwMechanics, SbwSensors
from plant.scenario import ScenarioTracker
from plant.single_track import SingleTrack, SingleTrackParams
from plant.vehicles import PARAMETER_FILES, AclassParams, SbwParams

_DEG = 180.0 / math.pi
_RAD = math.pi / 180.0
_KMH = 3.6

NAME, CODE = "ACLASS", 1     # BENCH_Control.Vehicle value table
PARAMETERS = (PARAMETER_FILES["ACLASS"], PARAMETER_FILES["SBW"])


#: What this vehicle's network carries from the plant's side (plant/factory.py stops the rest): the SBW ECU,
#: the IMU, the ABS node (wheel speeds; ABS_SteerState at its start values), the body's and the SBW's ground truth.
MESSAGES = frozenset({
    "SBW_HandWheel", "SBW_Pinion", "IMU_Motion", "ABS_WheelSpeeds", "ABS_SteerState",
    "PLANT_Status", "PLANT_Position", "PLANT_Motion", "PLANT_Dynamics",
    "PLANT_SbwAngles", "PLANT_SbwTorques", "PLANT_SbwSensors",
})

#: Its bench I/O (docs/contract/plant.md PLANT-IO-SBW-01): on the bus only while the SBW is external.
IO = {"SBW": frozenset({"IO_SbwHandWheel", "IO_SbwPinion", "IO_SbwCurrents", "IO_SbwActuators"})}

#: What its behaviours read of the stimulus: the steering robot and the sensor faults (the SBW's coding is
#: diagnostic, docs/contract/sbw.md SBW-DIAG-02).
STIMULUS = ("BENCH_SteeringRobot", "BENCH_SbwSensorFault")


def single_track_params(p: AclassParams) -> SingleTrackParams:
    """docs/spec/vehicles.md B as the §5 model's parameters."""
    return SingleTrackParams(p.mass, p.yaw_inertia, p.cog_to_front_axle, p.cog_to_rear_axle,
                             p.cornering_stiffness_front, p.cornering_stiffness_rear)


class AclassPlant:
    """The PLANT node of ACLASS (see the module docstring)."""

    nodes: tuple[str, ...] = ("PLANT",)

    def __init__(self, vehicle: AclassParams, sbw: SbwParams, ecu: SbwEcu | None,
                 linked: Sequence[Behaviour] = (), *, vehicle_code: int) -> None:
        self.vehicle_params = vehicle
        self.model = SingleTrack(single_track_params(vehicle))
        self.ecu = ecu
        self.mechanics = SbwMechanics(sbw)
        # the motor controller: the reference ECU's fast loops, or the rig's actuators for an external SBW
        self.emulation = ActuatorEmulation(self.mechanics) if ecu is None else None
        self.robot = SteeringRobot(sbw)
        self.sensors = SbwSensors()
        self.control_rate = sbw.control_rate
        self.ratio = sbw.steering_ratio
        self.linked = tuple(linked)
        self.scenario = ScenarioTracker(vehicle_code)
        self.reset()

    def reset(self) -> None:
        self.scenario.reset()
        self._reset_world()

    def _reset_world(self) -> None:
        self.model.reset(0.0)
        self.mechanics.reset()
        if self.emulation is not None:
            self.emulation.reset()
        self.robot.reset()
        self.x = self.y = 0.0               # world position of the CoG, m (start frame, docs/spec/formulas.md §1)

    def _restart(self, control: Mapping[str, float], t: float, dt: float) -> None:
        for behaviour in self.linked:
            behaviour.reset()
        self._reset_world()
        speed = control.get("InitialSpeed", 0.0)
        self.model.reset(speed if ranges.finite(speed) and speed > 0.0 else 0.0)

    # -- bus signs of the vehicle's state ---------------------------------------------------------------
    @property
    def yaw_rate_dps(self) -> float:
        """Yaw rate, deg/s, positive clockwise (right turn) — also read by the IMU."""
        return -self.model.yaw_rate * _DEG

    @property
    def lat_accel(self) -> float:
        """Lateral acceleration, m/s², positive to the right (as plant.body.PlanarBody, which the IMU reads)."""
        return -self.model.lat_accel

    @property
    def long_accel(self) -> float:
        """Longitudinal acceleration, m/s²: 0, the speed is held."""
        return 0.0

    @property
    def road_wheel_angle(self) -> float:
        """Front road-wheel angle, rad, bus signs."""
        return self.mechanics.road_wheel_angle

    # -- tick -------------------------------------------------------------------------------------------------
    def step(self, io: NodeIO, t: float, dt: float) -> None:
        scenario = self.scenario
        if scenario.poll(io, t, dt) and scenario.control is not None:
            self._restart(scenario.control, t, dt)
        self.robot.command(io.latest("BENCH_SteeringRobot"))
        model = self.model
        mech = self.mechanics
        fault = io.latest("BENCH_SbwSensorFault")
        if fault is not None and ranges.finite(fault.get("SensorFault", 0.0), fault.get("SensorOffset", 0.0)):
            mech.set_sensor_fault(int(fault["SensorFault"]), fault["SensorOffset"] * _RAD)
        else:
            mech.set_sensor_fault(0)
        self._load_front_axle(mech)
        substeps = max(1, math.ceil(dt * self.control_rate - 1e-9))
        emulation = self.emulation
        if emulation is not None:
            emulation.take(io.latest("IO_SbwActuators"))
            mech.advance(dt, emulation, self.robot, self.sensors, substeps)
        else:
            assert self.ecu is not None
            mech.advance(dt, self.ecu, self.robot, self.sensors, substeps)
        model.step(dt, -self.road_wheel_angle)
        self._move(dt)
        self._publish(io, t)
        if emulation is not None and abs(t - round(t / IO_CYCLE) * IO_CYCLE) < 1e-7:
            self._publish_io(io)

    def _load_front_axle(self, mech: SbwMechanics) -> None:
        """The front tyre force on the rack (eq. 10) from the vehicle's state, bus signs."""
        model, p = self.model, self.vehicle_params
        if model.kinematic:
            mech.set_front_axle(0.0, 0.0, -model.front_lateral_force)
        else:
            slip_offset = -(model.beta + p.cog_to_front_axle * model.yaw_rate / model.speed)
            mech.set_front_axle(p.cornering_stiffness_front, slip_offset)

    def _move(self, dt: float) -> None:
        """CoG position in the start frame: velocity direction = heading + sideslip (clockwise from +Y)."""
        model = self.model
        direction = -(model.yaw_angle + model.beta)
        speed = model.speed / math.cos(model.beta) if abs(model.beta) < 1.5 else model.speed
        self.x += speed * math.sin(direction) * dt
        self.y += speed * math.cos(direction) * dt

    def _publish(self, io: NodeIO, t: float) -> None:
        # every value limited to its ranges.* bounds, NaN (never expected) sent as 0: ranges.clamp written out
        # (hot: 14 values every tick)
        model = self.model
        x, y = self.x, self.y
        lo, hi = ranges.PLANT_POS
        x = 0.0 if x != x else lo if x < lo else hi if x > hi else x
        y = 0.0 if y != y else lo if y < lo else hi if y > hi else y
        io.send_values("PLANT_Position", PosX=x, PosY=y)
        heading = (-model.yaw_angle * _DEG + 180.0) % 360.0 - 180.0
        lo, hi = ranges.PLANT_HEADING
        heading = 0.0 if heading != heading else lo if heading < lo else hi if heading > hi else heading
        speed = model.speed
        lo, hi = ranges.PLANT_SPEED
        speed = 0.0 if speed != speed else lo if speed < lo else hi if speed > hi else speed
        yaw = self.yaw_rate_dps
        lo, hi = ranges.PLANT_YAW_RATE
        yaw = 0.0 if yaw != yaw else lo if yaw < lo else hi if yaw > hi else yaw
        io.send_values("PLANT_Motion", Heading=heading, Speed=speed, YawRate=yaw)
        slip = -model.beta * _DEG
        lo, hi = ranges.PLANT_SIDESLIP
        slip = 0.0 if slip != slip else lo if slip < lo else hi if slip > hi else slip
        lat = self.lat_accel
        lo, hi = ranges.PLANT_ACCEL
        lat = 0.0 if lat != lat else lo if lat < lo else hi if lat > hi else lat
        io.send_values("PLANT_Dynamics", Sideslip=slip, LatAccel=lat, LongAccel=0.0)
        self.scenario.acknowledge(io, t)
        mech = self.mechanics
        s = self.sensors
        mech.read(s)
        lo, hi = ranges.PLANT_SBW_ANGLE
        hand, pinion = mech.theta_h * _DEG, mech.theta_p * _DEG
        hand = 0.0 if hand != hand else lo if hand < lo else hi if hand > hi else hand
        pinion = 0.0 if pinion != pinion else lo if pinion < lo else hi if pinion > hi else pinion
        io.send_values("PLANT_SbwAngles", HandWheelAngle=hand, PinionAngle=pinion)
        lo, hi = ranges.PLANT_SBW_TORQUE
        driver, feel, aligning = mech.driver_torque, mech.road_feel_torque, mech.aligning_torque
        driver = 0.0 if driver != driver else lo if driver < lo else hi if driver > hi else driver
        feel = 0.0 if feel != feel else lo if feel < lo else hi if feel > hi else feel
        aligning = 0.0 if aligning != aligning else lo if aligning < lo else hi if aligning > hi else aligning
        io.send_values("PLANT_SbwTorques", DriverTorque=driver, RoadFeelTorque=feel, AligningTorque=aligning)
        lo, hi = ranges.PLANT_SBW_SENSOR_ANGLE
        hand, pinion = s.hand_wheel * _DEG, s.pinion * _DEG
        hand = 0.0 if hand != hand else lo if hand < lo else hi if hand > hi else hand
        pinion = 0.0 if pinion != pinion else lo if pinion < lo else hi if pinion > hi else pinion
        io.send_values("PLANT_SbwSensors", HandWheelSensor=hand, PinionSensor=pinion)


    def _publish_io(self, io: NodeIO) -> None:
        """The external SBW's sensors, sampled now (a multiple of 5 ms): PLANT-IO-SBW-02. `self.sensors` holds the
        reading `_publish` just took; every value limited to its signal's range (a reading beyond reads the end)."""
        s, mech = self.sensors, self.mechanics
        lo, hi = ranges.IO_SBW_ANGLE
        hand, column = s.hand_wheel * _DEG, s.column * _DEG
        hand = 0.0 if hand != hand else lo if hand < lo else hi if hand > hi else hand
        column = 0.0 if column != column else lo if column < lo else hi if column > hi else column
        torque = s.torsion_torque
        tlo, thi = ranges.IO_SBW_TORSION_TORQUE
        torque = 0.0 if torque != torque else tlo if torque < tlo else thi if torque > thi else torque
        io.send_values("IO_SbwHandWheel", HandWheelSensor=hand, ColumnAngle=column, TorsionBarTorque=torque)
        pinion, actuator = s.pinion * _DEG, s.motor_pinion * _DEG
        pinion = 0.0 if pinion != pinion else lo if pinion < lo else hi if pinion > hi else pinion
        actuator = 0.0 if actuator != actuator else lo if actuator < lo else hi if actuator > hi else actuator
        io.send_values("IO_SbwPinion", PinionSensor=pinion, ActuatorAngle=actuator)
        i_m, i_M = mech.i_m, mech.i_M
        lo, hi = ranges.SBW_ROAD_FEEL_CURRENT
        i_m = 0.0 if i_m != i_m else lo if i_m < lo else hi if i_m > hi else i_m
        lo, hi = ranges.SBW_STEER_MOTOR_CURRENT
        i_M = 0.0 if i_M != i_M else lo if i_M < lo else hi if i_M > hi else i_M
        io.send_values("IO_SbwCurrents", RoadFeelMotorCurrent=i_m, SteerMotorCurrent=i_M)


class WheelSpeedSensors:
    """Node ABS of ACLASS: ABS_WheelSpeeds (circumferential speeds, km/h) from the vehicle's rigid motion.

    Contact velocity of wheel i at (x_i, y_i) from the CoG (ISO: x forward, y left):
    (u − r y_i, u β + r x_i); a wheel's circumferential speed is its projection on the wheel heading
    (front wheels turned by δ_f, rear straight)."""

    nodes: tuple[str, ...] = ("ABS",)

    def __init__(self, plant: AclassPlant, vehicle: AclassParams) -> None:
        self.plant = plant
        half = vehicle.track / 2.0
        a, b = vehicle.cog_to_front_axle, vehicle.cog_to_rear_axle
        self.positions = (("FL", a, half, True), ("FR", a, -half, True),
                          ("RL", -b, half, False), ("RR", -b, -half, False))
        self._signals = tuple(f"WheelSpeed{name}" for name, *_ in self.positions)

    def reset(self) -> None:
        pass

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        model = self.plant.model
        u, r = model.speed, model.yaw_rate
        v = u * math.tan(model.beta)
        delta = -self.plant.road_wheel_angle          # ISO
        c, s = math.cos(delta), math.sin(delta)
        out = {}
        lo, hi = ranges.ABS_WHEEL_SPEED
        for signal, (_, x, y, steered) in zip(self._signals, self.positions):
            vx, vy = u - r * y, v + r * x
            speed = abs(vx * c + vy * s if steered else vx) * _KMH
            out[signal] = 0.0 if speed != speed else lo if speed < lo else hi if speed > hi else speed   # ranges.clamp
        io.send_values("ABS_WheelSpeeds", **out)


def build(external: Collection[str]) -> list[Behaviour]:
    """The ACLASS behaviours not in `external`, in step order (module docstring)."""
    vehicle, sbw = (parameters.load() for parameters in PARAMETERS)
    behaviours: list[Behaviour] = []
    if "PLANT" in external:
        if "IMU" not in external:
            behaviours.append(Imu(None))
        return behaviours
    ecu = SbwEcu(sbw) if "SBW" not in external else None
    plant = AclassPlant(vehicle, sbw, ecu, vehicle_code=CODE)
    behaviours.append(plant)
    linked: list[Behaviour] = []
    if ecu is not None:
        behaviours.append(ecu)
        linked.append(ecu)
    if "IMU" not in external:
        imu = Imu(plant)   # a MotionSource: yaw_rate_dps, lat_accel, long_accel as plant.body.PlanarBody
        behaviours.append(imu)
        linked.append(imu)
    if "ABS" not in external:
        wheels = WheelSpeedSensors(plant, vehicle)
        behaviours.append(wheels)
        linked.append(wheels)
    plant.linked = tuple(linked)
    return behaviours


VEHICLE = Vehicle(name=NAME, code=CODE, build=build, parameters=PARAMETERS, messages=MESSAGES, stimulus=STIMULUS,
                  io=IO)
