"""The live Rerun view: what it writes to an .rrd (read back with RrdReader), the blueprint, serving."""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess

import numpy as np
import pyarrow as pa
import pytest

from helpers import tcp_listeners
import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import RrdReader

from livesweep.monitor.blueprint import (
    ADEQUACY_PATH, ALERTS_PATH, FOCUS_PATH, FRACTION_PATH, MODEL_BODE_PATH, MODEL_SUMMARY_PATH, MODEL_TREND_PATH,
    MODEL_TREND_PLOT_PATH, TEST_POINTS_PATH, coherence_path, default_blueprint,
    magnitude_path, pair_path, phase_path, plot_box, plot_margins, sweep_frequency_path, telemetry_path, time_remaining_path,
    waterfall_path,
)
from livesweep.monitor.rerun_view import RerunView, _tensor_array, find_rerun_cli
from livesweep.monitor.text import percent

INPUTS = ["de", "da"]
OUTPUTS = ["q", "p", "r"]
FS = 500.0
N_SAMPLES = 5000
BLOCK = 700          # 5000 = 7 blocks of 700 + 1 of 100: block edges are not round numbers
T_EST = (4.0, 8.0)
UNITS = {"de": "deg", "da": "deg", "q": "deg/s", "p": "deg/s", "r": None}
KINDS = ("ordinary", "partial")                       # coherence kind of each estimate
SWEEPS = (None, {"de": (3.2, 45.0), "da": (None, None)})
TEST_POINTS = [      # (t_s, record): tp 1 opens, is judged, closes; tp 2 opens
    (2.0, {"state": "open", "start_s": 1.5, "end_s": None, "source": "marker", "swept_input": "de",
           "verdict": "WAIT", "pairs": [], "missing": []}),
    (4.5, {"state": "open", "start_s": 1.5, "end_s": None, "source": "marker", "swept_input": "de",
           "verdict": "NO-GO",
           "pairs": [{"output": "q", "input": "de", "adequate_fraction": 0.5999, "band_rad_s": [0.8, 20.0],
                      "coherence": "ordinary"}],
           "missing": ["q/de needs 0.3-0.8 rad/s: about 2 more minute(s) of sweep at low frequency"]}),
    (6.0, {"state": "closed", "start_s": 1.5, "end_s": 6.0, "source": "marker", "swept_input": "de",
           "verdict": "GO",
           "pairs": [{"output": "q", "input": "de", "adequate_fraction": 0.75, "band_rad_s": [0.4, 20.0],
                      "coherence": "partial"}],
           "missing": []}),
    (7.0, {"state": "open", "start_s": 7.0, "end_s": None, "source": "sweep", "swept_input": "da",
           "verdict": "WAIT", "pairs": [], "missing": ["da needs a sweep over 0.3-20 rad/s"]}),
]


def _ns(t):
    return np.rint(np.asarray(t, dtype=np.float64) * 1e9).astype(np.int64)


def _known_signals():
    t = np.arange(N_SAMPLES) / FS
    names = INPUTS + OUTPUTS
    k = np.arange(len(names))[:, None]
    values = np.sin(2 * np.pi * (0.3 + 0.7 * k) * t) * (1.0 + k) + 0.01 * k * t   # distinct, not round
    kinds = ["input"] * len(INPUTS) + ["output"] * len(OUTPUTS)
    return t, names, values, kinds


def _known_estimate(n, omega):
    shape = (len(OUTPUTS), len(INPUTS), omega.size)
    o = np.arange(len(OUTPUTS))[:, None, None]
    i = np.arange(len(INPUTS))[None, :, None]
    x = np.log10(omega)[None, None, :]
    coh = np.clip(0.5 + 0.45 * np.sin(3.0 * x + o + 2.0 * i + n), 0.0, 1.0)
    mag = -20.0 * x * (1 + o) + 3.0 * i + 0.37 * n
    pha = -90.0 - 40.0 * x * (1 + i) - 5.0 * o - 1.3 * n
    assert coh.shape == mag.shape == pha.shape == shape
    return coh, mag, pha


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """One .rrd with a known telemetry block stream, two estimates and alerts."""
    path = tmp_path_factory.mktemp("rrv") / "live.rrd"
    omega = np.logspace(np.log10(0.5), np.log10(40.0), 60)
    view = RerunView(INPUTS, OUTPUTS, recording_id="test-run", save_path=path, waterfall_rows=5)
    t, names, values, kinds = _known_signals()
    for a in range(0, N_SAMPLES, BLOCK):
        # the first block without units (the bare names), the others with them
        units = None if a == 0 else [UNITS[n] for n in names]
        view.log_timeseries(t[a:a + BLOCK], names, values[:, a:a + BLOCK], kinds, units=units)
    estimates = []
    tps = list(TEST_POINTS)
    for n, te in enumerate(T_EST):
        while tps and tps[0][0] <= te:
            view.log_test_point(*tps.pop(0))
        coh, mag, pha = _known_estimate(n, omega)
        if n == 1:
            mag[1, 0, 10:13] = np.nan          # a gap in one Bode curve: drawn as two strips
        rows = [{"output": o, "input": i, "band": (1.0 + n, 10.0 + n) if (o, i) != ("r", "da") else None,
                 "fraction": 0.25 * (io + 1) / 3 + 0.1 * n}
                for io, o in enumerate(OUTPUTS) for i in INPUTS]
        rows[0]["fraction"] = 0.5999            # rounds to 60 %: must not be printed as 60 %
        kw = {"coherence_kind": KINDS[n]} if n else {}      # the first call: the defaults
        if SWEEPS[n] is not None:
            kw["sweep"] = SWEEPS[n]
        view.log_estimate(te, omega, OUTPUTS, INPUTS, coh, mag, pha, rows,
                          verdict=["continue sweep", "adequate"][n], reasons=[f"reason {n} | piped"], **kw)
        estimates.append((coh, mag, pha, rows))
    for tp in tps:
        view.log_test_point(*tp)
    view.log_alerts(8.5, [("coverage", "no energy below 0.8 rad/s"), ("saturation", "de at 98 %")])
    view.close()
    view.close()   # idempotent
    chunks = RrdReader(path).stream().to_chunks()
    return {"path": path, "omega": omega, "signals": (t, names, values, kinds), "estimates": estimates,
            "chunks": chunks, "view": view}


