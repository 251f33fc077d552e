"""Issue 25, acceptance 2: a real-time run against examples/vcu_ecu.py with a CPU hog on every core.

Three processes on one host over udp_multicast (hop limit 0, a random group): `bench plant --external VCU`, the
example VCU, and `bench run --external all --dut VCU` on a selection of cases; beside them, with --hog, one bounded
busy loop per core (`os.cpu_count()`), each ending after --hog-seconds at the latest. At the end it reads the run's
results.json and says, per outcome, how many cases; for every failed case whether the bench's own figures during it
were within their bounds (then the failure is the DUT's) or not (then the rule of docs/reliability.md should have
made it inconclusive: counted as "failed because of the bench", which must be 0).

    python benchmarks/cpu_hog_run.py --hog --out /tmp/hog            # with the hog
    python benchmarks/cpu_hog_run.py --out /tmp/quiet                # the same cases without it

Exit code: 0 when no case failed because of the bench (and, without --hog, every case passed), else 1.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import common
from common import ROOT, Proc

BENCH = [sys.executable, "-m", "bench"]
DEFAULT_CASES = ["testcases/ev4wis/test_steering.py", "testcases/ev4wis/test_bad_requests.py"]
HOG = "import time\nend = time.monotonic() + {seconds}\nwhile time.monotonic() < end:\n    pass\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hog", action="store_true", help="run one bounded busy loop per core beside the bench")
    parser.add_argument("--hog-seconds", type=float, default=120.0, help="each busy loop ends after this at the latest")
    parser.add_argument("--out", type=Path, required=True, help="the run's report folder (must not exist)")
    parser.add_argument("-k", default="", help="pytest -k expression to narrow the cases")
    parser.add_argument("paths", nargs="*", default=DEFAULT_CASES, help=f"cases (default: {' '.join(DEFAULT_CASES)})")
    args = parser.parse_args()
    if args.out.exists():   # bench run would refuse it (exit 2) and the old results.json would be read as this run's
        parser.error(f"--out {args.out}: exists; give a new folder")

    bus = ["--interface", "udp_multicast", "--channel", common.random_group()]
    plant = Proc([*BENCH, "plant", *bus, "--external", "VCU", "--duration", "1800"])
    procs = [plant]
    hogs: list[subprocess.Popen[bytes]] = []
    try:
        plant.wait_for("simulating", 60)
        vcu = Proc([sys.executable, str(ROOT / "examples" / "vcu_ecu.py"), *bus])
        procs.append(vcu)
        vcu.wait_for("running", 60)
        if args.hog:
            hogs = [subprocess.Popen([sys.executable, "-c", HOG.format(seconds=args.hog_seconds)])
                    for _ in range(os.cpu_count() or 2)]
        load0 = os.getloadavg()
        started = time.monotonic()
        run = subprocess.run([*BENCH, "run", *bus, "--external", "all", "--dut", "VCU", "--out", str(args.out),
                              *(["-k", args.k] if args.k else []), *args.paths], cwd=ROOT, capture_output=True,
                             text=True)
        wall = time.monotonic() - started
        load1 = os.getloadavg()
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
        for proc in reversed(procs):
            proc.stop()
    print(run.stdout[-4000:])
    results = args.out / "results.json"
    if run.returncode not in (0, 1, 3) or not results.exists():   # 2: bad input, 4+: no verdicts to count
        print(run.stderr[-3000:])
        return 1
    cases = json.loads(results.read_text())["cases"]
    counts: dict[str, int] = {}
    for case in cases:
        counts[case["outcome"]] = counts.get(case["outcome"], 0) + 1
    late_failures = [c for c in cases if c["outcome"] in ("failed", "error")
                     and any("bound" in line and _over(line) for line in c.get("bench_timing", []))]
    print(f"hog: {'on, ' + str(len(hogs)) + ' busy loops' if args.hog else 'off'}; bench run exit {run.returncode} "
          f"in {wall:.1f} s; load average {load0[0]:.2f} -> {load1[0]:.2f}")
    print("cases: " + ", ".join(f"{n} {k}" for k, n in sorted(counts.items())))
    for case in cases:
        if case["outcome"] != "passed":
            lines = [ln for ln in (case.get("inconclusive") or case.get("message") or "").splitlines() if ln.strip()]
            why = lines[0] if case.get("inconclusive") else (lines[-1] if lines else "")   # an exception's last line
            print(f"  {case['outcome']}: {case['name']}: {why[:300]}")
            for line in case.get("bench_timing", [])[:3]:
                print(f"      {line}")
    behind = [ln.strip() for ln in plant.lines if "watchdog" in ln]
    print(f"bench plant: the watchdog moved it to the wall clock {len(behind)} times"
          + (f" (first: {behind[0]})" if behind else ""))
    print(f"failed because of the bench (a figure past its bound, yet failed): {len(late_failures)}")
    if late_failures:
        return 1
    return 0 if args.hog or counts.get("passed", 0) == len(cases) else 1


def _over(line: str) -> bool:
    """Whether a bench_timing line ("WHAT: late by X ms at T s, bound B ms") is past its bound."""
    try:
        late = float(line.split("late by ", 1)[1].split(" ms", 1)[0])
        bound = float(line.rsplit("bound ", 1)[1].split(" ms", 1)[0])
    except (IndexError, ValueError):
        return False
    return late > bound


if __name__ == "__main__":
    raise SystemExit(main())
