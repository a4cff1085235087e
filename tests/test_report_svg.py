"""The report's SVG plots: read back through their own tick labels, the drawn lines must be the
data (an analytic response, a time history with single-sample spikes), and the ticks must be the
round numbers an engineer expects."""

from __future__ import annotations

import math
import re
from xml.etree import ElementTree

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from livesweep.report.chart import bode_chart, residual_chart, time_history_chart
from livesweep.report.svg import TICK_FONT, angle_ticks, linear_ticks, log_ticks, to_svg
from livesweep.spectral.response import FrequencyResponse

NS = "{http://www.w3.org/2000/svg}"


def _frames(root):
    """(x, y, w, h) of each panel frame, top to bottom."""
    out = [tuple(float(r.get(k)) for k in ("x", "y", "width", "height")) for r in root.iter(NS + "rect")
           if r.get("fill") == "none" and r.get("stroke") == "#000"]
    return sorted(out, key=lambda b: b[1])


def _numbers(text: str) -> float | None:
    try:
        return float(text.replace("−", "-"))
    except (TypeError, ValueError):
        return None


def _y_map(root, frame):
    """Data value of an SVG y inside ``frame``, from the y tick labels left of it (a least-squares line)."""
    x, y, w, h = frame
    ticks = [(float(t.get("y")), _numbers(t.text)) for t in root.iter(NS + "text")
             if t.get("text-anchor") == "end" and float(t.get("x")) < x and y - 1 <= float(t.get("y")) <= y + h + 5]
    ticks = [(py, v) for py, v in ticks if v is not None]
    assert len(ticks) >= 3
    py, v = np.array(ticks).T
    a, b = np.polyfit(py - TICK_FONT * 0.35, v, 1)    # labels sit 0.35 font size below their line
    return lambda q: a * np.asarray(q) + b


def _x_map_log(root, frame):
    """Frequency of an SVG x, from the x tick labels under ``frame`` (log axis)."""
    x, y, w, h = frame
    ticks = [(float(t.get("x")), _numbers(t.text)) for t in root.iter(NS + "text")
             if t.get("text-anchor") == "middle" and t.get("y") and y + h < float(t.get("y")) < y + h + TICK_FONT + 6]
    ticks = [(px, v) for px, v in ticks if v is not None and v > 0]
    assert len(ticks) >= 2
    px, v = np.array(ticks).T
    a, b = np.polyfit(px, np.log10(v), 1)
    return lambda q: 10 ** (a * np.asarray(q) + b)


def _line_points(root, label_prefix):
    g = [e for e in root.iter(NS + "g") if (e.get("data-label") or "").startswith(label_prefix)]
    assert len(g) == 1, label_prefix
    pts = [np.array([[float(v) for v in p.split(",")] for p in pl.get("points").split()])
           for pl in g[0].iter(NS + "polyline")]
    return pts


def test_bode_svg_draws_an_analytic_response_where_its_axes_say():
    w = np.geomspace(0.3, 30.0, 120)
    H = 5.0 / (1j * w + 2.0) * np.exp(-0.05j * w)
    coh = np.where((w > 3.0) & (w < 4.0), 0.3, 0.95)          # a stretch of poor coherence
    resp = FrequencyResponse("p", "da", w, H, coh, np.full(w.shape, 0.05))
    root = ElementTree.fromstring(to_svg(bode_chart(resp, units=("deg/s", "deg"))))
    mag_f, ph_f, coh_f = _frames(root)
    f_of = _x_map_log(root, coh_f)                           # only the bottom panel labels its x axis
    runs = _line_points(root, "composite")
    assert len(runs) == 2                                     # broken where gamma^2 < 0.6
    assert sum(len(r) for r in runs) == int(np.sum(coh >= 0.6))
    db = _y_map(root, mag_f)
    for r in runs:
        wf = f_of(r[:, 0])
        np.testing.assert_allclose(wf, np.interp(wf, w, w), rtol=2e-3)        # on the measured frequencies
        np.testing.assert_allclose(db(r[:, 1]), 20 * np.log10(np.abs(5.0 / (1j * wf + 2.0))), atol=0.05)
    # the phase panel: the same points on the same branch as the data (deg), read through its ticks
    deg = _y_map(root, ph_f)
    g = [e for e in root.iter(NS + "g") if e.get("stroke-width") == "1.8" and e.get("data-label") is None]
    ph_runs = [np.array([[float(v) for v in p.split(",")] for p in pl.get("points").split()])
               for pl in g[0].iter(NS + "polyline")]
    for r in ph_runs:
        wf = f_of(r[:, 0])
        want = np.rad2deg(np.angle(5.0 / (1j * wf + 2.0))) - np.rad2deg(0.05 * wf)
        np.testing.assert_allclose(deg(r[:, 1]), want, atol=0.3)


