"""Target 3: real-time periodic sending on udp_multicast — period error of every restbus message.

`bench plant --interface udp_multicast --channel <random 239.255.x.y>` (hop limit 0, set by bench.transport.bus) sends
every message of the simulated nodes at its DBC cycle time for 60 s (quick: 10 s) after a 2 s warm-up; a
receiver in this process (python-can `can.Bus(interface="udp_multicast", hop_limit=0)`, receive buffer
enlarged as the bench does) records the kernel's receive time of every frame (SO_TIMESTAMPNS, so this
process's own scheduling does not enter the figures). Period error = interval between consecutive frames of
an identifier − its DBC cycle time; p50/p99/max of |error| per message and over all messages. Frames lost on
the way show as AliveCounter gaps (counted) and as long intervals (included).

Baseline in the same run, same receiver, same messages (ids and cycles from dbc/chassis.dbc + dbc/bench.dbc)
and duration: python-can's `bus.send_periodic(msg, period)` thread tasks, one per message, in a process of
their own (as the plant is), sending constant 8-byte payloads (on a port of its own, so that it disturbs no
other bench on this host; the receiver listens there).
Target (issue 9): p99 <= 0.5 ms, max <= 2 ms. The machine is a shared 2-core VM: other work on it shows here.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import common

WARMUP_S = 2.0
P99_TARGET_MS, MAX_TARGET_MS = 0.5, 2.0
RECEIVE_BUFFER = 8 * 1024 * 1024


def plant_messages() -> dict[int, tuple[str, float]]:
    """id -> (name, DBC cycle s) of every periodic message the plant sends (every node but the stimulus)."""
    from bench.config import load_config
    from bench.database.codec import load_codebook

    project = load_config()
    codebook = load_codebook(project.databases)
    nodes = set(codebook.nodes) - set(project.stimulus)
    return {c.frame_id: (c.name, c.cycle_time) for c in codebook.sent_by(nodes) if c.cycle_time}


#: The baseline's own port, so that its frames never meet another bench's bus whatever that bus's socket options
#: (bench plant has no port option: the measured run uses python-can's default port 43113).
BASELINE_PORT = 43117


def open_receiver(group: str, port: int = 43113):
    import can

    bus = can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=0)
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is not None:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
    common.isolate_group(bus)          # only this group's frames (see common.udp_multicast_users)
    return bus


def receive(bus, seconds: float, warmup: float) -> dict[int, list[tuple[float, int]]]:
    """(kernel receive time, E2E counter) per identifier, for `seconds` after `warmup` from the first frame."""
    frames: dict[int, list[tuple[float, int]]] = {}
    first = None
    deadline = time.monotonic() + warmup + seconds + 30.0     # never hang on a sender that does not come
    while time.monotonic() < deadline:
        msg = bus.recv(0.5)
        if msg is None:
            continue
        ts = msg.timestamp
        if first is None:
            first = ts
            deadline = time.monotonic() + warmup + seconds
        if ts - first < warmup:
            continue
        counter = common.protection_of(msg.arbitration_id).counter_of(msg.data) if len(msg.data) == 8 else 0
        frames.setdefault(msg.arbitration_id, []).append((ts, counter))
    return frames


def cpu_of(pid: int) -> float | None:
    """CPU seconds (user + system) a process has used so far, from /proc."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def period_errors(frames: dict[int, list[tuple[float, int]]], messages: dict[int, tuple[str, float]],
                  counters: bool) -> dict:
    per: dict[str, dict] = {}
    pooled: list[float] = []
    lost_total = 0
    missing = []
    for frame_id, (name, cycle) in sorted(messages.items()):
        got = frames.get(frame_id, [])
        if len(got) < 2:
            missing.append(name)
            continue
        errors = [abs((b[0] - a[0]) - cycle) for a, b in zip(got, got[1:])]
        protection = common.protection_of(frame_id)
        lost = sum(common.counter_gap(protection, a[1], b[1]) for a, b in zip(got, got[1:])) if counters else 0
        lost_total += lost
        pooled.extend(errors)
        s = common.summary(errors, 1000.0)
        s.update(cycle_ms=cycle * 1000, frames=len(got), lost=lost,
                 mean_interval_ms=(got[-1][0] - got[0][0]) / (len(got) - 1) * 1000)
        per[name] = s
    unexpected = sorted(hex(i) for i in frames if i not in messages)
    edges = (0.0001, 0.00025, 0.0005, 0.001, 0.002, 0.005, 0.01)     # s
    histogram = {f"<= {e * 1000:g} ms": sum(1 for x in pooled if x <= e) for e in edges}
    histogram[f"> {edges[-1] * 1000:g} ms"] = sum(1 for x in pooled if x > edges[-1])
    return {"per_message": per, "overall": common.summary(pooled, 1000.0), "lost": lost_total,
            "cumulative_histogram": histogram,
            "missing": missing, "unexpected_ids": unexpected}


