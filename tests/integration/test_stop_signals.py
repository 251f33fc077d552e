"""A `bench run` stops within a second of SIGINT or SIGTERM, whatever it is doing, with a report marked ABORTED
and a complete MCAP log (issue 27, finding 1 and acceptance 1; bench/stop.py).

Each test starts `python -m bench run` as a user would, waits for a point of the run (frames of a flood at the
bus's limit in the log, the last case's progress line, the collection's count) and sends the signal; the time from
the signal to the process's exit must be at most a second. Real-time tests (`-m realtime`): the second is wall
time, measured on the host as it is.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from tests.repo import ROOT

pytestmark = pytest.mark.realtime

CASES = ROOT / "tests" / "fixtures" / "cases"
LIMIT = 1.0          # s from the signal to the process's end
FLOOD = "flood:0x000:8@3-1e9"   # at the bus's limit (bench.faults.kinds.FLOOD_MAX_RATE), from bench time 3 s on


class Run:
    """`python -m bench run ...` with its output in a file (read while it runs)."""

    def __init__(self, out: Path, *argv: str) -> None:
        self.out = out
        self.output = out.parent / f"{out.name}.txt"
        with self.output.open("w") as sink:
            self.process = subprocess.Popen([sys.executable, "-m", "bench", "run", *argv, "--out", str(out)],
                                            cwd=ROOT, stdout=sink, stderr=subprocess.STDOUT,
                                            env={**os.environ, "PYTHONUNBUFFERED": "1"})

    def wait_for(self, done: object, seconds: float = 120.0) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            assert self.process.poll() is None, f"the run ended before it was stopped:\n{self.text()}"
            if done(self) if callable(done) else str(done) in self.text():
                return
            time.sleep(0.01)
        self.process.kill()
        raise AssertionError(f"no {done!r} within {seconds:g} s:\n{self.text()}")

    def stop(self, signum: int) -> float:
        """Send the signal; the seconds until the process ended (it is killed after 30 s)."""
        sent, self.sent_at = time.monotonic(), time.time()
        self.process.send_signal(signum)
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        return time.monotonic() - sent

    def text(self) -> str:
        return self.output.read_text(errors="replace")

    def timeline(self) -> str:
        """When each output file was last written, s after the signal: where a slow stop spent its time (the logs'
        close, the report, the interpreter's exit after the last of them)."""
        files = sorted(self.out.iterdir(), key=lambda f: f.stat().st_mtime) if self.out.is_dir() else []
        return ", ".join(f"{f.name} {f.stat().st_mtime - self.sent_at:+.3f} s" for f in files) or "no output"


def _log_grew(run: Run) -> bool:
    log = run.out / "run.mcap"
    return log.exists() and log.stat().st_size > 500_000


def _aborted_report(out: Path) -> str:
    html = (out / "report.html").read_text(encoding="utf-8")
    assert '<span class="verdict ABORTED">ABORTED</span>' in html and "Run aborted" in html
    assert 'name="aborted"' in (out / "junit.xml").read_text(encoding="utf-8")
    return html


def _frames_in_log(path: Path, frame_id: int | None = None) -> int:
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None, f"{path}: no summary (not closed)"
    if frame_id is None:
        return int(summary.statistics.message_count)
    with open(path, "rb") as f:
        return sum(b'"id":%d,' % frame_id in m.data for _, _, m in make_reader(f).iter_messages(topics=["/can/frames"]))


def test_sigterm_during_a_flood_at_the_bus_limit(tmp_path: Path) -> None:
    """The long case (a 100000 s run) under a flood of 8 frames per ms, then the three cases of test_mini.py
    that never start: ABORTED, the cases that never ran counted, the flood's frames in a complete log."""
    run = Run(tmp_path / "out", str(CASES / "test_long.py"), str(CASES / "test_mini.py"), "--fault", FLOOD)
    run.wait_for(_log_grew)
    time.sleep(1.0)                                   # bench time is past 3 s: the flood is on
    took = run.stop(signal.SIGTERM)
    assert run.process.returncode == 143, run.text()     # 128 + SIGTERM, the shell's convention
    assert took <= LIMIT, f"{took:.2f} s from SIGTERM to the end; files written: {run.timeline()}"
    html = _aborted_report(run.out)
    assert "3 of 4 cases never ran" in html
    assert _frames_in_log(run.out / "run.mcap", 0x000) > 1000   # the flood's frames, logged and closed


def test_sigint_while_the_report_is_written(tmp_path: Path) -> None:
    """Every case passed; the signal comes as the report is drawn (30 cases with long plots take seconds to
    draw): no exception ends it, the report is written and marked ABORTED, its plots cut short."""
    run = Run(tmp_path / "out", str(CASES / "test_heavy_plots.py"))
    run.wait_for(" 30/30]")                           # the last case's progress line: the run is finishing
    took = run.stop(signal.SIGINT)
    assert run.process.returncode == 130, run.text()
    assert took <= LIMIT, f"{took:.2f} s from SIGINT to the end; files written: {run.timeline()}"
    html = _aborted_report(run.out)
    assert "left out: the run was stopped while its report was written" in html
    assert html.count('<span class="badge passed">passed</span>') >= 30          # every case's result is there
    assert _frames_in_log(run.out / "run.mcap") > 0


def test_sigterm_before_the_first_case(tmp_path: Path) -> None:
    """Stopped as the collection ends: a report and a complete log all the same."""
    run = Run(tmp_path / "out", str(CASES / "test_mini.py"))
    run.wait_for("bench: 3 cases")
    took = run.stop(signal.SIGTERM)
    assert run.process.returncode == 143, run.text()
    assert took <= LIMIT, f"{took:.2f} s from SIGTERM to the end; files written: {run.timeline()}"
    _aborted_report(run.out)
    _frames_in_log(run.out / "run.mcap")


def _worker_logs_grew(run: Run) -> bool:
    logs = list(run.out.glob("run-gw*.mcap"))
    return bool(logs) and max(log.stat().st_size for log in logs) > 500_000


def test_sigterm_with_parallel_workers(tmp_path: Path) -> None:
    """`bench run -n 2`: the signal goes to the controller, which hands it on to its workers (before, each worker
    stayed in its case until pytest-xdist's shutdown ended it: 5.3 s). Every worker's log is complete."""
    run = Run(tmp_path / "out", "-n", "2", str(CASES / "test_long.py"), str(CASES / "test_mini.py"))
    run.wait_for(_worker_logs_grew)
    time.sleep(0.5)
    took = run.stop(signal.SIGTERM)
    assert run.process.returncode == 143, run.text()
    assert took <= LIMIT, f"{took:.2f} s from SIGTERM to the end; files written: {run.timeline()}"
    html = _aborted_report(run.out)
    assert "test_runs_long" in html
    logs = sorted(run.out.glob("run-gw*.mcap"))
    assert len(logs) == 2 and all(_frames_in_log(log) > 0 for log in logs)