def _rows(chunks, entity, column):
    """(time_ns or None for static, value) of every row of ``column`` at ``entity``, sorted by time."""
    out = []
    for c in chunks:
        if c.entity_path != "/" + entity:
            continue
        rb = c.to_record_batch()
        if column not in rb.schema.names:
            continue
        vals = rb.column(column).to_pylist()
        if "flight_time" in rb.schema.names:
            times = rb.column("flight_time").cast(pa.int64()).to_pylist()
        else:
            times = [None] * len(vals)
        out += list(zip(times, vals))
    return sorted(out, key=lambda r: -1 if r[0] is None else r[0])


def _at(rows, t_ns):
    got = [v for t, v in rows if t == t_ns]
    assert len(got) == 1, f"expected one row at {t_ns} ns, got {len(got)}"
    return got[0]


def _latest_at(rows, t_ns):
    before = [v for t, v in rows if t is not None and t <= t_ns]
    assert before, f"nothing at or before {t_ns} ns"
    return before[-1]


# ------------------------------------------------------------------------------------------- the .rrd


def test_timeseries_values_and_times_exact(recorded):
    t, names, values, kinds = recorded["signals"]
    for name, kind, v in zip(names, kinds, values):
        rows = _rows(recorded["chunks"], telemetry_path(kind, name), "Scalars:scalars")
        assert len(rows) == N_SAMPLES
        np.testing.assert_array_equal([r[0] for r in rows], _ns(t))
        assert all(len(r[1]) == 1 for r in rows)
        np.testing.assert_array_equal([r[1][0] for r in rows], v)      # exact float64
        # the legend name carries the unit once one is given (static: the last one logged holds)
        static = _rows(recorded["chunks"], telemetry_path(kind, name), "SeriesLines:names")
        assert static[-1] == (None, [f"{name} [{UNITS[name]}]" if UNITS[name] else name])


def _grey(rgba):
    r, g, b = (rgba >> 24) & 255, (rgba >> 16) & 255, (rgba >> 8) & 255
    return r == g == b


def _curve(chunks, path, t_ns):
    """(strips as float32 arrays, their colors) logged at ``path`` at ``t_ns``."""
    strips = [np.asarray(s, np.float32).reshape(-1, 2) for s in _at(_rows(chunks, path, "LineStrips2D:strips"), t_ns)]
    colors = _at(_rows(chunks, path, "LineStrips2D:colors"), t_ns)
    assert len(colors) == len(strips)
    return strips, colors


def _points(strips, colors, grey):
    pts = [s for s, c in zip(strips, colors) if _grey(c) == grey]
    return {tuple(p) for s in pts for p in s}


def _check_masked_curve(chunks, path, t_ns, x, y, coh):
    """Coherent points in colour, in order; every masked point within the coherent range grey; nothing else."""
    strips, colors = _curve(chunks, path, t_ns)
    ok = np.isfinite(y) & (coh >= 0.6)
    xy = np.column_stack([x, y]).astype(np.float32)
    coloured = [s for s, c in zip(strips, colors) if not _grey(c)]
    got = np.concatenate(coloured) if coloured else np.zeros((0, 2), np.float32)
    np.testing.assert_array_equal(got, xy[ok])                      # exactly the coherent points
    masked = np.isfinite(y) & ~ok
    lo, hi = (y[ok].min(), y[ok].max()) if ok.sum() >= 2 else (np.nanmin(y), np.nanmax(y))
    surely_drawn = masked & (y >= lo) & (y <= hi)
    grey_pts = _points(strips, colors, grey=True)
    assert {tuple(p) for p in xy[surely_drawn]} <= grey_pts
    # a grey strip holds masked points plus at most the coherent neighbours it joins
    assert grey_pts <= {tuple(p) for p in xy[np.isfinite(y)]}
    assert np.isfinite(np.concatenate(strips)).all()                 # a gap splits, never bridges
    return strips


