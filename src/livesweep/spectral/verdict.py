"""Is a test point good enough? The verdict over a whole test point, from its accumulated samples.

A test point is the stretch of flight in which one input is swept (docs/method.md §2). The live monitor
collects its aligned samples and, while it runs and when it closes, asks :func:`judge_test_point`:

* **The judged band.** When the autopilot flies the sweep itself and the monitor knows what it was
  told (:class:`~livesweep.spectral.injection.SweepInjection`: ArduCopter's ``SID_F_START_HZ`` to
  ``SID_F_STOP_HZ``), the band the autopilot was told to sweep; otherwise the map's band.
* **Responses over the whole test point.** The same composite of several window lengths the
  offline identification uses (:func:`livesweep.spectral.analysis.analyze`): the swept input is
  the only input (SISO, ordinary coherence: during a single-axis sweep the other inputs are the
  controller's reaction, not exogenous), or, when the map names the logged injection as the
  swept input's reference, the response through it (coherence "partial"). Each required pair is
  adequate where gamma^2 >= 0.6 and eps_r <= 0.2 (docs/method.md §2.5); its adequate fraction is
  measured in decades of the judged band, the part a record this short cannot resolve (3 periods
  in half the record) counting as not adequate.
* **Real excitation**, judged against what was injected, never against a baseline flown before
  the test point (a take-off or a loiter has manoeuvres of its own): with a known injection, the
  input counts as swept from the sweep's start frequency up to the frequency the injection has
  reached; with a logged injection (a reference), over the frequencies the reference's own
  oscillation passed through (the instantaneous frequency of its zero crossings, docs/method.md
  §2.5); with neither, over those the input's oscillation passed through. A sweep stopped early
  never reached the frequencies above, whatever the leakage of a short window would say, and is
  never called a full sweep; a window too short to resolve the lowest frequencies does not hide
  the periods the sweep flew there.
* **A verdict with its margin.** Each rule says how far it is from its threshold. The adequate
  fraction of a pair is uncertain by the coherence estimate's random error (Bendat & Piersol:
  ``sigma(gamma^2) = 2 gamma^2 eps_r sqrt(1 - gamma^2)`` with ``eps_r`` the response's normalised
  random error): counting only the frequencies adequate at ``gamma^2 - k sigma`` and every
  frequency adequate at ``gamma^2 + k sigma`` (``k`` = :data:`MARGINAL_SIGMAS`) brackets it. A
  verdict the bracket of a deciding rule straddles reads "(marginal)": another flight of the same
  sweep, or a few lost frames, may decide it the other way. A clear verdict does not flip.
* **Running and final.** While the test point runs it is judged over the band swept so far ("GO so
  far: 0.5-2.9 Hz of 0.5-12 Hz swept"); the closing verdict is judged once, over the whole test
  point and the whole band.
* **Data loss first.** Frames lost on the way (a radio, a full socket buffer, an analysis that
  skipped frames to keep up) leave holes the monitor's grid fills by interpolation; where a fill
  cannot follow the signal it lowers the coherence (:data:`LOSS_REASON_FRACTION`). The loss of the
  test point's own signals over its own span (:class:`DataLoss`) is then the verdict's first
  reason, and a NO-GO on a loss of :data:`LOSS_LINK_FRACTION` or more reads "NO-GO (link)": it says
  nothing of the sweep.
* **GO** when the test point lasted ``min_duration_s``, the input was excited and every required
  pair is adequate over ``required_fraction`` (60 %) of the band; otherwise **NO-GO**, with what is
  missing in words an operator can act on: which band of which pair, and for a gap at the bottom
  of the band how much more low-frequency sweep it needs (4 periods of its lowest frequency,
  docs/method.md §2.5: T_rec >= 4-5 T_max).

Pure: arrays in, a frozen :class:`TestPointJudgement` out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from livesweep.errors import ConfigError
from livesweep.numeric import percent as _percent
from livesweep.numeric import points as _pts
from livesweep.spectral.adequacy import REQUIRED_FRACTION
from livesweep.spectral.criteria import DEFAULT_CRITERIA, Criteria
from livesweep.spectral.analysis import analyze
from livesweep.spectral.excitation import half_period_frequencies
from livesweep.spectral.injection import SweepInjection
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW
from livesweep.spectral.windows import longest_window_samples

__all__ = ["PairJudgement", "TestPointJudgement", "judge_test_point", "REQUIRED_FRACTION", "LOW_FREQUENCY_PERIODS",
           "NYQUIST_FRACTION", "MARGINAL_SIGMAS", "coherence_sigma", "shows_up_to_rad_s", "DataLoss", "frames_missing",
           "LOSS_REASON_FRACTION", "LOSS_LINK_FRACTION", "MIN_ISLAND_DECADES", "band_gaps", "swept_stretches"]

#: Periods of its lowest frequency a sweep needs to resolve it (docs/method.md §2.5, T_rec >= 4-5 T_max).
LOW_FREQUENCY_PERIODS = 4.0
#: The judged band ends at most this fraction of the grid's Nyquist frequency (the composite's
#: zero-padded grid and the resampler's interpolation both distort the last fifth).
NYQUIST_FRACTION = 0.8
#: Adequate stretches narrower than this [decades] do not split what is missing into pieces.
MIN_ISLAND_DECADES = 0.1
#: A band swept so far narrower than this [decades] is not judged yet.
_MIN_SWEPT_DECADES = 0.05
#: The adequate fraction's bracket: the coherence at -/+ this many of its predicted standard
#: deviations, i.e. one standard deviation of the composite's coherence as it actually scatters:
#: measured on a system of known coherence (a first-order lag with white output noise, 240 s
#: records, eight seeds), its error was 1.5 of the sigma its random error predicts (and biased
#: +0.5 of it). tests/test_judgement.py judges the bracket on another system and other seeds.
MARGINAL_SIGMAS = 1.5

# Lost frames and the coherence. The monitor's grid fills a lost frame by interpolating across it
# (holes up to max(0.1 s, 1.5 sample periods); longer ones are gaps the spectra leave out, which
# costs averages instead). Where a fill cannot follow the signal (above about a radian per filled
# stretch: 20 rad/s across a 50 ms hole) a filled sample is about as wrong as the signal is large.
# A fraction L of a signal's samples so filled adds an error uncorrelated with the signal, of about
# L / (1 - L) of the power of the samples kept; with the input and the output in different messages
# (lost independently) the coherence reads gamma^2 / ((1 + L / (1 - L))^2) = (1 - L)^2 gamma^2 there.
# (A burst that takes every message at once fills both the same way and biases less: the thresholds
# are for the independent case, a radio's.)
# Two thresholds follow from the adequacy rule (Criteria: gamma^2 >= min_coherence, eps_r <=
# max_random_error), none from a test; with other criteria they follow those
# (Criteria.loss_reason_fraction, Criteria.loss_link_fraction):
#: A loss from this fraction of a test point's frames is the verdict's first reason: at the coherence
#: threshold, its bias (1 - (1 - L)^2) gamma^2 reaches the coherence estimate's own random error
#: there, ``2 gamma^2 eps_r sqrt(1 - gamma^2)`` with eps_r at its limit (:func:`coherence_sigma`):
#: L = 1 - sqrt(1 - 2 * 0.2 * sqrt(0.4)) = 13.6 %. Below it the loss moves a coherence less than the
#: verdict's own uncertainty does (it is still said, last).
LOSS_REASON_FRACTION = DEFAULT_CRITERIA.loss_reason_fraction
#: A NO-GO on a loss from this fraction reads "NO-GO (link)": (1 - L)^2 = MIN_COHERENCE, L = 22.5 %, so
#: even a pair of perfect coherence reads no better than the threshold where the fills cannot follow
#: the sweep; such a NO-GO says nothing of the sweep. (A GO stays a GO: a loss lowers the coherence,
#: never raises it.)
LOSS_LINK_FRACTION = DEFAULT_CRITERIA.loss_link_fraction


def shows_up_to_rad_s(rate_hz: float) -> float:
    """The top of the band a signal arriving at ``rate_hz`` [Hz] can show [rad/s]: ``NYQUIST_FRACTION``
    of its Nyquist frequency (the judged band ends there on the analysis grid too)."""
    return NYQUIST_FRACTION * math.pi * float(rate_hz)


def coherence_sigma(coherence: np.ndarray, random_error: np.ndarray) -> np.ndarray:
    """Standard deviation of a coherence estimate from the response's normalised random error.

    Bendat & Piersol: ``sigma(gamma^2) / gamma^2 = sqrt(2) (1 - gamma^2) / (|gamma| sqrt(n_d))`` and
    ``eps_r = sqrt(1 - gamma^2) / (|gamma| sqrt(2 n_d))``, hence ``sigma(gamma^2) = 2 gamma^2 eps_r
    sqrt(1 - gamma^2)``: the number of averages need not be known. NaN where either is not finite.
    """
    g = np.clip(np.asarray(coherence, float), 0.0, 1.0)
    e = np.asarray(random_error, float)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(e), 2.0 * g * np.where(np.isfinite(e), e, 0.0) * np.sqrt(1.0 - g), np.nan)


def frames_missing(times, lo: float, hi: float, spacing_s: float | None = None) -> tuple[int, int]:
    """``(frames received, frames missing)`` of one signal over the span ``(lo, hi]`` [s] from its
    sample times: a hole of ``d`` between two samples misses ``round(d / dt) - 1`` frames, ``dt``
    being the signal's own spacing there (the median of its spacings: a loss in bursts, or random
    and under half, does not move it; time-stamp jitter rounds away); so do the stretches from the
    span's ends to its first and last sample. ``spacing_s``: the spacing [s] when the span holds
    fewer than three samples (None: nothing can be told then)."""
    t = np.sort(np.asarray(times, float).ravel())
    t = t[(t > lo) & (t <= hi)]
    d = np.diff(t)
    d = d[d > 0]
    dt = float(np.median(d)) if d.size >= 2 else (spacing_s or 0.0)
    if not (dt > 0 and math.isfinite(dt)):
        return int(t.size), 0
    if t.size == 0:
        return 0, int(round((hi - lo) / dt))
    ends = np.array([t[0] - lo, hi - t[-1]])
    missing = np.maximum(np.rint(d / dt) - 1, 0).sum() + np.maximum(np.rint(ends / dt) - 1, 0).sum()
    return int(t.size), int(missing)


#: The link counters a live monitor reads while a test point is open, and how a reason names them.
LINK_COUNTERS = (("kernel_drops", "datagrams dropped by the kernel (socket buffer full: this computer did not read "
                                  "them in time)"),
                 ("seq_gaps", "frames missing by MAVLink sequence number (an estimate: losses before this "
                              "computer count too)"),
                 ("analysis_shed", "frames skipped by the analysis to keep up (recorded all the same)"))


@dataclass(frozen=True)
class DataLoss:
    """What a test point lost of its data, over its own span.

    Attributes
    ----------
    fraction : float
        The loss judged, 0..1: the largest of the fraction of frames missing from any of the
        test point's signals and the fraction of its grid samples in gaps (no data at all).
    signal : str or None
        The signal that lost the most frames (None: the grid's gaps, or the link's counters, said more).
    missing, expected : int
        Frames missing of that signal, and frames it should have had (received + missing); grid
        samples in gaps and all of them when ``signal`` is None and ``measured`` is ``"grid"``;
        frames lost and received on the link when ``"link"``.
    measured : str
        ``"signal"`` (from the signal's time stamps), ``"grid"`` (the grid's gaps) or ``"link"``
        (the link's counters: a map on receive time has no stamps to count from).
    link : dict of str -> int
        The live link's counters over the time the test point was open (:data:`LINK_COUNTERS`:
        ``kernel_drops``, ``seq_gaps``, ``analysis_shed``); empty for a file (a replay has no link).
    """

    fraction: float
    signal: str | None = None
    missing: int = 0
    expected: int = 0
    measured: str = "signal"
    link: dict = field(default_factory=dict, hash=False)

    @staticmethod
    def measure(times: dict, lo: float, hi: float, valid=None, *, spacings_s: dict | None = None,
                link: dict | None = None) -> "DataLoss":
        """The loss of a test point over ``(lo, hi]`` [s, data time].

        Parameters
        ----------
        times : dict of str -> array
            Per signal judged, the times of the samples it received [s] (empty dict: not known,
            a map on receive time).
        lo, hi : float
            The span: from one grid period before its first grid sample to its last.
        valid : array of bool, optional
            Its grid samples (False in a gap).
        spacings_s : dict of str -> float, optional
            Each signal's spacing [s], for a signal with fewer than three samples in the span.
        link : dict, optional
            The link counters over the time it was open (:data:`LINK_COUNTERS`, and ``received``:
            frames received then).
        """
        link = {k: int(v) for k, v in (link or {}).items() if v}
        best = DataLoss(0.0, link={k: v for k, v in link.items() if k != "received"})
        for name, t in times.items():
            got, miss = frames_missing(t, lo, hi, (spacings_s or {}).get(name))
            if got + miss and miss / (got + miss) > best.fraction:
                best = DataLoss(miss / (got + miss), name, miss, got + miss, "signal", best.link)
        if valid is not None and np.size(valid):
            bad = int(np.size(valid) - np.count_nonzero(valid))
            if bad / np.size(valid) > best.fraction:
                best = DataLoss(bad / np.size(valid), None, bad, int(np.size(valid)), "grid", best.link)
        if not times and link:             # no stamps to count from: the link's own count of what it lost
            lost = max(link.get("kernel_drops", 0), link.get("seq_gaps", 0))
            seen = link.get("received", 0) + lost
            if seen:
                frac = 1.0 - (1.0 - lost / seen) * (1.0 - min(link.get("analysis_shed", 0) / max(seen - lost, 1), 1.0))
                if frac > best.fraction:
                    best = DataLoss(frac, None, lost + link.get("analysis_shed", 0), seen, "link", best.link)
        return best

    def describe(self) -> str:
        """``"27 % of the frames of p lost during this test point (1 913 of 7 101, missing from its
        time stamps)"``."""
        pct = _percent(self.fraction, LOSS_REASON_FRACTION)
        if self.measured == "signal":
            return (f"{pct} of the frames of {self.signal} lost during this test point ({self.missing} of "
                    f"{self.expected}, missing from its time stamps)")
        if self.measured == "grid":
            return (f"{pct} of this test point's samples in gaps ({self.missing} of {self.expected}: no data, "
                    f"frames lost on the link or a signal silent)")
        return f"{pct} of the frames on the link lost while this test point was open ({self.missing} of {self.expected})"

    def cause(self) -> str:
        """What the live link counted while the test point was open, or "" (nothing, or a file)."""
        parts = [f"{self.link[k]} {words}" for k, words in LINK_COUNTERS if self.link.get(k)]
        return "on the link while this test point was open: " + "; ".join(parts) if parts else ""


