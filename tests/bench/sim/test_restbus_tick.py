"""The scheduler owns the tick and gives it to the restbus (issue 28): on ticks of 0.5 ms or 2 ms every message
keeps the cycle time its DBC states, and a tick that does not divide a cycle time is refused with one line naming
the message. Before, the restbus counted in a 1 ms tick of its own (TICKS_PER_MS), so a scheduler with another dt
sent every message at another cycle without a word.

The expected cycles are read from the DBCs with cantools (GenMsgCycleTime, ms), not from the bench's codec."""

from __future__ import annotations

from collections.abc import Callable

import can
import cantools
import pytest

from bench.checks.monitor import Monitor
from bench.database.codec import Codebook
from bench.errors import ConfigError
from bench.sim.clock import Scheduler, VirtualClock
from bench.sim.restbus import Restbus
from bench.sim.station import Station
from tests.fakes import FakeBus
from tests.repo import BENCH_DBC, CHASSIS_DBC

DURATION = 0.2   # s of bench time


def _dbc_cycles(nodes: set[str]) -> dict[int, float]:
    """{frame id: cycle time (s)} of every periodic message the nodes send, straight from the DBC files."""
    cycles = {}
    for path in (CHASSIS_DBC, BENCH_DBC):
        for message in cantools.database.load_file(str(path)).messages:
            if message.cycle_time and nodes & set(message.senders):
                cycles[message.frame_id] = message.cycle_time / 1000.0
    return cycles


class _StampingBus(FakeBus):
    """A bus that notes each frame sent with the bench time it went out at."""

    def __init__(self, now: Callable[[], float]) -> None:
        super().__init__("tick")
        self.now = now
        self.stamped: list[tuple[float, int]] = []

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.stamped.append((self.now(), msg.arbitration_id))


def _station(codebook: Codebook, nodes: set[str], clock: VirtualClock) -> tuple[Station, list[tuple[float, int]]]:
    """A station whose restbus frames are recorded as (bench time, id) by its bus."""
    bus = _StampingBus(clock.now)
    station = Station("sender", bus, Restbus(codebook, nodes), Monitor(codebook), clock.now)
    return station, bus.stamped


def _check_cycles(sent: list[tuple[float, int]], expected: dict[int, float]) -> None:
    times: dict[int, list[float]] = {}
    for t, frame_id in sent:
        times.setdefault(frame_id, []).append(t)
    assert set(times) == set(expected)
    for frame_id, stamps in times.items():
        cycle = expected[frame_id]
        # from the second frame on: the first goes out at the first tick at or after its phase (tick 0 is not run)
        gaps = [b - a for a, b in zip(stamps[1:], stamps[2:])]
        assert gaps and all(gap == pytest.approx(cycle, abs=1e-9) for gap in gaps), (hex(frame_id), cycle, gaps[:5])
        assert len(stamps) in (int(DURATION / cycle + 1e-9), int(DURATION / cycle + 1e-9) + 1), hex(frame_id)


@pytest.mark.parametrize(("dt", "nodes"), [(0.0005, {"PLANT", "SBW", "VCU"}), (0.001, {"PLANT", "SBW", "VCU"}),
                                           (0.002, {"VCU", "DRIVER"})])
def test_the_schedulers_tick_keeps_every_cycle_time(codebook: Codebook, dt: float, nodes: set[str]) -> None:
    clock = VirtualClock()
    station, sent = _station(codebook, nodes, clock)
    try:
        scheduler = Scheduler([station], clock, dt=dt)
        assert station.restbus.dt == dt
        scheduler.run_until(DURATION)
    finally:
        station.bus.shutdown()
    _check_cycles(sent, _dbc_cycles(nodes))


def test_a_station_ticked_by_hand_schedules_its_restbus_on_that_tick(codebook: Codebook) -> None:
    dt, nodes = 0.0005, {"SBW"}
    clock = VirtualClock()
    station, sent = _station(codebook, nodes, clock)
    try:
        for tick in range(1, round(DURATION / dt) + 1):
            clock.wait_until(tick * dt, [station])
            station.tick(tick, tick * dt, dt)
    finally:
        station.bus.shutdown()
    _check_cycles(sent, _dbc_cycles(nodes))


def test_a_tick_that_does_not_divide_a_cycle_time_is_refused(codebook: Codebook) -> None:
    """SBW sends messages of 5 ms: 2 ms ticks cannot keep them. One line naming a message and both times."""
    clock = VirtualClock()
    station, _ = _station(codebook, {"SBW"}, clock)
    try:
        with pytest.raises(ConfigError) as info:
            Scheduler([station], clock, dt=0.002)
    finally:
        station.bus.shutdown()
    five_ms = {m.name for path in (CHASSIS_DBC, BENCH_DBC) for m in cantools.database.load_file(str(path)).messages
               if m.cycle_time == 5 and "SBW" in m.senders}
    message = str(info.value)
    assert "\n" not in message and "5 ms" in message and "2 ms" in message
    assert message.split(":")[0] in five_ms
