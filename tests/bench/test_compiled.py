"""Which form of a compiled module runs (bench/compiled.py): the extension, unless BENCH_COMPILED=0 or a source edited
after the build sends every module to its source; and the line that says which.

A package of throwaway files stands in for bench/ and plant/: its "extension" is not a real one, so importing it
fails, which shows the finder chose it."""

from __future__ import annotations

import importlib
import importlib.machinery
import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from bench import compiled

SUFFIX = importlib.machinery.EXTENSION_SUFFIXES[0]


@pytest.fixture
def package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    root = tmp_path / "fakecore"
    (root / "sub").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    (root / "sub" / "__init__.py").write_text("")
    for name in ("sub/fast", "plain"):
        (root / f"{name}.py").write_text("FORM = 'source'\n")
    (root / f"sub/fast{SUFFIX}").write_bytes(b"not an extension")
    os.utime(root / "sub/fast.py", (1_000_000, 1_000_000))             # built after its source was last written
    os.utime(root / f"sub/fast{SUFFIX}", (2_000_000, 2_000_000))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(compiled, "PACKAGES", ("fakecore",))
    monkeypatch.delenv(compiled.ENV, raising=False)
    compiled.modules.cache_clear()
    compiled.from_source.cache_clear()
    yield root
    compiled.modules.cache_clear()
    compiled.from_source.cache_clear()
    for name in [m for m in sys.modules if m.startswith("fakecore")]:
        del sys.modules[name]


def test_the_extension_runs_where_one_is_built(package: Path) -> None:
    assert compiled.modules() == {"fakecore.sub.fast": (package / "sub/fast.py", package / f"sub/fast{SUFFIX}")}
    with pytest.raises(ImportError):                      # the (fake) extension was chosen
        importlib.import_module("fakecore.sub.fast")
    assert importlib.import_module("fakecore.plain").FORM == "source"   # no extension: not the finder's business
    assert compiled.status() == "compiled (mypyc): 1 modules"


def test_bench_compiled_0_runs_the_source(package: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(compiled.ENV, "0")
    assert importlib.import_module("fakecore.sub.fast").FORM == "source"
    assert compiled.status() == "pure Python (BENCH_COMPILED=0: the 1 compiled modules run from source)"


def test_a_source_edited_after_the_build_runs_as_source(package: Path) -> None:
    (package / "sub/fast.py").write_text("FORM = 'edited'\n")     # now: newer than the extension
    assert importlib.import_module("fakecore.sub.fast").FORM == "edited"
    assert compiled.status().startswith("pure Python: fakecore.sub.fast edited since it was built, so all 1")


def test_without_any_extension_the_line_says_pure_python(package: Path) -> None:
    (package / f"sub/fast{SUFFIX}").unlink()
    assert importlib.import_module("fakecore.sub.fast").FORM == "source"
    assert compiled.status().startswith("pure Python (no module was compiled at install")


def test_the_finder_is_installed_once() -> None:
    compiled.install()
    assert sum(isinstance(f, compiled.SourceWhereAsked) for f in sys.meta_path) == 1
