"""Target 1: the full campaign on the embedded default (virtual time) — bench seconds per wall second.

Measured: `bench run --out DIR` (every case of testcases/; --quick: three short files) run in this process
through `bench.cli.main`, figures from `bench.pytest.plugin.finished_run()`: per test case bench time / wall
time, the cases together, the run (from the bus opening to the end of the last case) and the whole command
(collection, start-up, report writing). The run's MCAP summary proves every frame was logged and every
valid one decoded (counts of /can/frames and /can/decoded/* against the monitor's frame count).

Baselines in the same run, the same scenario each (EV4WIS, PIVOT about (5, 2) m at 1 m/s, S s of bench time),
layer by layer, to show what each layer costs:
  B0  the bare plant tick loop: the vehicle's behaviours stepped every 1 ms on a dict-backed NodeIO (as
      tests/plant/test_plant_ev.py's Rig does) — no bus, no frames, no checks, no log;
  B1  a bench session on the virtual-time bus without a log: plant + restbus (encode, E2E) + both stations'
      monitors (decode, checks, history) + the tick loop;
  B2  B1 plus the run's log and timing collector (bench.run.BenchRun, as a campaign runs), without pytest.
Target (issue 9): >= 50x real time for the campaign, every frame logged and decoded.

The plant's floor: the campaign once more, with the CPU time (this thread's) of every `step` of the plant's
behaviours counted (its bus I/O calls, io.latest and io.send_values, included, and the counting wrapper's own
call; the cost of one clock read per step, calibrated here, subtracted). Bench time over that CPU is the
campaign's bench seconds per CPU-second if the bench itself, the test cases and the log cost nothing: no change
outside the plant can take the campaign past it.
A run of its own, so the headline figures above carry no counting overhead.
"""

from __future__ import annotations

import argparse
import math
import resource
import time
from pathlib import Path
from typing import Any

import common

from bench.sim.testing import MemoryIO

TARGET = 50.0
QUICK_PATHS = ["testcases/ev4wis/test_uturn.py", "testcases/sbw/test_step.py", "testcases/ev4wis/test_ackermann.py"]
PIVOT = {"DriveMode": "PIVOT", "PivotX": 5.0, "PivotY": 2.0, "TargetSpeed": 1.0}


def bare_plant(seconds: float, vehicle: str = "EV4WIS") -> dict[str, float]:
    """B0: the plant's behaviours (bench.plants entry point) stepped on a MemoryIO; EV4WIS gets a PIVOT request,
    other vehicles their stimulus start values (their models step the same equations every tick)."""
    from bench.config import load_config
    from bench.database.codec import load_codebook
    from bench.plugins import load_plant

    project = load_config()
    codebook = load_codebook(project.databases)
    behaviours = load_plant(project.plant)(set(project.stimulus), vehicle)
    values: dict[str, dict[str, float]] = {}
    for codec in codebook.sent_by(project.stimulus):      # the stimulus at its start values, then the request
        values[codec.name] = dict(codec.start_values())
    control = codebook["BENCH_Control"]
    values["BENCH_Control"]["Vehicle"] = control.physical("Vehicle", vehicle)
    if vehicle == "EV4WIS":
        motion = codebook["DRV_MotionRequest"]
        values["DRV_MotionRequest"].update({k: motion.physical(k, v) for k, v in PIVOT.items()})
    io = MemoryIO()
    io.values = values
    dt, ticks = 0.001, round(seconds / 0.001)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for tick in range(1, ticks + 1):
        io.t = t = tick * dt
        for behaviour in behaviours:
            behaviour.step(io, t, dt)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    speed = values.get("PLANT_Motion", {}).get("Speed", math.nan)
    return {"bench_s": seconds, "wall_s": wall, "cpu_s": cpu, "ticks": ticks, "us_per_tick": wall / ticks * 1e6,
            "plant_speed_at_end": speed}


def _scenario(case, seconds: float) -> None:
    case.start_scenario(Vehicle="EV4WIS")
    case.set("DRV_MotionRequest", **PIVOT)


def session_no_log(seconds: float) -> dict[str, float]:
    """B1: a BenchSession on the virtual-time bus, no sink (no log, no timing collector)."""
    from bench.case import Case
    from bench.checks.steps import StepLog
    from bench.config import RunSettings, load_config
    from bench.results.model import CaseResult
    from bench.session import BenchSession

    session = BenchSession(load_config(), RunSettings())
    session.start()
    case = Case(session, CaseResult(nodeid="B1", name="B1", outcome="passed"), StepLog(session.now))
    _scenario(case, seconds)
    frames0, t0 = session.monitor.frames, session.now()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    case.run(seconds)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    frames = session.monitor.frames - frames0
    bench_s = session.now() - t0
    session.close()
    return {"bench_s": bench_s, "wall_s": wall, "cpu_s": cpu, "frames": frames}


