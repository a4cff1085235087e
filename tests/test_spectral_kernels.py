"""Spectral kernels against scipy on identical settings, and Welch/random-error theory."""

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from scipy import signal as sps

from livesweep.errors import ConfigError
from livesweep.spectral.analysis import check_settings
from livesweep.spectral.response import FrequencyResponse, FrequencyResponseSet, broken_loop
from livesweep.spectral.miso import condition_output, condition_outputs, input_coherence_max
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW, coherence, random_error, spectral_matrix, window_spectra
from livesweep.spectral.transform import bin_grid, fft_length, segment_spectra, segment_transforms
from livesweep.spectral.windows import (MIN_WINDOW_SAMPLES, default_windows_s, effective_averages, hann,
                                        plan_segments, window_samples)


def test_single_window_spectra_equal_scipy_csd_and_coherence():
    rng = np.random.default_rng(0)
    fs, n, N = 50.0, 6000, 512
    x = rng.standard_normal(n)
    y = sps.lfilter([0.2, 0.1], [1, -0.7], x) + 0.3 * rng.standard_normal(n)
    hop = int(round(0.2 * N))
    kw = dict(fs=fs, window="hann", nperseg=N, noverlap=N - hop, detrend="constant")
    f, Pxy = sps.csd(x, y, **kw)
    _, Pxx = sps.welch(x, **kw)
    _, Cxy = sps.coherence(x, y, **kw)
    k = np.arange(3, 200)                       # bins away from DC
    omega = 2 * np.pi * f[k]
    plan = plan_segments(n, N, 0.8)
    X = segment_transforms(np.vstack([x, y]), plan.starts, N, hann(N), omega, fs)
    G = spectral_matrix(X, hann(N), fs)
    np.testing.assert_allclose(G[0, 1], Pxy[k], rtol=1e-9)
    np.testing.assert_allclose(G[0, 0].real, Pxx[k], rtol=1e-9)
    np.testing.assert_allclose(coherence(G, 0, 1), Cxy[k], rtol=1e-9)
    np.testing.assert_allclose(G[0, 1] / G[0, 0], Pxy[k] / Pxx[k], rtol=1e-9)


def test_czt_off_bin_equals_direct_dft():
    rng = np.random.default_rng(1)
    x = rng.standard_normal((1, 700))
    omega = np.linspace(0.37, 11.3, 97)
    fs = 50.0
    X = segment_transforms(x, np.array([0, 100]), 400, hann(400), omega, fs)
    n = np.arange(400)
    seg = x[0, 100:500] - x[0, 100:500].mean()
    direct = (hann(400) * seg) @ np.exp(-1j * np.outer(n / fs, omega))
    np.testing.assert_allclose(X[0, 1], direct, rtol=1e-9, atol=1e-9)


