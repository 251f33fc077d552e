"""The HTML report: one self-contained file that opens offline and survives hostile strings.

Everything a DBC, a test or the ECU under test can influence (names, notes, messages,
values) goes through jinja2 autoescaping; the plots are matplotlib SVG whose text
matplotlib escapes. A strict Content-Security-Policy (no scripts, no fetches) is a
second line of defence should an escaping bug ever slip through.
"""

from __future__ import annotations

import math
import os
import re
from functools import cache
from pathlib import Path
from urllib.parse import quote

from jinja2 import Environment, PackageLoader, select_autoescape
from markupsafe import Markup, escape

from bench.report.conformance import build_conformance
from bench.report.plots import Plotter, RenderedPlot
from bench.results import Plot, RunResult

_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")


def fmt(value: object) -> str:
    """A value for a table cell: numbers with 4 significant digits, nothing as "–"."""
    if value is None or value == "":
        return "–"
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "NaN"
        return f"{value:.4g}"
    return str(value)


def duration(seconds: float | None) -> str:
    """Seconds as "12.3 s", with h:mm:ss added once it gets long."""
    if seconds is None:
        return "–"
    text = f"{seconds:.4g} s"
    if seconds >= 60:
        s = int(round(seconds))
        text += f" ({s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d})"
    return text


def _finalize(value: object) -> object:
    """Every printed expression: None shows as "–"; control characters are dropped."""
    if value is None:
        return "–"
    if isinstance(value, Markup):
        return value
    return _CONTROL.sub("", str(value))


@cache
def _env() -> Environment:
    env = Environment(
        loader=PackageLoader("bench.report", "templates"),
        autoescape=select_autoescape(default=True, default_for_string=True),
        finalize=_finalize,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters["num"] = fmt
    env.filters["dur"] = duration
    return env


def _mcap_href(mcap_path: str, report_dir: Path) -> str:
    """A relative URL from the report to the MCAP log, percent-encoded (never a scheme)."""
    if not mcap_path:
        return ""
    target = Path(mcap_path)
    try:
        rel = os.path.relpath(target.resolve(), report_dir.resolve())
    except ValueError:  # other drive on Windows
        return target.resolve().as_uri()
    return quote(Path(rel).as_posix())  # ":" is encoded, so "javascript:x" stays a file name


def _render_plot(plotter: Plotter, plot: Plot, prefix: str) -> RenderedPlot:
    """A plot, or a visible note where it failed: a bad series must not cost the whole report."""
    try:
        return plotter.render(plot, prefix)
    except Exception as exc:  # noqa: BLE001 - the report of a long run matters more
        note = escape(f"plot could not be drawn: {type(exc).__name__}: {exc}")
        return RenderedPlot(str(plot.title), plot.kind, f'<p class="plot-error">{note}</p>', [])


def render_html(run: RunResult, report_dir: Path = Path(".")) -> str:
    """The report as a string; ``report_dir`` is where it will live (for relative links)."""
    plotter = Plotter()
    plots = [[_render_plot(plotter, plot, f"c{i}p{j}") for j, plot in enumerate(case.plots)]
             for i, case in enumerate(run.cases)]
    return _env().get_template("report.html.j2").render(
        run=run,
        counts=run.counts,
        plots=plots,
        conformance=build_conformance(run),
        mcap_href=_mcap_href(run.mcap_path, report_dir),
    )


def write_html(run: RunResult, path: Path) -> Path:
    """Write the HTML report of ``run`` to ``path`` (parent folders are created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render_html(run, path.parent), encoding="utf-8")
    return path