def run_with_log(seconds: float, out: Path) -> dict[str, float]:
    """B2: bench.run.BenchRun (the run's log and timing collector), one scenario, no pytest."""
    from bench.config import RunSettings, load_config
    from bench.run import BenchRun

    run = BenchRun(load_config(), RunSettings(), out)
    run.start()
    case = run.begin_case("B2", "B2")
    _scenario(case, seconds)
    session = run.session
    frames0, t0 = session.monitor.frames, session.now()
    wall0, cpu0, main0 = time.perf_counter(), common.cpu_seconds(), time.process_time()
    children0 = _children_cpu()
    case.run(seconds)
    wall, cpu_main = time.perf_counter() - wall0, time.process_time() - main0
    frames = session.monitor.frames - frames0
    bench_s = session.now() - t0
    case.close()
    finish0 = time.perf_counter()
    run.finish()
    finish = time.perf_counter() - finish0
    cpu = common.cpu_seconds() - cpu0   # includes a log process, waited for by finish()
    log_cpu = _children_cpu() - children0   # the log process, start (imports, databases) included
    return {"bench_s": bench_s, "wall_s": wall, "cpu_s": cpu_main, "cpu_s_incl_finish_and_log_process": cpu,
            "log_process_cpu_s": log_cpu, "frames": frames, "finish_s": finish}


def plant_floor(out: Path, paths: list[str]) -> dict[str, float]:
    """The campaign with the plant's CPU counted (module docstring): bench s, the plant's CPU s, ticks."""
    import bench.session as session_module

    spent = [0.0, 0]
    clock = time.thread_time
    original = session_module.load_plant

    class Counted:
        """A behaviour whose steps' CPU time is counted; everything else is the behaviour's own (a compiled
        behaviour takes no instance attribute in place of its step, so it is wrapped, not patched)."""

        def __init__(self, behaviour: Any) -> None:
            self._behaviour = behaviour
            self._step = behaviour.step

        def __getattr__(self, name: str) -> Any:
            return getattr(self._behaviour, name)

        def step(self, io: Any, t: float, dt: float) -> None:
            start = clock()
            self._step(io, t, dt)
            spent[0] += clock() - start
            spent[1] += 1

    def counting_factory(name: str) -> Any:
        factory = original(name)

        def build(*args: Any, **kwargs: Any) -> Any:
            return [Counted(behaviour) for behaviour in factory(*args, **kwargs)]
        return build

    session_module.load_plant = counting_factory
    try:
        code, run, _, _ = common.bench_inprocess(["run", "--out", str(out), *paths])
    finally:
        session_module.load_plant = original
    if run is None:
        raise RuntimeError(f"bench run (plant floor) finished no run (exit code {code})")
    calls = 200_000
    start = clock()
    for _ in range(calls):
        clock()
    per_read = (clock() - start) / (calls + 1)
    return {"bench_s": run.sim_time, "plant_cpu_s_raw": spent[0], "steps": spent[1], "clock_read_s": per_read,
            "plant_cpu_s": spent[0] - spent[1] * per_read, "verdict_passed": run.counts.get("passed", 0)}


def _children_cpu() -> float:
    """CPU seconds of this process's waited-for children (the run's log process once finish() waited)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def mcap_counts(path: Path) -> dict[str, int]:
    """Messages per topic kind from the MCAP summary (no need to read the file through)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        return {}
    topics = {c.id: c.topic for c in summary.channels.values()}
    out = {"frames": 0, "decoded": 0, "steps": 0}
    for channel, count in summary.statistics.channel_message_counts.items():
        topic = topics.get(channel, "")
        key = "frames" if topic == "/can/frames" else "decoded" if topic.startswith("/can/decoded/") else "steps"
        out[key] += count
    return out


