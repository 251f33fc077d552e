"""Markdown tables from run_all's JSON (what docs/performance.md quotes), so the doc's figures are copied, not typed.

    python benchmarks/run_all.py --json /tmp/perf.json
    python benchmarks/report_md.py /tmp/perf.json > /tmp/perf.md
"""

from __future__ import annotations

import argparse
import collections
import json
from pathlib import Path

import common


def _fig_value(f: dict) -> str:
    return common.fmt(f.get("value"), f.get("unit", ""))


def summary_table(data: dict) -> list[str]:
    out = ["| benchmark | figure | measured | baseline (same run) | target | met |", "|---|---|---|---|---|---|"]
    for r in data["benchmarks"]:
        name = r["benchmark"]
        if r.get("error"):
            out.append(f"| {name} | error: {r['error']} | | | | |")
        for f in r.get("figures", []):
            base = (f"{common.fmt(f.get('baseline'), f.get('unit', ''))} ({f['baseline_name']})"
                    if f.get("baseline_name") else "")
            target = (f"{f['target_op']} {common.fmt(f['target'], f.get('unit', ''))}"
                      if f.get("target") is not None else "")
            met = {None: "", True: "yes", False: "**no**"}[f.get("met")]
            out.append(f"| {name} | {f['name'].strip()} | {_fig_value(f)} | {base} | {target} | {met} |")
    return out


def loads(data: dict) -> list[str]:
    out = ["| benchmark | load average at start (1/5/15 min) | at end | took |", "|---|---|---|---|"]
    for r in data["benchmarks"]:
        m = r.get("machine", {})
        out.append(f"| {r['benchmark']} | {' / '.join(map(str, m.get('load_average', [])))} | "
                   f"{' / '.join(map(str, m.get('load_average_end', [])))} | {r.get('seconds', 0):.0f} s |")
    return out


def by_name(data: dict, name: str) -> dict | None:
    return next((r for r in data["benchmarks"] if r["benchmark"] == name), None)


def campaign_tables(r: dict) -> list[str]:
    cases = r["details"].get("cases", [])
    files: dict[str, list[dict]] = collections.defaultdict(list)
    for c in cases:
        files[c["case"].split("::")[0]].append(c)
    out = ["| file | cases | bench s | wall s | factor | slowest case |", "|---|---|---|---|---|---|"]
    for f, cs in sorted(files.items(), key=lambda kv: -sum(c["wall_s"] for c in kv[1])):
        b, w = sum(c["bench_s"] for c in cs), sum(c["wall_s"] for c in cs)
        slow = min((c["factor"] for c in cs if c["factor"]), default=None)
        out.append(f"| {f} | {len(cs)} | {b:.1f} | {w:.1f} | {b / w:.1f}× | {common.fmt(slow)}× |")
    out += ["", "<details><summary>every case</summary>", "", "| case | outcome | bench s | wall s | factor |",
            "|---|---|---|---|---|"]
    for c in cases:
        out.append(f"| `{c['case']}` | {c['outcome']} | {c['bench_s']:.2f} | {c['wall_s']:.2f} | "
                   f"{common.fmt(c['factor'])}× |")
    out += ["", "</details>"]
    return out


def periodic_table(r: dict) -> list[str]:
    plant, base = r["details"]["plant"]["per_message"], r["details"]["baseline"]["per_message"]
    out = ["| message | cycle ms | bench plant p50 / p99 / max ms | lost | send_periodic p50 / p99 / max ms |",
           "|---|---|---|---|---|"]
    for name, s in plant.items():
        b = base.get(name, {})
        out.append(f"| {name} | {s['cycle_ms']:g} | {s['p50']:.3f} / {s['p99']:.3f} / {s['max']:.2f} | {s['lost']} | "
                   f"{b.get('p50', float('nan')):.3f} / {b.get('p99', float('nan')):.3f} / "
                   f"{b.get('max', float('nan')):.2f} |")
    return out


def latency_table(r: dict) -> list[str]:
    out = ["| pair | virtual n / p50 / p99 / max ms | real time (udp_multicast) n / p50 / p99 / max ms |",
           "|---|---|---|"]
    v, rt = r["details"]["virtual"].get("per_wheel_ms", {}), r["details"]["realtime"].get("per_wheel_ms", {})
    for name in v:
        a, b = v[name], rt.get(name, {})
        out.append(f"| {name} | {a['n']} / {a['p50']:.2f} / {a['p99']:.2f} / {a['max']:.2f} | "
                   f"{b.get('n', 0)} / {b.get('p50', float('nan')):.2f} / {b.get('p99', float('nan')):.2f} / "
                   f"{b.get('max', float('nan')):.2f} |")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("json", type=Path)
    args = parser.parse_args()
    data = json.loads(args.json.read_text())
    lines = [f"Machine: {common.machine_line(data['machine'])}", "", *summary_table(data), "", *loads(data)]
    if (r := by_name(data, "virtual_time")) and r.get("details", {}).get("cases"):
        lines += ["", "### Campaign per file", "", *campaign_tables(r)]
    if (r := by_name(data, "periodic_udp")) and r.get("details", {}).get("plant"):
        lines += ["", "### Period error per message", "", *periodic_table(r)]
    if (r := by_name(data, "loop_latency")) and r.get("details", {}).get("virtual"):
        lines += ["", "### Latency per wheel", "", *latency_table(r)]
    print("\n".join(lines))


if __name__ == "__main__":
    main()
