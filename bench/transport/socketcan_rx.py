"""Receiving from a python-can socketcan bus without a `can.Message` per frame.

A station reads every frame on the bus (thousands per second) and needs only its time, identifier, flags
and data. python-can's `SocketcanBus.recv` costs a select() and a recvmsg() system call and a `can.Message`
of about twenty fields per frame; on a slow machine (the vcan lane's emulated guest) that was a large part of
the runner's time. Here the station reads the bus's own socket (the bus is opened, filtered and sent on by
python-can as before) with one non-blocking recvmsg() per frame and parses what python-can's
`capture_message` parses, the same way (tests/bench/transport/test_socketcan_rx.py compares the two on the same bytes).
Used only for a bus without python-can filters of its own (python-can would apply those in `recv`).

System calls are what a slow guest pays for (the vcan lane under User-mode Linux: a call costs many times what parsing
a frame does, docs/vcan-lane.md), so a batch is one `recvmmsg()` (through ctypes, Linux): up to `limit` frames and
their timestamps per call, and a short batch says the socket is empty without one more call. Where libc has no
recvmmsg, one non-blocking recvmsg() per frame. `send_frame` sends a classic data frame with one `send()`
(python-can's send adds a select() and a clock read per frame)."""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import os
import select
import socket
import struct
from collections.abc import Iterator
from typing import Any

import can

from bench import canid
from bench.transport.base import Frame
from bench.transport.capabilities import raw_can_socket

ENV_SWITCH = "BENCH_FAST_RX"           # "0": every frame through python-can's recv
CANFD_MTU = 72
_FLAGS = struct.Struct("=IBB")         # can_id, len, flags (struct canfd_frame; can_frame: __pad)
_TIMESPEC = struct.Struct("@ll")       # SO_TIMESTAMPNS: seconds, nanoseconds
_ANCILLARY = socket.CMSG_SPACE(_TIMESPEC.size) if hasattr(socket, "CMSG_SPACE") else 0
_CLASSIC = struct.Struct("=IBB1xB8s")  # struct can_frame as python-can's build_can_frame packs it (len8_dlc = len)
_FD = struct.Struct("=IBB2x64s")        # struct canfd_frame: can_id, len, flags, two reserved bytes, data
CANFD_BRS, CANFD_ESI, CANFD_FDF = 0x01, 0x02, 0x04   # canfd_frame.flags (linux/can.h)
SO_TIMESTAMPNS = 35                    # asm-generic/socket.h (Python's socket module lacks it before 3.12)
_CMSG_HEADER = socket.CMSG_LEN(0) if hasattr(socket, "CMSG_LEN") else 16   # cmsghdr, before its data


class _IOVec(ctypes.Structure):
    _fields_ = [("base", ctypes.c_void_p), ("length", ctypes.c_size_t)]


class _MsgHdr(ctypes.Structure):
    _fields_ = [("name", ctypes.c_void_p), ("namelen", ctypes.c_uint32), ("iov", ctypes.POINTER(_IOVec)),
                ("iovlen", ctypes.c_size_t), ("control", ctypes.c_void_p), ("controllen", ctypes.c_size_t),
                ("flags", ctypes.c_int)]


class _MMsgHdr(ctypes.Structure):
    _fields_ = [("hdr", _MsgHdr), ("len", ctypes.c_uint)]


def _libc_recvmmsg() -> Any:
    """libc's recvmmsg, or None (not Linux, or a libc without it)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        function = libc.recvmmsg
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_void_p]
    function.restype = ctypes.c_int
    return function


_recvmmsg = _libc_recvmmsg()


def parse(frame: bytes, ancillary: list[tuple[int, int, bytes]]) -> Frame:
    """One received struct can_frame/canfd_frame and its SO_TIMESTAMPNS, as python-can reads them."""
    seconds, nanoseconds = _TIMESPEC.unpack_from(ancillary[0][2])
    return _frame_at(frame, 0, seconds + nanoseconds * 1e-9, len(frame) == CANFD_MTU)


def _frame_at(buffer: bytes | memoryview, base: int, timestamp: float, fd: bool) -> Frame:
    """The struct can_frame (or canfd_frame when `fd`, by its size) at `base` of `buffer`, as python-can's
    capture_message reads it."""
    can_id, length, flags = _FLAGS.unpack_from(buffer, base)
    if length not in canid.FD_LENGTHS:     # python-can rounds an odd FD length up to the next valid one
        length = canid.fd_length(length)
    data = b"" if can_id & canid.RTR else bytes(buffer[base + 8:base + 8 + length])   # a remote frame: none
    if fd:
        can_id |= canid.FD | (canid.BRS if flags & CANFD_BRS else 0) | (canid.ESI if flags & CANFD_ESI else 0)
    return Frame(timestamp, can_id, data)


def plain_socketcan(bus: can.BusABC) -> bool:
    """A python-can socketcan bus (its raw socket reachable) without python-can filters of its own: one whose
    socket the bench may read (here) and filter in the kernel (bench/transport/periodic.py) without changing what
    python-can's recv would have delivered."""
    return raw_can_socket(bus) is not None and not getattr(bus, "filters", None)