def measure(result: common.Result, args: argparse.Namespace) -> None:
    from bench import compiled

    seconds = 5.0 if args.quick else 10.0
    running = 0 if compiled.from_source() else len(compiled.modules())
    result.add("modules of bench/ and plant/ running compiled", running, "modules",
               note=f"the bench's core: {compiled.status()} (BENCH_COMPILED=0: the same source as Python)")
    b0 = bare_plant(seconds)
    vehicles = {v: bare_plant(seconds / 2, v) for v in ("EV4WIS", "ACLASS", "ACLASS_ABS")}
    result.details["bare_plant_per_vehicle"] = vehicles
    b1 = session_no_log(seconds)
    b2 = run_with_log(seconds, args.work / "b2")
    result.details["baselines"] = {"B0_bare_plant": b0, "B1_session_no_log": b1, "B2_run_with_log": b2}

    out = args.work / "campaign"
    argv = ["run", "--out", str(out), *((str(common.ROOT / p) for p in QUICK_PATHS) if args.quick else ())]
    load = common.load_average()
    code, run, wall, cpu = common.bench_inprocess(argv)
    if run is None:
        raise RuntimeError(f"bench run finished no run (exit code {code})")
    cases = []
    for case in run.cases:
        factor = case.sim_time / case.wall_time if case.wall_time > 0 else math.nan
        cases.append({"case": case.nodeid, "outcome": case.outcome, "bench_s": case.sim_time,
                      "wall_s": case.wall_time, "factor": factor})
    sim_cases = sum(c["bench_s"] for c in cases)
    wall_cases = sum(c["wall_s"] for c in cases)
    counts = mcap_counts(out / "run.mcap")
    logged_all = counts.get("frames") == run.frames and counts.get("decoded") == run.frames - run.invalid_frames
    result.details.update(
        exit_code=code, load_average_before=load, verdict=run.verdict, counts=run.counts, cases=cases,
        campaign={"bench_s": run.sim_time, "run_wall_s": run.wall_time, "command_wall_s": wall,
                  "command_cpu_s_incl_log_process": cpu, "cases_bench_s": sim_cases, "cases_wall_s": wall_cases,
                  "frames": run.frames, "invalid_frames": run.invalid_frames, "mcap": counts,
                  "every_frame_logged_and_decoded": logged_all})

    floor = plant_floor(args.work / "plant_floor", argv[3:])
    result.details["plant_floor"] = floor

    b0f, b1f, b2f = (b["bench_s"] / b["wall_s"] for b in (b0, b1, b2))
    note_b = f"B1 session without log {b1f:.1f}×, B2 with log {b2f:.1f}× (same scenario)"
    result.add("campaign, whole command (bench time / wall time)", run.sim_time / wall, "× real time", b0f,
               "B0 bare plant tick loop, no bus", TARGET, ">=",
               note=f"{run.sim_time:.1f} s bench in {wall:.1f} s wall; {note_b}")
    result.add("campaign, cases only (Σ bench / Σ wall of the cases)", sim_cases / wall_cases, "× real time", b0f,
               "B0 bare plant tick loop, no bus", TARGET, ">=",
               note=f"{len(cases)} cases; without collection, start-up and reports")
    result.add("campaign per CPU-second (incl. the log process)", run.sim_time / cpu, "bench s / CPU-s", b0f,
               "B0 bare plant tick loop, no bus",
               note="load-independent; all the campaign's processes")
    result.add("campaign's plant alone per CPU-second (the floor)", floor["bench_s"] / floor["plant_cpu_s"],
               "bench s / CPU-s", run.sim_time / cpu, "the campaign per CPU-second, all processes",
               note=f"the plant's behaviours took {floor['plant_cpu_s']:.2f} s of CPU over {floor['steps']} steps "
                    f"({floor['plant_cpu_s'] / floor['steps'] * 1e6:.1f} µs each, bus I/O calls included) for "
                    f"{floor['bench_s']:.1f} s of bench time: the bound for the campaign per CPU-second if "
                    "nothing but the plant cost CPU")
    result.add("B0 bare plant tick loop (EV4WIS, no bus)", b0f, "× real time",
               note=f"{b0['us_per_tick']:.1f} µs per 1 ms tick; per CPU-second {b0['bench_s'] / b0['cpu_s']:.1f}×; "
                    "per vehicle (CPU, start values): " + ", ".join(
                        f"{v} {r['cpu_s'] / r['ticks'] * 1e6:.1f} µs/tick = {r['bench_s'] / r['cpu_s']:.0f}×"
                        for v, r in vehicles.items()))
    result.add("B1 session on the virtual bus, no log", b1f, "× real time", b0f, "B0 bare plant tick loop, no bus",
               note=f"{b1['frames'] / b1['bench_s']:.0f} frames per bench s; "
                    f"per CPU-second {b1['bench_s'] / b1['cpu_s']:.1f}×")
    result.add("B2 B1 + the run's log and timing", b2f, "× real time", b1f, "B1 session, no log",
               note=f"CPU per bench second: B0 {b0['cpu_s'] / b0['bench_s'] * 1000:.0f} ms, B1 "
                    f"{b1['cpu_s'] / b1['bench_s'] * 1000:.0f} ms, B2 {b2['cpu_s'] / b2['bench_s'] * 1000:.0f} ms in "
                    f"the run's process (+ its log process: B2 all processes incl. closing "
                    f"{b2['cpu_s_incl_finish_and_log_process'] / b2['bench_s'] * 1000:.0f} ms)")
    result.add("B2's log process, CPU per frame (its start included)", b2["log_process_cpu_s"] / b2["frames"] * 1e6,
               "µs CPU per frame", note=f"{b2['log_process_cpu_s']:.2f} s of CPU for {b2['frames']} frames; its start "
                                        "(interpreter, imports, databases) is about 0.2 s of it")
    factors = sorted(c["factor"] for c in cases if math.isfinite(c["factor"]))
    if factors:
        result.add("per case: median factor", factors[len(factors) // 2], "× real time",
                   note=f"slowest {factors[0]:.1f}×, fastest {factors[-1]:.1f}× (all cases in details)")
    result.add("every frame logged and decoded", 1.0 if logged_all else 0.0, "(1 = yes)", target=1.0,
               target_op=">=", note=f"monitor {run.frames} frames ({run.invalid_frames} invalid); MCAP {counts}")


if __name__ == "__main__":
    raise SystemExit(common.main("virtual_time", "Target 1: virtual-time campaign on the embedded default", measure,
                                 doc=__doc__))
