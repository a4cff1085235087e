"""The frequency-response stage of ``livesweep identify``.

case file -> signals from the logs -> one uniform record (resampled, records concatenated, gaps
flagged) -> wild points replaced, trim biases removed -> kinematic consistency checks ->
composite SISO (and MISO-conditioned) responses -> excitation adequacy per pair.

Everything repaired is counted in ``data_quality``; nothing is changed silently.

Concatenated records: spectral windows may span the joins, as the method concatenates repeated
sweeps for more low-frequency averages (docs/method.md §4.1); this is sound because flown records
start and end in trim and each part's trim is removed before the spectra.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from livesweep.config import Case, RecordSpec
from livesweep.consistency.kinematics import check_angle_against_rate, euler_angle_rates
from livesweep.consistency.resample import UniformRecord, concatenate, resample_uniform
from livesweep.consistency.wildpoints import replace_wild_points
from livesweep.errors import ConfigError
from livesweep.limits import MAX_RECORD_VALUES
from livesweep.spectral.adequacy import (PULSE_LIKE_SLOPE_DB_PER_DECADE, input_power_slope_db_per_decade,
                                         pair_adequacy)
from livesweep.spectral.analysis import SpectralAnalysis, analyze
from livesweep.stages.background import Background
from livesweep.telemetry.signals import read_signals

__all__ = ["FrequencyResponseStage", "load_record", "run_frequency_response_stage", "KINEMATIC_PAIRS"]

#: (angle, rate) signal names checked against each other when a case has both (names by convention)
KINEMATIC_PAIRS = (("phi", "p"), ("theta", "q"), ("psi", "r"))
_RAD_UNITS = {"rad": "deg", "rad/s": "deg/s"}


@dataclass(frozen=True)
class FrequencyResponseStage:
    """Everything the stage produced.

    Attributes
    ----------
    case : Case
    record : UniformRecord
        The repaired record the spectra came from.
    analysis : SpectralAnalysis
    adequacy : tuple of PairAdequacy
        For the responses reported (conditioned when there are several inputs).
    data_quality : dict
        Records, repairs, wild points, trim biases, gaps, kinematic checks and notes.
    """

    case: Case
    record: UniformRecord
    analysis: SpectralAnalysis
    adequacy: tuple
    data_quality: dict


def _grid_values(raw: dict, sample_rate_hz: float) -> tuple[int, float, float]:
    """(samples x signals, start [s], end [s]) of the grid :func:`resample_uniform` would lay over
    ``raw``: the overlap of the signals' finite samples (an upper bound on what it allocates)."""
    lo, hi = -math.inf, math.inf
    for s in raw.values():
        t = s.t_s[np.isfinite(s.t_s) & np.isfinite(s.values)]
        if t.size:
            lo, hi = max(lo, float(t.min())), min(hi, float(t.max()))
    if not hi > lo:
        return 0, lo, hi
    return int((hi - lo) * sample_rate_hz + 1) * len(raw), lo, hi


def _read(rec: RecordSpec, signals, names: list[str]) -> tuple[dict, list[str]]:
    notes: list[str] = []
    return read_signals(rec, signals, names, notes=notes), notes


def _read_only(raw: dict) -> dict:
    """Signals that came back from a child process (unpickled arrays are writable) made read-only again."""
    for s in raw.values():
        s.t_s.setflags(write=False)
        s.values.setflags(write=False)
    return raw


def load_record(case: Case, records: tuple[RecordSpec, ...], names: list[str], sample_rate_hz: float, *,
                notes: list[str] | None = None, parallel: bool = False) -> UniformRecord:
    """Read ``names`` from every record, resample each onto ``sample_rate_hz`` and concatenate them.

    Parameters
    ----------
    case : Case
    records : tuple of RecordSpec
    names : list of str
        Signals to read.
    sample_rate_hz : float
        Grid rate [Hz].
    notes : list of str, optional
        Receives a note per log that was unfinished (read up to its torn end) or recovered.
    parallel : bool
        Read the next log in a forked child while this one is read
        (:class:`~livesweep.stages.background.Background`); the result is the same.

    Raises
    ------
    ConfigError
        When the resampled records would hold more than :data:`~livesweep.limits.MAX_RECORD_VALUES`
        samples x signals (naming the case file, ``sample_rate_hz`` and the record), before
        anything is resampled.
    """
    parts, total = [], 0
    ahead = None
    for k, rec in enumerate(records):
        following = (Background(_read, records[k + 1], case.signals, names)       # read while this one is
                     if parallel and k + 1 < len(records) else None)
        raw, said = ahead.result() if ahead is not None else _read(rec, case.signals, names)
        raw = _read_only(raw)
        ahead = following
        if notes is not None:
            notes.extend(said)
        size, lo, hi = _grid_values(raw, sample_rate_hz)
        total += size
        if total > MAX_RECORD_VALUES:
            raise ConfigError(
                f"{case.path}: spectral.sample_rate_hz = {sample_rate_hz!r}: record {rec.label or rec.log.name!r} "
                f"spans {lo!r} to {hi!r} s; resampled with the records before it that is {total} samples x signals "
                f"({len(names)} signals), more than {MAX_RECORD_VALUES}: lower sample_rate_hz or crop the record "
                "(start_s, end_s)")
        parts.append(resample_uniform({n: (s.t_s, s.values) for n, s in raw.items()}, sample_rate_hz,
                                      label=rec.label or rec.log.name))
    return parts[0] if len(parts) == 1 else concatenate(parts)


