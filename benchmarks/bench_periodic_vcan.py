"""Periodic sending on SocketCAN vcan0: the kernel's broadcast manager (BCM) against the tick scheduler.

Needs SocketCAN with vcan0 up; on a machine without CAN in its kernel run it in the vcan lane's guest (User-mode
Linux where it runs, docs/vcan-lane.md):

    scripts/vcan-lane --command 'python benchmarks/bench_periodic_vcan.py --json "$LANE_OUT/periodic.json"'

The question (issue 15, acceptance 2): the period error of the bench's two send paths (the tick scheduler and
the broadcast manager through bench/transport/periodic.py), beside python-can's own `send_periodic` as the baseline,
measured in the same run. Four senders run at the same time, each in a process of its own, for 20 s (quick:
6 s) after a 2 s warm-up, while `bench plant` runs on the same bus as load (--no-load: without it):
- "tick scheduler": a bench station (bench.sim.station, the restbus of node DRIVER: DRV_Steering and DRV_Pedals
  at 10 ms, DRV_MotionRequest at 20 ms) on the wall clock's 1 ms tick, with kernel periodic sending off
  (what every message of the bench did before bench/transport/periodic.py);
- "bench + BCM": a bench station with bench/transport/periodic.py on (the restbus of node TESTER: BENCH_SteeringRobot
  at 10 ms, BENCH_Control at 20 ms, ...): its steady messages go to the BCM as 16-frame counter cycles;
- baseline "python-can send_periodic": python-can's `bus.send_periodic(16 frames, period)` (on socketcan a BCM
  task: 0x7E0 at 10 ms, 0x7E1 at 20 ms);
- "python-can thread": `can.broadcastmanager.ThreadBasedCyclicSendTask` with a modifier_callback that writes
  AliveCounter and Checksum (0x7F0 at 10 ms, 0x7F1 at 20 ms), how a python-can user sends E2E frames without
  the BCM (a second reference).
Each sender reports its CPU time (user + system, s), so the cost of a path is beside its accuracy.
A receiver process records the kernel's receive time of every frame (SO_TIMESTAMPNS: its own scheduling does
not enter the figures; on vcan that is the moment the frame was sent). Period error = |interval between
consecutive frames of an identifier - its cycle time|; p50/p99/max per sender over its identifiers;
AliveCounter gaps are counted as lost frames.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import common

WARMUP_S = 2.0
CHANNEL = os.environ.get("VCAN_CHANNEL", "vcan0")
RAW_BCM = {0x7E0: 0.010, 0x7E1: 0.020}
THREAD = {0x7F0: 0.010, 0x7F1: 0.020}
BASELINE = "python-can send_periodic"
KINDS = ("tick scheduler", "bench + BCM", BASELINE, "python-can thread")


def has_vcan() -> bool:
    try:
        sock = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except OSError:
        return False
    sock.close()
    return Path("/sys/class/net", CHANNEL).exists()


def station_messages(node: str) -> dict[int, tuple[str, float]]:
    from bench.config import load_config
    from bench.database.codec import load_codebook

    codebook = load_codebook(load_config().databases)
    return {c.frame_id: (c.name, c.cycle_time) for c in codebook.sent_by([node]) if c.cycle_time}


# -- the senders (each its own process) ------------------------------------------------------------------------
def run_station(node: str, kernel: bool, seconds: float) -> None:
    """A bench station playing `node` on the wall clock's tick, as bench plant / bench run do."""
    import can

    from bench.checks.monitor import Monitor
    from bench.config import load_config
    from bench.database.codec import load_codebook
    from bench.sim.clock import Scheduler, WallClock
    from bench.sim.restbus import Restbus
    from bench.sim.station import Station

    codebook = load_codebook(load_config().databases)
    bus = can.Bus(interface="socketcan", channel=CHANNEL, receive_own_messages=False)
    clock = WallClock()
    station = Station(node, bus, Restbus(codebook, {node}), Monitor(codebook), clock.now)
    if not kernel:
        station.kernel = None
    elif station.kernel is None:
        raise SystemExit("bench/transport/periodic.py did not attach to this socketcan bus")
    scheduler = Scheduler([station], clock)
    clock.start()
    scheduler.run_until(seconds)
    stats = station.kernel
    print(json.dumps({"node": node, "sent": station.sent, "max_lag_ms": clock.max_lag * 1000, "cpu_s": _cpu(),
                      "bcm_tasks_started": stats.started if stats else 0,
                      "bcm_modified": stats.modified if stats else 0, "bcm_stopped": stats.stopped if stats else 0}),
          flush=True)
    bus.shutdown()


