"""Virtual and wall clocks behind one interface, and the tick loop that drives a bench.

The plant steps every `dt` (1 ms); each tick every station receives, steps its behaviours and
sends what is due. With the virtual clock a tick costs only its work (deterministic, much faster
than real time); with the wall clock each tick waits for its wall-time deadline while receiving.
The same test-case code runs under both.

Clock reads are not free everywhere: in a User-mode Linux guest (the vcan lane) every read is a system call
trapped through ptrace, 16-52 us, where a host reads its vDSO in 0.05 us. So the wall clock is read where a
decision needs the present (how long to wait, how late a tick is), and everything else takes the time of the
latest read (`WallClock.recent`): a receive timestamp is checked against it, a station's behaviours see the
tick's time, a late runner's skip uses the read that ended its wait.
"""

from __future__ import annotations

import gc
import math
import os
import select
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

from bench.errors import ConfigError, Inconclusive
from bench.sim.station import POLL_BATCH, Station

if TYPE_CHECKING:
    from bench.checks.timing import SelfTiming

DEFAULT_DT = 0.001
#: A receive timestamp is taken as bench time only when it lies this far before now at most; outside
#: (an interface whose timestamps are not the host's epoch time) the frame gets the time it was read.
STAMP_WINDOW = 5.0
#: ... and this far after the clock's latest read at most: the read a frame is checked against may be up to a
#: tick's work old (WallClock.recent), so a frame received since then is newer than it.
STAMP_LEAD = 1.0
#: At most this many frames are read when a real-time run stops to be looked at (Scheduler._catch_up).
CATCH_UP_FRAMES = 8192
#: Batches (of POLL_BATCH frames) a station reads after a sleeping wait at most; the rest waits for its tick.
DRAIN_BATCHES = 16
#: The watchdog (real time): a tick the loop reaches this many seconds after its wall-clock deadline ends the case
#: in progress as inconclusive (bench.errors.Inconclusive) instead of letting it run for ever behind the wall
#: clock. Environment variable BENCH_WATCHDOG (s; "inf" or "0": off). Only a loop that replays every tick (an
#: in-process plant's) falls behind for good; a runner alone goes to the wall clock's tick after a stall, and what
#: the stall did to its frames is their lateness (bench.checks.timing.SelfTiming).
WATCHDOG_S = 1.0


def watchdog_bound() -> float:
    """The watchdog's bound, s: BENCH_WATCHDOG when set (inf for "0" or "inf"), else WATCHDOG_S."""
    text = os.environ.get("BENCH_WATCHDOG", "").strip()
    if not text:
        return WATCHDOG_S
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(f"BENCH_WATCHDOG={text!r}: a number of seconds (0 or inf: no watchdog)") from None
    return math.inf if value <= 0 or math.isnan(value) else value


def settle_heap() -> None:
    """Collect the garbage there is now and move every survivor out of the garbage collector's view (gc.freeze).

    Real time only, at moments no deadline runs (a clock's start, between two test cases): a full collection
    scans every tracked object, and one that stalls a tick loop for longer than a message's cycle is a timeout
    at its receivers (docs/vcan-lane.md). After this, a collection during the run scans only what was made
    since. What is frozen is never collected: a cycle made before and dropped after a settle stays in memory."""
    gc.collect()
    gc.freeze()


class Clock(Protocol):
    realtime: bool
    epoch_ns: int     # the wall-clock instant of bench time 0, ns since the epoch (the run log's times)

    def start(self) -> None: ...

    def between_cases(self) -> None:
        """A test case ends and the next begins: no deadline runs now."""

    def now(self) -> float:
        """Bench time, s."""

    def recent(self) -> float:
        """Bench time of the clock's latest read (no new read), s."""

    def wait_until(self, t: float, stations: Sequence[Station]) -> None:
        """Return at bench time t, receiving frames meanwhile."""