def _part_slices(record: UniformRecord):
    bounds = [0, *record.joins, record.n_samples]
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def _repair(record: UniformRecord):
    """Replace wild points and remove each part's trim (mean) per signal; report both."""
    values = record.values.copy()
    wild, bias = {}, {}
    for k, name in enumerate(record.names):
        fixed, rep = replace_wild_points(values[k], valid=record.valid[k], name=name)
        values[k] = fixed
        wild[name] = {"replaced": rep.n_replaced, "times_s": [round(float(record.t_s[i]), 3) for i in rep.indices[:50]],
                      "method": f"Hampel, window {2 * rep.half_window + 1} samples, {rep.n_sigma:g} sigma"}
        means = []
        for sl in _part_slices(record):
            ok = record.valid[k, sl]
            m = float(np.mean(values[k, sl][ok])) if ok.any() else 0.0
            values[k, sl] -= m
            means.append(round(m, 6))
        bias[name] = means
    return replace(record, values=values), wild, bias


def _in_deg(case: Case, record: UniformRecord, name: str) -> np.ndarray:
    """A signal in deg or deg/s (rad and rad/s converted by their declared units)."""
    return record.signal(name) * (np.rad2deg(1.0) if case.signals[name].units in _RAD_UNITS else 1.0)


def _euler_rate_sources(case: Case, record: UniformRecord) -> dict[str, tuple[np.ndarray, tuple[str, ...]]]:
    """Euler-angle rates [deg/s] to integrate for each angle, and the signals they were built from.

    With p, q, r, phi and theta all in the record, the full 3-2-1 kinematics
    (phi' = p + (q sin phi + r cos phi) tan theta, ...); otherwise each angle against its body
    rate alone (phi vs p, theta vs q, psi vs r), exact for level lateral or longitudinal motion.
    """
    have = set(record.names)
    if {"p", "q", "r", "phi", "theta"} <= have:
        d2r = np.deg2rad(1.0)
        p, q, r, phi, theta = (_in_deg(case, record, n) * d2r for n in ("p", "q", "r", "phi", "theta"))
        rates = euler_angle_rates(p, q, r, phi, theta)
        out = {"phi": (np.rad2deg(rates[0]), ("p", "q", "r", "phi", "theta")),
               "theta": (np.rad2deg(rates[1]), ("q", "r", "phi"))}
        if "psi" in have:
            out["psi"] = (np.rad2deg(rates[2]), ("q", "r", "phi", "theta"))
        return out
    return {angle: (_in_deg(case, record, rate), (rate,)) for angle, rate in KINEMATIC_PAIRS
            if angle in have and rate in have}


def _kinematic_checks(case: Case, record: UniformRecord):
    checks = []
    sources = _euler_rate_sources(case, record)
    for angle, (rate, used) in sources.items():
        source = used[0] if len(used) == 1 else f"Euler rate({', '.join(used)})"
        a = _in_deg(case, record, angle)
        if angle == "psi":
            a = np.rad2deg(np.unwrap(np.deg2rad(a)))      # heading wraps at +/-180 deg
        valid = record.valid_of(angle)
        for n in used:
            valid = valid & record.valid_of(n)
        lo = max(0.3, case.spectral.band_rad_s[0])
        hi = min(10.0, case.spectral.band_rad_s[1], 0.4 * np.pi * record.sample_rate_hz)
        try:
            c = check_angle_against_rate(a, rate, record.sample_rate_hz, valid=valid, band_rad_s=(lo, hi),
                                         angle_name=angle, rate_name=source)
        except ConfigError as exc:
            checks.append({"measured": angle, "reconstructed_from": source, "error": str(exc)})
            continue
        checks.append({
            "name": f"{angle} vs integral of {source}", "measured": angle, "reconstructed_from": f"integral of {source}",
            "scale_factor_error": round(c.scale_factor_error, 5), "skew_s": round(c.skew_s, 5),
            "rate_bias": round(c.rate_bias, 5), "rate_bias_units": "deg/s",
            "rms_residual": round(c.rms_residual, 5), "band_rad_s": list(c.band_rad_s),
            "tolerance_scale": c.tolerance_scale, "tolerance_skew_s": c.tolerance_skew_s, "passed": bool(c.passed),
            "model": "angle(t) = (1 + scale_factor_error) * integral(rate)(t - skew_s) + a + b t",
        })
    return checks


