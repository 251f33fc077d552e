"""A station under the wall clock: bounded draining, and frames timed by their receive timestamps.

A station slower than its bus must still get back to its tick (the vcan lane's runner in an emulated
guest did not: its receive loop never returned), and a station that reads late must still measure the
bus's intervals, not its own lateness.
"""

from __future__ import annotations

import time

import can
import pytest

from bench.checks.monitor import Monitor
from bench.sim.clock import STAMP_WINDOW, WallClock
from bench.sim.restbus import Restbus
from bench.sim.station import POLL_BATCH, Station
from bench.transport import Transport, open_bus
from tests.fakes import FakeBus, flood, ipv4_group


def flood_bus(frame: can.Message, budget: int | None = None) -> FakeBus:
    """A bus that always has another frame: `budget` frames, or without end when budget is None."""
    return FakeBus("flood", incoming=flood(frame, budget))


def _frame(codebook, name: str, timestamp: float = 0.0) -> can.Message:
    codec = codebook[name]
    return can.Message(arbitration_id=codec.frame_id, data=bytes(codec.length), is_extended_id=False,
                       timestamp=timestamp)


def _station(codebook, bus: can.BusABC | Transport, clock: WallClock | None = None) -> Station:
    now = clock.now if clock else (lambda: 0.0)
    return Station("runner", bus, Restbus(codebook, {"DRIVER"}), Monitor(codebook), now, (),
                   clock.stamp if clock else None)


def test_poll_takes_at_most_a_batch_and_leaves_the_rest_in_the_socket(codebook) -> None:
    bus = flood_bus(_frame(codebook, "VCU_WheelCmd_FL"), budget=POLL_BATCH + 10)
    station = _station(codebook, bus)
    assert station.poll() == POLL_BATCH
    assert station.monitor.frames == POLL_BATCH
    assert station.poll() == 10
    assert station.poll() == 0
    assert station.monitor.frames == POLL_BATCH + 10


@pytest.mark.realtime
def test_wall_clock_keeps_its_deadline_on_a_bus_that_never_goes_quiet(codebook) -> None:
    clock = WallClock()
    station = _station(codebook, flood_bus(_frame(codebook, "VCU_WheelCmd_FL")), clock)
    clock.start()
    clock.wait_until(0.05, [station])
    late = clock.now() - 0.05
    # One batch at most after the deadline: a few ms even on a slow machine, never "until the bus stops".
    assert 0 <= late < 0.5, f"returned {late * 1000:.1f} ms after its deadline"
    assert station.monitor.frames > POLL_BATCH


def test_a_frame_is_timed_by_its_receive_timestamp(codebook) -> None:
    clock = WallClock()
    clock.start()
    time.sleep(0.05)
    received = clock.epoch_ns / 1e9 + 0.01       # the kernel received it 10 ms after start (the clock's own
                                                 # epoch: a time.time() after start() was late under load)
    bus = flood_bus(_frame(codebook, "VCU_WheelCmd_FL", timestamp=received), budget=1)
    station = _station(codebook, bus, clock)
    station.poll()
    seen = station.monitor.state("VCU_WheelCmd_FL").last_seen
    assert seen == pytest.approx(0.01, abs=0.002)   # not the ~50 ms at which it was read


def test_a_timestamp_of_another_time_base_gets_the_time_of_reading(codebook) -> None:
    clock = WallClock()
    clock.start()
    time.sleep(0.02)
    # Some interfaces stamp with the device's uptime: nothing like this host's epoch time.
    bus = flood_bus(_frame(codebook, "VCU_WheelCmd_FL", timestamp=123.456), budget=1)
    station = _station(codebook, bus, clock)
    before = clock.now()
    station.poll()
    seen = station.monitor.state("VCU_WheelCmd_FL").last_seen
    assert before <= seen <= clock.now()
    assert clock.stamp(time.time() - 2 * STAMP_WINDOW, clock.now()) == pytest.approx(clock.now(), abs=0.01)


