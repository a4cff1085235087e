"""Chirp-z transforms of tapered segments on a dense frequency grid inside the band (method.md §4.2).

``X(w_k) = sum_n w_n (x_n - mean) exp(-j w_k n dt)`` for ``w_k = w_0 + k dw``, evaluated for every
segment and signal with scipy's chirp-z transform, a block of segments at a time (the tapered
segments of a long record overlap 5 to 20 times over, so holding them all at once would take 5 to
20 copies of the record). The grid spacing is half the window's resolution ``2 pi / T_win`` by
default: the CZT only samples the spectrum more densely, the true resolution stays that of the
window.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.signal import CZT

from livesweep.errors import ConfigError

__all__ = ["uniform_grid", "segment_transforms"]

#: Tapered segment samples (all signals) transformed per block: 128 MB of float64 at a time.
_BLOCK_SAMPLES = 2**24


def uniform_grid(omega_lo: float, omega_hi: float, window_s: float, oversample: float = 2.0) -> np.ndarray:
    """Uniform grid [rad/s] from ``omega_lo`` to ``omega_hi`` with spacing ``2 pi / (oversample T_win)``."""
    step = 2.0 * math.pi / (oversample * window_s)
    n = max(2, int(math.ceil((omega_hi - omega_lo) / step)) + 1)
    return np.linspace(omega_lo, omega_hi, n)


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
    transform = CZT(n_per_window, m=omega.size, w=np.exp(-1j * step * dt), a=np.exp(1j * omega[0] * dt))
    out = np.empty((x.shape[0], len(starts), omega.size), dtype=complex)
    block = max(1, _BLOCK_SAMPLES // (x.shape[0] * n_per_window))
    for a in range(0, len(starts), block):
        seg = view[:, starts[a:a + block], :]
        seg = seg - seg.mean(axis=-1, keepdims=True)
        out[:, a:a + block] = transform(seg * window, axis=-1)
    return out