def _reference(phase, coh):
    """Expected display phase for a curve without wraps: shifted by whole turns so the value at the
    lowest coherent frequency lies in (-180, 180]."""
    ok = np.flatnonzero(coh >= 0.6)
    j = ok[0] if ok.size else 0
    return phase - 360.0 * np.ceil((phase[j] - 180.0) / 360.0)


def test_coherence_points_values_kind_and_threshold(recorded):
    omega = recorded["omega"]
    x = np.log10(omega)
    for n, te in enumerate(T_EST):
        coh = recorded["estimates"][n][0]
        for io, o in enumerate(OUTPUTS):
            for ii, i in enumerate(INPUTS):
                path = coherence_path(o, i)
                c = coh[io, ii]
                np.testing.assert_array_equal(_at(_rows(recorded["chunks"], path, "Coherence:values"), _ns(te)), c)
                assert _at(_rows(recorded["chunks"], path, "Coherence:kind"), _ns(te)) == [KINDS[n]]
                _check_masked_curve(recorded["chunks"], path, _ns(te), x, c, c)
                pos = np.asarray(_at(_rows(recorded["chunks"], path, "Points2D:positions"), _ns(te)), np.float32)
                np.testing.assert_array_equal(pos, np.column_stack([x, c]).astype(np.float32))
                pcol = _at(_rows(recorded["chunks"], path, "Points2D:colors"), _ns(te))
                np.testing.assert_array_equal([_grey(v) for v in pcol], c < 0.6)      # grey below 0.6
    # the threshold is a line at 0.6 across the plotted frequencies, and the axis names the kind
    thr = _latest_at(_rows(recorded["chunks"], coherence_path("q", "de") + "/threshold", "LineStrips2D:strips"),
                     _ns(T_EST[-1]))
    (line,) = thr
    assert [p[1] for p in line] == pytest.approx([0.6, 0.6])
    assert 10 ** line[0][0] == pytest.approx(0.5) and 10 ** line[1][0] == pytest.approx(50.0)
    labels = _latest_at(_rows(recorded["chunks"], coherence_path("q", "de") + "/grid", "Points2D:labels"),
                        _ns(T_EST[-1]))
    assert labels[-1] == "γ² partial"
    first = _latest_at(_rows(recorded["chunks"], coherence_path("q", "de") + "/grid", "Points2D:labels"),
                       _ns(T_EST[0]))
    assert first[-1] == "γ² ordinary"


def _transform(chunks, path, t_ns):
    scale = _latest_at(_rows(chunks, path, "Transform3D:scale"), t_ns)
    trans = _latest_at(_rows(chunks, path, "Transform3D:translation"), t_ns)
    return np.array(scale[0]), np.array(trans[0])


def test_bode_strips_masked_phase_referenced_and_inside_their_box(recorded):
    omega = recorded["omega"]
    x = np.log10(omega)
    coh, mag, pha, _ = recorded["estimates"][-1]
    t_ns = _ns(T_EST[-1])
    for io, o in enumerate(OUTPUTS):
        for ii, i in enumerate(INPUTS):
            c = coh[io, ii]
            ref = _reference(pha[io, ii], c)
            assert -180.0 < ref[np.flatnonzero(c >= 0.6)[0]] <= 180.0
            for path, y, kind in ((magnitude_path(o, i), mag[io, ii], "magnitude"),
                                  (phase_path(o, i), ref, "phase")):
                strips = _check_masked_curve(recorded["chunks"], path, t_ns, x, y, c)
                # the transform maps every drawn point into the plot's box, y up (flipped)
                scale, trans = _transform(recorded["chunks"], path, t_ns)
                assert scale[0] > 0 and scale[1] < 0
                bx, by, w, h = plot_box(kind, len(INPUTS))
                pts = np.concatenate(strips).astype(np.float64)
                shown = pts * scale[:2] + trans[:2]
                assert np.all(shown[:, 0] >= bx - 1e-3) and np.all(shown[:, 0] <= bx + w + 1e-3)
                assert np.all(shown[:, 1] >= by - 1e-3) and np.all(shown[:, 1] <= by + h + 1e-3)
                # and the frequency axis spans the 1-2-5 values around the grid: 0.5 .. 50 rad/s
                assert (np.log10(0.5) * scale[0] + trans[0], np.log10(50.0) * scale[0] + trans[0]) == \
                    pytest.approx((bx, bx + w), abs=1e-3)      # float32 transform
    # a gap (NaN) in the magnitude splits the curve instead of bridging it
    strips, _ = _curve(recorded["chunks"], magnitude_path("p", "de"), t_ns)
    gap = np.float32(x[11])
    assert not any(np.any(s[:, 0] == gap) for s in strips)
    # the grid: frequency ticks at the 1-2-5 values in rad/s, value ticks, the axis name last
    labels = _latest_at(_rows(recorded["chunks"], magnitude_path("q", "de") + "/grid", "Points2D:labels"), t_ns)
    assert labels[:7] == ["0.5", "1", "2", "5", "10", "20", "50 rad/s"]
    assert labels[-1] == "|H| dB"
    values = [float(v) for v in labels[7:-1]]
    assert values == sorted(values) and len(values) <= 6
    ok = coh[0, 0] >= 0.6
    assert values[0] <= mag[0, 0][ok].min() and values[-1] >= mag[0, 0][ok].max()
    plabels = _latest_at(_rows(recorded["chunks"], phase_path("q", "de") + "/grid", "Points2D:labels"), t_ns)
    assert plabels[-1] == "phase deg"


