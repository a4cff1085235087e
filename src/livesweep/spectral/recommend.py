"""What to fly next: from a test point's judgement to the sweep that would make the next one adequate.

:func:`recommend_next` takes the closing verdict of :func:`~livesweep.spectral.verdict.judge_test_point`
and says which stretches of the judged band each required pair lacks, and why:

* ``"not_swept"``: the input had no power there: above where the sweep got to (stopped early, test
  point cut), below its first half-period (it left the start within half a cycle: method §2.2, start
  with about two cycles there), a hole in its oscillation or (``input_spectrum``) in its autospectrum
  (§2.5). A response adequate there is leakage: adequate stretches count only where it was swept.
* ``"short_record"``: below what the record resolves, or reached only as the record ended (just under
  a band never reached). Fix: a record of :data:`RECORD_PERIODS` periods of the lowest frequency.
* ``"incoherent"``: swept and resolved, yet gamma^2 < ``min_coherence`` or eps_r > ``max_random_error``.
  Noise uncorrelated with the input gives gamma^2 = SNR / (1 + SNR), SNR growing as the input power,
  eps_r^2 as 1 / SNR at a fixed number of averages (Bendat & Piersol; §4.5). From the stretch's
  medians (the coherence's few-averages bias removed) the power must rise by ``max((g*/(1-g*)) /
  (g/(1-g)), (eps/eps*)^2)``, the amplitude by its root (``MissingBand.amplitude_factor``): the median
  then meets the threshold, half the stretch still under it. The sweep's amplitude is instead the
  smallest that makes each pair a clear GO by the judge's own rule: the coherence predicted at each
  frequency (bias removed, power scaled, bias put back), less :data:`GO_MARGIN_SD` of the judge's
  bracket, adequate over ``required_fraction`` of every resolved frequency up to where the sweep
  got, as the judge counts them (the stretch a sweep's fade-in leaves weak is judged too, and
  the next sweep leaves it weak again); the frequencies it never reached are taken to fare as
  those did. Capped at :data:`MAX_AMPLITUDE_FACTOR`; random error left after the
  cap asks for more sweeps.

Then the method's sweep (band, T_rec, number of sweeps, amplitude, trims, fades: §2.1-2.3) and, for an
ArduCopter SystemID test point, the ``SID_*`` parameters: the injection's own, changed only where a
missing stretch needs it. Pure: a judgement in, a frozen :class:`Recommendation` out (numpy, no I/O).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW
from livesweep.spectral.verdict import (LOW_FREQUENCY_PERIODS, MARGINAL_SIGMAS, MIN_ISLAND_DECADES, TestPointJudgement,
                                        band_gaps, coherence_sigma, swept_stretches)

__all__ = ["MissingBand", "Recommendation", "recommend_next", "RECORD_PERIODS", "MAX_AMPLITUDE_FACTOR",
           "NUMBER_OF_SWEEPS", "TRIM_S", "FADE_CYCLES", "DWELL_CYCLES", "INPUT_HOLE_DB", "GO_MARGIN_SD"]

#: Periods of the lowest frequency a record needs [-]: the method's T_rec >= 4-5 T_max (§2.1,
#: ``LOW_FREQUENCY_PERIODS``), and what the analysis itself resolves: its longest window is half the
#: record (§4.4, T_win,max <= T_rec / 2) and needs ``MIN_PERIODS_PER_WINDOW`` (3) periods, so 6.
RECORD_PERIODS = max(LOW_FREQUENCY_PERIODS, 2.0 * MIN_PERIODS_PER_WINDOW)
#: Largest amplitude increase asked for at once [-]: the method's sweep amplitude, "large but
#: linear", is +-10-20 % of control travel (§2.2), a span of a factor 2; beyond it, check linearity.
MAX_AMPLITUDE_FACTOR = 2.0
#: Sweeps per axis, concatenated for the analysis (§2.1: "use >= 2 sweeps per axis").
NUMBER_OF_SWEEPS = 2
#: Quiescent trim before and after each sweep [s] (§2.2: "about 3 s ... at each end").
TRIM_S = 3.0
#: A fade lasts this many cycles of the frequency it fades (§2.3 design: fades of about one cycle).
FADE_CYCLES = 1.0
#: Cycles at the start frequency before the sweep rises (§2.2: "start with about 2 cycles at the
#: longest period"; ArduCopter's chirp dwells two periods, ``t_const = 2 / f_start``).
DWELL_CYCLES = 2.0
#: How far clear of the GO rule a recommended amplitude aims, in standard deviations of the coherence
#: estimate [-]: the judge's bracket (``MARGINAL_SIGMAS`` x its predicted sigma, verdict.py) is one; the
#: record the prediction starts from is itself one draw, so two (one-sided 97.7 % per frequency).
GO_MARGIN_SD = 2.0
#: A stretch where the input's power per unit log-frequency lies this far below its median over the
#: swept band is a hole, not swept [dB] (§2.5 design: no more than about 20 dB below the trend).
INPUT_HOLE_DB = 20.0

_HZ = 1.0 / (2.0 * math.pi)
_BRIDGE = 10 ** MIN_ISLAND_DECADES          # the judge's own granularity: holes narrower are bridged


@dataclass(frozen=True)
class MissingBand:
    """A stretch of the judged band a pair lacks, and why.

    Attributes
    ----------
    pair : str
        ``"output/input"`` (the swept input alone when the test point has no pair).
    band_rad_s : (float, float)
        [rad/s] (``band_hz``: the same in Hz).
    cause : str
        ``"not_swept"``, ``"short_record"`` or ``"incoherent"``.
    detail : str
        Why, in words, with numbers.
    median_coherence, median_random_error : float or None
        gamma^2 and eps_r over the stretch, as judged (None: no response there).
    amplitude_factor : float or None
        Amplitude increase the stretch needs, before the cap [-] (``"incoherent"`` only).
    """

    pair: str
    band_rad_s: tuple
    cause: str
    detail: str
    median_coherence: float | None = None
    amplitude_factor: float | None = None
    median_random_error: float | None = None

    @property
    def band_hz(self) -> tuple:
        return (self.band_rad_s[0] * _HZ, self.band_rad_s[1] * _HZ)

    def to_dict(self) -> dict:
        r = lambda x: None if x is None else round(float(x), 4)      # noqa: E731
        return {"pair": self.pair, "band_rad_s": [r(v) for v in self.band_rad_s],
                "band_hz": [r(v) for v in self.band_hz], "cause": self.cause, "detail": self.detail,
                "median_coherence": r(self.median_coherence),
                "amplitude_factor": r(self.amplitude_factor), "median_random_error": r(self.median_random_error)}


@dataclass(frozen=True)
class Recommendation:
    """What the next test point needs.

    Attributes
    ----------
    verdict : str
        The judgement's (``"GO"`` / ``"NO-GO"``).
    needed : bool
        False for a GO: nothing more is needed (everything else empty).
    missing : tuple of MissingBand
    sweep : mapping or None
        The method's sweep (read-only): ``omega_min_rad_s``, ``omega_max_rad_s`` [rad/s], ``duration_s``
        (T_rec of one sweep, trims apart) [s], ``amplitude`` (input units; None when unknown), ``trim_s``,
        ``fade_in_s``, ``fade_out_s`` [s] (:class:`livesweep.sim.inputs.FrequencySweep`'s names), and
        ``amplitude_factor``, ``n_sweeps``, ``dwell_s`` [s] (time at the start frequency), ``band_hz``.
    ardupilot : mapping or None
        ``SID_*`` parameter -> value for an ArduCopter SystemID test point (read-only; None otherwise).
    ardupilot_changed : tuple of str
        The ``SID_*`` parameters that differ from what was flown.
    chirp_cut_s : (float, float) or None
        ``(chirp time reached, SID_T_REC)`` [s] when the test point ended before the chirp did.
    lines : tuple of str
        What to do, one short sentence each, with numbers.
    """

    verdict: str
    needed: bool
    missing: tuple = ()
    sweep: Mapping | None = field(default=None, hash=False)
    ardupilot: Mapping | None = field(default=None, hash=False)
    ardupilot_changed: tuple = ()
    chirp_cut_s: tuple | None = None
    lines: tuple = ()

    def to_dict(self) -> dict:
        """JSON-ready: ``verdict``, ``needed``, ``missing`` (``pair``, ``band_rad_s``, ``band_hz``, ``cause``,
        ...), ``sweep``, ``ardupilot``, ``ardupilot_changed``, ``chirp_cut_s``, ``lines``."""
        def plain(m):
            return None if m is None else {k: list(v) if isinstance(v, tuple) else v for k, v in m.items()}

        return {"verdict": self.verdict, "needed": self.needed, "missing": [m.to_dict() for m in self.missing],
                "sweep": plain(self.sweep), "ardupilot": plain(self.ardupilot),
                "ardupilot_changed": list(self.ardupilot_changed),
                "chirp_cut_s": None if self.chirp_cut_s is None else [round(v, 3) for v in self.chirp_cut_s],
                "lines": list(self.lines)}


def _band(a: float, b: float) -> str:
    return f"{a:.3g}-{b:.3g} rad/s ({a * _HZ:.3g}-{b * _HZ:.3g} Hz)"


def _swept(j: TestPointJudgement, input_samples) -> tuple:
    """The stretches [rad/s] of the judged band the input was swept over, in order (empty: none)."""
    lo, hi = j.band_rad_s
    if j.injection is None and input_samples is None and j.swept_rad_s and j.excited_fraction is not None:
        a, b = j.swept_rad_s                                # more swept than its first stretch: where, untold
        if j.excited_fraction > math.log(b / a * _BRIDGE) / math.log(hi / lo):
            return ((lo, hi),)
    if j.injection is not None or input_samples is None:
        return (j.swept_rad_s,) if j.swept_rad_s else ()    # an injection's own schedule is exact
    x, rate = input_samples                                 # as the judge tells it, islands as its gaps do
    got = [b for b in (swept_stretches(np.asarray(x, float), float(rate), (lo, hi)) or ())
           if math.log10(b[1] / b[0]) >= MIN_ISLAND_DECADES]
    if got and got[0][0] <= lo * _BRIDGE:                   # a half-period's midpoint is inside the band
        got[0] = (lo, got[0][1])
    if got and got[-1][1] >= hi / _BRIDGE:
        got[-1] = (got[-1][0], hi)
    return tuple(got)


def _inside(w, swept) -> np.ndarray:
    """Mask: ``w`` [rad/s] within a swept stretch."""
    w = np.asarray(w, float)
    return np.any([(w >= a) & (w <= b) for a, b in swept], axis=0) if swept else np.zeros(w.shape, bool)


def _dark(input_spectrum, swept) -> tuple:
    """Stretches [rad/s] of the swept band where the input's power per unit log-frequency,
    ``omega G_xx``, lies :data:`INPUT_HOLE_DB` below its median over the swept band's decades."""
    if input_spectrum is None or not swept:
        return ()
    w, g = (np.asarray(v, float) for v in input_spectrum)
    ok = (w > 0) & np.isfinite(g) & (g > 0)
    if np.count_nonzero(ok) < 2:
        return ()
    grid = np.geomspace(swept[0][0], swept[-1][1], 400)
    inside = _inside(grid, swept)
    level = 10 * np.interp(np.log(grid), np.log(w[ok]), np.log10(w[ok] * g[ok]))
    low = inside & (level < np.median(level[inside]) - INPUT_HOLE_DB)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], low.astype(int), [0]])))
    runs = [(float(grid[i]), float(grid[k - 1])) for i, k in zip(edges[::2], edges[1::2])]
    return tuple((a, b) for a, b in runs if b > a and math.log10(b / a) >= MIN_ISLAND_DECADES)