@pytest.mark.realtime
def test_a_late_reader_measures_the_intervals_the_bus_had(codebook) -> None:
    """Over udp_multicast (loopback, hop limit 0): 20 frames 10 ms apart, read in one go 0.3 s later."""
    group = ipv4_group()
    sender, receiver = open_bus("udp_multicast", group), open_bus("udp_multicast", group)
    try:
        clock = WallClock()
        station = _station(codebook, receiver, clock)
        # Linux switches receive timestamping on a moment after the first socket asks for it (a deferred
        # static key); a frame that arrives before is stamped when it is read.
        time.sleep(0.1)
        clock.start()
        frame = _frame(codebook, "VCU_WheelCmd_FL")
        sent_at = []                             # (before, after) each send: the kernel stamps it in between
        for _ in range(20):
            before = time.monotonic()
            sender.send(frame)
            sent_at.append((before, time.monotonic()))
            time.sleep(0.01)
        time.sleep(0.3)
        while station.poll(0.05):
            pass
        state = station.monitor.state("VCU_WheelCmd_FL")
        assert state.frames == 20
        measured = list(state.intervals)
        assert len(measured) == 19
        # The reader took all 20 within a few ms; the stamps still give the sender's spacing: each interval
        # lies between the shortest and the longest the two sends allow (a sender descheduled between its clock
        # read and its send made a single read 3.4 ms off: seen under load). 1 ms: the stamp's clock
        # (CLOCK_REALTIME, bench/sim/clock.py) against the monotonic one over 10 ms.
        for (a0, a1), (b0, b1), got in zip(sent_at, sent_at[1:], measured, strict=False):
            assert b0 - a1 - 0.001 <= got <= b1 - a0 + 0.001, (got, b0 - a1, b1 - a0)
    finally:
        sender.shutdown()
        receiver.shutdown()


def test_a_frame_waiting_from_before_the_start_gets_time_zero() -> None:
    clock = WallClock()
    clock.start()
    assert clock.stamp(time.time() - 0.5, clock.now()) == 0.0


def test_the_log_process_skips_a_record_it_cannot_write_and_keeps_the_rest(tmp_path, codebook) -> None:
    """A frame whose time does not fit the log (negative) is reported and skipped; the log goes on."""
    from bench.config import load_config
    from bench.log.logproc import LogProcess
    from bench.log.logread import read_frames

    databases = load_config().databases
    codec = codebook["VCU_WheelCmd_FL"]
    log = LogProcess(tmp_path / "run.mcap", databases, "vcan0")
    log.frame(-0.25, codec.frame_id, bytes(8), "rx", False, "test")
    log.frame(0.5, codec.frame_id, bytes(range(8)), "rx", False, "test")
    log.close()
    frames = list(read_frames(tmp_path / "run.mcap"))
    assert [(f.t, f.data) for f in frames] == [(0.5, bytes(range(8)))]


def test_a_late_runner_goes_to_the_wall_clock_a_late_plant_replays_every_tick(codebook) -> None:
    """Scheduler under the wall clock, 0.1 s late at start: the runner jumps, the plant steps every tick."""
    from bench.sim.clock import Scheduler

    for every_tick in (False, True):
        clock = WallClock()
        steps: list[float] = []

        class Counting:
            nodes = ()

            def __init__(self, steps: list[float]) -> None:
                self.steps = steps

            def reset(self) -> None:
                pass

            def step(self, io: object, t: float, dt: float) -> None:
                self.steps.append(t)

        bus = flood_bus(_frame(codebook, "VCU_WheelCmd_FL"), budget=0)
        station = Station("s", bus, Restbus(codebook, {"DRIVER"}), Monitor(codebook), clock.now, [Counting(steps)],
                          clock.stamp, every_tick=every_tick)
        scheduler = Scheduler([station], clock)
        clock.start()
        time.sleep(0.1)
        scheduler.run_until(0.15)
        assert scheduler.tick == 150
        if every_tick:
            assert len(steps) == 150 and scheduler.skipped == 0
        else:
            assert scheduler.skipped >= 90 and len(steps) == 150 - scheduler.skipped
            assert steps[0] >= 0.09       # the first step is at the wall clock's time, not at 1 ms


