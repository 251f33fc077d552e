"""A station: one bus handle with what one process simulates on it.

It owns the restbus of its simulated nodes, their behaviours, and a monitor of everything it
sends and receives. The test runner is one station; `bench plant` is another; on the embedded
default both run in one process on the virtual-time bus.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence

import can

from bench.monitor import Monitor
from bench.node import Behaviour
from bench.restbus import Restbus


ECHO_WINDOW = 4
#: python-can buses that deliver a sender's own frames back to it, whatever receive_own_messages says.
LOOPING_BUS_CLASSES = ("UdpMulticastBus",)


class _StationIO:
    """The NodeIO a behaviour sees (bench.node)."""

    __slots__ = ("_station",)

    def __init__(self, station: "Station") -> None:
        self._station = station

    @property
    def now(self) -> float:
        return self._station.now()

    def send_values(self, message: str, **signals: float) -> None:
        self._station.restbus.set_unchecked(message, signals)

    def reset_outputs(self) -> None:
        self._station.restbus.reset_all()

    def latest(self, message: str) -> Mapping[str, float] | None:
        return self._station.monitor.latest(message, self._station.now())

    def timed_out(self, message: str) -> bool:
        return self._station.monitor.timed_out(message, self._station.now())

    def invalid(self, message: str) -> bool:
        return self._station.monitor.invalid(message)


class Station:
    def __init__(self, name: str, bus: can.BusABC, restbus: Restbus, monitor: Monitor,
                 now: Callable[[], float], behaviours: Sequence[Behaviour] = ()) -> None:
        self.name = name
        self.bus = bus
        self.restbus = restbus
        self.monitor = monitor
        self.now = now
        self.behaviours = list(behaviours)
        self.loops_back = type(bus).__name__ in LOOPING_BUS_CLASSES
        self.io = _StationIO(self)
        self.sent = 0
        self.send_errors = 0
        # Frames sent but not yet seen again, per identifier, to drop echoes of interfaces that loop
        # back a sender's own frames. A frame with our identifier and other data is a foreign sender:
        # it reaches the monitor (which will flag its counter). Bounded: only the last few are kept.
        self._echoes: dict[int, deque[bytes]] = {
            p.codec.frame_id: deque(maxlen=ECHO_WINDOW) for p in restbus.periodic.values()}

    def poll(self, timeout: float = 0.0) -> None:
        """Receive every pending frame into the monitor (the first recv may wait up to timeout)."""
        bus, monitor, echoes = self.bus, self.monitor, self._echoes
        msg = bus.recv(timeout)
        while msg is not None:
            data = bytes(msg.data)
            pending = echoes.get(msg.arbitration_id)
            if pending and data in pending:
                pending.remove(data)   # our own frame looped back (udp_multicast does): already logged as tx
            else:
                monitor.on_frame(self.now(), msg.arbitration_id, data, "rx", msg.is_extended_id,
                                 msg.is_error_frame)
            msg = bus.recv(0.0)

    def tick(self, tick: int, t: float, dt: float) -> None:
        self.poll(0.0)
        io = self.io
        for behaviour in self.behaviours:
            behaviour.step(io, t, dt)
        for frame_id, data in self.restbus.due(tick):
            self.send(t, frame_id, data)
        self.monitor.check_timeouts(t)

    def send(self, t: float, frame_id: int, data: bytes) -> None:
        msg = can.Message(timestamp=t, arbitration_id=frame_id, data=data, is_extended_id=False,
                          is_fd=False)
        try:
            self.bus.send(msg)
        except can.CanError:
            self.send_errors += 1   # a full queue or bus-off: counted, the frame is still logged as sent
        self.sent += 1
        if self.loops_back:
            self._echoes[frame_id].append(data)
        self.monitor.on_frame(t, frame_id, data, "tx")

    def reset_behaviours(self) -> None:
        for behaviour in self.behaviours:
            behaviour.reset()
