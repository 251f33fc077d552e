"""The shared fakes of the bench's own tests: one python-can bus without a wire, and the throwaway addresses of
real test buses.

Why one module: four test modules each wrote their own `can.BusABC` (a loopback like udp_multicast's, a flood
that never goes quiet, a bus with only attributes, a SocketCAN bus on a fake kernel), and each copy had to learn
python-can's abstract methods anew. What they share is here; what only one test needs (the fake kernel behind
SocketCAN in test_periodic) stays with that test and builds on `FakeBus`.
"""

from __future__ import annotations

import itertools
import uuid
from collections import deque
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import can
import pytest

from bench.errors import ConfigError
from bench.log.recorder import Recorder
from bench.transport import open_bus


class FakeBus(can.BusABC):
    """A python-can bus as far as the bench asks: what is sent goes to `sent` (and back into `inbox` when the bus
    loops a sender's frames back, `receive_own_messages=True`, as udp_multicast does); `recv` reads `inbox` first,
    then `incoming` (any iterable, e.g. `flood(frame)`), and counts its calls in `reads` (each a look at the socket,
found empty or not). Every keyword in `attributes` becomes an attribute: the
    bench asks a bus what it has (bench.transport.capabilities), never its class name. `socket`, when given, is the
    bus's socket (a raw SocketCAN socket is how the bench recognises SocketCAN)."""

    def __init__(self, channel: str = "fake", *, incoming: Iterable[can.Message] = (), socket: Any = None,
                 **attributes: Any) -> None:
        self.sent: list[can.Message] = []
        self.inbox: deque[can.Message] = deque()
        self.incoming: Iterator[can.Message] = iter(incoming)
        self.reads = 0
        super().__init__(channel=channel)
        if socket is not None:
            self.socket = socket
        for name, value in attributes.items():
            setattr(self, name, value)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(msg)
        if getattr(self, "receive_own_messages", False):
            self.inbox.append(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        self.reads += 1
        return (self.inbox.popleft() if self.inbox else next(self.incoming, None)), False


def flood(frame: can.Message, budget: int | None = None) -> Iterator[can.Message]:
    """`frame` again and again: `budget` times, or without end when budget is None (a bus that never goes quiet)."""
    return itertools.repeat(frame) if budget is None else itertools.repeat(frame, budget)


# -- throwaway addresses of real test buses -------------------------------------------------------------------
def ipv4_group() -> str:
    """A fresh IPv4 multicast group of the organisation-local scope 239.255/16: tests on one host never share one."""
    return f"239.255.{uuid.uuid4().int % 250 + 1}.{uuid.uuid4().int % 250 + 1}"


def ipv6_group() -> str:
    """A link-local (scope 2), transient IPv6 group."""
    return f"ff12::b3c:{uuid.uuid4().int % 0xFFFF:x}:{uuid.uuid4().int % 0xFFFF:x}"


def ipv6_available() -> None:
    """Skip, with the error, only where this host has no IPv6 multicast at all (no IPv6, no route for ff00::/8)."""
    try:
        with open_bus("udp_multicast", ipv6_group()) as bus:
            bus.send(can.Message(arbitration_id=0x001, data=b"", is_extended_id=False))
    except (ConfigError, can.CanError) as exc:
        pytest.skip(f"IPv6 multicast is not available on this host: {exc}")



# -- a run log ---------------------------------------------------------------------------------------------------
SPACING = 0.010   # s between the logged tx frames of `make_log`


def make_log(path: Path) -> list[tuple[int, bytes]]:
    """40 tx frames 10 ms apart, rx frames in between and one error frame; returns the tx (id, data)."""
    sent = []
    with Recorder(path, []) as recorder:
        for i in range(40):
            t = 5.0 + i * SPACING
            data = bytes([i, 0xA5, i ^ 0xFF])
            recorder.frame(t, 0x300 + i % 2, data, channel="can0", direction="tx", valid=i != 7,
                           error="checksum" if i == 7 else "")
            sent.append((0x300 + i % 2, data))
            recorder.frame(t + 0.004, 0x400, bytes([i]), channel="can0", direction="rx")
            if i == 20:
                recorder.frame(t + 0.005, 0, bytes(8), channel="can0", direction="tx", is_error=True, valid=False,
                               error="error frame")
    return sent
