"""The one interface between a station and its bus, and its adapter for any python-can bus.

Why: a station must read every frame on the bus and send its restbus at its tick, and each kind of bus has a
faster way to do it than python-can's per-frame `recv`/`send` (the embedded bus hands frames over as bytes,
SocketCAN reads batches from its socket and sends cyclic frames from the kernel). The station picks its adapter
once (`bench.transport.transport_for`) and then asks it nothing about the bus: what a kind of bus can do is said
here and in its adapter (bench.transport.embedded, .socketcan, .udp), never found out by the station.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, Protocol, final

import can

from bench import canid
from bench.transport.capabilities import delivers_own_frames

if TYPE_CHECKING:
    from bench.sim.restbus import Restbus
    from bench.transport.periodic import KernelPeriodic


class ReceivedFrame(Protocol):
    """What a station reads of a received frame (can.Message has these; so do the adapters' lighter frames)."""

    @property
    def timestamp(self) -> float: ...
    @property
    def arbitration_id(self) -> int: ...
    @property
    def data(self) -> bytes | bytearray: ...
    @property
    def is_extended_id(self) -> bool: ...
    @property
    def is_error_frame(self) -> bool: ...


@final   # no subclasses: the embedded bus's receive paths test `type(item) is Frame`, the fast test
class Frame:
    """A received frame as the bench's own receivers hand it over: its frame_id (bench.canid: SocketCAN's can_id,
    and the CAN FD flags above it), time and data, never changed. The embedded bus shares one with every receiver
    (`VirtualTimeBus.send_raw`; python-can's `recv` turns it into the receiver's own can.Message), the SocketCAN
    receiver makes one per frame it reads (bench.transport.socketcan_rx); the can.Message fields a station reads
    (ReceivedFrame) come from the frame_id."""

    __slots__ = ("timestamp", "frame_id", "data")

    def __init__(self, timestamp: float, frame_id: int, data: bytes) -> None:
        self.timestamp = timestamp
        self.frame_id = frame_id
        self.data = data

    @property
    def arbitration_id(self) -> int:
        return canid.arbitration_id(self.frame_id)

    @property
    def is_extended_id(self) -> bool:
        return canid.is_extended(self.frame_id)

    @property
    def is_error_frame(self) -> bool:
        return canid.is_error(self.frame_id)


class Transport(Protocol):
    """A station's bus: receive a batch, send, periodic sending where the bus offers it, the receive stamp."""

    bus: can.BusABC
    #: A frame it sends comes back to its own receive side (the station then drops such echoes).
    loops_back: bool
    #: Its frames' timestamps are their receive times on the wall clock (epoch s), which the clock turns into
    #: bench time; False: the sender's bench time (the embedded bus), and the station uses the time of reading.
    receive_stamped: bool
    #: Its frames carry the kernel's receive time and one call reads a batch: a wall-clock wait may sleep and read
    #: at its end (bench.sim.clock.WallClock.wait_until).
    stamped_batches: bool

    def frames(self, timeout: float, limit: int) -> Iterable[ReceivedFrame]:
        """Up to `limit` pending frames; the first may be waited for up to `timeout` s, the rest only if here."""

    def send(self, t: float, frame_id: int, data: bytes) -> None:
        """A frame at bench time `t`: its identifier, format and kind (an error frame, a CAN FD frame...) are
        `frame_id`'s (bench.canid); a refused frame raises can.CanError."""

    def periodic(self, restbus: Restbus) -> KernelPeriodic | None:
        """Periodic sending offered by the bus for `restbus`'s messages (SocketCAN's broadcast manager), or None."""

    def fileno(self) -> int | None:
        """A descriptor that becomes readable when a frame arrives (one poll() over several stations), or None."""

    def shutdown(self) -> None: ...


class PythonCanTransport:
    """Any python-can bus, through python-can's own `recv` and `send`."""

    receive_stamped = True
    stamped_batches = False

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.loops_back = delivers_own_frames(bus)   # asked of the bus (bench/transport/capabilities.py)

    def frames(self, timeout: float, limit: int) -> Iterable[ReceivedFrame]:
        return self._recv(timeout, limit)

    def _recv(self, timeout: float, limit: int) -> Iterator[can.Message]:
        bus = self.bus
        msg = bus.recv(timeout)
        count = 0
        while msg is not None:
            yield msg
            count += 1
            if count >= limit:
                return      # not one recv more: a frame read here would be lost
            msg = bus.recv(0.0)

    def send(self, t: float, frame_id: int, data: bytes) -> None:
        self.bus.send(can.Message(timestamp=t, data=data, **canid.message_kwargs(frame_id)))

    def periodic(self, restbus: Restbus) -> KernelPeriodic | None:
        return None

    def fileno(self) -> int | None:
        try:
            fd = int(self.bus.fileno())
        except (NotImplementedError, AttributeError, OSError, ValueError, TypeError):
            return None
        return fd if fd >= 0 else None

    def shutdown(self) -> None:
        self.bus.shutdown()
