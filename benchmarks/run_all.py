"""Every benchmark of issue 9, each with its baseline measured in the same run, on this machine.

    python benchmarks/run_all.py [--quick] [--json PATH] [--only NAME ...]

Runs each benchmark in its own process (benchmarks/bench_*.py), one after the other, and prints the machine
(CPU model, cores, Python, package versions, load average) and every figure next to its baseline and target.
The full run takes about 15 minutes (10 of them the memory soak) and is what docs/performance.md records;
--quick shortens each (about 2 minutes: a smoke run, e.g. for CI; its figures are not the recorded ones).
Logs and reports of each benchmark are kept under --work (default: a new temporary folder).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import common

#: name -> (script, what it measures); in the order they run (CPU-bound first, the long soak last)
BENCHMARKS = {
    "receive_path": ("bench_receive_path.py", "target 2: receive path frames/s"),
    "virtual_time": ("bench_virtual_time.py", "target 1: virtual-time campaign"),
    "scale_out": ("bench_scale_out.py", "target 6: bench run -n 2"),
    "loop_latency": ("bench_loop_latency.py", "target 4: command → status latency"),
    "periodic_udp": ("bench_periodic_udp.py", "target 3: periodic sending on udp_multicast"),
    "memory": ("bench_memory.py", "target 5: memory over a real-time soak"),
}
TIMEOUT_S = {"memory": 1200, "periodic_udp": 400}


def run_one(name: str, quick: bool, work: Path) -> dict:
    script, what = BENCHMARKS[name]
    out_json, log = work / f"{name}.json", work / f"{name}.log"
    argv = [sys.executable, str(common.BENCHMARKS / script), "--json", str(out_json), "--work", str(work / name)]
    if quick:
        argv.append("--quick")
    print(f"-- {name}: {what} ... ", end="", flush=True)
    t0 = time.perf_counter()
    with open(log, "w") as f:
        try:
            code = subprocess.run(argv, cwd=common.ROOT, stdout=f, stderr=subprocess.STDOUT,
                                  timeout=TIMEOUT_S.get(name, 900)).returncode
        except subprocess.TimeoutExpired:
            code = -1
    seconds = time.perf_counter() - t0
    print(f"{seconds:.0f} s" + ("" if code == 0 else f" (exit {code}; log {log})"), flush=True)
    if out_json.is_file():
        return json.loads(out_json.read_text())
    return {"benchmark": name, "title": what, "figures": [], "error": f"no figures (exit {code}); see {log}",
            "seconds": seconds}


def print_all(results: list[dict]) -> None:
    for r in results:
        result = common.Result(r["benchmark"], r["title"], quick=r.get("quick", False), seconds=r.get("seconds", 0.0),
                               error=r.get("error", ""), machine=r.get("machine", {}))
        for f in r.get("figures", []):
            f = {k: v for k, v in f.items() if k != "met"}
            result.figures.append(common.Figure(**f))
        print_result_with_load(result)


def print_result_with_load(result: common.Result) -> None:
    common.print_result(result)
    load = result.machine.get("load_average")
    if load:
        print(f"   (load average at start {' / '.join(map(str, load))}, at end "
              f"{' / '.join(map(str, result.machine.get('load_average_end', [])))})")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="shorten every benchmark (a smoke run, ~2 min)")
    parser.add_argument("--json", type=Path, default=None, help="write every figure and the machine as JSON here")
    parser.add_argument("--only", nargs="+", choices=list(BENCHMARKS), default=None, help="run only these")
    parser.add_argument("--work", type=Path, default=None, help="folder for logs and reports (default: temp)")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-benchmarks-"))
    work.mkdir(parents=True, exist_ok=True)
    machine = common.machine()
    print(f"machine: {common.machine_line(machine)}")
    print(f"work folder: {work}{'  (quick: a smoke run, not the recorded figures)' if args.quick else ''}")
    t0 = time.perf_counter()
    results = [run_one(name, args.quick, work) for name in (args.only or BENCHMARKS)]
    total = time.perf_counter() - t0
    print_all(results)
    met = [f for r in results for f in r.get("figures", []) if f.get("met") is not None]
    print(f"\n{sum(1 for f in met if f['met'])} of {len(met)} figures with a target meet it; "
          f"total {total / 60:.1f} min; load average now {' / '.join(map(str, common.load_average()))}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"machine": machine, "quick": args.quick, "total_s": total,
                                         "work": str(work), "benchmarks": results}, indent=1, ensure_ascii=False))
    return 1 if any(r.get("error") for r in results) else 0


if __name__ == "__main__":
    raise SystemExit(main())
