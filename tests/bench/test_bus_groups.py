"""bench/bus.py: a udp_multicast bus hears its own group only, from its first read on, while another bench
sends on another group of this host (python-can binds every such socket to one port on the wildcard address).

Found by tests/bench/test_replay.py failing under load beside other benches: the receiver's first frames were
another group's (0x121, 0x122 ... of a running `bench plant`), queued between the socket's bind and
IP_MULTICAST_ALL = 0 (48 of 200 fresh buses before the fix)."""

from __future__ import annotations

import subprocess
import sys
import uuid

import can

from bench.bus import open_bus
from tests.repo import ROOT

OPENS = 100

# Another bench on this host: a frame on its group every 0.1 ms for at most 60 s (the test stops it sooner).
SENDER = """
import sys, time
import can
from bench.bus import open_bus
bus = open_bus("udp_multicast", sys.argv[1])
end = time.monotonic() + 60.0
while time.monotonic() < end:
    bus.send(can.Message(arbitration_id=0x121, data=bytes(8), is_extended_id=False))
    time.sleep(0.0001)
"""


def _group() -> str:
    return f"239.255.{uuid.uuid4().int % 250 + 1}.{uuid.uuid4().int % 250 + 1}"


def test_a_fresh_bus_reads_no_frame_of_another_group() -> None:
    theirs, ours = _group(), _group()
    while ours == theirs:
        ours = _group()
    sender = subprocess.Popen([sys.executable, "-c", SENDER, theirs], cwd=ROOT)
    try:
        with open_bus("udp_multicast", theirs) as watch:      # the other bench is sending: no guessed sleep
            assert watch.recv(30.0) is not None, "the other bench sent nothing within 30 s"
        foreign = []
        for _ in range(OPENS):
            bus = open_bus("udp_multicast", ours)
            try:
                while (msg := bus.recv(0.0)) is not None:
                    foreign.append(msg)
            finally:
                bus.shutdown()
    finally:
        sender.kill()
        sender.wait()
    assert foreign == [], f"{len(foreign)} frames of group {theirs} read on {ours}: {foreign[:3]}"


def test_a_fresh_bus_still_reads_its_own_group() -> None:
    """Dropping what came before the bus was limited to its group loses nothing sent after it was opened."""
    group = _group()
    with open_bus("udp_multicast", group) as receiver, open_bus("udp_multicast", group) as sender:
        sender.send(can.Message(arbitration_id=0x321, data=b"\x05", is_extended_id=False))
        msg = receiver.recv(5.0)
    assert msg is not None and (msg.arbitration_id, bytes(msg.data)) == (0x321, b"\x05")
