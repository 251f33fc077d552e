"""The HTML report: one self-contained file that opens offline and survives hostile strings.

Everything a DBC, a test or the ECU under test can influence (names, notes, messages,
values) goes through jinja2 autoescaping; the plots are SVG whose text bench.report.plots
escapes. A strict Content-Security-Policy (no fetches; the one script allowed is the page's
own filter script, by its SHA-256 hash) is a second line of defence should an escaping bug
ever slip through: an injected script has another hash and does not run.

For an engineer in a hurry: the cases that did not pass come first, listed with their failed steps and then
opened in full (steps, plots, message) before the summary and every table; a search box and outcome filters
narrow the summary and the cases; every other case is collapsed (<details>) until opened or linked to.
"""

from __future__ import annotations

import base64
import hashlib
import math
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import TypedDict
from urllib.parse import quote

from jinja2 import Environment, PackageLoader, select_autoescape
from markupsafe import Markup, escape

from bench.checks.steps import step_values
from bench.report.conformance import build_conformance
from bench.report.junit import error_line
from bench.report.plots import Plotter, RenderedPlot
from bench.results.model import CaseResult, Plot, RunResult, Step

FAILED = ("failed", "error", "aborted")
OPEN = (*FAILED, "inconclusive")   # the cases a reader must look at: open at the top of the report
FAILED_STEPS_SHOWN = 3

#: The page's only script: search and outcome filters, and opening a collapsed case that a link
#: points to. Plain ES5 with no inline handlers, allowed by the CSP through its hash.
SCRIPT = """(function () {
  var q = document.getElementById('q'), shown = document.getElementById('shown');
  var boxes = document.querySelectorAll('#filters input[type=checkbox]');
  var items = document.querySelectorAll('[data-outcome]');
  function apply() {
    var text = q ? q.value.toLowerCase().trim() : '', on = {}, rows = 0, total = 0, i;
    for (i = 0; i < boxes.length; i++) { on[boxes[i].value] = boxes[i].checked; }
    for (i = 0; i < items.length; i++) {
      var el = items[i], ok = on[el.getAttribute('data-outcome')] !== false &&
        (!text || el.getAttribute('data-name').indexOf(text) >= 0);
      el.hidden = !ok;
      if (el.tagName === 'TR') { total++; if (ok) { rows++; } }
    }
    if (shown) { shown.textContent = (text || rows < total) ? rows + ' of ' + total + ' cases shown' : ''; }
  }
  function openTarget() {
    var id = decodeURIComponent(location.hash.slice(1)), el = id ? document.getElementById(id) : null;
    if (el && el.tagName === 'DETAILS') { el.hidden = false; el.open = true; el.scrollIntoView(); }
  }
  if (q) { q.addEventListener('input', apply); }
  for (var i = 0; i < boxes.length; i++) { boxes[i].addEventListener('change', apply); }
  window.addEventListener('hashchange', openTarget);
  openTarget();
}());"""
SCRIPT_HASH = "sha256-" + base64.b64encode(hashlib.sha256(SCRIPT.encode()).digest()).decode()

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


TEMPLATE = "report.html.j2"