def test_plot_range_follows_the_data_and_shrinks(tmp_path):
    """A phase that once spanned thousands of degrees no longer fixes the grid once it is gone."""
    path = tmp_path / "range.rrd"
    omega = np.logspace(-0.5, 1.5, 40)
    x = np.log10(omega)
    coh = np.full((1, 1, omega.size), 0.9)
    mag = (-20 * x)[None, None, :]
    wild = (-90 - 2000 * (x - x[0]))[None, None, :]         # -90 .. -4090 deg: many turns
    calm = (-90 - 60 * (x - x[0]))[None, None, :]
    view = RerunView(["de"], ["q"], save_path=path, waterfall_rows=0)
    try:
        view.log_estimate(1.0, omega, ["q"], ["de"], coh, mag, wild, [], "x", [])
        view.log_estimate(2.0, omega, ["q"], ["de"], coh, mag, calm, [], "x", [])
        view.log_estimate(3.0, omega, ["q"], ["de"], coh, mag, calm + 5.0, [], "x", [])
    finally:
        view.close()
    chunks = RrdReader(path).stream().to_chunks()
    grid = _rows(chunks, phase_path("q", "de") + "/grid", "Points2D:labels")
    scale = _rows(chunks, phase_path("q", "de"), "Transform3D:scale")

    def value_labels(t):
        labels = _latest_at(grid, _ns(t))
        k = next(k for k, v in enumerate(labels) if v.endswith(" rad/s"))    # frequency ticks come first
        return [float(v) for v in labels[k + 1:-1]]

    assert min(value_labels(1.0)) <= -4090 + 1e-9
    calm_labels = value_labels(2.0)
    assert min(calm_labels) >= -300 and max(calm_labels) <= 180        # shrunk to the new data
    assert calm_labels[0] <= -90 - 60 * (x[-1] - x[0]) and calm_labels[-1] >= -90
    # a 5-degree move is inside the hysteresis: no new grid or transform at t = 3 s
    assert _ns(3.0) not in {t for t, _ in grid} and _ns(3.0) not in {t for t, _ in scale}


def test_waterfall_holds_coherence_history_in_percent(recorded):
    omega = recorded["omega"]
    for io, o in enumerate(OUTPUTS):
        for ii, i in enumerate(INPUTS):
            rows = _rows(recorded["chunks"], waterfall_path(o, i), "Tensor:data")
            (tensor,) = _at(rows, _ns(T_EST[-1]))
            assert tensor["shape"] == [2, omega.size]
            got = np.array(tensor["buffer"], dtype=np.uint8).reshape(2, omega.size)
            want = np.stack([np.rint(100 * e[0][io, ii]) for e in recorded["estimates"]]).astype(np.uint8)
            np.testing.assert_array_equal(got, want)
            assert tensor["names"][0].startswith("estimate")
            vr = _rows(recorded["chunks"], waterfall_path(o, i), "Tensor:value_range")
            assert vr == [(None, [[0.0, 100.0]])]


def test_adequacy_table_fraction_and_alerts(recorded):
    docs = _rows(recorded["chunks"], ADEQUACY_PATH, "TextDocument:text")
    assert [t for t, _ in docs] == list(_ns(T_EST))
    text = docs[-1][1][0]
    assert text.startswith("## adequate\n") and "reason 1 \\| piped" in text
    assert "partial γ² (MISO-conditioned)" in text and "ordinary" not in text
    assert "ordinary γ²" in docs[0][1][0]                    # the default kind
    assert "- de: sweeping 3.2 rad/s, 45 s to the band top" in text
    assert "- da: not sweeping" in text
    assert "| pair | adequate band [rad/s] | fraction | verdict |" in text
    rows = recorded["estimates"][-1][3]
    for r in rows:
        line = next(ln for ln in text.splitlines() if ln.startswith(f"| {r['output']}/{r['input']} |"))
        assert f"| {percent(r['fraction'], 0.6)} |" in line
        if r["band"] is None:
            assert "| — |" in line and line.endswith("| not adequate |")
        else:
            assert f"{r['band'][0]:.3g} – {r['band'][1]:.3g}" in line
            assert line.endswith("| adequate |" if r["fraction"] >= 0.6 else "| partly adequate |")
    q_de = next(ln for ln in text.splitlines() if ln.startswith("| q/de |"))
    assert "| 59.9 % |" in q_de and "60 %" not in q_de        # 0.5999 is not shown as 60 %
    media = _rows(recorded["chunks"], ADEQUACY_PATH, "TextDocument:media_type")
    assert media[-1][1] == ["text/markdown"]

    frac = _at(_rows(recorded["chunks"], FRACTION_PATH, "Scalars:scalars"), _ns(T_EST[-1]))
    np.testing.assert_array_equal(frac, [r["fraction"] for r in rows])    # constructor pair order
    texts = _rows(recorded["chunks"], ALERTS_PATH, "TextLog:text")
    levels = _rows(recorded["chunks"], ALERTS_PATH, "TextLog:level")
    assert [v[0] for _, v in texts] == ["[coverage] no energy below 0.8 rad/s", "[saturation] de at 98 %"]
    assert {t for t, _ in texts} == {int(_ns(8.5))}
    assert [v[0] for _, v in levels] == ["WARN", "WARN"]