def _minus(swept, dark) -> tuple:
    """The stretches ``swept`` without the stretches ``dark``."""
    out = list(swept)
    for c, d in dark:
        out = [piece for a, b in out for piece in ((a, min(b, c)), (max(a, d), b)) if piece[1] > piece[0]]
    return tuple(out)


def _debiased(coh, eps) -> tuple[np.ndarray, np.ndarray]:
    """(gamma^2, n_d): the coherence without its few-averages bias and the number of averages, from the
    estimate ``coh = g + (1 - g)^2 / n_d`` (Bendat & Piersol, method §2.5) and the random error the
    analysis gives from g (``eps_r^2 = (1 - g) / (2 n_d g)``, spectra.random_error); so
    ``coh = g + 2 g (1 - g) eps_r^2``, solved for g (its root in [0, coh])."""
    c, e2 = np.clip(np.asarray(coh, float), 1e-6, 1 - 1e-9), np.asarray(eps, float) ** 2
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        a = 1.0 + 2.0 * e2
        g = np.clip(2.0 * c / (a + np.sqrt(np.clip(a * a - 8.0 * e2 * c, 0.0, None))), 1e-6, 1 - 1e-9)
        return g, (1.0 - g) / (2.0 * g * e2)


def _power_needed(resp, a: float, b: float, crit) -> tuple:
    """(median gamma^2, median eps_r, input power factor) over [a, b] of a response (module docstring)."""
    m = np.zeros(0, bool) if resp is None else (
        (resp.omega >= a) & (resp.omega <= b) & np.isfinite(resp.coherence) & np.isfinite(resp.random_error))
    if not np.any(m):
        return None, None, 1.0
    g = float(np.median(_debiased(resp.coherence[m], resp.random_error[m])[0]))
    eps, snr_need = float(np.median(resp.random_error[m])), crit.min_coherence / (1 - crit.min_coherence)
    power = max(snr_need * (1 - g) / g, (eps / crit.max_random_error) ** 2, 1.0)
    return float(np.median(resp.coherence[m])), eps, power


