"""Shards' report folders merged into one: JUnit and HTML rendered again from the merged results, and the
shards' MCAP logs copied next to them with an index (logs.json) that the report and `bench log info` read.

Why render again rather than splice files: the report's summaries (verdict, counts, conformance, failures)
are computed from all cases; and the shards are checked against each other first, so that a merged report
never silently lacks or doubles a case. Every problem names the folder it was found in.
"""

from __future__ import annotations

import json
import logging
import shutil
from dataclasses import dataclass
from pathlib import Path

from bench.errors import BenchError, LogError
from bench.pytest.shard import SHARD_NAME, ShardRecord
from bench.results import store as results_io
from bench.results.model import RunResult, Table
from bench.run import RESULTS_NAME, write_reports

log = logging.getLogger(__name__)

LOGS_NAME = "logs.json"      # the index of the merged folder's MCAP logs
LOGS_DIR = "shards"          # shards/K/<the shard's MCAP files>
SHARDS_TITLE = "Shards: one report folder and MCAP log each"
_WORKERS_TITLE = "Workers: one in-process bus and one MCAP log each"   # bench.results.store.merge's table


class MergeError(BenchError):
    """Shard folders that do not make one campaign; `problems` has one line per finding."""

    def __init__(self, problems: list[str]) -> None:
        super().__init__("; ".join(problems))
        self.problems = problems


@dataclass
class Shard:
    folder: Path
    record: ShardRecord
    result: RunResult

    @property
    def label(self) -> str:
        return f"{self.record.shard}/{self.record.of}"


def read_shard(folder: Path) -> Shard:
    """One shard's folder: its shard.json and results.json."""
    if not folder.is_dir():
        raise MergeError([f"{folder}: no such report folder"])
    results, record = folder / RESULTS_NAME, folder / SHARD_NAME
    if not results.is_file():
        raise MergeError([f"{folder}: no {RESULTS_NAME} (not a bench report folder, or a run that did not finish)"])
    if not record.is_file():
        raise MergeError([f"{folder}: no {SHARD_NAME}: not a shard (run it with bench run --shard K/N)"])
    try:
        return Shard(folder, ShardRecord.load(record), results_io.load(results))
    except (ValueError, TypeError, KeyError) as exc:
        raise MergeError([f"{folder}: unreadable {SHARD_NAME} or {RESULTS_NAME}: {exc}"]) from None


def check(shards: list[Shard]) -> list[str]:
    """Why these shards are not one whole campaign (empty: they are)."""
    problems: list[str] = []
    first = shards[0]
    same = (("of", "shard count"), ("bench_version", "bench version"), ("databases", "databases (DBC files)"),
            ("durations", "durations file"), ("selection", "selection (-k, -m, --dut)"))
    for shard in shards[1:]:
        for attribute, what in same:
            mine, theirs = getattr(shard.record, attribute), getattr(first.record, attribute)
            if mine != theirs:
                problems.append(f"{shard.folder}: {what} {_short(mine)} differs from {first.folder}'s "
                                f"{_short(theirs)}")
    if problems:
        return problems      # the rest would only repeat it
    by_k: dict[int, Shard] = {}
    for shard in shards:
        other = by_k.setdefault(shard.record.shard, shard)
        if other is not shard:
            problems.append(f"{shard.folder}: shard {shard.label} again (also {other.folder})")
    missing = [f"{k}/{first.record.of}" for k in range(1, first.record.of + 1) if k not in by_k]
    if missing:
        problems.append(f"shard(s) {', '.join(missing)} missing (given: "
                        f"{', '.join(f'{s.label} {s.folder}' for s in shards)})")
    campaign = _campaign(first.result)
    for shard in shards[1:]:
        theirs = _campaign(shard.result)
        if theirs != campaign:
            extra, lacking = sorted(theirs - campaign), sorted(campaign - theirs)
            problems.append(f"{shard.folder}: another campaign than {first.folder} (" +
                            ", ".join(x for x in (_few("only here", extra), _few("not here", lacking)) if x) + ")")
    ran: dict[str, Path] = {}
    for shard in shards:
        twice: dict[Path, list[str]] = {}
        for case in shard.result.cases:
            where = ran.setdefault(case.nodeid, shard.folder)
            if where != shard.folder:
                twice.setdefault(where, []).append(case.nodeid)
        for where, ids in twice.items():
            problems.append(f"{shard.folder}: {_few(f'cases ran here and in {where}', ids)}")
        lacking = sorted(set(shard.record.selected) - {c.nodeid for c in shard.result.cases})
        if lacking:
            what = "cases given to this shard but not in its results (aborted?)"
            problems.append(f"{shard.folder}: {_few(what, lacking)}")
    return problems


