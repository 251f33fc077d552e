"""E2E protect and check cost per frame: the AUTOSAR Profile 11 path (autosar-e2e, bench.e2e) against the
bench's former protection (CRC-8 in Python, its own receiver), loaded from the git history in the same run.

    python benchmarks/bench_e2e.py [--frames N] [--repeat R] [--before REV]

Each figure is the median CPU time (the thread's) of R passes over N frames of distinct payloads (no cache
helps either side): `protect` writes counter and CRC into a payload; `check` reads a received frame's counter
if its CRC is right and runs the receiver (check status and state machine). The before side is the module
bench/e2e.py as it was at REV (default 90a7bbc, the last tree with it), executed from `git show`; without git
the before figures are left out.
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import subprocess
import sys
import time
import types
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

FRAME_ID = 0x110   # VCU_WheelCmd_FL: DataID 0x110 in dbc/chassis.dbc


def _old_module(rev: str) -> types.ModuleType | None:
    try:
        source = subprocess.run(["git", "show", f"{rev}:bench/e2e.py"], cwd=REPO, capture_output=True, text=True,
                                check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    module = types.ModuleType("bench_e2e_before")
    sys.modules[module.__name__] = module      # dataclasses look their module up
    exec(compile(source, "bench/e2e.py@" + rev, "exec"), module.__dict__)
    return module


def _medians_ns(runs: dict[str, object], n: int, repeat: int) -> dict[str, float]:
    """Median CPU time per frame of each run; the runs take turns, so that a busy host slows them alike."""
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(repeat):
        for name, run in runs.items():
            t0 = time.thread_time_ns()
            run()  # type: ignore[operator]
            times[name].append((time.thread_time_ns() - t0) / n)
    return {name: statistics.median(values) for name, values in times.items()}


def measure(frames: int, repeat: int, rev: str) -> dict[str, float]:
    from bench.database.codec import load_codebook

    codec = load_codebook([REPO / "dbc" / "chassis.dbc"])["VCU_WheelCmd_FL"]
    protection = codec.protection
    assert protection is not None
    rng = random.Random(1)
    payloads = [bytearray(rng.randbytes(8)) for _ in range(frames)]
    from bench.e2e import Receiver

    def new_protect() -> None:
        for k, data in enumerate(payloads):
            protection.protect(data, k)

    new_protect()
    new_frames = [bytes(p) for p in payloads]

    def new_check() -> None:
        rx = Receiver(protection.counter_modulo, protection.max_delta_counter, protection.sm)
        for data in new_frames:
            rx.receive(protection.counter_if_intact(data))

    runs: dict[str, object] = {"after_protect_ns": new_protect, "after_check_ns": new_check}
    old = _old_module(rev)
    if old is not None:
        def old_protect() -> None:
            for k, data in enumerate(payloads):
                old.protect(FRAME_ID, data, k % 16)

        old_protect()
        old_frames = [bytes(p) for p in payloads]

        def old_check() -> None:
            rx = old.Receiver()
            for data in old_frames:
                found = old.counter_if_intact(FRAME_ID, data)
                rx.receive(found is not None, -1 if found is None else found)

        runs.update(before_protect_ns=old_protect, before_check_ns=old_check)
    return _medians_ns(runs, frames, repeat)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=20000)
    parser.add_argument("--repeat", type=int, default=9)
    parser.add_argument("--before", default="90a7bbc", help="the git revision whose bench/e2e.py is the baseline")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()
    figures = measure(args.frames, args.repeat, args.before)
    for what in ("protect", "check"):
        after = figures[f"after_{what}_ns"]
        before = figures.get(f"before_{what}_ns")
        ratio = f", {before / after:.2f}x faster" if before else ""
        base = f"before {before / 1000:.2f} µs, " if before else ""
        print(f"{what}: {base}after {after / 1000:.2f} µs per frame{ratio}")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
