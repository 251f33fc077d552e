"""The cuts for a User-mode Linux guest (docs/vcan-lane.md): no clock read per log record, and the garbage
collector's full scans moved to the gap between two test cases in real time."""

from __future__ import annotations

import gc
import math
import time
import weakref
from pathlib import Path

import pytest

from bench.log.logread import read_frames, summarise
from bench.log.recorder import Recorder
from bench.sim.clock import VirtualClock, WallClock


def test_a_recorder_without_interval_reads_no_clock_and_writes_chunks_only_when_flushed(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """flush_interval=math.inf (the log process): 300 records, no clock read, nothing in a chunk until flush()."""
    log = tmp_path / "run.mcap"
    recorder = Recorder(log, [], flush_interval=math.inf)
    head = log.stat().st_size

    def no_clock() -> float:
        raise AssertionError("a clock read per record")

    monkeypatch.setattr(time, "monotonic", no_clock)
    for i in range(300):
        recorder.frame(i * 0.001, 0x100, bytes([i % 256]), channel="can0", direction="rx")
    monkeypatch.undo()
    assert log.stat().st_size == head          # all in the open chunk
    recorder.flush()
    assert log.stat().st_size > head
    assert [f.data for f in read_frames(log)] == [bytes([i % 256]) for i in range(300)]
    recorder.close()
    assert summarise(log).frames == 300


def test_wall_clock_between_cases_freezes_what_the_case_left() -> None:
    """A survivor made during a case is out of the collector's view after between_cases (gc.freeze), and
    garbage cycles of the case are collected first, not frozen."""
    clock = WallClock()
    try:
        class Node:
            ref: object = None

        kept = [Node() for _ in range(100)]
        cycle = Node()
        cycle.ref = cycle
        probe = weakref.ref(cycle)
        del cycle
        before = gc.get_freeze_count()
        clock.between_cases()
        assert gc.get_freeze_count() >= before + len(kept)
        assert probe() is None                                      # the cycle was collected, not frozen
        assert not any(o is kept[0] for o in gc.get_objects())      # the survivor is frozen
    finally:
        gc.unfreeze()


def test_virtual_clock_between_cases_changes_nothing() -> None:
    gc.unfreeze()
    VirtualClock().between_cases()
    assert gc.get_freeze_count() == 0
