"""Reports of a run: a self-contained HTML page for people, JUnit XML for CI.

Both read only :class:`bench.results.model.RunResult`, so they can be (re)written from a stored
result without the bus or pytest.
"""

from bench.report.html import prepare_html, write_html
from bench.report.junit import write_junit

__all__ = ["prepare_html", "write_html", "write_junit"]