class VirtualClock:
    """Time moves only when the scheduler says so."""

    realtime = False

    def __init__(self) -> None:
        self._now = 0.0
        self.epoch_ns = time.time_ns()

    def start(self) -> None:
        """Bench time 0 now; `epoch_ns`, the wall-clock instant of the start, gives the run log its times."""
        self._now = 0.0
        self.epoch_ns = time.time_ns()

    def now(self) -> float:
        return self._now

    def recent(self) -> float:
        return self._now

    def between_cases(self) -> None:
        """Nothing: a collection costs virtual time nothing."""

    def wait_until(self, t: float, stations: Sequence[Station]) -> None:
        self._now = t


class WallClock:
    """Bench time = monotonic wall time since start."""

    realtime = True

    def __init__(self) -> None:
        self.start()
        self.max_lag = 0.0   # worst lateness of a tick, s
        self._poller = select.poll()
        self._polled: set[int] = set()
        self._bus_key: tuple[int, ...] = ()
        self._bus_fd_list: list[int] | None = None
        self._bus_poller = select.poll()

    def start(self) -> None:
        # What exists before real time starts (modules, databases, the plant's models) is moved out of the
        # garbage collector's view: a full collection of that heap stalled a plant's tick loop for 139 ms on
        # the host (61 k objects), and a plant late by more than 3 cycles is a timeout at its receivers.
        settle_heap()
        self._t0 = time.monotonic()
        self.epoch_ns = time.time_ns()   # the same instant in epoch time: the run log's times, receive stamps
        self._epoch0 = self.epoch_ns / 1e9
        self._last = 0.0

    def now(self) -> float:
        self._last = now = time.monotonic() - self._t0
        return now

    def recent(self) -> float:
        return self._last

    def between_cases(self) -> None:
        """What the last cases left (results, steps, plots) out of the collector's view too: a full collection in
        a case scanned all of it, growing with the campaign; after a settle at most a case's survivors (the figures:
        docs/vcan-lane.md)."""
        settle_heap()

    def recent_monotonic(self) -> float:
        """time.monotonic() of the latest read (no new read)."""
        return self._last + self._t0

    def _probe(self, stations: Sequence[Station]) -> list[Station]:
        """One poll() over every station's sockets: a station whose bus socket is empty is `drained` (its tick
        reads nothing), an empty echo socket is skipped once (bench.transport.periodic.KernelPeriodic.echo_idle).
        Returns the stations with frames waiting. Most sockets are empty at most ticks, and in a UML guest
        each read that finds nothing is a costly system call (docs/vcan-lane.md)."""
        fds = [station.socket_fds() for station in stations]
        ready = self._ready(fds)
        waiting = []
        for station, (bus_fd, echo_fd) in zip(stations, fds):
            if echo_fd is not None and echo_fd not in ready and station.kernel is not None:
                station.kernel.echo_idle = True
            if bus_fd in ready:
                waiting.append(station)
            else:
                station.drained = True
        return waiting

    def _ready(self, fds: list[tuple[int, int | None]]) -> set[int]:
        """The descriptors among `fds` with something to read (or an error to report) now: one poll()."""
        wanted = {fd for pair in fds for fd in pair if fd is not None}
        if wanted != self._polled:
            self._poller = select.poll()
            for fd in wanted:
                self._poller.register(fd, select.POLLIN)
            self._polled = wanted
        return {fd for fd, _ in self._poller.poll(0)}

    def stamp(self, timestamp: float, now: float | None = None) -> float:
        """Bench time of a frame the kernel stamped at `timestamp` (epoch s: python-can's socketcan and
        udp_multicast give the socket's receive time), read at bench time `now` (default: the clock's latest
        read, so that a frame costs no clock read). A station that reads late then still sees the intervals
        the bus had. A stamp outside [now - STAMP_WINDOW, now + STAMP_LEAD] is checked once more against a
        fresh read; one outside that too is not of this clock, and the frame gets the time of reading. A
        frame received before the clock started (waiting in the socket) gets 0."""
        t = timestamp - self._epoch0
        if now is None:
            last = self._last
            if last - STAMP_WINDOW <= t <= last + STAMP_LEAD:
                return max(t, 0.0)
            now = self.now()
        return max(t, 0.0) if now - STAMP_WINDOW <= t <= now else now

    def wait_until(self, t: float, stations: Sequence[Station]) -> None:
        """Return at bench time t, with what the stations' sockets received meanwhile read."""
        remaining = t - self.now()
        stamped = all(station.stamped_batches for station in stations)
        if remaining < 0:
            self.max_lag = max(self.max_lag, -remaining)
            if stamped:
                self._probe(stations)   # a late tick too: its stations read only sockets that hold something
            return
        if stamped:
            # Every frame carries the kernel's receive time and one call reads a batch (socketcan): sleep to the
            # deadline, then read what came. One system call for the wait and none for a frame that arrives
            # meanwhile (a wake-up per frame is a host context switch and a clock read in a UML guest); a frame
            # read at the deadline still has the time it arrived. No clock read after the sleep either: it
            # lasted its whole time (`recent` becomes t, a lower bound of the present).
            time.sleep(remaining)
            self._last = max(self._last, t)
            for station in self._probe(stations):
                for _ in range(DRAIN_BATCHES):
                    if station.poll(0.0) < POLL_BATCH:
                        station.drained = True   # its tick reads no more (bench.sim.station.Station.tick)
                        break
            return
        # Other buses: receive while waiting. A station whose last poll here found its socket empty (a short
        # batch) is `drained`, and its tick reads no more; a wait that ends with nothing received waited its
        # whole timeout, and the clock is not read again.
        if len(stations) == 1:
            station = stations[0]
            got = POLL_BATCH
            while remaining > 0:
                got = station.poll(timeout=remaining)   # bounded: returns after a batch, then the deadline
                if got == 0:
                    self._last = max(self._last, t)
                    break
                remaining = t - self.now()
            station.drained = got < POLL_BATCH
            return
        fds = self._bus_fds(stations)
        if fds is None:   # a bus without a descriptor to wait on: look every 0.2 ms
            while remaining > 0:
                for station in stations:
                    station.poll(timeout=0.0)
                time.sleep(min(remaining, 0.0002))
                remaining = t - self.now()
            return
        # Several stations (a runner and its plant in one process): wait in the kernel on all their sockets at
        # once, wake for a frame or the deadline (not every 0.2 ms: 5447 against 7855 voluntary context switches
        # in 3 s on udp_multicast), and read only the stations whose socket holds something.
        poller = self._bus_poller
        while remaining > 0:
            ready = poller.poll(remaining * 1000.0)
            if not ready:
                self._last = max(self._last, t)   # the whole timeout passed: no read
                break
            waiting = {fd for fd, _ in ready}
            for station, bus_fd in zip(stations, fds):
                if bus_fd in waiting:
                    station.poll(timeout=0.0)
            remaining = t - self.now()

    def _bus_fds(self, stations: Sequence[Station]) -> list[int] | None:
        """The descriptor of each station's bus (its transport's `fileno()`), registered in one poll() object; None
        when a bus has none (then wait_until looks at the stations every 0.2 ms)."""
        key = tuple(id(station.bus) for station in stations)
        if key == self._bus_key:
            return self._bus_fd_list
        fds: list[int] | None = []
        for station in stations:
            fd = station.transport.fileno()
            if fd is None:
                fds = None
                break
            assert fds is not None
            fds.append(fd)
        self._bus_key, self._bus_fd_list = key, fds
        self._bus_poller = select.poll()
        for fd in fds or ():
            self._bus_poller.register(fd, select.POLLIN)
        return fds


