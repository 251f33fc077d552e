"""The run's MCAP log, written by a child process.

Why a child: logging every frame (JSON of the raw frame and of its decoded values, then mcap's chunking and
compression) is a large part of a campaign's CPU (docs/performance.md, "the log package" and issue 18's
sections); in a child process it runs on the machine's other core while the simulation goes on, and the child
writes each run of frames with `Recorder.frames` (the texts of a repeated frame built once), and follows the
diagnostic connections (bench.log.diaglog: a whole UDS message per record, from the declaration the run names).
The simulation hands over raw frames in batches (no decoded values: the child decodes them again
with the same codec, which is cheaper than pickling them), each batch's frames as one list and its few other
items (steps, metadata, the time origin) apart with their place among the frames. The child
ignores SIGINT/SIGTERM and finishes the file when the run closes the pipe, or when the run dies:
a run killed with SIGKILL still leaves a complete log of every frame handed over before the kill
(at most BATCH_SECONDS of wall time of frames are lost).

In a User-mode Linux guest (the vcan lane, docs/vcan-lane.md) a clock read is a system call: the child reads the
clock once per batch (its chunk flushes, FLUSH_SECONDS), not once per record as the Recorder's own interval
would, and it runs at a lower priority (LOG_NICE): it has no deadline, the simulation has.
"""

from __future__ import annotations

import contextlib
import gc
import json
import logging
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from multiprocessing.connection import Connection
from operator import itemgetter
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bench.errors import BenchError, LogError

if TYPE_CHECKING:   # the run's process needs none of them (nor mcap's or udsoncan's import); the child imports them
    from bench.log.diaglog import DiagnosticLog
    from bench.log.recorder import Decoder, Recorder

BATCH_FRAMES = 2000      # hand over at least this often ...
BATCH_SECONDS = 0.2      # ... and at least every 0.2 s of wall time
CLOSE_TIMEOUT = 120.0    # s the child may take to write what it still has
FLUSH_SECONDS = 0.5      # the child finalises an MCAP chunk (and hands it to the OS) after a batch this often
LOG_NICE = 10            # the child's niceness increment: the run's ticks first when the CPU is short
_STEP = "step"
_META = "meta"
_ORIGIN = "origin"


