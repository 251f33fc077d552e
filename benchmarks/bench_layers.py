"""The layers B0, B1, B2 of bench_virtual_time.py, each in a fresh process, alternated between code trees: a
before/after comparison of the frame path under the same load.

    python benchmarks/bench_layers.py --tree /tmp/before --tree . --repeat 3 --seconds 10
    python benchmarks/bench_layers.py --tree /tmp/before --tree . --plant --repeat 5 --seconds 3 [--digest]

Each tree is a copy of the repository (e.g. `git archive COMMIT | tar -x -C /tmp/before`); its own
benchmarks/common.py puts it first on sys.path, so the child imports that tree's bench and plant. Printed per
tree and layer: the median CPU ms per bench second and the median of the ratios to B0 of the same round (the
machine is shared: B0 moves with the load, the ratio less).

`--plant`: B0 (the bare plant tick loop, no bus) per vehicle in a driving scenario each (PLANT_SCENARIOS: the EV in
PIVOT as B0, the EV at speed with ADAPTIVE rear steering, the A-class steering at speed, the A-class braking under ABS),
CPU µs per 1 ms tick, medians and the median ratio to the first tree of the same round. The child for these is this
file's own `plant_tick` (it needs only bench.config, bench.database.codec, bench.plugins and bench.sim.testing, so any
tree runs it). `--digest` prints instead a SHA-256 per scenario of every value the plant sent at every tick (repr of the
floats): a cost cut that keeps the physics' results gives the same digests in every tree.
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
#: per scenario: the coding of its ECUs (docs/contract/diagnostics.md DIAG-COD-01; values as numbers): the 4WS law
#: FEEDBACK, the SBW's combined feedback YAW_RATE_LAT_ACCEL with the default G_r
CODING: dict[str, dict[str, dict[str, float]]] = {
    "EV4WIS_4WS": {"VCU": {"RearSteerLaw": 2}},
    "ACLASS": {"SBW": {"SteeringMode": 2, "IdealYawGain": 0.28}},
}

#: per vehicle scenario: (vehicle, stimulus values by message and signal; enumerations by name)
PLANT_SCENARIOS: dict[str, tuple[str, dict[str, dict[str, float | str]]]] = {
    "EV4WIS": ("EV4WIS", {"DRV_MotionRequest": {"DriveMode": "PIVOT", "PivotX": 5.0, "PivotY": 2.0,
                                                "TargetSpeed": 1.0}}),
    "EV4WIS_4WS": ("EV4WIS", {"BENCH_Control": {"InitialSpeed": 15.0},
                              "DRV_MotionRequest": {"DriveMode": "ADAPTIVE", "TargetSpeed": 15.0},
                              "DRV_Steering": {"HandWheelAngle": 30.0}}),
    "ACLASS": ("ACLASS", {"BENCH_Control": {"InitialSpeed": 20.0},
                          "BENCH_SteeringRobot": {"RobotMode": "ANGLE", "RobotAngle": 45.0}}),
    "ACLASS_ABS": ("ACLASS_ABS", {"BENCH_Control": {"InitialSpeed": 25.0, "SensorNoise": 0.5},
                                  "BENCH_SteeringRobot": {"RobotMode": "ANGLE", "RobotAngle": 30.0},
                                  "DRV_Pedals": {"BrakePressure": 80.0}}),
}


def plant_tick(scenario: str, seconds: float, digest: bool = False) -> dict[str, float | str]:
    """B0 of one scenario in this process: CPU µs per 1 ms tick, or the digest of every value sent."""
    import hashlib
    import time

    from bench.config import load_config
    from bench.database.codec import load_codebook
    from bench.plugins import load_plant
    from bench.sim.testing import CodedSide, MemoryIO

    vehicle, stimulus = PLANT_SCENARIOS[scenario]
    project = load_config()
    codebook = load_codebook(project.databases)
    behaviours = load_plant(project.plant)(set(project.stimulus), vehicle)
    values: dict[str, dict[str, float]] = {c.name: dict(c.start_values()) for c in codebook.sent_by(project.stimulus)}
    values["BENCH_Control"]["Vehicle"] = codebook["BENCH_Control"].physical("Vehicle", vehicle)
    for message, signals in stimulus.items():
        codec = codebook[message]
        values.setdefault(message, {}).update({k: codec.physical(k, v) for k, v in signals.items()})
    io = MemoryIO()
    io.values = values
    io.diagnostic_sides = {node: CodedSide(coding) for node, coding in CODING.get(scenario, {}).items()}
    dt, ticks = 0.001, round(seconds / 0.001)
    sha = hashlib.sha256()
    cpu0 = time.process_time()
    for tick in range(1, ticks + 1):
        io.t = t = tick * dt
        for behaviour in behaviours:
            behaviour.step(io, t, dt)
        if digest:
            sha.update(repr(sorted((m, sorted(v.items())) for m, v in io.sent.items())).encode())
    cpu = time.process_time() - cpu0
    return {"digest": sha.hexdigest()} if digest else {"us_per_tick": cpu / ticks * 1e6}


def plant_main(trees: list[Path], repeat: int, seconds: float, digest: bool) -> int:
    """--plant: the scenarios alternated between the trees, each run in a fresh process."""
    me = str(Path(__file__).resolve())
    runs: dict[tuple[Path, str], list[float]] = {(t, s): [] for t in trees for s in PLANT_SCENARIOS}
    for _ in range(1 if digest else repeat):
        for scenario in PLANT_SCENARIOS:
            for tree in trees:
                argv = [sys.executable, me, "--plant-child", scenario, "--seconds", str(seconds)]
                out = subprocess.run(argv + (["--digest"] if digest else []), cwd=tree, env=_env(tree), check=True,
                                     capture_output=True, text=True).stdout
                result = json.loads(out.strip().splitlines()[-1])
                if digest:
                    print(f"{scenario:12} {result['digest']}  {tree}", flush=True)
                else:
                    runs[(tree, scenario)].append(result["us_per_tick"])
    if digest:
        return 0
    import os

    print(f"\nB0 per vehicle, CPU µs per 1 ms tick, medians of {repeat} (load average now "
          f"{', '.join(f'{x:.1f}' for x in os.getloadavg())})")
    first = trees[0]
    for scenario in PLANT_SCENARIOS:
        cells = []
        for tree in trees:
            us = runs[(tree, scenario)]
            ratio = statistics.median(a / b for a, b in zip(us, runs[(first, scenario)]))
            cells.append(f"{statistics.median(us):6.1f} (×{ratio:.2f})")
        print(f"  {scenario:12} " + "   ".join(cells))
    print("  trees: " + "  ".join(str(t) for t in trees))
    return 0


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
    parser.add_argument("--plant", action="store_true", help="B0 per vehicle scenario (module docstring)")
    parser.add_argument("--digest", action="store_true", help="with --plant: digests of the plant's outputs")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--plant-child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.seconds)))
        return 0
    if args.plant_child:
        print(json.dumps(plant_tick(args.plant_child, args.seconds, args.digest)))
        return 0
    trees = [t.resolve() for t in (args.tree or [Path(__file__).resolve().parent.parent])]
    if args.plant:
        return plant_main(trees, args.repeat, args.seconds, args.digest)
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