def test_a_real_time_run_reads_what_waits_before_it_returns(codebook) -> None:
    """run_until ends with the sockets read (up to CATCH_UP_FRAMES), so checks see the present."""
    from bench.sim.clock import CATCH_UP_FRAMES, Scheduler

    clock = WallClock()
    bus = flood_bus(_frame(codebook, "VCU_WheelCmd_FL"), budget=5 * POLL_BATCH)
    station = Station("runner", bus, Restbus(codebook, {"DRIVER"}), Monitor(codebook), clock.now, (),
                      clock.stamp, every_tick=False)
    scheduler = Scheduler([station], clock)
    clock.start()
    time.sleep(0.01)
    scheduler.run_until(0.001)            # one tick, one batch; then the rest before returning
    assert station.monitor.frames == 5 * POLL_BATCH
    flood = flood_bus(_frame(codebook, "VCU_WheelCmd_FL"))   # without end: bounded all the same
    station = Station("runner", flood, Restbus(codebook, {"DRIVER"}), Monitor(codebook), clock.now, (),
                      clock.stamp, every_tick=False)
    Scheduler([station], clock).run_until(0.0)
    assert CATCH_UP_FRAMES <= station.monitor.frames < CATCH_UP_FRAMES + POLL_BATCH


# -- clock reads: each is a system call in a User-mode Linux guest (16-52 us), so they are counted -------------
class _CountingMonotonic:
    def __init__(self) -> None:
        self.real = time.monotonic
        self.calls = 0

    def __call__(self) -> float:
        self.calls += 1
        return self.real()


def test_a_stamp_is_checked_against_the_latest_read_without_a_new_one(monkeypatch: pytest.MonkeyPatch) -> None:
    from bench.sim.clock import STAMP_LEAD

    clock = WallClock()
    clock.start()
    time.sleep(0.02)
    now = clock.now()
    counting = _CountingMonotonic()
    monkeypatch.setattr(time, "monotonic", counting)
    epoch0 = clock.epoch_ns / 1e9
    assert clock.stamp(epoch0 + now - 0.005) == pytest.approx(now - 0.005, abs=1e-6)   # received before the read
    assert clock.stamp(epoch0 + now + 0.004) == pytest.approx(now + 0.004, abs=1e-6)   # since the read (a tick's work)
    assert counting.calls == 0
    # beyond the lead: perhaps the latest read is old (a long pause); a fresh read decides
    assert clock.stamp(epoch0 + now + STAMP_LEAD + 5.0) == pytest.approx(clock.recent())
    assert counting.calls == 1   # the fresh read (clock.recent() reads nothing)
    assert clock.recent() >= now


def test_behaviours_see_the_tick_s_time_and_a_plant_tick_reads_the_clock_about_once(
        codebook, monkeypatch: pytest.MonkeyPatch) -> None:
    """A plant-like station asks for several messages every tick: the answers are timed against the tick's
    time, and the whole tick loop reads the clock about once per tick (it waits for each deadline)."""
    from bench.sim.clock import Scheduler

    seen: list[tuple[float, float]] = []

    class Asking:
        nodes = ()

        def reset(self) -> None:
            pass

        def step(self, io, t: float, dt: float) -> None:
            for _ in range(8):
                io.latest("VCU_WheelCmd_FL")
                io.timed_out("VCU_WheelCmd_FL")
            seen.append((t, io.now))

    clock = WallClock()
    bus = flood_bus(_frame(codebook, "VCU_WheelCmd_FL"), budget=0)
    station = Station("plant", bus, Restbus(codebook, {"DRIVER"}), Monitor(codebook), clock.now, [Asking()],
                      clock.stamp)
    scheduler = Scheduler([station], clock)
    counting = _CountingMonotonic()
    clock.start()
    monkeypatch.setattr(time, "monotonic", counting)
    scheduler.run_until(0.05)
    monkeypatch.setattr(time, "monotonic", counting.real)
    assert len(seen) == 50 and all(now == t for t, now in seen)
    # on time: one read to know the wait; a wait that received nothing ended at its deadline and reads no more;
    # 16 questions per tick cost none
    assert counting.calls <= 55, counting.calls