def run_plant(group: str, seconds: float, messages) -> dict:
    bus = open_receiver(group)
    plant = subprocess.Popen([sys.executable, "-m", "bench", "plant", "--interface", "udp_multicast", "--channel",
                              group, "--duration", str(seconds + WARMUP_S + 15)], cwd=common.ROOT,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        frames = receive(bus, seconds, WARMUP_S)
        cpu = cpu_of(plant.pid)
    finally:
        plant.send_signal(signal.SIGINT)
        try:
            out = plant.communicate(timeout=30)[0]
        except subprocess.TimeoutExpired:
            plant.kill()
            out = plant.communicate()[0]
        bus.shutdown()
    result = period_errors(frames, messages, counters=True)
    result["plant_status"] = [line for line in out.splitlines() if "max lag" in line][-2:]
    result["sender_cpu_s_total"] = cpu
    return result


def run_baseline(group: str, seconds: float, messages) -> dict:
    bus = open_receiver(group, BASELINE_PORT)
    sender = subprocess.Popen([sys.executable, __file__, "--baseline-sender", group, str(seconds + WARMUP_S + 5)],
                              cwd=common.ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        frames = receive(bus, seconds, WARMUP_S)
        cpu = cpu_of(sender.pid)
    finally:
        sender.send_signal(signal.SIGTERM)
        try:
            out = sender.communicate(timeout=30)[0]
        except subprocess.TimeoutExpired:
            sender.kill()
            out = sender.communicate()[0]
        bus.shutdown()
    result = period_errors(frames, messages, counters=False)
    result["sender_output"] = out.splitlines()[-3:]
    result["sender_cpu_s_total"] = cpu
    return result


def baseline_sender(group: str, seconds: float) -> None:
    """python-can's thread-based periodic tasks, one per message, for `seconds` (the baseline's process)."""
    import can

    stop = {"now": False}
    signal.signal(signal.SIGTERM, lambda *_: stop.update(now=True))
    bus = can.Bus(interface="udp_multicast", channel=group, port=BASELINE_PORT, hop_limit=0)
    tasks = []
    for frame_id, (_, cycle) in sorted(plant_messages().items()):
        msg = can.Message(arbitration_id=frame_id, data=bytes(8), is_extended_id=False)
        tasks.append(bus.send_periodic(msg, cycle))
    print(f"baseline sender: {len(tasks)} send_periodic tasks ({type(tasks[0]).__name__})", flush=True)
    end = time.monotonic() + seconds
    while not stop["now"] and time.monotonic() < end:
        time.sleep(0.1)
    for task in tasks:
        task.stop()
    bus.shutdown()


def measure(result: common.Result, args: argparse.Namespace) -> None:
    seconds = 10.0 if args.quick else 60.0
    messages = plant_messages()
    quiet = common.udp_users_at_start()
    load_before = common.load_average()
    watch = common.UdpWatch()
    plant = run_plant(common.random_group(), seconds, messages)
    baseline = run_baseline(common.random_group(), seconds, messages)
    others = watch.stop()
    common.note_udp_users(result, quiet, others)
    result.details.update(seconds=seconds, warmup_s=WARMUP_S, messages=len(messages), load_before=load_before,
                          other_udp_multicast=quiet,
                          plant=plant, baseline=baseline,
                          machine_note="shared 2-core VM: other engineers' processes run at the same time")
    po, bo = plant["overall"], baseline["overall"]
    base = "python-can send_periodic threads"
    result.add("bench plant: period error p50", po["p50"], "ms", bo["p50"], base)
    result.add("bench plant: period error p99", po["p99"], "ms", bo["p99"], base, P99_TARGET_MS, "<=",
               note=f"{len(messages)} messages, {po['n']} intervals in {seconds:g} s; lost {plant['lost']}; "
                    f"missing {plant['missing'] or 'none'}")
    result.add("bench plant: period error max", po["max"], "ms", bo["max"], base, MAX_TARGET_MS, "<=",
               note=f"plant: {'; '.join(plant['plant_status']) or '-'}")
    worst = max(plant["per_message"].items(), key=lambda kv: kv[1]["p99"], default=None)
    if worst:
        result.add("bench plant: worst message's p99", worst[1]["p99"], "ms", note=worst[0])
    if plant["sender_cpu_s_total"] is not None:
        result.add("bench plant: CPU (whole process life, incl. start-up)", plant["sender_cpu_s_total"], "s",
                   baseline["sender_cpu_s_total"], base)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--baseline-sender", nargs=2, metavar=("GROUP", "SECONDS"), default=None,
                        help=argparse.SUPPRESS)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--baseline-sender":
        baseline_sender(sys.argv[2], float(sys.argv[3]))
        raise SystemExit(0)
    raise SystemExit(common.main("periodic_udp", "Target 3: real-time periodic sending on udp_multicast", measure,
                                 configure, __doc__))