def _campaign(result: RunResult) -> set[str]:
    return {c.nodeid for c in result.cases} | {c.nodeid for c in result.deselected}


def _few(what: str, ids: list[str], shown: int = 3) -> str:
    if not ids:
        return ""
    more = f" and {len(ids) - shown} more" if len(ids) > shown else ""
    return f"{len(ids)} {what}: {', '.join(ids[:shown])}{more}"


def _short(value: object) -> str:
    text = json.dumps(value) if not isinstance(value, str) else value
    return text if len(text) <= 60 else text[:57] + "..."


def merge(folders: list[Path], out: Path) -> RunResult:
    """Check the shards, copy their logs under out/shards/K/, write the merged report.html, junit.xml,
    results.json and logs.json into `out`. Raises MergeError before writing anything when they do not fit."""
    if not folders:
        raise MergeError(["no shard folder given"])
    shards = [read_shard(f) for f in folders]
    problems = check(shards)
    if problems:
        raise MergeError(problems)
    shards.sort(key=lambda s: s.record.shard)
    index: list[dict[str, object]] = []
    parts: list[tuple[str, RunResult]] = []
    for shard in shards:
        target = out / LOGS_DIR / str(shard.record.shard)
        target.mkdir(parents=True, exist_ok=True)
        logs = sorted(shard.folder.glob("*.mcap"))
        for path in logs:
            shutil.copy2(path, target / path.name)
        main_log = shard.result.mcap_path
        shard.result.mcap_path = f"{LOGS_DIR}/{shard.record.shard}/{main_log}" if main_log else ""
        index.append({"shard": shard.label, "folder": str(shard.folder), "cases": len(shard.result.cases),
                      "logs": [f"{LOGS_DIR}/{shard.record.shard}/{p.name}" for p in logs]})
        parts.append((f"shard {shard.label}", shard.result))
        if not logs and shard.result.cases:
            log.warning("%s: no MCAP log in the shard's folder", shard.folder)
    # the shards ran side by side on their machines: the campaign took as long as its slowest shard
    merged = results_io.merge(parts, wall_time=max(s.result.wall_time for s in shards))
    merged.started = min(s.result.started for s in shards)
    merged.mcap_path = LOGS_NAME
    for table in merged.tables:
        if table.title == _WORKERS_TITLE:
            table.title, table.columns = SHARDS_TITLE, ["shard", *table.columns[1:]]
    merged.tables.insert(1, Table("Shards' report folders", ["shard", "folder", "cases"],
                                  [[str(e["shard"]), str(e["folder"]), str(e["cases"])] for e in index]))
    (out / LOGS_NAME).write_text(json.dumps({"logs": index}, indent=1))
    write_reports(merged, out)
    return merged


def log_files(path: Path) -> list[Path]:
    """The MCAP logs behind `path`: a log itself; a merged folder's index (the folder or its logs.json); or a
    report folder's own logs (with -n one per worker). An unreadable index is a LogError naming it."""
    index = path / LOGS_NAME if path.is_dir() else path
    if index.name == LOGS_NAME or index.suffix == ".json":
        try:
            entries = json.loads(index.read_text())["logs"]
            return [index.parent / name for entry in entries for name in entry["logs"]]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise LogError(f"{index}: not a log index ({LOGS_NAME} of bench report merge): {exc}") from None
    if path.is_dir():
        found = sorted(path.glob("*.mcap"))
        if not found:
            raise LogError(f"{path}: no MCAP log in this folder")
        return found
    return [path]
