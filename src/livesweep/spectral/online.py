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
The responses of a changed window are computed once, when a result first asks, from the running
sums: the ordinary ones elementwise, the MISO-conditioned ones of every output through one inverse
of the inputs' coherence matrix per frequency (:func:`_condition_many`).
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
from operator import itemgetter

import numpy as np

from livesweep.spectral import DEFAULT_WINDOW_S
from livesweep.errors import ConfigError, require_number
from livesweep.spectral.miso import condition_blocks, input_coherence_max
from livesweep.spectral.reference import combine_legs
from livesweep.spectral.response import FrequencyResponseSet
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW, _random_error_of_incoherence
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

    __slots__ = ("drivers", "driver_rows", "inputs", "outputs", "input_rows", "pair_a", "pair_b", "pair_rows",
                 "inputs_at", "outputs_at", "input_rows_at", "driver_rows_at")

    def __init__(self, names, inputs, outputs, references):
        self.drivers = tuple(sorted({names.index(n) for n in tuple(inputs) + tuple(references)}))
        self.driver_rows = np.array(self.drivers, dtype=np.intp)
        self.inputs = np.array([names.index(n) for n in inputs], dtype=np.intp)
        self.outputs = np.array([names.index(n) for n in outputs], dtype=np.intp)
        self.input_rows = np.array([self.drivers.index(i) for i in self.inputs], dtype=np.intp)
        a, b = np.triu_indices(len(self.inputs), 1)
        self.pair_a, self.pair_b, self.pair_rows = self.inputs[a], self.inputs[b], self.input_rows[a]
        # the same, as slices where they are runs (the usual layout): views instead of copies
        self.inputs_at, self.outputs_at, self.input_rows_at, self.driver_rows_at = (
            _run(i) for i in (self.inputs, self.outputs, self.input_rows, self.driver_rows))