class Scheduler:
    """The tick loop: one per bench, over all its stations, in a fixed order (determinism)."""

    def __init__(self, stations: Sequence[Station], clock: Clock, dt: float = DEFAULT_DT) -> None:
        self.stations = list(stations)
        self.clock = clock
        self.dt = dt
        for station in self.stations:   # the scheduler owns the tick: its restbuses count in it (or refuse it)
            station.restbus.set_tick(dt)
        self.tick = 0
        self.skipped = 0   # ticks left out because the wall clock had passed them (see run_until)
        self.self_timing: SelfTiming | None = None   # real time: where the tick loop's lateness goes
        self.watchdog = watchdog_bound() if clock.realtime else math.inf
        # The least lag of a tick since the case began (`begin_case`): the watchdog fires when a tick is later than
        # that by more than its bound, so that a pause between cases (by design: no tick runs then) is no lag.
        self.lag_floor = math.inf

    @property
    def now(self) -> float:
        return self.tick * self.dt

    def run_until(self, t_end: float, stop: Callable[[], bool] | None = None) -> bool:
        """Advance tick by tick to bench time t_end, or until stop() is true (checked every tick).
        Returns whether stop() became true."""
        last = round(t_end / self.dt)
        # In real time, a late scheduler whose stations need no tick of their own (a test runner: its
        # timers and its restbus are due-based) goes straight to the wall clock's tick. Replaying the
        # missed ticks would cost more time than they cover when the machine is short of CPU, and the
        # run would fall further behind for ever. A plant's models step every tick, late or not.
        realtime = self.clock.realtime
        may_skip = realtime and not any(station.every_tick for station in self.stations)
        stations, dt, wait_until = self.stations, self.dt, self.clock.wait_until   # (every tick: locals)
        timing, watchdog, recent = self.self_timing, self.watchdog, self.clock.recent
        while self.tick < last:
            tick = self.tick = self.tick + 1
            t = tick * dt
            wait_until(t, stations)
            if realtime:
                lag = recent() - t   # the read that ended the wait: no second read
                if timing is not None:
                    timing.add("tick loop", lag, t)
                if lag < self.lag_floor:
                    self.lag_floor = lag
                elif lag - self.lag_floor > watchdog and not may_skip:
                    self._watchdog(lag, t)
                if may_skip:
                    behind = min(int(recent() / dt) - tick, last - tick)
                    if behind > 0:
                        tick = self.tick = tick + behind
                        self.skipped += behind
                        t = tick * dt
            for station in stations:
                station.tick(tick, t, dt)
            if stop is not None and stop():
                self._catch_up()
                return True
        self._catch_up()
        return False

    def begin_case(self) -> None:
        """A case begins: its ticks' lag counts from what it is now (the pause before it is no lag of the loop)."""
        self.lag_floor = math.inf

    def _watchdog(self, lag: float, t: float) -> None:
        """The tick loop is `lag` s behind the wall clock at tick time t: go to the wall clock's tick (the next case
        starts on time; a plant's models skip the ticks between, and a scenario resets them) and end the case."""
        self.skipped += max(0, int(self.clock.now() / self.dt) - self.tick)
        self.tick = max(self.tick, int(self.clock.now() / self.dt))
        self.lag_floor = math.inf
        self._catch_up()
        raise Inconclusive(f"watchdog: bench time fell behind wall time by {lag:.3f} s at {t:.3f} s (more than "
                           f"{self.watchdog:g} s beyond its least lag in the case, BENCH_WATCHDOG): the bench could "
                           f"not keep real time")

    def _catch_up(self) -> None:
        """In real time, read what waits in the sockets before the caller looks at the bus: a station that
        is behind (it takes one batch per tick) would otherwise answer with values of the past, or call a
        message timed out that only waits to be read. Bounded (CATCH_UP_FRAMES), so that it returns."""
        if not self.clock.realtime:
            return
        for station in self.stations:
            read = 0
            while read < CATCH_UP_FRAMES:
                got = station.poll(0.0)
                read += got
                if got < POLL_BATCH:
                    break
