"""The residual loop's third stage: add a candidate effect to the model and re-identify it.

:func:`try_effect` writes a candidate (or a pair of them) into the ``[state_space]`` table, refits
the model and judges the refit: its shape must hold (the fit converges, the whitened residual and
J_ave fall beyond noise, verification is not worse) and its new parameters must meet the accuracy
guidelines (CR% <= 20, I% <= 10). A clearly present effect with one poorly determined shape
parameter, or whose only parameter is at least three Cramer-Rao bounds from zero, is kept with
that parameter fixed at its fitted value (structure reduction inside the effect).
:func:`re_identify` runs one step's refits: the strongest candidates, the best at each place,
everything when the fit is inadequate, the simpler kinds at an accepted effect's place, and pairs
when the best candidate fails alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from livesweep.effects import EFFECT_KINDS, parameter_role
from livesweep.effects.table import restart_from
from livesweep.errors import ConfigError
from livesweep.ident.accuracy import (MAX_CRAMER_RAO_PCT, MAX_INSENSITIVITY_PCT, guideline_failures, parameter_report,
                                      pct_text)
from livesweep.ident.residual_choice import _explained, pair_refusal
from livesweep.ident.residual_judge import n_free, verification_change, verification_summary
from livesweep.ident.residual_records import EffectRecord, ModelState, Trial
from livesweep.ident.residual_space import band_of, pair_residuals, whitened_ss
from livesweep.ident.residual_tables import augment_table, table_with_fit
from livesweep.ident.state_space import StateSpaceModel, refit_state_space

__all__ = ["MIN_RELATIVE_COST_DROP", "CLEAR_EVIDENCE_FACTOR", "FIXABLE_ROLES", "ONLY_PARAMETER_CR_PCT",
           "FREQUENCY_ROLES", "N_PAIR", "try_effect", "Refits", "re_identify"]

#: A refit must lower J_ave by at least this fraction.
MIN_RELATIVE_COST_DROP = 0.10
#: An effect whose parameter is fixed must be clearly there: its whitened residual drop at least
#: this many times what its F-test needs. At most one parameter is fixed per effect.
CLEAR_EVIDENCE_FACTOR = 2.0
#: Parameters of an effect with several that may be fixed at their fitted value when poorly
#: determined: the shape parameters (a damping, a notch's depth or a mode's gain), never the
#: frequency that places the effect (a frequency that is not determined means the effect is not there).
FIXABLE_ROLES = ("damping", "shape")
#: An effect's only parameter may miss the accuracy guidelines and be fixed at its fitted value
#: when its Cramer-Rao bound is at most this [%] of its value: three bounds from zero, the
#: parameter is there, as the effect's F-test (at :data:`CLEAR_EVIDENCE_FACTOR`) says the
#: effect is; only its value is poorly determined, and the report says so.
ONLY_PARAMETER_CR_PCT = 100.0 / 3.0
#: Parameters that place an effect in frequency [rad/s]: fixing another of its parameters needs
#: this one inside the fitted band (a "notch" at 25 rad/s fitted to 0.3-20 rad/s data is a lag in
#: disguise, not a notch whose depth the data could not pin down).
FREQUENCY_ROLES = ("frequency",)


def _role(name: str) -> str | None:
    """The role an effect declares for its parameter ``name`` (None: not an effect's)."""
    role = parameter_role(name)
    return None if role is None else role.role


def _worst(params):
    """The free parameter to fix at its fitted value, or None.

    The shape parameter (:data:`FIXABLE_ROLES`) that misses the guidelines by most, relative to
    its limit, when only shape parameters miss them and another parameter stays free; or an
    effect's only parameter when its Cramer-Rao bound is within :data:`ONLY_PARAMETER_CR_PCT`
    (e.g. a 25 ms skew on a noisy accelerometer, the cost flat in it alone; a 30 ms skew on a
    hover attitude at CR 25 %). Nothing when a parameter that places the effect is poorly
    determined.
    """
    def excess(p):
        cr, ins = p["cramer_rao_pct"], p["insensitivity_pct"]
        return max(math.inf if cr is None else cr / MAX_CRAMER_RAO_PCT,
                   math.inf if ins is None else ins / MAX_INSENSITIVITY_PCT)
    free = [p for p in params if not p.get("fixed")]
    bad = [p for p in free if excess(p) > 1.0]
    if not bad:
        return None
    if len(free) > 1 and all(_role(p["name"]) in FIXABLE_ROLES for p in bad):
        return max(bad, key=excess)
    if len(free) == 1 and bad[0]["cramer_rao_pct"] is not None and bad[0]["cramer_rao_pct"] <= ONLY_PARAMETER_CR_PCT:
        return bad[0]
    return None


def try_effect(table, cand, fit, judge, ss_before, ver_before) -> tuple[Trial, ModelState | None]:
    """Re-identify with ``cand`` (a Candidate, or several added together) added and judge it.

    Several candidates are judged as one effect with all their parameters; the record's
    ``partners`` are the others (kind, where, their parameters). When the effect's shape is
    supported (the fit converges, the whitened residual and J_ave fall beyond noise, verification
    is not worse) but one of its parameters misses the accuracy guidelines (a sharp mode's
    damping, a notch's depth), the structure-reduction step of the method is taken inside the
    effect: that parameter (one, a shape parameter: a damping or a gain) is fixed at its fitted
    value and the rest refitted, when the effect is clearly there (:data:`CLEAR_EVIDENCE_FACTOR`)
    and another of its parameters stays free. The record says which were fixed (``fixed``: name,
    value and why) and the effect is accepted with them.

    Parameters
    ----------
    table : dict
        The current ``[state_space]`` table (values = ``fit``).
    cand : Candidate or sequence of Candidate
    fit : StateSpaceFit
        The current fit.
    judge : Judge
    ss_before : float
        The current whitened sum of squares.
    ver_before : Verification or list or None
        The current model's verification.

    Returns
    -------
    trial : Trial
        With its verdict (``accepted``, ``reason``).
    model : ModelState or None
        The refitted model, None when it could not be re-identified.
    """
    cands = tuple(cand) if isinstance(cand, (list, tuple)) else (cand,)
    head = dict(kind=cands[0].kind, where=cands[0].where, evidence=round(float(sum(c.evidence for c in cands)), 2),
                cost_before=float(fit.cost_average), ss_before=float(ss_before), candidates=cands)
    n_model = n_free(fit)
    try:
        aug, new, own, new_fit = _refit_with(table, cands, judge)
    except (ConfigError, np.linalg.LinAlgError, ValueError) as exc:
        return Trial(**head, accepted=False, reason=f"could not re-identify: {exc}", cost_after=float("nan"),
                     identified=False), None
    got = _judged(new_fit, new, fit, judge, ss_before, ver_before, n_model)
    by_name = {p["name"]: p for p in got.parameters}
    partners = None
    if len(cands) > 1:
        partners = tuple(EffectRecord(c.kind, c.where, tuple(by_name[n] for n in names))
                         for c, names in zip(cands[1:], own[1:]))
    reasons = got.shape + got.accuracy
    reason = "; ".join(reasons) if reasons else (
        "accepted" + "".join(f"; {f['name']} fixed at {f['value']:.4g} ({f['reason'].split(':')[0]})"
                             for f in got.fixed))
    trial = Trial(**head, accepted=not reasons, reason=reason, cost_after=float(got.fit.cost_average),
                  parameters=tuple(by_name[n] for n in own[0]), fixed=got.fixed,
                  evidence_after=round(ss_before - got.ss_after, 2),
                  verification_after=verification_summary(got.verification), verification_change=got.change,
                  significance=got.significance.to_dict(), partners=partners, shape_held=not got.shape)
    return trial, ModelState(table_with_fit(aug, got.fit), got.fit, got.verification, got.residuals)


def _refit_with(table, cands, judge):
    """The table with ``cands`` added, their new parameter names (all, and per candidate), and its
    refit; when the refit from the current values does not converge, the model's derivatives are
    started again where the case starts them (a second start), the better kept."""
    aug, new, own = table, [], []
    for c in cands:
        aug, names = augment_table(aug, c)
        new += names
        own.append(names)
    model = StateSpaceModel.from_table(aug)
    new_fit = refit_state_space(model, judge.pairs)
    if not new_fit.converged and judge.origin is not None:
        # the model's derivatives had bent to make up for the missing effect and the refit from
        # them is stuck: start them again where the case starts them (a second start)
        again = refit_state_space(StateSpaceModel.from_table(restart_from(aug, judge.origin)), judge.pairs)
        if again.converged or again.cost_average < new_fit.cost_average:
            new_fit = again
    return aug, new, own, new_fit


@dataclass(frozen=True)
class _Judged:
    """A refit judged: the fit (with a parameter fixed, if one was), its residuals, its tests and
    what failed."""

    fit: object
    residuals: tuple
    ss_after: float
    significance: object
    parameters: list
    verification: object
    change: dict | None
    shape: list
    accuracy: list
    fixed: tuple


def _judged(new_fit, new, fit, judge, ss_before, ver_before, n_model) -> _Judged:
    """Judge the refit ``new_fit`` of ``fit`` with the parameters ``new`` added; when only the
    accuracy of one parameter fails and the effect is clearly there, fix that parameter at its
    fitted value, refit and judge again (once)."""
    pairs, frs, verify = judge.pairs, judge.frs, judge.verify
    fixed = []
    while True:
        res_after = tuple(pair_residuals(new_fit.model, new_fit.theta, pairs, frs))
        ss_after = whitened_ss(res_after)
        sig = judge.test(ss_before, ss_after, len(new), n_model)
        params = parameter_report(new_fit, new)
        ver_after = verify(new_fit.model, new_fit.theta) if verify else None
        change = verification_change(ver_before, ver_after, judge.alpha)
        shape = _shape_failures(new_fit, fit, sig, ss_before, ss_after, change)
        accuracy = guideline_failures(params)
        worst = _worst(params)
        lo, hi = band_of(pairs)
        outside = any(_role(p["name"]) in FREQUENCY_ROLES and not lo <= p["value"] <= hi for p in params)
        if (shape or not accuracy or worst is None or fixed or outside
                or ss_before - ss_after < CLEAR_EVIDENCE_FACTOR * sig.needed):
            break
        # the shape is there; one parameter is poorly determined: fix it where it is, refit the rest
        try:
            refit = refit_state_space(new_fit.model.with_values(new_fit.theta, fixed={worst["name"]: worst["value"]}), pairs)
        except (ConfigError, np.linalg.LinAlgError, ValueError):
            break
        why = (f"CR% {pct_text(worst['cramer_rao_pct'])}, I% {pct_text(worst['insensitivity_pct'])}: poorly determined, "
               f"fixed at its fitted value")
        fixed.append({"name": worst["name"], "value": float(worst["value"]),
                      "cramer_rao_pct": worst["cramer_rao_pct"], "insensitivity_pct": worst["insensitivity_pct"],
                      "reason": why})
        new_fit = refit
    return _Judged(new_fit, res_after, ss_after, sig, params, ver_after, change, shape, accuracy, tuple(fixed))


def _shape_failures(new_fit, fit, sig, ss_before, ss_after, change) -> list[str]:
    """Why the refit does not support the effect's shape, whatever its parameters' accuracy: no
    convergence, a whitened residual drop below its F-test, a J_ave drop below
    :data:`MIN_RELATIVE_COST_DROP`, verification worse beyond noise."""
    shape = []
    if not new_fit.converged:
        shape.append("fit did not converge")
    if not sig.significant:
        shape.append(f"whitened residual fell by {ss_before - ss_after:.1f} < {sig.needed:.1f} needed for "
                     f"{sig.k} parameter(s) (F = {sig.statistic:.1f}, p = {sig.p_value:.2g} >= {sig.level:.2g})")
    if new_fit.cost_average > (1 - MIN_RELATIVE_COST_DROP) * fit.cost_average:
        shape.append(f"J_ave {fit.cost_average:.2f} -> {new_fit.cost_average:.2f} "
                     f"(< {100 * MIN_RELATIVE_COST_DROP:.0f} % drop)")
    if change is not None and change["verdict"] == "worse":
        if change["mean_change"] is None:
            shape.append(f"verification: the model diverges open loop (J_rms {change['j_rms_before']} -> not finite)")
        else:
            shape.append(f"verification J_rms {change['j_rms_before']:.4g} -> {change['j_rms_after']:.4g}: worse "
                         f"beyond noise (mean squared-error change {change['mean_change']:.3g} > {change['z']:.2f} x "
                         f"{change['noise']:.3g})")
    return shape


#: Candidates (best evidence first, distinct kind and place) combined in pairs when the best one
#: fails alone.
N_PAIR = 4


@dataclass(frozen=True)
class Refits:
    """One step's re-identifications.

    Attributes
    ----------
    tried : tuple of Trial
        Every one, in the order run; a pair refused because a partner is not needed says so.
    accepted : tuple of (Trial, ModelState)
        The single effects accepted, in the order run.
    pairs : tuple of (Trial, ModelState or None)
        The pairs tried.
    n_fits : int
        Re-identifications run.
    """

    tried: tuple
    accepted: tuple
    pairs: tuple
    n_fits: int


class _Singles:
    """The step's single-effect refits, each kind and place run once, in the order asked."""

    def __init__(self, screen, current, progress):
        self.screen, self.current, self.progress = screen, current, progress
        self.tried, self.accepted, self.done = [], [], {}

    def run(self, c) -> tuple:
        """Re-identify with ``c`` alone (once per kind and place); its (trial, model)."""
        if (c.kind, c.where) not in self.done:
            if self.progress:
                self.progress(f"residual loop: re-identifying with {c.kind} at {c.where} (evidence {c.evidence:.0f})")
            trial, new = self.done[(c.kind, c.where)] = try_effect(
                self.current.table, c, self.current.fit, self.screen.judge, self.screen.ss_before,
                self.current.verification)
            self.tried.append(trial)
            if trial.accepted:
                self.accepted.append((trial, new))
        return self.done[(c.kind, c.where)]


def re_identify(screen, current, *, n_refit: int, pairs_allowed: bool, progress=None) -> Refits:
    """Re-identify the model ``current`` with the candidates of ``screen``, each judged alone.

    The ``n_refit`` strongest, and the best at each of the first ``n_refit`` places (one place's
    rival kinds must not take every refit from the next place's best). When the fit is inadequate
    and no accepted refit explains the residual, every missing derivative, then every control-path
    effect. The simpler kinds at an accepted effect's place (simplest first needs them refitted,
    whatever their screen said). When the best explanation fails alone and ``pairs_allowed``, the
    strongest candidates in pairs (:func:`_pair_search`), a pair kept only if each partner is
    significant on top of the other alone (:func:`~livesweep.ident.residual_choice.pair_refusal`).
    """
    singles = _Singles(screen, current, progress)
    for c in screen.strong:
        if len(singles.done) >= n_refit:
            break
        singles.run(c)
    for c in _best_per_place(screen.strong, n_refit):
        # one place's rival kinds (a delay, a lag and a second-order actuator on one
        # input) must not take every refit from the next place's best (a skew on an output)
        singles.run(c)
    if screen.inadequate and not _explained(singles.tried):
        # a derivative the fit compensated elsewhere screens far below what its refit
        # (restarted from the case's values) explains: each is re-identified once
        for c in screen.ranked:
            if c.kind == "missing_derivative":
                singles.run(c)
    if screen.inadequate and not _explained(singles.tried):
        # so does a control-path effect (a 6 rad/s second-order actuator on a yaw axis the
        # fit bent its derivatives to: screened as 0.2 rad/s notches and 10 s lags)
        for c in screen.ranked:
            if EFFECT_KINDS[c.kind].acts_on == "input":
                singles.run(c)
    for trial, _ in list(singles.accepted):
        # simplest first needs the simpler kinds at an accepted effect's place refitted too,
        # whatever their screen said (a delay screened below its test beside an accepted
        # second-order actuator on the same input)
        if not trial.partners:
            for c in screen.ranked:
                if c.where == trial.where and c.kind != trial.kind and c.n_parameters < len(trial.parameters):
                    singles.run(c)
    leader = max(singles.tried, key=_evidence_after, default=None)
    duo = []
    if leader is not None and not leader.accepted and pairs_allowed:
        # the best explanation fails alone: two effects may overlap (a mode and an actuator
        # lag); try the strongest candidates in pairs at different places, each pair judged
        # as one effect. The partners come from the whole ranking: while one effect
        # dominates the residual, another is not significant on its own at screening. A pair
        # is kept only if each partner lowers S significantly on top of the other alone
        # (the partners not yet refitted alone are refitted).
        duo = _pair_search(screen.ranked, current, screen.judge, screen.ss_before, progress)
        first = len(singles.tried)
        singles.tried += [trial for trial, _ in duo]
        for k, (trial, new) in enumerate(duo):
            if trial.accepted:
                alone = [singles.run(m)[0].evidence_after for m in trial.candidates]
                refusal = pair_refusal(trial, alone, screen.judge, screen.n_model)
                if refusal is not None:
                    duo[k] = (replace(trial, accepted=False, reason=refusal), new)
                    singles.tried[first + k] = duo[k][0]
    return Refits(tuple(singles.tried), tuple(singles.accepted), tuple(duo), len(singles.done) + len(duo))


def _evidence_after(trial) -> float:
    """The drop of the whitened sum of squares a refit gave (-inf when it could not be run)."""
    return -np.inf if trial.evidence_after is None else trial.evidence_after


def _best_per_place(ranked, n_places):
    """The best-ranked candidate at each of the first ``n_places`` places of ``ranked``."""
    out, seen = [], set()
    for c in ranked:
        if c.where not in seen:
            seen.add(c.where)
            out.append(c)
            if len(out) == n_places:
                break
    return out


def _pair_search(strong, current, judge, ss_before, progress) -> list:
    """Re-identify the pairs of the :data:`N_PAIR` most significant distinct candidates (``strong``: the
    ranking, most significant first) at different places; their (trial, model)."""
    top, seen = [], set()
    for c in strong:
        if (c.kind, c.where) not in seen and len(top) < N_PAIR:
            seen.add((c.kind, c.where))
            top.append(c)
    out = []
    for i, a in enumerate(top):
        for b in top[i + 1:]:
            if a.where == b.where:
                continue
            if progress:
                progress(f"residual loop: re-identifying with {a.kind} at {a.where} and {b.kind} at {b.where}")
            out.append(try_effect(current.table, [a, b], current.fit, judge, ss_before, current.verification))
    return out
