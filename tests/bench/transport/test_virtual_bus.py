"""The embedded bus (`embedded`, bench.transport.embedded.VirtualTimeBus) where python-can's own tests do not look
(scripts/python-can-suite runs those): recv(timeout) sleeps instead of polling, a dropped bus is collected and
stops receiving, each receiver gets its own copy with its own channel, a shut-down bus raises, and the sender's
(virtual) time is kept."""

from __future__ import annotations

import gc
import threading
import time
import weakref

import can
import pytest

from bench.transport import VirtualTimeBus


def test_recv_with_timeout_sleeps_on_a_quiet_bus() -> None:
    """A polling recv made hundreds of thousands of _recv_internal calls in 0.2 s; a sleeping one makes ~1."""
    with VirtualTimeBus(channel="quiet") as bus:
        calls = 0
        inner = bus._recv_internal

        def counted(timeout: float | None) -> tuple[can.Message | None, bool]:
            nonlocal calls
            calls += 1
            return inner(timeout)

        bus._recv_internal = counted  # type: ignore[method-assign]
        started = time.process_time()
        assert bus.recv(0.2) is None
        cpu = time.process_time() - started
    assert calls <= 3
    assert cpu < 0.05          # of 0.2 s waited: sleeping, not spinning


def test_recv_wakes_when_a_frame_arrives() -> None:
    with VirtualTimeBus(channel="wake") as sender, VirtualTimeBus(channel="wake") as receiver:
        timer = threading.Timer(0.05, sender.send, [can.Message(arbitration_id=0x42, is_extended_id=False)])
        started = time.monotonic()
        timer.start()
        msg = receiver.recv(5.0)
        waited = time.monotonic() - started
        timer.join()
    assert msg is not None and msg.arbitration_id == 0x42
    assert waited < 1.0


def test_a_dropped_bus_is_collected_and_stops_queueing() -> None:
    sender = VirtualTimeBus(channel="drop")
    dropped = VirtualTimeBus(channel="drop")
    inbox = dropped.queue
    gone = weakref.ref(dropped)
    del dropped
    gc.collect()
    assert gone() is None
    for _ in range(100):
        sender.send(can.Message())
    assert inbox.qsize() == 0
    sender.shutdown()


def test_each_receiver_gets_its_own_copy_with_its_channel_and_direction() -> None:
    with VirtualTimeBus(channel=7, receive_own_messages=True) as a, VirtualTimeBus(channel="7") as b:
        msg = can.Message(timestamp=1.25, arbitration_id=0x10, data=[1, 2, 3], is_extended_id=False)
        a.send(msg)
        msg.data[0] = 99                      # the sender changes its message after sending
        own, other = a.recv(0), b.recv(0)
    assert own is not other and own is not msg and other is not msg
    assert bytes(own.data) == bytes(other.data) == b"\x01\x02\x03"
    assert (own.channel, own.is_rx) == (7, False)
    assert (other.channel, other.is_rx) == ("7", True)
    assert own.timestamp == other.timestamp == 1.25       # virtual time: the sender's stamp, not the wall clock


def test_a_shut_down_bus_raises_and_no_longer_receives() -> None:
    a, b = VirtualTimeBus(channel="closed"), VirtualTimeBus(channel="closed")
    b.shutdown()
    a.send(can.Message())                      # the closed peer is off the channel: nothing to deliver to
    with pytest.raises(can.CanOperationError):
        b.send(can.Message())
    with pytest.raises(can.CanOperationError):
        b.recv(0)
    a.shutdown()


def test_shutdown_wakes_a_waiting_recv() -> None:
    bus = VirtualTimeBus(channel="wake-on-close")
    errors: list[BaseException] = []

    def wait() -> None:
        try:
            bus.recv(None)
        except can.CanOperationError as exc:
            errors.append(exc)

    thread = threading.Thread(target=wait)
    thread.start()
    time.sleep(0.05)
    bus.shutdown()
    thread.join(2.0)
    assert not thread.is_alive() and len(errors) == 1


def test_raw_frames_skip_can_message_yet_python_can_receivers_get_their_own() -> None:
    """send_raw (the stations' path) hands one shared frame to station readers (raw_frames) and a fresh
    can.Message, with its channel, is_rx and the sender's time, to a python-can recv; a can.Message sent the
    python-can way reaches raw_frames as the receiver's copy."""
    with VirtualTimeBus(channel="raw") as a, VirtualTimeBus(channel="raw") as b, \
            VirtualTimeBus(channel="raw") as c:
        payload = bytearray(b"\x01\x02\x03\x04\x05\x06\x07\x08")
        a.send_raw(0.125, 0x123, payload)
        payload[0] = 0xFF                      # the sender's buffer changes later: the frame sent does not
        frames = list(b.raw_frames(0.0, 64))
        assert [(f.timestamp, f.arbitration_id, bytes(f.data), f.is_extended_id, f.is_error_frame)
                for f in frames] == [(0.125, 0x123, b"\x01\x02\x03\x04\x05\x06\x07\x08", False, False)]
        msg = c.recv(0.0)
        assert msg is not None and msg.timestamp == 0.125 and msg.arbitration_id == 0x123
        assert msg.channel == "raw" and msg.is_rx and not msg.is_fd and msg.dlc == 8
        assert msg.data == bytearray(b"\x01\x02\x03\x04\x05\x06\x07\x08") and isinstance(msg.data, bytearray)
        assert a.recv(0.0) is None             # not its own frames (receive_own_messages=False)
        a.send(can.Message(timestamp=0.25, arbitration_id=0x7FF, data=b"\x09", is_extended_id=False))
        (copy,) = list(b.raw_frames(0.0, 64))
        assert isinstance(copy, can.Message) and copy.arbitration_id == 0x7FF and copy.data == bytearray(b"\x09")
        for i in range(5):
            a.send_raw(i, 0x100 + i, b"")
        assert [f.arbitration_id for f in b.raw_frames(0.0, 3)] == [0x100, 0x101, 0x102]   # at most `limit`
        assert [f.arbitration_id for f in b.raw_frames(0.0, 3)] == [0x103, 0x104]
    with pytest.raises(can.CanOperationError):
        list(b.raw_frames(0.0, 1))


def test_raw_frames_of_own_sends_when_asked() -> None:
    with VirtualTimeBus(channel="own", receive_own_messages=True) as a:
        a.send_raw(1.0, 0x10, b"\x00")
        (msg,) = list(a.raw_frames(0.0, 8))
        assert isinstance(msg, can.Message) and not msg.is_rx and msg.timestamp == 1.0
