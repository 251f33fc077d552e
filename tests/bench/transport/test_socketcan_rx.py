"""bench/transport/socketcan_rx.py reads a received frame exactly as python-can's socketcan `capture_message` does.

Both parse the same bytes (struct can_frame / canfd_frame and the SO_TIMESTAMPNS control message, as the
kernel delivers them) from a socket that replays them; hypothesis picks identifiers, flags, lengths, data and
times. The receiver itself runs on the fake kernel of tests/bench/transport/test_periodic.py and on the real vcan0
in the vcan lane (tests/integration/test_vcan_lane.py). Its batched receive (one recvmmsg() per batch) and its send are
checked on a real kernel socket that exists on every Linux host: an AF_UNIX datagram pair, which carries the same bytes
and SO_TIMESTAMPNS stamps.
"""

from __future__ import annotations

import socket
import struct
import time

import can
import pytest
from can.interfaces.socketcan.socketcan import capture_message
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.transport import socketcan_rx
from bench.transport.socketcan_rx import FastReceiver, MMsgBatch, parse

SO_TIMESTAMPNS = 35


class ReplaySocket:
    """Gives back prepared (frame, control message) pairs through recvmsg, then would block."""

    def __init__(self, items: list[tuple[bytes, bytes]]) -> None:
        self.items = list(items)

    def recvmsg(self, size: int, ancillary_size: int, flags: int = 0) -> tuple[bytes, list, int, tuple]:
        if not self.items:
            raise BlockingIOError
        frame, stamp = self.items.pop(0)
        assert len(frame) <= size
        return frame, [(socket.SOL_SOCKET, SO_TIMESTAMPNS, stamp)], 0, ("vcan0",)


def _frame(can_id: int, length: int, data: bytes, fd: bool) -> bytes:
    body = data[:length].ljust(64 if fd else 8, b"\0")
    return struct.pack("=IBB1xB", can_id, length, 0, 0) + body


frames = st.builds(
    lambda ext, err, rtr, ident, fd, length, data, sec, nsec: (
        (ident & (0x1FFFFFFF if ext else 0x7FF)) | (0x80000000 if ext else 0) | (0x20000000 if err else 0)
        | (0x40000000 if rtr else 0),
        length if fd else min(length, 8), data, fd, sec, nsec),
    st.booleans(), st.booleans(), st.booleans(), st.integers(0, 0x1FFFFFFF), st.booleans(),
    st.integers(0, 64), st.binary(min_size=64, max_size=64), st.integers(0, 2**31 - 1), st.integers(0, 999_999_999))


@settings(max_examples=400, deadline=None)
@given(frames)
def test_parse_agrees_with_python_can(item: tuple) -> None:
    can_id, length, data, fd, sec, nsec = item
    raw, stamp = _frame(can_id, length, data, fd), struct.pack("@ll", sec, nsec)
    ours = parse(raw, [(socket.SOL_SOCKET, SO_TIMESTAMPNS, stamp)])
    theirs: can.Message = capture_message(ReplaySocket([(raw, stamp)]))
    assert ours.timestamp == theirs.timestamp
    assert ours.arbitration_id == theirs.arbitration_id
    assert ours.is_extended_id == theirs.is_extended_id
    assert ours.is_error_frame == theirs.is_error_frame
    assert bytes(ours.data) == bytes(theirs.data)


def test_frames_stop_at_the_limit_and_when_the_socket_is_empty() -> None:
    items = [(_frame(0x100 + i, 8, bytes(range(8)), False), struct.pack("@ll", 10, i)) for i in range(5)]
    receiver = FastReceiver(ReplaySocket(items))
    first = list(receiver.frames(0.0, 3))
    assert [f.arbitration_id for f in first] == [0x100, 0x101, 0x102]
    rest = list(receiver.frames(0.0, 64))
    assert [f.arbitration_id for f in rest] == [0x103, 0x104]
    assert list(receiver.frames(0.0, 64)) == []


