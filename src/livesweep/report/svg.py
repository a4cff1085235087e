"""Draw a :class:`~livesweep.report.chart.Chart` as a standalone SVG document, without matplotlib.

The report's plots are vector drawings written as text: a Bode plot takes a few milliseconds
instead of about 0.15 s through matplotlib's Agg renderer, stays sharp at any zoom and is
smaller than the PNG it replaces. One SVG unit is one point (1/72 in), so font sizes and line
widths carry the Chart's point values directly.
"""

from __future__ import annotations

import math
from xml.sax.saxutils import escape

import numpy as np

from livesweep.report.chart import LIGHT_GREY, Band, Chart, Panel

__all__ = ["to_svg", "linear_ticks", "angle_ticks", "log_ticks"]

PT_PER_IN = 72.0
TICK_FONT = 11.0
LEGEND_FONT = 9.5
GRID = "#b0b0b0"
MINOR_GRID = "#e6e6e6"
SPAN_FILL, SPAN_ALPHA = LIGHT_GREY, 0.4


def linear_ticks(lo: float, hi: float, target: int = 6) -> np.ndarray:
    """Round tick values (1, 2, 2.5 or 5 times a power of ten apart) covering [lo, hi]."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return np.array([lo]) if math.isfinite(lo) else np.array([])
    raw = (hi - lo) / max(target - 1, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * mag >= raw * (1 - 1e-9))
    first = math.ceil(lo / step - 1e-9) * step
    ticks = first + step * np.arange(int(math.floor((hi - first) / step + 1e-9)) + 1)
    return np.where(np.abs(ticks) < step * 1e-9, 0.0, ticks)


ANGLE_STEPS = (5.0, 10.0, 15.0, 30.0, 45.0, 90.0, 180.0, 360.0)


def angle_ticks(lo: float, hi: float, target: int = 6) -> np.ndarray:
    """Tick values of an angle axis [deg], multiples of 15, 30, 45, 90 ... covering [lo, hi]."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return linear_ticks(lo, hi, target)
    raw = (hi - lo) / max(target - 1, 1)
    step = next((s for s in ANGLE_STEPS if s >= raw), None)
    if step is None or raw < ANGLE_STEPS[0]:
        return linear_ticks(lo, hi, target)
    first = math.ceil(lo / step - 1e-9) * step
    return first + step * np.arange(int(math.floor((hi - first) / step + 1e-9)) + 1)


