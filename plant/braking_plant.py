"""The PLANT node of vehicle ACLASS_ABS: the braking vehicle (plant/braking_vehicle.py), its brake hydraulics
(plant/brakes.py) and wheel-speed sensors (plant/sensors.py), driven from the bus; ground truth out.

Inputs (io.latest; a timed-out message keeps its last value, the driver does not vanish with a frame):
  - DRV_Steering.HandWheelAngle (the hand-wheel sensor, positive right): road-wheel angle of both front wheels
    = HandWheelAngle / hand_wheel_ratio (18, [P4] §4), a rigid mechanical linkage (no lag; the stimulus
    shapes the steering). BENCH_SteeringRobot is not used by this vehicle.
  - DRV_Pedals: brake demand (plant/brakes.py: BrakePressure, else BrakePedal x 1.5 bar/%), AccelPedal x
    max_drive_torque on the front axle.
  - BENCH_AbsStimulus (dbc/bench.dbc): CruiseSpeed > 0: a drive robot holds that speed (km/h, true speed)
    with the accelerator while the master pressure is below 0.5 bar (steady-state circular tests, [P4]
    §4); ValveBypass = 1: the hydraulic unit ignores the ABS valves (the locked-wheel reference run).
  - BENCH_AbsSensorFault (dbc/bench.dbc): a fault of one wheel-speed sensor (plant/sensors.py), on the simulated
    ABS's wires and on IO_AbsSensors alike; absent or timed out: none.
  - IO_AbsValves, only while the ABS is external (docs/contract/plant.md PLANT-IO-ABS-02): the valve commands
    of the external ABS, applied from the tick after a valid frame arrived and held; none valid for 15 ms (the
    message's timeout), or none yet: RELEASED, the valves unpowered.
  - BENCH_Control: a change of ScenarioId (the first one seen included) resets the world and every linked
    behaviour (the in-process ABS ECU): straight ahead at InitialSpeed, wheels free rolling, brakes
    released; RoadMu (tyre set, plant/braking_vehicle.road_shape) and SensorNoise (plant/sensors.py) are taken
    then and whenever they change. PLANT_Status.ScenarioIdAck echoes the id (the scenario protocol, plant/scenario.py).

Ground truth (dbc/bench.dbc): PLANT_Position (geometric centre = mid-point of the axles, start frame of
docs/spec/formulas.md §1), PLANT_Motion (Heading, Speed of the geometric centre, YawRate positive right),
PLANT_Dynamics (Sideslip at the CoG positive right, LatAccel positive right, LongAccel), PLANT_Status
(Vehicle 2 = ACLASS_ABS), and [P4]'s truth: PLANT_AbsVehicle (CoG speed over ground in km/h, front
road-wheel angle positive right, master pressure, bypass) and PLANT_AbsWheel_xx (true circumferential
speed, braking slip positive when braking, wheel pressure, normal load). All clamped to the DBC ranges, and
sampled every 10 ms at the ABS ECU's update instants (PUBLISH_MS), plus at once after a scenario reset.

Bench I/O of an external ABS (docs/contract/plant.md PLANT-IO-ABS-01): IO_AbsSensors, the sensor model's readings
sampled every 5 ms in the tick the frame goes out (SENSOR_PHASE_MS), so a reading is never older than its frame.
With the simulated ABS the plant sends no I/O: the ECU reads the sensors and sets the valves through its wires
(read_sensors, command_valves, release_valves).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from bench.sim.node import Behaviour, NodeIO
from plant import signal_ranges as ranges
from plant.brakes import BrakeHydraulics, Valve
from plant.braking_vehicle import KMH, BrakingVehicle, VehicleSpec
from plant.scenario import ScenarioTracker
from plant.sensors import WheelSpeedSensors
from plant.vehicles import AbsParams, AclassParams

_DEG = 180.0 / math.pi
CORNERS = ("FL", "FR", "RL", "RR")
CRUISE_RELEASE_BAR = 0.5
#: ground truth is sampled every 10 ms at bench times that are multiples of 10 ms: the instants at which the ABS
#: ECU updates its outputs (plant/ecus/abs.py), so truth and estimate are compared at the same instant; every
#: PLANT message has a cycle of 10 ms or more (dbc/bench.dbc)
PUBLISH_MS = 10
WHEEL_MESSAGES = tuple(f"PLANT_AbsWheel_{c}" for c in CORNERS)
#: IO_AbsSensors (dbc/bench.dbc): every 5 ms; the restbus sends a message at the ticks id mod cycle + k cycle
#: (0x6D0 mod 5 = 4 ms), so the plant samples the sensors in those ticks (before the frame is built)
SENSOR_PERIOD_MS, SENSOR_PHASE_MS = 5, 0x6D0 % 5
SENSOR_SIGNALS = tuple(f"WheelSensor{c}" for c in CORNERS)
VALVE_SIGNALS = tuple(f"Valve{c}" for c in CORNERS)
DUTY_SIGNALS = tuple(f"InletDuty{c}" for c in CORNERS)
RELEASED = 3          # IO_AbsValves.ValveXX: unpowered (the value table's fourth entry; plant/brakes.Valve has three)


def vehicle_spec(car: AclassParams, abs_params: AbsParams) -> VehicleSpec:
    return VehicleSpec(
        mass=car.mass, yaw_inertia=car.yaw_inertia, cog_to_front_axle=car.cog_to_front_axle,
        cog_to_rear_axle=car.cog_to_rear_axle, track=car.track, wheel_radius=car.wheel_radius,
        cog_height=car.cog_height, cornering_stiffness_front=car.cornering_stiffness_front,
        cornering_stiffness_rear=car.cornering_stiffness_rear, wheel_inertia=abs_params.wheel_inertia,
        lateral_c=abs_params.lateral_c, lateral_e=abs_params.lateral_e,
        slip_speed_floor=abs_params.slip_speed_floor, load_transfer_lag=abs_params.load_transfer_lag,
        stop_speed=abs_params.stop_speed)


class BrakingPlantNode:
    """Node PLANT of ACLASS_ABS; also the ABS ECU's hardware (sensors and valves, plant/ecus/abs.AbsHardware)."""

    nodes: tuple[str, ...] = ("PLANT",)

    def __init__(self, car: AclassParams, abs_params: AbsParams, *, vehicle_code: int,
                 external_abs: bool = False) -> None:
        self.params = abs_params
        self.external_abs = external_abs     # the ABS is a real ECU on the bench I/O (IO_AbsSensors, IO_AbsValves)
        self.vehicle = BrakingVehicle(vehicle_spec(car, abs_params))
        self.hydraulics = BrakeHydraulics(
            inlet_flow=abs_params.inlet_flow, outlet_flow=abs_params.outlet_flow,
            gain_front=abs_params.brake_gain_front, gain_rear=abs_params.brake_gain_rear,
            master_rate=abs_params.master_rate, pedal_to_pressure=abs_params.pedal_to_pressure,
            max_pressure=abs_params.max_pressure)
        self.sensors = WheelSpeedSensors(quantum=abs_params.sensor_quantum, roughness_ratio=abs_params.roughness_ratio,
                                         roughness_time=abs_params.roughness_time, seed=int(abs_params.noise_seed))
        self.linked: tuple[Behaviour, ...] = ()
        self.scenario = ScenarioTracker(vehicle_code)
        self._ratio = abs_params.hand_wheel_ratio
        self._gc = (car.cog_to_front_axle - car.cog_to_rear_axle) / 2.0   # geometric centre ahead of the CoG, m
        self.reset()

    def reset(self) -> None:
        self.vehicle.reset()
        self.hydraulics.reset()
        self.sensors.reset()
        self.scenario.reset()
        self._mu = math.nan
        self._hand_wheel = 0.0
        self._demand = 0.0
        self._accel = 0.0
        self._ack_due = True

    # -- the ABS ECU's wiring -------------------------------------------------------------------------------
    def read_sensors(self, dt: float) -> list[float]:
        return self.sensors.sample(self.vehicle.wheel_speeds_kmh(), dt)

    def command_valves(self, valves: Sequence[Valve], duties: Sequence[float]) -> None:
        self.hydraulics.command(valves, duties)

    def release_valves(self) -> None:
        self.hydraulics.release()

    # -- per tick ---------------------------------------------------------------------------------------------
    def _restart(self, control: Mapping[str, float], t: float, dt: float) -> None:
        v0 = control.get("InitialSpeed", 0.0)
        self.vehicle.reset(v0 if ranges.finite(v0) else 0.0)
        self.hydraulics.reset()
        self._mu = math.nan
        self._apply_control(control, force=True)
        for behaviour in self.linked:
            behaviour.reset()
        self._hand_wheel = self._demand = self._accel = 0.0
        self._ack_due = True

    def _apply_control(self, control: Mapping[str, float], force: bool = False) -> None:
        mu = control.get("RoadMu", 1.0)
        if force or mu != self._mu:
            self._mu = mu
            self.vehicle.set_road(mu if ranges.finite(mu) else 1.0)
        noise = control.get("SensorNoise", 0.0)
        if force:
            self.sensors.reset(noise if ranges.finite(noise) else 0.0)
        elif noise != self.sensors.noise and ranges.finite(noise) and noise >= 0.0:
            self.sensors.noise = noise

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        started = self.scenario.poll(io, t, dt)
        control = self.scenario.control
        if control is not None:
            if started:
                self._restart(control, t, dt)
            else:
                self._apply_control(control)
        p = self.params
        steering = io.latest("DRV_Steering")
        if steering is not None:
            hw = steering.get("HandWheelAngle", math.nan)
            if ranges.finite(hw):
                self._hand_wheel = hw
        pedals = io.latest("DRV_Pedals")
        if pedals is not None:
            demand = self.hydraulics.demand(pedals.get("BrakePressure", math.nan), pedals.get("BrakePedal", math.nan))
            accel = pedals.get("AccelPedal", 0.0)
            self._demand = demand
            self._accel = accel if ranges.finite(accel) and accel > 0.0 else 0.0
        fault = io.latest("BENCH_AbsSensorFault")
        if fault is None:
            self.sensors.set_fault(0, 0)
        else:
            self.sensors.set_fault(fault.get("FaultWheel", 0.0), fault.get("SensorFault", 0.0))
        if self.external_abs:
            self._apply_valves(io.latest("IO_AbsValves"))
        stimulus = io.latest("BENCH_AbsStimulus")
        cruise = bypass = 0.0
        if stimulus is not None:
            cruise = stimulus.get("CruiseSpeed", 0.0)
            bypass = stimulus.get("ValveBypass", 0.0)
        hyd, veh = self.hydraulics, self.vehicle
        hyd.bypass = bypass == 1
        hyd.step(self._demand, dt)
        drive = min(self._accel, 100.0) / 100.0 * p.max_drive_torque
        if ranges.finite(cruise) and cruise > 0.0 and hyd.master < CRUISE_RELEASE_BAR:
            drive += p.cruise_gain * (cruise - veh.speed * KMH)
        veh.drive_torque = 0.0 if drive < 0.0 else p.max_drive_torque if drive > p.max_drive_torque else drive
        veh.delta = -self._hand_wheel / self._ratio / _DEG          # bus positive right -> internal left
        veh.brake_torque = hyd.torques()
        veh.step(dt)
        ms = round(t * 1000.0)
        if self.external_abs and ms % SENSOR_PERIOD_MS == SENSOR_PHASE_MS:
            readings = self.sensors.sample(veh.wheel_speeds_kmh(), SENSOR_PERIOD_MS / 1000.0)
            io.send_values("IO_AbsSensors", **dict(zip(SENSOR_SIGNALS, readings, strict=True)))
        if ms % PUBLISH_MS == 0 or self._ack_due:
            self._ack_due = False
            self._publish(io, t)

    def _apply_valves(self, frame: Mapping[str, float] | None) -> None:
        """An external ABS's IO_AbsValves (the latest valid frame, None when timed out or never received):
        RELEASED (3) or no frame = valves unpowered."""
        hyd = self.hydraulics
        if frame is None:
            hyd.release()
            return
        codes = [frame.get(name, RELEASED) for name in VALVE_SIGNALS]
        if all(code == RELEASED for code in codes):
            hyd.release()
            return
        valves, duties = [], []
        for code, name in zip(codes, DUTY_SIGNALS, strict=True):
            if code == RELEASED or code not in (0, 1, 2):
                valves.append(Valve.INCREASE)
                duties.append(1.0)
            else:
                valves.append(Valve(int(code)))
                duties.append(frame.get(name, 1.0))
        hyd.command(valves, duties)

    def _publish(self, io: NodeIO, t: float) -> None:
        veh, hyd = self.vehicle, self.hydraulics
        clamp = ranges.clamp
        c, s = math.cos(veh.psi), math.sin(veh.psi)
        gx, gy = veh.x + self._gc * c, veh.y + self._gc * s          # geometric centre, internal world frame
        v_gc = veh.v + veh.r * self._gc
        io.send_values("PLANT_Position", PosX=clamp(-gy, ranges.PLANT_POS), PosY=clamp(gx, ranges.PLANT_POS))
        heading = (-veh.psi * _DEG + 180.0) % 360.0 - 180.0
        io.send_values("PLANT_Motion", Heading=clamp(heading, ranges.PLANT_HEADING),
                       Speed=clamp(math.hypot(veh.u, v_gc), ranges.PLANT_SPEED),
                       YawRate=clamp(-veh.r * _DEG, ranges.PLANT_YAW_RATE))
        io.send_values("PLANT_Dynamics", Sideslip=clamp(-veh.sideslip * _DEG, ranges.PLANT_SIDESLIP),
                       LatAccel=clamp(-veh.lat_accel, ranges.PLANT_ACCEL),
                       LongAccel=clamp(veh.long_accel, ranges.PLANT_ACCEL))
        self.scenario.acknowledge(io, t)
        io.send_values("PLANT_AbsVehicle", VehicleSpeed=clamp(veh.speed * KMH, ranges.PLANT_ABS_SPEED),
                       FrontWheelAngle=clamp(-veh.delta * _DEG, ranges.PLANT_ABS_ANGLE),
                       MasterPressure=clamp(hyd.master, ranges.PLANT_ABS_PRESSURE), ValveBypass=1 if hyd.bypass else 0)
        speeds = veh.wheel_speeds_kmh()
        for i, message in enumerate(WHEEL_MESSAGES):
            io.send_values(message, WheelSpeed=clamp(speeds[i], ranges.PLANT_ABS_WHEEL_SPEED),
                           Slip=clamp(-veh.kappa[i], ranges.PLANT_ABS_SLIP),
                           BrakePressure=clamp(hyd.pressures[i], ranges.PLANT_ABS_PRESSURE),
                           NormalLoad=clamp(veh.fz[i], ranges.PLANT_ABS_LOAD))
