"""The hot modules compiled by mypyc from their own source where a C compiler is present; elsewhere, or with
BENCH_COMPILED=0, no extension is built and the same modules run as Python (bench/compiled.py says which ran).

Everything else about the distribution is in pyproject.toml."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

#: the modules of the frame path and the plant's step (docs/performance.md, "a compiled core"); a package's
#: __init__ and bench/compiled.py stay Python (the finder that chooses between the forms lives there)
COMPILED = sorted(str(path) for path in Path("plant").rglob("*.py") if path.name != "__init__.py") + [
    "bench/sim/clock.py", "bench/sim/restbus.py", "bench/sim/station.py", "bench/checks/monitor.py",
    "bench/database/codec.py",
    "bench/e2e/config.py", "bench/e2e/profiles.py", "bench/e2e/receiver.py", "bench/e2e/senders.py",
]


def _uncompiled(why: str) -> None:
    print(f"chassis-hil-bench: not compiled ({why}); the bench runs as pure Python", file=sys.stderr)


class OptionalBuildExt(build_ext):
    """A failed compile (no C compiler, no Python headers) leaves the modules as Python, with one line saying so."""

    def build_extensions(self) -> None:
        try:
            super().build_extensions()
        except Exception as error:   # distutils raises several unrelated types for "no compiler"
            for extension in self.extensions:   # all or none: a module's shim without the shared library fails
                built = self.get_ext_fullpath(extension.name)
                if os.path.exists(built):
                    os.remove(built)
            self.extensions = []                # nothing to copy into the tree or the wheel
            _uncompiled(f"{type(error).__name__}: {error}")


def extensions() -> list[Extension]:
    if os.environ.get("BENCH_COMPILED") == "0":
        return []
    try:
        from mypyc.build import mypycify
    except ImportError:
        _uncompiled("mypyc is not installed")
        return []
    try:
        return mypycify(COMPILED, opt_level="3", group_name="bench._compiled")
    except (Exception, SystemExit) as error:   # mypy's errors end in sys.exit: the modules stay Python
        _uncompiled(f"mypyc: {error}")
        return []


setup(ext_modules=extensions(), cmdclass={"build_ext": OptionalBuildExt})