def _go_power(p, swept, r: float, crit) -> float:
    """Input power factor making pair ``p`` a clear GO (module docstring); 1 when nothing to gain,
    inf when not even ``4 MAX_AMPLITUDE_FACTOR^2`` would."""
    resp = None if p is None else p.response
    if resp is None:
        return 1.0
    w, coh, eps = resp.omega, resp.coherence, resp.random_error
    reach = swept[-1][1] if swept else math.inf
    part = (w >= r) & (w <= reach * (1 + 1e-9))             # resolved, up to where it got: it stands for the band
    m = part & np.isfinite(coh) & np.isfinite(eps) & (eps > 0)
    if np.count_nonzero(m) < 2:
        return 1.0
    g, n = _debiased(coh[m], eps[m])
    for power in np.geomspace(1.0, 4 * MAX_AMPLITUDE_FACTOR ** 2, 97):
        snr = power * g / (1 - g)                           # what the judge would estimate, and its bracket
        g2 = snr / (1 + snr)
        c2, e2 = np.clip(g2 + (1 - g2) ** 2 / n, 0.0, 1 - 1e-12), eps[m] / math.sqrt(power)
        c_lo = np.clip(c2 - GO_MARGIN_SD * MARGINAL_SIGMAS * coherence_sigma(c2, e2), 1e-9, 1.0)
        e_lo = e2 * np.sqrt((1 - c_lo) / c_lo) / np.sqrt((1 - c2) / c2)
        if np.count_nonzero(crit.adequate(c_lo, e_lo)) >= crit.required_fraction * np.count_nonzero(part):
            return float(power)
    return math.inf


