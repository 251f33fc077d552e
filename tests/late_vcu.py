"""A pytest plugin for tests/integration/test_late_vcu.py: the reference VCU made deliberately late.

Loaded with `-p tests.late_vcu` into a run of test cases in virtual time, it replaces the EV's simulated VCU by
one that sees the driver's request LATE_VCU_S seconds (environment variable) after it was received: every
read of DRV_MotionRequest and DRV_Steering (values, invalid, timed out) returns what the reference VCU would have
read that long before. Everything else (its task, the wheels, the plant) is unchanged, so the VCU's reaction to
a request is exactly that much later than the reference VCU's (5 ms task, docs/contract/vcu.md VCU-GEN-02).
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Mapping

import pytest

import plant.assemblies.ev4wis as ev4wis
from bench.sim.node import NodeIO
from plant.ecus.vcu import Vcu

DELAYED = ("DRV_MotionRequest", "DRV_Steering")


class _Seen:
    """What a message read as at one instant."""

    __slots__ = ("t", "latest", "invalid", "timed_out")

    def __init__(self, io: NodeIO, message: str, t: float) -> None:
        latest = io.latest(message)
        self.t = t
        self.latest = None if latest is None else dict(latest)
        self.invalid = io.invalid(message)
        self.timed_out = io.timed_out(message)


class _LateIO:
    """The VCU's NodeIO with DELAYED messages read as they were `delay` seconds ago."""

    def __init__(self, io: NodeIO, past: Mapping[str, _Seen | None]) -> None:
        self._io, self._past = io, past

    def __getattr__(self, name: str):
        return getattr(self._io, name)

    def latest(self, message: str):
        if message not in self._past:
            return self._io.latest(message)
        seen = self._past[message]
        return None if seen is None else seen.latest

    def invalid(self, message: str) -> bool:
        if message not in self._past:
            return self._io.invalid(message)
        seen = self._past[message]
        return False if seen is None else seen.invalid

    def timed_out(self, message: str) -> bool:
        if message not in self._past:
            return self._io.timed_out(message)
        seen = self._past[message]
        return True if seen is None else seen.timed_out


class LateVcu(Vcu):
    """The reference VCU, reacting `delay` seconds late to the driver's request."""

    delay = float(os.environ.get("LATE_VCU_S", "0"))

    def reset(self) -> None:
        super().reset()
        self._history: dict[str, deque[_Seen]] = {m: deque() for m in DELAYED}

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        past: dict[str, _Seen | None] = {}
        for message, history in self._history.items():
            history.append(_Seen(io, message, t))
            while len(history) > 1 and history[1].t <= t - self.delay:
                history.popleft()
            past[message] = history[0] if history[0].t <= t - self.delay else None
        super().step(_LateIO(io, past), t, dt)   # type: ignore[arg-type]


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    ev4wis.Vcu = LateVcu   # type: ignore[misc]   # plant/assemblies/ev4wis.py builds the VCU by this name
