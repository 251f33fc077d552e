"""HIL CAN test bench for chassis ECUs: vehicle-agnostic bus access, restbus, monitors, logs and reports."""

from __future__ import annotations

from functools import cache
from importlib import metadata

from bench import compiled

compiled.install()   # before any module that may have a compiled form is imported

DISTRIBUTION = "chassis-hil-bench"
UNKNOWN_VERSION = "0+unknown"   # a PEP 440 local version: the bench run from a tree that is not installed


@cache
def version() -> str:
    """The bench's version, from the installed distribution's metadata: the one source of it (pyproject.toml
    sets it), written into run logs, shard records and `__version__`."""
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return UNKNOWN_VERSION


def __getattr__(name: str) -> str:
    if name == "__version__":   # computed on first use: a metadata lookup reads the installed distributions
        return version()
    raise AttributeError(f"module 'bench' has no attribute {name!r}")
