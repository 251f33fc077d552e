"""Target 4: loop latency — a VCU_WheelCmd_xx change shows up in WHL_Status_xx within one cycle plus the servo.

The case benchmarks/cases/test_wheel_steps.py steps all four wheel commands N times (full 24, quick 8). The
latency of each change is what the report's timing section measures (bench/checks/timing.py: from the onset of a
command change by more than the threshold of bench.toml [timing], with the status at rest, to the first
status frame that moved by more than the threshold the same way). Two runs:
  virtual    `bench run <case>` on the embedded default, in this process; the per-wheel figures are read
             from the run's own timing table (finished_run().tables);
  real time  `bench plant --interface udp_multicast` in one process and `bench run --interface udp_multicast
             --external all <case>` in another (hop limit 0), both in real time.
For both, every wheel's events are pooled from the run's MCAP log with the same definition
(bench.checks.timing.follow_latencies) for p50/p99/max over all four wheels.

The bound ("within one cycle plus the servo dynamics"), per change: one WHL_Status cycle (DBC, 10 ms) + one
plant tick (the wheel ECU reads the command frame on the tick after it was sent) + the servo's time to move
the threshold (+ one LSB of the status) after that change's step (first-order lag 50 ms with a 120 °/s rate
limit, plant/vehicles EV4WIS: threshold / rate limit for steps over ~6°, longer for small steps). The p50/p99
are shown next to the bound for steps over 6° (11.4 ms).
On the virtual-time bus every frame has a fixed phase (its id modulo its cycle), so the latency there is
one deterministic number per wheel: the phase difference of status and command, plus the tick.
"""

from __future__ import annotations

import argparse
import bisect
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import common

CASE = common.CASES / "test_wheel_steps.py"
WHEELS = ("FL", "FR", "RL", "RR")


def wheel_pairs() -> list:
    from bench.config import load_config

    return [p for p in load_config().latency if p.command[0].startswith("VCU_WheelCmd_")]


class Servo:
    """The wheel ECU's steering servo as plant/vehicles EV4WIS parameterises it (first-order lag with a rate
    limit): how long it takes to move the threshold after a command step — the "servo dynamics" of the target."""

    def __init__(self) -> None:
        from plant.vehicles import load_parameters

        params = load_parameters("EV4WIS")
        self.tau, self.rate = params.servo_lag, params.servo_rate_limit

    def time_to_move(self, h: float, step: float) -> float:
        """s until the angle has moved h (deg) after a step of `step` deg from rest."""
        step = abs(step)
        knee = self.rate * self.tau                    # error below which the lag, not the rate limit, governs
        if step <= h:
            return float("inf")
        if step - h >= knee:
            return h / self.rate
        if step <= knee:
            return self.tau * math.log(step / (step - h))
        ramp = (step - knee) / self.rate               # at the rate limit down to the knee, then the lag
        return ramp + self.tau * math.log(knee / (knee - (h - (step - knee))))


def pooled_latencies(mcap: Path) -> tuple[dict[str, list[float]], dict[str, list[float]]]:
    """Per wheel pair: the latencies (s) from the logged decoded frames, by bench.checks.timing's definition (its
    LatencyFollower fed in time order as bench.checks.timing.follow_latencies does), and each change's step (deg):
    the latest command minus the status at rest before the change, when the status followed."""
    from bench.checks.timing import LatencyFollower
    from bench.log.logread import read_decoded

    pairs = wheel_pairs()
    wanted = {p.command[0] for p in pairs} | {p.status[0] for p in pairs}
    series: dict[str, tuple[list[float], list[dict]]] = {m: ([], []) for m in wanted}
    for t, message, signals in read_decoded(mcap):
        if message in series:
            series[message][0].append(t)
            series[message][1].append(signals)
    latencies, steps = {}, {}
    for p in pairs:
        tc, vc = series[p.command[0]][0], [v[p.command[1]] for v in series[p.command[0]][1]]
        ts, vs = series[p.status[0]][0], [v[p.status[1]] for v in series[p.status[0]][1]]
        follower = LatencyFollower(p.threshold, p.window)
        step_sizes: list[float] = []
        command = math.nan
        i = j = 0
        while i < len(tc) or j < len(ts):
            if j < len(ts) and (i >= len(tc) or ts[j] <= tc[i]):    # at equal times the status is earlier
                n = len(follower.latencies)
                follower.status(ts[j], vs[j])
                if len(follower.latencies) > n:
                    t0 = ts[j] - follower.latencies[-1]
                    k = bisect.bisect_right(ts, t0 + 1e-9) - 1       # the last status frame at or before the change
                    step_sizes.append(command - vs[k] if k >= 0 else math.nan)
                j += 1
            else:
                follower.command(tc[i], vc[i])
                command = vc[i]
                i += 1
        follower.finish()
        latencies[p.name] = list(follower.latencies)
        latencies[p.name + " (not followed)"] = [float(follower.not_followed)]
        steps[p.name] = step_sizes
    return latencies, steps