@dataclass(frozen=True)
class PairJudgement:
    """How well one required pair is identified over the test point.

    Attributes
    ----------
    output, input : str
    adequate_fraction : float
        Fraction of the judged band (decades) where gamma^2 >= 0.6 and eps_r <= 0.2.
    adequate_range : (float, float)
        The fraction counted at ``gamma^2 -/+`` its random error (``coherence_sigma``).
    band_rad_s : (float, float) or None
        The widest adequate stretch [rad/s].
    bands_rad_s : tuple of (float, float)
        Every adequate stretch [rad/s].
    coherence : str
        ``"ordinary"`` (SISO on the swept input) or ``"partial"`` (through the reference).
    median_coherence : float
        Over the resolved part of the band.
    response : FrequencyResponse or None
        The response judged, over the judged band (what a view draws next to the verdict).
    """

    output: str
    input: str
    adequate_fraction: float
    band_rad_s: tuple | None
    bands_rad_s: tuple
    coherence: str
    median_coherence: float
    adequate_range: tuple = (0.0, 0.0)
    response: object = None

    def marginal(self, required: float) -> bool:
        """The threshold lies within the fraction's random error (the bracket straddles it)."""
        lo, hi = self.adequate_range
        return lo < required <= hi


@dataclass(frozen=True)
class TestPointJudgement:
    """The verdict on one test point.

    Attributes
    ----------
    swept_input : str
    verdict : str
        ``"GO"`` or ``"NO-GO"`` (``final`` False: so far, over the band swept so far).
    final : bool
        Judged over the whole test point and the whole band (the closing verdict).
    band_rad_s : (float, float)
        The judged band [rad/s] (the injection's when it is known, else the map's).
    swept_rad_s : (float, float) or None
        The part of it swept so far [rad/s] (the injection's progress, or where the input or its
        reference has power); None when nothing is swept yet.
    pairs : tuple of PairJudgement
        The required pairs.
    excited_fraction : float or None
        Fraction of the judged band (decades) swept; None when it cannot be told.
    excitation : str
        What the sweep was judged from: ``"injection"`` (the autopilot's parameters),
        ``"reference"`` (a logged injection) or ``"input"`` (the input's own spectrum).
    marginal : bool
        A deciding rule is within its random error of the threshold.
    missing : tuple of str
        What a GO still needs, one line each (empty for GO).
    reasons : tuple of str
        Why, one line per rule, each with its distance from the threshold.
    duration_s : float
        Length of the test point's samples [s].
    resolvable_from_rad_s : float
        The lowest frequency the record's length resolves [rad/s].
    injection : SweepInjection or None
        What the autopilot was told to inject, when known.
    loss : DataLoss or None
        What the test point lost of its data over its span; None when not measured.
    criteria : Criteria
        The criteria that judged it.
    """

    __test__ = False                  # not a pytest class, whatever its name says

    swept_input: str
    verdict: str
    pairs: tuple
    excited_fraction: float | None
    missing: tuple
    reasons: tuple
    duration_s: float
    resolvable_from_rad_s: float
    final: bool = True
    band_rad_s: tuple = (0.0, 0.0)
    swept_rad_s: tuple | None = None
    excitation: str = "input"
    marginal: bool = False
    injection: SweepInjection | None = None
    loss: DataLoss | None = None
    criteria: Criteria = DEFAULT_CRITERIA

    @property
    def link_bound(self) -> bool:
        """A NO-GO on a loss of the criteria's ``loss_link_fraction`` or more: it says nothing of the sweep."""
        return (self.verdict == "NO-GO" and self.loss is not None
                and self.loss.fraction >= self.criteria.loss_link_fraction)

    @property
    def label(self) -> str:
        """``GO``, ``NO-GO``, ``GO (marginal)``, ``GO so far``, ``NO-GO (link)``, ..."""
        tag = " (link)" if self.link_bound else " (marginal)" if self.marginal else ""
        return self.verdict + ("" if self.final else " so far") + tag

    def progress(self) -> str:
        """``"0.5-2.9 Hz of 0.5-12 Hz swept"``: how much of the judged band the sweep has covered."""
        lo, hi = self.band_rad_s
        hz = 1 / (2 * math.pi)
        if self.swept_rad_s is None:
            return f"nothing of {lo * hz:.3g}-{hi * hz:.3g} Hz swept yet"
        a, b = self.swept_rad_s
        if a <= lo * (1 + 1e-6) and b >= hi * (1 - 1e-6):
            return f"all of {lo * hz:.3g}-{hi * hz:.3g} Hz ({lo:.3g}-{hi:.3g} rad/s) swept"
        return f"{a * hz:.3g}-{b * hz:.3g} Hz of {lo * hz:.3g}-{hi * hz:.3g} Hz swept"

    def to_dict(self) -> dict:
        """The judgement part of the ``/livesweep/test_point`` record (docs/outputs.md, live result channels)."""
        r = lambda x: None if x is None else [round(float(v), 4) for v in x]      # noqa: E731
        return {
            "swept_input": self.swept_input, "verdict": self.verdict, "final": self.final, "label": self.label,
            "marginal": self.marginal, "duration_s": round(self.duration_s, 3),
            "judged_band_rad_s": r(self.band_rad_s), "swept_band_rad_s": r(self.swept_rad_s),
            "excitation": self.excitation,
            "injection": None if self.injection is None else self.injection.to_dict(),
            "pairs": [{"output": p.output, "input": p.input, "adequate_fraction": round(p.adequate_fraction, 4),
                       "adequate_range": [round(p.adequate_range[0], 4), round(p.adequate_range[1], 4)],
                       "band_rad_s": r(p.band_rad_s), "coherence": p.coherence,
                       "median_coherence": round(p.median_coherence, 4)}
                      for p in self.pairs],
            "excited_fraction": None if self.excited_fraction is None else round(self.excited_fraction, 4),
            "missing": list(self.missing), "reasons": list(self.reasons),
            "resolvable_from_rad_s": round(self.resolvable_from_rad_s, 4),
            "loss_fraction": None if self.loss is None else round(self.loss.fraction, 4),
            "criteria": self.criteria.to_dict(),
        }


