"""Each vehicle's bus carries its own ECUs' messages only (plant/factory.py, the declarations' messages), and its
behaviours read of the stimulus exactly what the declaration says a scenario of it sends.

Checked on the virtual bus against what the plant's behaviours really do, not against the declarations
alone: every message a vehicle's behaviours set must be on the bus, and nothing of another vehicle may be.
"""

from __future__ import annotations

import pytest

from bench.config import RunSettings, load_config
from bench.session import BenchSession
from plant.factory import messages_of, vehicles
from plant.registry import vehicle as declared

VEHICLE_CODES = {name: declared(name).code for name in vehicles()}
CLAIMED = frozenset().union(*(messages_of(v) for v in vehicles()))


class _RecordingIO:
    """A behaviour's NodeIO, noting every message it sets (send_values) and asks for (latest)."""

    def __init__(self, io: object, sets: set[str], reads: set[str]) -> None:
        self._io, self._sets, self._reads = io, sets, reads

    def __getattr__(self, name: str) -> object:
        return getattr(self._io, name)

    def send_values(self, message: str, **signals: float) -> None:
        self._sets.add(message)
        self._io.send_values(message, **signals)

    def latest(self, message: str) -> object:
        self._reads.add(message)
        return self._io.latest(message)


class _Recorded:
    """One of the plant's behaviours, stepped on a _RecordingIO (the station's own attributes stay untouched: a
    compiled station takes no other object in their place)."""

    def __init__(self, behaviour: object, sets: set[str], reads: set[str]) -> None:
        self._behaviour, self._sets, self._reads = behaviour, sets, reads

    def __getattr__(self, name: str) -> object:
        return getattr(self._behaviour, name)

    def step(self, io: object, t: float, dt: float) -> None:
        self._behaviour.step(_RecordingIO(io, self._sets, self._reads), t, dt)


def _session(vehicle: str) -> tuple[BenchSession, set[str], set[str]]:
    """A session whose plant starts as `vehicle`, the set of messages its behaviours set and the set they read."""
    session = BenchSession(load_config(), RunSettings(vehicle=vehicle))
    sets: set[str] = set()
    reads: set[str] = set()
    session.plant.behaviours[:] = [_Recorded(b, sets, reads) for b in session.plant.behaviours]
    return session, sets, reads


def _seen_since(session: BenchSession, since: float) -> set[str]:
    return {name for name, state in session.runner.monitor.by_name.items()
            if state.last_seen is not None and state.last_seen >= since}


@pytest.mark.parametrize("vehicle", sorted(vehicles()))
def test_a_vehicle_sends_what_its_ecus_set_and_nothing_of_the_others(vehicle: str) -> None:
    session, set_by_behaviours, _ = _session(vehicle)
    session.start()
    session.runner.restbus.set("BENCH_Control", Vehicle=VEHICLE_CODES[vehicle], ScenarioId=1)
    session.run_until(1.0)
    seen = _seen_since(session, 0.5)
    plant_sent = {c.name for c in session.codebook.sent_by(session.plant.restbus.nodes)}
    session.close()
    assert set_by_behaviours, "the behaviours set nothing at all: the recording is broken"
    assert set_by_behaviours <= messages_of(vehicle), "set by the behaviours but not declared"
    assert set_by_behaviours <= seen, "set by the behaviours but not on the bus"
    others = CLAIMED - messages_of(vehicle)
    assert not (seen & others), f"{vehicle} sends messages of other vehicles: {sorted(seen & others)}"
    assert (plant_sent & messages_of(vehicle)) <= seen
    io = frozenset().union(*declared(vehicle).io.values())
    assert not (seen & io), f"bench I/O on the bus while its node is simulated: {sorted(seen & io)}"


@pytest.mark.parametrize("vehicle", sorted(vehicles()))
def test_a_vehicle_reads_the_stimulus_its_declaration_names(vehicle: str) -> None:
    """Every stimulus message the behaviours ask for (io.latest), besides BENCH_Control, is declared: a scenario
    that sends only the declared messages leaves none of their inputs silent. (Some declared ones are read only in
    some states, e.g. DRV_Steering, which the VCU reads in NORMAL and ADAPTIVE only, so the converse is not asked
    of a 0.5 s run.)"""
    session, _, read = _session(vehicle)
    stimulus_messages = {c.name for c in session.codebook.sent_by(session.project.stimulus)}
    session.start()
    session.runner.restbus.set("BENCH_Control", Vehicle=VEHICLE_CODES[vehicle], ScenarioId=1)
    session.run_until(0.5)
    session.close()
    assert read & stimulus_messages, "the behaviours read no stimulus at all: the recording is broken"
    assert (read & stimulus_messages) - {"BENCH_Control"} <= set(declared(vehicle).stimulus)


def test_switching_vehicle_switches_the_network() -> None:
    session, _, _ = _session("EV4WIS")
    session.start()
    session.runner.restbus.set("BENCH_Control", Vehicle=VEHICLE_CODES["EV4WIS"], ScenarioId=1)
    session.run_until(0.5)
    assert "VCU_WheelCmd_FL" in _seen_since(session, 0.3)
    session.runner.restbus.set("BENCH_Control", Vehicle=VEHICLE_CODES["ACLASS"], ScenarioId=2)
    session.run_until(1.0)
    seen = _seen_since(session, 0.8)
    session.close()
    assert "SBW_Pinion" in seen and "PLANT_SbwAngles" in seen
    assert not seen & (messages_of("EV4WIS") - messages_of("ACLASS"))


def _case(session: BenchSession):
    from bench.case import Case
    from bench.checks.steps import StepLog
    from bench.results.model import CaseResult

    return Case(session, CaseResult(nodeid="t", name="t", outcome="passed"), StepLog(session.now))


def test_a_scenario_sends_only_the_stimulus_it_names() -> None:
    session = BenchSession(load_config(), RunSettings())
    session.start()
    case = _case(session)
    case.start_scenario(Vehicle="EV4WIS", stimulus=["DRV_MotionRequest"])
    t0 = session.now()
    case.run(0.5)
    seen = _seen_since(session, t0 + 0.1)
    assert {"BENCH_Control", "DRV_MotionRequest"} <= seen
    assert not seen & {"DRV_Steering", "DRV_Pedals", "BENCH_SteeringRobot", "BENCH_AbsStimulus"}
    case.start_scenario(Vehicle="EV4WIS")          # the next scenario without a list: every stimulus again
    t1 = session.now()
    case.run(0.5)
    assert {"DRV_Steering", "DRV_Pedals", "BENCH_AbsStimulus"} <= _seen_since(session, t1 + 0.1)
    session.close()


def test_an_unknown_stimulus_message_is_a_clear_error() -> None:
    from bench.errors import BenchError

    session = BenchSession(load_config(), RunSettings())
    session.start()
    with pytest.raises(BenchError, match="VCU_WheelCmd_FL is no periodic stimulus message"):
        _case(session).start_scenario(Vehicle="EV4WIS", stimulus=["VCU_WheelCmd_FL"])
    session.close()


def test_an_unknown_vehicle_names_the_one_meant() -> None:
    with pytest.raises(ValueError, match=r"no plant for vehicle 'EV4WI' \(did you mean EV4WIS\?\)"):
        declared("EV4WI")
