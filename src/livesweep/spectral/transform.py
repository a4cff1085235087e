"""Fourier transforms of tapered segments on a dense frequency grid inside the band (method.md §4.2).

``X(w_k) = sum_n w_n (x_n - mean) exp(-j w_k n dt)``, evaluated for every segment and signal.

Two evaluators:

* :func:`segment_spectra` (what the spectral code uses): a real FFT of every tapered,
  mean-removed segment zero-padded to ``n_fft >= oversample n`` samples (:func:`fft_length`), kept
  at the FFT bins inside the band (:func:`bin_grid`). With the default ``oversample = 2`` the grid
  spacing is half the window's resolution, ``2 pi / (2 T_win)``, or slightly finer: zero padding
  only samples the spectrum more densely, the true resolution stays that of the window. Segments
  are transformed a block at a time (the tapered segments of a long record overlap 5 to 20 times
  over, so holding them all at once would take 5 to 20 copies of the record).
* :func:`segment_transforms`: the chirp-z transform on any uniform grid (:func:`uniform_grid`),
  for frequencies that are not FFT bins. It costs about twice the zero-padded FFT for the same
  grid density.

Both give the same numbers at the same frequencies (to rounding; a test says so).
"""

from __future__ import annotations

import math
import threading

import numpy as np
import scipy.fft
from numpy.lib.stride_tricks import as_strided, sliding_window_view

from livesweep.errors import ConfigError

__all__ = ["uniform_grid", "segment_transforms", "fft_length", "bin_grid", "segment_spectra"]

#: Tapered segment samples (all signals) transformed per block: 128 MB of float64 at a time.
_BLOCK_SAMPLES = 2**24

#: Zero-padded samples (all signals) per real-FFT block of :func:`segment_spectra`: 1 MB of
#: float64, so that a block's buffer and transform stay in cache.
_FFT_BLOCK_SAMPLES = 2**17

#: Per thread, the zero-padded input and the output of the last few block shapes, reused from call
#: to call (a live estimator transforms one segment per call: fresh megabyte buffers would cost
#: more in page faults than the FFT itself).
_scratch = threading.local()


