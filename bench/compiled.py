"""Compiled or not: which form of the bench's and the plant's hot modules runs, and a line that says so.

`pip install` builds the modules that setup.py lists with mypyc, from their own source, where a C compiler is
present; a compiled module is an extension file beside its `.py`. At import the extensions run unless
`BENCH_COMPILED=0` is set (the same source as Python: what CI's frame-digest comparison runs) or a `.py` is newer
than its extension (edited since the last `pip install -e .`: then every compiled module runs from its source, so an
edit is never silently lost).
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import os
import sys
from collections.abc import Sequence
from functools import cache
from pathlib import Path
from types import ModuleType

ENV = "BENCH_COMPILED"
PACKAGES = ("bench", "plant")
FROM_ENV = f"{ENV}=0"
EDITED = "edited since it was built"


def _extension(directory: Path, name: str) -> Path | None:
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        candidate = directory / f"{name}{suffix}"
        if candidate.is_file():
            return candidate
    return None


@cache
def modules() -> dict[str, tuple[Path, Path]]:
    """Every module of PACKAGES that has a compiled form, imported or not: its source and its extension (one walk
    of the packages' folders per process: the finder, `bench run`'s line and the report ask it)."""
    out: dict[str, tuple[Path, Path]] = {}
    for package in PACKAGES:
        spec = importlib.util.find_spec(package)
        for root in (spec.submodule_search_locations or []) if spec else []:
            for source in sorted(Path(root).rglob("*.py")):
                extension = _extension(source.parent, source.stem)
                if extension is not None:
                    out[".".join((package, *source.relative_to(root).with_suffix("").parts))] = (source, extension)
    return out


def edited(found: dict[str, tuple[Path, Path]]) -> list[str]:
    """The modules whose source changed after their extension was built."""
    return sorted(name for name, (source, extension) in found.items()
                  if source.stat().st_mtime > extension.stat().st_mtime)


@cache
def from_source() -> str | None:
    """Why every module runs from source (FROM_ENV, EDITED), or None: the compiled ones run. All or none: a
    compiled module calls the others of its group directly and takes only their compiled classes."""
    if os.environ.get(ENV) == "0":
        return FROM_ENV
    return EDITED if edited(modules()) else None


class SourceWhereAsked(importlib.abc.MetaPathFinder):
    """Ahead of the path finder: a module of PACKAGES that has an extension is loaded from its `.py` when
    `from_source` says so; every other module is left to the usual finders."""

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if path is None or fullname.partition(".")[0] not in PACKAGES:
            return None
        name = fullname.rpartition(".")[2]
        for entry in path:
            source = Path(entry) / f"{name}.py"
            if source.is_file() and _extension(Path(entry), name) is not None:
                if from_source() is None:
                    return None
                return importlib.util.spec_from_file_location(fullname, source)
        return None


def install() -> None:
    """Put the finder first on `sys.meta_path` (once); bench/__init__.py calls it before any other import."""
    if not any(isinstance(finder, SourceWhereAsked) for finder in sys.meta_path):
        sys.meta_path.insert(0, SourceWhereAsked())


def status() -> str:
    """One line for `bench run` and the report: compiled, or pure Python and why."""
    found = modules()
    why = from_source()
    if not found:
        return f"pure Python (no module was compiled at install: no C compiler, or {FROM_ENV} then)"
    if why == FROM_ENV:
        return f"pure Python ({FROM_ENV}: the {len(found)} compiled modules run from source)"
    if why == EDITED:
        names = edited(found)
        return (f"pure Python: {', '.join(names)} {EDITED}, so all {len(found)} compiled modules run from source "
                "(`pip install -e .` compiles them again)")
    return f"compiled (mypyc): {len(found)} modules"