def _log_fraction(bands, lo: float, hi: float) -> float:
    """Fraction of [lo, hi] (decades) covered by ``bands``."""
    span = math.log(hi / lo)
    covered = sum(math.log(min(b, hi) / max(a, lo)) for a, b in bands if min(b, hi) > max(a, lo))
    return min(covered / span, 1.0) if span > 0 else 0.0


def _adequate_bands(omega: np.ndarray, ok: np.ndarray) -> tuple:
    """Contiguous adequate stretches of a log grid, each widened by half a grid step on either side
    (a point stands for its cell, as in the live adequacy fractions)."""
    if not np.any(ok):
        return ()
    lw = np.log(omega)
    half = 0.5 * (lw[1] - lw[0]) if omega.size > 1 else 0.0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))
    return tuple((float(math.exp(lw[a] - half)), float(math.exp(lw[b - 1] + half)))
                 for a, b in zip(edges[::2], edges[1::2]))


def band_gaps(bands, lo: float, hi: float) -> list[tuple[float, float]]:
    """The parts of [lo, hi] no band covers (bands narrower than ``MIN_ISLAND_DECADES`` ignored, so a
    coherent island does not split one missing stretch into several lines)."""
    out, x = [], lo
    bands = [(a, b) for a, b in bands if math.log10(b / a) >= MIN_ISLAND_DECADES]
    for a, b in sorted(bands):
        if a > x * (1 + 1e-9):
            out.append((x, min(a, hi)))
        x = max(x, b)
    if x < hi * (1 - 1e-9):
        out.append((x, hi))
    return [(a, b) for a, b in out if b > a * (1 + 1e-6)]


