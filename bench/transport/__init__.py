"""The transport: everything between a station and its bus.

- opening a bus by name, its settings and the checks of a name (bus.py, busopts.py);
- one `Transport` per station (base.py), chosen once by `transport_for`: the embedded bus (embedded.py, in
  process, virtual time), SocketCAN with its fast receiver and the kernel's broadcast manager (socketcan.py,
  socketcan_rx.py, periodic.py), udp_multicast with its socket tuning (udp.py), any other python-can bus (base.py);
- what a bus can do, asked of the bus, never of its class name (capabilities.py).
"""

from bench.transport.base import PythonCanTransport, ReceivedFrame, Transport
from bench.transport.bus import (
    EMBEDDED,
    PYTHON_CAN_VIRTUAL,
    check_channel,
    check_interface,
    in_process,
    is_embedded,
    open_bus,
    probe_bus,
    transport_for,
)
from bench.transport.busopts import BusOptions, contract_options, positive_int
from bench.transport.embedded import VirtualTimeBus
from bench.transport.udp import UDP_MULTICAST_DEFAULT_GROUP, UDP_MULTICAST_HOP_LIMIT

__all__ = ["EMBEDDED", "PYTHON_CAN_VIRTUAL", "UDP_MULTICAST_DEFAULT_GROUP", "UDP_MULTICAST_HOP_LIMIT", "BusOptions",
           "PythonCanTransport", "ReceivedFrame", "Transport", "VirtualTimeBus", "check_channel", "check_interface",
           "contract_options", "in_process", "is_embedded", "open_bus", "positive_int", "probe_bus", "transport_for"]
