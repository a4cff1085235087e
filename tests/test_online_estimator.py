"""The online (sliding-window) estimator against the batch spectral code on the same segments.

The reference is ``livesweep.spectral.spectra.window_spectra`` (itself checked against
``scipy.signal.csd`` in test_spectral_kernels.py) run on the slice of the record that holds exactly
the segments the online window holds. Agreement is measured per element relative to
``sqrt(G_ii G_jj)`` (the scale of a cross-spectrum), so cross terms near zero do not inflate it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from livesweep.errors import ConfigError
from livesweep.spectral import online as online_mod
from livesweep.spectral.miso import condition_output
from livesweep.spectral.online import OnlineSpectralEstimator, default_segment_s
from livesweep.spectral.spectra import coherence, random_error, window_spectra
from livesweep.spectral.windows import plan_segments

FS = 50.0
NAMES = ["u1", "u2", "y"]
BAND = (0.8, 20.0)
SEG_S = 8.0          # 400 samples; 3 periods of 2.36 rad/s, so BAND's low end is below "usable" (fine here)
TOL = 1e-9


def _record(n=4000, seed=0):
    rng = np.random.default_rng(seed)
    u1 = rng.standard_normal(n)
    u2 = 0.4 * u1 + rng.standard_normal(n)
    kern = np.exp(-np.arange(30) / 6.0)
    y = np.convolve(u1, kern)[:n] - 0.5 * np.convolve(u2, kern[:10])[:n] + 0.3 * rng.standard_normal(n)
    x = np.vstack([u1, u2, y])
    x *= np.linspace(0.5, 3.0, n)          # non-stationary level
    return x + np.array([[1.0], [-2.0], [5.0]])   # offsets: the per-segment mean removal matters


def _feed(est, x, sizes, valid=None, on_block=None):
    i, k = 0, 0
    while i < x.shape[1]:
        m = int(sizes[k % len(sizes)])
        est.update(x[:, i:i + m], None if valid is None else valid[i:i + m])
        i = min(i + m, x.shape[1])
        k += 1
        if on_block is not None:
            on_block(i)


def _rel_err(G, Gref):
    d = np.sqrt(np.abs(np.einsum("iif->if", Gref).real))
    scale = d[:, None, :] * d[None, :, :]
    return float(np.max(np.abs(G - Gref) / np.where(scale > 0, scale, 1.0)))


def _expected_starts(consumed, n, hop, W):
    starts = np.arange(0, consumed - n + 1, hop)
    return starts[starts + n > consumed - W]


@settings(max_examples=25, deadline=None)
@given(sizes=st.lists(st.integers(1, 500), min_size=1, max_size=40), overlap=st.sampled_from([0.0, 0.5, 0.8]))
def test_whole_record_in_random_blocks_equals_batch(sizes, overlap):
    x = _record()
    est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=1000.0, segment_s=SEG_S,
                                  overlap=overlap)
    _feed(est, x, sizes)
    r = est.result()
    ws = window_spectra(x, NAMES, FS, SEG_S, BAND, overlap=overlap)
    assert r.n_segments == ws.n_segments
    assert r.n_eff == pytest.approx(ws.n_eff, rel=1e-12)
    np.testing.assert_array_equal(r.omega, ws.omega)
    assert _rel_err(r.G, ws.G) < TOL
    assert r.t_end_s == pytest.approx(x.shape[1] / FS)
    assert est.time_s == pytest.approx(x.shape[1] / FS)


def test_responses_equal_batch_formulas():
    x = _record()
    est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=1000.0, segment_s=SEG_S)
    _feed(est, x, [137])
    r = est.result()
    ws = window_spectra(x, NAMES, FS, SEG_S, BAND)
    o = r.ordinary
    H_ref = ws.G[0, 2] / ws.G[0, 0].real
    np.testing.assert_allclose(o.H[0, 0], H_ref, rtol=1e-9)
    np.testing.assert_allclose(o.coherence[0, 1], coherence(ws.G, 1, 2), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(o.random_error[0, 0], random_error(coherence(ws.G, 0, 2), ws.n_eff), rtol=1e-8)
    c = condition_output(ws.G, [0, 1], 2)
    m = r.conditioned
    assert m.conditioned and not o.conditioned
    np.testing.assert_allclose(m.H[0], c.H, rtol=1e-8)
    np.testing.assert_allclose(m.coherence[0], c.partial_coherence, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(m.multiple_coherence[0], c.multiple_coherence, rtol=1e-8, atol=1e-12)
    # conditioned random error: partial coherence with n_eff - q + 1 averages
    np.testing.assert_allclose(m.random_error[0, 1], random_error(c.partial_coherence[1], ws.n_eff - 1), rtol=1e-8)
    assert r.best is m
    # input coherence is the batch input cross-coherence
    np.testing.assert_allclose(r.input_coherence, coherence(ws.G, 0, 1), rtol=1e-8, atol=1e-12)
    # one input: no conditioned set
    est1 = OnlineSpectralEstimator(NAMES, ["u1"], ["y"], FS, BAND, window_s=1000.0, segment_s=SEG_S)
    _feed(est1, x, [500])
    r1 = est1.result()
    assert r1.conditioned is None and r1.best is r1.ordinary


@pytest.mark.slow
@settings(max_examples=15, deadline=None)
@given(sizes=st.lists(st.integers(1, 500), min_size=1, max_size=30), window_s=st.sampled_from([8.0, 13.3, 20.0, 31.0]))
def test_sliding_window_equals_batch_on_the_last_segments(sizes, window_s):
    x = _record(3000, seed=3)
    est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=window_s, segment_s=SEG_S)
    n, hop, W = 400, 80, int(round(window_s * FS))
    checked = []

    def check(consumed):
        r = est.result()
        starts = _expected_starts(consumed, n, hop, W)
        if starts.size == 0:
            assert r is None
            return
        np.testing.assert_array_equal(r.segment_starts, starts)
        # the slice holding exactly those segments; its own segmentation starts at starts[0], a
        # multiple of the hop, so it cuts the same segments
        ref = window_spectra(x[:, starts[0]:starts[-1] + n], NAMES, FS, SEG_S, BAND)
        assert ref.n_segments == starts.size == r.n_segments
        assert r.n_eff == pytest.approx(ref.n_eff, rel=1e-12)
        assert _rel_err(r.G, ref.G) < TOL
        checked.append(starts.size)

    _feed(est, x, sizes, on_block=check)
    assert checked and max(checked) >= int(W / hop) - 1


def test_gaps_exclude_exactly_the_segments_plan_segments_excludes():
    x = _record(5000, seed=5)
    valid = np.ones(x.shape[1], bool)
    for a, b in [(950, 960), (2000, 2001), (3100, 3500), (4990, 5000)]:
        valid[a:b] = False
    x = x.copy()
    x[:, ~valid] = np.nan          # a segment that used a missing sample would turn to NaN
    est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=1000.0, segment_s=SEG_S)
    _feed(est, x, [33, 251, 7, 499], valid=valid)
    r = est.result()
    plan = plan_segments(x.shape[1], 400, 0.8, valid)
    ws = window_spectra(x, NAMES, FS, SEG_S, BAND, valid=valid)
    np.testing.assert_array_equal(r.segment_starts, plan.starts)
    assert r.n_excluded == plan.n_excluded == est.n_segments_excluded > 0
    assert np.all(np.isfinite(r.G))
    assert _rel_err(r.G, ws.G) < TOL
    assert r.n_eff == pytest.approx(ws.n_eff, rel=1e-12)


def test_nonfinite_samples_count_as_missing():
    x = _record(3000)
    x[1, 1234] = np.nan
    valid = np.isfinite(x).all(axis=0)
    est = OnlineSpectralEstimator(NAMES, ["u1"], ["y"], FS, BAND, window_s=1000.0, segment_s=SEG_S)
    _feed(est, x, [100])
    assert est.n_nonfinite_samples == 1
    np.testing.assert_array_equal(est.result().segment_starts, plan_segments(3000, 400, 0.8, valid).starts)


def test_cost_per_update_does_not_depend_on_window_length():
    """Chirp-z calls and segment transforms per update are the same for a 10 s and a 1000 s window,
    at most one chirp-z call per update, and every segment is transformed exactly once."""
    x = _record(6000, seed=7)
    sizes = [40, 3, 397, 120, 1, 800, 57]
    logs = {}
    for window_s in (10.0, 1000.0):
        est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=window_s, segment_s=SEG_S)
        log = []
        prev = [0, 0]

        def on_block(_, est=est, log=log, prev=prev):
            log.append((est.n_transform_calls - prev[0], est.n_segment_transforms - prev[1]))
            prev[:] = [est.n_transform_calls, est.n_segment_transforms]

        _feed(est, x, sizes, on_block=on_block)
        logs[window_s] = log
        assert max(c for c, _ in log) == 1
        assert est.n_segment_transforms == plan_segments(x.shape[1], 400, 0.8).n_segments
    assert logs[10.0] == logs[1000.0]


def _bursty(n, seed):
    """Signals with a 1e4 dynamic range: loud bursts that later leave the window."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((2, n))
    x[1] += 0.7 * x[0]
    env = np.ones(n)
    for a in range(0, n, 7919):
        env[a:a + 60] = 1e4
    return x * env