class MMsgBatch:
    """Buffers for one recvmmsg() of up to `size` frames with their SO_TIMESTAMPNS, set up once."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.frames = ctypes.create_string_buffer(CANFD_MTU * size)
        self.control = ctypes.create_string_buffer(_ANCILLARY * size)
        self.iov = (_IOVec * size)()
        self.headers = (_MMsgHdr * size)()
        frames, control = ctypes.addressof(self.frames), ctypes.addressof(self.control)
        for i in range(size):
            self.iov[i].base, self.iov[i].length = frames + i * CANFD_MTU, CANFD_MTU
            header = self.headers[i].hdr
            header.iov = ctypes.pointer(self.iov[i])
            header.iovlen = 1
            header.control = control + i * _ANCILLARY
        self._frames_view = memoryview(self.frames).cast("B")
        self._control_view = memoryview(self.control).cast("B")

    def receive(self, fd: int, limit: int) -> list[Frame]:
        """The frames waiting in socket `fd`, up to min(limit, size), without waiting (one system call)."""
        count = min(limit, self.size)
        headers = self.headers
        for i in range(count):      # the kernel writes each control length back: reset it for this call
            header = headers[i].hdr
            header.controllen = _ANCILLARY
            header.flags = 0
        got = _recvmmsg(fd, headers, count, socket.MSG_DONTWAIT, None)
        if got < 0:
            error = ctypes.get_errno()
            if error in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EINTR):
                return []
            raise can.CanOperationError(f"Error receiving: {os.strerror(error)}", error)
        frames, control = self._frames_view, self._control_view
        out = []
        for i in range(got):
            if headers[i].hdr.controllen >= _ANCILLARY:
                seconds, nanoseconds = _TIMESPEC.unpack_from(control, i * _ANCILLARY + _CMSG_HEADER)
                timestamp = seconds + nanoseconds * 1e-9
            else:
                timestamp = 0.0     # no stamp: outside any clock's window, the frame gets the time of reading
            out.append(_frame_at(frames, i * CANFD_MTU, timestamp, headers[i].len == CANFD_MTU))
        return out


class FastReceiver:
    """Batches of frames from a socketcan bus's socket; `attach` says whether a bus can have one."""

    def __init__(self, sock: Any, batch: int = 64) -> None:
        self.sock = sock
        # a socket of the kernel (not a test's stand-in): batched receive and a plain send() on its descriptor
        self.native = isinstance(sock, socket.socket)
        self._batch = MMsgBatch(batch) if self.native and _recvmmsg is not None and _ANCILLARY else None

    @classmethod
    def attach(cls, bus: can.BusABC) -> FastReceiver | None:
        if not plain_socketcan(bus) or os.environ.get(ENV_SWITCH, "1") == "0" or not _ANCILLARY:
            return None
        return cls(raw_can_socket(bus))

    def fileno(self) -> int:
        return int(self.sock.fileno())

    def frames(self, timeout: float, limit: int) -> Iterator[Frame]:
        """Up to `limit` frames: the first may be waited for up to `timeout` s, the rest only if waiting."""
        sock = self.sock
        if timeout > 0:
            try:
                ready, _, _ = select.select([sock], [], [], timeout)
            except OSError as exc:
                raise can.CanOperationError(f"Failed to receive: {exc.strerror}", exc.errno) from exc
            if not ready:
                return
        batch = self._batch
        if batch is not None:
            fd = sock.fileno()
            while limit > 0:
                asked = min(limit, batch.size)
                got = batch.receive(fd, asked)
                yield from got
                if len(got) < asked:
                    return          # a short batch: the socket was empty
                limit -= asked
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

    def send_frame(self, frame_id: int, data: bytes) -> None:
        """A frame (its frame_id: bench.canid) with one non-blocking send() (python-can's send: a clock read, a
        select() and the send); a full queue raises CanOperationError as python-can's does."""
        try:
            length = len(data)
            if frame_id <= canid.CAN_ID:
                frame = _CLASSIC.pack(frame_id, length, 0, length, data)
            else:
                flags = (CANFD_FDF | (CANFD_BRS if frame_id & canid.BRS else 0)
                         | (CANFD_ESI if frame_id & canid.ESI else 0))
                frame = _FD.pack(frame_id & canid.CAN_ID, canid.fd_length(length), flags, data)
            sent = self.sock.send(frame, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError) as exc:
            raise can.CanOperationError("Transmit buffer full") from exc
        except ValueError as exc:   # longer than a CAN FD frame
            raise can.CanOperationError(str(exc)) from None
        except OSError as exc:
            raise can.CanOperationError(f"Failed to transmit: {exc.strerror}", exc.errno) from exc
        if sent != len(frame):
            raise can.CanOperationError("Transmit buffer full")

