"""The online estimator's result: one window's spectral matrix and the responses it gives.

One job: :class:`OnlineResult` turns the running sums of the segments in the sliding window (a
:class:`~livesweep.spectral.online_sums._WindowSums`), or a whole spectral matrix, into the
spectral matrix ``G``, the autospectra and cross-spectra, and the ordinary, MISO-conditioned and
referenced response sets (:class:`~livesweep.spectral.response.FrequencyResponseSet`), each
computed once per window contents and shared by that window's results. The conditioning itself is
in :mod:`livesweep.spectral.online_conditioning`.
"""

from __future__ import annotations

import math
from dataclasses import InitVar, dataclass, field
from functools import cached_property

import numpy as np

from livesweep.errors import ConfigError
from livesweep.spectral.miso import input_coherence_max
from livesweep.spectral.online_conditioning import _condition, _condition_many, _max_pair_coherence, _nan_conditioned
from livesweep.spectral.online_sums import _WindowSums, _readonly, _run
from livesweep.spectral.reference import combine_legs
from livesweep.spectral.response import FrequencyResponseSet
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW, _random_error_of_incoherence

__all__ = ["OnlineResult"]


def _instance_without_init(cls, fields: dict, **changed):
    """An instance of the dataclass ``cls`` whose ``__dict__`` is ``fields`` updated with
    ``changed``, made without calling ``__init__`` (so without ``__post_init__``).

    Why: the estimator is asked for a result after every block, and while no segment enters or
    leaves the window each result is the previous one with a few fields moved on (``t_end_s`` and
    ``n_excluded`` of an :class:`OnlineResult`, ``settings`` of its response sets). This per-block
    cached result is made by copying the fields instead of passing them through the dataclass
    ``__init__``, which keeps it cheap.

    What it relies on: ``cls`` is a plain dataclass whose fields all live in the instance
    ``__dict__`` (no ``__slots__``; frozen is fine, the ``__dict__`` is written directly, not
    through ``__setattr__``), ``fields`` holds every field, and ``__post_init__`` would do nothing
    for these values: no check that could fail, no conversion, no side effect. That holds for the
    two callers: :meth:`OnlineResult._of_window` (its ``__post_init__`` only stores a spectral
    matrix given whole, and the cached path has none: ``G`` is None and ``_sums`` is set) and
    :func:`_restamped` (the fields come from a :class:`FrequencyResponseSet` already made through
    ``__init__``, whose ``__post_init__`` froze and checked them; only ``settings`` changes, which
    it neither checks nor converts). ``tests/test_online_estimator.py`` pins both
    ``__post_init__`` methods, so a change to either fails there until this shortcut is reviewed.
    """
    obj = object.__new__(cls)
    obj.__dict__.update(fields)
    obj.__dict__.update(changed)
    return obj


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
        results (so with their memo). Made without ``__init__`` (:func:`_instance_without_init`):
        its one check, that a result has its spectral matrix or the running sums, holds by
        construction (``_sums`` is set)."""
        return _instance_without_init(cls, window, t_end_s=t_end_s, n_excluded=n_excluded)

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
        """Every signal of ``targets`` conditioned on the signals ``cond``
        (:func:`~livesweep.spectral.online_conditioning._condition_many`); the targets the fast path
        cannot do (a singular block) go through
        :func:`~livesweep.spectral.online_conditioning._condition` on their own block.
        ``ill_cond``: frequencies where ``cond`` are too coherent."""
        q = len(cond)
        out = _condition_many(*self._conditioning_spectra(cond, targets), self.n_segments, ill_cond)
        if out is None:                                   # the conditioning signals' matrix is singular
            redo, out = range(len(targets)), _nan_conditioned(len(targets), q, self.omega.size)
        else:
            redo = out[4]
        H, pc, mc, ill = out[:4]
        for a in redo:                                    # per block, singular-safe
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
        inputs, for every output at once from the running sums
        (:func:`~livesweep.spectral.online_conditioning._condition_many`: one inverse of the inputs'
        coherence matrix per frequency serves all outputs): conditioned H, partial coherence (stored
        as ``coherence``), multiple coherence, ill-conditioned flags.
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
        all references (:func:`~livesweep.spectral.online_conditioning._condition_many`;
        :func:`~livesweep.spectral.online_conditioning._condition` where a block is singular), with
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



def _restamped(window_set: FrequencyResponseSet, settings: dict) -> FrequencyResponseSet:
    """A copy of a window's response set with a result's own ``settings`` (``t_end_s`` and
    ``excluded_for_gaps`` move on while the window's contents stay): the same read-only arrays,
    already checked when the set was made, so the copy skips ``__init__``
    (:func:`_instance_without_init`)."""
    return _instance_without_init(FrequencyResponseSet, window_set.__dict__, settings=settings)


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