@pytest.mark.parametrize("resync_every", [1000, 10**9])
def test_drift_guard_keeps_equality_after_10000_segments(resync_every):
    fs, n_seg, overlap = 100.0, 20, 0.5          # 0.2 s segments, hop 10 samples
    n = 10 * 10_000 + n_seg
    x = _bursty(n, seed=11)
    names = ["a", "b"]
    band = (40.0, 250.0)
    est = OnlineSpectralEstimator(names, ["a"], ["b"], fs, band, window_s=1.0, segment_s=0.2, overlap=overlap,
                                  resync_every=resync_every)
    errs = []

    def check(consumed):
        if consumed < n - 3000 and consumed % 7 != 0:
            return
        r = est.result()
        s = r.segment_starts
        ref = window_spectra(x[:, s[0]:s[-1] + n_seg], names, fs, 0.2, band, overlap=overlap)
        assert ref.n_segments == r.n_segments
        errs.append(_rel_err(r.G, ref.G))

    _feed(est, x, [37, 12, 91, 3], on_block=check)
    assert est.n_segment_transforms >= 10_000
    assert max(errs) < TOL, max(errs)
    assert est.n_resyncs > 0


def test_without_the_guard_the_running_sum_drifts(monkeypatch):
    """The same stream with both resync rules off: the subtraction residue of the 1e4 bursts
    exceeds the tolerance, so the previous test does exercise the guard."""
    monkeypatch.setattr(online_mod, "DRIFT_TOLERANCE", math.inf)
    fs, n_seg = 100.0, 20
    n = 10 * 3000 + n_seg
    x = _bursty(n, seed=11)
    est = OnlineSpectralEstimator(["a", "b"], ["a"], ["b"], fs, (40.0, 250.0), window_s=1.0, segment_s=0.2,
                                  overlap=0.5, resync_every=10**9)
    _feed(est, x, [37, 12, 91, 3])
    r = est.result()
    s = r.segment_starts
    ref = window_spectra(x[:, s[0]:s[-1] + n_seg], ["a", "b"], fs, 0.2, (40.0, 250.0), overlap=0.5)
    assert est.n_resyncs == 0
    assert _rel_err(r.G, ref.G) > TOL


