"""The PLANT node of ACLASS_ABS on the bench I/O of an external ABS (plant/braking_plant.py; docs/contract/plant.md
PLANT-IO-ABS-01..03), on a fake NodeIO: IO_AbsSensors only while the ABS is external, sampled in the tick it is
sent, carrying the sensor model's noise; the valves set from IO_AbsValves; sensor faults on both paths.

Expected values come from the contract's definitions (the sensor model's noise, the valves' flow equations),
not from the code under test."""

from __future__ import annotations

import math
import statistics

import pytest

from bench.sim.testing import MemoryIO
from plant import signal_ranges
from plant.assemblies.aclass_abs import build
from plant.braking_plant import BrakingPlantNode
from plant.ecus.abs import AbsFault

DT = 1e-3
WHEELS = ("FL", "FR", "RL", "RR")
K_IN, K_OUT = 110.0, 160.0          # bar^0.5/s, PLANT-IO-ABS-02
HOLD, INCREASE, DECREASE, RELEASED = 0, 1, 2, 3


class RecordingIO(MemoryIO):
    """MemoryIO that also keeps the bench time of every IO_AbsSensors frame set (the plant sets it once per
    sample) and the values."""

    def __init__(self) -> None:
        super().__init__(signal_ranges.BY_SIGNAL, loopback=False)
        self.sensor_frames: list[tuple[float, dict[str, float]]] = []

    def send_values(self, message: str, **signals: float) -> None:
        super().send_values(message, **signals)
        if message == "IO_AbsSensors":
            self.sensor_frames.append((self.t, dict(signals)))


class Rig:
    def __init__(self, external: tuple[str, ...] = ("ABS",), **control: float) -> None:
        self.io = RecordingIO()
        self.behaviours = build(frozenset(external))
        self.plant = self.behaviours[0]
        assert isinstance(self.plant, BrakingPlantNode)
        self.tick = 0
        self.io.values["BENCH_Control"] = {"ScenarioId": 1, "RoadMu": 1.0, "InitialSpeed": 0.0, "SensorNoise": 0.0,
                                           "Vehicle": 2, **control}
        self.io.values["DRV_Pedals"] = {"AccelPedal": 0.0, "BrakePedal": 0.0, "BrakePressure": 0.0}
        self.io.values["DRV_Steering"] = {"HandWheelAngle": 0.0}

    def valves(self, valve: int | tuple[int, ...], duty: float = 1.0) -> None:
        codes = valve if isinstance(valve, tuple) else (valve,) * 4
        self.io.values["IO_AbsValves"] = {**{f"Valve{w}": c for w, c in zip(WHEELS, codes, strict=True)},
                                          **{f"InletDuty{w}": duty for w in WHEELS}}

    def step(self) -> None:
        self.tick += 1
        self.io.t = self.tick * DT
        for b in self.behaviours:
            b.step(self.io, self.io.t, DT)

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / DT)):
            self.step()

    @property
    def pressures(self) -> list[float]:
        return list(self.plant.hydraulics.pressures)


# -- IO_AbsSensors --------------------------------------------------------------------------------------------

def test_sensor_frames_only_with_an_external_abs_every_5_ms_in_their_send_tick() -> None:
    rig = Rig(InitialSpeed=10.0)
    rig.run(0.1)
    times = [round(t * 1000) for t, _ in rig.io.sensor_frames]
    assert len(times) == 20 and all(ms % 5 == 0x6D0 % 5 for ms in times)    # restbus phase: id mod cycle
    assert all(b - a == 5 for a, b in zip(times, times[1:]))
    # noise 0: the readings are the true circumferential speed, 36 km/h, quantised to 0.05 km/h
    assert rig.io.sensor_frames[-1][1] == {f"WheelSensor{w}": pytest.approx(36.0, abs=0.025) for w in WHEELS}
    simulated = Rig(external=(), InitialSpeed=10.0)
    simulated.run(0.1)
    assert simulated.io.sensor_frames == [] and "IO_AbsSensors" not in simulated.io.sent