def _fft_buffers(n_sig: int, block: int, n_fft: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Zero-padded input (zeros from sample ``n`` on) and output buffers for blocks of segments."""
    cache = getattr(_scratch, "buffers", None)
    if cache is None:
        cache = _scratch.buffers = {}
    key = (n_sig, block, n_fft, n)
    bufs = cache.pop(key, None)
    if bufs is None:
        bufs = (np.zeros((n_sig, block, n_fft)), np.empty((n_sig, block, n_fft // 2 + 1), complex))
        while len(cache) >= 4:
            cache.pop(next(iter(cache)))
    cache[key] = bufs                      # most recently used last
    return bufs


def uniform_grid(omega_lo: float, omega_hi: float, window_s: float, oversample: float = 2.0) -> np.ndarray:
    """Uniform grid [rad/s] from ``omega_lo`` to ``omega_hi`` with spacing ``2 pi / (oversample T_win)``."""
    step = 2.0 * math.pi / (oversample * window_s)
    n = max(2, int(math.ceil((omega_hi - omega_lo) / step)) + 1)
    return np.linspace(omega_lo, omega_hi, n)


def fft_length(n_per_window: int, oversample: float = 2.0) -> int:
    """Length of the zero-padded FFT of a window of ``n_per_window`` samples [samples].

    The smallest length at or above ``oversample * n_per_window`` whose prime factors are 2, 3
    and 5 (``scipy.fft.next_fast_len``): the bin spacing ``2 pi fs / n_fft`` [rad/s] is then
    ``2 pi / (oversample T_win)`` or slightly finer, and the transform never falls on a slow
    length (an awkward factor such as 13 x 29 doubles the cost of a 7540-point FFT).

    Parameters
    ----------
    n_per_window : int
        Window length [samples].
    oversample : float
        Bins per resolution cell ``2 pi / T_win``; at least 1.

    Returns
    -------
    int
    """
    if not oversample >= 1.0:
        raise ConfigError(f"oversample must be at least 1, got {oversample!r}")
    return int(scipy.fft.next_fast_len(max(int(n_per_window), int(math.ceil(oversample * n_per_window - 1e-9))),
                                       real=True))


def bin_grid(omega_lo: float, omega_hi: float, n_fft: int, sample_rate_hz: float) -> tuple[int, np.ndarray]:
    """The FFT bins that cover a band: the first bin's index and the bin frequencies [rad/s].

    Bins ``k0 .. k1`` of an ``n_fft``-point FFT at ``sample_rate_hz``, spacing ``2 pi fs / n_fft``,
    with ``k0`` the last bin at or below ``omega_lo`` and ``k1`` the first at or above
    ``omega_hi`` (a band edge within 1e-9 of a bin is that bin), at least two bins.

    Parameters
    ----------
    omega_lo, omega_hi : float
        Band [rad/s], ``0 <= omega_lo < omega_hi < pi fs``.
    n_fft : int
        FFT length [samples].
    sample_rate_hz : float
        [Hz].

    Returns
    -------
    k0 : int
        Index of the first bin.
    omega : ndarray, shape (k1 - k0 + 1,)
        Bin frequencies ``k * 2 pi fs / n_fft`` [rad/s].
    """
    nyq = math.pi * sample_rate_hz
    if omega_hi >= nyq:
        raise ConfigError(f"frequency {omega_hi:g} rad/s is at or above Nyquist ({nyq:g} rad/s)")
    step = 2.0 * math.pi * sample_rate_hz / n_fft
    k0 = max(0, int(math.floor(omega_lo / step + 1e-9)))
    k1 = min(n_fft // 2, max(k0 + 1, int(math.ceil(omega_hi / step - 1e-9))))
    k0 = min(k0, k1 - 1)
    return k0, np.arange(k0, k1 + 1) * step


def segment_spectra(x: np.ndarray, starts: np.ndarray, n_per_window: int, window: np.ndarray, n_fft: int,
                    k0: int, n_bins: int) -> np.ndarray:
    """Zero-padded real FFTs of every tapered, mean-removed segment, at bins ``k0 .. k0 + n_bins - 1``.

    ``X_k = sum_n w_n (x_n - mean(x)) exp(-2 pi j k n / n_fft)`` for every segment ``x`` of
    ``n_per_window`` samples starting at ``starts`` -- the discrete-time Fourier transform of the
    tapered segment at ``w_k = 2 pi k fs / n_fft`` [rad/s], with the phase referred to the
    segment's first sample (as :func:`segment_transforms`). The mean is removed and the taper
    applied while the segment is copied into the zero-padded buffer.

    Parameters
    ----------
    x : ndarray, shape (n_signals, n_samples)
        Signals on a uniform grid. Samples no segment touches may be non-finite.
    starts : ndarray of int
        Segment start indices [samples].
    n_per_window : int
        Segment length [samples].
    window : ndarray, shape (n_per_window,)
        Taper.
    n_fft : int
        Zero-padded FFT length [samples], at least ``n_per_window`` (:func:`fft_length`).
    k0 : int
        First bin kept (:func:`bin_grid`).
    n_bins : int
        Bins kept; ``k0 + n_bins - 1 <= n_fft // 2``.

    Returns
    -------
    ndarray, complex, shape (n_signals, n_segments, n_bins)
        A view of frequency-major storage (``np.moveaxis(X, -1, 0)`` is contiguous).
    """
    x = np.atleast_2d(np.asarray(x, float))
    starts = np.asarray(starts, dtype=np.intp)
    n = int(n_per_window)
    window = np.asarray(window, float)
    if n_fft < n or k0 < 0 or k0 + n_bins - 1 > n_fft // 2:
        raise ConfigError(f"bins {k0}..{k0 + n_bins - 1} of a {n_fft}-point FFT of {n}-sample segments do not exist")
    n_sig = x.shape[0]
    # frequency-major storage: the spectral matrix is then one batched matrix product per bin
    out = np.empty((n_bins, n_sig, starts.size), dtype=complex)
    if starts.size == 0:
        return np.moveaxis(out, 0, -1)
    if x.shape[1] < n:
        raise ConfigError(f"segments of {n} samples do not fit {x.shape[1]} samples")
    s0, s1 = x.strides
    view = as_strided(x, shape=(n_sig, x.shape[1] - n + 1, n), strides=(s0, s1, s1), writeable=False)
    kept = slice(k0, k0 + n_bins)
    block = min(max(1, _FFT_BLOCK_SAMPLES // (n_sig * n_fft)), starts.size)
    buf, spec = _fft_buffers(n_sig, block, n_fft, n)
    for a in range(0, starts.size, block):
        s = starts[a:a + block]
        m = s.size
        step = int(s[1] - s[0]) if m > 1 else 1
        if step > 0 and np.all(np.diff(s) == step):
            seg = view[:, s[0]:s[-1] + 1:step, :]            # evenly spaced starts: a view, no copy
        else:
            seg = view[:, s, :]
        head = buf[:, :m, :n]
        np.subtract(seg, seg.mean(axis=-1, keepdims=True), out=head)
        head *= window
        X = np.fft.rfft(buf[:, :m], axis=-1, out=spec[:, :m])
        out[:, :, a:a + m] = np.moveaxis(X[..., kept], -1, 0)
    return np.moveaxis(out, 0, -1)


def segment_transforms(x: np.ndarray, starts: np.ndarray, n_per_window: int, window: np.ndarray,
                       omega: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """Chirp-z transforms of every tapered, mean-removed segment of every signal.

    Parameters
    ----------
    x : ndarray, shape (n_signals, n_samples)
    starts : ndarray of int
        Segment start indices.
    n_per_window : int
    window : ndarray, shape (n_per_window,)
        Taper.
    omega : ndarray
        Uniformly spaced frequencies [rad/s] (from :func:`uniform_grid`).
    sample_rate_hz : float

    Returns
    -------
    ndarray, complex, shape (n_signals, n_segments, n_freq)
    """
    omega = np.asarray(omega, float)
    dt = 1.0 / sample_rate_hz
    if omega[-1] >= math.pi * sample_rate_hz:
        raise ConfigError(f"frequency {omega[-1]:g} rad/s is at or above Nyquist ({math.pi * sample_rate_hz:g} rad/s)")
    d = np.diff(omega)
    if omega.size > 1 and not np.allclose(d, d[0], rtol=1e-9, atol=0):
        raise ConfigError("segment_transforms needs a uniformly spaced grid")
    x = np.atleast_2d(np.asarray(x, float))
    view = sliding_window_view(x, n_per_window, axis=-1)
    step = d[0] if omega.size > 1 else 0.0
    from scipy.signal import CZT      # here: scipy.signal costs 0.3 s to import and the pipeline never calls this

    transform = CZT(n_per_window, m=omega.size, w=np.exp(-1j * step * dt), a=np.exp(1j * omega[0] * dt))
    out = np.empty((x.shape[0], len(starts), omega.size), dtype=complex)
    block = max(1, _BLOCK_SAMPLES // (x.shape[0] * n_per_window))
    for a in range(0, len(starts), block):
        seg = view[:, starts[a:a + block], :]
        seg = seg - seg.mean(axis=-1, keepdims=True)
        out[:, a:a + block] = transform(seg * window, axis=-1)
    return out