def _classify(pair, resp, a, b, swept, r, crit, dark) -> list[MissingBand]:
    """One missing stretch [a, b], split by cause (module docstring)."""
    s0, s1 = (swept[0][0], swept[-1][1]) if swept else (math.inf, math.inf)
    edges = {e for st in swept for e in st} | {r}
    cuts = sorted({a, b, *(x for x in edges if a * (1 + 1e-9) < x < b * (1 - 1e-9))})
    out: list[list] = []
    for x, y in zip(cuts[:-1], cuts[1:]):
        mid = math.sqrt(x * y)
        cause = "short_record" if (mid < r or resp is None) else "incoherent"
        cause = cause if _inside(mid, swept) else "not_swept"
        if out and out[-1][2] == cause:
            out[-1][1] = y
        else:
            out.append([x, y, cause])
    for k, (x, y, cause) in enumerate(out):                # reached only as the record ended
        if cause == "incoherent" and k + 1 < len(out) and out[k + 1][2] == "not_swept" and y >= s1 * (1 - 1e-9):
            out[k][2] = "ended"
    bands = []
    for x, y, cause in out:
        g, eps, power = _power_needed(resp, x, y, crit)
        factor = None
        if cause == "not_swept" and _inside(math.sqrt(x * y), dark):
            why = f"the input's power there is over {INPUT_HOLE_DB:g} dB below its median (a hole in its spectrum)"
        elif cause == "not_swept" and not swept:
            why = "nothing swept"
        elif cause == "not_swept" and x >= s1 * (1 - 1e-9):
            why = f"the sweep reached only {s1:.3g} rad/s ({s1 * _HZ:.3g} Hz) before the test point ended"
        elif cause == "not_swept" and y <= s0 * (1 + 1e-9):
            why = (f"the sweep was first at {s0:.3g} rad/s: start at {x:.3g} rad/s with about {DWELL_CYCLES:g} "
                   "cycles there")
        elif cause == "not_swept":
            why = "the input's oscillation skipped it (a hole in the sweep)"
        elif cause == "ended":
            cause, why = "short_record", "swept only as the record ended (too few averages)"
        elif cause == "short_record":
            why = ("no response: the test point was too short to analyse" if resp is None else
                   f"the record resolves only from {r:.3g} rad/s: {RECORD_PERIODS:g} periods of {x:.3g} rad/s "
                   f"need {RECORD_PERIODS * 2 * math.pi / x:.0f} s")
        elif g is None:
            factor = MAX_AMPLITUDE_FACTOR
            why = "no usable response there (coherence nil or random error undefined): the input must rise " \
                  "well above the noise"
        else:
            factor = math.sqrt(power)
            why = f"median coherence {g:.2f}: input power x{power:.2g} needed, amplitude x{factor:.2g}"
        bands.append(MissingBand(pair, (x, y), cause, why, g, factor, eps))
    return bands


