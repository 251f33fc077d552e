"""A bench session end to end on the virtual-time bus, with a minimal echo plant."""

from __future__ import annotations

from dataclasses import replace

import pytest

from bench.config import RunSettings, load_config
from bench.session import BenchSession, simulated_nodes


@pytest.fixture
def project():
    return replace(load_config(), plant="tests.fixtures.echo_plant:build")


def _frames_of(session: BenchSession) -> list[tuple[float, int, bytes]]:
    frames: list[tuple[float, int, bytes]] = []
    session.runner.monitor.sink = lambda f: frames.append((round(f.t, 9), f.frame_id, f.data))
    return frames


def test_stimulus_reaches_plant_and_back(project) -> None:
    session = BenchSession(project, RunSettings())
    session.start()
    session.runner.restbus.set("DRV_Steering", HandWheelAngle=123.0)
    session.run_until(0.1)
    assert session.runner.monitor.latest("VCU_WheelCmd_FL", session.now())["SteerAngleCmd"] == pytest.approx(12.3)
    # nothing rejected (each message's first frame is valid, only not applied: NODATA -> INIT, docs/spec/e2e.md)
    assert session.runner.monitor.invalid_frames == 0, session.runner.monitor.invalid_log[:3]
    session.close()


def test_two_runs_give_identical_frame_sequences(project) -> None:
    sequences = []
    for _ in range(2):
        session = BenchSession(project, RunSettings())
        frames = _frames_of(session)
        session.start()
        session.runner.restbus.set("DRV_Steering", HandWheelAngle=50.0)
        session.run_until(0.5)
        session.runner.restbus.set("DRV_Steering", HandWheelAngle=-70.0)
        session.run_until(1.0)
        session.close()
        sequences.append(frames)
    assert len(sequences[0]) > 500
    assert sequences[0] == sequences[1]


def test_cycle_times_are_exact_in_virtual_time(project) -> None:
    session = BenchSession(project, RunSettings())
    session.start()
    session.run_until(1.0)
    state = session.runner.monitor.state("VCU_WheelCmd_FL")
    assert state.intervals and all(abs(i - 0.010) < 1e-9 for i in state.intervals)
    state = session.runner.monitor.state("BENCH_Control")
    assert all(abs(i - 0.020) < 1e-9 for i in state.intervals)
    session.close()


def test_unknown_external_node_is_a_clear_error(project) -> None:
    from bench.errors import ConfigError
    with pytest.raises(ConfigError, match="unknown node.*NOPE"):
        BenchSession(project, RunSettings(external=["NOPE"]))


def test_the_nodes_a_process_simulates_are_its_stations_nodes() -> None:
    """One rule for the fault plan of a session and `bench run`'s check before the first case: the runner's
    process sends the stimulus nodes even when they are named external, the plant's process never does."""
    project = load_config()
    session = BenchSession(project, RunSettings(external=["DRIVER", "VCU"]))
    try:
        stations = frozenset().union(*(s.restbus.nodes for s in session.stations))
        simulated = simulated_nodes(session.codebook, project.stimulus, session.external, "runner")
        assert simulated == stations and session.faults.simulated == stations
        assert "DRIVER" in simulated and "VCU" not in simulated
    finally:
        session.close()
    plant = simulated_nodes(session.codebook, project.stimulus, {"VCU"}, "plant")
    assert not plant & set(project.stimulus) and "VCU" not in plant and "WHL_FL" in plant
