"""A station: one bus handle with what one process simulates on it.

It owns the restbus of its simulated nodes, their behaviours, and a monitor of everything it
sends and receives. The test runner is one station; `bench plant` is another; on the embedded
default both run in one process on the embedded bus. It reaches its bus through one transport
(bench.transport), picked once when it is made.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Protocol

import can

from bench import canid
from bench.canid import IDENTITY
from bench.checks.monitor import Monitor
from bench.faults.plan import FaultPlan
from bench.sim.node import Behaviour, DiagnosticSide
from bench.sim.restbus import Restbus
from bench.transport import ReceivedFrame, Transport, transport_for

if TYPE_CHECKING:
    from bench.checks.timing import SelfTiming
    from bench.sim.restbus import _Slot

log = logging.getLogger(__name__)

ECHO_WINDOW = 4
BABBLE_ECHO_WINDOW = 256   # a babbling node sends many identical frames per tick (flood: PARAM per ms)
#: Frames one poll takes from the socket at most: a station slower than the bus still gets back to its
#: tick (and the clock to its deadline) instead of draining for ever; the rest waits in the socket.
POLL_BATCH = 64
#: A frame the bench sends late by more than this many cycles of its message leaves its receivers a gap of more
#: than 3 cycles (their timeout, docs/spec/k-matrix.md): the bound of bench.checks.timing.SelfTiming for a sent frame.
LATE_CYCLES = 2


def _due_ticks(schedule: Sequence[tuple[int, int, _Slot]], tick: int) -> dict[int, int]:
    """{frame id: the tick it was due at} of the restbus' schedule entries due by `tick` (a heap: only the entries
    that are due and their children are looked at)."""
    out: dict[int, int] = {}
    stack, n = [0], len(schedule)
    while stack:
        i = stack.pop()
        if i < n and schedule[i][0] <= tick:
            due, _, slot = schedule[i]
            out[slot.codec.send_id] = due
            stack.append(2 * i + 1)
            stack.append(2 * i + 2)
    return out


class _StationIO:
    """The NodeIO a behaviour sees (bench.sim.node)."""

    __slots__ = ("_station",)

    def __init__(self, station: Station) -> None:
        self._station = station

    @property
    def now(self) -> float:
        return self._station.t

    def send_values(self, message: str, **signals: float) -> None:
        self._station.restbus.set_unchecked(message, signals)

    def reset_outputs(self) -> None:
        self._station.restbus.reset_all()

    def stop_sending(self, message: str) -> None:
        restbus = self._station.restbus
        if message in restbus.slots:      # a message of an external node is not this station's to switch
            restbus.stop_sending(message)

    def resume_sending(self, message: str) -> None:
        restbus = self._station.restbus
        if message in restbus.slots:
            restbus.resume_sending(message)

    # A behaviour lives in the tick's time (the time it steps to): received frames time out against it, without
    # a clock read per question (a plant asks several per tick; each read is a system call in a UML guest).
    def latest(self, message: str) -> Mapping[str, float] | None:
        return self._station.monitor.latest(message, self._station.t)

    def timed_out(self, message: str) -> bool:
        return self._station.monitor.timed_out(message, self._station.t)

    def invalid(self, message: str) -> bool:
        return self._station.monitor.invalid(message)

    def diagnostics(self, node: str) -> DiagnosticSide | None:
        return self._station.diagnostics.get(node)


class FrameListener(Protocol):
    """Takes the frames of some identifiers as they arrive, besides the monitor (an ISO-TP endpoint: a simulated
    node's UDS server, the bench's tester), and has timers of its own that the station runs while it is busy."""

    frame_ids: tuple[int, ...]

    @property
    def busy(self) -> bool: ...

    def on_frame(self, t: float, frame_id: int, data: bytes) -> None: ...

    def poll(self, t: float) -> None: ...


class Station:
    def __init__(self, name: str, bus: can.BusABC | Transport, restbus: Restbus, monitor: Monitor,
                 now: Callable[[], float], behaviours: Sequence[Behaviour] = (),
                 stamp: Callable[[float], float] | None = None, *, every_tick: bool = True,
                 recent_monotonic: Callable[[], float] | None = None, frozen_now: bool = False) -> None:
        self.name = name
        # the one choice of how to reach the bus (a bus given as is gets its kind's adapter)
        self.transport: Transport = transport_for(bus) if isinstance(bus, can.BusABC) else bus
        self.bus = self.transport.bus
        self.restbus = restbus
        self.monitor = monitor
        self.now = now
        self.t = 0.0       # bench time of the tick in progress (or the last one): what its behaviours see
        self.drained = False   # the clock's wait read the socket empty just before this tick
        # Real time: bench time of a received frame from its receive timestamp (bench.sim.clock.WallClock.stamp,
        # checked against the clock's latest read), so a late station still measures the bus's timing, not its
        # own lateness, and a frame costs no clock read. None: the time of reading.
        self.stamp = stamp if self.transport.receive_stamped else None
        self._last_rx = float("-inf")
        # `now` does not move during a poll (the virtual clock: bench time is the tick's): without a stamp, a
        # frame gets the time read once per poll instead of a read of its own (the same number).
        self.frozen_now = frozen_now
        # A plant's models integrate every tick; a runner's timers and restbus are due-based and may skip
        # ticks when late (bench.sim.clock.Scheduler).
        self.every_tick = every_tick
        self.behaviours = list(behaviours)
        self.loops_back = self.transport.loops_back
        self.io = _StationIO(self)
        self.sent = 0
        self.send_errors = 0
        self.faults: FaultPlan | None = None     # set by the session: the run's fault plan
        self.babbles = False                     # this station plays the babbling node of flood faults
        self._delayed: list[tuple[float, int, bytes]] = []
        # Frames sent but not yet seen again, per identifier, to drop echoes of interfaces that loop
        # back a sender's own frames. A frame with our identifier and other data is a foreign sender:
        # it reaches the monitor (which will flag its counter). Bounded: only the last few are kept.
        self._echoes: dict[int, deque[bytes]] = {
            p.codec.send_id: deque(maxlen=ECHO_WINDOW) for p in restbus.slots.values()}
        # socketcan only: the kernel's broadcast manager sends the messages whose payload stays (periodic sending
        # offered by the transport, bench/transport/periodic.py)
        self.kernel = self.transport.periodic(restbus)
        if self.kernel is not None and recent_monotonic is not None:
            self.kernel.clock = recent_monotonic   # its per-tick look uses the clock's latest read
        self._frames = self.transport.frames
        self._send = self.transport.send
        self._schedule = restbus.schedule   # the restbus' heap: a tick with nothing due does not call `due`
        # Real time (set by the session): the bench's own timing (bench.checks.timing.SelfTiming). A frame it sends is
        # logged with the clock read after the tick's frames went to the driver (`send_clock`), not the tick's
        # time, so that the monitor, the log and the report's timing section see when it went out; its lateness
        # against its schedule goes to `self_timing` under "<timing_label> <message>". `recent`: the clock's latest
        # read, to time how long a received frame waited in its socket.
        self.self_timing: SelfTiming | None = None
        self.send_clock: Callable[[], float] | None = None
        self.recent: Callable[[], float] | None = None
        self.timing_label = name
        # sent this tick: (frame_id, data, the tick's time or the end of its injected delay, on the schedule)
        self._outbox: list[tuple[int, bytes, float, bool]] = []
        self._due: dict[int, int] = {}
        self._t_before = 0.0
        # Frames some listeners take besides the monitor (diagnostics: ISO-TP endpoints), by identifier
        self.listeners: dict[int, list[FrameListener]] = {}
        self._listening: list[FrameListener] = []
        #: the diagnostic side of each node this station simulates (bench.diag.server, set by the session)
        self.diagnostics: dict[str, DiagnosticSide] = {}
        self._immediate = False   # send_now in progress: its frame goes to the monitor at once (real time)

    def listen(self, listener: FrameListener) -> None:
        """Hand the frames of the listener's identifiers to it as they arrive, and poll it every tick while busy."""
        for frame_id in listener.frame_ids:
            self.listeners.setdefault(frame_id, []).append(listener)
        self._listening.append(listener)

    def unlisten(self, listener: FrameListener) -> None:
        for frame_id in listener.frame_ids:
            taking = self.listeners.get(frame_id, [])
            if listener in taking:
                taking.remove(listener)
            if not taking:
                self.listeners.pop(frame_id, None)
        if listener in self._listening:
            self._listening.remove(listener)

    def send_now(self, frame_id: int, data: bytes) -> None:
        """Send one frame outside the restbus (a diagnostic message), at the station's time, through the fault
        plan like every frame it sends. In real time it reaches the monitor (and the log) at once, with the clock
        read after it went out, not at the end of the tick: an answer to it may be received before the tick ends,
        and the ISO-TP framing check must see the two in the order they were on the bus."""
        self._immediate = True
        try:
            self.send(self.now(), frame_id, data)
        finally:
            self._immediate = False

    @property
    def stamped_batches(self) -> bool:
        """Whether its frames carry the kernel's receive time and one call reads a batch of them (socketcan,
        bench/transport/socketcan_rx.py): then a wall-clock wait may sleep and read at its end
        (bench.sim.clock.WallClock)."""
        return self.transport.stamped_batches and self.stamp is not None

    def socket_fds(self) -> tuple[int, int | None]:
        """The descriptors of its bus socket and of its kernel echo socket (None while no kernel task runs), for
        one poll() over every station's sockets; only for a station with `stamped_batches`."""
        fd = self.transport.fileno()
        assert fd is not None
        kernel = self.kernel
        return fd, kernel.echo.fileno() if kernel is not None and kernel.tasks else None

    def poll(self, timeout: float = 0.0, limit: int = POLL_BATCH) -> int:
        """Receive up to `limit` pending frames into the monitor (the first recv may wait up to timeout).
        Returns how many were read: `limit` means more may be waiting."""
        frames: Iterable[ReceivedFrame] = self._frames(timeout, limit)
        monitor, echoes, stamp, now = self.monitor, self._echoes, self.stamp, self.now
        listeners = self.listeners
        count = 0
        frozen = self.frozen_now
        t_poll: float | None = None
        t_first: float | None = None
        for msg in frames:
            count += 1
            data = bytes(msg.data)
            frame_id = getattr(msg, "frame_id", None)   # the bench's own receivers give it (bench.canid)
            if frame_id is None:
                frame_id = canid.of_message(msg)
            pending = echoes.get(frame_id)
            if pending and data in pending:
                pending.remove(data)   # our own frame looped back (udp_multicast does): already logged as tx
            else:
                if stamp is None:
                    if not frozen:
                        t = now()
                    elif t_poll is None:
                        t = t_poll = now()
                    else:
                        t = t_poll
                else:   # one socket delivers in order: a stamp never goes back (one of another base could)
                    t = self._last_rx = max(self._last_rx, stamp(msg.timestamp))
                monitor.on_frame(t, frame_id, data, "rx")
                if listeners and frame_id in listeners:   # (an error frame's frame_id is no listener's)
                    for listener in listeners[frame_id]:
                        listener.on_frame(t, frame_id, data)
                if t_first is None:
                    t_first = t
        if t_first is not None and self.self_timing is not None and self.recent is not None and stamp is not None:
            # how long the oldest frame of this poll waited in its socket (at least: `recent` may be a tick old)
            self.self_timing.add("receive path", max(0.0, self.recent() - t_first), t_first)
        return count

    def tick(self, tick: int, t: float, dt: float) -> None:
        if dt != self.restbus.dt:   # the restbus counts in the ticks of whoever ticks it (bench.sim.restbus.Restbus)
            self.restbus.set_tick(dt)
        self._t_before = self.t   # the previous tick's time: a frame due before it was parked then (_flush)
        self.t = t
        if self.drained:   # the clock's wait just found the socket empty (bench.sim.clock.WallClock.wait_until)
            self.drained = False
        else:
            self.poll(0.0)
        io = self.io
        for behaviour in self.behaviours:
            behaviour.step(io, t, dt)
        for listener in self._listening:
            if listener.busy:
                listener.poll(t)
        faults = self.faults
        if faults is not None and (faults.any or self._delayed):
            self._tick_faults(faults, t, dt)
        kernel = self.kernel
        faulty = False
        if kernel is not None:   # the transport's periodic sending (bench/transport/periodic.py)
            stamp = self.stamp
            for frame_id, data, timestamp in kernel.echoes():   # what the kernel sent for this station: tx
                self.sent += 1
                self.monitor.on_frame(self.now() if stamp is None else stamp(timestamp), frame_id, data, "tx")
            faulty = faults is not None and faults.any
            kernel.check(faulty)
        schedule = self._schedule
        if (schedule and schedule[0][0] <= tick) or self.restbus.events:   # Restbus.due's own tests
            if self.send_clock is not None and schedule and schedule[0][0] <= tick:
                self._due = _due_ticks(schedule, tick)
            due = self.restbus.due(tick)
            try:
                for frame_id, data in due:
                    if kernel is None or not kernel.offer(frame_id, data, faulty):
                        self.send(t, frame_id, data)
            finally:
                due.close()   # a send that raised: the tick's other messages stay due (Restbus.due)
        if self._outbox:
            self._flush(dt)

    def _flush(self, dt: float) -> None:
        """Real time: the frames this tick handed to the driver, into the monitor with the clock read now (after
        they went out), and each one's lateness against the tick it was due into the bench's own timing."""
        assert self.send_clock is not None
        sent = self.send_clock()
        outbox, self._outbox = self._outbox, []
        due_ticks, self._due = self._due, {}
        timing, monitor, label = self.self_timing, self.monitor, self.timing_label
        for frame_id, data, due, scheduled in outbox:
            monitor.on_frame(sent, frame_id, data, "tx")
            state = monitor.states.get(frame_id & IDENTITY)
            if timing is None or state is None:
                continue
            tick = due_ticks.get(frame_id) if scheduled else None
            # A late station skipped ticks: the frame was due at its schedule's tick. One due before the previous
            # tick (which ran and took every frame due by then) was stopped then and resumed since (stop_sending,
            # a scenario's stimulus): due from that tick, not from when it was stopped.
            due_t = due if tick is None else max(tick * dt, self._t_before)
            cycle = state.codec.cycle_time
            timing.add(f"{label} {state.codec.name}", max(0.0, sent - due_t), due_t,
                       LATE_CYCLES * cycle if cycle else float("inf"))

    def send(self, t: float, frame_id: int, data: bytes) -> None:
        """Send one frame of the restbus, through the fault plan when there is one."""
        faults = self.faults
        if faults is None or not faults.any:
            self._transmit(t, frame_id, data)
            return
        for delay, frame in faults.apply(t, frame_id, data):
            if delay > 0:
                self._delayed.append((t + delay, frame_id, frame))
            else:
                self._transmit(t, frame_id, frame)

    def _tick_faults(self, faults: FaultPlan, t: float, dt: float) -> None:
        if self._delayed:
            ready = [d for d in self._delayed if d[0] <= t + 1e-9]
            self._delayed = [d for d in self._delayed if d[0] > t + 1e-9]
            for due, frame_id, frame in ready:
                self._transmit(t, frame_id, frame, due=due)   # due when its (injected) delay ended
        if self.babbles:
            for frame_id, data in faults.babble(t, dt):
                self._transmit(t, frame_id, data)

    def _transmit(self, t: float, frame_id: int, data: bytes, due: float | None = None) -> None:
        try:
            self._send(t, frame_id, data)   # the transport's fastest way for its bus
        except can.CanError as exc:
            self.send_errors += 1   # a full queue or bus-off: the frame never reached the bus
            if self.send_errors == 1:   # the first one now; the count at the end of the run (bench.run)
                log.warning("%s station: the bus driver refused a frame (%s at %.3f s): %s; the frame was "
                            "not sent", self.name, canid.text(frame_id), t, exc)
            self.monitor.note_send_failure(t, frame_id, str(exc))
            return
        self.sent += 1
        if self.loops_back:   # a babbling node's identifier (flood) has no periodic message: its own window
            echoes = self._echoes.get(frame_id)
            if echoes is None:
                echoes = self._echoes[frame_id] = deque(maxlen=BABBLE_ECHO_WINDOW)
            echoes.append(data)
        if self.send_clock is not None:   # real time: logged when the tick's frames are out (_flush)
            if self._immediate:
                self.monitor.on_frame(self.send_clock(), frame_id, data, "tx")
                return
            self._outbox.append((frame_id, data, t if due is None else due, due is None))
            return
        self.monitor.on_frame(t, frame_id, data, "tx")