def _describe_gap(pair: str, a: float, b: float, lo: float, hi: float, resolvable: float, duration_s: float,
                  criteria: Criteria = DEFAULT_CRITERIA) -> str:
    """One line an operator can act on, for an inadequate stretch [a, b] of the band [lo, hi]."""
    band = f"{a:.3g}-{b:.3g} rad/s"
    if a <= lo * (1 + 1e-6) and b <= math.sqrt(lo * hi):
        need_s = LOW_FREQUENCY_PERIODS * 2 * math.pi / a
        more = max(need_s - duration_s, 0.0) if resolvable > a else need_s
        what = (f"about {more / 60:.0f} more minute(s)" if more >= 90 else f"about {more:.0f} more seconds") + \
            f" of sweep at low frequency ({LOW_FREQUENCY_PERIODS:g} periods at {a:.3g} rad/s)"
        return f"{pair} needs {band}: {what}"
    if b >= hi * (1 - 1e-6):
        return f"{pair} needs {band}: sweep up to {hi:.3g} rad/s (more amplitude at high frequency if it did)"
    return f"{pair} needs {band}: coherence below {criteria.min_coherence:g} there (more amplitude, or repeat the sweep)"


def swept_stretches(x: np.ndarray, sample_rate_hz: float, band_rad_s) -> tuple | None:
    """Stretches [rad/s] of ``band_rad_s`` the oscillation of ``x`` passed through: the
    instantaneous frequencies of its half-periods (:func:`half_period_frequencies`) on a log grid,
    holes narrower than ``MIN_ISLAND_DECADES`` bridged (a sweep spends one half-period per cell at
    its lowest frequencies); None when the record is too short to tell."""
    lo, hi = band_rad_s
    if x.size < 16:
        return None
    _, w = half_period_frequencies(np.arange(x.size) / sample_rate_hz, x)
    w = w[(w >= lo * 10 ** -MIN_ISLAND_DECADES) & (w <= hi * 10 ** MIN_ISLAND_DECADES)]
    if w.size < 2:
        return ()
    grid = np.geomspace(lo, hi, 200)                        # judged in decades, as the pairs are
    hit = np.zeros(grid.size, bool)
    k = np.clip(np.searchsorted(grid, w), 0, grid.size - 1)
    hit[k] = True
    cells = int(math.ceil(MIN_ISLAND_DECADES / math.log10(grid[1] / grid[0])))
    filled = hit.copy()
    idx = np.flatnonzero(hit)
    for a, b in zip(idx[:-1], idx[1:]):
        if b - a <= cells:
            filled[a:b] = True
    return _adequate_bands(grid, filled)