def test_effective_averages_match_the_closed_form_for_hann_at_50_percent():
    N, K = 256, 12
    rho = (1 / 6) ** 2   # periodic Hann, shift N/2: overlap sum of w w' is N/16, sum of w^2 is 3N/8
    expected = K / (1 + 2 * (1 - 1 / K) * rho)
    assert effective_averages(K, N, N // 2) == pytest.approx(expected, rel=1e-9)
    assert effective_averages(K, N, N) == pytest.approx(K)


def test_random_error_formula_and_its_monte_carlo_scatter():
    # measured gamma^2 = 0.6 with 5 averages: the true coherence g satisfies g + (1-g)^2/5 = 0.6
    # (bias, method.md §2.5) -> g = 0.5615; eps = sqrt(1-g) / (sqrt(g) sqrt(2*5)) = 0.2794
    g = 1 - 2.5 * (1 - np.sqrt(1 - 4 * 0.4 / 5))
    assert g + (1 - g) ** 2 / 5 == pytest.approx(0.6)
    assert random_error(np.array([0.6]), 5.0)[0] == pytest.approx(np.sqrt(1 - g) / (np.sqrt(g) * np.sqrt(10)))
    assert random_error(np.array([0.6]), 5.0)[0] == pytest.approx(0.2794, abs=1e-4)
    # Monte Carlo: the scatter of |H| over noisy realisations agrees with eps_r within 25 %
    rng = np.random.default_rng(2)
    fs, n, N = 50.0, 5000, 500
    plan = plan_segments(n, N, 0.8)
    n_eff = effective_averages(plan.n_segments, N, plan.hop)
    omega = np.array([2.0, 5.0, 8.0])
    mags, cohs = [], []
    for _ in range(300):
        x = rng.standard_normal(n)
        y = 0.5 * x + 0.8 * rng.standard_normal(n)
        X = segment_transforms(np.vstack([x, y]), plan.starts, N, hann(N), omega, fs)
        G = spectral_matrix(X, hann(N), fs)
        mags.append(np.abs(G[0, 1] / G[0, 0]))
        cohs.append(coherence(G, 0, 1))
    scatter = np.std(mags, axis=0) / 0.5
    predicted = random_error(np.mean(cohs, axis=0), n_eff)
    np.testing.assert_allclose(scatter, predicted, rtol=0.25)


def test_segment_plan_excludes_windows_touching_gaps():
    valid = np.ones(1000, bool)
    valid[500:510] = False
    plan = plan_segments(1000, 100, 0.8, valid)
    assert plan.hop == 20
    assert all(s + 100 <= 500 or s >= 510 for s in plan.starts)
    assert plan.n_excluded == len(range(0, 901, 20)) - plan.n_segments == 5   # starts 420..500 touch 500-509


def test_default_windows_follow_the_method_and_refuse_short_records():
    w = default_windows_s(20_000, 50.0, 0.3, 20.0)                # 400 s at 50 Hz
    assert len(w) == 5 and w[0] == pytest.approx(20 * 2 * np.pi / 20.0, rel=1e-3)
    assert w[-1] == 200.0                                        # T_win,max = T_rec / 2
    with pytest.raises(ConfigError, match="needs windows of 62.8 s"):  # three periods of 0.3 rad/s
        default_windows_s(3000, 50.0, 0.3, 20.0)
    with pytest.raises(ConfigError, match="half the record is 7 samples"):
        default_windows_s(15, 50.0, 140.0, 150.0)


def test_default_windows_are_whole_samples_within_half_the_record():
    """The SIDD record of the report: 22798 samples at 400 Hz (56.995 s). Rounding half of it to
    the millisecond gave 28.498 s, which analyze refused (longer than 28.4975 s)."""
    w = default_windows_s(22798, 400.0, 1.0, 70.0)
    assert w[-1] == 11399 / 400.0
    assert [window_samples(x, 400.0) / 400.0 for x in w] == list(w)
    # a short record: the shortest window is held at 8 samples and equal counts merge
    assert default_windows_s(20, 50.0, 100.0, 150.0) == (8 / 50.0, 9 / 50.0, 10 / 50.0)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(fs=st.sampled_from([50.0, 200.0, 400.0, 1000.0]), n=st.integers(2 * MIN_WINDOW_SAMPLES, 600_000),
       margin=st.floats(1.000001, 50.0), span=st.floats(0.01, 1000.0))
@example(fs=400.0, n=22798, margin=1.5, span=60.0)        # the 56.995 s record analyze used to refuse
def test_analyze_accepts_its_default_windows_for_any_record_length(fs, n, margin, span):
    """Whatever the record length and rate, and whatever band half the record resolves
    (``margin`` x the lowest frequency it can), analyze's settings check accepts the default
    windows, and the longest is exactly half the record (rounded down to a sample)."""
    half_s = (n // 2) / fs
    lo = margin * MIN_PERIODS_PER_WINDOW * 2 * np.pi / half_s
    hi = min(lo * (1 + span), 0.99 * np.pi * fs)
    assume(lo < hi)
    k = np.arange(n)
    values = np.vstack([np.sin(0.1 * k), np.cos(0.37 * k)])
    windows = default_windows_s(n, fs, lo, hi, min_periods=MIN_PERIODS_PER_WINDOW)
    assert check_settings(values, ["u", "y"], fs, ["u"], ["y"], (lo, hi), None, None) == windows
    assert window_samples(windows[-1], fs) == n // 2
    assert all(window_samples(w, fs) >= MIN_WINDOW_SAMPLES for w in windows)


def _analytic(omega, f):
    return FrequencyResponse("y", "x", omega, f(1j * omega), np.full(omega.size, 0.9), np.full(omega.size, 0.1))


def test_frequency_response_arithmetic():
    w = np.logspace(-1, 1, 50)
    a = FrequencyResponse("b", "a", w, 1 / (1j * w + 1), np.full(50, 0.9), np.full(50, 0.1))
    b = FrequencyResponse("c", "b", w, 2 / (1j * w + 3), np.full(50, 0.8), np.full(50, 0.2))
    ab = b * a
    assert (ab.output, ab.input) == ("c", "a")
    np.testing.assert_allclose(ab.H, 2 / ((1j * w + 1) * (1j * w + 3)))
    np.testing.assert_allclose(ab.random_error, np.sqrt(0.1**2 + 0.2**2))
    np.testing.assert_allclose(ab.coherence, 0.72)
    np.testing.assert_allclose(a.inverse().H, 1j * w + 1)
    # broken loop from closed-loop data with a common reference: L = (y_fb/r)/(u/r)
    L = 5 * np.exp(-0.1j * w) / (1j * w * (0.2j * w + 1))
    yfb_r = FrequencyResponse("yfb", "r", w, L / (1 + L), np.ones(50), np.zeros(50))
    u_r = FrequencyResponse("u", "r", w, 1 / (1 + L), np.ones(50), np.zeros(50))
    np.testing.assert_allclose(broken_loop(yfb_r, u_r).H, L, rtol=1e-12)
    np.testing.assert_allclose(broken_loop(yfb_r, u_r, negative_feedback=False).H, -L, rtol=1e-12)
    with pytest.raises(ConfigError, match="different frequency grids"):
        a * FrequencyResponse("b", "a", w * 2, a.H, a.coherence, a.random_error)


def test_frequency_response_set_round_trips_through_its_dict():
    rng = np.random.default_rng(3)
    w = np.geomspace(0.3, 20, 40)
    H = rng.standard_normal((2, 2, 40)) + 1j * rng.standard_normal((2, 2, 40))
    err = rng.uniform(0.01, 0.3, (2, 2, 40))
    err[0, 0, 0] = np.inf
    s = FrequencyResponseSet(("p", "r"), ("da", "dr"), w, H, rng.uniform(0, 1, (2, 2, 40)), err, True,
                             rng.uniform(0, 1, (2, 40)), rng.uniform(0, 1, 40) > 0.5, {"windows_s": [7.0, 20.0]})
    back = FrequencyResponseSet.from_dict(s.to_dict())
    for name in ("omega", "H", "coherence", "random_error", "multiple_coherence", "ill_conditioned"):
        np.testing.assert_array_equal(getattr(back, name), getattr(s, name))
    assert back.settings == s.settings and back.conditioned
    one = FrequencyResponse.from_dict(s.pair("r", "da").to_dict())
    np.testing.assert_allclose(one.H, s.H[1, 0], rtol=1e-12)
    np.testing.assert_allclose(one.magnitude_db, 20 * np.log10(np.abs(s.H[1, 0])))


# ---------------------------------------------------------------------------------------------
# zero-padded FFT evaluation (the grid the spectral code uses)
# ---------------------------------------------------------------------------------------------

def _five_smooth(k):
    for p in (2, 3, 5):
        while k % p == 0:
            k //= p
    return k == 1


@pytest.mark.parametrize("n, oversample", [(400, 2.0), (377, 2.0), (1000, 2.0), (1024, 1.0), (999, 3.0)])
def test_fft_length_is_fast_and_at_least_as_dense_as_asked(n, oversample):
    n_fft = fft_length(n, oversample)
    assert n_fft >= oversample * n - 1e-9 and _five_smooth(n_fft)
    assert n_fft < 1.1 * oversample * n + 8                        # the next fast length, not far beyond
    fs = 50.0
    k0, omega = bin_grid(0.7, 11.3, n_fft, fs)
    step = 2 * np.pi * fs / n_fft
    assert step <= 2 * np.pi / (oversample * n / fs) * (1 + 1e-12)  # same or denser than asked
    np.testing.assert_allclose(omega, step * np.arange(k0, k0 + omega.size), rtol=1e-14)
    assert omega[0] <= 0.7 < omega[1] and omega[-2] < 11.3 <= omega[-1]  # the band, covered, no more
    k0e, omega_e = bin_grid(5 * step, 20 * step, n_fft, fs)          # band edges on bins are those bins
    assert k0e == 5 and omega_e.size == 16
    with pytest.raises(ConfigError, match="Nyquist"):
        bin_grid(1.0, np.pi * fs, n_fft, fs)


def test_segment_spectra_equal_a_direct_dft_and_the_chirp_z_at_the_bins():
    """Irregular starts (a gap) and several blocks of segments; offsets that the mean removal
    must take out."""
    rng = np.random.default_rng(4)
    fs, N, n = 100.0, 20_000, 1000
    x = rng.standard_normal((3, N)).cumsum(axis=1) * 0.05 + np.array([[3.0], [-250.0], [1e4]])
    plan = plan_segments(N, n, 0.8)
    starts = np.concatenate([plan.starts[:40], plan.starts[47:]])  # irregular: as around a data gap
    n_fft = fft_length(n)
    k0, omega = bin_grid(0.5, 40.0, n_fft, fs)
    w = hann(n)
    X = segment_spectra(x, starts, n, w, n_fft, k0, omega.size)
    assert X.shape == (3, starts.size, omega.size)
    # independent reference: the DTFT sum of the tapered, mean-removed segment at each bin
    E = np.exp(-1j * np.outer(np.arange(n) / fs, omega))
    for s_idx in (0, 39, 40, starts.size - 1):
        seg = x[:, starts[s_idx]:starts[s_idx] + n]
        direct = ((seg - seg.mean(axis=1, keepdims=True)) * w) @ E
        np.testing.assert_allclose(X[:, s_idx], direct, rtol=0, atol=1e-9 * np.abs(direct).max())
    Xc = segment_transforms(x, starts, n, w, omega, fs)             # chirp-z on the same frequencies
    np.testing.assert_allclose(X, Xc, rtol=0, atol=1e-9 * np.abs(Xc).max())


def test_window_spectra_equal_scipy_csd_with_the_same_zero_padding():
    rng = np.random.default_rng(5)
    fs, N = 50.0, 9000
    x = rng.standard_normal(N)
    y = sps.lfilter([0.2, 0.1], [1, -0.7], x) + 0.3 * rng.standard_normal(N) + 7.0
    window_s = 7.54                                                 # 377 samples: 2 n = 754 is not a fast length
    ws = window_spectra(np.vstack([x, y]), ["x", "y"], fs, window_s, (0.9, 20.0), overlap=0.8)
    n = 377
    n_fft = fft_length(n)
    assert n_fft == 768
    hop = int(round(0.2 * n))
    kw = dict(fs=fs, window="hann", nperseg=n, noverlap=n - hop, nfft=n_fft, detrend="constant")
    f, Pxy = sps.csd(x, y, **kw)
    _, Pxx = sps.welch(x, **kw)
    _, Cxy = sps.coherence(x, y, **kw)
    k = np.flatnonzero(np.isin(np.round(f * n_fft / fs).astype(int), np.round(ws.omega * n_fft / (2 * np.pi * fs))))
    np.testing.assert_allclose(ws.omega, 2 * np.pi * f[k], rtol=1e-12)
    np.testing.assert_allclose(ws.G[0, 1], Pxy[k], rtol=1e-9)
    np.testing.assert_allclose(ws.G[0, 0].real, Pxx[k], rtol=1e-9)
    np.testing.assert_allclose(coherence(ws.G, 0, 1), Cxy[k], rtol=1e-9)


@settings(max_examples=200, deadline=None)
@given(one_minus_coh=st.floats(1e-14, 1.0), n_eff=st.floats(1.0, 1000.0))
def test_random_error_matches_a_50_digit_evaluation(one_minus_coh, n_eff):
    """eps_r against the closed form evaluated in 50-digit decimal arithmetic (independent of
    numpy), including coherences within 1e-14 of 1 where the textbook root cancels."""
    from decimal import Decimal, getcontext

    getcontext().prec = 50
    coh = 1.0 - one_minus_coh                                        # the double the function gets
    u, n = 1 - Decimal(coh), Decimal(n_eff)                          # exact: a double is a finite decimal
    disc = 1 - 4 * u / n
    if disc < 0:
        expected = np.inf
    else:
        one_minus_g = n / 2 * (1 - disc.sqrt())                     # smaller root of g + (1 - g)^2 / n = coh
        g = 1 - one_minus_g
        expected = np.inf if g <= 0 else max(float((one_minus_g / (2 * n * g)).sqrt()), 1e-6)
        g = float(g)
    got = float(random_error(np.array([coh]), n_eff)[0])
    if np.isinf(expected):
        assert np.isinf(got)
    else:
        # where g nears 0, eps_r moves by ~ulp / g for one ulp of coherence: the tolerance says so
        assert got == pytest.approx(expected, rel=1e-12 + 4e-16 / g)


def test_random_error_keeps_the_shape_and_treats_nan_as_no_coherence():
    assert np.shape(random_error(0.6, 5.0)) == ()
    assert random_error(np.full((2, 3), 0.6), 5.0).shape == (2, 3)
    e = random_error(np.array([np.nan, 0.0, 1.0]), 5.0)
    assert np.isinf(e[0]) and np.isinf(e[1]) and e[2] == 1e-6


def test_conditioning_equals_the_schur_complement_formulas():
    """condition_blocks (inverse of the unit-diagonal block) against an independent per-frequency
    evaluation: H = Gxx^-1 g, noise Gnn = Gyy - g^H H, multiple coherence 1 - Gnn / Gyy, partial
    coherence |H_i|^2 / (|H_i|^2 + Gnn [Gxx^-1]_ii)."""
    rng = np.random.default_rng(6)
    q, n_out, n_f, K = 3, 4, 7, 40
    X = rng.standard_normal((q + n_out, K, n_f)) + 1j * rng.standard_normal((q + n_out, K, n_f))
    X[q:] += 0.8 * np.einsum("oi,ikf->okf", rng.standard_normal((n_out, q)), X[:q])
    X[1] += 0.5 * X[0]                                               # correlated inputs
    G = np.einsum("ikf,jkf->ijf", X.conj(), X) / K
    c = condition_outputs(G, list(range(q)), list(range(q, q + n_out)), max_input_coherence=0.5)
    for a, o in enumerate(range(q, q + n_out)):
        one = condition_output(G, list(range(q)), o)
        np.testing.assert_allclose(c.H[a], one.H, rtol=1e-13)
        for f in range(n_f):
            A, g, gyy = G[:q, :q, f], G[:q, o, f], G[o, o, f].real
            H = np.linalg.solve(A, g)
            gnn = gyy - np.real(np.conj(g) @ H)
            Ainv = np.linalg.inv(A)
            np.testing.assert_allclose(c.H[a, :, f], H, rtol=1e-10)
            np.testing.assert_allclose(c.multiple_coherence[a, f], 1 - gnn / gyy, rtol=1e-10)
            pc = np.abs(H) ** 2 / (np.abs(H) ** 2 + gnn * np.real(np.diag(Ainv)))
            np.testing.assert_allclose(c.partial_coherence[a, :, f], pc, rtol=1e-9)
    coh01 = np.abs(G[0, 1]) ** 2 / (G[0, 0].real * G[1, 1].real)
    assert np.all(input_coherence_max(G, [0, 1, 2]) >= coh01 - 1e-15)
    np.testing.assert_array_equal(c.ill_conditioned[0], input_coherence_max(G, [0, 1, 2]) > 0.5)