def recommend_next(judgement: TestPointJudgement, *, input_spectrum=None, input_samples=None,
                   amplitude: float | None = None, trim_s: float = TRIM_S) -> Recommendation:
    """What would make the next test point adequate, with numbers.

    Parameters
    ----------
    judgement : TestPointJudgement
        The closing verdict (:func:`~livesweep.spectral.verdict.judge_test_point`, ``final=True``).
    input_spectrum : (ndarray, ndarray), optional
        ``(omega [rad/s], G_xx)`` of the swept input over the test point (only ratios are used): where
        ``omega G_xx`` (power per unit log-frequency) lies :data:`INPUT_HOLE_DB` below its median over
        the rest of the swept band, the input was not swept (a hole).
    input_samples : (ndarray, float), optional
        ``(samples, sample rate [Hz])`` of the swept input (or its logged reference) over the test
        point, used without an injection: the stretches its half-periods passed through, as the judge
        finds them, instead of the judgement's ``swept_rad_s`` (only the first stretch: a sweep that
        leaves a wide band's bottom within a half-period makes a hole there, and ``swept_rad_s`` stops).
    amplitude : float, optional
        The amplitude flown (input units); an injection's ``magnitude`` when there is one.
    trim_s : float
        Trim before and after each sweep [s].

    Returns
    -------
    Recommendation
    """
    j, crit, inj = judgement, judgement.criteria, judgement.injection
    if j.verdict == "GO":
        return Recommendation(j.verdict, False, lines=(f"{j.label}: nothing more is needed for {j.swept_input}.",))
    (lo, hi), r, reach = j.band_rad_s, j.resolvable_from_rad_s, _swept(j, input_samples)
    dark = _dark(input_spectrum, reach)
    swept = _minus(reach, dark)                 # where the input had power

    missing: list[MissingBand] = []
    for p in j.pairs or [None]:
        bands = [] if p is None else [(max(a, c), min(b, d))      # adequate only where the input was swept
                                      for a, b in p.bands_rad_s for c, d in swept if min(b, d) > max(a, c)]
        for a, b in band_gaps(bands, lo, hi):
            missing += _classify(f"{p.output}/{p.input}" if p else j.swept_input, p.response if p else None,
                                 a, b, swept, r, crit, dark)
    lines = [f"{j.label} for {j.swept_input}: {len(missing)} band(s) missing." if missing else
             f"{j.label} for {j.swept_input}, no band missing: see the judgement's reasons; fly the sweep again."]
    if j.link_bound:
        lines.append(f"{100 * j.loss.fraction:.0f} % of the frames were lost: the NO-GO reflects the link; fix it "
                     "first (the coherence is the link's, not the sweep's: no amplitude change).")
    if reach == ((lo, hi),) and inj is None and input_samples is None and j.swept_rad_s != (lo, hi):
        lines.append("Where the input was swept is not known beyond its first stretch (pass input_samples): "
                     "the whole band is taken as swept.")
    lines += [f"{m.pair} lacks {_band(*m.band_rad_s)}: {m.cause.replace('_', ' ')}, {m.detail}." for m in missing]

    # the sweep: the judged band; T_rec for its lowest frequency, no shorter than what was flown whole
    reached_top = bool(reach) and reach[-1][1] >= hi * (1 - 1e-9)
    flown = inj.t_record_s if inj is not None else (j.duration_s if reached_top else 0.0)
    duration = float(math.ceil(max(RECORD_PERIODS * 2 * math.pi / lo, flown)))
    incoherent = {m.pair for m in missing if m.cause == "incoherent"}
    need = 1.0 if j.link_bound else math.sqrt(max((_go_power(p, swept, r, crit) for p in j.pairs
                                                   if f"{p.output}/{p.input}" in incoherent), default=1.0))
    factor, n_sweeps = min(need, MAX_AMPLITUDE_FACTOR), NUMBER_OF_SWEEPS
    if need > MAX_AMPLITUDE_FACTOR:             # eps_r^2 ~ 1 / (SNR x record length): more sweeps for the rest
        eps = max((m.median_random_error or 0.0 for m in missing if m.cause == "incoherent"), default=0.0)
        more = (eps / (factor * crit.max_random_error)) ** 2
        n_sweeps = max(n_sweeps, math.ceil(more * j.duration_s / (duration + 2 * trim_s)))
        said = f"x{need:.2g}" if math.isfinite(need) else f"more than x{2 * MAX_AMPLITUDE_FACTOR:g}"
        lines.append(f"Amplitude {said} needed for a clear GO, capped at x{MAX_AMPLITUDE_FACTOR:g} (check linearity "
                     f"and limits before more); fly in calmer air (turbulence lowers coherence)"
                     + (f" and {n_sweeps} sweeps (random error)." if n_sweeps > NUMBER_OF_SWEEPS else "."))
    amp = inj.magnitude if inj is not None else amplitude
    new_amp = None if amp is None else round(amp * factor, 3)
    fades = (inj.t_fade_in_s, inj.t_fade_out_s) if inj is not None else \
        (FADE_CYCLES * 2 * math.pi / lo, FADE_CYCLES * 2 * math.pi / hi)
    sweep = {"omega_min_rad_s": lo, "omega_max_rad_s": hi, "duration_s": duration, "amplitude": new_amp,
             "trim_s": float(trim_s), "fade_in_s": round(fades[0], 3), "fade_out_s": round(fades[1], 3),
             "amplitude_factor": round(factor, 3), "n_sweeps": int(n_sweeps),
             "dwell_s": round(inj.t_const_s if inj is not None else DWELL_CYCLES * 2 * math.pi / lo, 3),
             "band_hz": (lo * _HZ, hi * _HZ)}
    lines.append(f"Sweep {_band(lo, hi)} over {duration:.0f} s ({RECORD_PERIODS:g} periods of {lo:.3g} rad/s: "
                 f"{RECORD_PERIODS * 2 * math.pi / lo:.0f} s), {n_sweeps} sweeps, amplitude "
                 + (f"{amp:g} x {factor:.2g} = {new_amp:g}" if amp is not None else f"x{factor:.2g}")
                 + f", {trim_s:g} s trim at each end, fades {fades[0]:.2g} s in / {fades[1]:.2g} s out.")
    if inj is None:
        return Recommendation(j.verdict, True, tuple(missing), MappingProxyType(sweep), lines=tuple(lines))

    # ArduCopter SystemID: the injection's own parameters, changed only where needed
    w0, w1 = inj.band_rad_s
    before = {"SID_MAGNITUDE": inj.magnitude, "SID_F_START_HZ": round(w0 * _HZ, 6),
              "SID_F_STOP_HZ": round(w1 * _HZ, 6), "SID_T_REC": inj.t_record_s, "SID_T_FADE_IN": inj.t_fade_in_s,
              "SID_T_FADE_OUT": inj.t_fade_out_s}
    sid = {**({"SID_AXIS": inj.axis} if inj.axis is not None else {}), **before, "SID_MAGNITUDE": new_amp,
           "SID_T_REC": duration}
    changed = tuple(k for k, v in before.items() if sid[k] != v)
    top, cut = (reach[-1][1] if reach else w0), None
    if top < min(w1, hi) * (1 - 1e-6):          # the chirp's time at the frequency reached (its schedule inverted)
        tau = (inj.t_const_s + (inj.t_record_s - inj.t_const_s) * math.log(top / w0) / math.log(w1 / w0)
               if top > w0 * (1 + 1e-9) else min(max(j.duration_s - inj.delay_s, 0.0), inj.t_const_s))
        cut = (tau, inj.t_record_s)
        lines.append(f"The chirp was cut at {tau:.1f} s of its {inj.t_record_s:g} s (at {top * _HZ:.3g} Hz of "
                     f"{w1 * _HZ:.3g} Hz): hold SystemID until 'SystemID Finished' ({inj.duration_s:g} s after "
                     "the start).")
    lines.append("Set " + ", ".join(f"{k} {before[k]:g} -> {sid[k]:g}" for k in changed) + "; keep the rest."
                 if changed else "Keep the SID_* parameters as flown: "
                 + ", ".join(f"{k}={v:g}" for k, v in sid.items()) + ".")
    return Recommendation(j.verdict, True, tuple(missing), MappingProxyType(sweep), MappingProxyType(sid), changed, cut,
                          tuple(lines))
