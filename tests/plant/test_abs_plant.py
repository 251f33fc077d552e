"""The ACLASS_ABS plant without the bus: vehicle physics (plant/braking_vehicle.py), brake hydraulics
(plant/brakes.py), wheel-speed sensors (plant/sensors.py), the PLANT and ABS nodes on a fake NodeIO
(scenario reset and acknowledgement, faults, never a NaN or out-of-range value), and the cost of a tick."""

from __future__ import annotations

import math
import statistics
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bench.sim.testing import MemoryIO
from plant import signal_ranges
from plant.assemblies.aclass_abs import build
from plant.brakes import BrakeHydraulics, Valve
from plant.braking_plant import vehicle_spec
from plant.braking_vehicle import BrakingVehicle
from plant.ecus.abs import AbsEcu, AbsFault
from plant.factory import assemble
from plant.sensors import WheelSpeedSensors
from plant.vehicles import load_parameters

DT = 1e-3
CAR, PARAMS = load_parameters("ACLASS"), load_parameters("ABS")
G = 9.81


def mf(x: float, b: float, c: float, d: float, e: float) -> float:
    return d * math.sin(c * math.atan(b * x - e * (b * x - math.atan(b * x))))


def vehicle(speed: float = 0.0, mu: float = 1.0) -> BrakingVehicle:
    v = BrakingVehicle(vehicle_spec(CAR, PARAMS))
    v.set_road(mu)
    v.reset(speed)
    return v


# -- vehicle -------------------------------------------------------------------------------------------------

def test_free_rolling_keeps_its_speed_and_the_static_loads_carry_the_car() -> None:
    v = vehicle(20.0)
    for _ in range(2000):
        v.step(DT)
    assert v.speed == pytest.approx(20.0, rel=1e-6)
    assert sum(v.fz) == pytest.approx(CAR.mass * G, rel=1e-9)
    front = CAR.mass * G * CAR.cog_to_rear_axle / CAR.wheelbase
    assert v.fz[0] + v.fz[1] == pytest.approx(front, rel=1e-9)
    assert v.wheel_speeds_kmh() == pytest.approx([72.0] * 4, rel=1e-6)


@pytest.mark.parametrize("mu,bcde", [(1.0, (10, 1.9, 1.0, 0.97)), (0.82, (12, 2.3, 0.82, 1.0))], ids=["dry", "wet"])
def test_locked_wheels_decelerate_at_the_sliding_friction(mu: float, bcde: tuple) -> None:
    v = vehicle(25.0, mu)
    v.brake_torque = (5000.0,) * 4
    for _ in range(300):
        v.step(DT)
    assert all(w == 0.0 for w in v.omega)
    assert -v.long_accel == pytest.approx(mf(1.0, *bcde) * G, rel=1e-6)
    # load transfer to the front: m a h / L (docs/spec/vehicles.md B, h_cg 0.55 m), after the suspension lag
    shift = CAR.mass * -v.long_accel * CAR.cog_height / CAR.wheelbase
    static_front = CAR.mass * G * CAR.cog_to_rear_axle / CAR.wheelbase
    assert v.fz[0] + v.fz[1] == pytest.approx(static_front + shift, rel=1e-3)


def test_steady_turn_matches_the_linear_2dof_gain_at_low_lateral_acceleration() -> None:
    v = vehicle(25 / 3.6)
    v.delta = math.radians(3.0)
    for _ in range(4000):
        v.drive_torque = max(0.0, 400.0 * (25.0 - v.speed * 3.6))
        v.step(DT)
    x = v.u
    k = 1.90e-3                                      # docs/spec/vehicles.md B
    expected = x / CAR.wheelbase / (1 + k * x * x) * v.delta      # docs/spec/formulas.md §6 eq. 11
    assert v.r == pytest.approx(expected, rel=0.02)
    assert v.r > 0 and v.lat_accel > 0                      # left turn positive in the internal frame


def test_the_car_stops_and_stays_stopped() -> None:
    v = vehicle(5.0)
    v.brake_torque = (800.0,) * 4
    for _ in range(3000):
        v.step(DT)
    assert v.stopped and v.speed == 0.0 and v.kappa == [0.0] * 4


# -- hydraulics ------------------------------------------------------------------------------------------------

def hydraulics() -> BrakeHydraulics:
    return BrakeHydraulics(inlet_flow=100.0, outlet_flow=150.0, gain_front=18.0, gain_rear=7.0, master_rate=1e9,
                           pedal_to_pressure=1.5, max_pressure=200.0)