def _cpu() -> float:
    times = os.times()
    return round(times.user + times.system, 3)


def _protect(frame_id: int, data: bytearray, counter: int) -> None:
    common.protection_of(frame_id).protect(data, counter)


def run_raw_bcm(seconds: float) -> None:
    import can

    from bench.transport.periodic import counter_cycle

    bus = can.Bus(interface="socketcan", channel=CHANNEL)
    tasks = [bus.send_periodic(counter_cycle(common.protection_of(i), i, bytes(8), 0), period)
             for i, period in RAW_BCM.items()]
    time.sleep(seconds)
    for task in tasks:
        task.stop()
    bus.shutdown()
    print(json.dumps({"cpu_s": _cpu()}), flush=True)


def run_thread(seconds: float) -> None:
    import can
    from can.broadcastmanager import ThreadBasedCyclicSendTask

    bus = can.Bus(interface="socketcan", channel=CHANNEL)
    lock = threading.Lock()
    counters = dict.fromkeys(THREAD, 0)

    def e2e(msg: can.Message) -> None:            # runs before every send: next AliveCounter and its Checksum
        data = bytearray(msg.data)
        _protect(msg.arbitration_id, data, counters[msg.arbitration_id])
        counters[msg.arbitration_id] = common.protection_of(msg.arbitration_id).next_counter(
            counters[msg.arbitration_id])
        msg.data = data

    tasks = [ThreadBasedCyclicSendTask(bus, lock, can.Message(arbitration_id=i, data=bytes(8), is_extended_id=False),
                                       period, modifier_callback=e2e) for i, period in THREAD.items()]
    time.sleep(seconds)
    for task in tasks:
        task.stop()
    bus.shutdown()
    print(json.dumps({"cpu_s": _cpu()}), flush=True)


# -- the receiver --------------------------------------------------------------------------------------------------
def run_receiver(ids: list[int], seconds: float, out: Path) -> None:
    import can

    bus = can.Bus(interface="socketcan", channel=CHANNEL,
                  can_filters=[{"can_id": i, "can_mask": 0x7FF, "extended": False} for i in ids])
    bus.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 * 1024 * 1024)
    frames: dict[int, list[tuple[float, int]]] = {}
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        msg = bus.recv(0.2)
        if msg is not None:
            frames.setdefault(msg.arbitration_id, []).append(
                (msg.timestamp, common.protection_of(msg.arbitration_id).counter_of(msg.data)))
    bus.shutdown()
    out.write_text(json.dumps({str(k): v for k, v in frames.items()}))


# -- the measurement -----------------------------------------------------------------------------------------------
def spawn(*argv: str, log: Path) -> subprocess.Popen:
    with open(log, "w") as handle:
        return subprocess.Popen([sys.executable, __file__, *argv], cwd=common.ROOT, stdout=handle,
                                stderr=subprocess.STDOUT)


def analyse(frames: dict[int, list[tuple[float, int]]], cycles: dict[int, float], t_start: float) -> dict:
    errors: list[float] = []
    lost = 0
    per_id = {}
    for frame_id, cycle in cycles.items():
        got = [f for f in frames.get(frame_id, []) if f[0] >= t_start]
        e = [abs((b[0] - a[0]) - cycle) for a, b in zip(got, got[1:])]
        protection = common.protection_of(int(frame_id))
        gaps = sum(common.counter_gap(protection, a[1], b[1]) for a, b in zip(got, got[1:]))
        lost += gaps
        errors.extend(e)
        per_id[hex(frame_id)] = {**common.summary(e, 1000.0), "cycle_ms": cycle * 1000, "lost": gaps}
    return {"overall": common.summary(errors, 1000.0), "lost": lost, "per_id": per_id}


