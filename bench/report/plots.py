"""Plots of a case as small inline SVG, drawn directly (no matplotlib).

Size: a campaign has ~400 plots and the whole report must stay within a few MB
(tests/integration/test_report_campaign.py), so every series is reduced to what the page can show: at most
:data:`MAX_POINTS` points (min and max per bucket, so spikes survive), then simplified in
pixel space (a point goes when the line moves by less than :data:`SIMPLIFY_PX` without it),
and written as a relative path with 0.1 px resolution. Strokes, fonts and colours of the axes
are CSS classes of the page, not attributes repeated in every element.

Honesty: a line breaks where a series has a gap (NaN, or consecutive samples more than
``Series.gap`` apart: the frames stopped), so a silent sender is not drawn as a ramp; a
series without points stays in the legend marked "(no frames)"; fault windows are shaded.

Safety: every string is XML-escaped and stripped of control characters; ids carry the plot's
``prefix`` so that many inline SVGs can share one page.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np
from markupsafe import escape

from bench.results.model import Plot, Series

MAX_POINTS = 1000
"""Points per series at most before the pixel-space simplification: about two per pixel column."""
SIMPLIFY_PX = 0.4
"""A point is dropped when the polyline without it stays within this many pixels of it."""

_SIZE = {"time": (640, 210), "xy": (420, 380)}        # viewBox width, height (CSS px at natural size)
_LEFT, _RIGHT, _TOP, _BOTTOM = 56, 10, 8, 34         # axes margins, px
#: The data ranges' margins, as fractions of their span on each side. A signal's plateau at its maximum or minimum
#: (a steering angle held, a speed reached) otherwise lies on the frame, where it cannot be told from it (issue 27).
X_MARGIN, Y_MARGIN = 0.03, 0.08
PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
           "#8c564b", "#e377c2", "#17becf", "#7f7f7f", "#bcbd22")
NO_FRAMES = " (no frames)"
_STEPS = (1.0, 2.0, 2.5, 5.0, 10.0)                  # "nice" tick steps
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


def simplify(px: np.ndarray, py: np.ndarray, eps: float = SIMPLIFY_PX) -> np.ndarray:
    """Indices of the points to keep (Ramer-Douglas-Peucker in pixel space, tolerance ``eps`` px)."""
    n = len(px)
    keep = np.zeros(n, dtype=bool)
    if n == 0:
        return np.flatnonzero(keep)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        dx, dy = px[b] - px[a], py[b] - py[a]
        xs, ys = px[a + 1:b] - px[a], py[a + 1:b] - py[a]
        norm = math.hypot(dx, dy)
        d = np.abs(dy * xs - dx * ys) / norm if norm > 1e-9 else np.hypot(xs, ys)
        i = int(np.argmax(d))
        if d[i] > eps:
            keep[a + 1 + i] = True
            stack.append((a, a + 1 + i))
            stack.append((a + 1 + i, b))
    return np.flatnonzero(keep)


def clean(text: object) -> str:
    """Text without control characters, which are illegal in the XML that SVG is."""
    return _CONTROL.sub("", str(text))


def _cut(text: str, limit: int) -> str:
    """An axis label that fits its axis."""
    text = clean(text)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _arrays(series: Series) -> tuple[np.ndarray, np.ndarray]:
    """Series as float arrays of equal length: a length mismatch is cut, ±inf becomes a gap."""
    n = min(len(series.x), len(series.y))
    x = np.asarray(series.x[:n], dtype=float)
    y = np.asarray(series.y[:n], dtype=float)
    x[np.isinf(x)] = np.nan
    y[np.isinf(y)] = np.nan
    return x, y


def nice_ticks(lo: float, hi: float, bins: int) -> tuple[list[float], int]:
    """Tick values within [lo, hi] at a "nice" step (1, 2, 2.5, 5 × 10^k), and the decimals they need."""
    span = hi - lo
    raw = span / max(bins, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(s * mag for s in _STEPS if s * mag >= raw * (1 - 1e-9))
    first = math.ceil(lo / step - 1e-9)
    ticks = [k * step for k in range(first, math.floor(hi / step + 1e-9) + 1)]
    decimals = max(0, -math.floor(math.log10(step) + 1e-9))
    if round(step / 10.0 ** -decimals, 6) % 1:   # 2.5 × 10^k needs one more
        decimals += 1
    return ticks, decimals


def _limits(values: list[np.ndarray], margin: float = X_MARGIN) -> tuple[float, float]:
    """The axis range of the finite values, widened by `margin` of their span on each side (a flat line: ±5 %
    of its value, at least ±0.5)."""
    finite = [v[np.isfinite(v)] for v in values]
    finite = [v for v in finite if len(v)]
    if not finite:
        return 0.0, 1.0
    lo = float(min(v.min() for v in finite))
    hi = float(max(v.max() for v in finite))
    if hi - lo < 1e-12 * max(1.0, abs(hi)):
        pad = max(abs(hi) * 0.05, 0.5)
        return lo - pad, hi + pad
    pad = (hi - lo) * margin
    return lo - pad, hi + pad


def _num(tenths: int) -> str:
    """An int count of 0.1 px as short SVG number text: 12, 1.5, .5, -.5."""
    if tenths % 10 == 0:
        return str(tenths // 10)
    text = f"{tenths / 10:.1f}"
    return text.replace("0.", ".", 1) if text.startswith(("0.", "-0.")) else text


def _path(px: np.ndarray, py: np.ndarray) -> str:
    """Path data of one unbroken polyline: absolute start, then relative steps of 0.1 px."""
    xs = np.rint(px * 10).astype(np.int64)
    ys = np.rint(py * 10).astype(np.int64)
    parts = [f"M{_num(int(xs[0]))} {_num(int(ys[0]))}"]
    if len(xs) == 1:
        return parts[0] + "h.1"   # a lone sample still shows (round cap)
    dx, dy = np.diff(xs), np.diff(ys)
    moved = (dx != 0) | (dy != 0)
    steps = []
    for a, b in zip(dx[moved].tolist(), dy[moved].tolist()):
        sb = _num(b)
        steps.append(_num(a) + (sb if sb[0] == "-" else " " + sb))
    return parts[0] + "l" + " ".join(steps) if steps else parts[0] + "h.1"


def _runs(x: np.ndarray, y: np.ndarray, gap: float | None) -> list[np.ndarray]:
    """Index arrays of the unbroken stretches of a series: split at NaN and where x jumps by more than `gap`."""
    ok = np.isfinite(x) & np.isfinite(y)
    new = np.ones(len(x), dtype=bool)
    new[1:] = ~ok[:-1]
    if gap is not None and len(x) > 1:
        with np.errstate(invalid="ignore"):
            new[1:] |= np.diff(x) > gap
    idx = np.flatnonzero(ok)
    if not len(idx):
        return []
    run_of = np.cumsum(new)[idx]
    bounds = (np.flatnonzero(np.diff(run_of)) + 1).tolist()
    return [idx[a:b] for a, b in zip([0, *bounds], [*bounds, len(idx)])]


@dataclass
class RenderedPlot:
    """A plot ready for the page: the SVG, the legend as (name, colour) for HTML, the shaded windows."""

    title: str
    kind: str
    svg: str
    legend: list[tuple[str, str]]
    spans: list[str] = field(default_factory=list)


class Plotter:
    """Renders :class:`Plot` records to compact inline SVG. Title and legend are left to the HTML page."""

    def render(self, plot: Plot, prefix: str = "p",
               spans: list[tuple[float, float, str]] | None = None) -> RenderedPlot:
        """Draw ``plot``; ``prefix`` (unique in the page) namespaces the SVG's ids; ``spans`` are
        (x_start, x_end, label) windows to shade (faults), in the plot's x units."""
        kind = "xy" if plot.kind == "xy" else "time"
        w, h = _SIZE[kind]
        ax_w, ax_h = w - _LEFT - _RIGHT, h - _TOP - _BOTTOM
        data = [(s, *_arrays(s)) for s in plot.series]
        reduced = []
        for s, x, y in data:
            if len(x) and kind == "time" and np.isfinite(x).all() and np.all(np.diff(x) >= 0):
                gaps = np.zeros(len(x), dtype=bool)
                if s.gap is not None and len(x) > 1:
                    gaps[1:] = np.diff(x) > s.gap
                if not gaps.any():
                    x, y = decimate(x, y)
            elif len(x) > 20 * MAX_POINTS:
                x, y = decimate(x, y, max_points=20 * MAX_POINTS, keep_extremes=False)
            reduced.append((s, x, y))
        xlo, xhi = _limits([x for _, x, _ in reduced])
        ylo, yhi = _limits([y for _, _, y in reduced], Y_MARGIN)
        if kind == "xy":   # equal scales: widen the range that is short for its side
            scale = max((xhi - xlo) / ax_w, (yhi - ylo) / ax_h)
            cx, cy = (xlo + xhi) / 2, (ylo + yhi) / 2
            xlo, xhi = cx - scale * ax_w / 2, cx + scale * ax_w / 2
            ylo, yhi = cy - scale * ax_h / 2, cy + scale * ax_h / 2
        sx, sy = ax_w / (xhi - xlo), ax_h / (yhi - ylo)

        def X(v: np.ndarray | float) -> np.ndarray | float:
            return _LEFT + (v - xlo) * sx

        def Y(v: np.ndarray | float) -> np.ndarray | float:
            return _TOP + ax_h - (v - ylo) * sy

        out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" class="chart">',
               f'<defs><clipPath id="{prefix}-c"><rect x="{_LEFT}" y="{_TOP}" width="{ax_w}" height="{ax_h}"/>'
               f'</clipPath></defs>']
        shaded: list[str] = []
        for start, end, label in spans or []:
            a, b = max(start, xlo), min(end, xhi)
            if b <= a:
                continue
            x0, x1 = float(X(a)), float(X(b))
            text = escape(clean(label))
            out.append(f'<rect class="fault" x="{x0:.1f}" y="{_TOP}" width="{max(x1 - x0, 0.5):.1f}" '
                       f'height="{ax_h}"><title>{text}</title></rect>')
            shaded.append(clean(label))
        grid, labels = [], []
        xt, xd = nice_ticks(xlo, xhi, 7 if kind == "time" else 6)
        for v in xt:
            p = float(X(v))
            grid.append(f"M{p:.1f} {_TOP}v{ax_h}")
            labels.append(f'<text x="{p:.1f}" y="{_TOP + ax_h + 13}" class="xt">{v:.{xd}f}</text>')
        yt, yd = nice_ticks(ylo, yhi, 5 if kind == "time" else 6)
        for v in yt:
            p = float(Y(v))
            grid.append(f"M{_LEFT} {p:.1f}h{ax_w}")
            labels.append(f'<text x="{_LEFT - 4}" y="{p + 3:.1f}" class="yt">{v:.{yd}f}</text>')
        out.append(f'<path class="grid" d="{"".join(grid)}"/>')
        out.append(f'<rect class="frame" x="{_LEFT}" y="{_TOP}" width="{ax_w}" height="{ax_h}"/>')
        out.extend(labels)
        legend: list[tuple[str, str]] = []
        lines = [f'<g clip-path="url(#{prefix}-c)">']
        for i, (s, x, y) in enumerate(reduced):
            colour = PALETTE[i % len(PALETTE)]
            name = clean(s.name)
            if not np.isfinite(x).any():
                legend.append((name + NO_FRAMES, ""))
                continue
            legend.append((name, colour))
            d = []
            for run in _runs(x, y, s.gap if kind == "time" else None):
                px, py = np.asarray(X(x[run]), dtype=float), np.asarray(Y(y[run]), dtype=float)
                keep = simplify(px, py)
                d.append(_path(px[keep], py[keep]))
            lines.append(f'<path class="s" stroke="{colour}" d="{"".join(d)}"/>')
        lines.append("</g>")
        out.extend(lines)
        if not any(colour for _, colour in legend):
            out.append(f'<text x="{_LEFT + ax_w / 2:.0f}" y="{_TOP + ax_h / 2:.0f}" class="nodata">no data</text>')
        xlabel = escape(_cut(plot.xlabel, 110))
        ylabel = escape(_cut(plot.ylabel, 40 if kind == "time" else 60))
        out.append(f'<text x="{_LEFT + ax_w / 2:.0f}" y="{h - 6}" class="xl">{xlabel}</text>')
        out.append(f'<text transform="translate(12 {_TOP + ax_h / 2:.0f}) rotate(-90)" class="yl">{ylabel}</text>')
        out.append("</svg>")
        return RenderedPlot(clean(plot.title), kind, "".join(out), legend, shaded)
