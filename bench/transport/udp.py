"""udp_multicast: python-can's UdpMulticastBus kept on this host and on its own group (socket tuning).

The bench opens it with hop limit 0 (bench.transport.bus) and, once open, tunes its socket here: a larger receive
buffer, only its own group's datagrams, nothing that came before.
"""

from __future__ import annotations

import ctypes
import logging
import socket
import struct
import sys
import time

import can

from bench.transport.base import PythonCanTransport

log = logging.getLogger(__name__)

#: udp_multicast must never leave this host (Developers' guide: hop limit 0).
UDP_MULTICAST_HOP_LIMIT = 0
#: python-can's default IPv4 group for udp_multicast (an administratively scoped address).
UDP_MULTICAST_DEFAULT_GROUP = "239.74.163.2"


#: Bytes of socket receive buffer for udp_multicast: every frame is one datagram (about 1 KiB of kernel
#: memory each), so the default ~200 KiB holds only ~200 frames, a tenth of a second of a loaded bus; a
#: receiver that pauses longer (garbage collection, a busy core) would lose frames. The kernel caps the
#: request at net.core.rmem_max.
UDP_RECEIVE_BUFFER = 8 * 1024 * 1024


#: s between the two passes that empty a new udp_multicast socket of other groups' datagrams (_drop_queued)
DROP_SETTLE_S = 0.002
#: Linux's IP_MULTICAST_ALL (linux/in.h; socket.IP_MULTICAST_ALL where Python defines it).
IP_MULTICAST_ALL = getattr(socket, "IP_MULTICAST_ALL", 49)
#: Linux's IPV6_MULTICAST_ALL (linux/in6.h, since Linux 4.20; Python defines no name for it).
IPV6_MULTICAST_ALL = getattr(socket, "IPV6_MULTICAST_ALL", 29)


def multicast_socket(bus: can.BusABC) -> socket.socket | None:
    """The socket of python-can's UdpMulticastBus (a private attribute, isolated here), or None for another bus."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    return sock if isinstance(sock, socket.socket) else None


class UdpMulticastTransport(PythonCanTransport):
    """python-can's udp_multicast for a station: python-can's recv and send on the socket tuned when it was opened
    (tune_udp_socket); it loops a sender's own frames back (IP_MULTICAST_LOOP), which the station drops as echoes,
    and every frame carries the socket's receive time."""


def tune_udp_socket(bus: can.BusABC) -> None:
    """python-can's UdpMulticastBus has no options for these; set them on its socket (a private attribute,
    isolated here; without them the bus works, but worse):
    - SO_RCVBUF: see UDP_RECEIVE_BUFFER;
    - only its own group: python-can binds the socket to the wildcard address on its fixed port (43113), and
      Linux then delivers to it every group joined on that port by any socket of the host, so two benches on
      two groups would hear each other's frames. Off for both families: IP_MULTICAST_ALL = 0 on an IPv4
      socket; on an IPv6 socket IPV6_MULTICAST_ALL = 0 (the IPv6 groups) and IP_MULTICAST_ALL = 0 too,
      because python-can's IPv6 socket is dual-stack ([::], IPV6_V6ONLY off) and also receives the IPv4
      groups of its port while that option is on. Then the kernel delivers only the group the socket joined;
    - a socket filter that keeps only datagrams addressed to that group (_only_to_group): a datagram sent to
      the port itself (unicast, broadcast: any process or host may send one) reaches a socket bound so too, and
      python-can would decode it as a frame of this bus;
    what came before is dropped (_drop_queued)."""
    multicast = getattr(bus, "_multicast", None)
    sock = multicast_socket(bus)
    if sock is None:
        return
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RECEIVE_BUFFER)
    if not sys.platform.startswith("linux"):
        return
    group = getattr(multicast, "group", None)
    if isinstance(group, str):
        _only_to_group(sock, group)
    if sock.family == socket.AF_INET6:
        try:
            sock.setsockopt(socket.IPPROTO_IPV6, IPV6_MULTICAST_ALL, 0)
        except OSError as exc:   # a kernel before 4.20: the socket would hear every IPv6 group of the host
            raise can.CanInitializationError(
                f"cannot limit the socket to its own IPv6 group (IPV6_MULTICAST_ALL, Linux 4.20 or later: "
                f"{exc.strerror}); use an IPv4 group") from None
    sock.setsockopt(socket.IPPROTO_IP, IP_MULTICAST_ALL, 0)
    _drop_queued(sock)


#: Linux's SO_ATTACH_FILTER (asm-generic/socket.h) and classic BPF (linux/filter.h): load a 32-bit word at an
#: offset from the network header, jump if equal, return (0 drops the datagram, 0xFFFFFFFF keeps all of it).
SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
_SKF_NET_OFF = -0x100000
_BPF_LD_W_ABS, _BPF_JEQ_K, _BPF_RET_K = 0x20, 0x15, 0x06
_DESTINATION_OFFSET = {socket.AF_INET: 16, socket.AF_INET6: 24}   # in the IPv4 and the IPv6 header


def _only_to_group(sock: socket.socket, group: str) -> None:
    """Attach a classic BPF filter that drops every datagram whose destination address is not `group`: the
    kernel then queues nothing else (an IPv4 datagram on python-can's dual-stack IPv6 socket has no such
    address where the filter looks, and is dropped too). A filter the kernel refuses is logged, not fatal: the
    multicast options above keep other groups out already."""
    family = sock.family
    address = str(socket.getaddrinfo(group, None, family, socket.SOCK_DGRAM)[0][4][0])   # the group, as python-can
    words = struct.unpack(f"!{4 if family == socket.AF_INET6 else 1}I", socket.inet_pton(family, address))
    code = []
    for i, word in enumerate(words):
        code.append((_BPF_LD_W_ABS, 0, 0, (_SKF_NET_OFF + _DESTINATION_OFFSET[family] + 4 * i) & 0xFFFFFFFF))
        code.append((_BPF_JEQ_K, 0, 2 * (len(words) - i - 1) + 1, word))   # not equal: on to the drop
    code += [(_BPF_RET_K, 0, 0, 0xFFFFFFFF), (_BPF_RET_K, 0, 0, 0)]
    program = ctypes.create_string_buffer(b"".join(struct.pack("@HBBI", *op) for op in code))
    try:   # struct sock_fprog {unsigned short len; struct sock_filter *filter;}; the kernel copies the program
        sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER,
                        struct.pack("@HP", len(code), ctypes.addressof(program)))
    except OSError as exc:
        log.warning("udp_multicast %s: no socket filter (%s); datagrams sent to the port itself are read too",
                    group, exc)


def _drop_queued(sock: socket.socket) -> None:
    """Discard what the socket received between its bind and the settings that limit it to its group: other
    groups' frames (with another bench on this host, 48 of 200 fresh buses read a foreign frame first); this
    bus is not in use yet.
    Twice, DROP_SETTLE_S apart: a datagram the kernel had already matched to this socket before the setting may
    still be on its way into the queue while the first pass empties it (1 of 100 fresh buses read one in a CI run)."""
    dropped = 0
    for settle in (DROP_SETTLE_S, 0.0):
        while True:
            try:
                sock.recv(65535, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                break
            dropped += 1
        time.sleep(settle)
    if dropped:
        log.debug("udp_multicast: %d datagram(s) received before the socket was limited to its group, dropped",
                  dropped)
