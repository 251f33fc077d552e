"""RunResult to JSON and back: pytest-xdist workers hand their part of a run to the controller,
which merges the parts into one report."""

from __future__ import annotations

import json
from dataclasses import asdict, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench.results.model import (
    CaseRef,
    CaseResult,
    FaultRecord,
    Finding,
    Plot,
    RequirementInfo,
    RunResult,
    Series,
    Step,
    Table,
)


def dump(run: RunResult, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(dumps(run))
    tmp.replace(path)   # a reader never sees half a file


def dumps(run: RunResult) -> str:
    """The same text as `json.dumps(asdict(run))`, without asdict's deep copy: the encoder asks for each
    dataclass's fields only when it meets one, and writes the plots' float lists itself (asdict copied every
    float one call at a time: 0.2 s of a 200-case run, once per worker and again in the controller).

    One difference: the times of a time plot are written to the microsecond (TIME_DECIMALS). They are bench time
    minus the plot's start, so a virtual run's millisecond ticks came out as 0.0019999999999999983 (19 characters
    for 0.002): 60 % of the file was those times. Rounded, they are the ticks again (a real-time run's wall-clock
    times lose what lies below 1 us, far below a plot's pixel). Measured on 46 campaign cases: 3.76 -> 2.45 MB,
    and the dump 82 -> 62 ms of CPU (short numbers are quicker to write); steps, verdicts and every other value
    as they were (tests/bench/results/test_results_io.py)."""
    return json.dumps(run, default=_fields, allow_nan=True)


#: Decimals of a time plot's x values in results.json: 1 us.
TIME_DECIMALS = 6


def _fields(obj: object) -> dict[str, Any]:
    if isinstance(obj, Plot) and obj.kind == "time":
        out = {f.name: getattr(obj, f.name) for f in fields(obj)}
        out["series"] = [{**_fields(s), "x": np.round(np.asarray(s.x, dtype=float), TIME_DECIMALS).tolist()}
                         for s in obj.series]
        return out
    if is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: getattr(obj, f.name) for f in fields(obj)}
    raise TypeError(f"Object of type {type(obj).__name__} is not JSON serializable")


def load(path: Path) -> RunResult:
    data = json.loads(path.read_text())
    cases = [_case(c) for c in data.pop("cases")]
    tables = [Table(**t) for t in data.pop("tables")]
    # parts written before the contract existed have neither key
    requirements = [RequirementInfo(**_known(RequirementInfo, r)) for r in data.pop("requirements", [])]
    deselected = [CaseRef(**_known(CaseRef, c)) for c in data.pop("deselected", [])]
    faults = [FaultRecord(**_known(FaultRecord, f)) for f in data.pop("faults", [])]
    findings = [Finding(**_known(Finding, f)) for f in data.pop("findings", [])]   # absent in older parts
    return RunResult(**_known(RunResult, data), cases=cases, tables=tables, requirements=requirements,
                     deselected=deselected, faults=faults, findings=findings)


def _case(data: dict[str, Any]) -> CaseResult:
    steps = [Step(**s) for s in data.pop("steps")]
    plots = [Plot(**{**p, "series": [Series(**s) for s in p["series"]]}) for p in data.pop("plots")]
    tables = [Table(**t) for t in data.pop("tables")]
    faults = [FaultRecord(**_known(FaultRecord, f)) for f in data.pop("faults", [])]
    return CaseResult(**_known(CaseResult, data), steps=steps, plots=plots, tables=tables, faults=faults)


def _known(cls: type, data: dict[str, Any]) -> dict[str, Any]:
    names = {f.name for f in fields(cls)}
    return {k: v for k, v in data.items() if k in names}


def merge(parts: list[tuple[str, RunResult]], wall_time: float) -> RunResult:
    """One run from the workers' parts: cases in nodeid order, counts summed, each worker's log listed."""
    first = parts[0][1]
    merged = RunResult(started=min(p.started for _, p in parts), interface=first.interface,
                       channel=first.channel, time_mode=first.time_mode, external=first.external,
                       restbus_only=first.restbus_only, build=first.build,
                       mcap_path=first.mcap_path, aborted=any(p.aborted for _, p in parts), wall_time=wall_time,
                       requirements=first.requirements)
    logs = []
    for worker, part in sorted(parts):
        merged.cases.extend(part.cases)
        for fault in part.faults:   # a command-line fault acts in every worker: one record, frames summed
            same = next((f for f in merged.faults if (f.spec, f.source) == (fault.spec, fault.source)), None)
            if same is None:
                merged.faults.append(FaultRecord(**asdict(fault)))
            else:
                same.frames += fault.frames
        for finding in part.findings:   # the same warning in several workers: one finding, counts summed
            same_finding = next((f for f in merged.findings
                                 if (f.source, f.message) == (finding.source, finding.message)), None)
            if same_finding is None:
                merged.findings.append(Finding(**asdict(finding)))
            else:
                same_finding.count += finding.count
        merged.sim_time += part.sim_time
        merged.frames += part.frames
        merged.invalid_frames += part.invalid_frames
        logs.append([worker, part.mcap_path, str(len(part.cases)), f"{part.sim_time:.1f}", str(part.frames),
                     str(part.invalid_frames)])
        for table in part.tables:
            if table.title.startswith("Databases") and any(t.title == table.title for t in merged.tables):
                continue
            title = table.title if table.title.startswith("Databases") else f"[{worker}] {table.title}"
            merged.tables.append(Table(title, table.columns, table.rows))
    merged.cases.sort(key=lambda c: c.nodeid)
    merged.not_run = sum(part.not_run for _, part in parts)   # shards stopped early (bench report merge)
    ran = {c.nodeid for c in merged.cases}
    seen: set[str] = set()
    for _, part in parts:   # every worker deselects the same cases; none of them ran anywhere
        for ref in part.deselected:
            if ref.nodeid not in ran and ref.nodeid not in seen:
                seen.add(ref.nodeid)
                merged.deselected.append(ref)
    merged.tables.insert(0, Table("Workers: one in-process bus and one MCAP log each",
                                  ["worker", "log", "cases", "bench s", "frames", "invalid"], logs))
    return merged
