"""Overlapped, tapered windows: the segment plan, the Hann taper, and Welch's effective averages.

A window of ``n`` samples is taken every ``hop = round((1 - overlap) n)`` samples (docs/method.md
§4.1: Hann, 80 % overlap). A segment that touches an invalid sample (a long gap the resampler
refused to interpolate) is excluded: no window ever spans missing data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError

__all__ = ["hann", "SegmentPlan", "plan_segments", "effective_averages", "MIN_WINDOW_SAMPLES", "window_samples",
           "longest_window_samples", "default_windows_s"]

#: Fewest samples a spectral window may hold.
MIN_WINDOW_SAMPLES = 8


def window_samples(window_s: float, sample_rate_hz: float) -> int:
    """Samples in a window of ``window_s`` [s] at ``sample_rate_hz`` [Hz], ``round(window_s * fs)``.

    The one conversion the settings check, the default windows and the spectra all use.
    """
    return int(round(window_s * sample_rate_hz))


def longest_window_samples(n_samples: int) -> int:
    """Longest window [samples] allowed in a record of ``n_samples``: half of it, rounded down
    (so that several windows are averaged)."""
    return int(n_samples) // 2


def hann(n: int) -> np.ndarray:
    """Periodic (DFT-even) Hann taper of ``n`` samples, ``0.5 (1 - cos(2 pi k / n))``.

    The same taper as scipy's ``"hann_periodic"`` (its default since 1.17), so single-window
    spectra equal ``scipy.signal.csd`` on identical settings.
    """
    k = np.arange(n)
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * k / n)


@dataclass(frozen=True)
class SegmentPlan:
    """Where the windows of one length sit in a record.

    Attributes
    ----------
    n_per_window : int
        Samples per window.
    hop : int
        Samples between window starts.
    starts : ndarray of int
        Start index of every window used.
    n_excluded : int
        Windows dropped because they touch invalid samples.
    """

    n_per_window: int
    hop: int
    starts: np.ndarray
    n_excluded: int

    @property
    def n_segments(self) -> int:
        return int(self.starts.size)


def plan_segments(n_samples: int, n_per_window: int, overlap: float, valid: np.ndarray | None = None) -> SegmentPlan:
    """Window starts for a record of ``n_samples``.

    Parameters
    ----------
    n_samples : int
        Record length [samples].
    n_per_window : int
        Window length [samples]; at most ``n_samples``.
    overlap : float
        Fraction of a window shared with the next, 0 <= overlap < 1.
    valid : ndarray of bool, shape (n_samples,), optional
        False where a sample is missing; windows touching one are excluded.

    Returns
    -------
    SegmentPlan
    """
    if not 0.0 <= overlap < 1.0:
        raise ConfigError(f"overlap must be in [0, 1), got {overlap!r}")
    if n_per_window < 2 or n_per_window > n_samples:
        raise ConfigError(f"a window of {n_per_window} samples does not fit a record of {n_samples} samples")
    hop = max(1, int(round((1.0 - overlap) * n_per_window)))
    starts = np.arange(0, n_samples - n_per_window + 1, hop)
    n_excluded = 0
    if valid is not None:
        bad = np.concatenate([[0], np.cumsum(~np.asarray(valid, bool))])
        ok = bad[starts + n_per_window] - bad[starts] == 0
        n_excluded = int(np.sum(~ok))
        starts = starts[ok]
    return SegmentPlan(n_per_window, hop, starts, n_excluded)


def effective_averages(n_segments: int, n_per_window: int, hop: int, window: np.ndarray | None = None) -> float:
    """Welch's equivalent number of independent averages for overlapped windows.

    ``n_eff = K / [1 + 2 sum_{j=1}^{K-1} (1 - j/K) rho(j D)]`` with ``rho(s) = (sum w_n w_{n+s})^2 /
    (sum w_n^2)^2`` (docs/method.md §4.5). For Hann at 80 % overlap this is about 1.9x the number of
    non-overlapped windows, consistent with C_eps ~ 0.74 when n_d = T_rec/T_win.

    Parameters
    ----------
    n_segments : int
        K, windows averaged.
    n_per_window : int
    hop : int
        D [samples].
    window : ndarray, optional
        The taper (default Hann).

    Returns
    -------
    float
        n_eff (>= 1 when K >= 1, 0 when K = 0).
    """
    K = int(n_segments)
    if K <= 0:
        return 0.0
    w = hann(n_per_window) if window is None else np.asarray(window, float)
    w2 = float(np.sum(w * w))
    total = 0.0
    for j in range(1, K):
        s = j * hop
        if s >= w.size:
            break
        rho = (float(np.dot(w[:-s], w[s:])) / w2) ** 2
        total += (1.0 - j / K) * rho
    return K / (1.0 + 2.0 * total)


def default_windows_s(n_samples: int, sample_rate_hz: float, omega_min_rad_s: float, omega_max_rad_s: float,
                      n_windows: int = 5, min_periods: float = 3.0) -> tuple[float, ...]:
    """Window lengths for a record and band (docs/method.md §4.4), geometrically spaced.

    Shortest ``20 * 2 pi / omega_max`` (20 cycles of the highest frequency), at most a quarter of
    the longest and at least :data:`MIN_WINDOW_SAMPLES`; longest half the record (several
    averages), :func:`longest_window_samples`. Long windows matter: the windowing bias of a sweep's
    response falls with window length (measured on the XV-15 roll response at 0.34 rad/s: phase
    error -6.8, -2.0, -0.6 deg for 44, 84 and 160 s windows).

    Every length is a whole number of samples, ``k / sample_rate_hz`` with ``k`` the count
    :func:`window_samples` gives back, so the defaults always pass the check they are made for.

    Parameters
    ----------
    n_samples : int
        Record length [samples].
    sample_rate_hz : float
    omega_min_rad_s, omega_max_rad_s : float
        The band [rad/s].
    n_windows : int
        Window lengths wanted; fewer when a short record rounds two to the same sample count.
    min_periods : float
        Periods of ``omega_min`` the longest window must hold.

    Returns
    -------
    tuple of float
        Window lengths [s], ascending.

    Raises
    ------
    ConfigError
        When half the record cannot hold ``min_periods`` periods of ``omega_min``, or fewer than
        :data:`MIN_WINDOW_SAMPLES` samples.
    """
    n_max = longest_window_samples(n_samples)
    t_max = n_max / sample_rate_hz
    needed = min_periods * 2.0 * math.pi / omega_min_rad_s
    if t_max < needed:
        raise ConfigError(
            f"band_rad_s starts at {omega_min_rad_s:g} rad/s, which needs windows of {needed:.1f} s "
            f"({min_periods:g} periods); half the record is only {t_max:.1f} s: raise the band's lower end to at "
            f"least {min_periods * 2 * math.pi / t_max:.3g} rad/s or fly a longer record"
        )
    if n_max < MIN_WINDOW_SAMPLES:
        raise ConfigError(f"half the record is {n_max} samples; a spectral window needs at least "
                          f"{MIN_WINDOW_SAMPLES}: fly a longer record")
    t_min = min(20.0 * 2.0 * math.pi / omega_max_rad_s, t_max / 4.0)
    n_min = max(MIN_WINDOW_SAMPLES, window_samples(t_min, sample_rate_hz))
    counts = np.unique(np.round(np.geomspace(n_min, n_max, n_windows)).astype(np.int64))
    return tuple(float(k) / sample_rate_hz for k in counts)