def test_a_bus_with_python_can_filters_keeps_python_can_recv() -> None:
    class RawSocket:                 # what bench.transport.capabilities asks of a socket: a raw CAN one
        family, type = socket.AF_CAN, socket.SOCK_RAW

    class SocketcanBus:              # filters are python-can's to apply in recv
        socket = RawSocket()
        filters = [{"can_id": 0x100, "can_mask": 0x7FF}]

    assert FastReceiver.attach(SocketcanBus()) is None
    SocketcanBus.filters = None
    assert FastReceiver.attach(SocketcanBus()) is not None


needs_recvmmsg = pytest.mark.skipif(socketcan_rx._recvmmsg is None, reason="libc without recvmmsg")


def _pair() -> tuple[socket.socket, socket.socket]:
    """(sender, receiver): a kernel datagram socket pair; the receiver stamps like a CAN_RAW socket."""
    sender, receiver = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
    receiver.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    sender.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
    return sender, receiver


@needs_recvmmsg
@settings(max_examples=60, deadline=None)
@given(st.lists(frames, max_size=90))
def test_a_recvmmsg_batch_reads_what_recvmsg_and_parse_read(items: list[tuple]) -> None:
    sender, receiver = _pair()
    try:
        raw = [_frame(can_id, length, data, fd) for can_id, length, data, fd, _, _ in items]
        before = time.time()
        for frame in raw:
            sender.send(frame)
        batch = MMsgBatch(64)
        got = batch.receive(receiver.fileno(), 1000)       # at most the batch's size per call
        assert len(got) == min(len(raw), 64)
        got += batch.receive(receiver.fileno(), 1000)
        after = time.time()
        assert len(got) == len(raw)
        assert batch.receive(receiver.fileno(), 1000) == []     # empty: no error, nothing
        for frame, ours in zip(raw, got):
            theirs = parse(frame, [(socket.SOL_SOCKET, SO_TIMESTAMPNS, struct.pack("@ll", 0, 0))])
            assert (ours.arbitration_id, ours.is_extended_id, ours.is_error_frame, bytes(ours.data)) == (
                theirs.arbitration_id, theirs.is_extended_id, theirs.is_error_frame, bytes(theirs.data))
            assert before - 0.001 <= ours.timestamp <= after + 0.001   # the kernel's stamp, epoch seconds
    finally:
        sender.close()
        receiver.close()


@needs_recvmmsg
def test_frames_on_a_kernel_socket_stop_at_the_limit_and_when_the_socket_is_empty() -> None:
    sender, receiver = _pair()
    try:
        for i in range(150):
            sender.send(_frame(0x100 + i, 8, bytes(8), False))
        fast = FastReceiver(receiver)
        assert fast.native and fast.fileno() == receiver.fileno()
        first = list(fast.frames(0.0, 100))                   # two calls: 64 + 36
        assert [f.arbitration_id for f in first] == [0x100 + i for i in range(100)]
        assert [f.arbitration_id for f in fast.frames(0.01, 100)] == [0x100 + i for i in range(100, 150)]
        started = time.monotonic()
        assert list(fast.frames(0.05, 100)) == []              # waits up to the timeout, then nothing
        assert time.monotonic() - started >= 0.04
    finally:
        sender.close()
        receiver.close()


def test_send_frame_writes_what_python_can_writes() -> None:
    from can.interfaces.socketcan.socketcan import build_can_frame

    sender, receiver = _pair()
    try:
        fast = FastReceiver(sender)
        for frame_id, data in ((0x123, b"\x01\x02"), (0x7FF, bytes(range(8))), (0x000, b"")):
            fast.send_frame(frame_id, data)
            expected = build_can_frame(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False))
            assert receiver.recv(72) == expected
    finally:
        sender.close()
        receiver.close()


def test_send_frame_on_a_full_queue_raises_python_can_s_error() -> None:
    sender, receiver = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
    try:
        fast = FastReceiver(sender)
        with pytest.raises(can.CanOperationError, match="Transmit buffer full"):
            for _ in range(100_000):                           # nobody reads: the queue fills
                fast.send_frame(0x100, bytes(8))
    finally:
        sender.close()
        receiver.close()
