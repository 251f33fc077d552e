"""The databases are parsed once per process (bench.database.codec.load_codebook, issue 28): the same files with
the same [e2e] table give the same Codebook again without a second cantools parse; a changed file or other overrides are
parsed anew."""

from __future__ import annotations

import os
from pathlib import Path

import cantools.database
import pytest

from bench.database import codec
from tests.repo import BENCH_DBC, CHASSIS_DBC


@pytest.fixture
def parses(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The files cantools parses from now on (by name), in a process whose cache starts empty."""
    monkeypatch.setattr(codec, "_LOADED", {})
    seen: list[str] = []
    original = cantools.database.load_file

    def counting(filename: str, *args: object, **kwargs: object) -> object:
        seen.append(Path(filename).name)
        return original(filename, *args, **kwargs)

    monkeypatch.setattr(cantools.database, "load_file", counting)
    return seen


def test_the_same_databases_are_parsed_once(parses: list[str]) -> None:
    first = codec.load_codebook([CHASSIS_DBC, BENCH_DBC])
    again = codec.load_codebook([str(CHASSIS_DBC), BENCH_DBC.parent / ".." / "dbc" / BENCH_DBC.name])
    assert again is first
    assert parses == ["chassis.dbc", "bench.dbc"]


def test_other_overrides_or_a_changed_file_are_parsed_anew(parses: list[str], tmp_path: Path) -> None:
    copy = tmp_path / "bench.dbc"
    copy.write_bytes(BENCH_DBC.read_bytes())
    first = codec.load_codebook([copy])
    overridden = codec.load_codebook([copy], {"BENCH_Control": {"DataID": 0x0ABC}})
    assert overridden is not first
    copy.write_bytes(BENCH_DBC.read_bytes() + b"\n")
    os.utime(copy, ns=(1, 1))        # another size and another time: another file as far as the cache knows
    changed = codec.load_codebook([copy])
    assert changed is not first
    assert parses == ["bench.dbc"] * 3
