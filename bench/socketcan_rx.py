"""Receiving from a python-can socketcan bus without a `can.Message` per frame.

A station reads every frame on the bus (thousands per second) and needs only its time, identifier, flags
and data. python-can's `SocketcanBus.recv` costs a select() and a recvmsg() system call and a `can.Message`
of about twenty fields per frame; on a slow machine (the vcan lane's emulated guest) that was a large part of
the runner's time. Here the station reads the bus's own socket (the bus is opened, filtered and sent on by
python-can as before) with one non-blocking recvmsg() per frame and parses what python-can's
`capture_message` parses, the same way (tests/test_socketcan_rx.py compares the two on the same bytes).
Used only for a bus without python-can filters of its own (python-can would apply those in `recv`).
"""

from __future__ import annotations

import os
import select
import socket
import struct
from collections.abc import Iterator
from typing import Any

import can

from bench.capabilities import raw_can_socket

ENV_SWITCH = "BENCH_FAST_RX"           # "0": every frame through python-can's recv
CANFD_MTU = 72
CAN_EFF_FLAG, CAN_RTR_FLAG, CAN_ERR_FLAG = 0x80000000, 0x40000000, 0x20000000
_HEADER = struct.Struct("=IB")         # can_id, len (struct can_frame / canfd_frame)
_TIMESPEC = struct.Struct("@ll")       # SO_TIMESTAMPNS: seconds, nanoseconds
_ANCILLARY = socket.CMSG_SPACE(_TIMESPEC.size) if hasattr(socket, "CMSG_SPACE") else 0
_FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


class RawFrame:
    """What a station needs of a received frame (the fields of can.Message it reads)."""

    __slots__ = ("timestamp", "arbitration_id", "data", "is_extended_id", "is_error_frame")

    def __init__(self, timestamp: float, arbitration_id: int, data: bytes, is_extended_id: bool,
                 is_error_frame: bool) -> None:
        self.timestamp = timestamp
        self.arbitration_id = arbitration_id
        self.data = data
        self.is_extended_id = is_extended_id
        self.is_error_frame = is_error_frame


def parse(frame: bytes, ancillary: list[tuple[int, int, bytes]]) -> RawFrame:
    """One received struct can_frame/canfd_frame and its SO_TIMESTAMPNS, as python-can reads them."""
    can_id, length = _HEADER.unpack_from(frame)
    if length not in _FD_LENGTHS:          # python-can rounds an odd FD length up to the next valid one
        length = min(n for n in _FD_LENGTHS if n >= length)
    seconds, nanoseconds = _TIMESPEC.unpack_from(ancillary[0][2])
    extended = bool(can_id & CAN_EFF_FLAG)
    data = b"" if can_id & CAN_RTR_FLAG else frame[8:8 + length]   # a remote frame has no data (can.Message)
    return RawFrame(seconds + nanoseconds * 1e-9, can_id & (0x1FFFFFFF if extended else 0x7FF), data, extended,
                    bool(can_id & CAN_ERR_FLAG))


def plain_socketcan(bus: can.BusABC) -> bool:
    """A python-can socketcan bus (its raw socket reachable) without python-can filters of its own: one whose
    socket the bench may read (here) and filter in the kernel (bench/periodic.py) without changing what
    python-can's recv would have delivered."""
    return raw_can_socket(bus) is not None and not getattr(bus, "filters", None)


class FastReceiver:
    """Batches of frames from a socketcan bus's socket; `attach` says whether a bus can have one."""

    def __init__(self, sock: Any) -> None:
        self.sock = sock

    @classmethod
    def attach(cls, bus: can.BusABC) -> "FastReceiver | None":
        if not plain_socketcan(bus) or os.environ.get(ENV_SWITCH, "1") == "0" or not _ANCILLARY:
            return None
        return cls(raw_can_socket(bus))

    def frames(self, timeout: float, limit: int) -> Iterator[RawFrame]:
        """Up to `limit` frames: the first may be waited for up to `timeout` s, the rest only if waiting."""
        sock = self.sock
        if timeout > 0:
            try:
                ready, _, _ = select.select([sock], [], [], timeout)
            except OSError as exc:
                raise can.CanOperationError(f"Failed to receive: {exc.strerror}", exc.errno) from exc
            if not ready:
                return
        recvmsg, dontwait = sock.recvmsg, socket.MSG_DONTWAIT
        for _ in range(limit):
            try:
                frame, ancillary, _, _ = recvmsg(CANFD_MTU, _ANCILLARY, dontwait)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                raise can.CanOperationError(f"Error receiving: {exc.strerror}", exc.errno) from exc
            yield parse(frame, ancillary)
