"""Auto- and cross-spectral matrices of one window length, and the random-error formula.

Convention (method.md §0, §4.3): one-sided density ``G_ij = 2 / (fs sum w^2) * mean_k conj(X_ik) X_jk``,
conjugate on the first index, so ``H = G_xy / G_xx`` (H1) and ``gamma^2 = |G_xy|^2 / (G_xx G_yy)``.
This is exactly what ``scipy.signal.csd`` computes on identical settings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.spectral.transform import bin_grid, fft_length, segment_spectra
from livesweep.spectral.windows import effective_averages, hann, plan_segments, window_samples

__all__ = ["WindowSpectra", "window_spectra", "spectral_matrix", "coherence", "debiased_coherence", "random_error"]

# A window is used only from three periods of the frequency up (method.md §4.4 says two at least):
# at two, the Hann main lobe (+/- 2 bins) reaches DC and the negative-frequency image biases the
# estimate (measured: 2-6 deg at the bottom of a sweep band; 86 % -> 92 % of points within 2 eps).
MIN_PERIODS_PER_WINDOW = 3.0


@dataclass(frozen=True)
class WindowSpectra:
    """The full spectral matrix of a set of signals for one window length.

    Attributes
    ----------
    names : tuple of str
        Signal order of the matrix.
    omega : ndarray
        Frequencies [rad/s]: the bins of this window's zero-padded FFT that cover the band
        (:func:`livesweep.spectral.transform.bin_grid`), spacing ``2 pi / (oversample T_win)`` or
        slightly finer.
    G : ndarray, complex, shape (n_signals, n_signals, n_freq)
        One-sided spectral densities [units_i units_j / Hz].
    window_s : float
        Window length [s].
    n_segments : int
        Windows averaged.
    n_eff : float
        Welch's equivalent independent averages.
    n_excluded : int
        Windows dropped because they touched missing data.
    overlap : float
    sample_rate_hz : float
    """

    names: tuple[str, ...]
    omega: np.ndarray
    G: np.ndarray
    window_s: float
    n_segments: int
    n_eff: float
    n_excluded: int
    overlap: float
    sample_rate_hz: float

    def index(self, name: str) -> int:
        return self.names.index(name)

    @property
    def omega_min_usable(self) -> float:
        """Lowest frequency with MIN_PERIODS_PER_WINDOW full periods in the window [rad/s]."""
        return MIN_PERIODS_PER_WINDOW * 2.0 * np.pi / self.window_s


def spectral_matrix(X: np.ndarray, window: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """One-sided spectral matrix ``G_ij = 2 / (fs sum w^2) mean_k conj(X_ik) X_jk``.

    Parameters
    ----------
    X : ndarray, complex, shape (n_signals, n_segments, n_freq)
        Segment transforms (:func:`livesweep.spectral.transform.segment_spectra`; fastest when
        ``np.moveaxis(X, -1, 0)`` is contiguous, as there).
    window : ndarray
        The taper the transforms used.
    sample_rate_hz : float
        [Hz].

    Returns
    -------
    ndarray, complex, shape (n_signals, n_signals, n_freq)
        [units_i units_j / Hz].
    """
    scale = 2.0 / (sample_rate_hz * float(np.sum(window**2)) * X.shape[1])
    Y = np.moveaxis(X, -1, 0)                                   # (n_freq, n_signals, n_segments)
    G = np.matmul(Y.conj(), np.swapaxes(Y, 1, 2))               # one small matrix product per frequency
    out = np.empty(G.shape[1:] + G.shape[:1], dtype=complex)
    np.multiply(np.moveaxis(G, 0, -1), scale, out=out)
    return out


def coherence(G: np.ndarray, i: int, j: int) -> np.ndarray:
    """``|G_ij|^2 / (G_ii G_jj)``, clipped to [0, 1] (0 where either autospectrum vanishes)."""
    num = np.abs(G[i, j]) ** 2
    den = (G[i, i].real * G[j, j].real)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(den > 0, num / den, 0.0)
    return np.clip(c, 0.0, 1.0)


def debiased_coherence(coh: np.ndarray, n_eff: float) -> np.ndarray:
    """Coherence with the few-averages bias removed: solves ``g + (1 - g)^2 / n = coh`` for g.

    The estimate is biased high by about ``(1 - gamma^2)^2 / n_d`` (Bendat & Piersol; method.md
    §2.5); with the handful of averages the longest windows have, that makes eps_r optimistic.
    """
    coh = np.clip(np.asarray(coh, float), 0.0, 1.0)
    n = max(float(n_eff), 1.0)
    disc = 1.0 - 4.0 * (1.0 - coh) / n
    u = np.where(disc >= 0, 0.5 * n * (1.0 - np.sqrt(np.clip(disc, 0, None))), 1.0)
    return np.clip(1.0 - u, 0.0, 1.0)


def random_error(coh: np.ndarray, n_eff: float, floor: float = 1e-6) -> np.ndarray:
    """Normalised random error of H (Bendat & Piersol; method.md §4.5).

    ``eps_r = sqrt(1 - g) / (sqrt(g) sqrt(2 n_eff))`` with ``n_eff`` Welch's equivalent number of
    independent averages (no separate C_eps: the overlap is inside n_eff) and ``g`` the measured
    coherence with its few-averages bias removed (:func:`debiased_coherence`). 1 sigma of |H| is
    about ``eps_r`` relative (8.69 eps_r dB) and of the phase ``eps_r`` rad. ``inf`` where g = 0
    (and where the coherence is NaN).

    ``1 - g`` is taken as ``2 (1 - coh) / (1 + sqrt(disc))``, the cancellation-free form of
    :func:`debiased_coherence`'s root (they agree to rounding, except that this one keeps its
    accuracy as the coherence approaches 1), so that ``eps_r^2 = (1 - coh) / (n_eff (1 +
    sqrt(disc) - 2 (1 - coh)))``.

    Parameters
    ----------
    coh : array_like
        Measured (ordinary, partial or multiple) coherence.
    n_eff : float
        Equivalent independent averages.
    floor : float
        Smallest error reported.

    Returns
    -------
    ndarray
        eps_r, same shape as ``coh``.
    """
    shape = np.shape(coh)
    u = np.array(coh, dtype=float, ndmin=1)
    np.fmax(u, 0.0, out=u)                   # NaN counts as no coherence
    np.fmin(u, 1.0, out=u)
    np.subtract(1.0, u, out=u)               # 1 - coh
    return _random_error_of_incoherence(u, n_eff, floor).reshape(shape)


def _random_error_of_incoherence(u: np.ndarray, n_eff: float, floor: float = 1e-6) -> np.ndarray:
    """:func:`random_error` from ``u = 1 - coh`` (a float array, values in [0, 1], at least 1-d),
    computed in ``u``'s own storage (which it returns)."""
    n = max(float(n_eff), 1.0)
    # 1 - g = 2 u / (1 + sqrt(d)), d = 1 - 4 u / n, so eps_r^2 = (1 - g) / (2 n_eff g)
    # = u / (n_eff (1 + sqrt(d) - 2 u)); a denominator <= 0 is g <= 0: inf
    d = u * (-4.0 / n)
    d += 1.0
    no_root = d < 0.0 if n < 2.0 else None   # for n >= 2 the denominator is <= 0 there anyway
    np.maximum(d, 0.0, out=d)
    np.sqrt(d, out=d)
    d += 1.0
    d -= u
    d -= u
    if no_root is not None:
        d[no_root] = 0.0
    np.maximum(d, 0.0, out=d)
    d *= max(float(n_eff), 1e-12)
    with np.errstate(divide="ignore", invalid="ignore"):
        u /= d
    np.sqrt(u, out=u)
    return np.maximum(u, floor, out=u)


