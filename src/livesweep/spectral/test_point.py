"""Is a test point good enough? The verdict over a whole test point, from its accumulated samples.

A test point is the stretch of flight in which one input is swept (docs/method.md §2). The live monitor
collects its aligned samples and, while it runs and when it closes, asks :func:`judge_test_point`:

* **Responses over the whole test point.** The same composite of several window lengths the
  offline identification uses (:func:`livesweep.spectral.analysis.analyze`): the swept input is
  the only input (SISO, ordinary coherence: during a single-axis sweep the other inputs are the
  controller's reaction, not exogenous), or, when the map names the logged injection as the
  swept input's reference, the response through it (coherence "partial"). Each required pair is
  adequate where gamma^2 >= 0.6 and eps_r <= 0.2 (docs/method.md §2.5); its adequate fraction is
  measured in decades of the requested band, the part a record this short cannot resolve
  (3 periods in half the record) counting as not adequate.
* **Real excitation.** The swept input's autospectrum during the test point must stand
  ``excitation_margin_db`` (10 dB) above its level before the test point, and within 20 dB of its
  own 90th percentile over the band (a real part of the sweep, not leakage), over at least
  ``required_fraction`` of the band, so a constant trim, a motor spooling up, the pilot's usual
  corrections or a sweep stopped early are never called a full sweep. Without a pre-test record
  the check is skipped and a reason says so.
* **GO** when the test point lasted ``min_duration_s``, the input was excited and every required
  pair is adequate over ``required_fraction`` (60 %) of the band; otherwise **NO-GO**, with what is
  missing in words an operator can act on: which band of which pair, and for a gap at the bottom
  of the band how much more low-frequency sweep it needs (4 periods of its lowest frequency,
  docs/method.md §2.5: T_rec >= 4-5 T_max).

Pure: arrays in, a frozen :class:`TestPointJudgement` out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.numbers import percent as _percent
from livesweep.spectral.adequacy import MAX_RANDOM_ERROR, MIN_COHERENCE, REQUIRED_FRACTION
from livesweep.spectral.analysis import analyze
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW, window_spectra
from livesweep.spectral.windows import longest_window_samples

__all__ = ["PairJudgement", "TestPointJudgement", "judge_test_point", "REQUIRED_FRACTION", "EXCITATION_MARGIN_DB",
           "LOW_FREQUENCY_PERIODS", "COVERAGE_DROP_DB"]

#: The swept input's power must stand this far above its pre-test level [dB].
EXCITATION_MARGIN_DB = 10.0
#: Periods of its lowest frequency a sweep needs to resolve it (docs/method.md §2.5, T_rec >= 4-5 T_max).
LOW_FREQUENCY_PERIODS = 4.0
#: The swept input's power counts where it is within this of its 90th percentile over the band [dB]
#: (docs/method.md §2.5: no holes deeper than about 20 dB; an exponential sweep over two decades slopes 17-18).
COVERAGE_DROP_DB = 20.0
#: Adequate stretches narrower than this [decades] do not split what is missing into pieces.
_MIN_ISLAND_DECADES = 0.1


@dataclass(frozen=True)
class PairJudgement:
    """How well one required pair is identified over the test point.

    Attributes
    ----------
    output, input : str
    adequate_fraction : float
        Fraction of the requested band (decades) where gamma^2 >= 0.6 and eps_r <= 0.2.
    band_rad_s : (float, float) or None
        The widest adequate stretch [rad/s].
    bands_rad_s : tuple of (float, float)
        Every adequate stretch [rad/s].
    coherence : str
        ``"ordinary"`` (SISO on the swept input) or ``"partial"`` (through the reference).
    median_coherence : float
        Over the resolved part of the band.
    """

    output: str
    input: str
    adequate_fraction: float
    band_rad_s: tuple | None
    bands_rad_s: tuple
    coherence: str
    median_coherence: float


@dataclass(frozen=True)
class TestPointJudgement:
    """The verdict on one test point.

    Attributes
    ----------
    swept_input : str
    verdict : str
        ``"GO"`` or ``"NO-GO"``.
    pairs : tuple of PairJudgement
        The required pairs.
    excited_fraction : float or None
        Fraction of the band (decades) where the swept input stood ``EXCITATION_MARGIN_DB`` above
        its pre-test level; None without a pre-test record.
    missing : tuple of str
        What a GO still needs, one line each (empty for GO).
    reasons : tuple of str
        Why, one line per check.
    duration_s : float
        Length of the test point [s].
    resolvable_from_rad_s : float
        The lowest frequency the record's length resolves [rad/s].
    """

    swept_input: str
    verdict: str
    pairs: tuple
    excited_fraction: float | None
    missing: tuple
    reasons: tuple
    duration_s: float
    resolvable_from_rad_s: float

    def to_dict(self) -> dict:
        """The ``pairs``/``missing`` part of the ``/livesweep/test_point`` record (docs/outputs.md, live result channels)."""
        return {
            "swept_input": self.swept_input, "verdict": self.verdict, "duration_s": round(self.duration_s, 3),
            "pairs": [{"output": p.output, "input": p.input, "adequate_fraction": round(p.adequate_fraction, 4),
                       "band_rad_s": None if p.band_rad_s is None else [round(b, 4) for b in p.band_rad_s],
                       "coherence": p.coherence, "median_coherence": round(p.median_coherence, 4)}
                      for p in self.pairs],
            "excited_fraction": None if self.excited_fraction is None else round(self.excited_fraction, 4),
            "missing": list(self.missing), "reasons": list(self.reasons),
            "resolvable_from_rad_s": round(self.resolvable_from_rad_s, 4),
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


def _gaps(bands, lo: float, hi: float) -> list[tuple[float, float]]:
    """The parts of [lo, hi] no band covers (bands narrower than ``_MIN_ISLAND_DECADES`` ignored, so a
    coherent island does not split one missing stretch into several lines)."""
    out, x = [], lo
    bands = [(a, b) for a, b in bands if math.log10(b / a) >= _MIN_ISLAND_DECADES]
    for a, b in sorted(bands):
        if a > x * (1 + 1e-9):
            out.append((x, min(a, hi)))
        x = max(x, b)
    if x < hi * (1 - 1e-9):
        out.append((x, hi))
    return [(a, b) for a, b in out if b > a * (1 + 1e-6)]


def _describe_gap(pair: str, a: float, b: float, lo: float, hi: float, resolvable: float, duration_s: float) -> str:
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
    return f"{pair} needs {band}: coherence below {MIN_COHERENCE:g} there (more amplitude, or repeat the sweep)"


def _excited_bands(x_tp: np.ndarray, x_pre: np.ndarray, sample_rate_hz: float, band_rad_s,
                   margin_db: float) -> tuple[tuple, float] | None:
    """(stretches [rad/s], lowest frequency compared [rad/s]) where the input was swept: its
    autospectrum during the test point stands ``margin_db`` above its autospectrum before it (both
    with one window, the longest the shorter record allows, up to 20 s) and within
    ``COVERAGE_DROP_DB`` of the 90th percentile of its autospectrum over the whole band (a window of
    half the test point, up to 60 s: the reference a sweep stopped early cannot fake with leakage);
    None when the two records cannot be compared."""
    lo, hi = band_rad_s
    n = min(x_pre.size, x_tp.size // 2, int(20.0 * sample_rate_hz))
    if n < 16:
        return None
    window_s = n / sample_rate_hz
    lo_w = max(lo, MIN_PERIODS_PER_WINDOW * 2 * math.pi / window_s)
    ref_s = min(x_tp.size // 2, int(60.0 * sample_rate_hz)) / sample_rate_hz
    lo_ref = max(lo, MIN_PERIODS_PER_WINDOW * 2 * math.pi / ref_s)
    if lo_w >= hi or lo_ref >= hi:
        return None
    try:
        tp = window_spectra(x_tp[None, :], ["x"], sample_rate_hz, window_s, (lo_w, hi))
        pre = window_spectra(x_pre[None, :], ["x"], sample_rate_hz, window_s, (lo_w, hi))
        ref = window_spectra(x_tp[None, :], ["x"], sample_rate_hz, ref_s, (lo_ref, hi))
    except ConfigError:
        return None
    omega = np.geomspace(lo_w, hi, 200)                     # judged in decades, as the pairs are
    g_tp = np.interp(omega, tp.omega, tp.G[0, 0].real)
    g_pre = np.interp(omega, pre.omega, pre.G[0, 0].real)
    level = np.percentile(np.interp(np.geomspace(lo_ref, hi, 200), ref.omega, ref.G[0, 0].real), 90)
    ok = (g_tp > g_pre * 10 ** (margin_db / 10)) & (g_tp >= level * 10 ** (-COVERAGE_DROP_DB / 10))
    return _adequate_bands(omega, ok), lo_w


def judge_test_point(values: np.ndarray, names, sample_rate_hz: float, swept_input: str, outputs, band_rad_s, *,
                     valid: np.ndarray | None = None, pre_values: np.ndarray | None = None,
                     references: dict | None = None, required_fraction: float = REQUIRED_FRACTION,
                     min_duration_s: float = 10.0,
                     excitation_margin_db: float = EXCITATION_MARGIN_DB) -> TestPointJudgement:
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
        The requested band [rad/s].
    valid : ndarray of bool, shape (n_samples,), optional
        False in data gaps.
    pre_values : ndarray, shape (n_signals, n_pre), optional
        Samples just before the test point (for the excitation check).
    references : dict of input -> reference signal, optional
        The logged injection of an input (responses through it, coherence "partial").
    required_fraction, min_duration_s, excitation_margin_db : float
        The GO criteria (see the module docstring).

    Returns
    -------
    TestPointJudgement
    """
    values = np.atleast_2d(np.asarray(values, float))
    names = list(names)
    lo, hi = float(band_rad_s[0]), float(band_rad_s[1])
    n = values.shape[1]
    duration = n / sample_rate_hz
    resolvable = MIN_PERIODS_PER_WINDOW * 2 * math.pi / max(longest_window_samples(n) / sample_rate_hz, 1e-9)
    reasons, missing = [], []
    ref = (references or {}).get(swept_input)
    kind = "partial" if ref else "ordinary"
    pairs = []
    lo_eff = max(lo, resolvable * (1 + 1e-9))
    analysis = None
    if duration >= min_duration_s and lo_eff < hi:
        try:
            analysis = analyze(values, names, sample_rate_hz, [swept_input], list(outputs), (lo_eff, hi), valid=valid,
                               references=[ref] if ref else None)
        except ConfigError as e:
            reasons.append(f"no responses: {e}")
    for o in outputs:
        pair = f"{o}/{swept_input}"
        if analysis is None:
            pairs.append(PairJudgement(o, swept_input, 0.0, None, (), kind, 0.0))
            missing.append(f"{pair} needs {lo:.3g}-{hi:.3g} rad/s: a longer test point "
                           f"(at least {min_duration_s:g} s, {LOW_FREQUENCY_PERIODS:g} periods at {lo:.3g} rad/s = "
                           f"{LOW_FREQUENCY_PERIODS * 2 * math.pi / lo:.0f} s)")
            continue
        rs = analysis.referenced if ref else analysis.siso
        r = rs.pair(o, swept_input)
        ok = (r.coherence >= MIN_COHERENCE) & (r.random_error <= MAX_RANDOM_ERROR) & np.isfinite(r.H)
        bands = _adequate_bands(r.omega, ok)
        frac = _log_fraction(bands, lo, hi)
        widest = max(bands, key=lambda b: math.log(b[1] / b[0]), default=None)
        pairs.append(PairJudgement(o, swept_input, frac, widest, bands, kind, float(np.median(r.coherence))))
        word = "adequate" if frac >= required_fraction else "NOT adequate"
        reasons.append(f"{pair}: {_percent(frac, required_fraction)} of {lo:g}-{hi:g} rad/s {word} "
                       f"(need {_percent(required_fraction, required_fraction)}, {kind} coherence)")
        if frac < required_fraction:
            missing += [_describe_gap(pair, a, b, lo, hi, resolvable, duration) for a, b in _gaps(bands, lo, hi)]
    excited, compared = None, None
    if pre_values is not None and swept_input in names:
        k = names.index(swept_input)
        pre = np.asarray(pre_values, float)[k]
        pre = pre[np.isfinite(pre)]
        x = values[k]
        x = np.where(np.isfinite(x), x, np.nanmean(x))
        compared = _excited_bands(x - x.mean(), pre - pre.mean(), sample_rate_hz, (lo, hi), excitation_margin_db) \
            if pre.size >= 16 else None
    if compared is None:
        reasons.append(f"{swept_input}: no quiet record before the test point to compare its power with")
    else:
        bands, lo_w = compared
        excited = _log_fraction(bands, lo_w, hi)          # of the part the two records can compare
        word = "excited" if excited >= required_fraction else "NOT excited"
        reasons.append(f"{swept_input}: {excitation_margin_db:g} dB above its level before the test point over "
                       f"{_percent(excited, required_fraction)} of {lo_w:.3g}-{hi:g} rad/s: {word}")
        if excited < required_fraction:
            gaps = ", ".join(f"{a:.3g}-{b:.3g}" for a, b in _gaps(bands, lo_w, hi))
            missing.append(f"{swept_input} needs a sweep over {gaps} rad/s: its power there is within "
                           f"{excitation_margin_db:g} dB of its level before the test point")
    if duration < min_duration_s:
        reasons.insert(0, f"test point {duration:.1f} s long, shorter than {min_duration_s:g} s")
    go = (duration >= min_duration_s and bool(pairs) and all(p.adequate_fraction >= required_fraction for p in pairs)
          and (excited is None or excited >= required_fraction))
    return TestPointJudgement(swept_input, "GO" if go else "NO-GO", tuple(pairs), excited,
                              () if go else tuple(missing), tuple(reasons), duration, resolvable)
