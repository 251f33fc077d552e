"""Target 2: throughput of the receive path on one core — decode + monitor checks + MCAP write, frames/s.

N valid contract frames (every message of chassis.dbc and bench.dbc at its DBC cycle time, signals moving
as sinusoids over their DBC ranges, AliveCounter and Checksum right: built by `bench.sim.restbus.Restbus.build`)
go through `bench.checks.monitor.Monitor` (length, E2E, counter sequence, decode, range; history kept) with a sink
that logs the raw frame and its decoded values to `bench.log.recorder.Recorder`, on this one thread; the time
includes closing the log (every chunk compressed and on disk).

Baseline in the same run, same frames: plain cantools `Database.decode_message` plus python-can's
`can.BLFWriter` (a `can.Message` per frame, as a python-can logger needs it).

Also measured, to show where the time goes: the monitor alone (no sink), the recorder alone (frames and
pre-decoded values), and the receive path as `bench run` wires it today (BenchRun's own sink: when the log
is written by a child process that is two processes, so it is reported with the CPU time of both).
Target (issue 9): >= 20 000 frames/s, twice a fully loaded 1 Mbit/s classical CAN bus (about 9 000 frames/s).
"""

from __future__ import annotations

import argparse
import math
import random
import shutil
import time
from pathlib import Path

import common

TARGET = 20_000.0       # frames/s
FULL_BUS = 9_000.0      # eight-byte frames/s on a fully loaded 1 Mbit/s classical CAN bus (issue 9)
CHANNEL = "bench:receive-path"


def make_frames(n: int) -> tuple[list[tuple[float, int, bytes]], object, object]:
    """n frames in bus order (1 ms ticks, each message at its DBC cycle and phase), with moving values."""
    from bench.config import load_config
    from bench.database.codec import load_codebook
    from bench.sim.restbus import Restbus

    project = load_config()
    codebook = load_codebook(project.databases)
    restbus = Restbus(codebook, codebook.nodes)          # every node: every message of both databases
    rng = random.Random(9)
    # per signal: (name, centre, amplitude, frequency Hz, phase) or (name, [choices]) for value tables
    plans = {}
    for name, slot in restbus.periodic.items():
        plan = []
        for sig in slot.codec.signals:
            if sig.name in ("AliveCounter", "Checksum"):
                continue
            if sig.choices:
                plan.append((sig.name, sorted(sig.choices.values())))
                continue
            lo = sig.minimum if sig.minimum is not None else 0.0
            hi = sig.maximum if sig.maximum is not None else lo
            plan.append((sig.name, (lo + hi) / 2, 0.45 * (hi - lo), rng.uniform(0.1, 2.0), rng.uniform(0, 6.3)))
        plans[name] = plan
    slots = list(restbus.periodic.items())
    frames: list[tuple[float, int, bytes]] = []
    tick = 0
    while len(frames) < n:
        tick += 1
        t = tick * 0.001
        for name, slot in slots:
            if tick % slot.period != slot.next_due % slot.period:
                continue
            values = {}
            for item in plans[name]:
                if len(item) == 2:
                    choices = item[1]
                    values[item[0]] = choices[int(t) % len(choices)]
                else:
                    sig, centre, amp, freq, phase = item
                    values[sig] = centre + amp * math.sin(2 * math.pi * freq * t + phase)
            restbus.set(name, **values)
            frames.append((t, slot.codec.frame_id, restbus.build(slot)))
            if len(frames) >= n:
                break
    return frames, project, codebook


def bench_path(frames, project, codebook, path: Path) -> tuple[float, float, int]:
    """Monitor + Recorder (frame + decoded) on this thread; (wall s, CPU s, invalid frames)."""
    from bench.checks.monitor import Monitor
    from bench.database.codec import load_dbc
    from bench.log.recorder import Recorder

    recorder = Recorder(path, [load_dbc(p) for p in project.databases], attachments=list(project.databases))

    def sink(frame):   # a bench.checks.monitor.CheckedFrame, as bench/run.py's sink gets it
        recorder.frame(frame.t, frame.arbitration_id, frame.data, channel=CHANNEL, direction=frame.direction,
                       valid=frame.valid, error=frame.reason)
        if frame.values is not None and frame.codec is not None:
            recorder.decoded(frame.t, frame.codec.name, frame.values)

    monitor = Monitor(codebook, keep_history=True, sink=sink)
    on_frame = monitor.on_frame
    wall0, cpu0 = time.perf_counter(), common.cpu_seconds()
    for t, frame_id, data in frames:
        on_frame(t, frame_id, data, "rx")
    recorder.close()
    return time.perf_counter() - wall0, common.cpu_seconds() - cpu0, monitor.invalid_frames


def bench_monitor_only(frames, codebook) -> tuple[float, float]:
    from bench.checks.monitor import Monitor

    monitor = Monitor(codebook, keep_history=True)
    on_frame = monitor.on_frame
    wall0, cpu0 = time.perf_counter(), common.cpu_seconds()
    for t, frame_id, data in frames:
        on_frame(t, frame_id, data, "rx")
    wall, cpu = time.perf_counter() - wall0, common.cpu_seconds() - cpu0
    assert monitor.invalid_frames == 0, monitor.invalid_log[:3]
    return wall, cpu