def test_a_late_plant_reads_the_clock_once_per_tick(codebook, monkeypatch: pytest.MonkeyPatch) -> None:
    from bench.sim.clock import Scheduler

    clock = WallClock()
    bus = flood_bus(_frame(codebook, "VCU_WheelCmd_FL"), budget=0)
    station = Station("plant", bus, Restbus(codebook, {"DRIVER"}), Monitor(codebook), clock.now, (), clock.stamp)
    scheduler = Scheduler([station], clock)
    clock.start()
    time.sleep(0.2)                              # 200 ticks late: no tick waits
    counting = _CountingMonotonic()
    monkeypatch.setattr(time, "monotonic", counting)
    scheduler.run_until(0.1)
    monkeypatch.setattr(time, "monotonic", counting.real)
    assert scheduler.tick == 100
    assert counting.calls == 100, counting.calls


def test_a_tick_after_a_wait_that_found_the_socket_empty_reads_no_more(codebook) -> None:
    clock = WallClock()
    bus = flood_bus(_frame(codebook, "VCU_WheelCmd_FL"), budget=3)
    station = _station(codebook, bus, clock)
    clock.start()
    clock.wait_until(0.01, [station])
    assert station.drained and station.monitor.frames == 3      # the wait read the 3 frames and then nothing
    waited = bus.reads
    station.tick(10, 0.01, 0.001)
    assert bus.reads == waited and not station.drained          # no second look at an empty socket
    station.tick(11, 0.011, 0.001)                              # not after a wait: it reads, once (nothing there)
    assert bus.reads == waited + 1


def test_a_station_with_stamped_batches_sleeps_to_the_deadline_and_reads_at_its_end(
        codebook, monkeypatch: pytest.MonkeyPatch) -> None:
    """socketcan (here a kernel datagram pair that stamps the same way): no wake-up per frame and one clock read
    per wait; the frames that came during the sleep keep the time the kernel received them."""
    import socket
    import struct

    from bench.transport.socketcan import SocketcanTransport
    from bench.transport.socketcan_rx import SO_TIMESTAMPNS, FastReceiver

    sender, receiver = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
    receiver.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    try:
        clock = WallClock()
        bus = flood_bus(_frame(codebook, "VCU_WheelCmd_FL"), budget=0)
        station = _station(codebook, SocketcanTransport(bus, FastReceiver(receiver)), clock)
        assert station.stamped_batches
        frame_id = codebook["VCU_WheelCmd_FL"].frame_id
        clock.start()
        sent_at = []
        for _ in range(3 * POLL_BATCH + 5):         # more than a batch: all read at the end of the wait
            sent_at.append(clock.now())
            sender.send(struct.pack("=IB3x8s", frame_id, 8, bytes(8)))
        counting = _CountingMonotonic()
        monkeypatch.setattr(time, "monotonic", counting)
        clock.wait_until(0.03, [station])
        monkeypatch.setattr(time, "monotonic", counting.real)
        assert counting.calls == 1                    # to know the wait; none after the sleep
        assert clock.now() >= 0.03 and clock.recent() >= 0.03
        assert station.monitor.frames == 3 * POLL_BATCH + 5 and station.drained
        state = station.monitor.state("VCU_WheelCmd_FL")
        assert state.last_seen == pytest.approx(sent_at[-1], abs=0.005)   # when it came, not 30 ms
    finally:
        sender.close()
        receiver.close()


def test_the_wall_clock_s_start_moves_the_heap_out_of_the_collector_s_view() -> None:
    """A full collection of a plant's start-up heap stalled its tick loop for 139 ms (the host, 61 k objects):
    what exists when real time starts is frozen, so a collection in the run scans only what the run made."""
    import gc

    gc.unfreeze()
    kept = [[i] for i in range(10_000)]            # long-lived containers made before the start
    WallClock().start()
    try:
        assert gc.get_freeze_count() >= len(kept)
    finally:
        gc.unfreeze()
