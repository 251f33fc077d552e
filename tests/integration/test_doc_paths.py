"""The repository paths docs/architecture.md names exist (issue 27, finding 6: its recipe for a new ECU sent the
unit tests to `tests/test_<node>.py` on `tests/plant_io.py`, neither of which existed any more).

A path is a backticked word that starts with a folder of the repository; one with a placeholder
(`plant/ecus/<node>.py`) must have its folder, the part before the placeholder.
"""

from __future__ import annotations

import re

import pytest

from tests.repo import ROOT

DOCUMENTS = ["docs/architecture.md"]
FOLDERS = ("bench/", "plant/", "tests/", "docs/", "scripts/", "testcases/", "dbc/", "examples/")
PATH = re.compile(r"`([^`\s]+)`")


def named_paths(document: str) -> list[str]:
    text = (ROOT / document).read_text(encoding="utf-8")
    return sorted({m for m in PATH.findall(text) if m.startswith(FOLDERS) and "::" not in m})


@pytest.mark.parametrize("document", DOCUMENTS)
def test_every_path_the_document_names_exists(document: str) -> None:
    paths = named_paths(document)
    assert len(paths) > 20, paths                         # the pattern finds the document's paths
    missing = []
    for path in paths:
        fixed = re.split(r"[<*{]", path, maxsplit=1)[0]   # up to a placeholder or a glob
        target = ROOT / (fixed if fixed == path else fixed.rpartition("/")[0])
        if not target.exists():
            missing.append(path)
    assert missing == [], f"{document} names paths that do not exist: {missing}"