def test_valves_increase_hold_decrease_at_finite_rates() -> None:
    h = hydraulics()
    h.step(100.0, DT)
    assert h.pressures[0] == pytest.approx(100.0 * math.sqrt(100.0) * DT)      # orifice: k sqrt(dp)
    h.command([Valve.HOLD, Valve.INCREASE, Valve.DECREASE, Valve.INCREASE], [1.0, 0.5, 1.0, 1.0])
    p0 = list(h.pressures)
    h.step(100.0, DT)
    assert h.pressures[0] == p0[0]
    assert h.pressures[1] - p0[1] == pytest.approx(0.5 * 100.0 * math.sqrt(100.0 - p0[1]) * DT)
    assert h.pressures[2] == pytest.approx(p0[2] - 150.0 * math.sqrt(p0[2]) * DT)
    for _ in range(2000):
        h.step(100.0, DT)
    assert h.pressures[3] == 100.0 and h.pressures[2] == 0.0      # never beyond the master, never below 0
    assert h.torques()[3] == 700.0
    h.bypass = True
    for _ in range(2000):
        h.step(100.0, DT)
    assert h.pressures == [100.0] * 4


def test_pedal_demand_and_bad_values() -> None:
    h = hydraulics()
    assert h.demand(80.0, 0.0) == 80.0 and h.demand(0.0, 40.0) == 60.0 and h.demand(math.nan, math.nan) == 0.0
    assert h.demand(500.0, 0.0) == 200.0
    with pytest.raises(ValueError, match="inlet_flow"):
        BrakeHydraulics(inlet_flow=0.0, outlet_flow=1.0, gain_front=1.0, gain_rear=1.0, master_rate=1.0,
                        pedal_to_pressure=1.0, max_pressure=1.0)


# -- sensors ------------------------------------------------------------------------------------------------------

def test_sensors_quantise_are_seeded_and_have_the_configured_noise() -> None:
    s = WheelSpeedSensors(quantum=0.05, roughness_ratio=0.5, roughness_time=0.05, seed=3)
    # exactly raw x scale, as the bus decodes ABS_WheelSpeeds (so a replay computes on the same floats)
    assert s.sample([50.012, 50.04, 0.0, -1.0], 0.005) == [1000 * 0.05, 1001 * 0.05, 0.0, 0.0]
    s.reset(0.2)
    first = [s.sample([60.0] * 4, 0.005) for _ in range(20000)]
    s.reset()
    assert [s.sample([60.0] * 4, 0.005) for _ in range(20000)] == first        # deterministic
    values = [v[0] for v in first]
    assert all(abs(v / 0.05 - round(v / 0.05)) < 1e-9 for v in values)
    # white noise 0.2 plus roughness 0.5 * 0.2: total std 0.2 sqrt(1 + 0.25), quantisation adds 0.05/sqrt(12)
    expected = math.sqrt(0.04 * 1.25 + 0.05 ** 2 / 12)
    assert statistics.pstdev(values) == pytest.approx(expected, rel=0.05)
    assert statistics.mean(values) == pytest.approx(60.0, abs=0.01)


# -- nodes on a fake bus ----------------------------------------------------------------------------------------

class Rig:
    def __init__(self, external: tuple[str, ...] = (), **control: float) -> None:
        self.io = MemoryIO(signal_ranges.BY_SIGNAL, loopback=False)
        self.behaviours = build(frozenset(external))
        self.tick = 0
        self.io.values["BENCH_Control"] = {"ScenarioId": 1, "RoadMu": 1.0, "InitialSpeed": 0.0, "SensorNoise": 0.1,
                                           "Vehicle": 2, **control}
        self.io.values["DRV_Pedals"] = {"AccelPedal": 0.0, "BrakePedal": 0.0, "BrakePressure": 0.0}
        self.io.values["DRV_Steering"] = {"HandWheelAngle": 0.0}

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / DT)):
            self.tick += 1
            self.io.t = self.tick * DT
            for b in self.behaviours:
                b.step(self.io, self.io.t, DT)