def test_result_none_until_first_segment_and_time():
    est = OnlineSpectralEstimator(NAMES, ["u1"], ["y"], FS, BAND, window_s=60.0, segment_s=SEG_S)
    x = _record(500)
    assert est.update(x[:, :399]) == 0
    assert est.result() is None
    assert est.time_s == pytest.approx(399 / FS)
    assert est.update(x[:, 399:400]) == 1
    r = est.result()
    assert r.n_segments == 1 and r.segment_starts.tolist() == [0]
    assert not r.G.flags.writeable
    assert est.update(np.empty((3, 0))) == 0


def test_default_segment_length_rule():
    assert default_segment_s((0.3, 20.0), 60.0) == pytest.approx(30.0)            # capped at window/2
    assert default_segment_s((0.3, 20.0), 240.0) == pytest.approx(3 * 2 * math.pi / 0.3)
    assert default_segment_s((1.0, 40.0), 60.0) == pytest.approx(6 * math.pi)
    assert default_segment_s((5.0, 6.0), 100.0) == pytest.approx(20 * 2 * math.pi / 6.0)  # 20 cycles of the top
    est = OnlineSpectralEstimator(NAMES, ["u1"], ["y"], FS, (0.3, 20.0), window_s=60.0)
    assert est.segment_s == 30.0 and est.hop == 300
    r_usable = 3 * 2 * math.pi / est.segment_s
    assert r_usable == pytest.approx(0.628, abs=1e-3)


@pytest.mark.parametrize("kwargs, words", [
    (dict(band_rad_s=(1.0, 200.0)), "Nyquist"),
    (dict(band_rad_s=(2.0, 1.0)), "band_rad_s"),
    (dict(window_s=5.0, segment_s=8.0), "shorter than one segment"),
    (dict(segment_s=0.1), "fewer than 8 samples"),
    (dict(overlap=1.0), "overlap"),
    (dict(outputs=["zz"]), "'zz'"),
])
def test_bad_settings_are_named(kwargs, words):
    base = dict(names=NAMES, inputs=["u1"], outputs=["y"], sample_rate_hz=FS, band_rad_s=BAND, window_s=60.0)
    base.update(kwargs)
    with pytest.raises(ConfigError, match=words):
        OnlineSpectralEstimator(base.pop("names"), base.pop("inputs"), base.pop("outputs"), base.pop("sample_rate_hz"),
                                base.pop("band_rad_s"), **base)


def test_bad_block_shape_is_named():
    est = OnlineSpectralEstimator(NAMES, ["u1"], ["y"], FS, BAND, window_s=60.0, segment_s=SEG_S)
    with pytest.raises(ConfigError, match=r"shape \(3, n_new\)"):
        est.update(np.zeros((2, 10)))
    with pytest.raises(ConfigError, match="valid"):
        est.update(np.zeros((3, 10)), valid=np.ones(9, bool))


