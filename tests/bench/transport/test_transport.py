"""bench/transport: each kind of bus gets its own adapter, chosen once by what the bus is (issue 28), and each
adapter does what its docstring says with the real bus class where this host can build it."""

from __future__ import annotations

import random
import socket
import uuid
from typing import Any

import can
import pytest

from bench import canid
from bench.transport import PythonCanTransport, VirtualTimeBus, open_bus, transport_for
from bench.transport.embedded import EmbeddedTransport
from bench.transport.socketcan import SocketcanTransport
from bench.transport.udp import UdpMulticastTransport


class _RawCanSocket:
    """What python-can's socketcan bus holds in `socket`: a raw SocketCAN socket (family and type only)."""

    family, type = getattr(socket, "AF_CAN", 29), socket.SOCK_RAW

    def getsockopt(self, level: int, option: int) -> int:
        return 0

    def fileno(self) -> int:
        return 7


class _SocketcanLike(can.BusABC):
    def __init__(self) -> None:
        super().__init__(channel="fake")
        self.socket = _RawCanSocket()

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        pass

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return None, False


def _kind(bus: can.BusABC) -> type:
    return type(transport_for(bus))


def test_the_embedded_bus_gets_its_adapter_and_hands_frames_over_as_bytes() -> None:
    channel = f"transport-{uuid.uuid4()}"
    sender, receiver = VirtualTimeBus(channel=channel), VirtualTimeBus(channel=channel)
    try:
        out, into = transport_for(sender), transport_for(receiver)
        assert type(out) is EmbeddedTransport and type(into) is EmbeddedTransport
        assert not into.receive_stamped and not into.stamped_batches and not into.loops_back
        assert list(into.frames(0.0, 8)) == []       # nothing pending
        out.send(0.25, 0x101, b"\x01\x02\x03")
        [frame] = list(into.frames(0.0, 8))
        assert (frame.timestamp, frame.arbitration_id, bytes(frame.data)) == (0.25, 0x101, b"\x01\x02\x03")
        assert into.periodic(None) is None            # type: ignore[arg-type]  # no periodic sending offered
    finally:
        sender.shutdown()
        receiver.shutdown()


def test_python_cans_virtual_bus_goes_through_recv_and_send() -> None:
    channel = f"transport-{uuid.uuid4()}"
    sender, receiver = can.Bus(interface="virtual", channel=channel), can.Bus(interface="virtual", channel=channel)
    try:
        out, into = transport_for(sender), transport_for(receiver)
        assert type(out) is PythonCanTransport and into.receive_stamped and not into.stamped_batches
        out.send(0.0, 0x102, b"\xAA")
        out.send(0.0, canid.ERR, b"")      # an error frame (bench.canid)
        frames = list(into.frames(1.0, 8))
        assert [(f.arbitration_id, bytes(f.data), f.is_error_frame) for f in frames] == \
            [(0x102, b"\xAA", False), (0x000, b"", True)]
    finally:
        sender.shutdown()
        receiver.shutdown()


def test_a_batch_stops_at_its_limit_and_leaves_the_rest() -> None:
    channel = f"transport-{uuid.uuid4()}"
    sender, receiver = can.Bus(interface="virtual", channel=channel), can.Bus(interface="virtual", channel=channel)
    try:
        out, into = transport_for(sender), transport_for(receiver)
        for i in range(5):
            out.send(0.0, 0x100 + i, bytes([i]))
        assert [f.arbitration_id for f in into.frames(1.0, 3)] == [0x100, 0x101, 0x102]
        assert [f.arbitration_id for f in into.frames(1.0, 3)] == [0x103, 0x104]
    finally:
        sender.shutdown()
        receiver.shutdown()


def test_a_raw_socketcan_socket_gets_the_socketcan_adapter(monkeypatch: pytest.MonkeyPatch) -> None:
    bus = _SocketcanLike()
    assert _kind(bus) is SocketcanTransport
    transport: Any = transport_for(bus)
    assert transport.fast is not None and not transport.fast.native   # a stand-in socket: python-can's send
    assert not transport.stamped_batches
    monkeypatch.setenv("BENCH_FAST_RX", "0")
    assert transport_for(bus).fast is None                         # type: ignore[attr-defined]
    bus.shutdown()


def _group() -> str:
    return f"239.255.{random.randint(0, 255)}.{random.randint(1, 254)}"


def test_udp_multicast_gets_its_adapter_and_loops_its_frames_back() -> None:
    bus = open_bus("udp_multicast", _group())
    try:
        transport = transport_for(bus)
        assert type(transport) is UdpMulticastTransport and transport.loops_back and transport.receive_stamped
        assert transport.fileno() is not None
    finally:
        bus.shutdown()
