"""Excitation adequacy, a GO / NO-GO verdict and alerts for the live sweep display (method.md §2.5).

:class:`ExcitationMonitor` turns each :class:`~livesweep.spectral.online.OnlineResult` (and the
input samples received since the previous update) into an :class:`ExcitationStatus`:

* per pair, where the response is adequate -- gamma^2 >= 0.6 and eps_r <= 0.2
  (:mod:`livesweep.spectral.adequacy`) -- restricted to frequencies the segments resolve
  (3 periods per segment, :attr:`OnlineResult.omega_min_usable`);
* per input, how much of the band its autospectrum covers;
* per input, the sweep's current frequency and the time still needed to reach the band's top;
* a verdict: ``WAIT`` until the window holds ``min_n_eff`` equivalent averages (coherence from one
  or two segments is ~1 whatever the data, method.md §2.5), then ``GO`` when every required pair is
  adequate over at least ``required_fraction`` of the band, else ``NO-GO``;
* alerts: ``coherence_collapse``, ``input_correlation``, ``saturation``, ``data_gap``, ``packet_loss``;
  the monitor adds ``link`` (link and clock counters that grew, another system on the link),
  ``map`` (a signal of the map that found nothing, and why) and ``verdict`` (the verdict changed).

Fractions of the band are measured in log frequency (decades), as a Bode plot shows them: each
point of the uniform frequency grid counts for the log-width of its cell.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError, require_number
from livesweep.numeric import percent
from livesweep.spectral.adequacy import pair_adequacy
from livesweep.spectral.criteria import DEFAULT_CRITERIA, Criteria
from livesweep.spectral.online import OnlineResult
from livesweep.spectral.response import FrequencyResponse

__all__ = ["Alert", "PairStatus", "ExcitationStatus", "ExcitationMonitor", "SweepTrack", "track_sweep",
           "half_period_frequencies", "log_band_weights", "ALERT_KINDS"]

ALERT_KINDS = ("coherence_collapse", "input_correlation", "saturation", "data_gap", "packet_loss", "link", "map",
               "verdict", "limit")


@dataclass(frozen=True)
class Alert:
    """Something the flight-test engineer should look at now.

    Attributes
    ----------
    kind : str
        One of ``ALERT_KINDS``.
    message : str
        One line naming the signal(s), the value and the threshold.
    value : float
        The measured quantity (coherence drop, input coherence, fraction of samples at a limit,
        or a count of gaps / lost packets).
    """

    kind: str
    message: str
    value: float


@dataclass(frozen=True)
class PairStatus:
    """Adequacy of one output/input pair over the requested band.

    Attributes
    ----------
    output, input : str
    adequate_band_rad_s : (float, float) or None
        Widest contiguous stretch (in decades) where gamma^2 >= 0.6 and eps_r <= 0.2 [rad/s].
    fraction : float
        Fraction of the requested band (log frequency) that is adequate, 0..1.
    median_coherence : float
        Median gamma^2 over the resolved part of the band.
    required : bool
        Whether the pair counts for the verdict.
    """

    output: str
    input: str
    adequate_band_rad_s: tuple | None
    fraction: float
    median_coherence: float = 0.0
    required: bool = False


@dataclass(frozen=True)
class ExcitationStatus:
    """What the live display shows after one update.

    Attributes
    ----------
    t_s : float
        End of the data the spectra use [s since the estimator's first sample]; when there is no
        result yet, the newest input sample time on the caller's clock.
    pairs : tuple of PairStatus
        Every output/input pair, outputs outer.
    input_power_coverage : dict of str -> float
        Fraction of the band (log frequency) where the input autospectrum is within
        ``coverage_drop_db`` (20 dB) of its 90th percentile over the band (see
        :class:`ExcitationMonitor`); 0 without data.
    sweep_frequency_rad_s : dict of str -> float or None
        Current instantaneous frequency of each input [rad/s]; None when quiet or unknown.
    time_remaining_s : dict of str -> float or None
        Sweep time still needed to reach the band's top [s], assuming the frequency keeps rising
        exponentially at the rate observed over the last ``fit_s`` seconds; None when unknown or
        the frequency is not rising; 0 once the top is reached.
    verdict : str
        ``"WAIT"``, ``"GO"`` or ``"NO-GO"``.
    reasons : tuple of str
        Why (one line per required pair, or what is being waited for).
    alerts : tuple of Alert
    n_eff : float
        Equivalent independent averages in the window (0 without data).
    """

    t_s: float
    pairs: tuple
    input_power_coverage: dict
    sweep_frequency_rad_s: dict
    time_remaining_s: dict
    verdict: str
    reasons: tuple
    alerts: tuple
    n_eff: float = 0.0

    def pair(self, output: str, input: str) -> PairStatus:
        """The status of one pair; ConfigError naming the pair when absent."""
        for p in self.pairs:
            if p.output == output and p.input == input:
                return p
        raise ConfigError(f"no pair {output}/{input} in the excitation status")

    def alerts_of(self, kind: str) -> tuple:
        """Alerts of one kind."""
        return tuple(a for a in self.alerts if a.kind == kind)


def log_band_weights(omega: np.ndarray, band_rad_s) -> np.ndarray:
    """Weight of each grid point as a fraction of the band's decades (sums to <= 1).

    Each point stands for the cell between the geometric midpoints to its neighbours, clipped to
    the band; points outside the band weigh 0.

    Parameters
    ----------
    omega : ndarray
        Increasing positive frequencies [rad/s].
    band_rad_s : (float, float)
        [rad/s].
    """
    w = np.asarray(omega, float)
    lo, hi = float(band_rad_s[0]), float(band_rad_s[1])
    lw = np.log(w)
    mids = 0.5 * (lw[1:] + lw[:-1])
    left = np.concatenate([[lw[0]], mids])
    right = np.concatenate([mids, [lw[-1]]])
    left = np.clip(left, math.log(lo), math.log(hi))
    right = np.clip(right, math.log(lo), math.log(hi))
    return np.clip(right - left, 0.0, None) / math.log(hi / lo)


@dataclass(frozen=True)
class SweepTrack:
    """Instantaneous frequency of an oscillating input from its zero crossings.

    Attributes
    ----------
    omega_rad_s : float
        Frequency at ``t_s`` [rad/s], from a log-linear fit extrapolated to ``t_s``.
    rate_per_s : float or None
        d ln(omega)/dt [1/s] over the fit span (None with fewer than 3 half-periods).
    t_s : float
        Time the estimate refers to (newest sample) [s].
    n_half_periods : int
        Half-periods in the fit.
    """

    omega_rad_s: float
    rate_per_s: float | None
    t_s: float
    n_half_periods: int


def _crossing_times(t: np.ndarray, x: np.ndarray, h: float) -> np.ndarray:
    """Zero-crossing times of ``x`` with hysteresis ``h`` (a crossing counts once |x| > h on the
    other side); each crossing time is the mean of the linearly interpolated sign changes between
    leaving one threshold and reaching the other."""
    s = np.where(x > h, 1, np.where(x < -h, -1, 0))
    nz = np.flatnonzero(s)
    if nz.size < 2:
        return np.empty(0)
    st = s[nz]
    flip = np.flatnonzero(st[1:] != st[:-1]) + 1
    if flip.size == 0:
        return np.empty(0)
    k_from, k_to = nz[flip - 1], nz[flip]
    neg = x < 0
    zc = np.flatnonzero(neg[1:] != neg[:-1])       # sign change between zc and zc+1 (x0 - x1 != 0)
    if zc.size == 0:
        return np.empty(0)
    x0, x1 = x[zc], x[zc + 1]
    tz = t[zc] + (t[zc + 1] - t[zc]) * x0 / (x0 - x1)
    a = np.searchsorted(zc, k_from, "left")
    b = np.searchsorted(zc, k_to, "left") - 1
    ok = b >= a
    return 0.5 * (tz[a[ok]] + tz[b[ok]])


def _centred_crossings(t_s, values, hysteresis: float) -> tuple | None:
    """``(t, crossings, peak)``: the finite samples' times, the times they cross their midrange (of
    the 0.5/99.5 % percentiles: a sweep oscillates about trim, and the midrange does not depend on
    how many periods the buffer holds) with hysteresis ``hysteresis`` x the peak deviation, and that
    peak; None with fewer than 8 samples or no deviation."""
    t = np.asarray(t_s, float)
    x = np.asarray(values, float)
    ok = np.isfinite(x) & np.isfinite(t)
    t, x = t[ok], x[ok]
    if x.size < 8:
        return None
    lo, hi = np.percentile(x, [0.5, 99.5])
    x0 = x - 0.5 * (lo + hi)
    peak = float(np.max(np.abs(x0)))
    if peak == 0.0:
        return None
    return t, _crossing_times(t, x0, hysteresis * peak), peak


def half_period_frequencies(t_s, values, *, hysteresis: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """Instantaneous frequency of an oscillating signal, one value per half-period.

    The signal is centred on the midrange of its 0.5/99.5 % percentiles (a sweep oscillates about
    trim), zero crossings are found with hysteresis ``hysteresis`` x the peak deviation (noise on a
    quiet stretch crosses nothing), and each half-period ``d`` between consecutive crossings gives
    ``omega = pi / d`` at its midpoint (docs/method.md §2.5: the instantaneous frequency of the input
    from its zero-crossing spacing).

    Parameters
    ----------
    t_s : ndarray
        Sample times [s], increasing.
    values : ndarray
        Samples (NaN = missing).
    hysteresis : float
        Threshold as a fraction of the peak deviation.

    Returns
    -------
    t_mid : ndarray
        Midpoints of the half-periods [s].
    omega : ndarray
        Their frequencies [rad/s].
    """
    empty = (np.empty(0), np.empty(0))
    got = _centred_crossings(t_s, values, hysteresis)
    if got is None:
        return empty
    c = got[1]
    d = np.diff(c)
    keep = d > 0
    if not np.any(keep):
        return empty
    return (0.5 * (c[1:] + c[:-1]))[keep], np.pi / d[keep]


def track_sweep(t_s, values, *, hysteresis: float = 0.3, fit_s: float = 20.0, min_half_periods: int = 3,
                quiet_amplitude: float = 0.0, max_omega_rad_s: float | None = None) -> SweepTrack | None:
    """Current frequency and rate of increase of a sweep from the recent samples of the input.

    The signal is centred on the midrange of its 0.5/99.5 % percentiles (a sweep oscillates about
    trim, and the midrange does not depend on how many periods the buffer holds), zero crossings
    are found with hysteresis ``hysteresis`` x the peak, each half-period ``d`` gives ``omega = pi/d``
    at its midpoint, and ``ln omega`` is fitted linearly in time over the half-periods of the last
    ``fit_s`` seconds (at least the last ``min_half_periods``) and evaluated at the newest sample.

    Parameters
    ----------
    t_s : ndarray
        Sample times [s], increasing.
    values : ndarray
        Input samples (NaN = missing).
    hysteresis : float
        Threshold as a fraction of the peak deviation.
    fit_s : float
        Span of the fit [s].
    min_half_periods : int
        Fewer crossings than ``min_half_periods + 1`` -> None.
    quiet_amplitude : float
        Peak deviation at or below which the input is quiet (input units) -> None.
    max_omega_rad_s : float, optional
        Estimates above this (e.g. Nyquist) -> None.

    Returns
    -------
    SweepTrack or None
        None when the input is quiet, has stopped oscillating (no crossing for two of its last
        half-periods), or has too few crossings since its last pause (a half-period over three
        times the one before it ends a sweep; the crossings before it are not used).
    """
    got = _centred_crossings(t_s, values, hysteresis)
    if got is None or got[2] <= quiet_amplitude:
        return None
    t, c, _ = got
    if c.size < min_half_periods + 1:
        return None
    d = np.diff(c)
    # An oscillation does not slow down threefold within one half-period: such a half-period spans
    # a pause (trim between sweeps); only the crossings after the last pause belong to this sweep.
    brk = np.flatnonzero(d[1:] > 3.0 * d[:-1]) + 1
    if brk.size:
        c, d = c[brk[-1] + 1:], d[brk[-1] + 1:]
    if c.size < min_half_periods + 1 or not np.all(d > 0):
        return None
    t_now = float(t[-1])
    if t_now - c[-1] > 2.0 * d[-1]:
        return None                                 # stopped oscillating
    m = 0.5 * (c[1:] + c[:-1])
    lw = np.log(np.pi / d)
    sel = m >= t_now - fit_s
    if np.sum(sel) < min_half_periods:
        sel = np.zeros(m.size, bool)
        sel[-min_half_periods:] = True
    mm, ll = m[sel], lw[sel]
    if mm.size >= 3 and np.ptp(mm) > 0:
        rate, icpt = np.polyfit(mm - t_now, ll, 1)
        omega = float(np.exp(icpt))
        rate = float(rate)
    else:
        omega, rate = float(np.exp(ll[-1])), None
    if not np.isfinite(omega) or (max_omega_rad_s is not None and omega > max_omega_rad_s):
        return None
    return SweepTrack(omega, rate, t_now, int(mm.size))


def _per_input(value, inputs, what):
    """A scalar or a dict of per-input values -> dict for every input."""
    if value is None:
        return {i: None for i in inputs}
    if isinstance(value, dict):
        for k in value:
            if k not in inputs:
                raise ConfigError(f"{what}: {k!r} is not an input ({', '.join(inputs)})")
        return {i: value.get(i) for i in inputs}
    return {i: value for i in inputs}


class ExcitationMonitor:
    """Adequacy, verdict and alerts from successive online results (the state between updates).

    Parameters
    ----------
    inputs, outputs : sequence of str
        Signals to judge (subsets of the estimator's).
    band_rad_s : (float, float)
        Requested band [rad/s]; fractions are of this band, in decades.
    sample_rate_hz : float
        Rate of the input samples given to :meth:`update` [Hz] (sizes the input history and caps
        the sweep-frequency estimate at Nyquist).
    required_pairs : sequence of (output, input), optional
        Pairs that must be adequate for GO. Default: the on-axis pairs ``(outputs[k], inputs[k])``
        for ``k < min(len(outputs), len(inputs))`` -- list the outputs in the order of their
        on-axis inputs (e.g. inputs ``da, dr`` and outputs ``p, r, ...``) or pass the pairs.
    saturation_limits : dict of input -> (lo, hi), optional
        Travel limits (input units); a new sample at or beyond one (within ``saturation_margin``
        of the range) raises a ``saturation`` alert.
    collapse_drop : float
        A ``coherence_collapse`` alert is raised when, for a required pair, the median coherence
        over the adequate frequencies of a status within the last ``collapse_lookback_s`` seconds
        has dropped by more than this (default 0.3).
    max_input_coherence : float
        ``input_correlation`` alert when the median coherence between two inputs, over the
        frequencies where both carry power, exceeds this (default 0.5, method.md §6.2).
    min_n_eff : float
        Equivalent averages needed before a verdict (default 3, about 5 overlapped segments).
    conditioned : bool
        Judge pairs on the MISO-conditioned responses (partial coherence) instead of the ordinary
        ones (default False: during a single-axis sweep the other inputs are quiet and the input
        spectral matrix singular; the ``input_correlation`` alert says when ordinary coherence is
        contaminated by a correlated input).
    coverage_drop_db : float
        Input power coverage threshold below the band's 90th percentile of G_xx (default 20 dB,
        method.md §2.5). The 90th percentile rather than the median: while a sweep is in
        progress most of the band holds no power yet, and a median reference would sit in the
        leakage floor and call the whole band covered; a complete exponential or log sweep over
        two decades has a G_xx slope of ~17-18 dB, inside the 20 dB.
    collapse_lookback_s : float, optional
        Default: two segment hops of the result (at least 5 s).
    history_s : float, optional
        Input history kept for the sweep frequency [s]; default two periods of the band's low
        end, at least 10 s.
    fit_s : float
        Span of the log-linear frequency fit [s] (:func:`track_sweep`).
    quiet_amplitude : float or dict of input -> float, optional
        Peak deviation (input units) at or below which an input counts as quiet; default 0 (only
        a constant input is quiet). Set it above the noise of a trim with sensor noise.
    saturation_margin : float
        Fraction of the limit range counted as "at the limit" (default 0).
    criteria : Criteria
        Where a pair is adequate and what a GO needs (:class:`~livesweep.spectral.criteria.Criteria`).
    """

    def __init__(self, inputs, outputs, band_rad_s, sample_rate_hz: float, *, required_pairs=None,
                 saturation_limits: dict | None = None,
                 collapse_drop: float = 0.3, max_input_coherence: float = 0.5, min_n_eff: float = 3.0,
                 conditioned: bool = False, coverage_drop_db: float = 20.0,
                 collapse_lookback_s: float | None = None, history_s: float | None = None, fit_s: float = 20.0,
                 quiet_amplitude=None, saturation_margin: float = 0.0, criteria: Criteria = DEFAULT_CRITERIA):
        self.inputs, self.outputs = tuple(inputs), tuple(outputs)
        if not self.inputs or not self.outputs:
            raise ConfigError("the excitation monitor needs at least one input and one output")
        lo, hi = (float(b) for b in band_rad_s)
        if not 0 < lo < hi:
            raise ConfigError(f"band_rad_s = [{lo:g}, {hi:g}] must satisfy 0 < low < high")
        self.band_rad_s = (lo, hi)
        self.sample_rate_hz = require_number(sample_rate_hz, "sample_rate_hz", positive=True)
        if required_pairs is None:
            required_pairs = [(self.outputs[k], self.inputs[k]) for k in range(min(len(self.outputs), len(self.inputs)))]
        self.required_pairs = tuple((str(o), str(i)) for o, i in required_pairs)
        for o, i in self.required_pairs:
            if o not in self.outputs or i not in self.inputs:
                raise ConfigError(f"required pair {o}/{i} is not an output/input pair of "
                                  f"outputs {list(self.outputs)}, inputs {list(self.inputs)}")
        self.criteria = criteria
        self.required_fraction = float(criteria.required_fraction)
        self.saturation_limits = {}
        for k, v in (saturation_limits or {}).items():
            if k not in self.inputs:
                raise ConfigError(f"saturation_limits: {k!r} is not an input ({', '.join(self.inputs)})")
            a, b = (float(x) for x in v)
            if not a < b:
                raise ConfigError(f"saturation_limits[{k!r}] = ({a:g}, {b:g}) must be (low, high) with low < high")
            self.saturation_limits[k] = (a, b)
        self.collapse_drop = float(collapse_drop)
        self.max_input_coherence = float(max_input_coherence)
        self.min_n_eff = float(min_n_eff)
        self.conditioned = bool(conditioned)
        self.coverage_drop_db = float(coverage_drop_db)
        self.collapse_lookback_s = collapse_lookback_s
        self.history_s = float(history_s) if history_s is not None else max(2 * 2 * math.pi / lo, 10.0)
        self.fit_s = float(fit_s)
        self.quiet_amplitude = _per_input(quiet_amplitude, self.inputs, "quiet_amplitude")
        self.saturation_margin = float(saturation_margin)
        n_keep = int(math.ceil(self.history_s * self.sample_rate_hz)) + 1
        self._hist = {i: (deque(maxlen=n_keep), deque(maxlen=n_keep)) for i in self.inputs}
        self._snaps = {p: deque() for p in self.required_pairs}   # (t, n_freq, median coherence, adequate mask)
        self._cache_key, self._cache = None, None

    # ----------------------------------------------------------------------------------------
    def _ingest(self, recent_inputs) -> dict:
        """Append new samples to the histories; return the new samples per input."""
        new = {}
        for name, tv in (recent_inputs or {}).items():
            if name not in self._hist:
                raise ConfigError(f"recent_inputs: {name!r} is not an input ({', '.join(self.inputs)})")
            t, v = (np.atleast_1d(np.asarray(a, float)) for a in tv)
            if t.shape != v.shape:
                raise ConfigError(f"recent_inputs[{name!r}]: times {t.shape} and values {v.shape} differ in shape")
            ht, hv = self._hist[name]
            if ht:
                keep = t > ht[-1]
                t, v = t[keep], v[keep]
            ht.extend(t.tolist())
            hv.extend(v.tolist())
            new[name] = v
        return new

    def judged(self, result: OnlineResult) -> tuple:
        """(response set, ``"ordinary"`` or ``"partial"``): the responses the adequacy is judged on,
        which the view must show (a plot of one coherence next to a verdict on another misleads).

        Through the references when the map names them and they carry power (closed loop: the
        ordinary coherence there is biased by the feedback); the MISO-conditioned set when
        ``conditioned`` was asked for; else the ordinary set (a single-axis sweep: the other inputs
        are the controller's reaction, and conditioning on them would judge the wrong thing).
        """
        best = result.best
        if result.references and best is result.referenced:
            return best, "partial"
        if self.conditioned and result.conditioned is not None:
            return result.conditioned, "partial"
        return result.ordinary, "ordinary"

    def _pair_statuses(self, result: OnlineResult):
        rs, _kind = self.judged(result)
        w = result.omega
        in_band = (w >= self.band_rad_s[0] * (1 - 1e-12)) & (w <= self.band_rad_s[1] * (1 + 1e-12))
        use = in_band & result.usable
        weights = log_band_weights(w, self.band_rad_s)
        coh_all = np.nan_to_num(rs.coherence, nan=0.0)                 # (n_out, n_in, f), all pairs at once
        eps_all = np.nan_to_num(rs.random_error, nan=np.inf)
        ok_all = use & self.criteria.adequate(coh_all, eps_all) & np.isfinite(rs.H)
        frac_all = np.minimum(ok_all.astype(float) @ weights, 1.0)
        med_all = np.median(coh_all[..., use], axis=-1) if np.any(use) else np.zeros(coh_all.shape[:2])
        out, masks = [], {}
        for o in self.outputs:
            a = rs.outputs.index(o)
            for i in self.inputs:
                b = rs.inputs.index(i)
                coh, ok = coh_all[a, b], ok_all[a, b]
                widest = None
                if np.any(ok):
                    sub = FrequencyResponse(o, i, w[use], rs.H[a, b, use], np.where(ok[use], coh[use], 0.0),
                                            eps_all[a, b, use], rs.conditioned)
                    widest = pair_adequacy(sub, self.criteria).widest_band_rad_s
                out.append(PairStatus(o, i, widest, float(frac_all[a, b]), float(med_all[a, b]),
                                      (o, i) in self.required_pairs))
                masks[(o, i)] = (coh, ok)
        return tuple(out), masks, use, weights

    def _coverage(self, result: OnlineResult, use, weights):
        cov, masks = {}, {}
        for i in self.inputs:
            g = result.auto[result.index(i)]
            gu = g[use]
            if gu.size == 0 or not np.any(gu > 0):
                cov[i], masks[i] = 0.0, np.zeros(g.size, bool)
                continue
            ref = float(np.percentile(gu, 90))
            m = use & (g > 0) & (g >= ref * 10 ** (-self.coverage_drop_db / 10))
            cov[i], masks[i] = min(float(np.sum(weights[m])), 1.0), m
        return cov, masks

    @staticmethod
    def _result_key(result: OnlineResult):
        """Identifies the segments (and data) a result averages, to skip re-judging unchanged spectra."""
        st = result.segment_starts
        return (result.names, result.omega.size, result.n_segments, int(st[0]), int(st[-1]), result.n_excluded,
                float(np.sum(result.auto)))

    def _judge_spectra(self, result: OnlineResult):
        """Pair statuses, coherence masks, input coverage and input-correlation alerts of one result."""
        pairs, masks, use, weights = self._pair_statuses(result)
        coverage, power_masks = self._coverage(result, use, weights)
        alerts = []
        if result.n_eff >= self.min_n_eff:      # input correlation, where both inputs carry power
            for a in range(len(self.inputs)):
                for b in range(a + 1, len(self.inputs)):
                    ia, ib = self.inputs[a], self.inputs[b]
                    m = power_masks[ia] & power_masks[ib]
                    if np.sum(m) < 3:
                        continue
                    ga, gb = result.index(ia), result.index(ib)
                    c = np.abs(result.cross(ia, ib)[m]) ** 2 / (result.auto[ga, m] * result.auto[gb, m])
                    med = float(np.median(np.clip(c, 0.0, 1.0)))
                    if med > self.max_input_coherence:
                        alerts.append(Alert("input_correlation", f"inputs {ia} and {ib} are correlated: median "
                                            f"coherence {med:.2f} > {self.max_input_coherence:g} where both carry "
                                            "power; MISO conditioning unreliable", med))
        return pairs, masks, coverage, tuple(alerts), power_masks

    def update(self, result: OnlineResult | None, recent_inputs: dict | None = None, *, gaps: int = 0,
               packets_lost: int = 0, sweeping: bool = False) -> ExcitationStatus:
        """Judge the current window.

        Parameters
        ----------
        result : OnlineResult or None
            The estimator's current result (None before the first segment -> ``WAIT``).
        recent_inputs : dict of input -> (t_s, values)
            Input samples received since the previous update (times [s], any clock, increasing);
            samples not newer than the last one kept are ignored, so overlapping windows are fine.
        gaps : int
            Data gaps found since the previous update (passed through as a ``data_gap`` alert).
        packets_lost : int
            Telemetry packets lost since the previous update (``packet_loss`` alert).
        sweeping : bool
            A single-axis sweep's data is in the window: the other inputs move with the swept one
            (a controller's reaction, not a second exogenous input), so their correlation is
            expected and no ``input_correlation`` alert is raised.

        Returns
        -------
        ExcitationStatus
        """
        new = self._ingest(recent_inputs)
        alerts = []
        # sweep frequency and time remaining
        freq, remaining = {}, {}
        nyq = math.pi * self.sample_rate_hz
        t_latest = None
        for i in self.inputs:
            ht, hv = self._hist[i]
            tr = None
            if ht:
                t_latest = ht[-1] if t_latest is None else max(t_latest, ht[-1])
                q = self.quiet_amplitude[i]
                tr = track_sweep(np.fromiter(ht, float, len(ht)), np.fromiter(hv, float, len(hv)), fit_s=self.fit_s,
                                 quiet_amplitude=0.0 if q is None else float(q), max_omega_rad_s=nyq)
            freq[i] = None if tr is None else tr.omega_rad_s
            if tr is None:
                remaining[i] = None
            elif tr.omega_rad_s >= self.band_rad_s[1]:
                remaining[i] = 0.0
            elif tr.rate_per_s is None or tr.rate_per_s <= 0:
                remaining[i] = None
            else:
                remaining[i] = math.log(self.band_rad_s[1] / tr.omega_rad_s) / tr.rate_per_s
        # saturation
        for i, (a, b) in self.saturation_limits.items():
            v = new.get(i)
            if v is None or v.size == 0:
                continue
            margin = self.saturation_margin * (b - a)
            v = v[np.isfinite(v)]
            n_sat = int(np.sum((v >= b - margin) | (v <= a + margin)))
            if n_sat:
                alerts.append(Alert("saturation", f"{i} at its travel limit ({a:g}, {b:g}) in {n_sat} of "
                                    f"{v.size} new samples", n_sat / max(v.size, 1)))
        if gaps:
            alerts.append(Alert("data_gap", f"{int(gaps)} data gap(s) since the last update; segments touching "
                                "them are left out of the spectra", float(gaps)))
        if packets_lost:
            alerts.append(Alert("packet_loss", f"{int(packets_lost)} telemetry packet(s) lost since the last update",
                                float(packets_lost)))

        if result is None:
            pairs = tuple(PairStatus(o, i, None, 0.0, 0.0, (o, i) in self.required_pairs)
                          for o in self.outputs for i in self.inputs)
            return ExcitationStatus(t_s=float(t_latest) if t_latest is not None else 0.0, pairs=pairs,
                                    input_power_coverage={i: 0.0 for i in self.inputs},
                                    sweep_frequency_rad_s=freq, time_remaining_s=remaining, verdict="WAIT",
                                    reasons=("waiting for the first complete segment",), alerts=tuple(alerts))
        for n in self.inputs:
            if n not in result.inputs:
                raise ConfigError(f"input {n!r} is not an input of the online result ({', '.join(result.inputs)})")
        for n in self.outputs:
            if n not in result.outputs:
                raise ConfigError(f"output {n!r} is not an output of the online result ({', '.join(result.outputs)})")

        key = self._result_key(result)
        if key != self._cache_key:              # the spectra change only when a segment enters or leaves
            self._cache = self._judge_spectra(result)
            self._cache_key = key
            changed = True
        else:
            changed = False
        pairs, masks, coverage, corr_alerts, power_masks = self._cache
        enough = result.n_eff >= self.min_n_eff
        if not sweeping:
            alerts.extend(corr_alerts)

        # coherence collapse on the required pairs
        t_now = float(result.t_end_s)
        lookback = self.collapse_lookback_s
        if lookback is None:
            lookback = max(5.0, 2.0 * result.segment_s * (1.0 - result.overlap))
        # (only where the input still has power: a sweep that has moved on leaves its old band, and
        # the coherence there falls as it should; that is no collapse)
        for p in self.required_pairs:
            coh, ok = masks[p]
            snaps = self._snaps[p]
            while snaps and (t_now - snaps[0][0] > lookback or snaps[0][1] != coh.size):
                snaps.popleft()
            if enough:
                drop = 0.0
                powered = power_masks[p[1]]
                for _, _, ref_coh, m_ref in snaps:
                    m = m_ref & powered
                    if np.sum(m) >= 3:
                        drop = max(drop, float(np.median(ref_coh[m])) - float(np.median(coh[m])))
                if drop > self.collapse_drop:
                    alerts.append(Alert("coherence_collapse", f"{p[0]}/{p[1]}: median coherence over its adequate "
                                        f"band fell by {drop:.2f} (> {self.collapse_drop:g}) within {lookback:.0f} s "
                                        "where the input still has power", drop))
                if changed and np.sum(ok) >= 3:
                    snaps.append((t_now, coh.size, coh.copy(), ok))

        # verdict
        reasons = []
        if not enough:
            verdict = "WAIT"
            reasons.append(f"{result.n_segments} segment(s), n_eff {result.n_eff:.1f} < {self.min_n_eff:g}: "
                           "coherence is not meaningful yet")
        else:
            verdict = "GO"
            band = f"{self.band_rad_s[0]:g}-{self.band_rad_s[1]:g} rad/s"
            for ps in pairs:
                if not ps.required:
                    continue
                word = "adequate" if ps.fraction >= self.required_fraction else "NOT adequate"
                if ps.fraction < self.required_fraction:
                    verdict = "NO-GO"
                where = "" if ps.adequate_band_rad_s is None else \
                    f", widest {ps.adequate_band_rad_s[0]:.3g}-{ps.adequate_band_rad_s[1]:.3g} rad/s"
                reasons.append(f"{ps.output}/{ps.input}: {percent(ps.fraction, self.required_fraction)} of {band} {word} "
                               f"(need {percent(self.required_fraction)}){where}")
            if not self.required_pairs:
                verdict = "NO-GO"
                reasons.append("no required pairs")
        return ExcitationStatus(t_s=t_now, pairs=pairs, input_power_coverage=coverage, sweep_frequency_rad_s=freq,
                                time_remaining_s=remaining, verdict=verdict, reasons=tuple(reasons),
                                alerts=tuple(alerts), n_eff=float(result.n_eff))
