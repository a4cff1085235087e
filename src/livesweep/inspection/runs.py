"""The SystemID test points of a log, each with whether the log holds its data.

One job: :func:`_runs` turns the SystemID runs the log announces into
:class:`~livesweep.inspection.results.SystemIdRun` records: axis, band and magnitude in words, and
whether a preset that fits the vehicle has every signal it needs for the run
(:func:`_run_signals`) covering it at the rate the run's band needs (:func:`_covers`).
"""

from __future__ import annotations

import math

from livesweep.inspection.fits import _judged_top_hz
from livesweep.inspection.rates import _arrival_rate
from livesweep.inspection.results import SystemIdRun
from livesweep.inspection.stats import _Signal, _Stats
from livesweep.inspection.thresholds import COVER_FRACTION, RATE_PER_TOP_FREQUENCY, SHORT_S


def _run_signals(m, axis) -> list[str] | None:
    """The signals map ``m`` needs for a SystemID run on ``axis``: the input the axis sweeps and the
    outputs required with it; None when the map names no axes, or not this one."""
    sp = m.spectral
    tp = m.test_points
    if tp is None or not tp.axes:
        return None
    swept = tp.axes.get(int(axis)) if axis is not None else None
    if swept is None:
        return None
    outs = tp.required.get(swept)
    if not outs:
        k = list(sp.inputs).index(swept) if swept in sp.inputs else len(sp.outputs)
        outs = (sp.outputs[k],) if k < len(sp.outputs) else tuple(sp.outputs)
    return [swept, *outs]


def _covers(stats: _Stats, sig: _Signal, start: int, end: int, need_hz: float) -> bool:
    """Whether a signal's samples (the main system's) span :data:`COVER_FRACTION` of
    ``start..end`` [receive ns] and arrive there at ``need_hz`` at least."""
    rx, stamp = stats.samples(sig)
    inside = (rx >= start) & (rx <= end)
    if inside.sum() < 2:
        return False
    r = rx[inside]
    if (r.max() - r.min()) < COVER_FRACTION * (end - start):
        return False
    return _arrival_rate(r, stamp[inside]) >= need_hz


def _run_has_data(stats: _Stats, maps, start: int, end: int, axis, inj) -> bool:
    """Whether a preset that holds the log's signals (and fits its vehicle) has every signal it
    needs for the run covering it at the rate the run's band needs."""
    for _name, m, whole in maps:
        if m.spectral is None or whole or stats.vehicle.contradiction(m.vehicle):
            continue
        names = _run_signals(m, axis)
        if names is None:                   # no axis table: an input and an output the log holds
            have = [x for x in (*m.spectral.inputs, *m.spectral.outputs) if stats.signal(m.signals[x]).n]
            if not (set(have) & set(m.spectral.inputs) and set(have) & set(m.spectral.outputs)):
                continue
            names = have
        top = inj.omega_stop_rad_s / (2 * math.pi) if inj is not None else m.spectral.band_rad_s[1] / (2 * math.pi)
        need = RATE_PER_TOP_FREQUENCY * _judged_top_hz(top, "", m)[0]
        if all(_covers(stats, stats.signal(m.signals[n]), start, end, need) for n in names):
            return True
    return False


def _runs(stats: _Stats, t0: int, maps) -> list[SystemIdRun]:
    """The SystemID runs, each with whether the log holds the data a preset needs over it."""
    from livesweep.monitor.vehicle import axis_name

    out = []
    for r in stats.runs:
        start = r["start"]
        end = r["end"]
        inj = r["injection"]
        if end is None and inj is not None:
            end = start + int(inj.duration_s * 1e9)
        what = f"SystemID {axis_name(r['axis'])}"
        if inj is not None:
            what += f", magnitude {inj.magnitude:g}, {inj.describe()}"
        window_end = end if end is not None else start + int(SHORT_S * 1e9)
        has_data = _run_has_data(stats, maps, start, window_end, r["axis"], inj)
        out.append(SystemIdRun((start - t0) / 1e9, math.nan if end is None else (end - t0) / 1e9, r["axis"], what,
                               has_data))
    return out
