"""Soak: `bench plant` and `bench run` as two processes over udp_multicast (hop limit 0) in real time.

Measures what a long run must not do: lose frames between the sender's AliveCounter and the log,
grow resident memory, or fall behind (a growing queue shows as a growing lag). Prints a table and,
with --json, the figures as JSON (docs/reliability.md records them).

    python benchmarks/soak.py --seconds 600
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import common  # noqa: E402

from bench.log.logread import read_frames  # noqa: E402


def rss_kib(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def counter_gaps(path: Path) -> tuple[int, int, dict[int, int]]:
    """Frames received from the plant process, and AliveCounter gaps (lost frames) per identifier."""
    last: dict[int, int] = {}
    lost: dict[int, int] = {}
    received = 0
    for frame in read_frames(path):
        if frame.direction != "rx":
            continue
        received += 1
        protection = common.protection_of(frame.arbitration_id)
        counter = protection.counter_of(frame.data)
        if frame.arbitration_id in last:
            gap = common.counter_gap(protection, last[frame.arbitration_id], counter)
            if gap:
                lost[frame.arbitration_id] = lost.get(frame.arbitration_id, 0) + gap
        last[frame.arbitration_id] = counter
    return received, sum(lost.values()), lost


def soak(seconds: float, out: Path, sample_every: float = 5.0) -> dict:
    group = f"239.255.{random.randint(1, 254)}.{random.randint(1, 254)}"
    env = dict(os.environ, BENCH_SOAK_SECONDS=str(seconds))
    plant = subprocess.Popen([sys.executable, "-m", "bench", "plant", "--interface", "udp_multicast", "--channel",
                              group, "--duration", str(seconds + 60)], cwd=ROOT, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    time.sleep(1.0)
    runner = subprocess.Popen([sys.executable, "-m", "bench", "run", str(ROOT / "benchmarks/cases/test_soak.py"),
                               "--interface", "udp_multicast", "--channel", group, "--external", "all", "--out",
                               str(out)], cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              text=True)
    samples: list[tuple[float, int | None, int | None]] = []
    t0 = time.monotonic()
    while runner.poll() is None:
        samples.append((time.monotonic() - t0, rss_kib(plant.pid), rss_kib(runner.pid)))
        time.sleep(sample_every)
    runner_output = runner.stdout.read() if runner.stdout else ""
    plant.send_signal(signal.SIGINT)
    plant_output, _ = plant.communicate(timeout=30)
    received, lost, lost_by_id = counter_gaps(out / "run.mcap")
    steady = [s for s in samples if s[0] >= min(30.0, seconds / 4) and s[1] and s[2]]

    def growth(index: int) -> float:
        if len(steady) < 2:
            return float("nan")
        first, last = steady[0][index], steady[-1][index]
        return (last - first) / first * 100.0

    return {
        "seconds": seconds,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "runner_exit": runner.returncode, "plant_exit": plant.returncode,
        "frames_received_from_plant": received, "frames_lost": lost,
        "lost_by_id": {hex(k): v for k, v in lost_by_id.items()},
        "rss_plant_kib": [s[1] for s in samples], "rss_runner_kib": [s[2] for s in samples],
        "rss_growth_plant_pct": growth(1), "rss_growth_runner_pct": growth(2),
        "steady_from_s": steady[0][0] if steady else None,
        "plant_status": [line for line in plant_output.splitlines() if "max lag" in line][-3:],
        "runner_tail": runner_output.splitlines()[-4:],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="soak-"))
    result = soak(args.seconds, out)
    for key in ("seconds", "machine", "runner_exit", "plant_exit", "frames_received_from_plant", "frames_lost",
                "rss_growth_plant_pct", "rss_growth_runner_pct", "steady_from_s"):
        print(f"{key:28} {result[key]}")
    print("plant status:", *result["plant_status"], sep="\n  ")
    print("rss plant  [KiB]:", result["rss_plant_kib"][:3], "...", result["rss_plant_kib"][-3:])
    print("rss runner [KiB]:", result["rss_runner_kib"][:3], "...", result["rss_runner_kib"][-3:])
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
