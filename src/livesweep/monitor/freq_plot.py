"""The geometry of the live frequency plots: what is drawn where, without Rerun (pure numpy).

The view draws |H| [dB], phase [deg] and coherence gamma^2 against ``log10(omega)`` [rad/s] in
Rerun 2-D views (Rerun has no log axis). This module decides

* the phase as the operator reads it (:func:`reference_phase`): unwrapped along frequency and
  moved by a whole number of turns so its value at the lowest coherent frequency lies in
  (-180, 180] deg;
* which stretches are drawn in colour and which grey (:func:`masked_runs`): a point is
  *coherent* when gamma^2 >= the criteria's threshold (0.6 by default); masked stretches are drawn grey and thin, and a
  masked point outside the plotted range is not drawn at all (it would fall on the labels);
* the plotted range of a value axis (:func:`value_extent`): it follows the coherent data,
  shrinking as well as growing, with hysteresis so the grid does not move every estimate;
* the frequency ticks (:func:`log_ticks`, 1-2-5 per decade) and the value ticks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["reference_phase", "masked_runs", "value_extent", "frequency_extent", "log_ticks", "tick_label",
           "MAG_STEPS_DB", "PHASE_STEPS_DEG", "SHRINK_RATIO", "PAD_FRACTION"]

#: Candidate grid steps of the magnitude [dB] and phase [deg] axes.
MAG_STEPS_DB = (1.0, 2.0, 5.0, 10.0, 20.0, 40.0)
PHASE_STEPS_DEG = (5.0, 10.0, 15.0, 30.0, 45.0, 90.0, 180.0, 360.0, 720.0)
#: The plotted range is kept while it holds the data and is at most this many times the range
#: the data needs (hysteresis); past that it shrinks.
SHRINK_RATIO = 1.6
#: Margin added above and below the data when a new range is chosen (fraction of the data's span).
PAD_FRACTION = 0.15


def reference_phase(phase_deg: np.ndarray, coherent: np.ndarray | None = None,
                    min_run: int | None = None) -> np.ndarray:
    """Phase unwrapped along the last axis and shifted by a multiple of 360 deg.

    Parameters
    ----------
    phase_deg : array (..., n_f)
        Phase [deg], wrapped or unwrapped; NaN marks a missing value (skipped by the unwrap, kept NaN).
    coherent : bool array (..., n_f), optional
        Where gamma^2 >= the threshold. The points of coherent runs at least ``min_run`` long
        are unwrapped among themselves, so the noise of a masked stretch between them cannot add
        turns to the coherent curve; every other point (masked, or coherent by chance amid noise,
        as short-window coherence often is) is put within half a turn of the solid coherent point
        before it (or after it, before the first one), so noise cannot walk the curve away by
        whole turns either. The reference point is the lowest-frequency solid coherent point;
        without one, the lowest-frequency finite point.
    min_run : int, optional
        The shortest run of consecutive coherent finite points unwrapped as part of the curve;
        default 5 % of the points (at least 3): short-window coherence of pure noise crosses 0.6
        at a third of the bins, in runs of a few, while a response the sweep excited is coherent
        over dozens of consecutive bins. A short island is then placed like a masked point, on
        the branch nearest the curve, which is where the unwrap would have put it anyway unless
        the phase turned by more than half a turn across it.

    Returns
    -------
    array (..., n_f) float64
        Unwrapped phase [deg] whose value at the reference point lies in (-180, 180]; equal to
        the input modulo 360 deg at every finite point.
    """
    p = np.array(phase_deg, dtype=np.float64, copy=True)
    flat = p.reshape(-1, p.shape[-1]) if p.ndim else p.reshape(1, 1)
    coh = (np.zeros(flat.shape, bool) if coherent is None
           else np.broadcast_to(np.asarray(coherent, bool), p.shape).reshape(flat.shape))
    for k, row in enumerate(flat):
        idx = np.flatnonzero(np.isfinite(row))
        if idx.size == 0:
            continue
        v = row[idx]
        out = np.unwrap(v, period=360.0)
        cf = coh[k, idx]
        if (solid := _solid(cf, min_run if min_run is not None else max(3, p.shape[-1] // 20))).any():
            cf = solid
        if cf.any() and not cf.all():
            out[cf] = np.unwrap(v[cf], period=360.0)
            pos = np.arange(v.size)
            prev = np.maximum.accumulate(np.where(cf, pos, -1))
            nxt = np.minimum.accumulate(np.where(cf, pos, v.size)[::-1])[::-1]
            a = out[np.where(prev >= 0, prev, nxt)[~cf]]
            out[~cf] = a + (v[~cf] - a + 180.0) % 360.0 - 180.0     # the branch nearest the anchor
        j = int(np.argmax(cf)) if cf.any() else 0
        out -= 360.0 * math.ceil((out[j] - 180.0) / 360.0)      # smallest n with out[j] - 360 n <= 180
        row[idx] = out
    return flat.reshape(p.shape)


def _solid(coherent: np.ndarray, min_run: int) -> np.ndarray:
    """``coherent`` without its runs shorter than ``min_run`` points."""
    if min_run <= 1 or not coherent.any():
        return coherent
    c = np.concatenate(([False], coherent, [False])).astype(np.int8)
    d = np.diff(c)
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    out = np.zeros_like(coherent)
    for a, b in zip(starts, stops):
        if b - a >= min_run:
            out[a:b] = True
    return out


def masked_runs(y: np.ndarray, coherent: np.ndarray, y_range: tuple[float, float] | None = None
                ) -> list[tuple[int, int, bool]]:
    """Stretches of one curve to draw, as ``(start, stop, is_coherent)`` index ranges (stop exclusive).

    Coherent stretches are maximal runs of finite coherent points. Masked stretches are the runs of
    finite non-coherent points, extended by one point onto each coherent neighbour so the drawn
    curve stays continuous (the joining segment is drawn grey). A non-finite point breaks the
    curve; with ``y_range`` a masked point outside it is not drawn either (a gap). Runs are in
    frequency order; a run may hold a single point.
    """
    y = np.asarray(y, dtype=np.float64)
    coh = np.asarray(coherent, dtype=bool) & np.isfinite(y)
    drawn = np.isfinite(y)
    if y_range is not None:
        lo, hi = y_range
        drawn &= coh | ((y >= lo) & (y <= hi))
    n = y.size
    runs: list[tuple[int, int, bool]] = []
    k = 0
    while k < n:
        if not drawn[k]:
            k += 1
            continue
        state = bool(coh[k])
        j = k
        while j < n and drawn[j] and bool(coh[j]) == state:
            j += 1
        if state:
            runs.append((k, j, True))
        else:
            a = k - 1 if k > 0 and coh[k - 1] else k
            b = j + 1 if j < n and coh[j] else j
            runs.append((a, b, False))
        k = j
    return runs


def _step_for(span: float, steps: Sequence[float], max_divisions: int) -> float:
    for s in steps:
        if span / s <= max_divisions:
            return s
    k = span / (max_divisions * steps[-1])         # beyond the list: 1-2-5 multiples of the largest step
    m = 10.0 ** math.floor(math.log10(k))
    return steps[-1] * m * next(f for f in (1.0, 2.0, 5.0, 10.0) if f * m >= k)


def value_extent(old: tuple[float, float, float] | None, lo: float, hi: float, steps: Sequence[float], *,
                 max_divisions: int = 4, min_span: float | None = None) -> tuple[float, float, float] | None:
    """The plotted range ``(y0, y1, step)`` of a value axis after an estimate.

    Parameters
    ----------
    old : (y0, y1, step) or None
        The range plotted so far.
    lo, hi : float
        The range the data needs (the coherent points'); non-finite: keep ``old``.
    steps : sequence of float
        Candidate grid steps, ascending (e.g. :data:`PHASE_STEPS_DEG`).
    max_divisions : int
        Most grid intervals on the axis.
    min_span : float, optional
        Smallest plotted span (default: the smallest step times 2).

    Returns
    -------
    (y0, y1, step) or None
        ``old`` itself while it holds [lo, hi] and is at most :data:`SHRINK_RATIO` times the
        span a new range would have; otherwise a new range: [lo, hi] padded by
        :data:`PAD_FRACTION` of its span and rounded outwards to multiples of the step. It
        never keeps an old maximum the data has left.
    """
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return old
    lo, hi = min(lo, hi), max(lo, hi)
    floor_span = 2.0 * steps[0] if min_span is None else float(min_span)
    span = max(hi - lo, floor_span)
    mid = 0.5 * (lo + hi)
    a, b = mid - 0.5 * span, mid + 0.5 * span
    pad = PAD_FRACTION * span
    a, b = min(a, lo - pad), max(b, hi + pad)
    step = _step_for(b - a, steps, max_divisions)
    y0, y1 = step * math.floor(a / step), step * math.ceil(b / step)
    if old is not None:
        o0, o1, _ = old
        if o0 <= lo and hi <= o1 and (o1 - o0) <= SHRINK_RATIO * (y1 - y0):
            return old
    return (float(y0), float(y1), float(step))


def frequency_extent(omega: np.ndarray) -> tuple[float, float]:
    """``(log10 lo, log10 hi)``: the 1-2-5 values just outside the frequency grid [rad/s]."""
    w = np.asarray(omega, dtype=np.float64)
    return _round_125(float(w.min()), down=True), _round_125(float(w.max()), down=False)


def _round_125(w: float, *, down: bool) -> float:
    d = math.floor(math.log10(w))
    cands = [m * 10.0 ** e for e in (d - 1, d, d + 1) for m in (1, 2, 5)]
    v = max(c for c in cands if c <= w * (1 + 1e-9)) if down else min(c for c in cands if c >= w * (1 - 1e-9))
    return math.log10(v)


def log_ticks(x0: float, x1: float) -> list[tuple[float, bool]]:
    """``(log10 value, is a decade)`` of the 1-2-5 values in [10^x0, 10^x1]."""
    out = []
    for e in range(math.floor(x0) - 1, math.ceil(x1) + 1):
        for m in (1, 2, 5):
            x = e + math.log10(m)
            if x0 - 1e-9 <= x <= x1 + 1e-9:
                out.append((x, m == 1))
    return out


def tick_label(value: float) -> str:
    """A tick value as printed: ``0.05``, ``0.5``, ``2``, ``100``, ``-180`` (no trailing zeros)."""
    if value == 0:
        return "0"
    if abs(value) >= 1.0 and abs(value - round(value)) <= 1e-9 * abs(value):
        return f"{round(value):d}"
    return f"{value:.3g}"