class LogProcess:
    """Same calls as the recorder's frame/step/close, served by a child process."""

    def __init__(self, path: Path, databases: Sequence[Path], channel: str,
                 e2e_overrides: Mapping[str, Mapping[str, Any]] | None = None, diagnostics: Path | None = None) -> None:
        """`e2e_overrides`: bench.toml's [e2e] table, so that the child loads the databases as the run does;
        `diagnostics`: its [diagnostics] file, the nodes and addresses of the log's diagnostic topics."""
        # A program of its own (not multiprocessing, which would re-import the caller's main module), in a
        # session of its own so that a signal to the run's process group does not cut the log short.
        self._process = subprocess.Popen(
            [sys.executable, "-m", "bench.log.logproc", str(path), channel, json.dumps(dict(e2e_overrides or {})),
             str(diagnostics or ""), *map(str, databases)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, start_new_session=True)
        assert self._process.stdin is not None and self._process.stdout is not None
        self._to_child = Connection(os.dup(self._process.stdin.fileno()), readable=False)
        self._from_child = Connection(os.dup(self._process.stdout.fileno()), writable=False)
        self._process.stdin.close()
        self._process.stdout.close()
        status = self._receive_status()
        if status != "ready":
            self._process.wait(10)
            raise LogError(status)
        self._batch: list[tuple[Any, ...]] = []          # frames
        self._others: list[tuple[int, tuple[Any, ...]]] = []   # (how many frames of the batch come before, item)
        self._deadline = time.monotonic() + BATCH_SECONDS
        self._closed = False
        self.path = path

    def frame(self, t: float, frame_id: int, data: bytes, direction: str, valid: bool, error: str) -> None:
        batch = self._batch
        batch.append((t, frame_id, data, direction, valid, error))
        # the clock every 32nd frame only: a read is a system call in a UML guest (issue 15), and the runner
        # logs every frame on the bus
        if len(batch) >= BATCH_FRAMES or (not len(batch) & 31 and time.monotonic() >= self._deadline):
            self._hand_over()

    def step(self, t: float, level: int, name: str, message: str) -> None:
        self._others.append((len(self._batch), (_STEP, t, level, name, message)))

    def origin(self, epoch_ns: int, realtime: bool) -> None:
        """The epoch time (ns) of bench time 0: log times become epoch times (Foxglove shows the date)."""
        self._others.append((len(self._batch), (_ORIGIN, int(epoch_ns), bool(realtime))))

    def metadata(self, name: str, data: dict[str, str]) -> None:
        """A metadata record (e.g. an injected fault) in the log."""
        self._others.append((len(self._batch), (_META, name, {str(k): str(v) for k, v in data.items()})))

    def _hand_over(self) -> None:
        if (self._batch or self._others) and not self._closed:
            # the frames apart from the rare other items: the child writes runs of frames without a look at each
            self._to_child.send((self._batch, self._others))
            self._batch = []
            self._others = []
        self._deadline = time.monotonic() + BATCH_SECONDS

    def close(self) -> None:
        """Hand over the rest and wait for the child to finish the file; idempotent."""
        if self._closed:
            return
        self._hand_over()
        self._closed = True
        try:
            self._to_child.send(None)
            status = self._receive_status(CLOSE_TIMEOUT)
        finally:
            self._to_child.close()
            self._from_child.close()
            self._process.wait(CLOSE_TIMEOUT)
        if status != "closed":
            raise LogError(f"{self.path}: {status}")

    def _receive_status(self, timeout: float = 60.0) -> str:
        if not self._from_child.poll(timeout):
            return f"the log process did not answer within {timeout:g} s"
        try:
            return str(self._from_child.recv())
        except EOFError:
            return "the log process ended unexpectedly"


def _leave_real_time() -> None:
    """The child has no deadline: it drops a real-time policy inherited from the run (`chrt -f`, as the README
    advises on a loaded host), under which nice means nothing and each batch it decodes (tens of ms) would hold a
    core that the tick loops of the run, the plant and the ECU need. Lowering one's own policy needs no privilege."""
    with contextlib.suppress(AttributeError, OSError):   # (no sched_* on this platform: nothing was inherited)
        if os.sched_getscheduler(0) in (os.SCHED_FIFO, os.SCHED_RR):
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def _serve(conn: Connection, reply: Connection, path: str, databases: list[str], channel: str,
           e2e_overrides: Mapping[str, Mapping[str, Any]] | None = None, diagnostics: str = "") -> None:
    """The child: one Recorder, fed batch by batch until the pipe says stop or closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # Ctrl-C and SIGTERM are for the run; it closes us
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _leave_real_time()
    try:
        os.nice(LOG_NICE)
    except OSError as exc:   # not fatal: the log is only written later than it could be
        logging.getLogger("bench.log.logproc").warning("log process: nice(%d) failed: %s", LOG_NICE, exc)
    from bench.database.codec import load_codebook
    from bench.diag.declaration import load_declaration
    from bench.log.diaglog import DiagnosticLog
    from bench.log.recorder import Recorder

    try:
        codebook = load_codebook(databases, e2e_overrides)
        # flush_interval inf: the Recorder reads no clock per record; the chunks are finalised below, per batch
        recorder = Recorder(Path(path), [db for _, db in codebook.databases], attachments=[Path(p) for p in databases],
                            flush_interval=math.inf)
    except BenchError as exc:
        reply.send(str(exc))
        return
    try:
        declaration = load_declaration(Path(diagnostics)) if diagnostics else None
    except BenchError:   # the run's session reports it; the log follows the databases' diagnostic messages
        declaration = None
    trace = DiagnosticLog(recorder, codebook, declaration)
    reply.send("ready")
    # The collector's automatic passes cost about a tenth of this process's CPU (each batch is tens of thousands of
    # new tuples, none in a cycle); the start's objects (modules, databases) are moved out of its scans, and it
    # runs once per flush instead.
    gc.freeze()
    gc.disable()
    by_id = codebook.by_id
    rejected = 0
    flush_at = time.monotonic() + FLUSH_SECONDS
    try:
        while True:
            try:
                batch = conn.recv()
            except EOFError:       # the run died: finish the file with what arrived
                break
            if batch is None:
                break
            frames, others = batch
            start = 0   # each run of frames between other items is written in one call
            for position, item in others:
                rejected += _write_frames(recorder, frames[start:position], channel, by_id, path, rejected, trace)
                start = position
                try:
                    if item[0] == _STEP:
                        recorder.step(item[1], item[2], item[3], item[4])
                    elif item[0] == _META:
                        recorder.metadata(item[1], item[2])
                    elif item[0] == _ORIGIN:
                        recorder.set_origin(item[1], "real" if item[2] else "virtual")
                except (BenchError, ValueError, TypeError) as exc:   # one bad record must not end the log
                    rejected += 1
                    _report_first(path, rejected, str(exc))
            rejected += _write_frames(recorder, frames[start:] if start else frames, channel, by_id, path, rejected,
                                      trace)
            now = time.monotonic()   # one clock read per batch
            if now >= flush_at:
                recorder.flush()     # on disk: a run killed now loses at most this batch's successors
                gc.collect()
                flush_at = now + FLUSH_SECONDS
    finally:
        recorder.close()
    if rejected:
        print(f"bench log: {path}: {rejected} record(s) not written", file=sys.stderr, flush=True)
    try:
        reply.send("closed")
    except (BrokenPipeError, OSError):
        pass


def _write_frames(recorder: Recorder, frames: list[tuple[Any, ...]], channel: str,
                  codecs: Mapping[int, Decoder], path: str, rejected: int, trace: DiagnosticLog | None = None) -> int:
    """Write a run of frames with their decoded values, and after each diagnostic frame the message it completes;
    how many records were refused (reported as they come)."""
    if not frames:
        return 0
    try:   # one pass in C over the run's ids: a run without diagnostic frames (nearly all) costs no more
        diagnostic = trace is not None and not trace.ids.isdisjoint(map(itemgetter(1), frames))
    except (TypeError, IndexError):   # a malformed item: the frames alone, as below
        diagnostic = False
    if not diagnostic:
        return _write_run(recorder, frames, channel, codecs, path, rejected)
    assert trace is not None
    count = start = 0
    for end, frame in enumerate(frames, 1):
        if frame[1] in trace.ids:
            count += _write_run(recorder, frames[start:end], channel, codecs, path, rejected + count)
            start = end
            try:
                trace.on_frame(frame[0], frame[1], bytes(frame[2]))
            except (BenchError, ValueError, TypeError) as exc:
                count += 1
                _report_first(path, rejected + count, str(exc))
    return count + _write_run(recorder, frames[start:], channel, codecs, path, rejected + count)


def _write_run(recorder: Recorder, frames: list[tuple[Any, ...]], channel: str,
               codecs: Mapping[int, Decoder], path: str, rejected: int) -> int:
    """`_write_frames` of frames without the diagnostic topics."""
    if not frames:
        return 0
    try:
        problems = recorder.frames(frames, channel=channel, codecs=codecs)
    except (BenchError, ValueError, TypeError):   # a malformed item: one record at a time, as before
        problems = []
        for frame in frames:
            try:
                problems += recorder.frames([frame], channel=channel, codecs=codecs)
            except (BenchError, ValueError, TypeError) as exc:
                problems.append(str(exc))
    for count, problem in enumerate(problems, rejected + 1):
        _report_first(path, count, problem)
    return len(problems)


def _report_first(path: str, count: int, problem: str) -> None:
    if count == 1:
        print(f"bench log: {path}: record not written ({problem}); later ones are counted", file=sys.stderr,
              flush=True)


if __name__ == "__main__":
    _serve(Connection(os.dup(0), writable=False), Connection(os.dup(1), readable=False), sys.argv[1],
           sys.argv[5:], sys.argv[2], json.loads(sys.argv[3]), sys.argv[4])
