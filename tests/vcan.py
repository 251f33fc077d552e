"""Whether this kernel can reach a SocketCAN vcan interface, for the tests that need the real one.

The vcan lane (scripts/vcan-lane) sets VCAN_CHANNEL; inside it those tests must fail, not skip, when the
interface is missing, so that the lane never passes empty.
"""

from __future__ import annotations

import os
import socket

CHANNEL = os.environ.get("VCAN_CHANNEL", "vcan0")
IN_LANE = "VCAN_CHANNEL" in os.environ


def has_vcan(channel: str = CHANNEL) -> bool:
    """True when a raw CAN socket opens (CONFIG_CAN, can-raw) and `channel` exists."""
    try:
        sock = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except (OSError, AttributeError):
        return False
    sock.close()
    return os.path.exists(f"/sys/class/net/{channel}")
