"""Opening buses by name: the embedded bus (in process, virtual time: the default) or any python-can interface.

Why here: `bench run`, `plant`, `monitor`, `replay` and the pytest plugin open buses alike; the names, the checks
of a name and a channel, and the settings no user chooses (udp_multicast's hop limit) are in one place.
"""

from __future__ import annotations

from typing import Any

import can

from bench.errors import ConfigError
from bench.transport.base import PythonCanTransport, Transport
from bench.transport.busopts import BusOptions
from bench.transport.capabilities import raw_can_socket, takes_hop_limit
from bench.transport.embedded import EmbeddedTransport, VirtualTimeBus
from bench.transport.socketcan import SocketcanTransport
from bench.transport.udp import (
    UDP_MULTICAST_DEFAULT_GROUP,
    UDP_MULTICAST_HOP_LIMIT,
    UdpMulticastTransport,
    multicast_socket,
    tune_udp_socket,
)

#: The embedded bus's one name (command line, pytest options, the report, python-can's entry point): not python-can's
#: `virtual`, which names python-can's own in-process bus (real time) and reaches it.
EMBEDDED = "embedded"
#: python-can's in-process bus: like the embedded bus it reaches only its own process.
PYTHON_CAN_VIRTUAL = "virtual"
#: Earlier names of the embedded bus, refused with one line naming the new one.
RENAMED = {"bench_virtual": EMBEDDED}


def is_embedded(interface: str) -> bool:
    """The embedded bus: in process, in virtual time (the only bus on which the bench's time is not the wall clock)."""
    return interface == EMBEDDED


def in_process(interface: str) -> bool:
    """A bus that only this process can reach (the embedded bus, python-can's virtual bus)."""
    return interface in (EMBEDDED, PYTHON_CAN_VIRTUAL)


def known_interfaces() -> list[str]:
    return sorted({EMBEDDED, *can.interfaces.VALID_INTERFACES})


def check_interface(interface: str, option: str = "--interface") -> None:
    """An interface name the bench can open: the embedded bus or a python-can interface; an old name of the
    embedded bus is one line naming the new one."""
    if interface in RENAMED:
        raise ConfigError(f"{option} {interface}: renamed to {RENAMED[interface]} (the bench's in-process "
                          "virtual-time bus)")
    if not is_embedded(interface) and interface not in can.interfaces.VALID_INTERFACES:
        raise ConfigError(f"{option}: unknown python-can interface {interface!r} "
                          f"(known: {', '.join(known_interfaces())})")


def open_bus(interface: str, channel: str | None, options: BusOptions | None = None) -> can.BusABC:
    """Open a bus by python-can interface name with `options` (bitrate, CAN FD, [bus] table); errors name the
    interface and channel. The embedded bus has no bit timing: it ignores `options`."""
    check_interface(interface)
    if is_embedded(interface):
        return VirtualTimeBus(channel=channel or "bench")
    kwargs: dict[str, Any] = options.kwargs() if options is not None else {}
    if takes_hop_limit(interface):   # an IP multicast bus (udp_multicast): asked of its class's parameters
        kwargs["hop_limit"] = UDP_MULTICAST_HOP_LIMIT   # never a user's choice: the frames stay on this host
        channel = channel or UDP_MULTICAST_DEFAULT_GROUP
    if interface == "socketcan":
        kwargs.setdefault("receive_own_messages", False)
    if not channel:
        raise ConfigError(f"interface {interface!r} needs a channel (--channel)")
    try:
        bus = can.Bus(interface=interface, channel=channel, **kwargs)
        try:
            tune_udp_socket(bus)   # a bus without python-can's multicast socket is left alone
        except BaseException:
            bus.shutdown()
            raise
        return bus
    except Exception as exc:   # drivers raise anything (vendor DLL errors, TypeError on a bad [bus] key)
        message = f"cannot open interface {interface!r} channel {channel!r}: {type(exc).__name__}: {exc}"
        _forget_half_open(exc)
        raise ConfigError(message.replace("\n", " ")) from None


def transport_for(bus: can.BusABC) -> Transport:
    """The station's adapter for `bus`, chosen once by what the bus is (its class for the bench's own bus, its socket
    for python-can's socketcan and udp_multicast): every other bus goes through python-can's recv and send."""
    if isinstance(bus, VirtualTimeBus):
        return EmbeddedTransport(bus)
    if raw_can_socket(bus) is not None:
        return SocketcanTransport(bus)
    if multicast_socket(bus) is not None:
        return UdpMulticastTransport(bus)
    return PythonCanTransport(bus)


def _forget_half_open(exc: BaseException) -> None:
    """A driver that fails inside its __init__ leaves a half-built bus whose finaliser later logs "was not
    properly shut down" under the one-line error; there is nothing to shut down, so mark it so (python-can's
    BusABC flag)."""
    tb = exc.__traceback__
    while tb is not None:
        candidate = tb.tb_frame.f_locals.get("self")
        if isinstance(candidate, can.BusABC):
            candidate._is_shutdown = True
        tb = tb.tb_next


def probe_bus(interface: str, channel: str | None, options: BusOptions | None = None) -> None:
    """Open the bus once and close it: a bus that cannot be opened stops a run before its first case (an
    in-process bus has nothing to probe: the run opens it on a channel of its own)."""
    if in_process(interface):
        check_interface(interface)
        return
    open_bus(interface, channel, options).shutdown()


def check_channel(interface: str, channel: str | None, option: str = "--channel") -> None:
    """`--channel` on the embedded bus is a mistake (the user meant another bus), not a no-op."""
    if is_embedded(interface) and channel:
        raise ConfigError(f"{option} {channel}: the embedded bus (in process, virtual time) has no channels; "
                          "name the interface too (e.g. --interface socketcan --channel vcan0)")
