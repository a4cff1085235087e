"""A model per test point: the low-order equivalent system of each pair a test point excited.

When a test point closes with a usable band, the monitor asks :func:`model_test_point` for the
parametric result of each pair it judged, with the same code and criteria as offline
``livesweep identify`` (:mod:`livesweep.stages.parametric`):

* **The structure.** The case's or map's ``[transfer_functions]`` table for the pair when it has
  one; otherwise, for a rate or attitude response, the low-order equivalent system of the method
  (docs/method.md §7.3): a first-order lag with a delay, ``K / (s + 1/T) e^(-tau s)``, and a
  second-order one, ``K / [zeta, wn] e^(-tau s)``; the first is kept when its cost is excellent
  (J <= 50, the method's own grade), else the one of lower cost.
* **The fit.** :func:`~livesweep.ident.cost.fit_points` over the pair's widest coherent stretch
  (the criteria's ``min_coherence``) and :func:`~livesweep.ident.transfer_function.fit_transfer_function`,
  with their Cramer-Rao bounds and insensitivities (docs/method.md §8.4).
* **Handling-qualities figures** of the fitted model, as the report computes them
  (:func:`~livesweep.stages.parametric.handling_qualities`: bandwidth, phase delay, omega_180),
  and for a broken-loop pair (``[limits] broken_loop``) crossover and margins, each with its
  Cramer-Rao bound propagated from the parameters' covariance (``sigma_f^2 = g^T C g``, ``g`` the
  figure's gradient by central differences).
* **Flags** where the method says not to trust a value: J > 100, CR% > 20, I% > 10, a parameter
  the data do not determine, a figure read outside the fitted band, a quadratic more damped than
  ``MAX_QUADRATIC_ZETA`` (two real roots).
* **Limits and the prediction** (:mod:`livesweep.ident.envelope`): each limit set is checked, with
  the value's bound in the text ("phase margin 38 +/- 3 deg, limit 45 deg: do not proceed").

Pure: a frozen :class:`TestPointModel` out, :meth:`TestPointModel.to_dict` the
``/livesweep/model`` record (docs/outputs.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.ident.accuracy import (MAX_COST, MAX_CRAMER_RAO_PCT, MAX_INSENSITIVITY_PCT, MAX_QUADRATIC_ZETA,
                                      NOT_DETERMINED_PCT)
from livesweep.ident.cost import fit_points, pair_cost
from livesweep.ident.envelope import NO_LIMITS, EnvelopeLimits, Prediction
from livesweep.ident.handling import crossover_and_margins, handling_qualities
from livesweep.ident.transfer_function import TransferFunctionModel, fit_transfer_function
from livesweep.spectral.criteria import DEFAULT_CRITERIA, Criteria

__all__ = ["Figure", "LimitCheck", "PairModel", "TestPointModel", "model_pair", "model_test_point",
           "default_structures", "EXCELLENT_COST", "SCHEMA"]

#: The method's grade of an excellent fit (docs/method.md §7.2: J <= 50): the first-order model is
#: kept when it reaches it (a lower order that describes the data is the better model).
EXCELLENT_COST = MAX_COST / 2
#: Name of the record's schema (the ``/livesweep/model`` channel's).
SCHEMA = "livesweep.model/1"
#: Points of the model's curve the record carries (over the fitted band and a little beyond).
_CURVE_POINTS = 60
#: Relative step of the central differences a figure's bound is propagated with, in units of each
#: parameter's own bound (small against it, large against the interpolation's resolution).
_STEP_OF_BOUND = 0.05
_RATE_OR_ATTITUDE = ("deg/s", "rad/s", "deg", "rad")


def default_structures(output_units: str) -> tuple[tuple[str, str, str], ...]:
    """``(label, numerator, denominator)`` of the low-order equivalent systems tried on a pair
    whose output is in ``output_units`` (empty when the output is no rate or attitude)."""
    if (output_units or "").strip() not in _RATE_OR_ATTITUDE:
        return ()
    return (("first order", "", "(1/T)"), ("second order", "", "[zeta, wn]"))


@dataclass(frozen=True)
class Figure:
    """One value of a model with its Cramer-Rao bound.

    Attributes
    ----------
    name : str
    value : float or None
        None where it is not in the data.
    cramer_rao : float or None
        Its bound, in its own units (None: not determined).
    units : str
    flags : tuple of str
        Why the method says not to trust it (empty: nothing).
    """

    name: str
    value: float | None
    cramer_rao: float | None
    units: str = ""
    flags: tuple = ()

    def text(self, spec: str = ".3g") -> str:
        if self.value is None:
            return f"{self.name} n/a"
        bound = "" if self.cramer_rao is None else f" ± {format(self.cramer_rao, spec)}"
        return f"{self.name} {format(self.value, spec)}{bound} {self.units}".rstrip()

    def to_dict(self) -> dict:
        return {"name": self.name, "value": _num(self.value), "cramer_rao": _num(self.cramer_rao),
                "units": self.units, "flags": list(self.flags)}


@dataclass(frozen=True)
class LimitCheck:
    """One limit of ``[limits]`` (or a prediction) checked on one pair's model.

    Attributes
    ----------
    pair : str
        ``"output/input"``.
    name : str
        ``"phase margin"``, ``"bandwidth"``, ``"damping"``, ``"delay"``, ``"prediction"``, ...
    value : float or None
    limit : float or tuple
    ok : bool
    text : str
        The operator's line ("p/roll: phase margin 38 ± 3 deg, limit 45 deg: do not proceed").
    """

    pair: str
    name: str
    value: float | None
    limit: object
    ok: bool
    text: str

    def to_dict(self) -> dict:
        lim = list(self.limit) if isinstance(self.limit, tuple) else _num(self.limit)
        return {"pair": self.pair, "name": self.name, "value": _num(self.value), "limit": lim, "ok": self.ok,
                "text": self.text}


@dataclass(frozen=True)
class PairModel:
    """One pair's model of a test point.

    Attributes
    ----------
    output, input : str
    structure : str
        ``"first order"``, ``"second order"`` or ``"case"`` (the case's or map's table).
    fit : FittedTransferFunction
    parameters : tuple of Figure
        The fitted parameters (``gain``, ``tau`` [s], ``1/T``, ``zeta``, ``wn`` [rad/s], ...).
    figures : tuple of Figure
        Handling-qualities figures of the fitted model.
    flags : tuple of str
        The method's guidelines the fit fails.
    limits : tuple of LimitCheck
        Every limit checked (and the prediction's), passed or not.
    curve : dict
        The data and the model over the band: ``omega_rad_s``, ``magnitude_db``, ``phase_deg``,
        ``coherence``, ``model_magnitude_db``, ``model_phase_deg`` (and ``predicted_*``).
    """

    output: str
    input: str
    structure: str
    fit: object
    parameters: tuple
    figures: tuple
    flags: tuple
    limits: tuple
    curve: dict

    @property
    def name(self) -> str:
        return f"{self.output}/{self.input}"

    @property
    def breaches(self) -> tuple:
        return tuple(c for c in self.limits if not c.ok)

    def to_dict(self) -> dict:
        f = self.fit
        return {"name": self.name, "output": self.output, "input": self.input, "structure": self.structure,
                "numerator": _shorthand(f.numerator), "denominator": _shorthand(f.denominator), "band_rad_s": [_num(b) for b in f.band_rad_s],
                "cost": _num(f.cost), "converged": bool(f.converged),
                "parameters": [p.to_dict() for p in self.parameters], "figures": [p.to_dict() for p in self.figures],
                "flags": list(self.flags), "limits": [c.to_dict() for c in self.limits],
                "curve": {k: [_num(v, 5) for v in vals] for k, vals in self.curve.items()}}


@dataclass(frozen=True)
class TestPointModel:
    """The model of one test point: one :class:`PairModel` per pair it could be fitted on.

    Attributes
    ----------
    pairs : tuple of PairModel
    skipped : tuple of str
        Pairs not modelled, one line each with why.
    criteria : Criteria
    """

    __test__ = False

    pairs: tuple
    skipped: tuple = ()
    criteria: Criteria = DEFAULT_CRITERIA

    @property
    def breaches(self) -> tuple:
        return tuple(c for p in self.pairs for c in p.breaches)

    def pair(self, name: str) -> PairModel | None:
        return next((p for p in self.pairs if p.name == name), None)

    def to_dict(self) -> dict:
        return {"schema": SCHEMA, "pairs": [p.to_dict() for p in self.pairs], "skipped": list(self.skipped),
                "limits_ok": not self.breaches, "breaches": [c.text for c in self.breaches],
                "criteria": self.criteria.to_dict()}


def _num(v, digits: int | None = None):
    if v is None:
        return None
    v = float(v)
    if not math.isfinite(v):
        return None
    return round(v, digits) if digits is not None else v


def _shorthand(text: str) -> str:
    """A structure as a case file writes it: ``""`` for no factor (its display form ``"1"`` would
    read back as a first-order factor)."""
    return "" if text == "1" else text


def _param_units(key: str) -> str:
    if key == "tau":
        return "s"
    if key == "gain":
        return ""
    if key.startswith("1/") or key.startswith("w"):
        return "rad/s"
    return ""


def _param_figures(fit) -> tuple:
    out = []
    for k, v in fit.parameters.items():
        cr, pct, ins = fit.cramer_rao.get(k), fit.cramer_rao_pct.get(k), fit.insensitivity_pct.get(k)
        flags = []
        if pct is None or not math.isfinite(pct) or pct > NOT_DETERMINED_PCT:
            flags.append("not determined by the data")
        else:
            if pct > MAX_CRAMER_RAO_PCT:
                flags.append(f"CR {pct:.3g} % > {MAX_CRAMER_RAO_PCT:g} %")
            if ins is not None and math.isfinite(ins) and ins > MAX_INSENSITIVITY_PCT:
                flags.append(f"insensitivity {ins:.3g} % > {MAX_INSENSITIVITY_PCT:g} %")
        out.append(Figure(k, v, cr if cr is not None and math.isfinite(cr) else None, _param_units(k), tuple(flags)))
    return tuple(out)


def _response(fit, values: dict, omega) -> np.ndarray:
    """The fitted structure's response with its parameters set to ``values`` (key -> value)."""
    s = 1j * np.asarray(omega, float)
    num, den = np.ones(s.shape, complex), np.ones(s.shape, complex)
    for f in fit.factors:
        if f["kind"] == "s":
            term = s ** f["power"]
        elif f["kind"] == "first":
            a = f["inverse_time_constant"] if f["fixed"] else values[f"1/{f['name']}"]
            term = s + a
        else:
            zn, wn = f["names"]
            z = f["zeta"] if f["fixed"][0] else values[zn]
            w = f["omega"] if f["fixed"][1] else values[wn]
            term = s * s + 2.0 * z * w * s + w * w
        if f["where"] == "numerator":
            num = num * term
        else:
            den = den * term
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return values["gain"] * num / den * np.exp(-s * values.get("tau", fit.delay_s))


def _propagated(fit, figures_of, omega) -> dict:
    """``figures_of(H) -> {name: value or None}`` of the fitted model on ``omega``, each with its
    Cramer-Rao bound through the parameters' covariance: ``{name: (value, bound or None)}``."""
    base = dict(fit.parameters)
    at = figures_of(_response(fit, base, omega))
    keys = list(base)
    C = None if fit.covariance is None else np.asarray(fit.covariance, float)
    out = {}
    grads = {n: np.zeros(len(keys)) for n, v in at.items() if v is not None}
    usable = C is not None and np.all(np.isfinite(np.diag(C)))
    if usable:
        for i, k in enumerate(keys):
            cr = math.sqrt(C[i, i])
            h = _STEP_OF_BOUND * cr if cr > 0 else 1e-6 * max(abs(base[k]), 1e-9)
            up = figures_of(_response(fit, {**base, k: base[k] + h}, omega))
            dn = figures_of(_response(fit, {**base, k: base[k] - h}, omega))
            for n in grads:
                if up.get(n) is None or dn.get(n) is None:
                    grads[n][i] = np.nan
                else:
                    grads[n][i] = (up[n] - dn[n]) / (2 * h)
    for n, v in at.items():
        if v is None:
            out[n] = (None, None)
            continue
        g = grads.get(n)
        if not usable or g is None or not np.all(np.isfinite(g)):
            out[n] = (v, None)
        else:
            out[n] = (v, float(math.sqrt(max(float(g @ C @ g), 0.0))))
    return out


_HQ = (("bandwidth", "bandwidth_rad_s", "rad/s"), ("phase delay", "phase_delay_s", "s"),
       ("omega_180", "omega_180_rad_s", "rad/s"))
_LOOP = (("crossover", 0, "rad/s"), ("phase margin", 1, "deg"), ("gain margin", 3, "dB"))


def _figures(fit, omega, units: str, broken_loop: bool) -> tuple:
    """Handling-qualities (and, for a broken loop, loop) figures of the fitted model on the data's grid."""
    lo, hi = fit.band_rad_s
    out = []

    def hq(H):
        d = handling_qualities(omega, H, output_units=units) or {}
        return {name: d.get(key) for name, key, _ in _HQ}

    for name, (v, cr) in _propagated(fit, hq, omega).items():
        flags = () if v is None or lo <= v <= hi or name == "phase delay" else (
            f"read at {v:.3g} rad/s, outside the fitted band {lo:.3g}-{hi:.3g} rad/s",)
        out.append(Figure(name, v, cr, dict((n, u) for n, _, u in _HQ)[name], flags))
    if broken_loop:
        def loop(H):
            m = crossover_and_margins((omega, H))
            return {name: m[i] for name, i, _ in _LOOP}

        for name, (v, cr) in _propagated(fit, loop, omega).items():
            flags = ()
            if name == "crossover" and v is not None and not lo <= v <= hi:
                flags = (f"crossover {v:.3g} rad/s outside the fitted band {lo:.3g}-{hi:.3g} rad/s",)
            out.append(Figure(name, v, cr, dict((n, u) for n, _, u in _LOOP)[name], flags))
    return tuple(out)


def _fit_flags(fit, params) -> tuple:
    flags = []
    if not fit.converged:
        flags.append(f"the fit did not converge ({fit.message})")
    if not fit.cost <= MAX_COST:
        flags.append(f"J {fit.cost:.3g} > {MAX_COST:g}: the model does not describe the data")
    flags += [f"{p.name}: {f}" for p in params for f in p.flags]
    for fac in fit.factors:
        if fac["kind"] == "second" and fac["where"] == "denominator" and fac["zeta"] > MAX_QUADRATIC_ZETA:
            flags.append(f"{fac['names'][0] or 'zeta'} {fac['zeta']:.3g} > {MAX_QUADRATIC_ZETA:g}: a degenerate "
                         "quadratic, two first-order factors")
    return tuple(flags)


def _pm(v, cr, units, spec=".3g"):
    return f"{format(v, spec)}{'' if cr is None else ' ± ' + format(cr, spec)} {units}".rstrip()


def _check_limits(name: str, fit, figures, limits: EnvelopeLimits, broken: bool) -> list:
    checks = []
    fig = {f.name: f for f in figures}

    def add(what, value, cr, limit, ok, units, limit_text):
        word = "" if ok else ": do not proceed"
        checks.append(LimitCheck(name, what, value, limit, ok,
                                 f"{name}: {what} {_pm(value, cr, units)}, limit {limit_text}{word}"))

    if broken and limits.min_phase_margin_deg is not None and (f := fig.get("phase margin")) and f.value is not None:
        add("phase margin", f.value, f.cramer_rao, limits.min_phase_margin_deg, f.value >= limits.min_phase_margin_deg,
            "deg", f"{limits.min_phase_margin_deg:g} deg")
    if broken and limits.min_gain_margin_db is not None and (f := fig.get("gain margin")) and f.value is not None:
        add("gain margin", f.value, f.cramer_rao, limits.min_gain_margin_db, f.value >= limits.min_gain_margin_db,
            "dB", f"{limits.min_gain_margin_db:g} dB")
    if limits.bandwidth_rad_s is not None and (f := fig.get("bandwidth")) and f.value is not None:
        lo, hi = limits.bandwidth_rad_s
        add("bandwidth", f.value, f.cramer_rao, (lo, hi), lo <= f.value <= hi, "rad/s", f"{lo:g}-{hi:g} rad/s")
    if limits.min_damping is not None:
        for fac in fit.factors:
            if fac["where"] == "denominator" and fac["kind"] == "second":
                zn = fac["names"][0]
                cr = None if fac["fixed"][0] else fit.cramer_rao.get(zn)
                add(f"damping {zn}", fac["zeta"], cr if cr is not None and math.isfinite(cr) else None,
                    limits.min_damping, fac["zeta"] >= limits.min_damping, "", f"{limits.min_damping:g}")
    if limits.max_delay_s is not None and "tau" in fit.parameters:
        cr = fit.cramer_rao.get("tau")
        add("delay", fit.delay_s, cr if cr is not None and math.isfinite(cr) else None, limits.max_delay_s,
            fit.delay_s <= limits.max_delay_s, "s", f"{limits.max_delay_s:g} s")
    return checks


def _check_prediction(name: str, pd, prediction: Prediction, fit, limits: EnvelopeLimits) -> LimitCheck:
    J = pair_cost(pd, prediction.response(pd.omega))
    ok = J <= limits.max_prediction_cost
    tau = fit.cramer_rao.get("tau")
    delay = "" if "tau" not in fit.parameters else (
        f"; delay predicted {prediction.delay_s:.3g} s, measured {_pm(fit.delay_s, tau if tau and math.isfinite(tau) else None, 's')}")
    text = (f"{name}: prediction {prediction.name!r} J {J:.3g}, limit {limits.max_prediction_cost:g}"
            + ("" if ok else ": the aircraft is not what was predicted; do not proceed") + delay)
    return LimitCheck(name, "prediction", J, limits.max_prediction_cost, ok, text)


def _curve(resp, fit, prediction: Prediction | None) -> dict:
    lo, hi = fit.band_rad_s
    w = resp.omega
    keep = np.flatnonzero(np.isfinite(resp.H) & (w >= lo / 1.5) & (w <= hi * 1.5))
    if keep.size > _CURVE_POINTS:
        keep = keep[np.unique(np.round(np.linspace(0, keep.size - 1, _CURVE_POINTS)).astype(int))]
    w = w[keep]
    H, T = resp.H[keep], fit.response(w)
    out = {"omega_rad_s": w, "magnitude_db": 20 * np.log10(np.abs(H)), "phase_deg": np.degrees(np.unwrap(np.angle(H))),
           "coherence": resp.coherence[keep], "model_magnitude_db": 20 * np.log10(np.abs(T)),
           "model_phase_deg": np.degrees(np.unwrap(np.angle(T)))}
    if prediction is not None:
        P = prediction.response(w)
        out["predicted_magnitude_db"] = 20 * np.log10(np.abs(P))
        out["predicted_phase_deg"] = np.degrees(np.unwrap(np.angle(P)))
    return out


def model_pair(resp, *, output_units: str = "", spec=None, criteria: Criteria = DEFAULT_CRITERIA,
               prediction: Prediction | None = None, limits: EnvelopeLimits = NO_LIMITS) -> PairModel:
    """The model of one pair's response.

    Parameters
    ----------
    resp : FrequencyResponse
        The pair's composite response over the test point.
    output_units : str
        The output's units (picks the default structure and the handling-qualities reading).
    spec : TransferFunctionSpec, optional
        The case's or map's ``[transfer_functions]`` table for the pair (structure and band).
    criteria : Criteria
        The fit band is the widest stretch with ``gamma^2 >= min_coherence``.
    prediction : Prediction, optional
    limits : EnvelopeLimits

    Returns
    -------
    PairModel

    Raises
    ------
    ConfigError
        The pair has no coherent band, or no structure applies (naming the pair).
    """
    name = f"{resp.output}/{resp.input}"
    band = None if spec is None else spec.band_rad_s
    pd = fit_points(resp, band_rad_s=band, min_coherence=criteria.min_coherence)
    if spec is not None:
        tried = (("case", spec.model),)
    else:
        tried = tuple((label, TransferFunctionModel(name=name, numerator=num, denominator=den, delay=True))
                      for label, num, den in default_structures(output_units))
        if not tried:
            raise ConfigError(f"{name}: no structure for an output in {output_units or 'no units'!r}: give the pair "
                              "a [transfer_functions] table")
    chosen = None
    for label, model in tried:
        fit = fit_transfer_function([pd], [model])[0]
        if chosen is None or fit.cost < chosen[1].cost:
            chosen = (label, fit)
        if label == "first order" and fit.converged and fit.cost <= EXCELLENT_COST:
            chosen = (label, fit)
            break
    label, fit = chosen
    broken = name in limits.broken_loop
    params = _param_figures(fit)
    figures = _figures(fit, resp.omega, output_units, broken)
    checks = _check_limits(name, fit, figures, limits, broken)
    if prediction is not None:
        checks.append(_check_prediction(name, pd, prediction, fit, limits))
    return PairModel(resp.output, resp.input, label, fit, params, figures, _fit_flags(fit, params), tuple(checks),
                     _curve(resp, fit, prediction))


def model_test_point(judgement, *, units: dict | None = None, specs=(), criteria: Criteria | None = None,
                     predictions=(), limits: EnvelopeLimits = NO_LIMITS) -> TestPointModel:
    """The model of a judged test point: :func:`model_pair` on each pair the judgement holds a
    response of.

    Parameters
    ----------
    judgement : TestPointJudgement
        The closing judgement (:func:`livesweep.spectral.verdict.judge_test_point`).
    units : dict of str -> str
        Signal -> units.
    specs : sequence of TransferFunctionSpec
        The ``[transfer_functions]`` tables (the first for a pair is used).
    criteria : Criteria, optional
        Default the judgement's.
    predictions : sequence of Prediction
    limits : EnvelopeLimits

    Returns
    -------
    TestPointModel
    """
    criteria = judgement.criteria if criteria is None else criteria
    units = units or {}
    pairs, skipped = [], []
    for pj in judgement.pairs:
        resp = getattr(pj, "response", None)
        name = f"{pj.output}/{pj.input}"
        if resp is None:
            skipped.append(f"{name}: no response (the test point was too short to analyse)")
            continue
        spec = next((s for s in specs if (s.model.output, s.model.input) == (pj.output, pj.input)), None)
        pred = next((p for p in predictions if (p.output, p.input) == (pj.output, pj.input)), None)
        try:
            pairs.append(model_pair(resp, output_units=units.get(pj.output, ""), spec=spec, criteria=criteria,
                                    prediction=pred, limits=limits))
        except ConfigError as e:
            skipped.append(str(e))
    return TestPointModel(tuple(pairs), tuple(skipped), criteria)
