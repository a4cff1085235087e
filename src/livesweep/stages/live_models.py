"""The models the live monitor recorded in flight, read back and set beside the full identification.

While a sweep is flown the monitor fits each closed test point and records the result on
``/livesweep/model`` (docs/outputs.md; :mod:`livesweep.ident.test_point_model`). When an
``[[identify]]`` record of a case is such a recording, ``livesweep identify`` reads those models
back (:func:`read_live_models`: the one function here that touches a file) and the report shows
them beside its own fits ("the same after landing"): for each live pair that the case also fits
as a ``[transfer_functions]`` table of the same structure, :func:`compare_pair` gives every
parameter's in-flight value and Cramer-Rao bound, the identification's, and their difference in
units of the combined bound ``sqrt(CR_live^2 + CR_offline^2)``.

Which models belong to a record: those whose test point lies for more than :data:`MIN_OVERLAP` of
its duration inside the record's ``[start_s, end_s)`` (the whole log when the record has no
slice), both on the signals' stamp clock [s].

A log without the channel gives no models; a message that is not a model (not JSON, or missing
or mistyped keys) is skipped and counted (:attr:`LiveModels.skipped`), never an error.

Examples
--------
>>> from livesweep.stages.live_models import read_live_models, compare_live_models   # doctest: +SKIP
>>> live = read_live_models(ident.case.identify)                                       # doctest: +SKIP
>>> compare_live_models(live, ident.transfer_functions.fits)                           # doctest: +SKIP
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from livesweep.errors import ConfigError, LogFormatError

__all__ = ["MODEL_TOPIC", "MIN_OVERLAP", "AGREE_BOUNDS", "LiveValue", "LivePair", "LiveModel", "LiveModels",
           "ParameterComparison", "PairComparison", "read_live_models", "parse_model", "overlap_fraction",
           "compare_pair", "compare_live_models", "live_models_section"]

#: The channel the monitor records a test point's model on.
MODEL_TOPIC = "/livesweep/model"
#: A test point belongs to a record when more than this fraction of its duration lies in the record's slice.
MIN_OVERLAP = 0.5
#: A parameter agrees when the in-flight and offline values differ by at most this many combined
#: bounds (the monitor's own threshold for a parameter that moved between test points,
#: :data:`livesweep.monitor.models.MOVED_BOUNDS`).
AGREE_BOUNDS = 2.0
#: Keys of ``test_point`` kept from the record (docs/outputs.md, /livesweep/model.test_point).
_TEST_POINT_KEYS = ("number", "start_s", "end_s", "swept_input", "axis", "source", "verdict", "label", "conditions")
#: Relative tolerance on the fixed values of two structures (the shorthand prints 6 digits).
_FIXED_RTOL = 1e-5


class _Malformed(ValueError):
    """A ``/livesweep/model`` message that is not a model; the text says what is wrong."""


# ------------------------------------------------------------------------------------------------
# results
# ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class LiveValue:
    """One parameter or figure of an in-flight model.

    Attributes
    ----------
    name : str
        ``gain``, ``tau``, ``1/T``, ``zeta``, ``wn`` ... or a figure's (``bandwidth``, ``phase delay``).
    value : float or None
        In ``units``; None where the monitor could not compute it.
    cramer_rao : float or None
        Its Cramer-Rao bound, absolute, in ``units`` (None: not determined).
    units : str
        ``s`` for ``tau``, ``rad/s`` for ``1/T``, ``wn`` and the frequencies, ``""`` for the gain
        (output units per input unit times s^-(poles - zeros)) and ``zeta``.
    flags : tuple of str
        The method's guidelines the value fails, as the monitor recorded them.
    """

    name: str
    value: float | None
    cramer_rao: float | None
    units: str = ""
    flags: tuple = ()

    def to_dict(self) -> dict:
        return {"name": self.name, "value": self.value, "cramer_rao": self.cramer_rao, "units": self.units,
                "flags": list(self.flags)}


@dataclass(frozen=True)
class LivePair:
    """One pair of an in-flight model.

    Attributes
    ----------
    name : str
        ``"output/input"``.
    output, input : str
    structure : str
        ``"first order"``, ``"second order"`` or ``"case"`` (the map's or case's table).
    numerator, denominator : str
        The structure in the factored shorthand (``""``: no factor).
    band_rad_s : tuple of float
        The fitted band [rad/s] (empty when not recorded).
    cost : float or None
        J of the fit (docs/method.md §7.2).
    converged : bool
    parameters : tuple of LiveValue
    figures : tuple of LiveValue
        Handling-qualities (and loop) figures with propagated bounds.
    flags : tuple of str
        The guidelines the fit fails.
    limits : tuple of dict
        Each ``[limits]`` check as recorded (``pair``, ``name``, ``value``, ``limit``, ``ok``, ``text``).
    """

    name: str
    output: str
    input: str
    structure: str
    numerator: str
    denominator: str
    band_rad_s: tuple
    cost: float | None
    converged: bool
    parameters: tuple
    figures: tuple
    flags: tuple
    limits: tuple

    def parameter(self, name: str) -> LiveValue | None:
        return next((p for p in self.parameters if p.name == name), None)

    def to_dict(self) -> dict:
        return {"name": self.name, "output": self.output, "input": self.input, "structure": self.structure,
                "numerator": self.numerator, "denominator": self.denominator, "band_rad_s": list(self.band_rad_s),
                "cost": self.cost, "converged": self.converged, "parameters": [p.to_dict() for p in self.parameters],
                "figures": [f.to_dict() for f in self.figures], "flags": list(self.flags),
                "limits": [dict(c) for c in self.limits]}


@dataclass(frozen=True)
class LiveModel:
    """One ``/livesweep/model`` record of a log, for one ``[[identify]]`` record.

    Attributes
    ----------
    log : str
        The MCAP file it was read from.
    record : str
        The ``[[identify]]`` record's label (the log's file name when it has none).
    test_point : dict
        ``number``, ``start_s``, ``end_s`` [s, stamp clock], ``swept_input``, ``axis``, ``source``,
        ``verdict``, ``label``, ``conditions`` (name -> the map's condition signal averaged over
        the test point, or None), those recorded.
    overlap : float
        Fraction of the test point's duration inside the record's slice (0-1).
    pairs : tuple of LivePair
    skipped : tuple of str
        Pairs the monitor did not model, with why.
    breaches : tuple of str
        The operator's line of each limit broken.
    """

    log: str
    record: str
    test_point: dict
    overlap: float
    pairs: tuple
    skipped: tuple = ()
    breaches: tuple = ()

    def to_dict(self) -> dict:
        return {"log": self.log, "record": self.record, "test_point": dict(self.test_point),
                "overlap": self.overlap, "pairs": [p.to_dict() for p in self.pairs], "skipped": list(self.skipped),
                "breaches": list(self.breaches)}


@dataclass(frozen=True)
class LiveModels:
    """What :func:`read_live_models` found in the logs of a case.

    Attributes
    ----------
    models : tuple of LiveModel
        In record order, then test-point order; a test point is listed once even when two
        records of the same log hold it.
    skipped : int
        ``/livesweep/model`` messages that are not models (not JSON, missing or mistyped keys).
    skip_examples : tuple of str
        The first few of them: file, message, what is wrong.
    notes : tuple of str
        Lines for the report: logs that could not be read for models, what was skipped.
    """

    models: tuple = ()
    skipped: int = 0
    skip_examples: tuple = ()
    notes: tuple = ()


@dataclass(frozen=True)
class ParameterComparison:
    """One parameter in flight and after landing.

    Attributes
    ----------
    name : str
        The in-flight name (``gain``, ``1/T``, ``tau`` ...).
    offline_name : str
        The same parameter's key in the case's transfer function (``1/Tr`` ...).
    units : str
    live_value, live_cramer_rao : float or None
        In flight, in ``units``.
    offline_value, offline_cramer_rao : float or None
        The identification's (:class:`~livesweep.ident.transfer_function_result.FittedTransferFunction`),
        in ``units``; a bound that is not finite is None.
    difference : float or None
        ``live_value - offline_value`` in ``units``.
    combined_bound : float or None
        ``sqrt(live_cramer_rao^2 + offline_cramer_rao^2)`` in ``units``; None without both bounds.
    bounds : float or None
        ``difference / combined_bound`` (signed); None without a combined bound.
    agrees : bool or None
        ``|bounds| <= AGREE_BOUNDS``; None without a combined bound.
    """

    name: str
    offline_name: str
    units: str
    live_value: float | None
    live_cramer_rao: float | None
    offline_value: float | None
    offline_cramer_rao: float | None
    difference: float | None
    combined_bound: float | None
    bounds: float | None
    agrees: bool | None

    def to_dict(self) -> dict:
        return {"name": self.name, "offline_name": self.offline_name, "units": self.units,
                "live_value": self.live_value, "live_cramer_rao": self.live_cramer_rao,
                "offline_value": self.offline_value, "offline_cramer_rao": self.offline_cramer_rao,
                "difference": self.difference, "combined_bound": self.combined_bound, "bounds": self.bounds,
                "agrees": self.agrees}


@dataclass(frozen=True)
class PairComparison:
    """A live pair beside the case's transfer function of the same pair and structure.

    Attributes
    ----------
    pair : str
        ``"output/input"``.
    transfer_function : str
        The ``[transfer_functions.<name>]`` it is compared with.
    live_band_rad_s, offline_band_rad_s : tuple of float
        The two fitted bands [rad/s].
    live_cost, offline_cost : float or None
        The two J.
    parameters : tuple of ParameterComparison
        In the in-flight order.
    max_bounds : float or None
        The largest ``|bounds|`` (None when no parameter has a combined bound).
    agrees : bool or None
        Every parameter with a combined bound within :data:`AGREE_BOUNDS` (None: none has one).
    """

    pair: str
    transfer_function: str
    live_band_rad_s: tuple
    offline_band_rad_s: tuple
    live_cost: float | None
    offline_cost: float | None
    parameters: tuple
    max_bounds: float | None
    agrees: bool | None

    def to_dict(self) -> dict:
        return {"pair": self.pair, "transfer_function": self.transfer_function,
                "live_band_rad_s": list(self.live_band_rad_s), "offline_band_rad_s": list(self.offline_band_rad_s),
                "live_cost": self.live_cost, "offline_cost": self.offline_cost,
                "parameters": [p.to_dict() for p in self.parameters], "max_bounds": self.max_bounds,
                "agrees": self.agrees}


# ------------------------------------------------------------------------------------------------
# reading (the only I/O)
# ------------------------------------------------------------------------------------------------

def read_live_models(records, *, min_overlap: float = MIN_OVERLAP) -> LiveModels:
    """The ``/livesweep/model`` records of the logs of ``records`` that lie in their slices.

    Parameters
    ----------
    records : sequence of RecordSpec
        A case's ``[[identify]]`` records (``log``, ``label``, ``start_s``, ``end_s`` [s]).
    min_overlap : float
        A test point belongs to a record when more than this fraction of its duration lies in the
        record's ``[start_s, end_s)``.

    Returns
    -------
    LiveModels
        Empty for logs without the channel. Never raises for a log's content: a log that cannot
        be read for models gives a note, a message that is not a model a counted skip.
    """
    cache: dict[str, tuple] = {}
    models, seen, notes, examples = [], set(), [], []
    skipped = 0
    for rec in records:
        log = str(rec.log)
        if log not in cache:
            cache[log] = _read_log(Path(rec.log))
            found, bad, why, log_notes = cache[log]
            skipped += bad
            examples += why
            notes += log_notes
        found = cache[log][0]
        for data in found:
            tp = data["test_point"]
            frac = overlap_fraction(tp["start_s"], tp["end_s"], rec.start_s, rec.end_s)
            key = (log, tp.get("number"), tp["start_s"], tp["end_s"])
            if frac > min_overlap and key not in seen:
                seen.add(key)
                models.append(_model(data, log, rec.label or Path(rec.log).name, frac))
    if skipped:
        notes.append(f"{skipped} {MODEL_TOPIC} message(s) skipped, not a model: " + "; ".join(examples[:3]))
    return LiveModels(tuple(models), skipped, tuple(examples[:5]), tuple(notes))


def _read_log(path: Path) -> tuple[list, int, list, list]:
    """(valid model dicts, messages skipped, why (first few), notes) of one log."""
    from livesweep.telemetry.mcap_log import SkippedMessages, iter_file_order, read_messages, read_summary

    try:
        if not read_summary(path).message_counts.get(MODEL_TOPIC):
            return [], 0, [], []
    except (LogFormatError, OSError) as exc:
        return [], 0, [], [f"{path}: {MODEL_TOPIC} not read: {exc}"]
    lenient = None
    try:            # the channel's chunks only, through the index
        messages = list(read_messages(path, topics=MODEL_TOPIC))
    except LogFormatError:          # a message that is not JSON, a damaged chunk: read leniently
        lenient = SkippedMessages()
        try:
            messages = list(iter_file_order(path, MODEL_TOPIC, skipped=lenient))
        except (LogFormatError, OSError) as exc:
            return [], 0, [], [f"{path}: {MODEL_TOPIC} not read: {exc}"]
    out, why = [], list(lenient.examples) if lenient else []
    bad = lenient.total if lenient else 0
    for k, m in enumerate(messages):
        try:
            out.append(parse_model(m.data))
        except _Malformed as exc:
            bad += 1
            why.append(f"{path}: {MODEL_TOPIC} message {k} (log_time {m.log_time_ns} ns): {exc}")
    return out, bad, why, []


# ------------------------------------------------------------------------------------------------
# parsing and matching (pure)
# ------------------------------------------------------------------------------------------------

def _number(v, where: str, *, required: bool = False) -> float | None:
    """A finite number, None for null or a non-finite one (``"NaN"``, ``"Infinity"`` as MCAP
    records write them); _Malformed for anything else (or None when ``required``)."""
    if v is None or v in ("NaN", "Infinity", "-Infinity"):
        if required:
            raise _Malformed(f"{where} is not a number: {v!r}")
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise _Malformed(f"{where} is not a number: {v!r}")
    v = float(v)
    if not math.isfinite(v):
        if required:
            raise _Malformed(f"{where} is not finite")
        return None
    return v


def _text(v, where: str) -> str:
    if not isinstance(v, str):
        raise _Malformed(f"{where} is not text: {v!r}")
    return v


def _list(d: dict, key: str, where: str) -> list:
    v = d.get(key, [])
    if not isinstance(v, list):
        raise _Malformed(f"{where}.{key} is not a list")
    return v


def _values(items: list, where: str) -> list:
    out = []
    for k, p in enumerate(items):
        w = f"{where}[{k}]"
        if not isinstance(p, dict):
            raise _Malformed(f"{w} is not an object")
        out.append({"name": _text(p.get("name"), w + ".name"), "value": _number(p.get("value"), w + ".value"),
                    "cramer_rao": _number(p.get("cramer_rao"), w + ".cramer_rao"),
                    "units": _text(p.get("units", ""), w + ".units"),
                    "flags": [_text(f, w + ".flags") for f in _list(p, "flags", w)]})
    return out


def parse_model(data) -> dict:
    """One ``/livesweep/model`` message checked and reduced to what the report uses.

    Parameters
    ----------
    data : dict
        The decoded message (docs/outputs.md, /livesweep/model).

    Returns
    -------
    dict
        ``test_point`` (``start_s < end_s`` finite [s]), ``pairs`` (name, output, input, structure,
        numerator, denominator, band_rad_s [rad/s], cost, converged, parameters, figures, flags,
        limits), ``skipped``, ``breaches``.

    Raises
    ------
    ValueError
        (a private subclass) saying which key is missing or of the wrong type.
    """
    if not isinstance(data, dict):
        raise _Malformed("is not an object")
    tp = data.get("test_point")
    if not isinstance(tp, dict):
        raise _Malformed("test_point is missing or not an object")
    start = _number(tp.get("start_s"), "test_point.start_s", required=True)
    end = _number(tp.get("end_s"), "test_point.end_s", required=True)
    if not end > start:
        raise _Malformed(f"test_point ends ({end}) before it starts ({start})")
    test_point = {k: tp.get(k) for k in _TEST_POINT_KEYS if k in tp}
    test_point.update(start_s=start, end_s=end)
    if "conditions" in tp:
        if not isinstance(tp["conditions"], dict):
            raise _Malformed("test_point.conditions is not an object")
        test_point["conditions"] = {_text(k, "test_point.conditions"): _number(v, f"test_point.conditions.{k}")
                                    for k, v in tp["conditions"].items()}
    if not isinstance(data.get("pairs"), list):
        raise _Malformed("pairs is missing or not a list")
    pairs = []
    for k, p in enumerate(data["pairs"]):
        w = f"pairs[{k}]"
        if not isinstance(p, dict):
            raise _Malformed(f"{w} is not an object")
        name = _text(p.get("name"), w + ".name")
        out, _, inp = name.partition("/")
        band = [_number(b, w + ".band_rad_s", required=True) for b in _list(p, "band_rad_s", w)]
        if len(band) not in (0, 2):
            raise _Malformed(f"{w}.band_rad_s has {len(band)} values, not 2")
        limits = _list(p, "limits", w)
        if not all(isinstance(c, dict) for c in limits):
            raise _Malformed(f"{w}.limits holds a value that is not an object")
        pairs.append({"name": name, "output": _text(p.get("output", out), w + ".output"),
                      "input": _text(p.get("input", inp), w + ".input"),
                      "structure": _text(p.get("structure", ""), w + ".structure"),
                      "numerator": _text(p.get("numerator"), w + ".numerator"),
                      "denominator": _text(p.get("denominator"), w + ".denominator"),
                      "band_rad_s": band, "cost": _number(p.get("cost"), w + ".cost"),
                      "converged": bool(p.get("converged", True)),
                      "parameters": _values(_list(p, "parameters", w), w + ".parameters"),
                      "figures": _values(_list(p, "figures", w), w + ".figures"),
                      "flags": [_text(f, w + ".flags") for f in _list(p, "flags", w)],
                      "limits": [dict(c) for c in limits]})
    skipped = [_text(s, "skipped") for s in _list(data, "skipped", "model")]
    breaches = [_text(s, "breaches") for s in _list(data, "breaches", "model")]
    return {"test_point": test_point, "pairs": pairs, "skipped": skipped, "breaches": breaches}


def _model(data: dict, log: str, record: str, overlap: float) -> LiveModel:
    pairs = tuple(LivePair(p["name"], p["output"], p["input"], p["structure"], p["numerator"], p["denominator"],
                           tuple(p["band_rad_s"]), p["cost"], p["converged"],
                           tuple(LiveValue(v["name"], v["value"], v["cramer_rao"], v["units"], tuple(v["flags"]))
                                 for v in p["parameters"]),
                           tuple(LiveValue(v["name"], v["value"], v["cramer_rao"], v["units"], tuple(v["flags"]))
                                 for v in p["figures"]),
                           tuple(p["flags"]), tuple(p["limits"]))
                  for p in data["pairs"])
    return LiveModel(log, record, data["test_point"], overlap, pairs, tuple(data["skipped"]), tuple(data["breaches"]))


def overlap_fraction(start_s: float, end_s: float, lo_s: float | None, hi_s: float | None) -> float:
    """Fraction (0-1) of the test point ``[start_s, end_s]`` [s] inside the slice ``[lo_s, hi_s)`` [s]
    (None: open at that end)."""
    lo = start_s if lo_s is None else max(start_s, lo_s)
    hi = end_s if hi_s is None else min(end_s, hi_s)
    return max(0.0, hi - lo) / (end_s - start_s) if end_s > start_s else 0.0


def _structure(text: str, prefix: str):
    """The parsed shorthand; ``"1"`` is the display form of no factor (``str(Structure())``)."""
    from livesweep.ident.transfer_function_structure import parse_structure

    return parse_structure("" if str(text).strip() == "1" else text, prefix=prefix)


def _same_fixed(a: tuple, b: tuple) -> bool:
    return len(a) == len(b) and all((x is None and y is None) or (x is not None and y is not None and math.isclose(
        x, y, rel_tol=_FIXED_RTOL, abs_tol=1e-12)) for x, y in zip(a, b))


def parameter_map(live: LivePair, fit) -> tuple[dict | None, str]:
    """In-flight parameter name -> the fit's key when both have the same structure, else (None, why).

    The same structure: the same numerator and denominator factors in the same order (kind, power
    of s, fixed values), and a delay in both or neither. Parameter names may differ; they are
    matched by their place in the structure (``gain`` and ``tau`` by name).
    """
    from livesweep.ident.transfer_function_structure import STRUCTURE_PREFIXES

    mapping = {"gain": "gain"}
    for where, prefix in STRUCTURE_PREFIXES.items():
        try:
            a = _structure(getattr(live, where), prefix)
            b = _structure(getattr(fit, where), prefix)
        except ConfigError as exc:
            return None, f"the {where} does not parse: {exc}"
        if len(a.factors) != len(b.factors) or not all(
                fa.kind == fb.kind and fa.power == fb.power and _same_fixed(fa.fixed, fb.fixed)
                for fa, fb in zip(a.factors, b.factors)):
            return None, (f"another structure: in flight {live.numerator or '1'} / {live.denominator or '1'}, "
                          f"TF {fit.name} {fit.numerator or '1'} / {fit.denominator or '1'}")
        for fa, fb in zip(a.factors, b.factors):
            mapping.update({ka: kb for ka, kb in zip(fa.keys, fb.keys) if ka is not None})
    live_names = {p.name for p in live.parameters}
    if ("tau" in live_names) != ("tau" in fit.parameters):
        return None, f"a delay in {'flight' if 'tau' in live_names else 'TF ' + fit.name} only"
    if "tau" in live_names:
        mapping["tau"] = "tau"
    if set(mapping) != live_names or not set(mapping.values()) <= set(fit.parameters):
        return None, f"the parameters differ: in flight {sorted(live_names)}, TF {fit.name} {sorted(fit.parameters)}"
    return mapping, ""


def _finite(x) -> float | None:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def compare_pair(live: LivePair, fit) -> tuple[PairComparison | None, str]:
    """The in-flight pair beside a fitted transfer function of the case.

    Parameters
    ----------
    live : LivePair
    fit : FittedTransferFunction
        Of the same output and input.

    Returns
    -------
    (PairComparison or None, str)
        None and why when the structures differ.
    """
    mapping, why = parameter_map(live, fit)
    if mapping is None:
        return None, why
    rows = []
    for p in live.parameters:
        key = mapping[p.name]
        ov, oc = _finite(fit.parameters.get(key)), _finite(fit.cramer_rao.get(key))
        diff = None if p.value is None or ov is None else p.value - ov
        bound = None if p.cramer_rao is None or oc is None else math.hypot(p.cramer_rao, oc)
        n = None if diff is None or not bound else diff / bound
        rows.append(ParameterComparison(p.name, key, p.units, p.value, p.cramer_rao, ov, oc, diff, bound or None, n,
                                        None if n is None else abs(n) <= AGREE_BOUNDS))
    ns = [abs(r.bounds) for r in rows if r.bounds is not None]
    return PairComparison(live.name, fit.name, live.band_rad_s, tuple(float(b) for b in fit.band_rad_s), live.cost,
                          _finite(fit.cost), tuple(rows), max(ns) if ns else None,
                          all(r.agrees for r in rows if r.agrees is not None) if ns else None), ""


def _match(live: LivePair, fits) -> tuple[PairComparison | None, str]:
    """The first fit of the pair with the same structure, or why none is compared."""
    same_pair = [f for f in fits if (f.output, f.input) == (live.output, live.input)]
    if not same_pair:
        return None, f"the case fits no transfer function of {live.name}"
    why = []
    for f in same_pair:
        cmp, reason = compare_pair(live, f)
        if cmp is not None:
            return cmp, ""
        why.append(reason)
    return None, "; ".join(why)


def compare_live_models(live: LiveModels, fits) -> list[list[tuple[PairComparison | None, str]]]:
    """Per model, per pair: (the comparison with the case's transfer function, or None and why)."""
    return [[_match(p, fits or ()) for p in m.pairs] for m in live.models]


def live_models_section(live: LiveModels | None, fits=()) -> list[dict]:
    """``report.json``'s ``live_models``: every model with, per pair, ``comparison`` (or null and
    ``not_compared``, why). Empty without models."""
    if live is None:
        return []
    out = []
    for m, compared in zip(live.models, compare_live_models(live, fits)):
        d = m.to_dict()
        for pd, (cmp, why) in zip(d["pairs"], compared):
            pd["comparison"] = None if cmp is None else cmp.to_dict()
            pd["not_compared"] = why or None
        out.append(d)
    return out