def test_a_verdict_change_after_the_last_estimate_is_shown_at_once(tmp_path):
    """A test point that closes after the last samples (the telemetry stopped) changes the verdict
    with no estimate to follow: the status document shows the new verdict at its time, with the
    last estimate's table; a verdict before any estimate waits for the first one."""
    path = tmp_path / "v.rrd"
    omega = np.logspace(0, 1, 20)
    view = RerunView(["da"], ["p"], recording_id="verdict", save_path=path)
    view.log_verdict(1.0, "WAIT", ["no test point yet"])
    coh, mag, pha = (np.full((1, 1, 20), v) for v in (0.9, -3.0, -45.0))
    rows = [{"output": "p", "input": "da", "band": (1.0, 10.0), "fraction": 1.0}]
    view.log_estimate(4.0, omega, ["p"], ["da"], coh, mag, pha, rows, verdict="WAIT", reasons=["running"],
                      sweep={"da": (5.0, 3.0)})
    view.log_verdict(9.0, "NO-GO", ["last test point (da swept 2 s - 8 s): NO-GO", "telemetry lost"])
    view.close()
    docs = _rows(RrdReader(path).stream().to_chunks(), ADEQUACY_PATH, "TextDocument:text")
    assert [t for t, _ in docs] == list(_ns([4.0, 9.0]))
    last = docs[-1][1][0]
    assert last.startswith("## NO-GO\n") and "**last test point (da swept 2 s - 8 s): NO-GO**" in last
    assert "- telemetry lost" in last and "| p/da | 1 – 10 | 100 % | adequate |" in last
    assert "- da: not sweeping" in last


def test_sweep_frequency_and_time_remaining_series(recorded):
    t_ns = _ns(T_EST[1])
    f = _rows(recorded["chunks"], sweep_frequency_path("de"), "Scalars:scalars")
    rem = _rows(recorded["chunks"], time_remaining_path("de"), "Scalars:scalars")
    assert f == [(t_ns, [3.2])] and rem == [(t_ns, [45.0])]      # only the estimate that had a sweep
    (f_da,) = _rows(recorded["chunks"], sweep_frequency_path("da"), "Scalars:scalars")
    (r_da,) = _rows(recorded["chunks"], time_remaining_path("da"), "Scalars:scalars")
    assert f_da[0] == t_ns and np.isnan(f_da[1][0]) and np.isnan(r_da[1][0])    # unknown: NaN, a gap
    names = _rows(recorded["chunks"], sweep_frequency_path("de"), "SeriesLines:names")
    assert names == [(None, ["de [rad/s]"])]
    assert _rows(recorded["chunks"], time_remaining_path("de"), "SeriesLines:names") == [(None, ["de [s]"])]


def test_test_point_history(recorded):
    docs = _rows(recorded["chunks"], TEST_POINTS_PATH, "TextDocument:text")
    assert [t for t, _ in docs] == [int(_ns(t)) for t, _ in TEST_POINTS]
    first = docs[0][1][0]
    assert first.startswith("**Test point 1 (open): WAIT**, sweeping de, from 1.5 s, 0 s so far, found by marker")
    judged = docs[1][1][0]
    assert "| pair | adequate band [rad/s] | fraction | verdict | still missing |" in judged
    assert "| q/de | 0.8 – 20 | 59.9 % | NOT adequate | 1 below |" in judged
    assert "- q/de needs 0.3-0.8 rad/s: about 2 more minute(s) of sweep at low frequency" in judged
    assert "coherence judged: ordinary γ²" in judged
    last = docs[-1][1][0]
    # one entry per test point: the open one first, then the closed one (replacing its open record)
    assert last.count("**Test point") == 2
    assert last.index("**Test point 2 (open): WAIT**") < last.index("**Test point 1 (closed): GO**")
    assert "1.5 – 6.0 s (4 s)" in last and "coherence judged: partial γ²" in last
    assert "| q/de | 0.4 – 20 | 75 % | adequate | — |" in last
    assert "- da needs a sweep over 0.3-20 rad/s" in last
    assert "59.9 %" not in last                                 # the open record of tp 1 is gone


