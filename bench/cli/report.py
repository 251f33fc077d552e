"""`bench report`: work on finished report folders: merge shards' folders into one (`merge`), and record
the case durations the shards are balanced by (`durations`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from rich.console import Console

from bench.cli.common import check_out_dir
from bench.errors import ConfigError
from bench.pytest.shard import DURATIONS_NAME
from bench.report.merge import LOGS_NAME, merge
from bench.results import store as results_io
from bench.run import RESULTS_NAME


def register(sub: Any) -> None:
    parser = sub.add_parser("report", help="merge shards' report folders; record case durations",
                            description=__doc__)
    actions = parser.add_subparsers(dest="report_command", required=True, metavar="ACTION")
    join = actions.add_parser(
        "merge", help="merge the report folders of `bench run --shard K/N` into one",
        description="Check that the folders are the N shards of one campaign (same shard count, bench version, "
                    "databases, durations file and selection; each case in exactly one shard), then write one "
                    "report.html, junit.xml and results.json rendered from all their cases, the shards' MCAP logs "
                    f"under shards/K/ and their index {LOGS_NAME} (`bench log info` reads it).")
    join.add_argument("folders", nargs="+", type=Path, metavar="DIR", help="the shards' report folders")
    join.add_argument("--out", required=True, type=Path, help="the merged report folder")
    join.add_argument("--force", "--overwrite", action="store_true",
                      help="write into an existing --out folder that is not empty")
    join.set_defaults(handler=merge_handler)
    durations = actions.add_parser(
        "durations", help="write the case durations of report folders as the shards' durations file",
        description="Each case's wall time from the folders' results.json (later folders win), as pytest-split's "
                    f"JSON (case id -> seconds); by default into {DURATIONS_NAME} next to bench.toml.")
    durations.add_argument("folders", nargs="+", type=Path, metavar="DIR", help="report folders of full runs")
    durations.add_argument("--output", "-o", type=Path, required=True, help="the durations file to write")
    durations.set_defaults(handler=durations_handler)


def merge_handler(args: argparse.Namespace) -> int:
    for folder in args.folders:
        if folder.resolve() == args.out.resolve():
            raise ConfigError(f"--out {args.out}: is one of the shards' folders")
    check_out_dir(args.out, args.force)
    result = merge(list(args.folders), args.out)
    counts = ", ".join(f"{n} {k}" for k, n in result.counts.items() if n)
    Console().print(f"bench report merge: {len(args.folders)} shards, {len(result.cases)} cases ({counts}): "
                    f"{result.verdict}; report: {args.out}", highlight=False)
    return {"PASS": 0, "INCONCLUSIVE": 3}.get(result.verdict, 1)   # as `bench run` (bench.cli.run.EXIT_INCONCLUSIVE)


def durations_handler(args: argparse.Namespace) -> int:
    durations: dict[str, float] = {}
    for folder in args.folders:
        path = folder / RESULTS_NAME
        if not path.is_file():
            raise ConfigError(f"{folder}: no {RESULTS_NAME} (not a bench report folder)")
        for case in results_io.load(path).cases:
            if case.outcome != "aborted":
                durations[case.nodeid] = round(case.wall_time, 3)
    args.output.write_text(json.dumps(durations, indent=1, sort_keys=True) + "\n")
    Console(stderr=True).print(f"bench report durations: {len(durations)} cases to {args.output}", highlight=False)
    return 0
