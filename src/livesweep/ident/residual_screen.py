"""The residual loop's first stages: find the model's residual and rank what could explain it.

The residual of every pair (data minus model at the fitting points) is whitened by the data's
random error (:class:`~livesweep.ident.residual_space.ResidualSpace`) and every effect of the
catalogue screens itself against it (:meth:`~livesweep.effects.Effect.candidates`): its evidence
is the drop of the whitened sum of squares its best parameters give after the model's own
parameters re-adjust. The candidates are ranked by the margin of their F-test; those that pass go
to re-identification first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from livesweep.effects import EFFECT_KINDS, Candidate
from livesweep.ident.accuracy import MAX_COST_AVERAGE
from livesweep.ident.residual_judge import Judge, n_free
from livesweep.ident.residual_space import ResidualSpace, whitened_ss
from livesweep.ident.residual_tables import KINDS
from livesweep.ident.selection import NOISE_INFLATION
from livesweep.ident.state_space import StateSpaceFit

__all__ = ["UNDETECTABLE_PCT", "diagnose", "Screen", "screen_residual"]

#: A fixed-shape effect (a scale factor) whose smallest detectable size exceeds this [%] is
#: reported as not identifiable in the band.
UNDETECTABLE_PCT = 10.0


def diagnose(table: dict, fit: StateSpaceFit, pairs, frs, *, kinds=KINDS, residuals=None) -> list[Candidate]:
    """Rank the catalogue's effects by how much of the residual each explains (module docstring).

    Parameters
    ----------
    table : dict
        The ``[state_space]`` table the fit's model was built from
        (:func:`~livesweep.ident.residual.table_with_fit`).
    fit : StateSpaceFit
    pairs : list of PairData
    frs : FrequencyResponseSet
    kinds : sequence of str
        Which kinds to consider.
    residuals : list of PairResidual, optional
        :func:`~livesweep.ident.residual_space.pair_residuals` of the fit when the caller has them
        already.

    Returns
    -------
    list of Candidate
        Largest evidence first; one per kind and place (its best grid point).
    """
    sp = ResidualSpace(fit.model, fit.theta, pairs, frs, residuals)
    out: list[Candidate] = []
    for kind in kinds:
        out += EFFECT_KINDS[kind].candidates(sp, table)
    out.sort(key=lambda c: -c.evidence)
    return out


def _limits(cands, needed):
    """Fixed-shape candidates the data could not show below :data:`UNDETECTABLE_PCT`: kind, where,
    the smallest detectable size [%] (a scale error ``exp(sqrt(needed / sensitivity)) - 1``)."""
    out = []
    for c in cands:
        if c.sensitivity is None:
            continue
        a = math.sqrt(needed / c.sensitivity) if c.sensitivity > 0 else math.inf
        pct = 100.0 * (math.exp(min(a, 50.0)) - 1.0)
        if pct > UNDETECTABLE_PCT:
            out.append({"kind": c.kind, "where": c.where, "smallest_detectable_pct": round(pct, 1)})
    return out


@dataclass(frozen=True)
class Screen:
    """What one step's screen found.

    Attributes
    ----------
    ss_before : float
        The whitened sum of squares of the current model's residual.
    candidates : tuple of Candidate
        Every candidate, largest evidence first (:func:`diagnose`).
    ranked : tuple of Candidate
        The same, largest margin of their F-test first.
    strong : tuple of Candidate
        Those to re-identify first: the significant ones, or every ranked one when the fit is
        inadequate.
    inadequate : bool
        The fit fails the J_ave guideline, or its whitened residual's mean square exceeds
        :data:`~livesweep.ident.selection.NOISE_INFLATION`: the linear screen underrates what a
        refit explains.
    any_significant : bool
        Some candidate passed its F-test, or the fit is inadequate.
    limits : tuple of dict
        Scale errors the data cannot show (kind, where, smallest_detectable_pct).
    n_model : int
        Free parameters of the current model.
    judge : Judge
        The loop's criterion with this step's number of candidates screened.
    """

    ss_before: float
    candidates: tuple
    ranked: tuple
    strong: tuple
    inadequate: bool
    any_significant: bool
    limits: tuple
    n_model: int
    judge: Judge


def screen_residual(current, judge: Judge, kinds) -> Screen:
    """Find the residual of ``current`` (a :class:`~livesweep.ident.residual_records.ModelState`)
    and rank the candidates of ``kinds`` that could explain it."""
    ss_before = whitened_ss(current.residuals)
    cands = diagnose(current.table, current.fit, judge.pairs, judge.frs, kinds=kinds, residuals=current.residuals)
    judge = replace(judge, n_tests=max(len(cands), 1))
    n_model = n_free(current.fit)
    scored = [(judge.test(ss_before, ss_before - c.evidence, c.n_parameters, n_model), c) for c in cands]
    scored.sort(key=lambda x: -x[0].margin)
    ranked = [c for _, c in scored]
    strong = [c for sig, c in scored if sig.significant]
    # The screen is linear about the current fit. When that fit fails the method's own J_ave
    # guideline, or its whitened residual's mean square exceeds NOISE_INFLATION (the factor by
    # which clean logs' structured residual exceeds noise), the model is far from the data and
    # the screen underrates what a refit explains (the derivatives re-adjust once the effect is
    # in): the best-ranked are refitted anyway, then every missing derivative, and each refit's
    # own test decides.
    n_values = sum(2 * r.omega.size for r in current.residuals)
    inadequate = current.fit.cost_average > MAX_COST_AVERAGE or ss_before > NOISE_INFLATION * n_values
    any_significant = bool(strong) or inadequate
    if not strong and inadequate:
        strong = ranked
    limits = _limits(cands, judge.test(ss_before, ss_before, 1, n_model).needed)
    return Screen(ss_before, tuple(cands), tuple(ranked), tuple(strong), inadequate, any_significant, tuple(limits),
                  n_model, judge)
