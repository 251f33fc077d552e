"""The scenario protocol, plant side: one helper that every PLANT node uses (docs/architecture.md, "The scenario
protocol").

Why one helper: the bench starts a scenario by sending a new id in BENCH_Control.ScenarioId and waits for the
plant to echo it in PLANT_Status.ScenarioIdAck (bench.toml [scenario]); a plant node that detects the change
differently, or acknowledges before it has reset, would let a case start on the previous scenario's state.

The rule: whenever BENCH_Control.ScenarioId differs from the id last acknowledged (the first one seen
included; a missing or non-finite id is ignored), the node resets itself and every in-process node linked to
it, in that same tick, and from then on PLANT_Status carries ScenarioIdAck = that id, Vehicle = the vehicle's
code and PlantTime = the time since that tick's start (before any scenario: since the node's first tick).
"""

from __future__ import annotations

from collections.abc import Mapping

from bench.sim.node import NodeIO
from plant import signal_ranges as ranges

#: The bench.dbc names of the protocol (plant/ may know its vehicle's databases; the bench takes them from
#: bench.toml).
CONTROL = "BENCH_Control"
SCENARIO_ID = "ScenarioId"
STATUS = "PLANT_Status"
_PLANT_TIME = ranges.PLANT_TIME


class ScenarioTracker:
    """Detects a new scenario and acknowledges it, for one PLANT node of a vehicle with DBC code `vehicle_code`.

    Per tick the node calls `poll` first (True: reset now, with `control` as the scenario's settings), then
    `acknowledge` whenever it publishes PLANT_Status."""

    def __init__(self, vehicle_code: int) -> None:
        self.vehicle_code = vehicle_code
        self.reset()

    def reset(self) -> None:
        """No scenario seen yet (a node's own reset)."""
        self.scenario: int | None = None
        self.t0: float | None = None
        self.control: Mapping[str, float] | None = None   # BENCH_Control's latest values (None: never received)

    def poll(self, io: NodeIO, t: float, dt: float) -> bool:
        """Read BENCH_Control; True when its ScenarioId is new, i.e. the caller must reset now (itself and its
        linked nodes) from the settings in `self.control`."""
        control = io.latest(CONTROL)
        self.control = control
        started = False
        if control is not None:
            sid = control.get(SCENARIO_ID)
            if sid is not None and ranges.finite(sid) and sid != self.scenario:
                self.scenario = int(sid)
                self.t0 = t - dt
                started = True
        if self.t0 is None:
            self.t0 = t - dt
        return started

    def setting(self, name: str, default: float) -> float:
        """A finite BENCH_Control value of the current tick (e.g. "InitialSpeed"), else `default`."""
        value = default if self.control is None else self.control.get(name, default)
        return value if ranges.finite(value) else default

    def elapsed(self, t: float) -> float:
        """Time since the scenario started (or since the first tick), s."""
        return t - (self.t0 if self.t0 is not None else t)

    def acknowledge(self, io: NodeIO, t: float) -> None:
        """PLANT_Status: the acknowledged id (0 before any), the vehicle's code, the scenario's time."""
        t0 = self.t0
        elapsed = t - (t0 if t0 is not None else t)                     # self.elapsed(t), written out (every tick)
        lo, hi = _PLANT_TIME                                              # ranges.clamp, written out
        elapsed = 0.0 if elapsed != elapsed else lo if elapsed < lo else hi if elapsed > hi else elapsed
        io.send_values(STATUS, ScenarioIdAck=self.scenario or 0, Vehicle=self.vehicle_code, PlantTime=elapsed)
