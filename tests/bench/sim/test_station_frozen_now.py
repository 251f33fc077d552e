"""Station(frozen_now=True): on the virtual clock a poll reads the time once for all its frames; every frame
still gets the time of reading, as with a read per frame (the session sets it only when time cannot move)."""

from __future__ import annotations

import itertools

from bench.checks.monitor import Monitor
from bench.database.codec import Codebook
from bench.sim.restbus import Restbus
from bench.sim.station import Station
from bench.transport import VirtualTimeBus


def _received_times(codebook: Codebook, frozen: bool) -> tuple[list[float], int]:
    sender = Station("plant", VirtualTimeBus(channel="frozen-now"), Restbus(codebook, {"VCU"}), Monitor(codebook),
                     lambda: 0.0)
    reads = itertools.count()
    times: list[float] = []
    monitor = Monitor(codebook, sink=lambda frame: times.append(frame.t))
    receiver = Station("runner", VirtualTimeBus(channel="frozen-now"), Restbus(codebook, {"DRIVER"}), monitor,
                       lambda: float(next(reads)), frozen_now=frozen)
    try:
        for tick in range(1, 21):          # several frames wait in the receiver's inbox
            sender.tick(tick, tick / 1000, 0.001)
        assert receiver.poll(0.0) == len(times) > 1
        return times, next(reads)
    finally:
        sender.bus.shutdown()
        receiver.bus.shutdown()


def test_one_read_per_poll_when_frozen(codebook: Codebook) -> None:
    times, reads = _received_times(codebook, frozen=True)
    assert set(times) == {0.0} and reads == 1


def test_a_read_per_frame_otherwise(codebook: Codebook) -> None:
    times, reads = _received_times(codebook, frozen=False)
    assert times == [float(i) for i in range(len(times))] and reads == len(times)


def test_an_empty_inbox_reads_no_time(codebook: Codebook) -> None:
    reads = itertools.count()
    station = Station("runner", VirtualTimeBus(channel="frozen-empty"), Restbus(codebook, {"DRIVER"}),
                      Monitor(codebook), lambda: float(next(reads)), frozen_now=True)
    try:
        assert station.poll(0.0) == 0 and next(reads) == 0
    finally:
        station.bus.shutdown()
