"""Why real-time frames are late: `bench plant` in this process, with its late ticks and the garbage collector's
pauses recorded (a diagnostic for target 3, not part of run_all).

    python benchmarks/diag_plant_ticks.py [--seconds 40] [--channel 239.255.x.y]

A tick is late when it starts more than 0.5 ms after its wall-clock deadline (bench.sim.clock.WallClock.wait_until
is wrapped to see it); the collector's pauses come from gc.callbacks. Prints how many ticks were late, by how
much, every collection of generation 1 and 2, and how many late ticks followed a pause within 20 ms.
"""

from __future__ import annotations

import argparse
import collections
import gc
import time

import common  # noqa: F401 - puts the repository on sys.path

LATE_S = 0.0005


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=40.0)
    parser.add_argument("--channel", default=None, help="multicast group (default: a random 239.255.x.y)")
    args = parser.parse_args()

    from bench.cli import main as bench_main
    from bench.sim.clock import WallClock

    pauses: list[tuple[float, int, float]] = []
    started: dict[str, float] = {}

    def on_gc(phase: str, info: dict) -> None:
        if phase == "start":
            started["t"] = time.perf_counter()
        else:
            pauses.append((time.monotonic(), info["generation"], time.perf_counter() - started["t"]))

    late: list[tuple[float, float]] = []
    original = WallClock.wait_until

    def wait_until(self: WallClock, t: float, stations) -> None:   # type: ignore[no-untyped-def]
        behind = self.now() - t
        if behind > LATE_S:
            late.append((time.monotonic(), behind))
        original(self, t, stations)

    gc.callbacks.append(on_gc)
    WallClock.wait_until = wait_until   # type: ignore[method-assign]
    t0 = time.monotonic()
    try:
        bench_main(["plant", "--interface", "udp_multicast", "--channel", args.channel or common.random_group(),
                    "--duration", str(args.seconds)])
    finally:
        WallClock.wait_until = original   # type: ignore[method-assign]
        gc.callbacks.remove(on_gc)
    ticks = round(args.seconds * 1000)
    bins = collections.Counter()
    for _, behind in late:
        bins[next(label for edge, label in ((0.001, "0.5-1 ms"), (0.002, "1-2 ms"), (0.005, "2-5 ms"),
                                            (0.02, "5-20 ms"), (float("inf"), "> 20 ms")) if behind < edge)] += 1
    print(f"\nlate ticks (> {LATE_S * 1000:g} ms behind): {len(late)} of ~{ticks} ({len(late) / ticks * 100:.2f} %); "
          f"max {max((b for _, b in late), default=0) * 1000:.2f} ms; "
          + ", ".join(f"{k}: {n}" for k, n in sorted(bins.items())))
    for when, generation, pause in pauses:
        if generation >= 1:
            print(f"gc generation {generation} at {when - t0:7.2f} s: {pause * 1000:.2f} ms")
    young = [p for _, g, p in pauses if g == 0]
    print(f"gc generation 0: {len(young)} collections, max {max(young, default=0) * 1000:.2f} ms")
    big = [when for when, _, pause in pauses if pause > 0.0003]
    near = sum(1 for when, _ in late if any(0 <= when - g <= 0.02 for g in big))
    print(f"late ticks within 20 ms after a collection longer than 0.3 ms: {near}")


if __name__ == "__main__":
    main()
