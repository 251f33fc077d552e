"""One shard of a campaign: `--bench-shard K/N` handed to pytest-split, and the shard's record (shard.json)
that `bench report merge` checks the shards against each other with.

Why pytest-split: it partitions the collected cases deterministically, balanced by recorded durations, and
every machine computes the same partition from the same inputs (cases, durations file, N). So the record
holds those inputs' fingerprints: shards whose inputs differ may overlap or miss cases, and merge says so.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import logging
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from bench import options
from bench import version as bench_version
from bench.config import load_config
from bench.errors import ConfigError

log = logging.getLogger(__name__)

SHARD_NAME = "shard.json"
DURATIONS_NAME = ".test_durations"     # pytest-split's name; kept next to bench.toml
ALGORITHM = "least_duration"           # longest case first into the lightest shard: the best balance


@dataclass
class ShardRecord:
    """What one shard ran and what its partition was computed from."""

    shard: int                          # K, from 1
    of: int                             # N
    bench_version: str
    databases: dict[str, str]           # DBC file name -> sha256 of its bytes
    durations: str                      # sha256 of the durations file ("" when there was none)
    selection: dict[str, Any]           # -k, -m, --bench-dut: what narrowed the campaign before the split
    selected: list[str] = field(default_factory=list)   # the case ids this shard was given

    def dump(self, folder: Path) -> Path:
        path = folder / SHARD_NAME
        path.write_text(json.dumps(asdict(self), indent=1))
        return path

    @classmethod
    def load(cls, path: Path) -> ShardRecord:
        data = json.loads(path.read_text())
        return cls(**{k: data[k] for k in cls.__dataclass_fields__ if k in data})


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else ""


def durations_path(project_dir: Path, durations: str | None) -> Path:
    """The durations file: --durations, else .test_durations next to bench.toml."""
    return Path(durations) if durations else project_dir / DURATIONS_NAME


def check(shard: tuple[int, int] | None, durations: str | None, project_dir: Path) -> list[str]:
    """The shard inputs' problems, one line each (empty: fine). A missing default durations file is no
    problem (pytest-split then splits by count; logged), a missing --durations file is."""
    problems: list[str] = []
    if shard is None:
        if durations:
            problems.append("--durations: only with --shard K/N (the durations balance the shards)")
        return problems
    if importlib.util.find_spec("pytest_split") is None:
        problems.append("--shard needs the pytest-split plugin: pip install pytest-split")
    path = durations_path(project_dir, durations)
    if not path.is_file():
        if durations:
            problems.append(f"--durations {path}: no such file")
        else:
            log.warning("no durations file %s: the shards get equal numbers of cases, not equal times", path)
        return problems
    try:
        recorded = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        problems.append(f"--durations {path}: not a durations file (pytest-split's JSON): {exc}")
        return problems
    if not isinstance(recorded, dict) or not all(isinstance(v, int | float) for v in recorded.values()):
        problems.append(f"--durations {path}: not a durations file (a JSON object: case id -> seconds)")
    return problems


def apply_shard(config: Any) -> None:
    """Translate `--bench-shard K/N` (and `--bench-durations`) into pytest-split's options. Every problem is a
    ConfigError raised before collection: no case runs."""
    value = options.get(config, "shard")
    durations = options.get(config, "durations")
    if value is None and not durations:
        return
    config_option = options.get(config, "config")
    project_dir = load_config(Path(config_option) if config_option else None).path.parent
    problems = check(value, durations, project_dir)
    if problems:
        raise ConfigError("; ".join(problems))
    if config.option.splits or config.option.group:
        raise ConfigError("--shard K/N and pytest-split's --splits/--group say the same: give one of them")
    k, n = value
    for name in ("color", "code_highlight"):   # pytest-split writes through a terminal writer, which reads
        if not hasattr(config.option, name):    # these; `bench run` disables pytest's terminal plugin (their home)
            setattr(config.option, name, "no")
    config.option.splits, config.option.group = n, k
    config.option.splitting_algorithm = ALGORITHM
    config.option.durations_path = str(durations_path(project_dir, durations))


def current(config: Any) -> tuple[int, int] | None:
    """(K, N) when this pytest run is a shard (by --bench-shard or pytest-split's own options)."""
    splits, group = getattr(config.option, "splits", None), getattr(config.option, "group", None)
    return (int(group), int(splits)) if splits and group else None


def record(config: Any, databases: tuple[Path, ...], selected: list[str]) -> ShardRecord | None:
    """The shard's record, or None when the run is not a shard."""
    which = current(config)
    if which is None:
        return None
    return ShardRecord(
        shard=which[0], of=which[1], bench_version=bench_version(),
        databases={p.name: sha256(p) for p in databases},
        durations=sha256(Path(getattr(config.option, "durations_path", "") or DURATIONS_NAME)),
        selection={"keyword": config.option.keyword or "", "markexpr": config.option.markexpr or "",
                   "dut": sorted(options.get(config, "dut") or [])},
        selected=sorted(selected))