def _contiguous(bands) -> tuple[float, float] | None:
    """The covered stretch from the lowest covered frequency up to the first hole wider than
    ``MIN_ISLAND_DECADES`` (the sweep's progress: islands above a hole do not count)."""
    out = None
    for a, b in sorted(bands):
        if out is None:
            out = (a, b)
        elif a <= out[1] * 10 ** MIN_ISLAND_DECADES:
            out = (out[0], max(out[1], b))
        else:
            break
    return out


def _pair(analysis, ref, o: str, swept: str, lo: float, hi: float, kind: str,
          criteria: Criteria = DEFAULT_CRITERIA) -> PairJudgement:
    rs = analysis.referenced if ref else analysis.siso
    r = rs.pair(o, swept)
    finite = np.isfinite(r.H) & np.isfinite(r.coherence) & np.isfinite(r.random_error)
    g = np.where(finite, r.coherence, 0.0)
    eps = np.where(finite, r.random_error, np.inf)
    ok = finite & criteria.adequate(g, eps)
    bands = _adequate_bands(r.omega, ok)
    frac = _log_fraction(bands, lo, hi)
    # the bracket: the coherence at -/+ its random error, with eps_r scaled as sqrt(1 - g) / sqrt(g)
    sigma = MARGINAL_SIGMAS * np.where(finite, coherence_sigma(g, eps), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        shape = np.sqrt(np.clip(1.0 - g, 0.0, None) / np.clip(g, 1e-12, None))
        out = []
        for gg in (np.clip(g - sigma, 0.0, 1.0), np.clip(g + sigma, 0.0, 1.0)):
            e = np.where(shape > 0, eps * np.sqrt(np.clip(1.0 - gg, 0.0, None) / np.clip(gg, 1e-12, None)) / shape,
                         eps)
            out.append(_log_fraction(_adequate_bands(r.omega, finite & criteria.adequate(gg, e)), lo, hi))
    widest = max(bands, key=lambda b: math.log(b[1] / b[0]), default=None)
    med = float(np.median(r.coherence[finite])) if np.any(finite) else 0.0
    return PairJudgement(o, swept, frac, widest, bands, kind, med, (min(out[0], frac), max(out[1], frac)), r)


def judge_test_point(values: np.ndarray, names, sample_rate_hz: float, swept_input: str, outputs, band_rad_s, *,
                     valid: np.ndarray | None = None, references: dict | None = None,
                     injection: SweepInjection | None = None, elapsed_s: float | None = None, final: bool = True,
                     min_duration_s: float = 10.0,
                     source_rates_hz: dict | None = None, loss: DataLoss | None = None,
                     criteria: Criteria = DEFAULT_CRITERIA) -> TestPointJudgement:
    """The verdict on a test point from its aligned samples.

    Parameters
    ----------
    values : ndarray, shape (n_signals, n_samples)
        The test point's samples on a uniform grid (every signal of ``names``).
    names : sequence of str
    sample_rate_hz : float
    swept_input : str
        The input that was swept.
    outputs : sequence of str
        The outputs whose pairs with ``swept_input`` must be adequate.
    band_rad_s : (float, float)
        The map's band [rad/s]; the injection's replaces it when ``injection`` is given.
    valid : ndarray of bool, shape (n_samples,), optional
        False in data gaps.
    references : dict of input -> reference signal, optional
        The logged injection of an input (responses through it, coherence "partial").
    injection : SweepInjection, optional
        What the autopilot was told to inject (its band and schedule).
    elapsed_s : float, optional
        Time from the test point's start to its last sample [s] (how far the injection has got);
        default the samples' length.
    final : bool
        True: the closing verdict, over the whole judged band. False: a running verdict, over the
        band swept so far.
    min_duration_s : float
        A test point shorter than this [s] is not analysed.
    source_rates_hz : dict of str -> float, optional
        The rate each signal arrives at [Hz]: a pair whose signals arrive too slowly to show the
        top of the band is told so.
    loss : DataLoss, optional
        What the test point lost of its data (:meth:`DataLoss.measure`): from
        :data:`LOSS_REASON_FRACTION` on the first reason (and the first thing a NO-GO needs), a
        NO-GO from :data:`LOSS_LINK_FRACTION` on labelled "NO-GO (link)"; a smaller loss is said last
        (both follow ``criteria``).
    criteria : Criteria
        The adequacy and GO criteria (:class:`~livesweep.spectral.criteria.Criteria`); default the method's.

    Returns
    -------
    TestPointJudgement
    """
    required_fraction = criteria.required_fraction
    values = np.atleast_2d(np.asarray(values, float))
    names = list(names)
    n = values.shape[1]
    duration = n / sample_rate_hz
    elapsed = duration if elapsed_s is None else float(elapsed_s)
    reasons, missing = [], []
    top = NYQUIST_FRACTION * math.pi * sample_rate_hz
    lo, hi = (float(b) for b in (injection.band_rad_s if injection is not None else band_rad_s))
    if hi > top:
        reasons.append(f"the judged band ends at {top:.3g} rad/s, {NYQUIST_FRACTION:g} of the Nyquist frequency of "
                       f"the {sample_rate_hz:g} Hz grid (asked for up to {hi:.3g} rad/s)")
        hi = top
    if not lo < hi:
        raise ConfigError(f"test point band {lo:g}-{hi:g} rad/s is empty (grid {sample_rate_hz:g} Hz)")
    resolvable = MIN_PERIODS_PER_WINDOW * 2 * math.pi / max(longest_window_samples(n) / sample_rate_hz, 1e-9)
    ref = (references or {}).get(swept_input)
    kind = "partial" if ref else "ordinary"

    # what was swept: the injection's progress, or where the reference or the input has power
    excitation = "injection" if injection is not None else "reference" if ref else "input"
    swept_bands: tuple | None
    if injection is not None:
        sb = injection.swept_band(elapsed)
        swept_bands = () if sb is None else ((sb[0], sb[1]),)
    else:
        row = names.index(ref if ref else swept_input) if (ref or swept_input) in names else None
        swept_bands = None if row is None else swept_stretches(values[row], sample_rate_hz, (lo, hi))
    swept = None if not swept_bands else _contiguous(swept_bands)
    if swept is not None:
        swept = (max(swept[0], lo), min(swept[1], hi))
        swept = swept if swept[1] > swept[0] else None

    # the band judged now: all of it at the close, the part swept so far while running
    j_hi = hi
    if not final:
        if swept is None or math.log10(swept[1] / max(swept[0], lo)) < _MIN_SWEPT_DECADES:
            why, needs = _with_loss([f"{swept_input}: nothing of {lo:.3g}-{hi:.3g} rad/s swept yet"],
                                    ["nothing swept yet"], False, loss, criteria)
            return TestPointJudgement(swept_input, "NO-GO", (), None, needs, why, duration,
                                      resolvable, final=False, band_rad_s=(lo, hi), swept_rad_s=None,
                                      excitation=excitation, injection=injection, loss=loss, criteria=criteria)
        j_hi = swept[1]
    band_text = f"{lo:.3g}-{j_hi:.3g} rad/s"

    pairs = []
    lo_eff = max(lo, resolvable * (1 + 1e-9))
    analysis = None
    if duration >= min_duration_s and lo_eff < j_hi:
        try:
            analysis = analyze(values, names, sample_rate_hz, [swept_input], list(outputs), (lo_eff, j_hi),
                               valid=valid, references=[ref] if ref else None)
        except ConfigError as e:
            reasons.append(f"no responses: {e}")
    for o in outputs:
        pair = f"{o}/{swept_input}"
        if analysis is None:
            pairs.append(PairJudgement(o, swept_input, 0.0, None, (), kind, 0.0))
            missing.append(f"{pair} needs {lo:.3g}-{j_hi:.3g} rad/s: a longer test point "
                           f"(at least {min_duration_s:g} s, {LOW_FREQUENCY_PERIODS:g} periods at {lo:.3g} rad/s = "
                           f"{LOW_FREQUENCY_PERIODS * 2 * math.pi / lo:.0f} s)")
            continue
        p = _pair(analysis, ref, o, swept_input, lo, j_hi, kind, criteria)
        pairs.append(p)
        ok = p.adequate_fraction >= required_fraction
        a, b = p.adequate_range
        tag = " (marginal)" if p.marginal(required_fraction) else ""
        reasons.append(f"{pair}: {_percent(p.adequate_fraction, required_fraction)} of {band_text} "
                       f"{'adequate' if ok else 'NOT adequate'}{tag} (need {_percent(required_fraction)}: "
                       f"{_pts(p.adequate_fraction, required_fraction)}; {100 * a:.0f}-{100 * b:.0f} % within the "
                       f"random error; {kind} coherence)")
        if not ok:
            missing += [_describe_gap(pair, ga, gb, lo, j_hi, resolvable, duration, criteria)
                        for ga, gb in band_gaps(p.bands_rad_s, lo, j_hi)]
    failing = [p.output for p in pairs if p.adequate_fraction < required_fraction]
    for sig in dict.fromkeys([swept_input, *failing] if failing else []):   # each signal once
        rate = (source_rates_hz or {}).get(sig)
        if rate and shows_up_to_rad_s(rate) < j_hi:
            reasons.append(f"{sig} arrives at {rate:.3g} Hz: it cannot show above {shows_up_to_rad_s(rate):.3g} "
                           f"rad/s ({NYQUIST_FRACTION:g} of its Nyquist frequency); send it faster")

    excited = None if swept_bands is None else _log_fraction(swept_bands, lo, j_hi)
    if excited is None:
        reasons.append(f"{swept_input}: too little of the test point to tell what was swept")
    else:
        what = {"injection": f"the injection ({injection.describe()}) has reached"
                             if injection is not None else "",
                "reference": f"its reference {ref} oscillated over",
                "input": "it oscillated over"}[excitation]
        if excitation == "injection":
            reached = f"{what} {swept[1]:.3g} rad/s" if swept is not None else f"{what} nothing of the band yet"
        else:
            reached = f"{what} {swept[0]:.3g}-{swept[1]:.3g} rad/s" if swept is not None else f"{what} none of the band"
        word = "swept" if excited >= required_fraction else "NOT swept"
        reasons.append(f"{swept_input}: {_percent(excited, required_fraction)} of {band_text} {word} "
                       f"(need {_percent(required_fraction)}: {_pts(excited, required_fraction)}): {reached}")
        if final and excited < required_fraction:
            gaps = ", ".join(f"{a:.3g}-{b:.3g}" for a, b in band_gaps(swept_bands, lo, j_hi))
            missing.append(f"{swept_input} needs a sweep over {gaps} rad/s: {reached}")
    if duration < min_duration_s:
        reasons.insert(0, f"test point {duration:.1f} s long, shorter than {min_duration_s:g} s")
    pairs_ok = bool(pairs) and all(p.adequate_fraction >= required_fraction for p in pairs)
    excited_ok = excited is not None and excited >= required_fraction
    go = duration >= min_duration_s and pairs_ok and excited_ok
    if go:
        marginal = any(p.marginal(required_fraction) for p in pairs)
    else:
        failing = [p for p in pairs if p.adequate_fraction < required_fraction]
        marginal = (duration >= min_duration_s and excited_ok and bool(failing)
                    and all(p.marginal(required_fraction) for p in failing))
    reasons, missing = _with_loss(reasons, [] if go else missing, go, loss, criteria)
    return TestPointJudgement(swept_input, "GO" if go else "NO-GO", tuple(pairs), excited,
                              missing, reasons, duration, resolvable, final=final,
                              band_rad_s=(lo, hi), swept_rad_s=swept, excitation=excitation, marginal=marginal,
                              injection=injection, loss=loss, criteria=criteria)


def _with_loss(reasons: list, missing: list, go: bool, loss: DataLoss | None,
               criteria: Criteria = DEFAULT_CRITERIA) -> tuple[tuple, tuple]:
    """The reasons and what a NO-GO needs, with the data's loss said: first from the criteria's
    ``loss_reason_fraction`` on (what the link counted right after it), else last."""
    if loss is None or not loss.missing:
        return tuple(reasons), tuple(missing)
    text, cause = loss.describe(), loss.cause()
    if loss.fraction < criteria.loss_reason_fraction:
        said = [f"{text}: too little to move a coherence by more than its own random error (below "
                f"{100 * criteria.loss_reason_fraction:.1f} %)",
                *([cause] if cause else [])]
        return (*reasons, *said), tuple(missing)
    if go:
        first = f"{text}: adequate all the same (a loss lowers the coherence, it never raises it)"
    elif loss.fraction >= criteria.loss_link_fraction:
        first = f"{text}: the verdict reflects the link, not the sweep"
    else:
        first = (f"{text}: enough to lower a coherence by more than its random error; the NO-GO may be the "
                 f"link's, not the sweep's")
    if not go:
        shed = loss.link.get("analysis_shed", 0)
        missing = [f"a link that keeps the frames before this sweep is flown again ({_percent(loss.fraction)} "
                   f"lost: see the troubleshooting page, frames lost on the link)"
                   + (f"; the recording holds the {shed} frames the analysis skipped: replay it "
                      f"(livesweep replay) for the verdict on them" if shed else ""), *missing]
    return (first, *([cause] if cause else []), *reasons), tuple(missing)
