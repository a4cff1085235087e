"""The rate a signal arrives at, measured on its own clock.

One job: :func:`_arrival_rate`, the median of a signal's samples per whole second of its stamps (or
receive times), so gaps, a stream rate raised later and a ground station's bursts do not pull it;
:func:`_signal_rate`, that rate over the SystemID runs when the signal has samples there; and
:func:`_rate`, a topic's mean rate over its span.
"""

from __future__ import annotations

import numpy as np

from livesweep.inspection.stats import _Signal, _Stats

#: A stamp that steps back by more than this [s] starts a new stretch of its clock (a reboot, a wrap).
_CLOCK_BREAK_S = 1.0


def _arrival_rate(rx: np.ndarray, stamp: np.ndarray) -> float:
    """The rate samples arrive at [Hz]: the median of the samples per whole second of their clock
    (their stamps when every sample has one and they advance, else the receive times), so a gap,
    a stream rate raised later or a ground station's bursts do not pull it; the mean rate over
    their span when they cover fewer than 5 whole seconds."""
    n = rx.size
    if n < 2:
        return 0.0
    clock = stamp
    if not np.isfinite(stamp).all() or not np.median(np.diff(stamp)) > 0:
        clock = rx * 1e-9
    sec = np.floor(clock).astype(np.int64)
    stretch = np.concatenate(([0], np.cumsum(np.diff(clock) < -_CLOCK_BREAK_S)))    # a reboot, a clock wrap
    key = stretch * (1 << 40) + (sec - sec.min())
    _, counts = np.unique(key, return_counts=True)
    counts = counts[1:-1]                                                          # whole seconds only
    if counts.size >= 3:
        return float(np.sort(counts)[counts.size // 2])
    span = float(clock.max() - clock.min())
    return (n - 1) / span if span > 0 else 0.0


def _signal_rate(stats: _Stats, sig: _Signal) -> float:
    """The rate a signal arrives at [Hz] (:func:`_arrival_rate` of the main system's samples), over
    the SystemID runs that ended when it has samples there (what the verdict judges)."""
    rx, stamp = stats.samples(sig)
    ended = [(r["start"], r["end"]) for r in stats.runs if r["end"] is not None]
    if ended:
        inside = np.zeros(rx.size, dtype=bool)
        for a, b in ended:
            inside |= (rx >= a) & (rx <= b)
        if inside.sum() >= 5:
            r = _arrival_rate(rx[inside], stamp[inside])
            if r > 0:
                return r
    return _arrival_rate(rx, stamp)


def _rate(n: int, first, last) -> float:
    span = (last - first) * 1e-9 if first is not None and last is not None else 0.0
    return (n - 1) / span if n > 1 and span > 0 else 0.0
