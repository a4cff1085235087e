"""The residual loop's last stage: decide which re-identified effect, if any, to add.

Among the accepted refits the one that explains most is taken, unless a simpler one explains
nearly as much (the richer one's extra parameters not significant: CIFER practice prefers the
simplest structure the data support); a pair of effects must beat the best single one the same
way. An accepted effect that explains less than half of what the best refit does (accepted or
not) is a partial explanation and is refused. The chosen effect's rivals, explanations the data
cannot tell from it, are named beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from livesweep.ident.selection import indistinguishable, prefers, significance

__all__ = ["PARTIAL", "choose", "rivals", "pair_refusal", "Decision", "decide"]

#: An accepted effect that explains less than this fraction of the whitened residual drop the
#: best-explaining refit gives (accepted or not) is a partial explanation, not the effect.
PARTIAL = 0.5


def _size(trial) -> int:
    """Parameters an effect (a Trial, a pair's partners included) adds, fixed ones included."""
    return len(trial.parameters) + sum(len(w.parameters) for w in trial.partners or ())


def _explained(tried) -> bool:
    """Whether some accepted refit in ``tried`` explains the residual, not just part of it
    (:data:`PARTIAL`)."""
    top = _top_evidence(tried)
    return any(t.accepted and t.evidence_after >= PARTIAL * top for t in tried)


def _top_evidence(tried) -> float:
    """The largest drop of the whitened residual a refit in ``tried`` gave, accepted or not."""
    return max((-np.inf if t.evidence_after is None else t.evidence_after for t in tried), default=-np.inf)


def choose(accepted, judge, n_model):
    """The effect to add among the accepted ``(trial, model)``: the one that explains most,
    unless a simpler one (fewer new parameters, fixed ones included) explains nearly as much,
    i.e. the richer one's extra parameters are not significant (:func:`~livesweep.ident.selection.prefers`):
    then the simpler one, as CIFER practice prefers the simplest structure the data support (a
    delay before a second-order actuator, a first-order before a second-order one). Candidates
    that explain the data as well as the chosen one are listed by :func:`rivals`.

    Returns
    -------
    tuple or None
        ``(chosen (trial, model), note)``: ``note`` is what the chosen trial's reason gains when
        it was preferred to one that explains more ("" otherwise); None when nothing was accepted.
    """
    if not accepted:
        return None
    ss0 = accepted[0][0].ss_before
    ss = {id(a): ss0 - a[0].evidence_after for a in accepted}
    order = sorted(accepted, key=lambda a: (_size(a[0]), ss[id(a)]))
    chosen = order[0]
    for a in order[1:]:
        if prefers(ss[id(chosen)], _size(chosen[0]), ss[id(a)], _size(a[0]), judge.n_points, n_model, judge.alpha):
            chosen = a
    best = min(accepted, key=lambda a: ss[id(a)])
    note = ""
    if chosen is not best:
        note = (f"; preferred to {best[0].kind} at {best[0].where} (whitened residual lower by only "
                f"{ss[id(chosen)] - ss[id(best)]:.0f}, not significant for its "
                f"{_size(best[0]) - _size(chosen[0])} more parameter(s))")
    return chosen, note


def rivals(chosen, tried, judge, n_model) -> list[dict]:
    """The single effects re-identified alone that the chosen single effect cannot be told from
    (none for a pair).

    Rival explanations of the same feature (the same place, or the same kind elsewhere: a scale
    factor on phi or on p) whose shape held (converged, significant, not worse in verification;
    accepted or failing only the accuracy guidelines, e.g. a lag whose corner lies above the band,
    where it is a delay) and whose whitened sum of squares differs from the chosen one's by less
    than one parameter's F-test needs (:func:`~livesweep.ident.selection.indistinguishable`). A
    rival with no more parameters than the chosen one is held to the loop's screening level (the
    candidates screened counted: the data prefer one to the other no more than they would prefer
    an effect to nothing); a richer one is a rival when it was accepted and its extra parameters
    are not significant (:func:`~livesweep.ident.selection.prefers`, the test by which
    :func:`choose` took the simpler one: a notch that explains a little more than a lag), never
    when it was not accepted (a second-order actuator whose damping the data cannot pin down is
    the chosen lag with a useless parameter, not an alternative).

    Parameters
    ----------
    chosen : Trial
        One of ``tried``.
    tried : sequence of Trial
    judge : Judge
    n_model : int
        Free parameters of the model before the step.

    Returns
    -------
    list of dict
        kind, where, evidence_after, cost_after, parameters, accepted of each rival.
    """
    if chosen.partners:
        return []
    out, seen, k = [], {(chosen.kind, chosen.where)}, _size(chosen)
    for t in tried:
        if (t is chosen or not t.shape_held or t.partners or (t.kind, t.where) in seen
                or (t.kind != chosen.kind and t.where != chosen.where)):
            continue
        ss_t, ss_chosen = t.ss_before - t.evidence_after, chosen.ss_before - chosen.evidence_after
        if len(t.parameters) > k:
            # a richer rival: the chosen shape with parameters the data cannot pin down (not
            # accepted) is no alternative; an accepted one is when its extra parameters are not
            # significant, the very reason choose took the simpler
            tie = t.accepted and not prefers(ss_chosen, k, ss_t, len(t.parameters), judge.n_points, n_model,
                                             judge.alpha)
        else:
            tie = indistinguishable(ss_t, ss_chosen, judge.n_points, n_model, k, judge.alpha, judge.n_tests)
        if tie:
            seen.add((t.kind, t.where))
            out.append({"kind": t.kind, "where": t.where, "evidence_after": t.evidence_after,
                        "cost_after": t.cost_after, "parameters": list(t.parameters), "accepted": t.accepted})
    return out


def pair_refusal(pair, alone, judge, n_model) -> str | None:
    """Why an accepted pair is not two effects, or None when it is.

    Each partner must lower the whitened sum of squares significantly on top of the other
    partner alone: an F-test at ``false_alarm`` with the partner's parameters counted, the other
    nested in the pair. A pair one of whose partners only patches what the other leaves (a
    spurious notch next to the real actuator) is not two effects.

    Parameters
    ----------
    pair : Trial
        The pair's record.
    alone : sequence of float or None
        ``evidence_after`` of each partner refitted alone, in the pair's order (None: that refit
        could not be run, so there is nothing to nest in).
    judge : Judge
    n_model : int
    """
    ss_pair = pair.ss_before - pair.evidence_after
    sizes = [len(pair.parameters)] + [len(w.parameters) for w in pair.partners or ()]
    labels = [f"{pair.kind} at {pair.where}"] + [f"{w.kind} at {w.where}" for w in pair.partners or ()]
    for i, (k, label) in enumerate(zip(sizes, labels)):
        other = alone[1 - i]
        ss_other = pair.ss_before - (other if other is not None else -math.inf)
        sig = significance(ss_other, ss_pair, k, judge.n_points, n_model + sizes[1 - i], 1, judge.alpha)
        if not sig.significant:
            return (f"{label} adds {max(ss_other - ss_pair, 0.0):.0f} to {labels[1 - i]} alone, "
                    f"< {sig.needed:.0f} needed for its {k} parameter(s): not a second effect")
    return None


@dataclass(frozen=True)
class Decision:
    """One step's decision.

    Attributes
    ----------
    tried : tuple of Trial
        Every re-identification with its final verdict.
    chosen : (Trial, ModelState) or None
        The effect to add (its record naming its rivals) and the refitted model, or None.
    """

    tried: tuple
    chosen: tuple | None


def _revise(tried: list, old, new) -> None:
    """Put the record ``new`` in the place of ``old`` in ``tried``."""
    tried[next(k for k, t in enumerate(tried) if t is old)] = new


def _pick(accepted, tried, judge, n_model):
    """:func:`choose` among ``accepted``, the chosen record's reason extended in ``tried``."""
    got = choose(accepted, judge, n_model)
    if got is None:
        return None
    (trial, model), note = got
    if note:
        revised = replace(trial, reason=trial.reason + note)
        _revise(tried, trial, revised)
        trial = revised
    return trial, model


def decide(refits, screen) -> Decision:
    """Choose the effect to add among ``refits`` (:class:`~livesweep.ident.residual_trial.Refits`)
    of the step ``screen``: the best single effect (:func:`choose`), unless an accepted pair is
    preferred to it; refused when it explains less than :data:`PARTIAL` of the best refit; its
    :func:`rivals` recorded."""
    judge, n_model, ss_before = screen.judge, screen.n_model, screen.ss_before
    tried = list(refits.tried)
    best = _pick(list(refits.accepted), tried, judge, n_model)
    if refits.pairs:
        pick = _pick([a for a in refits.pairs if a[0].accepted], tried, judge, n_model)
        if pick is not None and (best is None or prefers(
                ss_before - best[0].evidence_after, _size(best[0]),
                ss_before - pick[0].evidence_after, _size(pick[0]), judge.n_points, n_model, judge.alpha)):
            best = pick
    # An accepted candidate that explains less than half of what the best-explaining one
    # does (even if that one failed a guideline) is a partial explanation, not the effect.
    top = _top_evidence(tried)
    if best is not None and best[0].evidence_after < PARTIAL * top:
        _revise(tried, best[0], replace(best[0], accepted=False, reason=(
            f"explains {best[0].evidence_after:.0f}, less than half of the best candidate's {top:.0f}: a partial "
            "explanation")))
        return Decision(tuple(tried), None)
    if best is None:
        return Decision(tuple(tried), None)
    trial, model = best
    chosen = replace(trial, ambiguous_with=tuple(rivals(trial, tried, judge, n_model)))
    _revise(tried, trial, chosen)
    return Decision(tuple(tried), (chosen, model))
