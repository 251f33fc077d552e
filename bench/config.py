"""The project configuration (`bench.toml`) and the settings of one run.

A user's own bench project has its own bench.toml; this repository's is the default.
Every problem is a ConfigError naming the file and the key.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from bench.bus import VIRTUAL, is_virtual
from bench.errors import ConfigError
from bench.paths import ROOT

CONFIG_NAME = "bench.toml"


@dataclass(frozen=True)
class ProjectConfig:
    path: Path
    databases: tuple[Path, ...]
    stimulus: tuple[str, ...]
    plant: str
    testcases: Path
    reports: Path


def find_config(start: Path | None = None) -> Path:
    """bench.toml in the working directory or above it, else the repository's own."""
    here = (start or Path.cwd()).resolve()
    for folder in (here, *here.parents):
        candidate = folder / CONFIG_NAME
        if candidate.is_file():
            return candidate
    return ROOT / CONFIG_NAME


def load_config(path: Path | None = None) -> ProjectConfig:
    path = Path(path) if path else find_config()
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    section = data.get("bench")
    if not isinstance(section, dict):
        raise ConfigError(f"{path}: missing table [bench]")
    base = path.parent

    def strings(key: str) -> tuple[str, ...]:
        value = section.get(key)
        if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
            raise ConfigError(f"{path}: [bench] {key} must be a non-empty list of strings, got {value!r}")
        return tuple(value)

    def string(key: str) -> str:
        value = section.get(key)
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{path}: [bench] {key} must be a non-empty string, got {value!r}")
        return value

    unknown = set(section) - {"databases", "stimulus", "plant", "testcases", "reports"}
    if unknown:
        raise ConfigError(f"{path}: [bench] unknown key(s) {', '.join(sorted(unknown))}")
    return ProjectConfig(
        path=path,
        databases=tuple(base / p for p in strings("databases")),
        stimulus=strings("stimulus"),
        plant=string("plant"),
        testcases=base / string("testcases"),
        reports=base / string("reports"),
    )


@dataclass
class RunSettings:
    """How one run reaches its bus; the same for `bench run`, `bench plant` and plain pytest."""

    interface: str = VIRTUAL
    channel: str | None = None
    external: list[str] = field(default_factory=list)
    vehicle: str | None = None

    @property
    def virtual_time(self) -> bool:
        return is_virtual(self.interface)