def test_test_point_history_is_bounded(tmp_path):
    view = RerunView(["de"], ["q"], save_path=tmp_path / "tp.rrd", test_point_history=3)
    try:
        for k in range(6):
            view.log_test_point(10.0 * k + 5, {"state": "closed", "start_s": 10.0 * k, "end_s": 10.0 * k + 5,
                                                "source": "sweep", "swept_input": "de", "verdict": "GO",
                                                "pairs": [], "missing": []})
        with pytest.raises(TypeError, match="dict"):
            view.log_test_point(60.0, [1, 2])
    finally:
        view.close()
    docs = _rows(RrdReader(tmp_path / "tp.rrd").stream().to_chunks(), TEST_POINTS_PATH, "TextDocument:text")
    last = docs[-1][1][0]
    assert [int(m) for m in re.findall(r"\*\*Test point (\d+)", last)] == [6, 5, 4]     # newest first, 3 kept


def test_a_receive_time_clock_is_a_utc_timeline_and_text(tmp_path):
    """Data times in seconds since the UNIX epoch (a receive-time map): flight_time is a timestamp
    timeline (the axis reads as the clock, not 20 781 days) at the same nanoseconds, and the test
    point reads in UTC clock time, checked against the standard library's calendar."""
    import datetime

    t0 = 1795531580.5                                   # 2026-11-24 14:46:20.5 UTC
    utc = datetime.datetime.fromtimestamp(t0, datetime.timezone.utc)
    t = t0 + np.arange(50) / 50.0
    view = RerunView(["roll"], ["p"], save_path=tmp_path / "epoch.rrd")
    try:
        view.log_timeseries(t, ["roll", "p"], np.vstack([np.sin(t - t0), np.cos(t - t0)]), ["input", "output"],
                            units=["deg/s", "deg/s"])
        view.log_test_point(t0 + 50.0, {"state": "closed", "start_s": t0, "end_s": t0 + 50.0, "source": "autopilot",
                                        "swept_input": "roll", "verdict": "GO", "pairs": [], "missing": []})
    finally:
        view.close()
    chunks = RrdReader(tmp_path / "epoch.rrd").stream().to_chunks()
    types = {str(c.to_record_batch().schema.field("flight_time").type) for c in chunks
             if "flight_time" in c.to_record_batch().schema.names}
    assert types and all(ty.startswith("timestamp") for ty in types), types
    rows = _rows(chunks, telemetry_path("input", "roll"), "Scalars:scalars")
    np.testing.assert_array_equal([r[0] for r in rows], _ns(t))
    doc = _rows(chunks, TEST_POINTS_PATH, "TextDocument:text")[-1][1][0]
    want = f"{utc:%H:%M:%S}.{utc.microsecond // 100_000} UTC"
    assert want == "14:46:20.5 UTC" and f"{want} – " in doc and "(50 s)" in doc, doc


