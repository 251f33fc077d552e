"""The bench's own lateness in real time over the example ECUs' campaigns, against the host's floor in the same run.

floor     two processes (one per core) run at the same time the simplest 1 ms loop Python has (sleep to the next
          millisecond, note how late it woke), with the host's steal time (/proc/stat) over them: what any 1 ms loop
          of this host does, the floor under the bench's tick loop.
examples  each example ECU's campaign as tests/external_ecu.py runs it (`bench plant --external NODE`, the example,
          `bench run --external all --dut NODE` over udp_multicast, hop limit 0), without real-time priority
          unless --chrt: the report's table of the bench's own lateness (tick loop, stimuli: "below 2 ms counts as
          0", so a p99 of 0 means under 2 ms), its inconclusive cases, and the steal time over the campaign.

Targets (issue 34): the bench's own frames' lateness p99 <= 1 ms, max <= 5 ms, no inconclusive case.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import common

EXAMPLES = {"SBW": "examples/sbw_ecu.py", "ABS": "examples/abs_ecu.py", "VCU": "examples/vcu_ecu.py"}
SELF_TABLE = "Timing: the bench's own lateness"
P99_TARGET_MS, MAX_TARGET_MS = 1.0, 5.0


def probe(seconds: float) -> None:
    """The floor's loop: print the summary of how late each 1 ms tick woke (ms), as JSON."""
    late: list[float] = []
    start = due = time.monotonic()
    while due - start < seconds:
        due += 0.001
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        late.append(max(0.0, time.monotonic() - due))
    print(json.dumps(common.summary(late, 1000.0)))


def steal() -> tuple[int, int]:
    """(steal ticks, all ticks) of every CPU so far (/proc/stat); (0, 0) where there is none."""
    try:
        fields = [int(x) for x in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    except (OSError, ValueError):
        return 0, 0
    return (fields[7] if len(fields) > 7 else 0), sum(fields[:8])


def steal_share(before: tuple[int, int], after: tuple[int, int]) -> float | None:
    total = after[1] - before[1]
    return None if total <= 0 else 100.0 * (after[0] - before[0]) / total


def floor(seconds: float, chrt: list[str]) -> dict[str, Any]:
    before = steal()
    probes = [subprocess.Popen([*chrt, sys.executable, __file__, "--probe", str(seconds)], stdout=subprocess.PIPE,
                               text=True) for _ in range(os.cpu_count() or 1)]
    loops = [json.loads(p.communicate(timeout=seconds + 60)[0]) for p in probes]
    return {"loops": loops, "steal_percent": steal_share(before, steal())}


def campaign(node: str, work: Path, chrt: list[str], keyword: str | None) -> dict[str, Any]:
    """One example's campaign; the bench's own lateness rows, outcomes and steal time."""
    bus = ["--interface", "udp_multicast", "--channel", common.random_group()]
    bench = [*chrt, sys.executable, "-m", "bench"]
    out = work / node
    shutil.rmtree(out, ignore_errors=True)
    plant = common.Proc([*bench, "plant", *bus, "--external", node, "--duration", "1500"])
    processes = [plant]
    try:
        plant.wait_for("simulating", 60)
        ecu = common.Proc([*chrt, sys.executable, EXAMPLES[node], *bus])
        processes.append(ecu)
        ecu.wait_for("running", 60)
        load, before, wall0 = common.load_average(), steal(), time.perf_counter()
        selection = ["-k", keyword] if keyword else []
        run = subprocess.run([*bench, "run", *bus, "--external", "all", "--dut", node, "--out", str(out), *selection],
                             cwd=common.ROOT, capture_output=True, text=True, timeout=1500)
        wall, stolen = time.perf_counter() - wall0, steal_share(before, steal())
    finally:
        for process in reversed(processes):
            process.stop()
    results = json.loads((out / "results.json").read_text())
    table = next((t for t in results["tables"] if t["title"].startswith(SELF_TABLE)), None)
    if table is None:
        raise RuntimeError(f"{node}: no table {SELF_TABLE!r} in {out / 'results.json'}; exit {run.returncode}")
    rows = {row[0]: dict(zip(table["columns"], row)) for row in table["rows"]}
    outcomes = dict(Counter(case["outcome"] for case in results["cases"]))
    return {"exit": run.returncode, "wall_s": wall, "load_before": load, "steal_percent": stolen,
            "outcomes": outcomes, "rows": rows,
            "inconclusive": [f"{c['name']}: {c.get('inconclusive', '')}" for c in results["cases"]
                             if c["outcome"] == "inconclusive"]}


def number(text: str) -> float | None:
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def measure(result: common.Result, args: argparse.Namespace) -> None:
    chrt = ["chrt", "-f", "50"] if args.chrt else []
    seconds = 15.0 if args.quick else 60.0
    nodes = args.examples or (["ABS"] if args.quick else list(EXAMPLES))
    keyword = "steady" if args.quick else None
    result.details["priority"] = "chrt -f 50" if chrt else "none (SCHED_OTHER, nice 0)"
    host = floor(seconds, chrt)
    result.details["floor"] = host
    worst = max(host["loops"], key=lambda loop: loop["max"])
    note = f"{len(host['loops'])} loops side by side, {seconds:g} s; steal {common.fmt(host['steal_percent'], '%')}"
    result.add("host floor: 1 ms loop lateness p99 (worst loop)", max(lo["p99"] for lo in host["loops"]), "ms",
               note=note)
    result.add("host floor: 1 ms loop lateness max", worst["max"], "ms")
    for node in nodes:
        got = campaign(node, args.work, chrt, keyword)
        result.details[node] = got
        tick = got["rows"].get("tick loop", {})
        sent = [row for name, row in got["rows"].items() if name.startswith("stimulus ")]
        p99 = max([number(tick.get("p99 [ms]")) or 0.0] + [number(r.get("p99 [ms]")) or 0.0 for r in sent])
        top = max([number(tick.get("max [ms]")) or 0.0] + [number(r.get("max [ms]")) or 0.0 for r in sent])
        note = (f"{got['outcomes']}, steal {common.fmt(got['steal_percent'], '%')}, load before "
                f"{got['load_before'][0]}, {got['wall_s']:.0f} s")
        result.add(f"{node} example: bench's own lateness p99 (tick loop, stimuli)", p99, "ms",
                   target=P99_TARGET_MS, target_op="<=", note=note)
        result.add(f"{node} example: bench's own lateness max", top, "ms", worst["max"], "host floor's max",
                   MAX_TARGET_MS, "<=")
        result.add(f"{node} example: inconclusive cases", len(got["inconclusive"]), "", target=0, target_op="<=",
                   note="; ".join(got["inconclusive"])[:400])


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--chrt", action="store_true", help="run every process at chrt -f 50 (the README's advice)")
    parser.add_argument("--examples", nargs="*", choices=sorted(EXAMPLES), help="which examples (default: all)")


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--probe":
        probe(float(sys.argv[2]))
        raise SystemExit(0)
    raise SystemExit(common.main("self_lateness", "The bench's own lateness in real time (issue 34)", measure,
                                 configure, __doc__))