def test_time_history_svg_keeps_single_sample_spikes_when_it_thins_a_long_record():
    t = np.arange(0.0, 60.0, 0.01)                           # 6000 samples on ~500 units of width
    y = np.sin(0.7 * t)
    y[1234], y[4321] = 3.0, -2.5                              # one-sample spikes
    chart = time_history_chart(t, y[None], 0.5 * y[None], np.zeros((1, t.size)), ["p"], ["deg/s"], ["da"])
    root = ElementTree.fromstring(to_svg(chart))
    frame = _frames(root)[0]
    val = _y_map(root, frame)
    pts = np.vstack(_line_points(root, "flight"))
    assert len(pts) < t.size / 2                              # thinned
    assert abs(val(pts[:, 1]).max() - 3.0) < 0.02 and abs(val(pts[:, 1]).min() + 2.5) < 0.02


def test_labels_with_markup_characters_stay_well_formed():
    w = np.geomspace(1, 10, 20)
    resp = FrequencyResponse('a<b & "c"', "d>e", w, 1.0 / (1j * w + 1), np.ones(20), np.full(20, 0.1))
    text = to_svg(bode_chart(resp, title="x < y & z", models=[('TF "1" <fit>', w, 1.0 / (1j * w + 1))]))
    root = ElementTree.fromstring(text)
    assert any(t.text == "x < y & z" for t in root.iter(NS + "text"))
    assert any(e.get("data-label") == 'TF "1" <fit>' for e in root.iter(NS + "g"))


def test_residual_svg_has_a_panel_per_pair_and_quantity():
    from livesweep.ident.residual_space import PairResidual

    w = np.geomspace(0.5, 12, 40)
    pairs = [PairResidual(o, "da", w, np.sin(w), 5 * np.cos(w), np.full(40, 0.3), np.full(40, 2.0))
             for o in ("p", "r", "ay", "beta", "phi")]
    root = ElementTree.fromstring(to_svg(residual_chart(pairs, pairs, title="step 1")))
    assert len(_frames(root)) == 10                                 # five pairs x magnitude and phase
    assert sum(1 for e in root.iter(NS + "polygon")) >= 10          # each with its noise band


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e4, 1e4), st.floats(1e-3, 1e4))
def test_linear_ticks_are_round_and_cover_the_range(lo, span):
    hi = lo + span
    t = linear_ticks(lo, hi)
    assert 2 <= t.size <= 12
    step = t[1] - t[0]
    mant = step / 10 ** math.floor(math.log10(step))
    assert min(abs(mant - m) for m in (1, 2, 2.5, 5, 10)) < 1e-6
    tol = 1e-6 * step                                 # a tick a millionth of a step outside is on the edge
    assert t[0] >= lo - tol and t[-1] <= hi + tol
    assert t[0] - step < lo + tol and t[-1] + step > hi - tol


def test_angle_ticks_are_multiples_of_15_degrees_and_log_ticks_are_decades():
    for lo, hi in ((-200, 20), (-720, 0), (-95, -20), (10, 170)):
        t = angle_ticks(lo, hi)
        assert t.size >= 3 and np.all(np.isclose(t % 15, 0) | np.isclose(t % 15, 15))
    major, minor = log_ticks(0.3, 150.0)
    np.testing.assert_allclose(major, [1, 10, 100])
    assert np.all(minor > 0.3) and 20 in minor
    major, _ = log_ticks(0.5, 20.0)                               # under three decades: 2 and 5 too
    np.testing.assert_allclose(major, [0.5, 1, 2, 5, 10, 20])
    assert re.fullmatch(r"[0-9.]+", "%g" % major[0])