def bench_recorder_only(frames, project, codebook, path: Path) -> tuple[float, float]:
    from bench.database.codec import load_dbc
    from bench.log.recorder import Recorder

    by_id = codebook.by_id
    decoded = [(t, fid, data, by_id[fid].name, by_id[fid].decode(data)) for t, fid, data in frames]
    recorder = Recorder(path, [load_dbc(p) for p in project.databases], attachments=list(project.databases))
    wall0, cpu0 = time.perf_counter(), common.cpu_seconds()
    for t, fid, data, name, values in decoded:
        recorder.frame(t, fid, data, channel=CHANNEL, direction="rx", valid=True, error="")
        recorder.decoded(t, name, values)
    recorder.close()
    return time.perf_counter() - wall0, common.cpu_seconds() - cpu0


def bench_baseline(frames, project, path: Path) -> tuple[float, float]:
    """cantools decode_message + python-can BLFWriter; (wall s, CPU s)."""
    import can
    import cantools

    dbs = [cantools.database.load_file(str(p), database_format="dbc") for p in project.databases]
    by_id = {m.frame_id: db for db in dbs for m in db.messages}
    writer = can.BLFWriter(str(path), channel=1)
    on_message = writer.on_message_received
    Message = can.Message
    wall0, cpu0 = time.perf_counter(), common.cpu_seconds()
    for t, frame_id, data in frames:
        by_id[frame_id].decode_message(frame_id, data)
        on_message(Message(timestamp=t, arbitration_id=frame_id, data=data, is_extended_id=False, channel=1))
    writer.stop()
    return time.perf_counter() - wall0, common.cpu_seconds() - cpu0


def bench_as_run(frames, project, codebook, out: Path) -> tuple[float, float, str] | None:
    """The monitor with the sink `bench.run.BenchRun` builds today (whatever the log's process layout)."""
    from bench.checks.monitor import Monitor
    from bench.config import RunSettings
    from bench.run import BenchRun

    run = BenchRun(project, RunSettings(), out)
    sink = getattr(run, "_sink", None)
    if sink is None:
        run.finish()
        return None
    layout = type(run.recorder).__name__ if getattr(run, "recorder", None) is not None else "?"
    monitor = Monitor(codebook, keep_history=True, sink=sink)
    on_frame = monitor.on_frame
    wall0, cpu0 = time.perf_counter(), common.cpu_seconds()
    for t, frame_id, data in frames:
        on_frame(t, frame_id, data, "rx")
    run.finish()                    # closes the log (waits for a log process to finish the file)
    return time.perf_counter() - wall0, common.cpu_seconds() - cpu0, layout


def measure(result: common.Result, args: argparse.Namespace) -> None:
    n = args.frames or (30_000 if args.quick else 200_000)
    frames, project, codebook = make_frames(n)
    work: Path = args.work
    messages = len({f[1] for f in frames})
    result.details.update(frames=n, messages=messages, bench_seconds_of_traffic=frames[-1][0])

    wall, cpu, invalid = bench_path(frames, project, codebook, work / "receive.mcap")
    if invalid:
        raise RuntimeError(f"{invalid} generated frames were judged invalid: the generator is wrong")
    base_wall, base_cpu = bench_baseline(frames, project, work / "baseline.blf")
    mon_wall, mon_cpu = bench_monitor_only(frames, codebook)
    rec_wall, rec_cpu = bench_recorder_only(frames, project, codebook, work / "recorder-only.mcap")
    as_run = bench_as_run(frames, project, codebook, work / "as-run")

    base = "cantools decode_message + can.BLFWriter"
    result.add("receive path, one thread: monitor + MCAP (frame + decoded)", n / wall, "frames/s", n / base_wall,
               base, TARGET, ">=", note=f"wall time; {n / wall / FULL_BUS:.2f}× a full 1 Mbit/s bus (~9 000 frames/s)")
    result.add("  the same per CPU-second (load-independent)", n / cpu, "frames/CPU-s", n / base_cpu, base,
               TARGET, ">=", note="CPU time of the process: what one core that is not shared would do")
    result.add("  of which: monitor alone (E2E, counter, decode, range, history)", n / mon_cpu, "frames/CPU-s",
               note=f"{mon_cpu / cpu * 100:.0f} % of the path's CPU time")
    result.add("  of which: recorder alone (JSON + mcap/zstd, 2 records per frame)", n / rec_cpu, "frames/CPU-s",
               note=f"{rec_cpu / cpu * 100:.0f} % of the path's CPU time")
    result.details.update(
        path={"wall_s": wall, "cpu_s": cpu, "mcap_bytes": (work / "receive.mcap").stat().st_size},
        baseline={"wall_s": base_wall, "cpu_s": base_cpu, "blf_bytes": (work / "baseline.blf").stat().st_size},
        monitor_only={"wall_s": mon_wall, "cpu_s": mon_cpu},
        recorder_only={"wall_s": rec_wall, "cpu_s": rec_cpu})
    if as_run is not None:
        w, c, layout = as_run
        result.add(f"receive path as bench run wires it ({layout})", n / w, "frames/s", n / base_wall, base,
                   note=f"wall; CPU of all its processes {c:.2f} s = {n / c:,.0f} frames/CPU-s")
        result.details["as_run"] = {"wall_s": w, "cpu_s": c, "log_writer": layout}
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=0, help="number of frames (default 200 000; quick 30 000)")
    parser.add_argument("--keep", action="store_true", help="keep the logs written")


if __name__ == "__main__":
    raise SystemExit(common.main("receive_path", "Target 2: receive-path throughput on one core", measure,
                                 configure, __doc__))