def test_sensor_frames_carry_the_noise_of_sensor_noise() -> None:
    """PLANT-IO-ABS-01: reading - true speed = roughness (OU, std 0.5 sigma, correlation time 0.05 s) + white
    noise (std sigma), quantised to 0.05 km/h: std sqrt(1.25 sigma^2 + q^2/12); the lag-1 (5 ms) correlation of
    the error is that of the roughness alone, 0.25 sigma^2 exp(-0.005/0.05) over the total variance."""
    sigma, q = 1.0, 0.05
    rig = Rig(InitialSpeed=15.0, SensorNoise=sigma)
    errors: list[list[float]] = [[] for _ in WHEELS]
    for _ in range(40_000):
        before = len(rig.io.sensor_frames)
        rig.step()
        if len(rig.io.sensor_frames) > before:
            truth = rig.plant.vehicle.wheel_speeds_kmh()   # the tick's true speed, what the sample was taken of
            frame = rig.io.sensor_frames[-1][1]
            for i, w in enumerate(WHEELS):
                errors[i].append(frame[f"WheelSensor{w}"] - truth[i])
    a = math.exp(-0.005 / 0.05)
    total = 1.25 * sigma ** 2 + q ** 2 / 12
    rho1 = 0.25 * sigma ** 2 * a / total
    assert [len(e) for e in errors] == [8000] * 4
    pooled = [x for e in errors for x in e]
    n = len(pooled)
    # standard error of the mean: white part sigma^2 / n, roughness part (0.5 sigma)^2 / n (1 + a) / (1 - a)
    se_mean = math.sqrt(sigma ** 2 / n + 0.25 * sigma ** 2 / n * (1 + a) / (1 - a))
    assert statistics.fmean(pooled) == pytest.approx(0.0, abs=5 * se_mean)           # 5 se = 0.07 km/h
    assert statistics.pstdev(pooled) == pytest.approx(math.sqrt(total), rel=0.03)   # se about 0.5 %
    lags = []
    for e in errors:
        m = statistics.fmean(e)
        lags.append(sum((x - m) * (y - m) for x, y in zip(e, e[1:])) / sum((x - m) ** 2 for x in e))
    assert statistics.fmean(lags) == pytest.approx(rho1, abs=0.03)                 # 0.18: roughness included


# -- IO_AbsValves -------------------------------------------------------------------------------------------

def test_decrease_received_over_the_bus_keeps_the_pressure_down_and_the_wheels_rolling() -> None:
    rig = Rig(InitialSpeed=20.0)
    rig.valves(DECREASE)
    rig.io.values["DRV_Pedals"]["BrakePressure"] = 150.0
    rig.run(0.5)
    assert rig.plant.hydraulics.master == pytest.approx(150.0)
    assert rig.pressures == [0.0] * 4
    assert max(rig.io.sent[f"PLANT_AbsWheel_{w}"]["Slip"] for w in WHEELS) < 0.01
    # without the valve frame (no frame, or timed out: io.latest gives None) the valves are RELEASED: the wheels
    # follow the master cylinder at the full inlet rate and lock
    del rig.io.values["IO_AbsValves"]
    rig.run(0.5)
    assert rig.pressures == [pytest.approx(150.0)] * 4
    assert min(rig.io.sent[f"PLANT_AbsWheel_{w}"]["Slip"] for w in WHEELS) > 0.9


def test_each_valve_state_follows_the_flow_equations() -> None:
    """PLANT-IO-ABS-02: INCREASE at duty d: dp/dt = d k_in sqrt(p_m - p); HOLD and duty 0: dp/dt = 0; DECREASE:
    dp/dt = -k_out sqrt(p), so sqrt(p) falls linearly by k_out t / 2; RELEASED: INCREASE at duty 1. The plant
    integrates per 1 ms tick, so the closed forms hold within the Euler error (well under 1 % here)."""
    rig = Rig(InitialSpeed=5.0)
    rig.io.values["DRV_Pedals"]["BrakePressure"] = 200.0
    rig.valves(HOLD)
    rig.run(0.3)                                     # master at 200 bar, wheels still at 0
    assert rig.plant.hydraulics.master == pytest.approx(200.0) and rig.pressures == [0.0] * 4
    rig.valves(INCREASE, duty=0.5)
    rig.run(0.02)
    # sqrt(p_m - p) falls linearly at d k_in / 2: p = p_m - (sqrt(p_m) - d k_in t / 2)^2
    expected = 200.0 - (math.sqrt(200.0) - 0.5 * K_IN * 0.02 / 2) ** 2
    assert rig.pressures == [pytest.approx(expected, rel=0.01)] * 4
    held = rig.pressures
    rig.valves(INCREASE, duty=0.0)
    rig.run(0.02)
    assert rig.pressures == held
    rig.valves(HOLD)
    rig.run(0.02)
    assert rig.pressures == held
    rig.valves((DECREASE, HOLD, RELEASED, INCREASE), duty=1.0)
    rig.run(0.01)
    p0 = held[0]
    assert rig.pressures[0] == pytest.approx((math.sqrt(p0) - K_OUT * 0.01 / 2) ** 2, rel=0.01)
    assert rig.pressures[1] == held[1]
    rise = 200.0 - (math.sqrt(200.0 - p0) - K_IN * 0.01 / 2) ** 2       # duty 1 from p0
    assert rig.pressures[2] == pytest.approx(rise, rel=0.01)
    assert rig.pressures[3] == pytest.approx(rise, rel=0.01)


