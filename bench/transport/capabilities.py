"""What a bus can do, asked of the bus (its socket, its attributes, its interface's parameters), never of the
name of its class: a python-can interface the bench has not met, or a test's fake, is then judged by what it
does (docs/architecture.md "Adding a bus interface").

- `delivers_own_frames`: does the bus hand a sender's own frames back to it? (the station then drops them
  as echoes instead of monitoring them as another sender's);
- `raw_can_socket`: has the bus a raw SocketCAN socket the bench may read and filter in the kernel itself?
  (socketcan_rx.py, periodic.py);
- `takes_hop_limit`: is the interface an IP network bus whose frames could leave this host? (bus.py
  pins its hop limit to 0).
"""

from __future__ import annotations

import importlib
import inspect
import logging
import os
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import can

log = logging.getLogger(__name__)

_AF_CAN = getattr(socket, "AF_CAN", None)                    # absent off Linux: no bus has a raw CAN socket
_SOL_CAN_RAW = getattr(socket, "SOL_CAN_RAW", 101)          # linux/can/raw.h
_CAN_RAW_RECV_OWN_MSGS = getattr(socket, "CAN_RAW_RECV_OWN_MSGS", 4)
_MULTICAST_LOOP: dict[int, tuple[int, int]] = {socket.AF_INET: (socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP),
                   socket.AF_INET6: (socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_LOOP)}


def raw_can_socket(bus: can.BusABC) -> Any | None:
    """The bus's raw SocketCAN socket (`bus.socket`, address family AF_CAN, type SOCK_RAW), or None: a
    TCP socket (socketcand), a UDP one or none at all is not a socket the bench can read CAN frames from."""
    sock = getattr(bus, "socket", None)
    if sock is None or _AF_CAN is None:
        return None
    if getattr(sock, "family", None) == _AF_CAN and getattr(sock, "type", None) == socket.SOCK_RAW:
        return sock
    return None


def delivers_own_frames(bus: can.BusABC) -> bool:
    """Whether a frame this bus sends comes back to its own receive side. Asked of its socket where it has
    one (SocketCAN: CAN_RAW_RECV_OWN_MSGS; IP multicast: IP_MULTICAST_LOOP, which python-can's udp_multicast
    leaves on whatever `receive_own_messages` says), else of its `receive_own_messages` attribute (python-can's
    virtual bus, the bench's virtual-time bus, a test's fake); False when neither says."""
    with _socket_of(bus) as sock:
        if sock is not None:
            answer = _own_frames_option(sock)
            if answer is not None:
                return answer
    declared = getattr(bus, "receive_own_messages", None)
    return declared if isinstance(declared, bool) else False


def _own_frames_option(sock: Any) -> bool | None:
    family = getattr(sock, "family", None)
    if not isinstance(family, int):
        return None
    if _AF_CAN is not None and family == _AF_CAN:
        option: tuple[int, int] | None = (_SOL_CAN_RAW, _CAN_RAW_RECV_OWN_MSGS)
    else:
        option = _MULTICAST_LOOP.get(family) if getattr(sock, "type", None) == socket.SOCK_DGRAM else None
    if option is None:
        return None
    try:
        return bool(sock.getsockopt(*option))
    except OSError as exc:
        log.warning("cannot ask the bus's socket whether it loops its own frames back: %s", exc)
        return None


@contextmanager
def _socket_of(bus: can.BusABC) -> Iterator[Any | None]:
    """The bus's socket to ask options of: `bus.socket` where python-can exposes it, else a duplicate of the
    socket behind `bus.fileno()` (closed afterwards; the bus's own stays open), else None."""
    sock = getattr(bus, "socket", None)
    if sock is not None and hasattr(sock, "getsockopt"):
        yield sock
        return
    try:
        fd = bus.fileno()
    except (NotImplementedError, AttributeError, OSError, ValueError):
        fd = -1
    if not isinstance(fd, int) or fd < 0:
        yield None
        return
    duplicate = os.dup(fd)
    try:
        sock = socket.socket(fileno=duplicate)      # the kernel says its family and type
    except OSError:                                 # not a socket (a driver's event handle)
        os.close(duplicate)
        yield None
        return
    with sock:
        yield sock


def takes_hop_limit(interface: str) -> bool:
    """Whether the python-can interface's bus takes a `hop_limit` (its frames travel over IP and could leave
    the host), found from the signature of the interface's bus class."""
    backend = can.interfaces.BACKENDS.get(interface)
    if backend is None:
        return False
    module, class_name = backend
    try:
        cls = getattr(importlib.import_module(module), class_name)
        return "hop_limit" in inspect.signature(cls).parameters
    except (ImportError, AttributeError, TypeError, ValueError):   # a driver that cannot load says nothing here
        return False