def within_bounds(latencies: dict[str, list[float]], steps: dict[str, list[float]]) -> dict:
    """Each followed change against one status cycle + one plant tick + the servo's time to move the threshold
    (plus one LSB of the status signal, for its quantisation) after that change's step."""
    from bench.config import load_config
    from bench.database.codec import load_codebook

    codebook = load_codebook(load_config().databases)
    servo = Servo()
    ok = total = 0
    slack: list[float] = []
    worst: list[tuple[float, str, float, float]] = []
    for pair in wheel_pairs():
        status = codebook[pair.status[0]]
        h = pair.threshold + abs(status.by_name[pair.status[1]].scale)
        for latency, step in zip(latencies.get(pair.name, []), steps.get(pair.name, [])):
            bound = status.cycle_time + 0.001 + servo.time_to_move(h, step)
            total += 1
            ok += latency <= bound + 1e-9
            slack.append(bound - latency)
            worst.append((latency - bound, pair.name, latency, step))
    worst.sort(reverse=True)
    return {"within": ok, "changes": total, "slack_ms": common.summary(slack, 1000.0),
            "worst": [{"pair": w[1], "latency_ms": w[2] * 1000, "step_deg": w[3], "over_bound_ms": w[0] * 1000}
                      for w in worst[:5]]}


def bound_ms() -> tuple[float, str]:
    """The bound for steps over ~6° (where the servo moves the threshold at its rate limit), ms."""
    from bench.config import load_config
    from bench.database.codec import load_codebook

    codebook = load_codebook(load_config().databases)
    servo = Servo()
    pair = wheel_pairs()[0]
    status = codebook[pair.status[0]]
    h = pair.threshold + abs(status.by_name[pair.status[1]].scale)
    move = h / servo.rate
    bound = (status.cycle_time + 0.001 + move) * 1000
    return bound, (f"{status.cycle_time * 1000:g} ms status cycle + 1 ms tick + {move * 1000:.2f} ms servo "
                   f"({h:g}° at {servo.rate:g} °/s)")


def _pool(per_pair: dict[str, list[float]]) -> tuple[list[float], int]:
    pooled = [x for k, v in per_pair.items() if not k.endswith("(not followed)") for x in v]
    not_followed = int(sum(v[0] for k, v in per_pair.items() if k.endswith("(not followed)")))
    return pooled, not_followed


def run_virtual(out: Path, steps: int) -> dict:
    os.environ["BENCH_WHEEL_STEPS"] = str(steps)
    code, run, wall, _ = common.bench_inprocess(["run", "--out", str(out), str(CASE)])
    if run is None:
        raise RuntimeError(f"bench run (virtual) finished no run (exit code {code})")
    table = common.table_rows(run, "Timing: command → status latency")
    per_pair, steps = pooled_latencies(out / "run.mcap")
    return {"exit_code": code, "verdict": run.verdict, "bench_s": run.sim_time, "wall_s": wall,
            "report_table": {"columns": table[0], "rows": table[1]} if table else None,
            "latencies_s": per_pair, "steps_deg": steps}


