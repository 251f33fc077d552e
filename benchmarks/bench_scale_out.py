"""Target 6: scale-out — the same virtual-time sweep in one process and with `bench run -n 2` (pytest-xdist).

The sweep: benchmarks/cases/test_sweep_rotation_centres.py, N random rotation centres (full 200, quick 40),
each checked against docs/spec/formulas.md §2. Measured: wall time of `bench run -n 2 <sweep>` (two workers, each with
its own embedded bus (in process, virtual time) and MCAP log; the controller merges one report); baseline in the same
run: `bench run <sweep>` (one process, no xdist). Speed-up = baseline wall / measured wall (the whole
command: start-up, the cases, the reports); with --repeat N the pairs run back to back N times and the median
pair's ratio is reported. With --with-n1 also `-n 1` (the cost of xdist itself).
Target (issue 9): >= 1.7x on this machine's 2 cores.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import IO

import common

CASE = common.CASES / "test_sweep_rotation_centres.py"
TARGET = 1.7
PROGRESS = re.compile(r"^\[\s*\d+/\d+\] ")   # bench run's line per case: [  3/200] passed  ...


def has_workers_option() -> bool:
    out = subprocess.run([sys.executable, "-m", "bench", "run", "--help"], capture_output=True, text=True,
                         cwd=common.ROOT).stdout
    return "-n N" in out


def one_run(out: Path, n: int, workers: str | None) -> dict:
    env = dict(os.environ, BENCH_SWEEP_N=str(n))
    argv = [sys.executable, "-m", "bench", "run", "--out", str(out), *(["-n", workers] if workers else []), str(CASE)]
    load = common.load_average()
    wall0, cpu0 = time.perf_counter(), common.cpu_seconds()
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.parent / f"{out.name}.log", "w") as log:   # beside: bench run wants an empty or new --out
        proc = subprocess.Popen(argv, cwd=common.ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        lines = _Lines(proc, log, wall0)
        roles = common.ProcessCpu(proc.pid)
        while proc.poll() is None and time.perf_counter() - wall0 < 1800:
            roles.sample()
            time.sleep(0.25)
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        lines.join()
    wall, cpu = time.perf_counter() - wall0, common.cpu_seconds() - cpu0
    tests = failures = errors = 0
    bench_s = None
    junit = out / "junit.xml"
    if junit.is_file():
        root = ET.parse(junit).getroot()
        tests, failures, errors = (int(root.get(k, 0)) for k in ("tests", "failures", "errors"))
        for prop in root.iter("property"):
            if prop.get("name") == "bench_time":
                bench_s = float(prop.get("value"))
    return {"workers": workers or "none (one process)", "exit_code": proc.returncode, "wall_s": wall,
            "cpu_s_all_processes": cpu, "cpu_s_by_role": roles.by_role(), "cases": tests, "failures": failures,
            "errors": errors, "bench_s": bench_s, "phases_s": lines.phases(wall),
            "mcap_logs": sorted(p.name for p in out.glob("*.mcap")), "load_before": load}


class _Lines(threading.Thread):
    """Copies the run's console to its log and notes when the case lines came: the phases of a run's wall time
    (start until the first case's line, cases, and the tail after the last one: merge, reports, exit)."""

    def __init__(self, proc: subprocess.Popen, log: IO[str], wall0: float) -> None:
        super().__init__(daemon=True)
        self.proc, self.log, self.wall0 = proc, log, wall0
        self.case_lines: list[float] = []
        self.start()

    def run(self) -> None:
        assert self.proc.stdout is not None
        for raw in self.proc.stdout:
            line = raw.decode(errors="replace")
            self.log.write(line)
            if PROGRESS.match(line):
                self.case_lines.append(time.perf_counter() - self.wall0)

    def phases(self, wall: float) -> dict[str, float]:
        if not self.case_lines:
            return {}
        first, last = self.case_lines[0], self.case_lines[-1]
        return {"until the first case's line": round(first, 2), "first to last case line": round(last - first, 2),
                "after the last case line (merge, reports, exit)": round(wall - last, 2)}


def measure(result: common.Result, args: argparse.Namespace) -> None:
    if args.schedule:
        replay_schedules(result, args.schedule)
        return
    if not has_workers_option():
        result.error = "bench run has no -n option (pytest-xdist scale-out not available in this version)"
        return
    n = 40 if args.quick else 200
    pairs = []   # one process then -n 2, back to back, --repeat times: the shared machine's load moves
    for i in range(args.repeat):
        pairs.append((one_run(args.work / f"single{i}", n, None), one_run(args.work / f"n2_{i}", n, "2")))
    ratios = sorted(a["wall_s"] / b["wall_s"] for a, b in pairs)
    single, parallel = _median_run([a for a, _ in pairs]), _median_run([b for _, b in pairs])
    runs = {"single": single, "n2": parallel}
    if args.repeat > 1:
        result.details["pairs"] = [{"single_wall_s": a["wall_s"], "n2_wall_s": b["wall_s"],
                                    "load_before": (a["load_before"], b["load_before"]),
                                    "speedup": a["wall_s"] / b["wall_s"],
                                    "cpu_s": (a["cpu_s_all_processes"], b["cpu_s_all_processes"]),
                                    "phases_s": (a["phases_s"], b["phases_s"])} for a, b in pairs]
    if args.with_n1:
        runs["n1"] = one_run(args.work / "n1", n, "1")
    result.details.update(centres=n, runs=runs)
    for label, run in runs.items():
        if run["exit_code"] != 0 or run["cases"] != n:
            result.details.setdefault("problems", []).append(
                f"{label}: exit {run['exit_code']}, {run['cases']} cases, {run['failures']} failed, "
                f"{run['errors']} errors")
    speedup = ratios[len(ratios) // 2]   # the median pair's ratio
    result.add("sweep wall time, bench run -n 2", parallel["wall_s"], "s", single["wall_s"],
               "bench run, one process",
               note=f"{n} centres; logs {', '.join(parallel['mcap_logs'])}; "
                    f"CPU {parallel['cpu_s_all_processes']:.0f} s "
                    f"vs {single['cpu_s_all_processes']:.0f} s")
    cores = common.machine()["usable_cores"] or 1
    busy = single["cpu_s_all_processes"] / single["wall_s"]
    roles = single["cpu_s_by_role"]
    main_cpu = roles.get("bench run (pytest, bus, plant, monitors)", 0.0)
    demand = (single["cpu_s_all_processes"] / main_cpu) if main_cpu else float("nan")
    result.add("speed-up on 2 cores (one process / -n 2)", speedup, "×", 1.0, "one process", TARGET, ">=",
               note=f"cores busy: one process {busy:.2f}, "
                    f"-n 2 {parallel['cpu_s_all_processes'] / parallel['wall_s']:.2f} "
                    f"(what the machine gave us); CPU -n 2 / one process "
                    f"{parallel['cpu_s_all_processes'] / single['cpu_s_all_processes']:.2f}")
    result.add("cores one run wants (its CPU / its main process's CPU)", demand, "cores",
               note="the log process works beside the run: CPU by role "
                    f"{', '.join(f'{k} {v:.1f} s' for k, v in roles.items())}; "
                    f"so {cores} cores allow at most ~{cores / demand:.2f}× over one run, on an otherwise idle machine")
    for label, run in runs.items():
        phases = run["phases_s"]
        if phases:
            result.add(f"tail of the median run, {label}", phases["after the last case line (merge, reports, exit)"],
                       "s", note="; ".join(f"{k} {v:.2f} s" for k, v in phases.items()))
    if "n1" in runs:
        result.add("sweep wall time, bench run -n 1 (xdist overhead)", runs["n1"]["wall_s"], "s", single["wall_s"],
                   "bench run, one process")
    if single.get("bench_s"):
        result.add("sweep, one process: bench time / wall time", single["bench_s"] / single["wall_s"], "× real time")
        result.add("sweep, -n 2: bench time / wall time", (parallel["bench_s"] or 0) / parallel["wall_s"],
                   "× real time", single["bench_s"] / single["wall_s"], "one process")


def _median_run(runs: list[dict]) -> dict:
    """The run of median wall time (its CPU and roles go with it)."""
    return sorted(runs, key=lambda run: run["wall_s"])[len(runs) // 2]


class _Node:
    """What pytest-xdist's schedulers talk to: a worker that queues the case indices it is sent."""

    def __init__(self, i: int) -> None:
        self.gateway = type("Gateway", (), {"id": f"gw{i}"})()
        self.shutting_down = False
        self.queue: list[int] = []
        self.steal: list[int] = []

    def send_runtest_some(self, indices: list[int]) -> None:
        self.queue.extend(indices)

    def send_runtest_all(self) -> None:
        raise NotImplementedError

    def send_steal(self, indices: list[int]) -> None:
        self.steal.extend(indices)

    def shutdown(self) -> None:
        self.shutting_down = True


def _makespan(scheduler_class: type, ids: list[str], seconds: list[float], workers: int) -> float:
    """The campaign's cases through one of xdist's own schedulers, each case taking its recorded duration; the
    run ends when the last worker is done (start-up and the merge not counted)."""
    config = argparse.Namespace(option=argparse.Namespace(maxschedchunk=None, tx=["popen"] * workers,
                                                          numprocesses=workers, dist="load"))
    config.getvalue = lambda name: getattr(config.option, name, None)
    config.getoption = config.getvalue
    scheduler = scheduler_class(config)
    nodes = [_Node(i) for i in range(workers)]
    for node in nodes:
        scheduler.add_node(node)
    for node in nodes:
        scheduler.add_node_collection(node, ids)
    scheduler.schedule()
    clock = [0.0] * workers
    while any(node.queue for node in nodes):
        i = min((clock[i] + seconds[n.queue[0]], i) for i, n in enumerate(nodes) if n.queue)[1]
        item = nodes[i].queue.pop(0)
        clock[i] += seconds[item]
        scheduler.mark_test_complete(nodes[i], item, seconds[item])
        for node in nodes:   # a steal request: the victim hands back what it has not started
            if node.steal:
                back = [x for x in node.steal if x in node.queue]
                node.queue = [x for x in node.queue if x not in back]
                node.steal = []
                scheduler.remove_pending_tests_from_node(node, back)
    return max(clock)


def replay_schedules(result: common.Result, durations: Path, workers: int = 2) -> None:
    """How pytest-xdist's --dist modes would share the campaign between two workers, from the recorded case
    durations (pytest-split's .test_durations) in collection order: why `bench run -n` uses worksteal."""
    import contextlib
    import io
    import json

    from xdist.scheduler.load import LoadScheduling
    from xdist.scheduler.worksteal import WorkStealingScheduling

    recorded = json.loads(durations.read_text())
    collected = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
                                "testcases"], cwd=common.ROOT, capture_output=True, text=True).stdout
    ids = [line.strip() for line in collected.splitlines() if "::" in line]
    seconds = [float(recorded.get(i, 0.0)) for i in ids]
    even = sum(seconds) / workers
    result.details.update(cases=len(ids), without_duration=sum(1 for i in ids if i not in recorded),
                          longest={ids[seconds.index(max(seconds))]: max(seconds)})
    for name, cls in (("load", LoadScheduling), ("worksteal", WorkStealingScheduling)):
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):   # their log
            span = _makespan(cls, ids, seconds, workers)
        result.add(f"campaign on {workers} workers, --dist {name}", span, "s", even, "an even split of the "
                   "recorded durations", note=f"{span / even - 1:+.1%} over an even split; {len(ids)} cases")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--with-n1", action="store_true", help="also run with -n 1 (one xdist worker)")
    parser.add_argument("--schedule", type=Path, metavar="DURATIONS", default=None,
                        help="instead of running: replay the campaign's recorded case durations (.test_durations) "
                             "through pytest-xdist's load and worksteal schedulers, 2 workers")
    parser.add_argument("--repeat", type=int, default=1,
                        help="pairs (one process, then -n 2) run back to back; the median pair's ratio is reported")


if __name__ == "__main__":
    raise SystemExit(common.main("scale_out", "Target 6: scale-out with bench run -n 2", measure, configure,
                                 __doc__))