def test_rrd_has_blueprint_and_verifies(recorded):
    reader = RrdReader(recorded["path"])
    (rec,) = reader.recordings()
    assert (rec.application_id, rec.recording_id) == ("livesweep", "test-run")
    assert reader.blueprints(), "default blueprint missing from the .rrd"
    # only the flight_time timeline: log_time/log_tick are off so a replay gives the same file content
    assert {n for c in recorded["chunks"] for n in c.timeline_names} == {"flight_time"}
    try:
        cli = find_rerun_cli()
    except FileNotFoundError:
        pytest.skip("rerun CLI binary not available")
    res = subprocess.run([*cli, "rrd", "verify", str(recorded["path"])], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stdout + res.stderr


def test_closed_view_refuses_to_log(recorded):
    view = recorded["view"]
    with pytest.raises(RuntimeError, match="closed"):
        view.log_alerts(1.0, [("x", "y")])
    view.flush()   # a no-op after close, not an error


# ------------------------------------------------------------------------------------------- blueprint


def _views(node):
    if isinstance(node, rrb.Blueprint):
        return _views(node.root_container)
    if isinstance(node, rrb.View):
        return [node]
    return [v for child in node.contents for v in _views(child)]


def _covers(view, entity):
    """Does the view show ``entity`` (origin + the ``$origin/...`` content expressions used here)?"""
    origin = str(view.origin).rstrip("/")
    contents = view.contents if isinstance(view.contents, (list, tuple)) else [view.contents]
    for expr in contents:
        expr = str(expr).replace("$origin", origin)
        assert expr.endswith("/**"), expr
        root = expr[:-3]
        if entity == root or entity.startswith(root + "/"):
            return True
    return False


def test_blueprint_is_pure_and_covers_every_entity(recorded):
    assert rr.get_global_data_recording() is None
    bp = default_blueprint(INPUTS, OUTPUTS)
    assert rr.get_global_data_recording() is None        # built without creating or touching a recording
    assert isinstance(bp, rrb.Blueprint)
    views = _views(bp)
    assert len(views) == 13 + 2 * len(INPUTS) * len(OUTPUTS)       # the test-point and model tabs, and every pair's
    # the same inputs give the same layout (names, kinds, origins)
    again = _views(default_blueprint(INPUTS, OUTPUTS))
    assert [(type(v), v.name, v.origin, v.contents) for v in views] == \
           [(type(v), v.name, v.origin, v.contents) for v in again]

    by_type = {}
    for v in views:
        by_type.setdefault(type(v).__name__, []).append(v)
    assert {str(v.origin) for v in by_type["TimeSeriesView"]} == {
        "/telemetry/inputs", "/telemetry/outputs", "/" + FRACTION_PATH, "/status/sweep_frequency",
        "/status/time_remaining"}
    assert [str(v.origin) for v in by_type["TextDocumentView"]] == ["/" + ADEQUACY_PATH, "/" + TEST_POINTS_PATH,
                                                                     "/" + MODEL_SUMMARY_PATH, "/" + MODEL_TREND_PATH]
    assert [str(v.origin) for v in by_type["TextLogView"]] == ["/" + ALERTS_PATH]
    assert "BarChartView" not in by_type                   # coherence is drawn on the log frequency axis
    assert {str(v.origin) for v in by_type["TensorView"]} == {"/" + waterfall_path(o, i)
                                                             for o in OUTPUTS for i in INPUTS}
    assert {str(v.origin) for v in by_type["Spatial2DView"]} == {"/" + pair_path(o, i)
                                                                for o in OUTPUTS for i in INPUTS} | {
        "/" + FOCUS_PATH, "/" + MODEL_BODE_PATH, "/" + MODEL_TREND_PLOT_PATH}
    # every entity the view wrote is shown by a view of the right kind
    kinds = {"telemetry": "TimeSeriesView", "coherence": "Spatial2DView", "waterfall": "TensorView",
             "magnitude_db": "Spatial2DView", "phase_deg": "Spatial2DView", "sweep_frequency": "TimeSeriesView",
             "time_remaining": "TimeSeriesView", "test_points": "TextDocumentView"}
    entities = {c.entity_path for c in recorded["chunks"]} - {"/__properties"}
    for e in sorted(entities):
        showing = [v for v in views if _covers(v, e)]
        assert showing, f"{e} is in no view"
        want = next((k for part, k in kinds.items() if part in e.split("/")), None)
        if want:
            assert {type(v).__name__ for v in showing} == {want}, e
    # a pair's view shows its three frequency plots (and only its own): one view, so aligned axes
    (pv,) = [v for v in by_type["Spatial2DView"] if str(v.origin) == "/" + pair_path("q", "de")]
    for path in (coherence_path, magnitude_path, phase_path):
        assert _covers(pv, "/" + path("q", "de")) and not _covers(pv, "/" + path("p", "de"))


def test_plot_boxes_stack_inside_the_visual_bounds():
    for n in (1, 2, 4):
        left, right, top, bottom = plot_margins(n)
        assert (left, top) == (90.0 * n, 50.0 * n)               # labels keep their size on screen
        boxes = [plot_box(k, n) for k in ("coherence", "magnitude", "phase")]
        assert len({(b[0], b[2]) for b in boxes}) == 1          # same x and width: the frequency axes line up
        for upper, lower in zip(boxes, boxes[1:]):
            assert lower[1] >= upper[1] + upper[3] + top + bottom - 1e-9     # labels of one never on the next
        assert boxes[1][3] > boxes[0][3] and boxes[0][3] == 150.0 * n
    with pytest.raises(ValueError, match="plot kind"):
        plot_box("waterfall", 1)


def test_blueprint_rejects_colliding_pair_paths():
    with pytest.raises(ValueError, match="same entity path"):
        default_blueprint(["b_c", "c"], ["a", "a_b"])
    with pytest.raises(ValueError, match="duplicate input"):
        default_blueprint(["x", "x"], ["y"])


# ------------------------------------------------------------------------------------------- inputs


def test_fast_tensor_arrays_match_rerun_conversion():
    from rerun.components import TensorDataBatch
    x = np.linspace(0.0, 1.0, 37)
    assert _tensor_array(x).equals(TensorDataBatch(x).as_arrow_array())
    img = (np.arange(60).reshape(4, 15) % 101).astype(np.uint8)
    ref = TensorDataBatch(rr.encodings.TensorData(array=img, dim_names=["a", "b"])).as_arrow_array()
    assert _tensor_array(img, ("a", "b")).equals(ref)


def test_bad_inputs_name_what_is_wrong(tmp_path):
    view = RerunView(["de"], ["q"], save_path=tmp_path / "bad.rrd")
    try:
        w = np.array([1.0, 2.0, 3.0])
        ok = np.zeros((1, 1, 3))
        with pytest.raises(ValueError, match=r"coherence must have shape .*\(1, 1, 3\).*\(1, 1, 2\)"):
            view.log_estimate(1.0, w, ["q"], ["de"], np.zeros((1, 1, 2)), ok, ok, [], "x", [])
        with pytest.raises(ValueError, match="omega"):
            view.log_estimate(1.0, np.array([0.0, 1.0, 2.0]), ["q"], ["de"], ok, ok, ok, [], "x", [])
        with pytest.raises(ValueError, match="'sensor'"):
            view.log_timeseries(np.arange(3.0), ["de"], np.zeros((1, 3)), ["sensor"])
        with pytest.raises(ValueError, match=r"shape \(len\(names\), len\(t_s\)\)"):
            view.log_timeseries(np.arange(3.0), ["de", "q"], np.zeros((2, 4)), ["input", "output"])
        with pytest.raises(ValueError, match="finite"):
            view.log_timeseries(np.array([0.0, np.nan]), ["de"], np.zeros((1, 2)), ["input"])
        with pytest.raises(ValueError, match="one unit per name"):
            view.log_timeseries(np.arange(3.0), ["de"], np.zeros((1, 3)), ["input"], units=["deg", "deg"])
        with pytest.raises(ValueError, match="coherence_kind must be 'ordinary' or 'partial'"):
            view.log_estimate(1.0, w, ["q"], ["de"], ok, ok, ok, [], "x", [], coherence_kind="multiple")
        with pytest.raises(ValueError, match=r"sweep\['de'\]"):
            view.log_estimate(1.0, w, ["q"], ["de"], ok, ok, ok, [], "x", [], sweep={"de": 3.0})
    finally:
        view.close()
    with pytest.raises(ValueError, match="spawn"):
        RerunView(["de"], ["q"], spawn=True, serve=True)


# ------------------------------------------------------------------------------------------- cost


def test_estimate_of_48_pairs_150_frequencies_logs_every_update():
    """4 inputs x 12 outputs x 150 frequencies: every log_estimate after the first logs the update
    into the recording. Its cost (budget 100 ms CPU, against the plain Rerun SDK route) is
    benchmarks/bench_rerun_view.py's: no timing here."""
    ins = [f"u{k}" for k in range(4)]
    outs = [f"y{k}" for k in range(12)]
    view = RerunView(ins, outs)          # no sink: in-memory recording, drained below
    try:
        omega = np.logspace(np.log10(0.3), np.log10(40.0), 150)
        rng = np.random.default_rng(1)
        s = 1j * omega
        g = 10.0 / (s * (s / 5.0 + 1.0))
        rows = [{"output": o, "input": i, "band": (1.0, 10.0), "fraction": 0.5} for o in outs for i in ins]
        view.memory.drain_as_bytes()
        sizes = []
        for n in range(3):
            coh = np.clip(rng.normal(0.8, 0.1, (12, 4, 150)), 0, 1)
            mag = 20 * np.log10(abs(g)) + rng.normal(0, 0.5, (12, 4, 150))
            pha = np.degrees(np.unwrap(np.angle(g))) + rng.normal(0, 3, (12, 4, 150))
            view.log_estimate(1.0 + n, omega, outs, ins, coh, mag, pha, rows, "continue", [])
            view.flush()
            sizes.append(len(view.memory.drain_as_bytes()))
        # every update carries its 48 x 3 curves of 150 points (float32 x, y: > 48 x 3 x 150 x 8 bytes)
        assert all(size > 48 * 3 * 150 * 8 for size in sizes), sizes
    finally:
        view.close()


# ------------------------------------------------------------------------------------------- serve


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listening(port):
    """Local addresses listening on TCP ``port`` according to ``ss -ltn``."""
    return tcp_listeners(port) or []


@pytest.mark.skipif(shutil.which("ss") is None, reason="ss (iproute2) not installed")
def test_serve_binds_loopback_only_and_child_goes_away(tmp_path):
    try:
        find_rerun_cli()
    except FileNotFoundError:
        pytest.skip("rerun CLI binary not available")
    grpc_port, web_port = _free_port(), _free_port()
    view = RerunView(["de"], ["q"], serve=True, bind_host="127.0.0.1", grpc_port=grpc_port, web_port=web_port,
                     save_path=tmp_path / "served.rrd")
    pid = view.server_pid
    try:
        assert view.grpc_url == f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        assert view.web_url.startswith(f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}")
        for port in (grpc_port, web_port):
            addrs = _listening(port)
            assert addrs, f"nothing listens on {port}"
            assert set(addrs) == {"127.0.0.1"}, f"port {port} bound to {addrs}"
        view.log_timeseries(np.arange(10) / 10.0, ["de"], np.arange(10.0)[None], ["input"])
        view.flush()
    finally:
        view.close()
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)
    assert _listening(grpc_port) == [] and _listening(web_port) == []
    # the file sink ran alongside the gRPC sink
    rows = _rows(RrdReader(tmp_path / "served.rrd").stream().to_chunks(), telemetry_path("input", "de"),
                 "Scalars:scalars")
    assert [v[0] for _, v in rows] == list(np.arange(10.0))


def test_serve_reports_a_busy_port(tmp_path):
    try:
        find_rerun_cli()
    except FileNotFoundError:
        pytest.skip("rerun CLI binary not available")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        with pytest.raises(RuntimeError, match=re.escape("exited with code")):
            RerunView(["de"], ["q"], serve=True, grpc_port=port, web_port=_free_port())
