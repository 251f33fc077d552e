"""Target 5: resident memory flat (± 10 %) over a 10-minute real-time run (quick: 30 s).

The soak harness (benchmarks/soak.py, reused as it is): `bench plant` and `bench run
benchmarks/cases/test_soak.py` as two processes over udp_multicast (hop limit 0) in real time, every message
at its cycle time, every frame checked and logged; RSS of both processes sampled every 5 s. Growth = last
sample against the first sample of the steady state (from min(30 s, a quarter of the run)): that first
sample is the baseline of this target, measured in the same run. Frames lost (AliveCounter gaps in the
runner's log) are reported with it.
"""

from __future__ import annotations

import argparse
import math
import statistics

import common
import soak

TARGET_PCT = 10.0
SAMPLE_S = 5.0     # soak.py samples RSS every 5 s


def measure(result: common.Result, args: argparse.Namespace) -> None:
    seconds = args.seconds or (30.0 if args.quick else 600.0)
    out = args.work / "soak"
    quiet = common.udp_users_at_start()
    result.details["other_udp_multicast"] = quiet
    watch = common.UdpWatch()
    figures = soak.soak(seconds, out)
    others = watch.stop()
    common.note_udp_users(result, quiet, others)
    steady_from = figures.get("steady_from_s")
    result.details.update(soak=figures, steady_from_s=steady_from)
    for who in ("plant", "runner"):
        samples = [s for s in figures[f"rss_{who}_kib"] if s]
        growth = figures[f"rss_growth_{who}_pct"]
        last = samples[-1] if samples else None
        # soak.py: growth = (last - first) / first of the steady state, so its first sample is:
        first = last / (1 + growth / 100) if last and growth is not None and math.isfinite(growth) else None
        change = abs(growth) if growth is not None and math.isfinite(growth) else None
        result.add(f"{who}: RSS at the end", last / 1024 if last else None, "MiB", first / 1024 if first else None,
                   f"RSS at {steady_from:.0f} s (steady state begins)" if steady_from is not None
                   else "RSS when the steady state begins",
                   note=f"max {common.fmt(max(samples) / 1024 if samples else None, 'MiB')}, median "
                        f"{common.fmt(statistics.median(samples) / 1024 if samples else None, 'MiB')} "
                        f"({len(samples)} samples, 5 s apart)")
        result.add(f"{who}: RSS change (absolute) over the steady state", change, "%",
                   target=TARGET_PCT, target_op="<=",
                   note=f"signed {common.fmt(growth, '%')} (soak.py's figure: last sample, which may fall into "
                        f"the report writing after the case)")
        # Samples are taken every SAMPLE_S from the runner's launch; one taken before `seconds` had passed is
        # certainly inside the case (the case starts after the runner's start-up and lasts `seconds`).
        during = [s for i, s in enumerate(figures[f"rss_{who}_kib"]) if s and i * SAMPLE_S <= seconds]
        if first and len(during) >= 2:
            change_case = (during[-1] - first) / first * 100.0
            result.add(f"{who}: RSS change (absolute) to the last sample in the case", abs(change_case), "%",
                       target=TARGET_PCT, target_op="<=",
                       note=f"signed {common.fmt(change_case, '%')}; {common.fmt(during[-1] / 1024, 'MiB')} at "
                            f"~{(len(during) - 1) * SAMPLE_S:g} s")
        series = [(i * SAMPLE_S, v) for i, v in enumerate(figures[f"rss_{who}_kib"]) if v]
        if len(series) >= 4:
            final = series[-1][1]
            settled = next((t for k, (t, _) in enumerate(series)
                            if all(abs(v - final) <= 0.02 * final for _, v in series[k:])), None)
            half = [v for t, v in series if t >= series[-1][0] / 2]
            result.add(f"{who}: RSS change over the second half of the run",
                       (half[-1] - half[0]) / half[0] * 100.0, "%",
                       note=f"within ±2 % of its final value from {settled:g} s on" if settled is not None else
                            "never within ±2 % of its final value for the rest of the run")
    result.add("frames received from the plant", figures["frames_received_from_plant"], "frames",
               note=f"lost (AliveCounter gaps): {figures['frames_lost']}; runner exit {figures['runner_exit']}, "
                    f"plant exit {figures['plant_exit']}")
    result.add("frames lost", figures["frames_lost"], "frames", target=0, target_op="<=")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seconds", type=float, default=0.0, help="soak duration (default 600; quick 30)")


if __name__ == "__main__":
    raise SystemExit(common.main("memory", "Target 5: memory over a real-time soak", measure, configure, __doc__))