def window_spectra(values: np.ndarray, names, sample_rate_hz: float, window_s: float, band_rad_s,
                   *, valid: np.ndarray | None = None, overlap: float = 0.8, oversample: float = 2.0) -> WindowSpectra:
    """Spectral matrix of ``values`` for one window length over the band.

    Parameters
    ----------
    values : ndarray, shape (n_signals, n_samples)
        Signals on a uniform grid.
    names : sequence of str
    sample_rate_hz : float
    window_s : float
        Window length [s].
    band_rad_s : (float, float)
        Frequency band [rad/s]; must be below Nyquist.
    valid : ndarray of bool, shape (n_samples,), optional
        Samples every signal has; windows touching a False are excluded.
    overlap : float
        Window overlap fraction (default 0.8).
    oversample : float
        Grid spacing at most ``2 pi / (oversample T_win)`` [rad/s]: the segments are zero-padded to
        ``fft_length(n, oversample) >= oversample n`` samples
        (:func:`livesweep.spectral.transform.fft_length`).

    Returns
    -------
    WindowSpectra
    """
    values = np.atleast_2d(np.asarray(values, float))
    n = window_samples(window_s, sample_rate_hz)
    if n > values.shape[1]:
        raise ConfigError(
            f"window {window_s:g} s is longer than the record ({values.shape[1] / sample_rate_hz:.1f} s)"
        )
    plan = plan_segments(values.shape[1], n, overlap, valid)
    if plan.n_segments == 0:
        raise ConfigError(f"no {window_s:g} s window fits between the data gaps of the record")
    w = hann(n)
    n_fft = fft_length(n, oversample)
    k0, omega = bin_grid(band_rad_s[0], band_rad_s[1], n_fft, sample_rate_hz)
    X = segment_spectra(values, plan.starts, n, w, n_fft, k0, omega.size)
    G = spectral_matrix(X, w, sample_rate_hz)
    return WindowSpectra(
        names=tuple(names), omega=omega, G=G, window_s=float(window_s), n_segments=plan.n_segments,
        n_eff=effective_averages(plan.n_segments, n, plan.hop, w), n_excluded=plan.n_excluded,
        overlap=float(overlap), sample_rate_hz=float(sample_rate_hz),
    )