def test_conditioning_before_enough_segments_is_flagged_not_raised():
    """One segment gives a rank-1 spectral matrix: nothing to condition yet, no exception."""
    x = _record(500)
    est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=60.0, segment_s=SEG_S)
    est.update(x[:, :400])
    m = est.result().conditioned
    assert np.all(np.isnan(m.H)) and np.all(m.ill_conditioned) and np.all(np.isinf(m.random_error))


def test_results_of_one_window_share_their_spectra_and_stay_valid_after_it_moves_on():
    """While no segment enters or leaves, successive results share G and the responses (same
    numbers, later t_end_s); a result kept from earlier still holds its own window's spectra after
    the estimator has moved on (the running sums are never written in place)."""
    x = _record(4000, seed=9)
    est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=20.0, segment_s=SEG_S)
    est.update(x[:, :1610])
    r1 = est.result()
    est.update(x[:, 1610:1620])                      # 10 more samples: no segment completes (hop 80)
    r2 = est.result()
    assert r2.t_end_s > r1.t_end_s and r2.n_segments == r1.n_segments
    np.testing.assert_array_equal(r2.segment_starts, r1.segment_starts)
    assert r2.ordinary.H is r1.ordinary.H and r2.G is r1.G
    assert r2.ordinary.settings["t_end_s"] == pytest.approx(1620 / FS)
    kept = r1
    est.update(x[:, 1620:3000])                      # many segments enter and leave
    r3 = est.result()
    assert r3.segment_starts[0] > kept.segment_starts[-1] - 400
    for r in (kept, r3):
        s = r.segment_starts
        ref = window_spectra(x[:, s[0]:s[-1] + 400], NAMES, FS, SEG_S, BAND)
        assert ref.n_segments == r.n_segments
        assert _rel_err(r.G, ref.G) < TOL
        np.testing.assert_allclose(r.ordinary.H[0, 1], ref.G[1, 2] / ref.G[1, 1].real, rtol=1e-9)


def test_autospectra_and_cross_spectra_read_without_the_whole_matrix():
    """``auto`` and ``cross`` (from the running sums of the inputs' rows) equal the batch matrix;
    so does ``G`` when it is built, including the output-output block formed from the stored
    transforms."""
    rng = np.random.default_rng(10)
    n = 4000
    u = rng.standard_normal((2, n))
    y = np.vstack([np.convolve(u[0] + u[1], np.ones(5) / 5)[:n], np.convolve(u[0], [0.5, 0.3])[:n]])
    x = np.vstack([u, y + 0.1 * rng.standard_normal((2, n))])
    names = ["u1", "u2", "y1", "y2"]
    est = OnlineSpectralEstimator(names, ["u1", "u2"], ["y1", "y2"], FS, BAND, window_s=1000.0, segment_s=SEG_S)
    _feed(est, x, [250])
    r = est.result()
    ws = window_spectra(x, names, FS, SEG_S, BAND)
    np.testing.assert_allclose(r.auto, np.einsum("iif->if", ws.G).real, rtol=1e-9)
    for a, b in [("u1", "y2"), ("y2", "u1"), ("u2", "u1"), ("y1", "y2"), ("y2", "y2")]:
        i, j = names.index(a), names.index(b)
        d = np.sqrt(ws.G[i, i].real * ws.G[j, j].real)
        assert np.max(np.abs(r.cross(a, b) - ws.G[i, j]) / d) < TOL
    assert _rel_err(r.G, ws.G) < TOL
    assert not r.auto.flags.writeable and not r.G.flags.writeable