def _run(idx: np.ndarray):
    """``slice(a, b)`` when ``idx`` is ``a, a+1, .., b-1``, else ``idx``: indexes the same elements."""
    if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


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

    @classmethod
    def _of_window(cls, window: dict, t_end_s: float, n_excluded: int) -> "OnlineResult":
        """The estimator's result: every field but ``t_end_s`` and ``n_excluded`` from ``window``,
        which the estimator builds once per window contents and shares between that window's
        results (so with their memo). Made without ``__init__``: its one check, that a result has
        its spectral matrix or the running sums, holds by construction (``_sums`` is set)."""
        r = object.__new__(cls)
        r.__dict__.update(window)
        r.__dict__["t_end_s"], r.__dict__["n_excluded"] = t_end_s, n_excluded
        return r

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
            lay = s.layout
            ii, io = lay.inputs_at, lay.outputs_at
            gxy = s.rows[lay.input_rows_at][:, io]
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
        def build():
            H, coh, eps = self._ordinary_arrays()
            ill = _readonly(self.input_coherence > self.max_input_coherence) if len(self.inputs) > 1 else None
            return self._response_set(False, H, coh, eps, None, ill)
        return _restamped(self._shared("ordinary", build), self._settings())

    def _response_set(self, conditioned, H, coh, eps, mc, ill) -> FrequencyResponseSet:
        """The response set of this window's contents (shared, see the class docstring); each result
        hands out a copy with its own settings (:func:`_restamped`)."""
        return FrequencyResponseSet(tuple(self.outputs), tuple(self.inputs), self.omega, H, coh, eps, conditioned,
                                    mc, ill, {})

    def _conditioning_spectra(self, cond, targets):
        """What conditioning ``targets`` on ``cond`` (signal indices) needs, unscaled or scaled alike
        (conditioning is scale-free): ``Gcc`` (q, q, f), ``Gct`` (q, T, f) and the autospectra of
        both, from the driver rows of the running sums (``cond`` are drivers) or from ``G``."""
        s = self._sums
        if s is None or "G" in self._memo:
            G = self.G
            auto = np.diagonal(G, axis1=0, axis2=1).real.T
            return G[np.ix_(cond, cond)], G[np.ix_(cond, targets)], auto[cond], auto[targets]
        lay = s.layout
        if list(cond) == lay.inputs.tolist() and list(targets) == lay.outputs.tolist():   # the usual: views
            crow, cond, targets = lay.input_rows_at, lay.inputs_at, lay.outputs_at
        else:
            crow, cond, targets = (_run(np.array(i, dtype=np.intp)) for i in
                                   ([s.drivers.index(i) for i in cond], cond, targets))
        rows = s.rows[crow]
        return rows[:, cond], rows[:, targets], s.auto[cond], s.auto[targets]

    def _condition_all(self, cond, targets, ill_cond):
        """Every signal of ``targets`` conditioned on the signals ``cond`` (:func:`_condition_many`);
        the targets the fast path cannot do (a singular block) go through :func:`_condition` on
        their own block, as before. ``ill_cond``: frequencies where ``cond`` are too coherent."""
        q = len(cond)
        out = _condition_many(*self._conditioning_spectra(cond, targets), self.n_segments, ill_cond)
        if out is None:                                   # the conditioning signals' matrix is singular
            redo, out = range(len(targets)), _nan_conditioned(len(targets), q, self.omega.size)
        else:
            redo = out[4]
        H, pc, mc, ill = out[:4]
        for a in redo:                                    # old path: per block, singular-safe
            Ha, pca, mca, illa = _condition(self._block(list(cond) + [targets[a]]), q, self.max_input_coherence,
                                            self.n_segments)
            H[a], pc[a], mc[a] = Ha, pca, mca
            ill |= illa
        dof = self.n_eff - q + 1
        if dof >= 1:                      # random_error of pc: in [0, 1] (NaN from a singular block: none)
            u = np.subtract(1.0, pc)
            eps = _random_error_of_incoherence(np.nan_to_num(u, copy=False, nan=1.0) if len(redo) else u, dof)
        else:
            eps = np.full(pc.shape, np.inf)
        return H, pc, eps, mc, ill

    def _conditioned_arrays(self):
        ii = [self.index(n) for n in self.inputs]
        io = [self.index(n) for n in self.outputs]
        ill_in = self.input_coherence > self.max_input_coherence
        return tuple(_readonly(a) for a in self._condition_all(ii, io, ill_in))

    @cached_property
    def conditioned(self) -> FrequencyResponseSet | None:
        """MISO-conditioned responses (more than one input), else None.

        Per output, the arithmetic of :func:`livesweep.spectral.miso.condition_output` over all
        inputs, for every output at once from the running sums (:func:`_condition_many`: one
        inverse of the inputs' coherence matrix per frequency serves all outputs): conditioned H,
        partial coherence (stored as ``coherence``), multiple coherence, ill-conditioned flags.
        Random error from the partial coherence with ``n_eff - q + 1`` degrees of freedom (q inputs;
        method.md §6.2); ``inf`` while ``n_eff - q + 1 < 1``. With fewer than ``q + 1`` segments the
        spectral matrix is singular and every frequency is NaN / flagged ill-conditioned; so is any
        frequency where it is exactly singular.
        """
        if len(self.inputs) < 2:
            return None
        window_set = self._shared("conditioned", lambda: self._response_set(True, *self._conditioned_arrays()))
        return _restamped(window_set, {**self._settings(), "max_input_coherence": self.max_input_coherence})

    def _referenced_arrays(self):
        idx_ref = [self.index(n) for n in self.references]
        ii = [self.index(n) for n in self.inputs]
        io = [self.index(n) for n in self.outputs]
        Gcc, _, acc, _ = self._conditioning_spectra(idx_ref, [])
        ill_ref = _max_pair_coherence(Gcc, acc) > self.max_input_coherence
        T, pc, eps, mc, ill = self._condition_all(idx_ref, ii + io, ill_ref)
        u, y = slice(0, len(ii)), slice(len(ii), None)
        rr = combine_legs(T[u], pc[u], eps[u], T[y], pc[y], eps[y], mc[y], ill)
        return tuple(_readonly(a) for a in (rr.H, rr.coherence, rr.random_error, rr.multiple_coherence,
                                            rr.ill_conditioned))

    @cached_property
    def referenced(self) -> FrequencyResponseSet | None:
        """Responses through the references, ``(y/r)(u/r)^-1`` (:mod:`livesweep.spectral.reference`),
        from this window's spectral matrix; None without references. Each leg is conditioned on
        all references (:func:`_condition_many`; :func:`_condition` where a block is singular), with
        ``n_eff - q + 1`` degrees of freedom for its random error."""
        if not self.references:
            return None
        window_set = self._shared("referenced", lambda: self._response_set(True, *self._referenced_arrays()))
        return _restamped(window_set, {**self._settings(), "references": list(self.references)})

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


def _restamped(window_set: FrequencyResponseSet, settings: dict) -> FrequencyResponseSet:
    """A copy of a window's response set with a result's own ``settings`` (``t_end_s`` and
    ``excluded_for_gaps`` move on while the window's contents stay): the same read-only arrays,
    already checked when the set was made, so the copy skips ``__init__``."""
    out = object.__new__(FrequencyResponseSet)
    out.__dict__.update(window_set.__dict__)
    out.__dict__["settings"] = settings
    return out


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