def log_ticks(lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Labelled and minor ticks of a log axis over [lo, hi] (lo > 0).

    Decades are labelled; when the range holds fewer than three decades, 2 and 5 times a decade
    are labelled too. The minor ticks are the other integer multiples of each decade.
    """
    if not (lo > 0 and hi > lo and math.isfinite(hi)):
        return np.array([]), np.array([])
    d0, d1 = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
    every = np.array([m * 10.0 ** d for d in range(d0, d1 + 1) for m in range(1, 10)])
    every = every[(every >= lo * (1 - 1e-9)) & (every <= hi * (1 + 1e-9))]
    mant = np.round(every / 10.0 ** np.floor(np.log10(every) + 1e-9))
    decades = mant == 1
    major = decades | ((mant == 2) | (mant == 5)) if decades.sum() < 3 else decades
    return every[major], every[~major]


def _fmt_tick(v: float, step: float | None = None) -> str:
    """A tick label: ``%g`` on a log axis (0.01, 0.2, 1, 20), else as many decimals as ``step`` needs."""
    if step is None:
        return f"{v:g}"
    power = math.floor(math.log10(step) + 1e-9)
    decimals = max(0, -power) + (1 if abs(step / 10.0 ** power - 2.5) < 1e-9 else 0)     # 0.25 steps
    s = f"{v:.{decimals}f}"
    return "0" if float(s) == 0 else s.replace("-", "−")


def _grid_line(x1: float, y1: float, x2: float, y2: float, color: str = GRID) -> str:
    return f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" stroke="{color}" stroke-width="0.4"/>'


class _Scale:
    """Data to SVG coordinates of one axis (linear or log)."""

    def __init__(self, lo: float, hi: float, p0: float, p1: float, log: bool):
        self.log = log
        self.lo, self.hi = (math.log10(lo), math.log10(hi)) if log else (lo, hi)
        self.p0, self.k = p0, (p1 - p0) / (self.hi - self.lo)

    def __call__(self, v):
        v = np.asarray(v, float)
        if self.log:
            with np.errstate(divide="ignore", invalid="ignore"):
                v = np.log10(np.where(v > 0, v, np.nan))
        return self.p0 + (v - self.lo) * self.k


def _points(px: np.ndarray, py: np.ndarray) -> str:
    return " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(px.tolist(), py.tolist()))


def _thin(px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At most four points per SVG unit of x: first, lowest, highest and last of each unit column.

    A 60 s record at 100 Hz drawn 500 units wide keeps its envelope to within the stroke width
    with a sixth of the points. Only for x increasing along the line; otherwise unchanged.
    """
    if px.size < 8 or np.any(np.diff(px) < 0):
        return px, py
    col = np.floor(px - px[0]).astype(np.int64)
    starts = np.flatnonzero(np.concatenate([[True], col[1:] != col[:-1]]))
    if starts.size * 4 >= px.size:
        return px, py
    ends = np.concatenate([starts[1:], [px.size]]) - 1
    lo, hi = np.minimum.reduceat(py, starts), np.maximum.reduceat(py, starts)
    x = np.repeat(px[starts], 4)
    x[3::4] = px[ends]
    y = np.stack([py[starts], lo, hi, py[ends]], axis=1).ravel()
    return x, y


def _runs(ok: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of each run of True in ``ok``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def _x_range(panels: list[Panel]) -> tuple[float, float]:
    lo, hi = math.inf, -math.inf
    for p in panels:
        for s in list(p.lines) + list(p.bands):
            x = np.asarray(s.x, float)
            ok = np.isfinite(x) & (x > 0) if p.log_x else np.isfinite(x)
            if ok.any():
                lo, hi = min(lo, float(x[ok].min())), max(hi, float(x[ok].max()))
    if not math.isfinite(lo):
        return (1.0, 10.0) if panels and panels[0].log_x else (0.0, 1.0)
    if hi <= lo:
        return (lo / 2, lo * 2) if panels[0].log_x else (lo - 0.5, lo + 0.5)
    return lo, hi


def _y_range(p: Panel) -> tuple[float, float]:
    if p.y_limits is not None:
        return float(p.y_limits[0]), float(p.y_limits[1])
    vals = [np.asarray(s.y, float) for s in p.lines] + [np.asarray(b.lo, float) for b in p.bands] + \
           [np.asarray(b.hi, float) for b in p.bands] + [np.array([h.y], float) for h in p.hlines]
    v = np.concatenate([a.ravel() for a in vals]) if vals else np.array([])
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    if hi - lo < 1e-12 * max(1.0, abs(hi)):
        return lo - 1.0, hi + 1.0
    return lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo)


def _dash(dashed: bool, width: float) -> str:
    return f' stroke-dasharray="{3.7 * width:.1f},{1.6 * width:.1f}"' if dashed else ""


def _panel(out: list, p: Panel, box: tuple, xr: tuple, uid: str) -> None:
    x0, y0, w, h = box
    ylo, yhi = _y_range(p)
    sx, sy = _Scale(xr[0], xr[1], x0, x0 + w, p.log_x), _Scale(ylo, yhi, y0 + h, y0, False)
    out.append(f'<clipPath id="{uid}"><rect x="{x0:.1f}" y="{y0:.1f}" width="{w:.1f}" height="{h:.1f}"/></clipPath>')
    # grid and ticks
    if p.log_x:
        major, minor = log_ticks(*xr)
        for v in minor:
            X = float(sx(v))
            out.append(_grid_line(X, y0, X, y0 + h, MINOR_GRID))
        x_labels = [(v, _fmt_tick(v)) for v in major]
    else:
        ticks = linear_ticks(*xr, target=9)
        step = float(ticks[1] - ticks[0]) if ticks.size > 1 else 1.0
        x_labels = [(v, _fmt_tick(v, step)) for v in ticks]
    for v, text in x_labels:
        X = float(sx(v))
        out.append(_grid_line(X, y0, X, y0 + h))
        if p.x_tick_labels:
            out.append(f'<text x="{X:.1f}" y="{y0 + h + TICK_FONT + 3:.1f}" font-size="{TICK_FONT}" '
                       f'text-anchor="middle">{escape(text)}</text>')
    yt = angle_ticks(ylo, yhi) if p.y_angle else linear_ticks(ylo, yhi)
    ystep = float(yt[1] - yt[0]) if yt.size > 1 else 1.0
    for v in yt:
        Y = float(sy(v))
        out.append(_grid_line(x0, Y, x0 + w, Y))
        out.append(f'<text x="{x0 - 3:.1f}" y="{Y + TICK_FONT * 0.35:.1f}" font-size="{TICK_FONT}" '
                   f'text-anchor="end">{escape(_fmt_tick(v, ystep))}</text>')
    # data, clipped to the axes
    out.append(f'<g clip-path="url(#{uid})">')
    if p.x_span is not None:
        a, b = (float(v) for v in sx(np.asarray(p.x_span, float)))
        if math.isfinite(a) and math.isfinite(b):
            out.append(f'<rect x="{min(a, b):.1f}" y="{y0:.1f}" width="{abs(b - a):.1f}" height="{h:.1f}" '
                       f'fill="{SPAN_FILL}" fill-opacity="{SPAN_ALPHA}"/>')
    for band in p.bands:
        px, lo, hi = sx(band.x), sy(band.lo), sy(band.hi)
        for i, j in _runs(np.isfinite(px) & np.isfinite(lo) & np.isfinite(hi)):
            if j - i < 2:
                continue
            pts = _points(np.concatenate([px[i:j], px[i:j][::-1]]), np.concatenate([hi[i:j], lo[i:j][::-1]]))
            out.append(f'<polygon points="{pts}" fill="{band.color}" fill-opacity="{band.alpha:g}"/>')
    for line in p.lines:
        px, py = sx(line.x), sy(line.y)
        runs = [r for r in _runs(np.isfinite(px) & np.isfinite(py)) if r[1] - r[0] >= 2]
        if not runs:
            continue
        attrs = (f'fill="none" stroke="{line.color}" stroke-width="{line.width:g}" stroke-linejoin="round"'
                 + (f' stroke-opacity="{line.alpha:g}"' if line.alpha < 1 else "") + _dash(line.dashed, line.width))
        label = f' data-label="{escape(line.label, {chr(34): "&quot;"})}"' if line.label else ""
        out.append(f'<g {attrs}{label}>' + "".join(f'<polyline points="{_points(*_thin(px[i:j], py[i:j]))}"/>'
                                                     for i, j in runs) + "</g>")
    for hl in p.hlines:
        Y = float(sy(hl.y))
        out.append(f'<line x1="{x0:.1f}" y1="{Y:.1f}" x2="{x0 + w:.1f}" y2="{Y:.1f}" stroke="{hl.color}" '
                   f'stroke-width="{hl.width:g}"{_dash(hl.dashed, hl.width)}/>')
    out.append("</g>")
    out.append(f'<rect x="{x0:.1f}" y="{y0:.1f}" width="{w:.1f}" height="{h:.1f}" fill="none" stroke="#000" '
               'stroke-width="0.8"/>')
    # labels
    if p.y_label:
        X, Y = x0 - 3 - TICK_FONT * 3.6, y0 + h / 2
        out.append(f'<text transform="translate({X:.1f},{Y:.1f}) rotate(-90)" font-size="{p.label_size:g}" '
                   f'text-anchor="middle">{escape(p.y_label)}</text>')
    if p.x_label:
        out.append(f'<text x="{x0 + w / 2:.1f}" y="{y0 + h + TICK_FONT + 5 + p.label_size:.1f}" '
                   f'font-size="{p.label_size:g}" text-anchor="middle">{escape(p.x_label)}</text>')
    if p.note:
        out.append(f'<text x="{x0 + w - 4:.1f}" y="{y0 + 0.15 * h + 3:.1f}" font-size="8" text-anchor="end">'
                   f'{escape(p.note)}</text>')
    if p.legend:
        _legend(out, p, box)


def _legend(out: list, p: Panel, box: tuple) -> None:
    entries = [("band", b) for b in p.bands if b.label] + [("line", s) for s in p.lines if s.label]
    if p.x_span is not None and p.x_span_label:
        entries.append(("band", Band(np.asarray(p.x_span, float), np.zeros(2), np.zeros(2), SPAN_FILL,
                                     max(SPAN_ALPHA, 0.6), p.x_span_label)))
    if not entries:
        return
    x0, y0, w, h = box
    row = LEGEND_FONT * 1.35
    width = 26 + max(len(s.label) for _, s in entries) * LEGEND_FONT * 0.55
    height = row * len(entries) + 4
    lx = x0 + 4
    ly = y0 + 4 if p.legend.startswith("upper") else y0 + h - 4 - height
    out.append(f'<rect x="{lx:.1f}" y="{ly:.1f}" width="{width:.1f}" height="{height:.1f}" fill="#fff" '
               f'fill-opacity="0.85" stroke="#ccc" stroke-width="0.5" rx="2"/>')
    for k, (kind, s) in enumerate(entries):
        yc = ly + 2 + row * (k + 0.5)
        if kind == "band":
            out.append(f'<rect x="{lx + 4:.1f}" y="{yc - 3:.1f}" width="16" height="6" fill="{s.color}" '
                       f'fill-opacity="{max(s.alpha, 0.3):g}"/>')
        else:
            out.append(f'<line x1="{lx + 4:.1f}" y1="{yc:.1f}" x2="{lx + 20:.1f}" y2="{yc:.1f}" stroke="{s.color}" '
                       f'stroke-width="{s.width:g}"{_dash(s.dashed, s.width)}/>')
        out.append(f'<text x="{lx + 24:.1f}" y="{yc + LEGEND_FONT * 0.35:.1f}" font-size="{LEGEND_FONT}">'
                   f'{escape(s.label)}</text>')


def _layout(chart: Chart) -> list[tuple[int, int, tuple]]:
    """(row, column, (x, y, width, height)) of each cell in SVG units."""
    W, H = (v * PT_PER_IN for v in chart.size_in)
    left, right, top, bottom = chart.margins
    nrows, ncols = len(chart.rows), max(len(r) for r in chart.rows)
    ratios = np.asarray(chart.height_ratios or [1.0] * nrows, float)
    avail_h, avail_w = (top - bottom) * H, (right - left) * W
    mean_h = avail_h / (nrows + chart.hspace * (nrows - 1))
    mean_w = avail_w / (ncols + chart.wspace * (ncols - 1))
    heights = ratios / ratios.sum() * mean_h * nrows
    cells = []
    y = (1 - top) * H
    for r in range(nrows):
        for c in range(ncols):
            cells.append((r, c, (left * W + c * mean_w * (1 + chart.wspace), y, mean_w, float(heights[r]))))
        y += float(heights[r]) + chart.hspace * mean_h
    return cells


def to_svg(chart: Chart) -> str:
    """The chart as an SVG document (text).

    Parameters
    ----------
    chart : Chart

    Returns
    -------
    str
        A standalone SVG 1.1 document, ``chart.size_in`` at 72 units per inch. Each data line
        carries its legend label as ``data-label``.
    """
    W, H = (v * PT_PER_IN for v in chart.size_in)
    ncols = max(len(r) for r in chart.rows)
    xr = {}
    for c in range(ncols):
        col = [r[c] for r in chart.rows if c < len(r) and r[c] is not None]
        if chart.share_x:
            xr.update({(r, c): _x_range(col) for r in range(len(chart.rows))})
        else:
            xr.update({(r, c): _x_range([chart.rows[r][c]]) for r in range(len(chart.rows))
                       if c < len(chart.rows[r]) and chart.rows[r][c] is not None})
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W:.0f} {H:.0f}" width="{W:.0f}" height="{H:.0f}" '
           'font-family="DejaVu Sans, Helvetica, Arial, sans-serif">',
           f'<rect width="{W:.0f}" height="{H:.0f}" fill="#fff"/>']
    if chart.title:        # a long title is set smaller rather than cut at the edges (0.6 em a character)
        size = min(chart.title_size, 0.96 * W / (0.6 * len(chart.title)))
        out.append(f'<text x="{W / 2:.1f}" y="{(1 - chart.margins[2]) * H * 0.62 + size * 0.35:.1f}" '
                   f'font-size="{size:.3g}" text-anchor="middle">{escape(chart.title)}</text>')
    for r, c, box in _layout(chart):
        p = chart.rows[r][c] if c < len(chart.rows[r]) else None
        if p is not None:
            _panel(out, p, box, xr[(r, c)], f"c{r}_{c}")
    out.append("</svg>")
    return "\n".join(out)
