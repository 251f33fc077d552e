"""Plots of a case as inline SVG, drawn with matplotlib's object API (no pyplot, no GUI).

Speed: a run has ~60 cases with ~3 plots; building a matplotlib figure and its axes costs
more than drawing the data, so a :class:`Plotter` keeps one figure per plot kind and
only swaps lines and labels. Layout is fixed (constrained/tight layout measure every
tick label several times); title and legend are HTML. Series are cut to at most
:data:`MAX_POINTS` points.

Safety: text stays SVG text (``svg.fonttype = "none"``): the files stay small, labels
stay selectable, and matplotlib XML-escapes every string it writes (tests check that
hostile signal names cannot become markup). Mathtext is off for all user strings so a
``$`` in a DBC signal name neither changes nor breaks the plot.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass

import matplotlib
import numpy as np
from matplotlib.backends.backend_svg import FigureCanvasSVG
from matplotlib.figure import Figure
from matplotlib.axes import Axes
from matplotlib.ticker import MaxNLocator

from bench.results import Plot, Series

MAX_POINTS = 1000
"""Points per series at most: about two per horizontal pixel of the axes as the page shows them."""

_RC = {"svg.fonttype": "none", "svg.hashsalt": "bench", "path.simplify": True}
_FIG_IN = {"time": (7.5, 2.8), "xy": (5.0, 4.4)}     # figure width, height in inches
_LEFT, _RIGHT, _BOTTOM, _TOP = 0.8, 0.2, 0.5, 0.15    # margins in inches
PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
           "#8c564b", "#e377c2", "#17becf", "#7f7f7f", "#bcbd22")
_PROLOGUE = re.compile(r"\A.*?(?=<svg\b)", re.S)
_METADATA = re.compile(r"<metadata>.*?</metadata>\s*", re.S)
_GLOBAL_STYLE = re.compile(r'<style type="text/css">\*\{[^}]*\}</style>\s*')
_TAG = re.compile(r"<[^<>]+>")
_REF = re.compile(r'(\sid=["\']|href=["\']#|url\(#)')
_STEPS = [1, 2, 2.5, 5, 10]                           # "nice" tick steps, as AutoLocator
_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")


def decimate(x: np.ndarray, y: np.ndarray, max_points: int = MAX_POINTS,
             *, keep_extremes: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Reduce a series to at most ``max_points`` points.

    With ``keep_extremes`` each bucket contributes its minimum and maximum of ``y`` in
    their original order, so spikes and the envelope of a signal survive; otherwise (xy
    trajectories, where no axis is "time") and with NaNs a plain stride is used.
    """
    n = len(y)
    if n <= max_points:
        return x, y
    if not keep_extremes or not np.isfinite(y).all():
        step = -(-n // (max_points - 1))
        idx = np.r_[np.arange(0, n - 1, step), n - 1]
        return x[idx], y[idx]
    buckets = (max_points - 2) // 2
    edges = np.linspace(0, n, buckets + 1).astype(int)
    bucket_of = np.repeat(np.arange(buckets), np.diff(edges))
    lo = np.minimum.reduceat(y, edges[:-1])[bucket_of] == y
    hi = np.maximum.reduceat(y, edges[:-1])[bucket_of] == y
    idx = np.unique(np.concatenate([_first_per_bucket(lo, edges), _first_per_bucket(hi, edges),
                                    [0, n - 1]]))
    return x[idx], y[idx]


def _first_per_bucket(mask: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Index of the first True of ``mask`` in every bucket ``edges[i]:edges[i+1]`` (each has one)."""
    hits = np.flatnonzero(mask)
    return hits[np.searchsorted(hits, edges[:-1])]


def clean(text: object) -> str:
    """Text without control characters, which are illegal in the XML that SVG is."""
    return _CONTROL.sub("", str(text))


def _cut(text: str, limit: int) -> str:
    """An axis label that fits its axis; the SVG would silently clip a longer one."""
    text = clean(text)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _arrays(series: Series) -> tuple[np.ndarray, np.ndarray]:
    """Series as float arrays of equal length: a length mismatch is cut, ±inf becomes a gap."""
    n = min(len(series.x), len(series.y))
    x = np.asarray(series.x[:n], dtype=float)
    y = np.asarray(series.y[:n], dtype=float)
    x[np.isinf(x)] = np.nan  # an infinite value would make autoscaling raise: show a gap
    y[np.isinf(y)] = np.nan
    return x, y


def _unique_ids(svg: str, prefix: str) -> str:
    """Prefix every id and id reference so that many inline SVGs can share one HTML page.

    Only tags are touched: user text is escaped (no raw "<" or ">"), so it never matches.
    """
    return _TAG.sub(lambda tag: _REF.sub(lambda m: m.group(1) + prefix, tag.group(0)), svg)


@dataclass
class RenderedPlot:
    """A plot ready for the page: the SVG, and the legend as (name, colour) for HTML."""

    title: str
    kind: str
    svg: str
    legend: list[tuple[str, str]]


class Plotter:
    """Renders :class:`Plot` records to inline SVG, reusing one figure per kind.

    Title and legend are left to the HTML page: text measurement is most of matplotlib's
    cost per plot, and HTML wraps long DBC signal names instead of clipping them.
    Not thread-safe; make one per report.
    """

    def __init__(self) -> None:
        self._figs: dict[str, Figure] = {}

    def _axes(self, kind: str) -> tuple[Figure, Axes]:
        if kind not in self._figs:
            w, h = _FIG_IN[kind]
            fig = Figure(figsize=(w, h))
            fig.subplots_adjust(left=_LEFT / w, right=1 - _RIGHT / w, bottom=_BOTTOM / h,
                                top=1 - _TOP / h)
            ax = fig.add_subplot()
            ax.grid(True, alpha=0.3)
            ax.tick_params(labelsize=8)
            # fewer ticks than matplotlib's "auto": each tick is several artists to draw
            ax.xaxis.set_major_locator(MaxNLocator(nbins=7 if kind == "time" else 6, steps=_STEPS))
            ax.yaxis.set_major_locator(MaxNLocator(nbins=5 if kind == "time" else 6, steps=_STEPS))
            self._figs[kind] = fig
        fig = self._figs[kind]
        ax = fig.axes[0]
        for artist in [*ax.lines, *ax.texts]:
            artist.remove()
        ax.set_autoscale_on(True)  # an empty plot before fixed the limits
        return fig, ax

    def render(self, plot: Plot, prefix: str = "p") -> RenderedPlot:
        """Draw ``plot``; ``prefix`` (unique in the page) namespaces the SVG's ids."""
        kind = "xy" if plot.kind == "xy" else "time"
        legend: list[tuple[str, str]] = []
        with matplotlib.rc_context(_RC):
            fig, ax = self._axes(kind)
            for i, series in enumerate(plot.series):
                x, y = _arrays(series)
                if len(x):
                    x, y = decimate(x, y, keep_extremes=kind == "time")
                    colour = PALETTE[i % len(PALETTE)]
                    ax.plot(x, y, linewidth=1.0, color=colour, marker="." if len(x) == 1 else "")
                    legend.append((clean(series.name), colour))
            if legend:
                ax.relim()
                ax.autoscale_view()
            else:
                ax.set(xlim=(0, 1), ylim=(0, 1))
                ax.text(0.5, 0.5, "no data", transform=ax.transAxes, ha="center",
                        va="center", color="0.5")
            ax.set_aspect("equal" if kind == "xy" else "auto", adjustable="datalim")
            ax.set_xlabel(_cut(plot.xlabel, 110), parse_math=False, fontsize=9)
            ax.set_ylabel(_cut(plot.ylabel, 45 if kind == "time" else 70), parse_math=False,
                          fontsize=9)
            buf = io.StringIO()
            FigureCanvasSVG(fig).print_svg(buf, metadata={"Date": None})
        svg = _PROLOGUE.sub("", buf.getvalue(), count=1)
        svg = _METADATA.sub("", svg, count=1)
        # matplotlib's "*{...}" rule would style the whole HTML page; the page CSS scopes it
        svg = _GLOBAL_STYLE.sub("", svg, count=1)
        return RenderedPlot(clean(plot.title), kind, _unique_ids(svg, prefix + "-"), legend)


def render_svg(plot: Plot, prefix: str = "p") -> str:
    """One plot as an inline ``<svg>`` (a fresh :class:`Plotter`; reuse one for many plots)."""
    return Plotter().render(plot, prefix).svg
