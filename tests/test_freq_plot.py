"""Geometry of the live frequency plots: phase reference, masked stretches, plotted ranges, ticks."""

from __future__ import annotations

import numpy as np
import pytest

from livesweep.monitor.freq_plot import (
    PHASE_STEPS_DEG, frequency_extent, log_ticks, masked_runs, reference_phase, tick_label, value_extent,
)


def _wrap(p):
    return (np.asarray(p) + 180.0) % 360.0 - 180.0


def test_reference_phase_recovers_a_wrapped_curve_through_noise():
    """A smooth phase falling 20 turns, wrapped, with wild noise where coherence is low."""
    n = 1200
    w = np.logspace(-0.5, 1.5, n)
    truth = -30.0 - 7200.0 * (np.log10(w) + 0.5) / 2.0          # -30 .. -7230 deg, about 6 deg per bin
    coherent = np.ones(n, bool)
    coherent[:20] = False                                         # noise below the first coherent point
    coherent[450:475] = False     # and a stretch in the middle (the truth turns 150 deg across it)
    rng = np.random.default_rng(1)
    measured = _wrap(truth)
    measured[~coherent] = rng.uniform(-180, 180, (~coherent).sum())    # pure noise: anything goes
    out = reference_phase(measured, coherent)
    j = 20
    shift = out[j] - truth[j]
    assert -180.0 < out[j] <= 180.0
    assert shift % 360.0 == pytest.approx(0.0, abs=1e-9) or shift % 360.0 == pytest.approx(360.0, abs=1e-9)
    # every coherent point is the truth moved by the same whole turns: the noise added none
    np.testing.assert_allclose(out[coherent], truth[coherent] + shift, atol=1e-9)
    # masked points keep their value modulo 360 and sit within half a turn of a neighbour
    np.testing.assert_allclose(_wrap(out[~coherent] - measured[~coherent]), 0.0, atol=1e-9)
    assert abs(out[450] - out[449]) <= 180.0 and abs(out[19] - out[20]) <= 180.0
    # the plain unwrap of every point, noise included, does gain turns here (what this guards against)
    plain = np.unwrap(measured, period=360.0)
    assert np.ptp((plain - truth)[coherent]) > 300.0


def test_reference_phase_noise_coherent_by_chance_cannot_walk_the_curve_away():
    """A short-window estimate past the sweep's reach: noise whose coherence crosses the threshold
    at scattered bins (a real ArduPilot stream showed a p/roll phase walking to -1080 deg). The
    solid coherent curve is kept exactly; every point past it stays within half a turn of its end."""
    n = 400
    truth = np.linspace(10.0, -200.0, 200)                       # the swept part: coherent
    rng = np.random.default_rng(4)
    measured = np.concatenate([_wrap(truth), rng.uniform(-180, 180, n - 200)])
    coherent = np.concatenate([np.ones(200, bool), rng.random(n - 200) < 0.3])   # 30 % by chance
    coherent[200] = False
    out = reference_phase(measured, coherent)
    np.testing.assert_allclose(out[:200], truth, atol=1e-9)
    assert np.all(np.abs(out[200:] - out[199]) <= 180.0)
    np.testing.assert_allclose(_wrap(out - measured), 0.0, atol=1e-9)       # the same phase modulo 360
    # unwrapping the chance-coherent points among themselves walks (what this guards against)
    walk = np.unwrap(measured[coherent], period=360.0)
    assert np.ptp(walk) > 540.0


def test_reference_phase_nan_and_shapes():
    p = np.array([[[190.0, 200.0, np.nan, 210.0], [np.nan] * 4]])
    out = reference_phase(p, np.array([[[False, True, True, True], [True] * 4]]))
    np.testing.assert_allclose(out[0, 0], [-170.0, -160.0, np.nan, -150.0])   # referenced at 200 -> -160
    assert np.isnan(out[0, 1]).all()
    # no coherent point: the lowest finite one is the reference; exactly 180 stays 180, -180 becomes 180
    np.testing.assert_allclose(reference_phase(np.array([180.0, 170.0])), [180.0, 170.0])
    np.testing.assert_allclose(reference_phase(np.array([-180.0, -170.0])), [180.0, 190.0])
    np.testing.assert_allclose(reference_phase(np.array([540.0, 550.0])), [180.0, 190.0])


def test_masked_runs_join_and_gaps():
    y = np.array([0.0, 1, 2, 3, 4, np.nan, 6, 7, 100, 9])
    coh = np.array([1, 1, 0, 0, 1, 1, 1, 0, 0, 1], bool)
    runs = masked_runs(y, coh, (0.0, 10.0))
    # coherent 0-1, grey 1..4 (joins both neighbours), coherent 4, gap at 5 (NaN), coherent 6,
    # grey 6..7 (100 is out of range: not drawn, so the grey run ends at 7 and does not reach 9), coherent 9
    assert runs == [(0, 2, True), (1, 5, False), (4, 5, True), (6, 7, True), (6, 8, False), (9, 10, True)]
    assert masked_runs(y, coh) [-2:] == [(6, 10, False), (9, 10, True)]    # without a range 100 is drawn
    assert masked_runs(np.array([np.nan, np.nan]), np.ones(2, bool)) == []


def test_value_extent_grows_holds_and_shrinks():
    e1 = value_extent(None, -95.0, -20.0, PHASE_STEPS_DEG)
    y0, y1, step = e1
    assert y0 <= -95.0 and y1 >= -20.0 and (y1 - y0) / step <= 4 and y0 % step == 0 and y1 % step == 0
    assert value_extent(e1, -90.0, -25.0, PHASE_STEPS_DEG) is e1            # small moves: the same grid
    grown = value_extent(e1, -300.0, -20.0, PHASE_STEPS_DEG)                  # data left it: grows at once
    assert grown[0] <= -300.0 and grown[1] >= -20.0
    big = value_extent(None, -4000.0, 100.0, PHASE_STEPS_DEG)
    small = value_extent(big, -100.0, -60.0, PHASE_STEPS_DEG)                 # data shrank: so does the grid
    assert small != big and small[0] >= -200.0 and small[1] <= 0.0
    assert value_extent(e1, np.nan, 1.0, PHASE_STEPS_DEG) is e1
    flat = value_extent(None, 3.0, 3.0, (1.0, 2.0, 5.0))                     # a constant still gets a span
    assert flat[0] < 3.0 < flat[1]


def test_frequency_ticks_and_labels():
    assert frequency_extent(np.array([0.3, 20.0])) == pytest.approx((np.log10(0.2), np.log10(20.0)))
    ticks = log_ticks(np.log10(0.2), np.log10(20.0))
    assert [round(10 ** x, 6) for x, _ in ticks] == [0.2, 0.5, 1, 2, 5, 10, 20]
    assert [d for _, d in ticks] == [False, False, True, False, False, True, False]
    assert [tick_label(v) for v in (0.2, 0.5, 1.0, 20.0, -180.0, 1440.0, 0.0, 0.8)] == \
        ["0.2", "0.5", "1", "20", "-180", "1440", "0", "0.8"]
