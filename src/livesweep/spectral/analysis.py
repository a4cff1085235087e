"""From uniformly sampled signals to frequency-response sets (the FRESPID/MISOSA/COMPOSITE chain).

``analyze`` checks the settings against the record, computes one spectral matrix per window
length (overlapped Hann windows, zero-padded FFT on a dense grid), then composites them onto a common
log-spaced grid: ordinary (SISO) responses for every pair and, with more than one input,
MISO-conditioned responses with partial and multiple coherences. With one exogenous reference per
input (a closed-loop test point's logged sweep injection), it also forms the responses through the
references, free of the feedback bias (:mod:`livesweep.spectral.reference`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.limits import MAX_SPECTRAL_VALUES, window_spectra_values
from livesweep.spectral.composite import composite_miso, composite_siso, interpolate_windows
from livesweep.spectral.miso import input_coherence_max
from livesweep.spectral.reference import reference_responses
from livesweep.spectral.response import FrequencyResponseSet
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW, window_spectra
from livesweep.spectral.windows import (MIN_WINDOW_SAMPLES, default_windows_s, longest_window_samples,
                                        window_samples)

__all__ = ["SpectralAnalysis", "analyze", "check_settings"]


@dataclass(frozen=True)
class SpectralAnalysis:
    """Result of :func:`analyze`.

    Attributes
    ----------
    siso : FrequencyResponseSet
        Ordinary responses of every output to every input (not conditioned).
    miso : FrequencyResponseSet or None
        Conditioned responses (more than one input), else None.
    windows : tuple of WindowSpectra
        The per-window spectral matrices the composite was made from.
    referenced : FrequencyResponseSet or None
        Responses through the references, ``(y/r)(u/r)^-1``, when references were given.
    """

    siso: FrequencyResponseSet
    miso: FrequencyResponseSet | None
    windows: tuple
    referenced: FrequencyResponseSet | None = None

    @property
    def best(self) -> FrequencyResponseSet:
        """The referenced set when there is one, else the conditioned set, else the ordinary set."""
        if self.referenced is not None:
            return self.referenced
        return self.miso if self.miso is not None else self.siso


def check_settings(values: np.ndarray, names, sample_rate_hz: float, inputs, outputs, band_rad_s,
                   windows_s, valid, references=()) -> tuple[float, ...]:
    """Validate band, windows and signals against the record; return the window lengths [s]."""
    names = list(names)
    references = list(references or ())
    if references and len(references) != len(inputs):
        raise ConfigError(f"one reference per input: {len(references)} references for {len(inputs)} inputs")
    for n in list(inputs) + list(outputs) + references:
        if n not in names:
            raise ConfigError(f"signal {n!r} is not in the record (signals: {', '.join(names)})")
    if not inputs or not outputs:
        raise ConfigError("spectral analysis needs at least one input and one output")
    lo, hi = float(band_rad_s[0]), float(band_rad_s[1])
    nyq = math.pi * sample_rate_hz
    if not (0 < lo < hi):
        raise ConfigError(f"band_rad_s = [{lo:g}, {hi:g}] must satisfy 0 < low < high")
    if hi >= nyq:
        raise ConfigError(f"band_rad_s upper end {hi:g} rad/s is at or above Nyquist ({nyq:.1f} rad/s at {sample_rate_hz:g} Hz)")
    ok = np.ones(values.shape[1], bool) if valid is None else np.asarray(valid, bool)
    for k, n in enumerate(names):
        if n not in inputs and n not in outputs and n not in references:
            continue
        x = values[k][ok]
        if x.size == 0 or not np.any(np.isfinite(x)):
            raise ConfigError(f"signal {n!r} has no valid samples")
        if np.nanstd(x) == 0:
            raise ConfigError(f"signal {n!r} is constant ({x[0]:g}): nothing to identify from")
    n_samples = values.shape[1]
    n_longest = longest_window_samples(n_samples)
    t_longest = n_longest / sample_rate_hz
    if windows_s is None:
        windows_s = default_windows_s(n_samples, sample_rate_hz, lo, hi, min_periods=MIN_PERIODS_PER_WINDOW)
    windows_s = tuple(float(w) for w in windows_s)
    for w in windows_s:
        n = window_samples(w, sample_rate_hz)
        if n > n_longest:
            raise ConfigError(f"window {w:g} s ({n} samples) is longer than half the record ({n_longest} of "
                              f"{n_samples} samples, {t_longest:g} s at {sample_rate_hz:g} Hz)")
        if n < MIN_WINDOW_SAMPLES:
            raise ConfigError(f"window {w:g} s holds {n} samples at {sample_rate_hz:g} Hz, fewer than "
                              f"{MIN_WINDOW_SAMPLES}")
    lowest = MIN_PERIODS_PER_WINDOW * 2 * math.pi / max(windows_s)
    if lowest > lo * (1 + 1e-9):
        raise ConfigError(
            f"band_rad_s starts at {lo:g} rad/s but the longest window ({max(windows_s):g} s) resolves only from "
            f"{lowest:.3g} rad/s ({MIN_PERIODS_PER_WINDOW:g} periods per window): raise the band's lower end or "
            f"lengthen the windows (at most half the record, {t_longest:g} s)")
    return windows_s


def _check_spectral_size(n_signals: int, n_samples: int, sample_rate_hz: float, windows_s, overlap: float,
                         band_rad_s) -> None:
    """ConfigError before any transform when one window length's spectra would exceed
    :data:`~livesweep.limits.MAX_SPECTRAL_VALUES` complex values."""
    for w in windows_s:
        size = window_spectra_values(n_signals, n_samples, sample_rate_hz, w, overlap, band_rad_s)
        if size > MAX_SPECTRAL_VALUES:
            raise ConfigError(
                f"windows_s: a {w:g} s window over band_rad_s [{band_rad_s[0]:g}, {band_rad_s[1]:g}] at {sample_rate_hz:g} "
                f"Hz with overlap {overlap:g} for {n_signals} signals needs {size} spectral values, more than "
                f"{MAX_SPECTRAL_VALUES}: narrow the band, shorten the windows or lower the overlap")


def analyze(values: np.ndarray, names, sample_rate_hz: float, inputs, outputs, band_rad_s, *,
            valid: np.ndarray | None = None, windows_s=None, overlap: float = 0.8, n_freq: int = 150,
            max_input_coherence: float = 0.5, references=None) -> SpectralAnalysis:
    """Frequency responses of ``outputs`` to ``inputs`` from a uniformly sampled record.

    Parameters
    ----------
    values : ndarray, shape (n_signals, n_samples)
    names : sequence of str
        Signal names, in ``values`` order.
    sample_rate_hz : float
    inputs, outputs : sequence of str
    band_rad_s : (float, float)
        Band of the composite grid [rad/s].
    valid : ndarray of bool, shape (n_samples,), optional
        False in data gaps; windows touching a gap are excluded.
    windows_s : sequence of float, optional
        Window lengths [s]; default five, geometrically spaced (method.md §4.4).
    overlap : float
        Window overlap (default 0.8).
    n_freq : int
        Points of the common log-spaced grid.
    max_input_coherence : float
        Input cross-coherence above which a frequency is flagged ill-conditioned.
    references : sequence of str, optional
        One exogenous reference per input, in ``inputs`` order (e.g. the logged sweep injection
        of a closed-loop test point); adds the referenced set, which ``best`` then returns.

    Returns
    -------
    SpectralAnalysis
    """
    values = np.atleast_2d(np.asarray(values, float))
    names = tuple(names)
    references = list(references or ())
    windows_s = check_settings(values, names, sample_rate_hz, inputs, outputs, band_rad_s, windows_s, valid, references)
    used = [n for n in names if n in inputs or n in outputs or n in references]
    _check_spectral_size(len(used), values.shape[1], sample_rate_hz, windows_s, overlap, band_rad_s)
    rows = [names.index(n) for n in used]
    x = values[rows]
    windows, skipped = [], []
    for w in windows_s:
        try:
            windows.append(window_spectra(x, used, sample_rate_hz, w, band_rad_s, valid=valid, overlap=overlap))
        except ConfigError:
            if valid is None or np.all(valid):
                raise
            skipped.append(w)             # no window of this length fits between the data gaps
    if not windows:
        raise ConfigError(f"no window of {list(windows_s)} s fits between the data gaps of the record")
    windows = tuple(windows)
    omega = np.geomspace(band_rad_s[0], band_rad_s[1], n_freq)
    idx_in = [used.index(n) for n in inputs]
    idx_out = [used.index(n) for n in outputs]
    interpolated = interpolate_windows(windows, omega)       # every window's matrix on the common grid, once
    H, coh, eps = composite_siso(windows, omega, idx_in, idx_out, interpolated)
    settings = {
        "windows_s": list(windows_s), "overlap": overlap, "sample_rate_hz": sample_rate_hz,
        "band_rad_s": [float(band_rad_s[0]), float(band_rad_s[1])], "n_freq": n_freq,
        "taper": "hann (periodic)", "transform": "zero-padded FFT, grid 2x window resolution",
        "composite": "inverse-variance weighted spectra (livesweep.spectral.composite)",
        "averages": [{"window_s": w.window_s, "segments": w.n_segments, "n_eff": round(w.n_eff, 2),
                      "excluded_for_gaps": w.n_excluded} for w in windows],
        "windows_skipped_for_gaps_s": skipped,
    }
    ill_in = None
    if len(idx_in) > 1:
        ill_in = _input_coherence_composite(windows, interpolated, idx_in) > max_input_coherence
    siso = FrequencyResponseSet(tuple(outputs), tuple(inputs), omega, H, coh, eps, False, None, ill_in, settings)
    miso = None
    if len(idx_in) > 1:
        Hm, pc, mc, em, ill_o = composite_miso(windows, omega, idx_in, idx_out, max_input_coherence, interpolated)
        miso = FrequencyResponseSet(tuple(outputs), tuple(inputs), omega, Hm, pc, em, True, mc, np.any(ill_o, axis=0),
                                    {**settings, "max_input_coherence": max_input_coherence})
    referenced = None
    if references:
        idx_ref = [used.index(n) for n in references]
        rr = reference_responses(list(windows), omega, idx_ref, idx_in, idx_out, max_input_coherence, interpolated)
        referenced = FrequencyResponseSet(
            tuple(outputs), tuple(inputs), omega, rr.H, rr.coherence, rr.random_error, True, rr.multiple_coherence,
            rr.ill_conditioned,
            {**settings, "max_input_coherence": max_input_coherence, "references": list(references),
             "referenced": "(y/r)(u/r)^-1 through one exogenous reference per input (method.md §4.6); "
                           "coherence = product of the two legs' partial coherences, random error added in quadrature"})
    return SpectralAnalysis(siso, miso, windows, referenced)


def _input_coherence_composite(windows, interpolated, idx_in):
    """Input cross-coherence on the common grid, from the shortest window able to resolve each point
    (the most averages, so the least bias upward).

    Parameters
    ----------
    windows : sequence of WindowSpectra
    interpolated : list of (ndarray, ndarray)
        The windows' matrices on the common grid and where each resolves it
        (:func:`~livesweep.spectral.composite.interpolate_windows`).
    idx_in : list of int
        Input indices on the matrices' signal axes.

    Returns
    -------
    ndarray
        Largest input-input coherence per frequency, in [0, 1].
    """
    order = sorted(range(len(windows)), key=lambda k: -windows[k].window_s)
    out = np.zeros(interpolated[0][0].shape[-1])
    for k in order:                                 # the shortest usable window (most averages) wins
        G, usable = interpolated[k]
        out = np.where(usable, input_coherence_max(G, idx_in), out)
    return out