def test_the_simulated_abs_ignores_the_valve_message() -> None:
    rig = Rig(external=(), InitialSpeed=20.0)
    rig.valves(DECREASE)
    rig.io.values["DRV_Pedals"]["BrakePressure"] = 30.0      # below the locking pressure: the ABS stays passive
    rig.run(0.3)
    assert rig.pressures == [pytest.approx(30.0)] * 4


# -- BENCH_AbsSensorFault -------------------------------------------------------------------------------------

@pytest.mark.parametrize("fault, reading", [(1, 0.0), (2, 204.75)], ids=["OPEN_LINE", "SHORT"])
def test_open_line_and_short_on_the_io(fault: int, reading: float) -> None:
    rig = Rig(InitialSpeed=15.0, SensorNoise=0.5)
    rig.run(0.05)
    rig.io.values["BENCH_AbsSensorFault"] = {"FaultWheel": 2, "SensorFault": fault}
    rig.run(0.05)
    frame = rig.io.sensor_frames[-1][1]
    assert frame["WheelSensorRL"] == reading
    assert all(abs(frame[f"WheelSensor{w}"] - 54.0) < 5.0 for w in ("FL", "FR", "RR"))
    del rig.io.values["BENCH_AbsSensorFault"]                 # timed out: NONE
    rig.run(0.01)
    assert abs(rig.io.sensor_frames[-1][1]["WheelSensorRL"] - 54.0) < 5.0


def test_stuck_holds_its_first_reading_while_the_car_slows() -> None:
    rig = Rig(InitialSpeed=15.0, SensorNoise=0.5)
    rig.run(0.05)
    rig.io.values["BENCH_AbsSensorFault"] = {"FaultWheel": 0, "SensorFault": 3}
    rig.run(0.006)
    held = rig.io.sensor_frames[-1][1]["WheelSensorFL"]
    rig.valves(INCREASE)
    rig.io.values["DRV_Pedals"]["BrakePressure"] = 40.0
    rig.run(1.0)
    assert rig.plant.vehicle.speed * 3.6 < 50.0                # the car slowed by more than 4 km/h ...
    assert {f[1]["WheelSensorFL"] for f in rig.io.sensor_frames[-150:]} == {held}    # ... the sensor did not
    assert len({f[1]["WheelSensorFR"] for f in rig.io.sensor_frames[-150:]}) > 10


def test_the_fault_reaches_the_simulated_abs_through_its_wires() -> None:
    """ABS-FLT-01 on the reference: a SHORT reads 204.75 km/h, outside the 0-200 km/h measuring range, which the
    reference reports as WHEEL_SPEED_INVALID in its next frame; the I/O stays off the bus meanwhile."""
    rig = Rig(external=(), InitialSpeed=15.0, SensorNoise=0.1)
    rig.run(0.1)
    assert rig.io.sent["ABS_SteerState"]["AbsFault"] == AbsFault.OK
    rig.io.values["BENCH_AbsSensorFault"] = {"FaultWheel": 1, "SensorFault": 2}
    rig.run(0.02)
    assert rig.io.sent["ABS_SteerState"]["AbsFault"] == AbsFault.WHEEL_SPEED_INVALID
    assert rig.io.sent["ABS_WheelSpeeds"]["WheelSpeedFR"] == 204.75
    assert "IO_AbsSensors" not in rig.io.sent
