"""An external ABS on the bench I/O, in virtual time: a bench node of this test plays the ABS on the in-process bus
(its own station, as a real ECU would be a node of its own) while the bench runs with `--external ABS`. It proves
what issue 26 asks of the I/O (docs/contract/plant.md PLANT-IO-ABS-01, -02): the plant's sensor frames reach the
external ABS every 5 ms with the sensor noise on them, its valve commands brake the car (DECREASE keeps the wheel
pressures at 0 bar against 150 bar in the master cylinder), and when its valve frames stop the plant releases the
valves 15 ms (3 cycles) after the last one."""

from __future__ import annotations

import statistics

from bench.checks.monitor import Monitor
from bench.config import RunSettings, load_config
from bench.session import BenchSession
from bench.sim.node import NodeIO
from bench.sim.restbus import Restbus
from bench.sim.station import Station
from bench.transport import VirtualTimeBus

WHEELS = ("FL", "FR", "RL", "RR")
DECREASE = 2


class ToyAbs:
    """Node ABS reduced to what the test needs: notes every IO_AbsSensors frame it reads and commands DECREASE on
    every wheel while `commanding`, then stops sending IO_AbsValves (an ECU that fell silent)."""

    nodes = ("ABS",)

    def __init__(self) -> None:
        self.readings: list[tuple[float, dict[str, float]]] = []
        self.commanding = True
        self.sending = True
        self.last_sent: float | None = None

    def reset(self) -> None:
        pass

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        frame = io.latest("IO_AbsSensors")
        if frame is not None and (not self.readings or self.readings[-1][1] is not frame):
            self.readings.append((t, frame))
        if self.commanding:
            io.send_values("IO_AbsValves", **{f"Valve{w}": DECREASE for w in WHEELS})
        elif self.sending:
            io.stop_sending("IO_AbsValves")
            self.sending = False


def test_an_external_abs_reads_the_sensors_and_brakes_through_its_valves() -> None:
    session = BenchSession(load_config(), RunSettings(external=["ABS"]))
    toy = ToyAbs()
    abs_station = Station("abs", VirtualTimeBus(channel=session.channel), Restbus(session.codebook, {"ABS"}),
                          Monitor(session.codebook), session.now, [toy])
    session.scheduler.stations.append(abs_station)
    pressures: list[tuple[float, list[float]]] = []
    try:
        session.start()
        runner = session.runner.restbus
        runner.set("BENCH_Control", Vehicle="ACLASS_ABS", ScenarioId=1, InitialSpeed=20.0, SensorNoise=1.0)
        runner.set("BENCH_AbsStimulus", CruiseSpeed=72.0)
        session.run_until(1.0)
        # the sensor frames: every 5 ms, noisy (SensorNoise 1 km/h) around the true 72 km/h
        frames = [(t, f) for t, f in toy.readings if t >= 0.5]
        assert 99 <= len(frames) <= 101, len(frames)
        fl = [f["WheelSensorFL"] for _, f in frames]
        assert 0.7 < statistics.pstdev(fl) < 1.6 and abs(statistics.fmean(fl) - 72.0) < 1.0
        assert all(abs(v / 0.05 - round(v / 0.05)) < 1e-6 for v in fl)
        # braking with 150 bar: DECREASE over the bus keeps every wheel circuit empty
        plant = next(b for b in session.plant.behaviours[0].inner if b.nodes == ("PLANT",))   # the braking plant
        runner.set("DRV_Pedals", BrakePressure=150.0)
        t_brake = session.now()
        while session.now() < t_brake + 0.5:
            session.run_until(session.now() + 0.001)
            pressures.append((session.now(), list(plant.hydraulics.pressures)))
        assert plant.hydraulics.master == 150.0
        assert max(max(p) for _, p in pressures) == 0.0
        # the ABS falls silent: 15 ms after its last valve frame the valves are released, the pressures rise
        toy.commanding = False
        t_silent = session.now()
        pressures.clear()
        while session.now() < t_silent + 0.1:
            session.run_until(session.now() + 0.001)
            pressures.append((session.now(), list(plant.hydraulics.pressures)))
        times, _ = session.runner.monitor.history("IO_AbsValves", "ValveFL")
        last = max(times)
        rise = next(t for t, p in pressures if min(p) > 0.0)
        print(f"valves released {rise - last:.3f} s after the last IO_AbsValves frame")
        assert 0.015 <= rise - last <= 0.017, (last, rise)
        assert not session.runner.monitor.invalid_log
    finally:
        abs_station.bus.shutdown()
        session.close()