def test_factory_knows_the_vehicle_and_the_plant_acknowledges_the_scenario() -> None:
    assert [b.nodes for b in assemble("ACLASS_ABS", ())] == [("PLANT",), ("ABS",)]
    rig = Rig(InitialSpeed=10.0)
    rig.run(0.05)
    assert rig.io.sent["PLANT_Status"]["ScenarioIdAck"] == 1 and rig.io.sent["PLANT_Status"]["Vehicle"] == 2
    assert rig.io.sent["PLANT_AbsVehicle"]["VehicleSpeed"] == pytest.approx(36.0, abs=0.01)
    assert rig.io.sent["ABS_SteerState"]["AbsFault"] == 0
    rig.io.values["BENCH_Control"]["ScenarioId"] = 2
    rig.io.values["BENCH_Control"]["InitialSpeed"] = 0.0
    rig.run(0.02)
    assert rig.io.sent["PLANT_Status"]["ScenarioIdAck"] == 2
    assert rig.io.sent["PLANT_AbsVehicle"]["VehicleSpeed"] == 0.0


def test_abs_keeps_the_wheels_from_locking_and_external_abs_does_not() -> None:
    for external, locks in (((), False), (("ABS",), True)):
        rig = Rig(external, InitialSpeed=20.0)
        rig.run(0.1)
        rig.io.values["DRV_Pedals"]["BrakePressure"] = 150.0
        slips = []
        for _ in range(100):
            rig.run(0.01)
            if rig.io.sent["PLANT_AbsVehicle"]["VehicleSpeed"] > 20.0:
                slips.append(max(rig.io.sent[f"PLANT_AbsWheel_{w}"]["Slip"] for w in ("FL", "FR", "RL", "RR")))
        assert (max(slips[20:]) > 0.9) == locks


def test_pedals_timeout_is_a_fault_and_the_abs_goes_passive() -> None:
    rig = Rig(InitialSpeed=20.0)
    rig.run(0.05)
    del rig.io.values["DRV_Pedals"]
    rig.run(0.02)
    assert rig.io.sent["ABS_SteerState"]["AbsFault"] == AbsFault.INPUT_TIMEOUT
    assert rig.io.sent["ABS_SteerState"]["AbsActive"] == 0


class _DeadSensors:
    """Hardware whose FL sensor line is open: reads 0 while the car rolls."""

    def __init__(self) -> None:
        self.released = 0

    def read_sensors(self, dt: float) -> list[float]:
        return [0.0, 50.0, 50.0, 50.0]

    def command_valves(self, valves, duties) -> None:
        pass

    def release_valves(self) -> None:
        self.released += 1


def test_a_dead_wheel_speed_sensor_is_a_fault() -> None:
    hw = _DeadSensors()
    ecu = AbsEcu(PARAMS, CAR, hw)
    io = MemoryIO(signal_ranges.BY_SIGNAL, loopback=False)
    io.values["DRV_Pedals"] = {"AccelPedal": 0.0, "BrakePedal": 0.0, "BrakePressure": 0.0}
    for k in range(1, 700):
        io.t = k * DT
        ecu.step(io, io.t, DT)
    assert io.sent["ABS_SteerState"]["AbsFault"] == AbsFault.WHEEL_SPEED_INVALID
    assert hw.released > 0 and io.sent["ABS_SteerState"]["TurnDirection"] == 0


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pressure=st.one_of(st.floats(-50, 400), st.just(math.nan)),
       pedal=st.one_of(st.floats(-10, 200), st.just(math.nan)),
       hand_wheel=st.one_of(st.floats(-900, 900), st.just(math.inf)),
       mu=st.one_of(st.floats(0.0, 1.5), st.just(math.nan)),
       speed=st.one_of(st.floats(0, 80), st.just(math.nan)), noise=st.floats(0, 2.5))
def test_never_a_nan_or_out_of_range_value_on_the_bus(pressure, pedal, hand_wheel, mu, speed, noise) -> None:
    rig = Rig(InitialSpeed=speed, RoadMu=mu, SensorNoise=noise)
    rig.io.values["DRV_Pedals"] = {"AccelPedal": 0.0, "BrakePedal": pedal, "BrakePressure": pressure}
    rig.io.values["DRV_Steering"] = {"HandWheelAngle": hand_wheel}
    rig.run(0.3)                                   # MemoryIO checks every value sent


def test_plant_tick_cost(capsys) -> None:
    rig = Rig(InitialSpeed=22.0)
    rig.io.values["DRV_Steering"]["HandWheelAngle"] = -90.0
    rig.run(0.2)
    rig.io.values["DRV_Pedals"]["BrakePressure"] = 150.0
    n = 1500
    start = time.perf_counter()
    rig.run(n * DT)
    per_tick = (time.perf_counter() - start) / n * 1e6
    with capsys.disabled():
        print(f"\nACLASS_ABS plant tick (PLANT + ABS, braking under ABS): {per_tick:.1f} us")
    assert per_tick < 1000.0      # loose bound for loaded machines; the target is tens of us