@cache
def _env() -> Environment:
    env = Environment(
        loader=PackageLoader("bench.report", "templates"),
        autoescape=select_autoescape(default=True, default_for_string=True),
        finalize=_finalize,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters.update(FILTERS)
    return env


#: The template's filters. A step's values as JUnit and the console show them (bench.checks.steps.format_value).
FILTERS = {"num": fmt, "dur": duration, "measured": lambda step: step_values(step)[0],
           "expected": lambda step: step_values(step)[1]}


def _mcap_href(mcap_path: str, report_dir: Path) -> str:
    """A relative URL from the report to the MCAP log, percent-encoded (never a scheme)."""
    if not mcap_path:
        return ""
    target = Path(mcap_path)
    if not target.is_absolute():   # the run writes the log's name relative to its report folder, not to the cwd
        target = report_dir / target
    try:
        rel = os.path.relpath(target.resolve(), report_dir.resolve())
    except ValueError:  # other drive on Windows
        return target.resolve().as_uri()
    return quote(Path(rel).as_posix())  # ":" is encoded, so "javascript:x" stays a file name


def _spans(case: CaseResult, plot: Plot) -> list[tuple[float, float, str]]:
    """The case's fault windows in the plot's x (time plots that know their bench time at x = 0)."""
    if plot.kind != "time" or plot.x0 is None:
        return []
    end = case.sim_start + case.sim_time
    return [(f.start - plot.x0, (end if f.end is None else f.end) - plot.x0, f"{f.spec} ({f.frames} frames)")
            for f in case.faults]


def _render_plot(plotter: Plotter, plot: Plot, prefix: str, case: CaseResult | None = None) -> RenderedPlot:
    """A plot, or a visible note where it failed: a bad series must not cost the whole report."""
    try:
        return plotter.render(plot, prefix, _spans(case, plot) if case is not None else None)
    except Exception as exc:  # noqa: BLE001 - the report of a long run matters more
        note = escape(f"plot could not be drawn: {type(exc).__name__}: {exc}")
        return RenderedPlot(str(plot.title), plot.kind, f'<p class="plot-error">{note}</p>', [])


@dataclass
class Failure:
    """A case that did not pass, as the list at the top of the report shows it."""

    index: int                   # 1-based: the case's anchor is case-<index>
    case: CaseResult
    steps: list[Step]
    more: int
    line: str                    # first line of the failure message (an exception, a timeout)


def failures(run: RunResult) -> list[Failure]:
    out = []
    for i, case in enumerate(run.cases, 1):
        if case.outcome in OPEN:
            failed = case.failed_steps
            line = (case.inconclusive or case.message)[:300] if case.outcome == "inconclusive" \
                else error_line(case.message)[:300]
            out.append(Failure(i, case, failed[:FAILED_STEPS_SHOWN], max(0, len(failed) - FAILED_STEPS_SHOWN), line))
    return out


class _InvalidCase(TypedDict):
    """A case in which a message's invalid frames of one reason arrived (a row of the report's table)."""

    index: int
    name: str
    frames: int
    fault: bool


@dataclass
class _InvalidRow:
    message: str
    reason: str
    frames: int = 0
    cases: list[_InvalidCase] = field(default_factory=list)


@dataclass
class InvalidSources:
    rows: list[_InvalidRow]
    outside: int                 # invalid frames of the run that no case's record itemises


def invalid_sources(run: RunResult) -> InvalidSources:
    """Where the run's invalid frames come from: per message and reason, with the cases they arrived in."""
    rows: dict[tuple[str, str], _InvalidRow] = {}
    itemised = 0
    for i, case in enumerate(run.cases, 1):
        for message, reason, count in case.invalid:
            n = int(count)
            itemised += n
            row = rows.setdefault((message, reason), _InvalidRow(message, reason))
            row.frames += n
            row.cases.append(_InvalidCase(index=i, name=case.name, frames=n, fault=bool(case.faults)))
    for row in rows.values():
        row.cases.sort(key=lambda c: -c["frames"])
    ordered = sorted(rows.values(), key=lambda r: -r.frames)
    return InvalidSources(ordered, max(0, run.invalid_frames - itemised))


def _search_key(case: CaseResult) -> str:
    return " ".join([case.name, case.nodeid, *case.reqs, *case.duts, *(f.spec for f in case.faults)]).lower()


def prepare_html() -> None:
    """Compile the report's template now, in a process that will write a report: a run stopped by a signal has a
    second for its report (bench.stop), and compiling the template took a third of it on a busy host."""
    _env().get_template(TEMPLATE)


def render_html(run: RunResult, report_dir: Path = Path("."), keep_drawing: Callable[[], bool] | None = None) -> str:
    """The report as a string; ``report_dir`` is where it will live (for relative links). ``keep_drawing``: asked
    before each case's plots; once it says False the remaining cases' plots are left out, and the report says how
    many (a run stopped by a signal must end within a second: bench.stop)."""
    plotter = Plotter()
    plots: list[list[RenderedPlot]] = []
    left_out = 0
    for i, case in enumerate(run.cases):
        if case.plots and keep_drawing is not None and (left_out or not keep_drawing()):
            left_out += 1
            plots.append([])
            continue
        plots.append([_render_plot(plotter, plot, f"c{i}p{j}", case) for j, plot in enumerate(case.plots)])
    return _env().get_template(TEMPLATE).render(
        run=run,
        counts=run.counts,
        plots=plots,
        plots_left_out=left_out,
        failed_outcomes=OPEN,   # these cases open at the top, before the tables; the others follow them, collapsed
        failed_index=[i for i, c in enumerate(run.cases) if c.outcome in OPEN],
        case_index=[i for i, c in enumerate(run.cases) if c.outcome not in OPEN],
        conformance=build_conformance(run),
        mcap_href=_mcap_href(run.mcap_path, report_dir),
        failures=failures(run),
        invalid=invalid_sources(run),
        keys=[_search_key(c) for c in run.cases],
        script=Markup(SCRIPT),
        script_hash=SCRIPT_HASH,
    )


def write_html(run: RunResult, path: Path, keep_drawing: Callable[[], bool] | None = None) -> Path:
    """Write the HTML report of ``run`` to ``path`` (parent folders are created); ``keep_drawing``: render_html's."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render_html(run, path.parent, keep_drawing), encoding="utf-8")
    return path
