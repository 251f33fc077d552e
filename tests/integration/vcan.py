"""Whether this kernel can reach a SocketCAN vcan interface, for the tests that need the real one.

The vcan lane (scripts/vcan-lane) sets VCAN_CHANNEL; inside it those tests must fail, not skip, when the
interface is missing, so that the lane never passes empty.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import socket
import sys
from types import ModuleType

from tests import repo

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


def load_lane_script() -> ModuleType:
    """scripts/vcan-lane as a module (its file name has no .py), for the tests of its host-side logic."""
    name = "vcan_lane"
    if name in sys.modules:
        return sys.modules[name]
    path = repo.ROOT / "scripts" / "vcan-lane"
    loader = importlib.machinery.SourceFileLoader(name, str(path))
    spec = importlib.util.spec_from_loader(name, loader)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module       # dataclasses look their module up while the file executes
    loader.exec_module(module)
    return module