def test_a_result_made_from_a_whole_matrix_gives_the_same_responses():
    """OnlineResult built from a spectral matrix (the batch one of the same segments) reads
    everything from it: the same responses as the estimator's result, to rounding."""
    from livesweep.spectral.online import OnlineResult

    x = _record()
    est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=1000.0, segment_s=SEG_S)
    _feed(est, x, [321])
    r = est.result()
    ws = window_spectra(x, NAMES, FS, SEG_S, BAND)
    b = OnlineResult(ws.omega, ws.names, ("u1", "u2"), ("y",), ws.G, ws.n_segments, ws.n_eff, 1000.0, SEG_S,
                     r.t_end_s, 0.8, FS, r.segment_starts)
    np.testing.assert_allclose(b.ordinary.H, r.ordinary.H, rtol=1e-9)
    np.testing.assert_allclose(b.conditioned.H, r.conditioned.H, rtol=1e-8)
    np.testing.assert_allclose(b.conditioned.multiple_coherence, r.conditioned.multiple_coherence, rtol=1e-8)
    np.testing.assert_allclose(b.input_coherence, r.input_coherence, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(b.auto, r.auto, rtol=1e-9)
    np.testing.assert_allclose(b.cross("y", "u2"), ws.G[2, 1], rtol=1e-12)
    assert b.G is not ws.G and not b.G.flags.writeable


# --- the incremental result against a from-scratch numpy/scipy estimate ---------------------------

def _scipy_window(x, starts, n, hop, n_fft, fs, k0, n_f):
    """The spectral matrix of the segments ``starts`` from scratch: ``scipy.signal.csd`` (Welch,
    periodic Hann, mean removed, one-sided density, zero-padded to ``n_fft``) of every pair over the
    slice that holds exactly those segments, at bins ``k0 .. k0 + n_f - 1``."""
    from scipy.signal import csd

    seg = x[:, starts[0]:starts[-1] + n]
    m = x.shape[0]
    G = np.empty((m, m, n_f), complex)
    for i in range(m):
        _, p = csd(seg[i][None, :], seg, fs=fs, window="hann", nperseg=n, noverlap=n - hop, nfft=n_fft,
                   detrend="constant", scaling="density", return_onesided=True, average="mean")
        G[i] = p[:, k0:k0 + n_f]
    return G


def _numpy_miso(G, inputs, outputs):
    """Textbook MISO conditioning per output and frequency (Bendat & Piersol ch. 7): H solves
    Gxx H = Gxy; with C the inverse of the (inputs, output) block scaled to unit diagonal, the
    partial coherence is |C_iy|^2 / (C_ii C_yy) and the multiple coherence 1 - 1 / C_yy."""
    q, n_f = len(inputs), G.shape[-1]
    H = np.empty((len(outputs), q, n_f), complex)
    pc, mc = np.empty(H.shape), np.empty((len(outputs), n_f))
    for a, o in enumerate(outputs):
        idx = list(inputs) + [o]
        for f in range(n_f):
            S = G[np.ix_(idx, idx, [f])][..., 0]
            H[a, :, f] = np.linalg.solve(S[:q, :q], S[:q, q])
            d = np.sqrt(np.diag(S).real)
            C = np.linalg.inv(S / np.outer(d, d))
            pc[a, :, f] = np.abs(C[:q, q]) ** 2 / (np.diag(C)[:q].real * C[q, q].real)
            mc[a, f] = 1.0 - 1.0 / C[q, q].real
    return H, pc, mc


def _rel(a, ref):
    return float(np.max(np.abs(a - ref) / np.abs(ref)))


def test_sliding_result_equals_scipy_from_scratch_on_the_same_window():
    """After hundreds of segments have entered and left the window (running sums added to and
    subtracted from), the estimator's spectral matrix and its ordinary and MISO responses equal a
    from-scratch scipy/numpy estimate of the segments in the window, to 1e-9 relative."""
    rng = np.random.default_rng(21)
    n_rec, fs = 30_000, FS
    u = rng.standard_normal((3, n_rec))
    u[1] += 0.3 * u[0]                                        # partly correlated inputs
    kern = np.exp(-np.arange(40) / 8.0)
    y = np.vstack([np.convolve(u[0] - 0.4 * u[1] + 0.2 * u[2], kern)[:n_rec],
                   np.convolve(0.5 * u[2] + u[1], kern[:15])[:n_rec]]) + 0.2 * rng.standard_normal((2, n_rec))
    x = np.vstack([u, y]) + np.array([[1.0], [-2.0], [0.5], [3.0], [-1.0]])
    names = ["u1", "u2", "u3", "y1", "y2"]
    ins, outs = ["u1", "u2", "u3"], ["y1", "y2"]
    est = OnlineSpectralEstimator(names, ins, outs, fs, BAND, window_s=40.0, segment_s=SEG_S)
    n, hop, n_fft, k0 = est.n, est.hop, est.n_fft, est._k0
    checked = []

    def check(consumed):
        if consumed < 20_000 or len(checked) >= 6 or consumed % 3:
            return
        r = est.result()
        s = r.segment_starts
        np.testing.assert_array_equal(s, _expected_starts(consumed, n, hop, est._W))
        G = _scipy_window(x, s, n, hop, n_fft, fs, k0, r.omega.size)
        assert _rel_err(r.G, G) < TOL
        o = r.ordinary
        for a in range(2):
            for b in range(3):
                gxy, gxx, gyy = G[b, 3 + a], G[b, b].real, G[3 + a, 3 + a].real
                assert _rel(o.H[a, b], gxy / gxx) < TOL
                assert _rel(o.coherence[a, b], np.abs(gxy) ** 2 / (gxx * gyy)) < TOL
        H, pc, mc = _numpy_miso(G, [0, 1, 2], [3, 4])
        c = r.conditioned
        assert c.ill_conditioned.mean() < 0.1          # mostly well conditioned (compared everywhere)
        assert _rel(c.H, H) < TOL
        assert _rel(c.coherence, pc) < TOL
        assert _rel(c.multiple_coherence, mc) < TOL
        checked.append(consumed)

    _feed(est, x, [37, 400, 1, 113, 250], on_block=check)
    assert len(checked) == 6 and est.n_segment_transforms > 300


def test_referenced_responses_equal_numpy_from_scratch():
    """The references' legs conditioned from the running sums, combined (``combine_legs``), equal
    the legs conditioned from scratch per frequency with numpy on the scipy spectral matrix."""
    from livesweep.spectral.reference import combine_legs
    from livesweep.spectral.spectra import random_error as eps_of

    rng = np.random.default_rng(5)
    n_rec = 12_000
    r_ = rng.standard_normal((2, n_rec))
    d = np.convolve(rng.standard_normal(n_rec), np.ones(20) / 20)[:n_rec]          # a disturbance
    u = np.vstack([r_[0] - 0.5 * d, r_[1] + 0.3 * r_[0] + 0.2 * d])
    y = np.vstack([np.convolve(u[0] + 0.5 * u[1], np.exp(-np.arange(30) / 5.0))[:n_rec] + d,
                   np.convolve(u[1], [0.3, 0.2, 0.1])[:n_rec]]) + 0.1 * rng.standard_normal((2, n_rec))
    x = np.vstack([r_, u, y])
    names = ["r1", "r2", "u1", "u2", "y1", "y2"]
    est = OnlineSpectralEstimator(names, ["u1", "u2"], ["y1", "y2"], FS, BAND, window_s=60.0, segment_s=SEG_S,
                                  references=["r1", "r2"])
    _feed(est, x, [333])
    res = est.result()
    s = res.segment_starts
    G = _scipy_window(x, s, est.n, est.hop, est.n_fft, FS, est._k0, res.omega.size)
    Tu, pcu, _ = _numpy_miso(G, [0, 1], [2, 3])
    Ty, pcy, mcy = _numpy_miso(G, [0, 1], [4, 5])
    dof = res.n_eff - 1
    ref = combine_legs(Tu, pcu, eps_of(pcu, dof), Ty, pcy, eps_of(pcy, dof), mcy, np.zeros(res.omega.size, bool))
    rr = res.referenced
    ok = ~rr.ill_conditioned
    assert ok.sum() > 0.9 * ok.size
    assert _rel(rr.H[..., ok], ref.H[..., ok]) < TOL
    assert _rel(rr.coherence[..., ok], ref.coherence[..., ok]) < TOL
    assert _rel(rr.multiple_coherence[..., ok], ref.multiple_coherence[..., ok]) < TOL
    assert _rel(rr.random_error[..., ok], ref.random_error[..., ok]) < 1e-8


def _per_block(r, cond, targets):
    """The previous implementation: each (conditioning signals, target) block conditioned on its own."""
    q = len(cond)
    out = [online_mod._condition(r._block(list(cond) + [t]), q, r.max_input_coherence, r.n_segments)
           for t in targets]
    ill = np.logical_or.reduce([o[3] for o in out])
    return (np.array([o[0] for o in out]), np.array([o[1] for o in out]), np.array([o[2] for o in out]),
            ill | (online_mod.input_coherence_max(r._block(list(cond)), list(range(q))) > r.max_input_coherence))


@pytest.mark.parametrize("case", ["plain", "quiet output", "quiet input", "explained output", "few segments"])
def test_conditioning_all_outputs_at_once_equals_each_block_on_its_own(case):
    """The vectorised conditioning (one inverse per frequency for every output) gives the numbers,
    NaNs and flags of conditioning each output's block on its own, including quiet signals, an
    output the inputs explain exactly and too few segments."""
    rng = np.random.default_rng(3)
    n_rec = 3000
    u = rng.standard_normal((2, n_rec))
    u[1] += 0.5 * u[0]
    y = np.vstack([np.convolve(u[0] + u[1], np.ones(4) / 4)[:n_rec] + 0.3 * rng.standard_normal(n_rec),
                   np.convolve(u[1], [0.5, 0.5])[:n_rec] + 0.1 * rng.standard_normal(n_rec),
                   0.2 * u[0] + 0.1 * rng.standard_normal(n_rec)])
    if case == "quiet output":
        y[1] = 0.0
    elif case == "quiet input":
        u[1] = 0.0
    elif case == "explained output":
        y[2] = 0.7 * u[0] - 0.2 * u[1]
    x = np.vstack([u, y])
    names = ["u1", "u2", "y1", "y2", "y3"]
    est = OnlineSpectralEstimator(names, ["u1", "u2"], ["y1", "y2", "y3"], FS, BAND, window_s=60.0,
                                  segment_s=SEG_S)
    _feed(est, x[:, :480] if case == "few segments" else x, [250])
    r = est.result()
    c = r.conditioned
    H, pc, mc, ill = _per_block(r, [0, 1], [2, 3, 4])
    np.testing.assert_array_equal(c.ill_conditioned, ill)
    np.testing.assert_array_equal(np.isnan(c.H), np.isnan(H))
    if case == "explained output":
        # y3 = 0.7 u1 - 0.2 u2 exactly: H is exact, its block singular to rounding (its coherences
        # are rounding residue, as before), the other outputs unaffected
        np.testing.assert_allclose(c.H[2], np.broadcast_to([[0.7], [-0.2]], c.H[2].shape), rtol=1e-9)
        H, pc, mc, c_H, c_pc, c_mc = H[:2], pc[:2], mc[:2], c.H[:2], c.coherence[:2], c.multiple_coherence[:2]
    else:
        c_H, c_pc, c_mc = c.H, c.coherence, c.multiple_coherence
    f = np.isfinite(H)                          # compared wherever a block could be conditioned, flagged or not
    np.testing.assert_allclose(c_H[f], H[f], rtol=1e-9)
    np.testing.assert_allclose(c_pc[f], pc[f], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(c_mc[f[:, 0]], mc[f[:, 0]], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(c_pc[~f], 0.0)
    np.testing.assert_array_equal(c_mc[~f[:, 0]], 0.0)
    if case == "quiet output":
        assert np.all(c.ill_conditioned) and np.all(np.isnan(c.H[1])) and np.isfinite(c.H[[0, 2]]).all()
    elif case in ("quiet input", "few segments"):
        assert np.all(c.ill_conditioned) and np.all(np.isnan(c.H))
    else:
        assert f.mean() > 0.9


def test_condition_many_equals_condition_blocks_with_signals_quiet_at_some_frequencies():
    """``_condition_many`` against :func:`livesweep.spectral.miso.condition_blocks` on each
    (inputs, target) block, with an input quiet at some frequencies and a target at others."""
    from livesweep.spectral.miso import condition_blocks

    rng = np.random.default_rng(8)
    q, T, K, n_f = 3, 4, 12, 30
    X = rng.standard_normal((q + T, K, n_f)) + 1j * rng.standard_normal((q + T, K, n_f))
    X[q:] += 0.8 * X[0] - 0.5 * X[1]
    X[1, :, [3, 7]] = 0.0                        # an input quiet there: every target blank
    X[q + 2, :, [5, 11]] = 0.0                   # one target quiet there: that target blank
    G = np.einsum("ikf,jkf->ijf", X.conj(), X)
    auto = np.einsum("iif->if", G).real
    cond, targets = [0, 1, 2], [3, 4, 5, 6]
    H, pc, mc, ill, redo = online_mod._condition_many(G[np.ix_(cond, cond)], G[np.ix_(cond, targets)], auto[cond],
                                                      auto[targets], K, np.zeros(n_f, bool))
    assert len(redo) == 0
    for a, t in enumerate(targets):
        ref = condition_blocks(G[np.ix_(cond + [t], cond + [t])], q, max_input_coherence=2.0)
        np.testing.assert_array_equal(np.isnan(H[a]), np.isnan(ref.H))
        k = np.isfinite(ref.H)
        np.testing.assert_allclose(H[a][k], ref.H[k], rtol=1e-9)
        np.testing.assert_allclose(pc[a], ref.partial_coherence, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(mc[a], ref.multiple_coherence, rtol=1e-9, atol=1e-12)
    expected = np.zeros(n_f, bool)
    expected[[3, 5, 7, 11]] = True
    np.testing.assert_array_equal(ill, expected)


def test_later_results_of_a_window_have_every_field_of_the_first():
    """The estimator's results (made without ``__init__``) hold every field of the dataclass; a
    later result of an unchanged window the same ones as its first result, with its own time."""
    import dataclasses

    x = _record(4000, seed=4)
    valid = np.ones(x.shape[1], bool)
    valid[1500:1510] = False
    est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=20.0, segment_s=SEG_S)
    est.update(x[:, :1610], valid[:1610])
    r1 = est.result()
    est.update(x[:, 1610:1620], valid[1610:1620])
    r2 = est.result()
    assert type(r2) is type(r1)
    assert {f.name for f in dataclasses.fields(r1)} <= set(vars(r1)) and set(vars(r1)) == set(vars(r2))
    for f in dataclasses.fields(r1):
        a, b = getattr(r1, f.name), getattr(r2, f.name)
        if f.name == "t_end_s":
            assert b == pytest.approx(1620 / FS) and a == pytest.approx(1610 / FS)
        elif isinstance(a, np.ndarray):
            assert b is a
        else:
            assert b == a, f.name
    assert r2.n_excluded == r1.n_excluded > 0
    assert r2.conditioned.H is r1.conditioned.H and r2.conditioned.settings["t_end_s"] == pytest.approx(1620 / FS)
    assert "OnlineResult(" in repr(r2)


#: The ``__post_init__`` methods the cached-result shortcut was checked against
#: (``livesweep.spectral.online_result._instance_without_init``): on the values that shortcut copies
#: they do nothing (OnlineResult: no ``G`` is given and the running sums are set;
#: FrequencyResponseSet: the arrays were frozen and checked when the copied set was made, and only
#: ``settings`` changes, which it does not look at).
_POST_INIT_THE_SHORTCUT_SKIPS = {
    "FrequencyResponseSet": '''\
def __post_init__(self):
    for name in ("omega", "H", "coherence", "random_error", "multiple_coherence", "ill_conditioned"):
        object.__setattr__(self, name, _readonly(getattr(self, name)))
    want = (len(self.outputs), len(self.inputs), self.omega.size)
    for name in ("H", "coherence", "random_error"):
        if getattr(self, name).shape != want:
            raise ConfigError(f"FrequencyResponseSet: {name} has shape {getattr(self, name).shape}, "
                              f"expected (outputs, inputs, frequencies) = {want}")
''',
    "OnlineResult": '''\
def __post_init__(self, G):
    if G is None and self._sums is None:
        raise ConfigError("an OnlineResult needs its spectral matrix G")
    if G is not None:                       # given whole: everything is read from it
        G = np.asarray(G)
        if not G.flags.writeable:
            self._memo.setdefault("G", G)
        else:
            self._memo.setdefault("G", _readonly(G.copy()))
''',
}


def test_the_cached_result_shortcut_skips_no_post_init_check():
    """The per-block results of an unchanged window, and their response sets, are made without
    ``__init__`` (``online_result._instance_without_init``), so no ``__post_init__`` runs on them.
    This fails when FrequencyResponseSet or OnlineResult gains a ``__post_init__`` (or a base class
    one) or changes the one it has, so a new check cannot be skipped silently: review the shortcut,
    then update ``_POST_INIT_THE_SHORTCUT_SKIPS``. It also checks that the shortcut's copies equal
    what ``__init__`` makes from the same fields, and that the classes keep their fields in
    ``__dict__`` (no ``__slots__``), which the shortcut writes."""
    import dataclasses
    import inspect
    import textwrap

    from livesweep.spectral.online import OnlineResult
    from livesweep.spectral.response import FrequencyResponseSet

    for cls in (FrequencyResponseSet, OnlineResult):
        assert dataclasses.is_dataclass(cls) and "__slots__" not in vars(cls), cls.__name__
        owners = [c.__name__ for c in cls.__mro__ if "__post_init__" in vars(c)]
        assert owners == [cls.__name__], f"{cls.__name__}: __post_init__ defined by {owners}"
        source = textwrap.dedent(inspect.getsource(cls.__post_init__))
        assert source == _POST_INIT_THE_SHORTCUT_SKIPS[cls.__name__], (
            f"{cls.__name__}.__post_init__ changed: the cached result path skips it "
            f"(livesweep.spectral.online_result._instance_without_init); review that, then update this test")

    def same(a, b):
        if isinstance(a, np.ndarray):
            return (isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape
                    and a.flags.writeable == b.flags.writeable and np.array_equal(a, b, equal_nan=True))
        return a == b

    x = _record(4000, seed=4)
    est = OnlineSpectralEstimator(NAMES, ["u1", "u2"], ["y"], FS, BAND, window_s=20.0, segment_s=SEG_S,
                                  references=["u1", "u2"])
    est.update(x[:, :1610])
    first = est.result()
    for s in (first.ordinary, first.conditioned, first.referenced):
        assert s is not None
    est.update(x[:, 1610:1620])                          # completes no segment: the cached path
    r = est.result()
    assert r._memo is first._memo
    built = OnlineResult(G=None, **{f.name: getattr(r, f.name) for f in dataclasses.fields(OnlineResult)})
    for f in dataclasses.fields(OnlineResult):
        assert same(getattr(r, f.name), getattr(built, f.name)), f.name
    assert set(vars(r)) == set(vars(built))
    for s in (r.ordinary, r.conditioned, r.referenced):
        made = FrequencyResponseSet(**{f.name: getattr(s, f.name) for f in dataclasses.fields(FrequencyResponseSet)})
        for f in dataclasses.fields(FrequencyResponseSet):
            assert same(getattr(s, f.name), getattr(made, f.name)), f.name