def measure(result: common.Result, args: argparse.Namespace) -> None:
    if not has_vcan():
        raise RuntimeError(f"needs SocketCAN and {CHANNEL} up: run it in the vcan lane (scripts/vcan-lane "
                           f"--command 'python benchmarks/bench_periodic_vcan.py')")
    seconds = 6.0 if args.quick else 20.0
    total = WARMUP_S + seconds
    work = args.work
    driver, tester = station_messages("DRIVER"), station_messages("TESTER")
    cycles = {"tick scheduler": {i: c for i, (_, c) in driver.items()},
              "bench + BCM": {i: c for i, (_, c) in tester.items()},
              BASELINE: dict(RAW_BCM), "python-can thread": dict(THREAD)}
    ids = [i for kind in cycles.values() for i in kind]
    load = None
    if not args.no_load:
        load = subprocess.Popen([sys.executable, "-m", "bench", "plant", "--interface", "socketcan", "--channel",
                                 CHANNEL, "--duration", f"{total + 60:.0f}"], cwd=common.ROOT,
                                stdout=open(work / "plant.log", "w"), stderr=subprocess.STDOUT)
        time.sleep(3.0)
    frames_file = work / "frames.json"
    receiver = spawn("--receive", str(frames_file), f"{total + 3:.1f}", *map(str, ids), log=work / "receiver.log")
    time.sleep(1.0)
    t_start = time.time() + WARMUP_S          # receive timestamps are wall-clock (SO_TIMESTAMPNS)
    senders = {
        "tick scheduler": spawn("--station", "DRIVER", "off", f"{total:.1f}", log=work / "tick.log"),
        "bench + BCM": spawn("--station", "TESTER", "on", f"{total:.1f}", log=work / "bench_bcm.log"),
        BASELINE: spawn("--raw-bcm", f"{total:.1f}", log=work / "raw_bcm.log"),
        "python-can thread": spawn("--thread", f"{total:.1f}", log=work / "thread.log"),
    }
    try:
        for name, process in senders.items():
            if process.wait(total + 120) != 0:
                raise RuntimeError(f"sender {name!r} failed; its log is in {work}")
        receiver.wait(60)
    finally:
        for process in (*senders.values(), receiver, load):
            if process is not None and process.poll() is None:
                process.send_signal(signal.SIGINT)
                try:
                    process.wait(30)
                except subprocess.TimeoutExpired:
                    process.kill()
    raw = json.loads(frames_file.read_text())
    frames = {int(k): [tuple(f) for f in v] for k, v in raw.items()}
    analysis = {kind: analyse(frames, cycles[kind], t_start) for kind in KINDS}
    stations = {}
    for kind, log in (("tick scheduler", "tick.log"), ("bench + BCM", "bench_bcm.log"), (BASELINE, "raw_bcm.log"),
                      ("python-can thread", "thread.log")):
        lines = [line for line in (work / log).read_text().splitlines() if line.startswith("{")]
        stations[kind] = json.loads(lines[-1]) if lines else {}
    plant_status = []
    if load is not None:
        plant_status = [line for line in (work / "plant.log").read_text().splitlines() if "max lag" in line][-1:]
    result.details.update(seconds=seconds, warmup_s=WARMUP_S, channel=CHANNEL, load="bench plant" if load else "none",
                          plant_status=plant_status, stations=stations, analysis=analysis, uname=" ".join(os.uname()),
                          loadavg=_loadavg(), date=time.strftime("%Y-%m-%d %H:%M:%S %Z"))
    base = analysis[BASELINE]["overall"]
    for kind in ("tick scheduler", "bench + BCM", "python-can thread"):
        o = analysis[kind]["overall"]
        for stat in ("p50", "p99", "max"):
            result.add(f"{kind}: period error {stat}", o[stat], "ms", base[stat], BASELINE,
                       note=(f"{o['n']} intervals, lost {analysis[kind]['lost']} (baseline: "
                             f"{base['n']} intervals, lost {analysis[BASELINE]['lost']}); "
                             f"{json.dumps(stations.get(kind, {}))}" if stat == "max" else ""))
    print(f"load: {result.details['load']} {' '.join(plant_status)}")


def _loadavg() -> str:
    """The load of the machine the benchmark sees (in a guest: the guest's)."""
    try:
        return Path("/proc/loadavg").read_text().strip()
    except OSError:
        return "unknown"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-load", action="store_true", help="without bench plant as load on the bus")


if __name__ == "__main__":
    argv = sys.argv[1:]
    if argv and argv[0] == "--station":
        run_station(argv[1], argv[2] == "on", float(argv[3]))
    elif argv and argv[0] == "--raw-bcm":
        run_raw_bcm(float(argv[1]))
    elif argv and argv[0] == "--thread":
        run_thread(float(argv[1]))
    elif argv and argv[0] == "--receive":
        run_receiver([int(i) for i in argv[3:]], float(argv[2]), Path(argv[1]))
    else:
        raise SystemExit(common.main("periodic_vcan", "Periodic sending on vcan0: kernel BCM against the tick "
                                     "scheduler", measure, configure, __doc__))
