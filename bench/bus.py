"""Opening buses: the in-process virtual-time bus (the embedded default) or any python-can interface.

`VirtualTimeBus` is a python-can `BusABC` registered as the interface `bench_virtual`. Unlike
python-can's `virtual` interface it has no threads and never blocks: frames are handed over in
the order they were sent, stamped by the sender with the bench's virtual time, so that a campaign
gives the same frame sequence on every run.
"""

from __future__ import annotations

import socket
import sys
from collections import deque
from typing import Any

import can

from bench.errors import ConfigError

VIRTUAL = "virtual"   # the name users give on the command line for the embedded default

#: udp_multicast must never leave this host (Developers' guide: hop limit 0).
UDP_MULTICAST_HOP_LIMIT = 0
#: python-can's default IPv4 group for udp_multicast (an administratively scoped address).
UDP_MULTICAST_DEFAULT_GROUP = "239.74.163.2"


class VirtualTimeBus(can.BusABC):
    """An in-process bus whose instances on the same channel receive each other's frames."""

    _channels: dict[str, list["VirtualTimeBus"]] = {}

    def __init__(self, channel: Any = "bench", receive_own_messages: bool = False, **kwargs: Any) -> None:
        super().__init__(channel=channel, **kwargs)
        self.channel_info = f"bench virtual-time bus {channel!r}"
        self._channel_name = str(channel)
        self._queue: deque[can.Message] = deque()
        self._own = receive_own_messages
        self._peers = self._channels.setdefault(self._channel_name, [])
        self._peers.append(self)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        for peer in self._peers:
            if peer is not self or self._own:
                peer._queue.append(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        queue = self._queue
        return (queue.popleft() if queue else None), False

    def shutdown(self) -> None:
        if self in self._peers:
            self._peers.remove(self)
        super().shutdown()


#: Bytes of socket receive buffer for udp_multicast: every frame is one datagram (about 1 KiB of kernel
#: memory each), so the default ~200 KiB holds only ~200 frames, a tenth of a second of a loaded bus; a
#: receiver that pauses longer (garbage collection, a busy core) would lose frames. The kernel caps the
#: request at net.core.rmem_max.
UDP_RECEIVE_BUFFER = 8 * 1024 * 1024


#: Linux's IP_MULTICAST_ALL (socket.IP_MULTICAST_ALL where Python defines it).
IP_MULTICAST_ALL = getattr(socket, "IP_MULTICAST_ALL", 49)


def _tune_udp_socket(bus: can.BusABC) -> None:
    """python-can's UdpMulticastBus has no options for these; set them on its socket (a private attribute,
    isolated here; without them the bus works, but worse):
    - SO_RCVBUF: see UDP_RECEIVE_BUFFER;
    - IP_MULTICAST_ALL = 0: the socket is bound to the wildcard address on python-can's fixed port, and
      Linux then delivers every group joined by any socket on the host to it; two benches on two groups
      would hear each other's frames."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None:
        return
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RECEIVE_BUFFER)
    if sock.family == socket.AF_INET and sys.platform.startswith("linux"):
        sock.setsockopt(socket.IPPROTO_IP, IP_MULTICAST_ALL, 0)


def is_virtual(interface: str) -> bool:
    return interface in (VIRTUAL, "bench_virtual")


def open_bus(interface: str, channel: str | None) -> can.BusABC:
    """Open a bus by python-can interface name; errors name the interface and channel."""
    if is_virtual(interface):
        return VirtualTimeBus(channel=channel or "bench")
    if interface not in can.interfaces.VALID_INTERFACES:
        raise ConfigError(f"unknown python-can interface {interface!r} "
                          f"(known: virtual, {', '.join(sorted(can.interfaces.VALID_INTERFACES))})")
    kwargs: dict[str, Any] = {}
    if interface == "udp_multicast":
        kwargs["hop_limit"] = UDP_MULTICAST_HOP_LIMIT
        channel = channel or UDP_MULTICAST_DEFAULT_GROUP
    if interface == "socketcan":
        kwargs["receive_own_messages"] = False
    if not channel:
        raise ConfigError(f"interface {interface!r} needs a channel (--channel)")
    try:
        bus = can.Bus(interface=interface, channel=channel, **kwargs)
        if interface == "udp_multicast":
            _tune_udp_socket(bus)
        return bus
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        raise ConfigError(f"cannot open interface {interface!r} channel {channel!r}: {exc}") from None
