"""bench/transport/capabilities.py: what a bus can do is asked of the bus, never of its class name. Real python-can
classes where this host can build them (udp_multicast on loopback with hop limit 0, python-can's virtual bus)
and the bench's virtual-time bus; SocketCAN does not exist here, so its socket is a fake of the right family."""

from __future__ import annotations

import os
import socket
import uuid

import can
import pytest

from bench.transport import UDP_MULTICAST_HOP_LIMIT, VirtualTimeBus, capabilities, open_bus
from bench.transport.socketcan_rx import plain_socketcan
from tests.fakes import FakeBus, ipv4_group


class _FakeCanSocket:
    """A raw SocketCAN socket as far as the bench asks: family, type and CAN_RAW_RECV_OWN_MSGS."""

    def __init__(self, own: int = 0, family: int = socket.AF_CAN, kind: int = socket.SOCK_RAW) -> None:
        self.family, self.type, self.own = family, kind, own

    def getsockopt(self, level: int, option: int) -> int:
        assert (level, option) == (socket.SOL_CAN_RAW, socket.CAN_RAW_RECV_OWN_MSGS)
        return self.own


# -- "does this bus deliver my own frames back to me?" ------------------------------------------------------
def test_udp_multicast_loops_its_own_frames_back_and_says_so() -> None:
    """python-can's udp_multicast: its socket has IP_MULTICAST_LOOP on (whatever receive_own_messages says);
    the answer is checked against what the bus really does."""
    bus = open_bus("udp_multicast", ipv4_group())
    try:
        assert capabilities.delivers_own_frames(bus)
        bus.send(can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False))
        echo = bus.recv(2.0)
        assert echo is not None and echo.arbitration_id == 0x123 and bytes(echo.data) == b"\x01\x02"
    finally:
        bus.shutdown()


def test_virtual_buses_say_what_they_were_told() -> None:
    for own in (False, True):
        ours = VirtualTimeBus(channel=f"cap-{uuid.uuid4()}", receive_own_messages=own)
        theirs = can.Bus(interface="virtual", channel=f"cap-{uuid.uuid4()}", receive_own_messages=own)
        try:
            assert capabilities.delivers_own_frames(ours) is own
            assert capabilities.delivers_own_frames(theirs) is own
            ours.send(can.Message(arbitration_id=1, data=b"", is_extended_id=False))
            assert (ours.recv(0.0) is not None) is own          # and so they do
        finally:
            ours.shutdown()
            theirs.shutdown()


def test_socketcan_is_asked_through_its_socket_option() -> None:
    assert not capabilities.delivers_own_frames(FakeBus(socket=_FakeCanSocket(own=0)))
    assert capabilities.delivers_own_frames(FakeBus(socket=_FakeCanSocket(own=1)))
    # the socket outranks an attribute that says otherwise
    assert capabilities.delivers_own_frames(FakeBus(socket=_FakeCanSocket(own=1), receive_own_messages=False))


def test_a_bus_that_says_nothing_does_not_loop() -> None:
    assert not capabilities.delivers_own_frames(FakeBus())


# -- "does it have a raw SocketCAN socket I can read directly?" ----------------------------------------------
def test_raw_can_socket_needs_family_af_can_and_a_raw_socket() -> None:
    raw = _FakeCanSocket()
    assert capabilities.raw_can_socket(FakeBus(socket=raw)) is raw
    assert capabilities.raw_can_socket(FakeBus(socket=_FakeCanSocket(kind=socket.SOCK_DGRAM))) is None   # BCM, ISO-TP
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as tcp:                     # socketcand's TCP link
        assert capabilities.raw_can_socket(FakeBus(socket=tcp)) is None
    assert capabilities.raw_can_socket(FakeBus()) is None
    # python-can filters of the bus's own: the bench must not read around them
    assert plain_socketcan(FakeBus(socket=raw))
    filtered = FakeBus(socket=raw)
    filtered.set_filters([{"can_id": 0x100, "can_mask": 0x7FF}])
    assert not plain_socketcan(filtered)


def test_udp_multicast_and_virtual_buses_have_no_raw_can_socket() -> None:
    bus = open_bus("udp_multicast", ipv4_group())
    ours = VirtualTimeBus(channel=f"cap-{uuid.uuid4()}")
    try:
        assert capabilities.raw_can_socket(bus) is None and capabilities.raw_can_socket(ours) is None
    finally:
        bus.shutdown()
        ours.shutdown()


# -- "could this interface's frames leave the host?" --------------------------------------------------------
@pytest.mark.parametrize(("interface", "expected"), [("udp_multicast", True), ("socketcan", False),
                                                     ("virtual", False), ("no_such_interface", False)])
def test_takes_hop_limit_from_the_interface_class(interface: str, expected: bool) -> None:
    assert capabilities.takes_hop_limit(interface) is expected


def test_open_bus_pins_the_hop_limit_of_a_multicast_bus() -> None:
    bus = open_bus("udp_multicast", ipv4_group())
    try:
        with socket.socket(fileno=os.dup(bus.fileno())) as sock:
            assert sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == UDP_MULTICAST_HOP_LIMIT
    finally:
        bus.shutdown()
