"""SocketCAN for a station: its fast receiver (batches from the bus's own socket, bench/transport/socketcan_rx.py)
and the kernel's broadcast manager for periodic sending (bench/transport/periodic.py).

Each of the two is used only where it cannot change what python-can would have done: a bus with python-can
filters of its own, or either switched off (BENCH_FAST_RX=0, BENCH_KERNEL_PERIODIC=0), keeps python-can's
`recv`/`send` and the tick scheduler.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import can

from bench.transport.base import PythonCanTransport
from bench.transport.periodic import KernelPeriodic
from bench.transport.socketcan_rx import FastReceiver

if TYPE_CHECKING:
    from bench.sim.restbus import Restbus


class SocketcanTransport(PythonCanTransport):
    """A python-can socketcan bus (a raw SocketCAN socket): frames read in batches with the kernel's receive time,
    sent with one send() each, cyclic frames handed to the kernel."""

    def __init__(self, bus: can.BusABC, fast: FastReceiver | None = None) -> None:
        """`fast`: the receiver of the bus's socket (default: `FastReceiver.attach`, None where it does not apply)."""
        super().__init__(bus)
        self.fast = fast if fast is not None else FastReceiver.attach(bus)
        if self.fast is not None:
            self.frames = self.fast.frames   # type: ignore[method-assign]
            # a socket of the kernel (not a test's stand-in): one plain send() per frame, batches with the kernel's
            # receive time
            self.stamped_batches = self.fast.native
            if self.fast.native:
                self._send_frame = self.fast.send_frame
                self.send = self._send_fast   # type: ignore[method-assign]

    def _send_fast(self, t: float, frame_id: int, data: bytes) -> None:
        self._send_frame(frame_id, data)     # one send(): no can.Message, no select, no clock read

    def periodic(self, restbus: Restbus) -> KernelPeriodic | None:
        return KernelPeriodic.attach(self.bus, restbus)

    @property
    def channel(self) -> str | None:
        """The interface's name (e.g. vcan0), for a socket of another protocol on it (the kernel's ISO-TP)."""
        channel = getattr(self.bus, "channel", None)
        return channel if isinstance(channel, str) else None

    def fileno(self) -> int | None:
        if self.fast is not None:
            return self.fast.fileno()
        return super().fileno()