def run_frequency_response_stage(case: Case, *, parallel: bool = False) -> FrequencyResponseStage:
    """Run the stage for a loaded case (see module docstring); ``parallel``: read the logs two at a
    time in forked children (:func:`load_record`)."""
    sp = case.spectral
    if sp is None:
        raise ConfigError(f"{case.path}: the case has no [spectral] table; the frequency-response stage needs one")
    refs = list(sp.references or ())
    names = list(dict.fromkeys([*sp.inputs, *sp.outputs, *refs, *(n for pair in KINEMATIC_PAIRS for n in pair
                                                                   if n in case.signals)]))
    notes: list[str] = []
    raw = load_record(case, case.identify, names, sp.sample_rate_hz, notes=notes, parallel=parallel)
    record, wild, bias = _repair(raw)
    checks = _kinematic_checks(case, record)
    used = list(dict.fromkeys([*sp.inputs, *sp.outputs, *refs]))
    rows = [record.names.index(n) for n in used]
    valid = np.all(record.valid[rows], axis=0)
    try:
        analysis = analyze(record.values[rows], used, sp.sample_rate_hz, sp.inputs, sp.outputs, sp.band_rad_s,
                           valid=valid, windows_s=sp.windows_s, overlap=sp.overlap, n_freq=sp.n_freq,
                           references=refs or None)
    except ConfigError as e:
        raise ConfigError(f"{case.path}: spectral: {e}") from None
    best = analysis.best
    adequacy = tuple(pair_adequacy(p, case.criteria) for p in best.pairs())
    gaps = {n: {"samples_excluded": int(np.sum(~record.valid_of(n)))} for n in record.names}
    if refs:
        notes.append("responses formed through the exogenous references " + ", ".join(
            f"{r} -> {i}" for r, i in zip(refs, sp.inputs)) + " as (y/r)(u/r)^-1, free of the bias of disturbances "
            "fed back into the inputs by a closed loop (docs/method.md §4.6); frequency_responses_ordinary keeps the "
            "direct (biased) estimates")
    if not np.all(valid):
        notes.append(f"{int(np.sum(~valid))} samples lie in data gaps; every spectral window touching them was excluded")
    slopes = {i: input_power_slope_db_per_decade(analysis.windows, i, sp.band_rad_s) for i in sp.inputs}
    for i, slope in slopes.items():
        poor = [a for a in adequacy if a.input == i and a.fraction < 0.5]
        if np.isfinite(slope) and slope < PULSE_LIKE_SLOPE_DB_PER_DECADE and poor:
            notes.append(f"input {i}: its power falls {-slope:.0f} dB per decade across the band (a frequency sweep "
                         f"falls about 10): pulse-like inputs such as doublets excite only the bottom of the band, so "
                         f"{len(poor)} of its pairs are adequate over less than half of it; fly frequency sweeps for "
                         "frequency responses and keep the doublets for time-domain verification")
    if best.ill_conditioned is not None and np.any(best.ill_conditioned):
        frac = float(np.mean(best.ill_conditioned))
        notes.append(f"input cross-coherence above 0.5 at {100 * frac:.0f} % of frequencies: conditioned responses "
                     "there are unreliable (fly less correlated off-axis inputs)")
    for a in adequacy:
        if a.fraction < 0.2:
            notes.append(f"{a.output}/{a.input}: adequate ({case.criteria.ascii()}) over only {100 * a.fraction:.0f} % "
                         "of the band")
    data_quality = {
        "records": [{"label": lab, "log": str(rec.log), "start_s": rec.start_s, "end_s": rec.end_s}
                    for lab, rec in zip(record.labels, case.identify)],
        "sample_rate_hz": record.sample_rate_hz,
        "duration_s": round(record.n_samples / record.sample_rate_hz, 3),
        "joins_s": [round(j / record.sample_rate_hz, 3) for j in record.joins],
        "repairs": {n: asdict(c) for n, c in record.repairs.items()},
        "wild_points": wild,
        "trim_removed": bias,
        "gaps": gaps,
        "kinematic_checks": checks,
        "excitation": [a.to_dict() for a in adequacy],
        "input_power_slope_db_per_decade": {i: (round(v, 2) if np.isfinite(v) else None) for i, v in slopes.items()},
        "notes": notes,
    }
    return FrequencyResponseStage(case, record, analysis, adequacy, data_quality)
