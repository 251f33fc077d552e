"""Crash safety: a bench run killed with SIGKILL keeps at least 95 % of the frames it put on the bus
before the kill in its MCAP log. The log is written by a child process (bench/log/logproc.py) that gets the
frames every 0.2 s and finishes the file when the run dies; if it dies too, the file still reads back
up to its last chunk (flushed every 0.5 s: tests/bench/log/test_recorder.py kills a recorder itself)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from bench.log.logread import read_frames, summarise
from bench.transport import open_bus
from tests.fakes import ipv4_group
from tests.repo import ROOT

RUN_SECONDS = 8.0


@pytest.mark.realtime
def test_sigkill_keeps_95_percent_of_the_frames_sent(tmp_path: Path) -> None:
    group = ipv4_group()
    listener = open_bus("udp_multicast", group)   # hop limit 0, and only this group's frames
    try:
        run = subprocess.Popen([sys.executable, "-m", "bench", "run", str(ROOT / "tests/fixtures/cases/test_long.py"),
                                "--interface", "udp_multicast", "--channel", group, "--out", str(tmp_path)],
                               cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        on_bus = 0
        deadline = time.monotonic() + RUN_SECONDS + 15.0
        started = None
        while time.monotonic() < deadline:
            msg = listener.recv(0.05)
            if msg is not None:
                on_bus += 1
                started = started or time.monotonic()
            if started and time.monotonic() - started >= RUN_SECONDS:
                break
        run.kill()
        run.wait(timeout=30)
        while (msg := listener.recv(0.2)) is not None:   # frames already on the bus before the kill
            on_bus += 1
    finally:
        listener.shutdown()
    assert on_bus > 1000, "the run put too few frames on the bus to judge"
    logged = sum(1 for _ in read_frames(tmp_path / "run.mcap"))
    assert summarise(tmp_path / "run.mcap").frames == logged
    assert logged >= 0.95 * on_bus, f"{logged} frames logged of {on_bus} on the bus"