def run_realtime(out: Path, steps: int) -> dict:
    group = common.random_group()
    env = dict(os.environ, BENCH_WHEEL_STEPS=str(steps))
    plant = subprocess.Popen([sys.executable, "-m", "bench", "plant", "--interface", "udp_multicast", "--channel",
                              group, "--duration", str(60 + 3 * steps)], cwd=common.ROOT, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    try:
        assert plant.stdout is not None
        plant.stdout.readline()                     # "bench plant: simulating ..." once it is up
        wall0 = time.perf_counter()
        runner = subprocess.run([sys.executable, "-m", "bench", "run", "--interface", "udp_multicast", "--channel",
                                 group, "--external", "all", "--out", str(out), str(CASE)], cwd=common.ROOT, env=env,
                                capture_output=True, text=True, timeout=120 + 5 * steps)
        wall = time.perf_counter() - wall0
    finally:
        plant.send_signal(2)                         # SIGINT: the plant stops cleanly
        try:
            plant_out = plant.communicate(timeout=30)[0]
        except subprocess.TimeoutExpired:
            plant.kill()
            plant_out = plant.communicate()[0]
    (out / "runner.log").write_text(runner.stdout + runner.stderr)
    (out / "plant.log").write_text(plant_out)
    per_pair, steps = pooled_latencies(out / "run.mcap")
    lag = [line for line in plant_out.splitlines() if "max lag" in line][-1:]
    return {"exit_code": runner.returncode, "group": group, "wall_s": wall, "latencies_s": per_pair,
            "steps_deg": steps,
            "runner_tail": runner.stdout.splitlines()[-3:], "plant_last_status": lag}


def measure(result: common.Result, args: argparse.Namespace) -> None:
    steps = 8 if args.quick else 24
    bound, bound_text = bound_ms()
    quiet = common.udp_users_at_start()
    result.details["other_udp_multicast"] = quiet
    watch = common.UdpWatch()
    virtual = run_virtual(args.work / "virtual", steps)
    realtime = run_realtime(args.work / "realtime", steps)
    others = watch.stop()
    common.note_udp_users(result, quiet, others)
    result.details.update(steps=steps, bound_ms=bound, bound=bound_text, virtual=virtual, realtime=realtime)
    for label, run in (("virtual time", virtual), ("real time, udp_multicast", realtime)):
        pooled, not_followed = _pool(run["latencies_s"])
        s = common.summary(pooled, 1000.0)
        run["pooled_ms"] = s
        check = run["bounds"] = within_bounds(run["latencies_s"], run["steps_deg"])
        note = (f"{s['n']} changes on 4 wheels, {not_followed} not followed; max {common.fmt(s['max'], 'ms')}; "
                f"case exit code {run['exit_code']}")
        base = "1 cycle + 1 tick + servo, steps ≥ 6°"
        result.add(f"latency p50, {label}", s["p50"], "ms", bound, base, note=note)
        result.add(f"latency p99, {label}", s["p99"], "ms", bound, base)
        share = 100.0 * check["within"] / check["changes"] if check["changes"] else None
        result.add(f"changes within 1 cycle + 1 tick + servo(step), {label}", share, "%", target=100.0,
                   target_op=">=", note=f"{check['within']} of {check['changes']}; smallest margins: "
                   + ", ".join(f"{w['pair']} {w['latency_ms']:.1f} ms after a {w['step_deg']:+.2f}° step "
                               f"(margin {-w['over_bound_ms']:+.1f} ms)" for w in check["worst"][:2]))
        for name, values in run["latencies_s"].items():
            if not name.endswith("(not followed)"):
                per = common.summary(values, 1000.0)
                run.setdefault("per_wheel_ms", {})[name] = per
    result.details["bound_note"] = bound_text


if __name__ == "__main__":
    raise SystemExit(common.main("loop_latency", "Target 4: loop latency VCU_WheelCmd → WHL_Status", measure,
                                 doc=__doc__))
