"""Issue 27, finding 6: one name for a time limit across the `bench` fixture. It was `wait_until(timeout)`,
`eventually(within_s)` and `always(during)` beside `run(seconds)`; now every "for how long" is `seconds`, and
nothing in the repository's cases, examples or documents uses the old names."""

from __future__ import annotations

import inspect
import re

from bench.case import Case
from tests.repo import ROOT

LIMITED = ("run", "wait_until", "eventually", "always")
OLD = re.compile(r"\b(?:wait_until|eventually|always)\([^()]*(?:\([^()]*\)[^()]*)*\b(timeout|within_s|during)\s*=",
                 re.DOTALL)


def test_every_time_limit_of_the_fixture_is_called_seconds() -> None:
    for method in LIMITED:
        parameters = inspect.signature(getattr(Case, method)).parameters
        assert "seconds" in parameters, f"Case.{method}{inspect.signature(getattr(Case, method))}"
        assert not {"timeout", "within_s", "during"} & set(parameters), method


def test_the_fixture_docs_say_it() -> None:
    """The class docstring says it, and the reference page shows that docstring (rendered by mkdocstrings from
    `::: bench.case.Case`, or written out by a generator of the page)."""
    said = "Every time limit (\"for how long\") is the argument `seconds`"
    assert said in " ".join((Case.__doc__ or "").split())
    page = " ".join((ROOT / "docs/reference/fixture.md").read_text(encoding="utf-8").split())
    assert "::: bench.case.Case" in page or said in page


def test_no_case_example_or_document_uses_an_old_name() -> None:
    files = [*ROOT.glob("testcases/**/*.py"), *ROOT.glob("examples/*.py"), *ROOT.glob("tests/fixtures/**/*.py"),
             ROOT / "README.md", *(p for p in ROOT.glob("docs/**/*.md") if p.name != "fixture.md")]
    found = [f"{path.relative_to(ROOT)}: {match.group(0)[:80]!r}" for path in files
             for match in OLD.finditer(path.read_text(encoding="utf-8"))]
    assert found == []
