"""The layers B0, B1, B2 of bench_virtual_time.py, each in a fresh process, alternated between code trees: a
before/after comparison of the frame path under the same load.

    python benchmarks/bench_layers.py --tree /tmp/before --tree . --repeat 3 --seconds 10

Each tree is a copy of the repository (e.g. `git archive COMMIT | tar -x -C /tmp/before`); its own
benchmarks/common.py puts it first on sys.path, so the child imports that tree's bench and plant. Printed per
tree and layer: the median CPU ms per bench second and the median of the ratios to B0 of the same round (the
machine is shared: B0 moves with the load, the ratio less).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

LAYERS = ("B0", "B1", "B2", "B2all")


def child(layer: str, seconds: float) -> dict[str, float]:
    """One layer in this process (the tree is the one this file lives in)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_virtual_time as bvt

    if layer == "B0":
        r = bvt.bare_plant(seconds)
        return {"B0": r["cpu_s"] / r["bench_s"] * 1000}
    if layer == "B1":
        r = bvt.session_no_log(seconds)
        return {"B1": r["cpu_s"] / r["bench_s"] * 1000}
    with tempfile.TemporaryDirectory() as out:
        r = bvt.run_with_log(seconds, Path(out))
    return {"B2": r["cpu_s"] / r["bench_s"] * 1000,
            "B2all": r["cpu_s_incl_finish_and_log_process"] / r["bench_s"] * 1000}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tree", action="append", type=Path, help="a repository tree (repeatable)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.seconds)))
        return 0
    trees = [t.resolve() for t in (args.tree or [Path(__file__).resolve().parent.parent])]
    runs: dict[Path, list[dict[str, float]]] = {t: [] for t in trees}
    for _ in range(args.repeat):
        for tree in trees:
            figures: dict[str, float] = {}
            for layer in ("B0", "B1", "B2"):
                out = subprocess.run([sys.executable, str(tree / "benchmarks" / "bench_layers.py"), "--child", layer,
                                      "--seconds", str(args.seconds)], cwd=tree, env=_env(tree), check=True,
                                     capture_output=True, text=True).stdout
                figures.update(json.loads(out.strip().splitlines()[-1]))
            runs[tree].append(figures)
            print(tree, {k: round(v, 1) for k, v in figures.items()}, flush=True)
    for tree, rounds in runs.items():
        print(f"\n{tree} (medians of {len(rounds)})")
        for layer in LAYERS:
            ms = statistics.median(r[layer] for r in rounds)
            ratio = statistics.median(r[layer] / r["B0"] for r in rounds)
            print(f"  {layer:6} {ms:7.1f} ms CPU per bench s   {ratio:5.2f} × B0")
    return 0


def _env(tree: Path) -> dict[str, str]:
    import os

    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    return env


if __name__ == "__main__":
    raise SystemExit(main())
