"""Sliding-window auto- and cross-spectra, updated incrementally as samples arrive (the live path).

The estimator cuts the incoming uniform stream into overlapped Hann segments exactly as the batch
code does (:func:`livesweep.spectral.windows.plan_segments`: segments of ``n`` samples starting at
sample 0, one every ``hop = round((1 - overlap) n)`` samples), transforms every *new* segment once
with the batch zero-padded real FFT (:func:`livesweep.spectral.transform.segment_spectra`, at the
bins :func:`livesweep.spectral.transform.bin_grid` gives :func:`livesweep.spectral.spectra.window_spectra`)
and keeps running sums over those bins of what the responses need: the rows of the spectral
matrix that belong to a *driver* (an input or a reference), ``sum_k conj(X_d) X_j``, and every
autospectrum ``sum_k |X_j|^2``. Segments whose end leaves the sliding window are subtracted again.
The rest of the matrix (cross-spectra between two outputs) is formed from the stored transforms
only when a result's ``G`` is read. Fed a whole record, the result is the batch ``window_spectra``
on the same segments (to rounding; a test says so).

Cost per update
---------------
An update that completes no segment and drops none only appends the samples: the window's
spectra, its averages and every response already computed from them are shared with the previous
result (they are the same numbers; only ``t_end_s`` moves on). An update that changes the window
makes one real-FFT call over the segments completed by the new samples only, plus one driver-row
product per segment added or removed: independent of ``window_s``. The drift resyncs below are
the exception -- they re-sum the ``K`` stored transforms, only at the flagged frequencies -- and
are rare (none in the 600 s benchmark, 23 in 10 000 segments of a stream with 1e4 bursts).
Memory: the transforms of the segments in the window (``n_signals x n_freq`` complex each) and the
un-segmented tail of the stream.

Rounding drift
--------------
Adding and subtracting leaves rounding residue in the running sums. For every autospectrum the
estimator keeps the classical bound of recursive summation, ``eps * sum over operations of the
partial sum`` (cross-spectrum errors are bounded by the geometric mean of their autospectra's,
since the matrix of partial sums is positive semi-definite). The sums are recomputed from the
stored transforms

* at the frequencies where that bound exceeds ``DRIFT_TOLERANCE`` (1e-11) of the current value --
  typically when a loud stretch (a sweep passing a frequency) leaves the window and the value there
  falls by more than ~45 dB; only those frequency columns are recomputed (the bound is checked
  whenever a segment leaves: adding one raises it by at most ``eps``) -- and
* every ``resync_every`` segments regardless (default 1000; a backstop, amortised cost
  ``K / 1000`` products per segment for ``K`` segments in the window).

So the online result stays within ~1e-11 (relative to ``sqrt(G_ii G_jj)``) of the batch one however
long it runs.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import InitVar, dataclass, field
from functools import cached_property

import numpy as np

from livesweep.spectral import DEFAULT_WINDOW_S
from livesweep.errors import ConfigError, require_number
from livesweep.spectral.miso import condition_blocks, input_coherence_max
from livesweep.spectral.reference import combine_legs
from livesweep.spectral.response import FrequencyResponseSet
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW, _random_error_of_incoherence, random_error
from livesweep.spectral.transform import bin_grid, fft_length, segment_spectra
from livesweep.spectral.windows import effective_averages, hann

__all__ = ["OnlineSpectralEstimator", "OnlineResult", "default_segment_s", "DRIFT_TOLERANCE", "DEFAULT_WINDOW_S"]

#: Bound on the relative rounding error of the running sum above which it is recomputed.
DRIFT_TOLERANCE = 1e-11
_EPS = float(np.finfo(float).eps)


def default_segment_s(band_rad_s, window_s: float) -> float:
    """Default segment length [s] for a band and a sliding window.

    ``MIN_PERIODS_PER_WINDOW`` (3) periods of the band's low end, so the whole band is resolved
    (the rule the batch code uses, ``spectra.MIN_PERIODS_PER_WINDOW``); at least 20 cycles of the
    band's high end (method.md §4.4, shortest window); and at most ``window_s / 2`` so the window
    always holds several overlapped segments. The upper cap wins over the two lower bounds: with a
    short window the low end of the band is then not resolved (see
    :attr:`OnlineResult.omega_min_usable`).

    Parameters
    ----------
    band_rad_s : (float, float)
        Band [rad/s].
    window_s : float
        Sliding-window length [s].

    Returns
    -------
    float
        Segment length [s].
    """
    lo, hi = float(band_rad_s[0]), float(band_rad_s[1])
    seg = max(MIN_PERIODS_PER_WINDOW * 2.0 * math.pi / lo, 20.0 * 2.0 * math.pi / hi)
    return min(seg, window_s / 2.0)


class _Layout:
    """Where the estimator's signals sit, worked out once: drivers (inputs and references, in
    signal order), inputs, outputs, and the input pairs of the input coherence."""

    __slots__ = ("drivers", "driver_rows", "inputs", "outputs", "input_rows", "pair_a", "pair_b", "pair_rows")

    def __init__(self, names, inputs, outputs, references):
        self.drivers = tuple(sorted({names.index(n) for n in tuple(inputs) + tuple(references)}))
        self.driver_rows = np.array(self.drivers, dtype=np.intp)
        self.inputs = np.array([names.index(n) for n in inputs], dtype=np.intp)
        self.outputs = np.array([names.index(n) for n in outputs], dtype=np.intp)
        self.input_rows = np.array([self.drivers.index(i) for i in self.inputs], dtype=np.intp)
        a, b = np.triu_indices(len(self.inputs), 1)
        self.pair_a, self.pair_b, self.pair_rows = self.inputs[a], self.inputs[b], self.input_rows[a]


class _WindowSums:
    """Running sums of one window's contents, as the estimator held them when a result was made.

    ``rows[d, j] = sum_k conj(X_kd) X_kj`` for every *driver* ``d`` (an input or a reference: the
    signals the responses divide by or condition on) and every signal ``j``; ``auto[j] = sum_k
    |X_kj|^2``; ``X`` the segments' transforms (for the rest of the matrix, computed only if
    ``G`` is read); ``scale`` turns sums into one-sided densities (``2 / (fs sum w^2 K)``).
    Never written: the estimator replaces its sums by new arrays instead of updating them in place.
    """

    __slots__ = ("layout", "drivers", "rows", "auto", "X", "scale")

    def __init__(self, layout, rows, auto, X, scale):
        self.layout, self.drivers = layout, layout.drivers
        self.rows, self.auto, self.X, self.scale = rows, auto, X, scale


@dataclass(frozen=True)
class OnlineResult:
    """The spectral matrix of the segments in the sliding window, and the responses it gives.

    Attributes
    ----------
    omega : ndarray, shape (n_freq,)
        The bins of the segments' zero-padded FFT that cover the band [rad/s]
        (``bin_grid(band, fft_length(n, oversample), fs)``, as the batch ``window_spectra``).
    names : tuple of str
        Signal order of ``G``.
    inputs, outputs : tuple of str
    G : ndarray, complex, shape (n_signals, n_signals, n_freq)
        One-sided densities ``2 / (fs sum w^2) mean_k conj(X_ik) X_jk`` [units_i units_j / Hz],
        scaled exactly like :func:`livesweep.spectral.spectra.spectral_matrix`. Read-only.
        Built when first read: the responses, :attr:`auto` and :meth:`cross` do not need it.
    n_segments : int
        Segments averaged (those ending within the last ``window_s``).
    n_eff : float
        Welch's equivalent independent averages (:func:`~livesweep.spectral.windows.effective_averages`).
    window_s : float
        Sliding-window length [s].
    segment_s : float
        Segment length [s] (a whole number of samples).
    t_end_s : float
        Time of the end of the data consumed [s since the estimator's first sample].
    overlap : float
    sample_rate_hz : float
    segment_starts : ndarray of int
        First sample of every averaged segment [samples since the estimator's first sample].
    n_excluded : int
        Segments ending within the window that were dropped because they touched a missing sample.
    max_input_coherence : float
        Input cross-coherence above which a frequency is flagged ill-conditioned.
    references : tuple of str
        One exogenous reference per input (a closed-loop test point's logged sweep injection),
        or empty; see :attr:`referenced`.

    Results of the same window contents (the estimator's successive results while no segment
    enters or leaves) share their spectra and the response arrays computed from them (a private
    memo): each is computed once per window, whichever result asks first.
    """

    omega: np.ndarray
    names: tuple
    inputs: tuple
    outputs: tuple
    G: InitVar[np.ndarray | None]
    n_segments: int
    n_eff: float
    window_s: float
    segment_s: float
    t_end_s: float
    overlap: float
    sample_rate_hz: float
    segment_starts: np.ndarray
    n_excluded: int = 0
    max_input_coherence: float = 0.5
    references: tuple = ()
    _sums: _WindowSums | None = field(default=None, repr=False, compare=False)
    _memo: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self, G):
        if G is None and self._sums is None:
            raise ConfigError("an OnlineResult needs its spectral matrix G")
        if G is not None:                       # given whole: everything is read from it
            G = np.asarray(G)
            if not G.flags.writeable:
                self._memo.setdefault("G", G)
            else:
                self._memo.setdefault("G", _readonly(G.copy()))

    def _shared(self, key: str, compute):
        """``compute()``, once per window contents (see the class docstring)."""
        value = self._memo.get(key)
        if value is None:
            value = self._memo[key] = compute()
        return value

    def _full_matrix(self) -> np.ndarray:
        s = self._sums
        n, n_f = len(self.names), self.omega.size
        drv = list(s.drivers)
        S = np.empty((n, n, n_f), complex)
        others = [j for j in range(n) if j not in s.drivers]
        if others and len(s.X):                 # the block no driver is in: from the stored transforms
            Y = np.stack([x[others] for x in s.X], axis=-1).transpose(1, 0, 2)   # (n_f, n_others, K)
            S[np.ix_(others, others)] = np.moveaxis(Y.conj() @ np.swapaxes(Y, 1, 2), 0, -1)
        S[:, drv, :] = np.swapaxes(s.rows, 0, 1).conj()     # driver columns, then the driver rows over them
        S[drv, :, :] = s.rows
        d = np.arange(n)
        S[d, d, :] = s.auto
        S *= s.scale
        return _readonly(S)

    def index(self, name: str) -> int:
        """Position of ``name`` on G's signal axes."""
        return self.names.index(name)

    @property
    def auto(self) -> np.ndarray:
        """Autospectra of every signal, ``G_ii`` [units_i^2 / Hz], shape (n_signals, n_freq). Read-only."""
        def compute():
            if self._sums is None:
                return _readonly(np.diagonal(self._memo["G"], axis1=0, axis2=1).real.T.copy())
            return _readonly(self._sums.scale * self._sums.auto)
        return self._shared("auto", compute)

    def cross(self, a: str, b: str) -> np.ndarray:
        """Cross-spectrum ``G_ab`` [units_a units_b / Hz], shape (n_freq,), conjugate on ``a``."""
        i, j = self.index(a), self.index(b)
        s = self._sums
        if s is None or "G" in self._memo:
            return self.G[i, j]
        if i == j:
            return self.auto[i].astype(complex)
        if i in s.drivers:
            return s.scale * s.rows[s.drivers.index(i), j]
        if j in s.drivers:
            return s.scale * s.rows[s.drivers.index(j), i].conj()
        return self.G[i, j]

    def _block(self, idx) -> np.ndarray:
        """``G[np.ix_(idx, idx)]``, from the driver rows when at most one signal of ``idx`` is not a
        driver (every response block is such: inputs or references, and one output)."""
        s = self._sums
        if s is None or "G" in self._memo or sum(i not in s.drivers for i in idx) > 1:
            return self.G[np.ix_(idx, idx)]
        m = len(idx)
        B = np.empty((m, m, self.omega.size), complex)
        for a, i in enumerate(idx):
            if i in s.drivers:
                B[a] = s.rows[s.drivers.index(i)][idx]                 # G[i, idx]
        for a, i in enumerate(idx):
            if i not in s.drivers:                                     # its row: the conjugate column
                for b in range(m):
                    if b != a:
                        B[a, b] = B[b, a].conj()
        for a, i in enumerate(idx):
            B[a, a] = s.auto[i]
        B *= s.scale
        return B

    def _all_carry_power(self, names) -> bool:
        return _carry_power(self.auto, [self.index(n) for n in names])

    @property
    def usable(self) -> np.ndarray:
        """Bool per frequency: at or above :attr:`omega_min_usable`."""
        return self.omega >= self.omega_min_usable * (1 - 1e-12)

    @property
    def omega_min_usable(self) -> float:
        """Lowest frequency with ``MIN_PERIODS_PER_WINDOW`` periods in a segment [rad/s]."""
        return MIN_PERIODS_PER_WINDOW * 2.0 * math.pi / self.segment_s

    def _settings(self) -> dict:
        return {"source": "online", "window_s": self.window_s, "segment_s": self.segment_s,
                "overlap": self.overlap, "sample_rate_hz": self.sample_rate_hz,
                "n_segments": self.n_segments, "n_eff": round(self.n_eff, 3), "t_end_s": self.t_end_s,
                "excluded_for_gaps": self.n_excluded, "taper": "hann (periodic)",
                "transform": "zero-padded FFT, grid 2x segment resolution"}

    @cached_property
    def input_coherence(self) -> np.ndarray:
        """Largest ordinary coherence between any two inputs, per frequency (zeros for one input).

        Where an input has no power at all the coherence is undefined and reported as 1
        (:func:`livesweep.spectral.miso.input_coherence_max`).
        """
        def compute():
            s = self._sums
            if s is None or "G" in self._memo or len(self.inputs) < 2:
                ii = [self.index(n) for n in self.inputs]
                return _readonly(input_coherence_max(self._block(ii), list(range(len(ii)))))
            lay = s.layout
            g = s.rows[lay.pair_rows, lay.pair_b]                           # (pairs, f); the scale cancels
            den = s.auto[lay.pair_a] * s.auto[lay.pair_b]
            with np.errstate(divide="ignore", invalid="ignore"):
                c = np.where(den > 0, (g.real**2 + g.imag**2) / den, 1.0)
            return _readonly(np.clip(c, 0.0, 1.0).max(axis=0))
        return self._shared("input_coherence", compute)

    def _ordinary_arrays(self):
        s = self._sums
        if s is None or "G" in self._memo:
            ii = [self.index(n) for n in self.inputs]
            io = [self.index(n) for n in self.outputs]
            gxy = self.G[np.ix_(ii, io)]                                 # (n_in, n_out, f): G[x, y]
            auto = self.auto
        else:                                                            # from the sums: the scale cancels
            ii, io = s.layout.inputs, s.layout.outputs
            gxy = s.rows[np.ix_(s.layout.input_rows, io)]
            auto = s.auto
        gxx = auto[ii][:, None, :]                                       # (n_in, 1, f)
        den = gxx * auto[io][None, :, :]
        num = gxy.real**2 + gxy.imag**2
        with np.errstate(divide="ignore", invalid="ignore"):
            if np.all(den > 0):                                          # the usual case: no signal is quiet
                H, coh = gxy * (1.0 / gxx), num / den
            else:
                H = np.where(gxx > 0, gxy / gxx, np.nan + 0j)
                coh = np.where(den > 0, num / den, 0.0)
        np.clip(coh, 0.0, 1.0, out=coh)
        eps = _random_error_of_incoherence(np.subtract(1.0, coh), self.n_eff)
        return tuple(_readonly(a.transpose(1, 0, 2)) for a in (H, coh, eps))  # (n_out, n_in, f)

    @cached_property
    def ordinary(self) -> FrequencyResponseSet:
        """SISO responses of every output to every input: ``H = G_xy / G_xx`` (H1), ordinary coherence
        ``|G_xy|^2 / (G_xx G_yy)`` (as :func:`livesweep.spectral.spectra.coherence`, vectorised over
        the pairs), random error with ``n_eff`` averages (:func:`livesweep.spectral.spectra.random_error`).

        ``H`` is NaN where the input autospectrum is zero.
        """
        H, coh, eps = self._shared("ordinary", self._ordinary_arrays)
        ill = self.input_coherence > self.max_input_coherence if len(self.inputs) > 1 else None
        return FrequencyResponseSet(tuple(self.outputs), tuple(self.inputs), self.omega, H, coh, eps, False,
                                    None, ill, self._settings())

    def _conditioned_arrays(self):
        q = len(self.inputs)
        idx_in = [self.index(n) for n in self.inputs]
        shape = (len(self.outputs), q, self.omega.size)
        H, pc, eps = np.empty(shape, complex), np.empty(shape), np.empty(shape)
        mc = np.empty((len(self.outputs), self.omega.size))
        ill = np.zeros(self.omega.size, bool)
        dof = self.n_eff - q + 1
        for a, o in enumerate(self.outputs):
            Ha, pca, mca, illa = _condition(self._block(idx_in + [self.index(o)]), q, self.max_input_coherence,
                                            self.n_segments)
            H[a], pc[a], mc[a] = Ha, pca, mca
            ill |= illa
            eps[a] = random_error(pca, dof) if dof >= 1 else np.inf
        return tuple(_readonly(a) for a in (H, pc, eps, mc, ill))

    @cached_property
    def conditioned(self) -> FrequencyResponseSet | None:
        """MISO-conditioned responses (more than one input), else None.

        Per output, :func:`livesweep.spectral.miso.condition_output` over all inputs: conditioned H,
        partial coherence (stored as ``coherence``), multiple coherence, ill-conditioned flags.
        Random error from the partial coherence with ``n_eff - q + 1`` degrees of freedom (q inputs;
        method.md §6.2); ``inf`` while ``n_eff - q + 1 < 1``. With fewer than ``q + 1`` segments the
        spectral matrix is singular and every frequency is NaN / flagged ill-conditioned; so is any
        frequency where it is exactly singular.
        """
        if len(self.inputs) < 2:
            return None
        H, pc, eps, mc, ill = self._shared("conditioned", self._conditioned_arrays)
        return FrequencyResponseSet(tuple(self.outputs), tuple(self.inputs), self.omega, H, pc, eps, True, mc, ill,
                                    {**self._settings(), "max_input_coherence": self.max_input_coherence})

    def _referenced_arrays(self):
        q = len(self.references)
        idx_ref = [self.index(n) for n in self.references]
        dof = self.n_eff - q + 1
        legs, ill = {}, np.zeros(self.omega.size, bool)
        for key, names in (("u", self.inputs), ("y", self.outputs)):
            T = np.empty((len(names), q, self.omega.size), complex)
            pc, eps = np.empty(T.shape), np.empty(T.shape)
            mc = np.empty((len(names), self.omega.size))
            for a, n in enumerate(names):
                T[a], pc[a], mc[a], ill_a = _condition(self._block(idx_ref + [self.index(n)]), q,
                                                       self.max_input_coherence, self.n_segments)
                eps[a] = random_error(pc[a], dof) if dof >= 1 else np.inf
                ill |= ill_a
            legs[key] = (T, pc, eps, mc)
        (Tur, pcu, epsu, _), (Tyr, pcy, epsy, mcy) = legs["u"], legs["y"]
        rr = combine_legs(Tur, pcu, epsu, Tyr, pcy, epsy, mcy, ill)
        return tuple(_readonly(a) for a in (rr.H, rr.coherence, rr.random_error, rr.multiple_coherence,
                                            rr.ill_conditioned))

    @cached_property
    def referenced(self) -> FrequencyResponseSet | None:
        """Responses through the references, ``(y/r)(u/r)^-1`` (:mod:`livesweep.spectral.reference`),
        from this window's spectral matrix; None without references. Each leg is conditioned on
        all references (:func:`_condition`, singular-safe), with ``n_eff - q + 1`` degrees of freedom
        for its random error."""
        if not self.references:
            return None
        H, coh, eps, mc, ill = self._shared("referenced", self._referenced_arrays)
        return FrequencyResponseSet(tuple(self.outputs), tuple(self.inputs), self.omega, H, coh, eps, True, mc, ill,
                                    {**self._settings(), "references": list(self.references)})

    @property
    def best(self) -> FrequencyResponseSet:
        """Through the references when there are references and every one carries power; else the
        conditioned set when there are several inputs and every one carries power; else the
        ordinary set.

        During a single-axis sweep the other inputs may be exactly quiet: conditioning on a zero
        input is singular and would blank every pair, while the ordinary response of the swept
        input is then exact (nothing correlated to remove).
        """
        if self.references and self._all_carry_power(self.references):
            return self.referenced
        if len(self.inputs) < 2 or not self._all_carry_power(self.inputs):
            return self.ordinary
        return self.conditioned


def _readonly(a: np.ndarray) -> np.ndarray:
    """``a``, made read-only (arrays shared by the results of one window must not be written)."""
    a = np.asarray(a)
    a.setflags(write=False)
    return a


def _G_property(self) -> np.ndarray:
    return self._shared("G", self._full_matrix)


OnlineResult.G = property(_G_property, doc="""One-sided spectral matrix ``G`` (n_signals, n_signals, n_freq)
[units_i units_j / Hz], read-only; see the class docstring.""")


def _carry_power(auto, idx) -> bool:
    """Every signal ``idx`` has power (median autospectrum above 1e-12 of the largest peak).

    ``auto`` holds the autospectra, shape (n_signals, n_freq)."""
    a = np.asarray(auto)[list(idx)]
    peak = float(np.max(a)) if a.size else 0.0
    return peak > 0 and not np.any(np.median(a, axis=-1) <= 1e-12 * peak)


def _condition(S, q, max_input_coherence, n_segments):
    """:func:`livesweep.spectral.miso.condition_blocks` of one (q+1)x(q+1) block over (inputs,
    output), surviving a singular spectral matrix.

    With fewer segments than inputs + 1 the block has rank < q+1 at every frequency (nothing can
    be conditioned yet); exactly collinear signals make it singular at some. Those frequencies get
    H = NaN, coherences 0 and the ill-conditioned flag, instead of an exception.
    """
    n_f = S.shape[-1]
    nan = (np.full((q, n_f), np.nan + 0j), np.zeros((q, n_f)), np.zeros(n_f), np.ones(n_f, bool))
    if n_segments < q + 1:
        return nan
    try:
        c = condition_blocks(S, q, max_input_coherence=max_input_coherence)
        return c.H, c.partial_coherence, c.multiple_coherence, c.ill_conditioned
    except np.linalg.LinAlgError:
        H, pc, mc, ill = (a.copy() for a in nan)
        for f in range(n_f):
            try:
                c = condition_blocks(S[:, :, f:f + 1], q, max_input_coherence=max_input_coherence)
            except np.linalg.LinAlgError:
                continue
            H[:, f], pc[:, f], mc[f], ill[f] = c.H[:, 0], c.partial_coherence[:, 0], c.multiple_coherence[0], \
                c.ill_conditioned[0]
        return H, pc, mc, ill


class OnlineSpectralEstimator:
    """Sliding-window spectral matrix of a uniformly sampled stream, updated segment by segment.

    Parameters
    ----------
    names : sequence of str
        Signals, in the row order of the blocks given to :meth:`update`.
    inputs, outputs : sequence of str
        Which signals are inputs and outputs (for the responses of :class:`OnlineResult`).
    sample_rate_hz : float
        Sample rate of the stream [Hz].
    band_rad_s : (float, float)
        Band [rad/s], ``0 < low < high < pi fs``.
    window_s : float
        Sliding window [s]: the segments that *end* within the last ``window_s`` seconds are
        averaged (so the data span is up to ``window_s + segment_s``). At least ``segment_s``.
    segment_s : float, optional
        Segment length [s]; default :func:`default_segment_s` (3 periods of the band's low end,
        at least 20 cycles of its high end, at most ``window_s / 2``). Rounded to whole samples.
    overlap : float
        Segment overlap fraction, 0 <= overlap < 1 (default 0.8, method.md §4.1).
    oversample : float
        Grid spacing at most ``2 pi / (oversample segment_s)`` [rad/s]: segments are zero-padded to
        ``fft_length(n, oversample) >= oversample n`` samples
        (:func:`livesweep.spectral.transform.fft_length`).
    max_input_coherence : float
        Input cross-coherence above which a frequency is flagged ill-conditioned.
    resync_every : int
        Recompute the running sums from the stored transforms after this many segments have been
        added (default 1000), besides the error-bound trigger (module docstring).

    Attributes
    ----------
    omega : ndarray
        The frequency grid [rad/s] (the FFT bins covering the band; read-only).
    n_fft : int
        Zero-padded FFT length of a segment [samples].
    n_transform_calls : int
        Calls to :func:`~livesweep.spectral.transform.segment_spectra` (real-FFT invocations) so far.
    n_segment_transforms : int
        Segments transformed so far (each at most once).
    n_resyncs : int
        Times the running sums were recomputed from the stored transforms.
    n_segments_excluded : int
        Segments dropped because they touched a missing sample, since the start.
    n_nonfinite_samples : int
        Samples flagged valid whose value was NaN/inf in some signal; they are treated as missing.
    """

    def __init__(self, names, inputs, outputs, sample_rate_hz: float, band_rad_s, *, window_s: float = DEFAULT_WINDOW_S,
                 segment_s: float | None = None, overlap: float = 0.8, oversample: float = 2.0,
                 max_input_coherence: float = 0.5, resync_every: int = 1000, references=()):
        self.names = tuple(str(n) for n in names)
        if len(set(self.names)) != len(self.names) or not self.names:
            raise ConfigError(f"signal names must be unique and non-empty, got {list(self.names)}")
        self.inputs, self.outputs = tuple(inputs), tuple(outputs)
        if not self.inputs or not self.outputs:
            raise ConfigError("the online estimator needs at least one input and one output")
        self.references = tuple(references or ())
        if self.references and len(self.references) != len(self.inputs):
            raise ConfigError(f"one reference per input: {len(self.references)} references for {len(self.inputs)} inputs")
        for n in self.inputs + self.outputs + self.references:
            if n not in self.names:
                raise ConfigError(f"signal {n!r} is not among the streamed signals ({', '.join(self.names)})")
        self.sample_rate_hz = require_number(sample_rate_hz, "sample_rate_hz", positive=True)
        lo, hi = (float(b) for b in band_rad_s)
        nyq = math.pi * self.sample_rate_hz
        if not (0 < lo < hi < nyq):
            raise ConfigError(f"band_rad_s = [{lo:g}, {hi:g}] must satisfy 0 < low < high < Nyquist ({nyq:.4g} rad/s)")
        self.band_rad_s = (lo, hi)
        self.window_s = require_number(window_s, "window_s", positive=True)
        if not 0.0 <= overlap < 1.0:
            raise ConfigError(f"overlap must be in [0, 1), got {overlap!r}")
        self.overlap = float(overlap)
        seg = default_segment_s(self.band_rad_s, self.window_s) if segment_s is None else \
            require_number(segment_s, "segment_s", positive=True)
        self.n = int(round(seg * self.sample_rate_hz))
        if self.n < 8:
            raise ConfigError(f"segment_s = {seg:g} s holds fewer than 8 samples at {self.sample_rate_hz:g} Hz")
        self.segment_s = self.n / self.sample_rate_hz
        self._W = int(round(self.window_s * self.sample_rate_hz))
        if self._W < self.n:
            raise ConfigError(f"window_s = {self.window_s:g} s is shorter than one segment ({self.segment_s:g} s)")
        self.hop = max(1, int(round((1.0 - self.overlap) * self.n)))
        self.max_input_coherence = float(max_input_coherence)
        if int(resync_every) < 1:
            raise ConfigError(f"resync_every must be >= 1, got {resync_every!r}")
        self.resync_every = int(resync_every)

        self.taper = hann(self.n)
        self.n_fft = fft_length(self.n, oversample)
        self._k0, self.omega = bin_grid(lo, hi, self.n_fft, self.sample_rate_hz)
        self.omega.setflags(write=False)
        self._scale = 2.0 / (self.sample_rate_hz * float(np.sum(self.taper**2)))
        n_sig, n_f = len(self.names), self.omega.size
        # stream state: samples from _next_start on, in _buf[:, _buf_off:_buf_off + _buf_len]
        # (compacted to the front when the end is reached, grown by doubling)
        self._consumed = 0                                  # samples seen
        self._next_start = 0                                # start of the next segment to cut
        cap = 4 * self.n
        self._buf = np.empty((n_sig, cap))
        self._buf_valid = np.empty(cap, bool)
        self._buf_off = 0
        self._buf_len = 0
        # window state
        self._segs: deque = deque()                         # (start, X (n_sig, n_freq)) in the window
        self._excluded: deque = deque()                     # ends of excluded segments (for n_excluded)
        # drivers: the signals responses divide by or condition on (inputs, references); the running
        # sums hold their rows of the spectral matrix and every autospectrum, the rest of the matrix
        # is formed from the stored transforms only when a result's G is read
        self._layout = _Layout(self.names, self.inputs, self.outputs, self.references)
        self._drivers = self._layout.driver_rows
        self._rows = np.zeros((len(self._drivers), n_sig, n_f), complex)   # sum conj(X_d) X_j
        self._auto = np.zeros((n_sig, n_f))                                 # sum |X_j|^2
        self._err = np.zeros((n_sig, n_f))                  # summation-error scale per autospectrum
        self._since_resync = 0
        self._version = 0                                   # bumped whenever the segments or their sum change
        self._snapshot = None                               # (version, sums, starts, n_eff, memo) of the last result
        self._n_eff: dict = {}                              # n_eff by number of segments
        # counters
        self.n_transform_calls = 0
        self.n_segment_transforms = 0
        self.n_resyncs = 0
        self.n_segments_excluded = 0
        self.n_nonfinite_samples = 0

    # ------------------------------------------------------------------ stream
    @property
    def time_s(self) -> float:
        """Samples consumed / sample rate [s]."""
        return self._consumed / self.sample_rate_hz

    @property
    def n_samples(self) -> int:
        """Samples consumed."""
        return self._consumed

    def update(self, block, valid=None) -> int:
        """Consume new samples; add every segment they complete; drop segments leaving the window.

        Parameters
        ----------
        block : array_like, shape (n_signals, n_new)
            New uniformly spaced samples, rows in ``names`` order, continuing the stream.
        valid : array_like of bool, shape (n_new,), optional
            False where a sample is missing (a gap). A segment touching a missing sample is never
            added. Non-finite values are treated as missing too (counted in ``n_nonfinite_samples``).

        Returns
        -------
        int
            Segments added to the window by this block.
        """
        block = np.asarray(block, float)
        if block.ndim == 1 and len(self.names) == 1:
            block = block[None, :]
        if block.ndim != 2 or block.shape[0] != len(self.names):
            raise ConfigError(f"block must have shape ({len(self.names)}, n_new) for signals "
                              f"{list(self.names)}, got {block.shape}")
        m = block.shape[1]
        ok = np.ones(m, bool) if valid is None else np.asarray(valid, bool)
        if ok.shape != (m,):
            raise ConfigError(f"valid must have shape ({m},) like the block's samples, got {ok.shape}")
        finite = np.all(np.isfinite(block), axis=0)
        bad = ok & ~finite
        if np.any(bad):
            self.n_nonfinite_samples += int(np.sum(bad))
            ok = ok & finite
        if m:
            self._append(block, ok)
            self._consumed += m

        added = 0
        n_avail = self._buf_len
        if n_avail >= self.n:
            rel = np.arange(0, n_avail - self.n + 1, self.hop)    # segment starts in the buffer
            tail = slice(self._buf_off, self._buf_off + n_avail)
            if rel.size:
                valid = self._buf_valid[tail]
                if valid.all():
                    good = np.ones(rel.size, bool)
                else:
                    nbad = np.concatenate([[0], np.cumsum(~valid)])
                    good = nbad[rel + self.n] - nbad[rel] == 0
                for r in rel[~good]:
                    self._excluded.append(self._next_start + int(r) + self.n)
                self.n_segments_excluded += int(np.sum(~good))
                keep = rel[good]
                if keep.size:
                    X = segment_spectra(self._buf[:, tail], keep, self.n, self.taper, self.n_fft, self._k0,
                                        self.omega.size)
                    self.n_transform_calls += 1
                    self.n_segment_transforms += int(keep.size)
                    for k, r in enumerate(keep):
                        Xk = _readonly(np.ascontiguousarray(X[:, k, :]))
                        self._add(Xk, +1)
                        self._segs.append((self._next_start + int(r), Xk))
                    added = int(keep.size)
                drop = int(rel[-1]) + self.hop
                self._next_start += drop
                self._buf_off += drop
                self._buf_len = n_avail - drop
        # slide: keep segments that end after consumed - W
        limit = self._consumed - self._W
        removed = False
        while self._segs and self._segs[0][0] + self.n <= limit:
            _, Xk = self._segs.popleft()
            self._add(Xk, -1)
            removed = True
        while self._excluded and self._excluded[0] <= limit:
            self._excluded.popleft()
        if added or removed:
            self._version += 1
        if not self._segs:
            self._rows = np.zeros_like(self._rows)
            self._auto = np.zeros_like(self._auto)
            self._err[...] = 0.0
        elif added or removed:
            self._since_resync += added
            if self._since_resync >= self.resync_every:
                self._resync(None)
            elif removed:       # adding a segment raises the bound by at most eps: checked when one leaves
                bad = self._drift_bound() > DRIFT_TOLERANCE
                if np.any(bad):
                    self._resync(bad)
        return added

    def _append(self, block: np.ndarray, ok: np.ndarray) -> None:
        """Append samples to the un-segmented tail: moved to the front of its storage when the end
        is reached, the storage doubled when even that is too small."""
        m, n_sig = block.shape[1], self._buf.shape[0]
        off, length = self._buf_off, self._buf_len
        if off + length + m > self._buf.shape[1]:
            cap = self._buf.shape[1]
            if length + m > cap:
                cap = max(length + m, 2 * cap)
            buf, buf_valid = (self._buf, self._buf_valid) if cap == self._buf.shape[1] else \
                (np.empty((n_sig, cap)), np.empty(cap, bool))
            buf[:, :length] = self._buf[:, off:off + length]
            buf_valid[:length] = self._buf_valid[off:off + length]
            self._buf, self._buf_valid, self._buf_off, off = buf, buf_valid, 0, 0
        self._buf[:, off + length:off + length + m] = block
        self._buf_valid[off + length:off + length + m] = ok
        self._buf_len = length + m

    def _add(self, Xk: np.ndarray, sign: int) -> None:
        # new arrays, never written in place: the results made so far keep referring to theirs
        c = Xk[self._drivers].conj()[:, None, :] * Xk[None, :, :]
        a = Xk.real**2 + Xk.imag**2
        if sign > 0:
            self._rows = np.add(self._rows, c, out=c)
            self._auto = np.add(self._auto, a, out=a)
        else:
            self._rows = np.subtract(self._rows, c, out=c)
            self._auto = np.subtract(self._auto, a, out=a)
        # recursive-summation bound: eps * sum over operations of |partial sum| (autospectra are >= 0)
        self._err += np.abs(self._auto)

    def _drift_bound(self) -> np.ndarray:
        """Per frequency, the largest bound on the relative rounding error of the running sums
        (inf where an autospectrum is 0 with rounding residue behind it; NaN ratios, 0 / 0, count
        as no error)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return _EPS * np.fmax.reduce(self._err / np.abs(self._auto), axis=0)

    def _resync(self, freqs: np.ndarray | None) -> None:
        """Recompute the running sums from the stored transforms: all frequencies, or those flagged."""
        X = np.stack([x for _, x in self._segs], axis=1)     # (n_sig, K, n_freq)
        if freqs is not None:
            X = X[:, :, freqs]
        rows = np.einsum("dkf,jkf->djf", X[self._drivers].conj(), X, optimize=True)
        auto = np.einsum("jkf,jkf->jf", X.real, X.real) + np.einsum("jkf,jkf->jf", X.imag, X.imag)
        if freqs is None:
            self._rows, self._auto = rows, auto
            self._err = X.shape[1] * np.abs(auto)
            self._since_resync = 0
        else:
            self._rows, self._auto = self._rows.copy(), self._auto.copy()
            self._rows[:, :, freqs] = rows
            self._auto[:, freqs] = auto
            self._err[:, freqs] = X.shape[1] * np.abs(auto)
        self.n_resyncs += 1
        self._version += 1

    # ------------------------------------------------------------------ result
    def result(self) -> OnlineResult | None:
        """The spectral matrix of the segments now in the window, or None when it holds none.

        While no segment has entered or left the window since the previous result, the new result
        shares that one's ``G`` and the responses computed from it (they are the same numbers).
        """
        K = len(self._segs)
        if K == 0:
            return None
        if self._snapshot is None or self._snapshot[0] != self._version:
            starts = np.fromiter((s for s, _ in self._segs), dtype=np.int64, count=K)
            starts.setflags(write=False)
            n_eff = self._n_eff.get(K)
            if n_eff is None:
                n_eff = self._n_eff[K] = effective_averages(K, self.n, self.hop, self.taper)
            sums = _WindowSums(self._layout, self._rows, self._auto, tuple(x for _, x in self._segs), self._scale / K)
            self._snapshot = (self._version, sums, starts, n_eff, {})
        _, sums, starts, n_eff, memo = self._snapshot
        return OnlineResult(
            omega=self.omega, names=self.names, inputs=self.inputs, outputs=self.outputs, G=None, n_segments=K,
            n_eff=n_eff, window_s=self.window_s, segment_s=self.segment_s, t_end_s=self.time_s, overlap=self.overlap,
            sample_rate_hz=self.sample_rate_hz, segment_starts=starts, n_excluded=len(self._excluded),
            max_input_coherence=self.max_input_coherence, references=self.references, _sums=sums, _memo=memo,
        )
