"""Where the time goes: a py-spy profile (raw/collapsed stacks) summed by component of the bench.

Not part of run_all (py-spy is a developer's tool, not a dependency of the project):

    pip install py-spy
    py-spy record --subprocesses -r 250 -f raw -o /tmp/campaign.txt -- python -m bench run --out /tmp/x
    python benchmarks/profile_breakdown.py /tmp/campaign.txt [--top 25]

Each sample is charged to the innermost frame that belongs to a component (rules below, leaf to root), so
`codec.decode` called by the monitor counts as "monitor", and `io.latest` called by a plant model counts as
"plant's bus I/O", not as "plant". With --subprocesses, samples are also split by process (the run, its log
process, xdist workers). Idle samples (py-spy records only active threads by default) are not counted; py-spy's
idea of "active" is a heuristic, so compare processes by their CPU time (/proc, benchmarks/common.ProcessCpu), and
components within a process by these shares.
"""

from __future__ import annotations

import argparse
import collections
import re
from pathlib import Path

#: (component, path fragment, function name regex or None[, a path fragment that must be further out]);
#: innermost match wins; order matters only between rules that could match the same frame.
RULES: list[tuple[str, ...] | tuple[str, str, str | None]] = [
    ("idle: waiting for the tick's wall-clock deadline (recv timeout, sleep)", "can/", r"recv", "WallClock.wait_until"),
    ("idle: waiting for the tick's wall-clock deadline (recv timeout, sleep)", "bench/sim/clock.py",
     r"WallClock\.wait_until"),
    ("log: mcap writer (records, chunks, indexes)", "mcap/", None, "bench/log/recorder.py"),
    ("log: zstd compression", "zstandard", None, "bench/log/recorder.py"),
    ("log: JSON of decoded values (json module)", "json/", None, "bench/log/recorder.py"),
    ("log: hand-over to the log process (pickle, pipe)", "bench/log/logproc.py", r"LogProcess\."),
    ("log: recorder's own code (frame JSON, checks)", "bench/log/recorder.py", None),
    ("log: log process's own loop (decode again, dispatch)", "bench/log/logproc.py", r"_serve"),
    ("report: HTML, plots (SVG, jinja2)", "bench/report/", None),
    ("report: HTML, plots (SVG, jinja2)", "bench/results/store.py", None),
    ("timing collector (report's timing section)", "bench/checks/timing.py", None),
    ("plant's bus I/O (io.latest, io.send_values)", "bench/sim/station.py", r"_StationIO\."),
    ("monitor: E2E, counter, decode, range, history", "bench/checks/monitor.py", r"Monitor\.on_frame"),
    ("monitor: queries (latest, timed_out, history)", "bench/checks/monitor.py", None),
    ("restbus: values, encode, E2E", "bench/sim/restbus.py", None),
    ("python-can: Message, bus send/recv", "can/", None),
    ("test case code and Case API", "bench/case.py", None),
    ("test case code and Case API", "bench/checks/steps.py", None),
    ("test case code and Case API", "testcases/", None),
    ("test case code and Case API", "benchmarks/cases/", None),
    ("plant models and reference ECUs", "plant/", None),
    ("tick loop and stations (own code)", "bench/sim/station.py", None),
    ("tick loop and stations (own code)", "bench/sim/clock.py", None),
    ("tick loop and stations (own code)", "bench/session.py", None),
    ("pytest, xdist, imports, start-up", "_pytest/", None),
    ("pytest, xdist, imports, start-up", "pluggy/", None),
    ("pytest, xdist, imports, start-up", "xdist/", None),
    ("pytest, xdist, imports, start-up", "execnet/", None),
    ("pytest, xdist, imports, start-up", "<frozen importlib", None),
]
_FRAME = re.compile(r"^(?P<func>.*) \((?P<path>.*?)(?::\d+)?\)$")


def component(frames: list[str]) -> str:
    for i in range(len(frames) - 1, -1, -1):
        m = _FRAME.match(frames[i])
        if not m:
            continue
        path, func = m["path"], m["func"]
        for rule in RULES:
            name, fragment, func_re = rule[:3]
            within = rule[3] if len(rule) > 3 else None
            if (path.startswith(fragment) or "/" + fragment in path or fragment.startswith("<") and fragment in path) \
                    and (func_re is None or re.search(func_re, func)) and \
                    (within is None or any(within in f for f in frames[:i])):
                return name
    return "other (interpreter, libraries)"


def process_of(frames: list[str]) -> str:
    """The innermost `process PID:"cmdline"` frame (py-spy --subprocesses nests children under parents)."""
    procs = [f for f in frames if f.startswith("process ")]
    if not procs:
        return "main"
    inner = procs[-1]
    if "bench.log.logproc" in inner:
        return "log process" + (" (of an xdist worker)" if len(procs) > 2 else "")
    if len(procs) > 1:
        return "child: " + re.sub(r'^process \d+:"?', "", inner)[:50]
    return "main: " + re.sub(r'^process \d+:"?', "", inner)[:50]


def breakdown(path: Path) -> tuple[int, collections.Counter, collections.Counter, collections.Counter]:
    by_component: collections.Counter = collections.Counter()
    by_process: collections.Counter = collections.Counter()
    leaves: collections.Counter = collections.Counter()
    total = 0
    for line in path.read_text().splitlines():
        stack, _, count = line.rpartition(" ")
        if not stack or not count.isdigit():
            continue
        n = int(count)
        frames = stack.split(";")
        total += n
        proc = process_of(frames)
        by_process[proc] += n
        by_component[(proc, component(frames))] += n
        leaf = _FRAME.match(frames[-1])
        leaves[re.sub(r".*site-packages/", "", f"{leaf['path']}:{leaf['func']}") if leaf else frames[-1]] += n
    return total, by_component, by_process, leaves


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("profiles", nargs="+", type=Path, help="py-spy raw output (-f raw)")
    parser.add_argument("--top", type=int, default=20, help="how many hottest leaf functions to list")
    args = parser.parse_args()
    for path in args.profiles:
        total, by_component, by_process, leaves = breakdown(path)
        print(f"== {path}: {total} samples")
        for proc, n in by_process.most_common():
            print(f"  process {proc}: {n / total * 100:.1f} % of the samples (of this process / of all)")
            for (p, name), m in by_component.most_common():
                if p == proc:
                    print(f"    {m / n * 100:5.1f} % / {m / total * 100:5.1f} %  {name}")
        print("  hottest functions (self time):")
        for name, n in leaves.most_common(args.top):
            print(f"    {n / total * 100:5.1f} %  {name}")


if __name__ == "__main__":
    main()