def _nan_conditioned(n_targets, q, n_f):
    """Nothing conditioned: H NaN, coherences 0, every frequency flagged."""
    return (np.full((n_targets, q, n_f), np.nan + 0j), np.zeros((n_targets, q, n_f)), np.zeros((n_targets, n_f)),
            np.ones(n_f, bool))


def _max_pair_coherence(Gcc, acc) -> np.ndarray:
    """Largest ordinary coherence ``|G_ij|^2 / (G_ii G_jj)`` between two of the signals of the
    spectral block ``Gcc`` (q, q, f) with autospectra ``acc`` (q, f), per frequency; 1 where a
    signal has no power, 0 for one signal (:func:`livesweep.spectral.miso.input_coherence_max`)."""
    q = acc.shape[0]
    if q < 2:
        return np.zeros(acc.shape[-1])
    a, b = np.triu_indices(q, 1)
    g = Gcc[a, b]
    den = acc[a] * acc[b]
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(den > 0, (g.real**2 + g.imag**2) / den, 1.0)
    return np.clip(c, 0.0, 1.0).max(axis=0)


def _condition_many(Gcc, Gct, acc, att, n_segments, ill_cond):
    """Every target conditioned on the same q signals at once (method.md §6): the arithmetic of
    :func:`livesweep.spectral.miso.condition_blocks` on each (q+1)x(q+1) block over (conditioning
    signals, target), through the block inverse, so that one inverse per frequency serves every
    target.

    With ``R = D^-1 Gcc D^-1`` (the conditioning signals' coherence matrix, ``D`` their root
    autospectra), ``r`` the target's cross-spectra scaled the same way and by its own root
    autospectrum, ``P = R^-1`` and ``b = P r``: the block's inverse ``C`` (scaled to unit diagonal)
    has ``C_yy = 1 / (1 - m)``, ``C_iy = -b_i C_yy``, ``C_ii = P_ii + |b_i|^2 C_yy`` with ``m = r^H b``,
    so the multiple coherence is ``m``, the partial coherence ``|b_i|^2 / ((1 - m) P_ii + |b_i|^2)``
    and ``H = Gcc^-1 Gct = D^-1 b sqrt(G_yy)``.

    Parameters
    ----------
    Gcc : ndarray, complex, shape (q, q, f)
        Spectral matrix of the conditioning signals (conjugate on the first index).
    Gct : ndarray, complex, shape (q, T, f)
        Their cross-spectra with the targets.
    acc, att : ndarray, shape (q, f) and (T, f)
        Autospectra (the same scale as ``Gcc`` and ``Gct``).
    n_segments : int
        Segments averaged (fewer than q + 1: nothing can be conditioned).
    ill_cond : ndarray of bool, shape (f,)
        Frequencies flagged ill-conditioned by the conditioning signals' cross-coherence.

    Returns
    -------
    (H, pc, mc, ill, redo) or None
        ``H``, ``pc`` (T, q, f), ``mc`` (T, f), ``ill`` (f,): where a signal of a block has no power
        H is NaN, the coherences 0 and the frequency flagged (as ``condition_blocks``); ``redo``:
        targets whose block is singular somewhere (``1 - m <= 0``), to be conditioned on their own.
        None when ``Gcc`` itself is singular at some frequency.
    """
    q, T, n_f = Gcc.shape[0], Gct.shape[1], Gcc.shape[-1]
    if n_segments < q + 1:
        return _nan_conditioned(T, q, n_f) + ((),)
    dx, dy = np.sqrt(acc), np.sqrt(att)
    everywhere = dx.min() > 0 and dy.min() > 0                  # the usual case: every signal has power
    if everywhere:
        f, ill = slice(None), ill_cond.copy()
    else:
        ok_x = np.all(dx > 0, axis=0)                           # (f,): every conditioning signal has power
        ok = ok_x & (dy > 0)                                    # (T, f): so has the target
        if not ok.any():
            return _nan_conditioned(T, q, n_f) + ((),)
        f, ill = np.flatnonzero(ok_x), ill_cond | ~ok.all(axis=0)
        dx, dy, Gcc, Gct = dx[:, f], dy[:, f], Gcc[..., f], Gct[..., f]
    with np.errstate(divide="ignore", invalid="ignore"):
        ix, iy = 1.0 / dx, 1.0 / dy
        Rm = np.moveaxis(Gcc * (ix[:, None, :] * ix[None, :, :]), -1, 0)      # (F, q, q), unit diagonal
        r = np.moveaxis(Gct * (ix[:, None, :] * iy[None, :, :]), -1, 0)        # (F, q, T)
    d = np.arange(q)
    Rm[:, d, d] = 1.0
    try:
        P = np.linalg.inv(Rm)
    except np.linalg.LinAlgError:
        return None
    b = P @ r                                                   # (F, q, T)
    m = np.einsum("fqt,fqt->ft", r.real, b.real)                # multiple coherence Re(r^H b), (F, T)
    m += np.einsum("fqt,fqt->ft", r.imag, b.imag)
    res = 1.0 - m                                               # 1 / C_yy: the unexplained fraction
    b2 = b.real**2
    b2 += b.imag**2
    den = np.diagonal(P, axis1=1, axis2=2).real[:, :, None] * res[:, None, :]
    den += b2
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np.divide(b2, den, out=b2)                          # partial coherence, (F, q, T)
        b *= (dy * ix[:, None, :]).transpose(2, 0, 1)          # H = D^-1 b sqrt(G_yy)
    np.clip(p, 0.0, 1.0, out=p)
    np.clip(m, 0.0, 1.0, out=m)
    H, pc, mc = b.transpose(2, 1, 0), p.transpose(2, 1, 0), m.T   # (T, q, F), (T, q, F), (T, F)
    okf = True if everywhere else ok[:, f]
    redo = () if res.min() > 0 else np.flatnonzero(np.any(okf & ~(res.T > 0), axis=1))
    if not everywhere:                                          # blanks where a signal has no power
        Hs, pcs, mcs = _nan_conditioned(T, q, n_f)[:3]
        Hs[:, :, f] = np.where(okf[:, None, :], H, np.nan + 0j)
        pcs[:, :, f] = np.where(okf[:, None, :], pc, 0.0)
        mcs[:, f] = np.where(okf, mc, 0.0)
        H, pc, mc = Hs, pcs, mcs
    return H, pc, mc, ill, redo


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
        self._snapshot = None                               # (version, fields of its results) of the last window
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
        ok = True if valid is None else np.asarray(valid, bool)    # True: every sample valid
        if valid is not None and ok.shape != (m,):
            raise ConfigError(f"valid must have shape ({m},) like the block's samples, got {ok.shape}")
        if not np.isfinite(block).all():                         # rare: find the samples
            finite = np.all(np.isfinite(block), axis=0)
            bad = ok & ~finite
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
            elif removed and self._drifted():   # adding a segment raises the bound by at most eps:
                self._resync(self._drifted(per_frequency=True))   # checked when one leaves
        return added

    def _append(self, block: np.ndarray, ok) -> None:
        """Append samples to the un-segmented tail: moved to the front of its storage when the end
        is reached, the storage doubled when even that is too small. ``ok``: validity per sample,
        or True for all."""
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
        c = Xk[self._layout.driver_rows_at].conj()[:, None, :] * Xk[None, :, :]
        a = Xk.real**2 + Xk.imag**2
        if sign > 0:
            self._rows = np.add(self._rows, c, out=c)
            self._auto = np.add(self._auto, a, out=a)
        else:
            self._rows = np.subtract(self._rows, c, out=c)
            self._auto = np.subtract(self._auto, a, out=a)
        # recursive-summation bound: eps * sum over operations of |partial sum| (autospectra are >= 0)
        self._err += np.abs(self._auto)

    def _drifted(self, per_frequency: bool = False):
        """Whether the bound on the relative rounding error of some running sum, ``eps * err /
        |sum|``, exceeds ``DRIFT_TOLERANCE`` (so where a sum is 0 with rounding residue behind it;
        0 / 0 counts as no error), compared without dividing: anywhere, or per frequency."""
        over = self._err > (DRIFT_TOLERANCE / _EPS) * np.abs(self._auto)
        return over.any(axis=0) if per_frequency else bool(over.any())

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
        if self._snapshot is not None and self._snapshot[0] == self._version:
            return OnlineResult._of_window(self._snapshot[1], self.time_s, len(self._excluded))
        starts = np.fromiter(map(itemgetter(0), self._segs), dtype=np.int64, count=K)
        starts.setflags(write=False)
        n_eff = self._n_eff.get(K)
        if n_eff is None:
            n_eff = self._n_eff[K] = effective_averages(K, self.n, self.hop, self.taper)
        sums = _WindowSums(self._layout, self._rows, self._auto, tuple(map(itemgetter(1), self._segs)),
                           self._scale / K)
        window = dict(omega=self.omega, names=self.names, inputs=self.inputs, outputs=self.outputs, n_segments=K,
                      n_eff=n_eff, window_s=self.window_s, segment_s=self.segment_s, overlap=self.overlap,
                      sample_rate_hz=self.sample_rate_hz, segment_starts=starts,
                      max_input_coherence=self.max_input_coherence, references=self.references, _sums=sums,
                      _memo={})
        self._snapshot = (self._version, window)
        return OnlineResult._of_window(window, self.time_s, len(self._excluded))
