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
of the inputs' coherence matrix per frequency
(:func:`~livesweep.spectral.online_conditioning._condition_many`).
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

Modules
-------
This module holds the estimator: the stream, its segments and the running sums' updates and
drift resyncs. What a result reads is in :mod:`livesweep.spectral.online_result`
(:class:`OnlineResult`), the conditioning in :mod:`livesweep.spectral.online_conditioning`, and the
layout of the running sums in :mod:`livesweep.spectral.online_sums`; the names of those modules that
callers import from here are re-exported.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import InitVar, dataclass, field  # noqa: F401  (re-exported)
from functools import cached_property  # noqa: F401  (re-exported)
from operator import itemgetter

import numpy as np

from livesweep.spectral import DEFAULT_WINDOW_S
from livesweep.errors import ConfigError, require_number
from livesweep.spectral.miso import condition_blocks, input_coherence_max  # noqa: F401  (re-exported)
from livesweep.spectral.online_result import OnlineResult
from livesweep.spectral.online_sums import _Layout, _WindowSums, _readonly
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW
from livesweep.spectral.transform import bin_grid, fft_length, segment_spectra
from livesweep.spectral.windows import effective_averages, hann

# Re-exported for callers and tests that import them from this module: the result's helpers, the
# conditioning and the names those use.
from livesweep.spectral.online_conditioning import (  # noqa: F401
    _condition, _condition_many, _max_pair_coherence, _nan_conditioned)
from livesweep.spectral.online_result import _G_property, _carry_power, _restamped  # noqa: F401
from livesweep.spectral.online_sums import _run  # noqa: F401
from livesweep.spectral.reference import combine_legs  # noqa: F401
from livesweep.spectral.response import FrequencyResponseSet  # noqa: F401
from livesweep.spectral.spectra import _random_error_of_incoherence  # noqa: F401

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

