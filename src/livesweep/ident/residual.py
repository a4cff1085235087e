"""Close the loop: find the model's residual, trace it to the effect the model lacks, add it.

After a state-space fit, the frequency-domain residual of every pair (data minus model, dB and
deg at the fitting points) is whitened by the data's random error and matched against the
effect catalogue (:mod:`livesweep.effects`: delays, actuators, notch filters, structural modes,
sensor skews and scale factors, missing derivatives). Each kind screens itself
(:meth:`~livesweep.effects.Effect.candidates`): its evidence is the drop of the whitened sum of
squares its best parameters give after the model's own parameters re-adjust
(:class:`~livesweep.ident.residual_space.ResidualSpace`).

Model selection (:mod:`livesweep.ident.selection`). A candidate counts when an F-test on the
whitened sums of squares, with the effective number of independent frequency points (from the
windows' resolution bandwidth) and the candidate's parameters counted, rejects "nothing" at
``false_alarm / m`` for ``m`` candidates screened. The strongest (smallest p-value first) are added
to the case's ``[state_space]`` table (:func:`augment_table`: new states, parameters, delays, as a
user would write them) and re-identified. One is kept when its refit passes the same test, J_ave
drops by :data:`MIN_RELATIVE_COST_DROP`, the verification error (when a callback is given) is not
worse beyond noise (at the one-sided normal quantile of ``false_alarm``), and its new parameters
meet the accuracy guidelines (CR% <= 20, I% <= 10). A clearly present effect with one poorly
determined shape parameter (a sharp mode's damping, a notch's depth), or whose only parameter is at
least three Cramer-Rao bounds from zero, is kept with that parameter fixed at its fitted value
(structure reduction inside the effect). Rivals that both pass go to the simpler one unless the
richer one's extra parameters are significant; rival explanations of the same feature that the data
prefer no more than they would prefer an effect to nothing are reported as hard to tell apart
(:func:`~livesweep.ident.residual_choice.rivals`). When the best candidate fails alone, the strongest are tried in pairs, and a
pair is kept only if each partner is significant on top of the other alone; after each step, an
effect added earlier that is no longer significant with the later ones in is taken out
(:func:`~livesweep.ident.residual_backward.backward_step`). When the fit is inadequate (J_ave above the guideline, or a whitened mean
square above ``NOISE_INFLATION``) the screen underrates what refits explain: the best-ranked are
refitted whatever their screening test and, if none explains the residual (:func:`~livesweep.ident.residual_choice._explained`),
every missing derivative and every control-path effect once. A coherent pair the model has no path
for (no residual in dB to screen) is first given one (:mod:`livesweep.ident.coupling`). The loop
repeats until nothing significant remains or ``max_steps``.

Each step runs in stages, each in a module with one job: find the residual and rank the
candidates (:mod:`~livesweep.ident.residual_screen`), add them and re-identify
(:mod:`~livesweep.ident.residual_trial`), decide (:mod:`~livesweep.ident.residual_choice`), then
re-test the effects added before (:mod:`~livesweep.ident.residual_backward`). What each step
found, tried and decided is recorded in frozen records (:mod:`~livesweep.ident.residual_records`)
that serialise to report.json.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from livesweep.effects import Candidate
from livesweep.errors import ConfigError
from livesweep.ident import residual_dicts as _dicts
from livesweep.ident.cost import MIN_COHERENCE
from livesweep.ident.coupling import find_coupling, no_path_pairs
from livesweep.ident.residual_backward import HistoryEntry, backward_step, rechoose
from livesweep.ident.residual_choice import PARTIAL, decide
from livesweep.ident.residual_judge import VERIFICATION_BLOCK_S, Judge, verification_change, verification_summary
from livesweep.ident.residual_records import (CouplingTrial, EffectRecord, LoopStep, ModelState, Replacement,
                                              ResidualLoop, Trial, added_effects)
from livesweep.ident.residual_screen import UNDETECTABLE_PCT, diagnose, screen_residual
from livesweep.ident.residual_space import PairResidual, pair_residuals, whitened_ss
from livesweep.ident.residual_tables import KINDS, augment_table, table_with_fit
from livesweep.ident.residual_text import conclusion_text, effect_text, model_effects
from livesweep.ident.residual_trial import (CLEAR_EVIDENCE_FACTOR, FIXABLE_ROLES, FREQUENCY_ROLES,
                                            MIN_RELATIVE_COST_DROP, N_PAIR, ONLY_PARAMETER_CR_PCT, re_identify)
from livesweep.ident.selection import FALSE_ALARM, NOISE_INFLATION, effective_points
from livesweep.ident.state_space import StateSpaceFit, fit_state_space, select_pairs

__all__ = ["KINDS", "FALSE_ALARM", "MIN_RELATIVE_COST_DROP", "FIXABLE_ROLES", "FREQUENCY_ROLES",
           "CLEAR_EVIDENCE_FACTOR", "ONLY_PARAMETER_CR_PCT", "PARTIAL", "PairResidual", "Candidate", "LoopStep",
           "ResidualLoop", "EffectRecord", "Replacement", "Trial", "CouplingTrial", "pair_residuals", "diagnose",
           "augment_table", "run_residual_loop", "table_with_fit", "effect_text", "model_effects",
           "N_OMEGA_LOOP", "N_PAIR", "UNDETECTABLE_PCT", "VERIFICATION_BLOCK_S"]

#: Fitting points per pair inside the loop (the state-space stage fits 20).
N_OMEGA_LOOP = 100

# The loop's criterion and its decision rules under their private names; the last four take the
# records in their dict form (report.json's), for callers that hold them as plain dicts.
_Judge = Judge
_verification_change = verification_change
_choose, _rivals, _partners_needed, _backward = _dicts.choose, _dicts.rivals, _dicts.partners_needed, _dicts.backward


def run_residual_loop(table: dict, fit: StateSpaceFit, frs, *, verify=None, max_steps: int = 3,
                      n_refit: int = 3, false_alarm: float = FALSE_ALARM, n_omega: int = N_OMEGA_LOOP,
                      kinds=KINDS, progress=None, min_coherence: float = MIN_COHERENCE) -> ResidualLoop:
    """Diagnose, augment, re-identify, repeat (see the module docstring).

    Parameters
    ----------
    table : dict
        ``[state_space]`` table of the fitted model.
    fit : StateSpaceFit
        The identified model (after structure reduction, if any).
    frs : FrequencyResponseSet
        The responses it was fitted to. The loop re-selects the same pairs at ``n_omega`` points
        (not the criterion's 20: a mode with zeta = 0.05 is 10 % of its frequency wide, 20 points
        over two decades are 26 % apart) and refits the model there once as its baseline.
    verify : callable, optional
        ``verify(model, theta) -> Verification`` (or a list, one per record) on dissimilar
        manoeuvres (:func:`livesweep.ident.verify.verify`).
        A change is refused when it makes the verification error worse beyond noise (the mean
        change of the squared error, against its scatter over 2 s blocks); without a callback only
        the frequency-domain tests decide.
    max_steps : int
        Effects added at most.
    n_refit : int
        Candidates re-identified in full per step (most significant first).
    false_alarm : float
        Family-wise probability per step of adding an effect to a log without one
        (:data:`~livesweep.ident.selection.FALSE_ALARM`).
    n_omega : int
        Fitting points per pair inside the loop.
    kinds : sequence of str
        Catalogue entries to consider (default all of :data:`KINDS`).
    progress : callable, optional
        ``progress(str)`` for long steps.
    min_coherence : float
        The fit bands' coherence threshold (the case's criteria), as the state-space stage used.
    """
    if not (0.0 < float(false_alarm) < 1.0):
        raise ConfigError(f"residual loop: false_alarm = {false_alarm!r} must be between 0 and 1")
    pairs, skipped = select_pairs(frs, fit.model, n_omega=n_omega, min_coherence=min_coherence)
    if not pairs:
        raise ConfigError("residual loop: no pair of the model has usable coherence")
    fit = fit_state_space(fit.model.with_values(fit.theta), pairs)
    origin, table = table, table_with_fit(table, fit)
    steps, n_fits, ver = [], 1, None
    if max_steps > 0 and no_path_pairs(skipped):
        # coherent pairs the model has no path for: no residual in dB, so no screen sees them
        paths = _give_paths(table, origin, fit, frs, skipped, pairs, verify, n_omega, progress, min_coherence)
        n_fits += paths.n_fits
        if paths.step is not None:
            steps.append(paths.step)
            pairs, fit, origin, table, ver = paths.pairs, paths.fit, paths.origin, paths.table, paths.verification
    judge = Judge(pairs, frs, verify, effective_points(pairs, getattr(frs, "settings", {})), float(false_alarm),
                  origin=origin)
    if ver is None and verify:
        ver = verify(fit.model, fit.theta)
    current = ModelState(table, fit, ver, _fitted_residuals(fit, pairs, frs))
    unexplained, history, any_significant, limits = [], [], False, []
    for _ in range(max_steps + 1):
        screen = screen_residual(current, judge, kinds)
        any_significant, limits = screen.any_significant, list(screen.limits)
        decision = None
        if len(steps) < max_steps:
            refits = re_identify(screen, current, n_refit=n_refit, pairs_allowed=len(steps) + 2 <= max_steps,
                                 progress=progress)
            n_fits += refits.n_fits
            decision = decide(refits, screen)
        if decision is None or decision.chosen is None:
            tried = () if decision is None else decision.tried
            summary = verification_summary(current.verification)
            steps.append(LoopStep(screen.candidates, tried, None, current.fit.cost_average, current.fit.cost_average,
                                  summary, summary, current.residuals, current.residuals))
            unexplained += [{"kind": t.kind, "where": t.where, "reason": t.reason} for t in tried]
            break
        added = _add_effect(decision, screen, current, history, steps, verify, progress)
        n_fits += added.n_fits
        steps.append(added.step)
        current, history = added.current, added.history
    return _finish(steps, current, unexplained, limits, any_significant, judge, n_fits)


def _fitted_residuals(fit, pairs, frs) -> tuple:
    """The fit's residual on every pair; ConfigError when the model's response is zero or not
    finite somewhere (no residual in dB)."""
    before = tuple(pair_residuals(fit.model, fit.theta, pairs, frs))
    for r in before:
        if not (np.all(np.isfinite(r.magnitude_db)) and np.all(np.isfinite(r.phase_deg))):
            raise ConfigError(f"residual loop: the fitted model's response {r.output}/{r.input} is zero or not finite "
                              f"at some fitting points; the loop cannot compare it with the data in dB")
    return before


@dataclass(frozen=True)
class _Paths:
    """The coupling step: its record, and the pairs, fit, tables and verification it leaves
    (``step`` None: no entry gave the pairs a path)."""

    n_fits: int
    step: LoopStep | None = None
    pairs: list | None = None
    fit: StateSpaceFit | None = None
    origin: dict | None = None
    table: dict | None = None
    verification: object = None


def _give_paths(table, origin, fit, frs, skipped, pairs, verify, n_omega, progress, min_coherence) -> _Paths:
    """Give the coherent pairs the model has no path for one
    (:func:`~livesweep.ident.coupling.find_coupling`), as the loop's first step."""
    coupling = find_coupling(table, origin, fit, frs, skipped, n_omega=n_omega, progress=progress,
                             min_coherence=min_coherence)
    if coupling is None:
        return _Paths(1)
    old_pairs, before = pairs, tuple(pair_residuals(fit.model, fit.theta, pairs, frs))
    pairs, _ = select_pairs(frs, coupling.fit.model, n_omega=n_omega, min_coherence=min_coherence)
    cost_before, ver_before = fit.cost_average, verify(fit.model, fit.theta) if verify else None
    fit, origin = coupling.fit, coupling.table
    effect = EffectRecord("missing_derivative", coupling.where, (coupling.parameter,),
                    gives_a_path_for=tuple(f"{o}/{i}" for o, i in coupling.pairs),
                    ambiguous_with=tuple({"kind": "missing_derivative", "where": w} for w in coupling.rivals))
    tried = tuple(CouplingTrial("missing_derivative", t["where"], t["cost_after"], t["where"] == coupling.where,
                                ("kept: the lowest J_ave within the guidelines" if t["where"] == coupling.where
                                 else f"within the guidelines, but J_ave above {coupling.where}'s"
                                 if t["reason"] == "acceptable" else t["reason"]),
                                (t["parameter"],) if "parameter" in t else ())
                  for t in coupling.tried)
    ver = verify(fit.model, fit.theta) if verify else None
    # residuals on the pairs the model had before (the new ones had none to compare)
    step = LoopStep((), tried, effect, cost_before, fit.cost_average, verification_summary(ver_before),
                    verification_summary(ver), before, tuple(pair_residuals(fit.model, fit.theta, old_pairs, frs)))
    return _Paths(len(coupling.tried), step, pairs, fit, origin, table_with_fit(origin, fit), ver)


@dataclass(frozen=True)
class _Added:
    """A step that added an effect: its record, the model it leaves, the effects added so far."""

    step: LoopStep
    current: ModelState
    history: list
    n_fits: int


def _add_effect(decision, screen, current, history, steps, verify, progress) -> _Added:
    """Add the chosen effect of ``decision``, then re-test the effects added before it: take out
    one no longer significant (:func:`~livesweep.ident.residual_backward.backward_step`) or, if
    none, put a simpler rival in an earlier one's place
    (:func:`~livesweep.ident.residual_backward.rechoose`). An earlier step whose effect goes is
    marked so in ``steps`` (``removed``)."""
    trial, new = decision.chosen
    judge = screen.judge
    effect = EffectRecord(trial.kind, trial.where, trial.parameters, trial.significance,
                    ambiguous_with=trial.ambiguous_with or (), partners=trial.partners or ())
    simpler = tuple(t.candidates[0] for t in decision.tried
                    if not trial.partners and not t.partners and t.parameters and t.where == trial.where
                    and t.kind != trial.kind and len(t.parameters) < len(trial.parameters))
    names = (tuple(p["name"] for p in trial.parameters)
             + tuple(p["name"] for w in trial.partners or () for p in w.parameters))
    history = [*history, HistoryEntry(current.table, trial.candidates, names, simpler, effect, len(steps))]
    n_fits = sum(len(h.candidates) == 1 for h in history[:-1])
    after, cost_after, ver_after = new, trial.cost_after, new.verification
    out, untested = (backward_step(history, new.table, new.fit, whitened_ss(new.residuals), judge, progress)
                     if len(history) > 1 else (None, []))
    if untested:
        effect = replace(effect, not_retested=tuple(untested))
    if out is not None:
        # an effect added earlier is not significant any more: the later one explains what it did
        i, table, fit, residuals, why, befores = out
        history = _later_tables(history, i, befores)
        old = history.pop(i)
        _mark_removed(steps, old, {"at_step": len(steps) + 1, "reason": why})
        effect = replace(effect, removes={"kind": old.effect.kind, "where": old.effect.where, "reason": why})
        ver_after = verify(fit.model, fit.theta) if verify else None
        after, cost_after = ModelState(table, fit, ver_after, residuals), fit.cost_average
    elif len(history) > 1:
        swap = rechoose(history, new.table, new.fit, whitened_ss(new.residuals), judge, progress)
        n_fits += sum(len(h.simpler) for h in history[:-1] if len(h.candidates) == 1)
        if swap is not None:
            # an earlier effect's simpler rival explains as much once the later effects are in
            i, table, fit, residuals, entry, why, befores = swap
            history = _later_tables(history, i, befores)
            old = history[i]
            history[i] = replace(entry, step=len(steps), replacement=True)
            _mark_removed(steps, old, {"at_step": len(steps) + 1, "reason": why,
                                       "replaced_by": f"{entry.effect.kind} at {entry.effect.where}"})
            effect = replace(effect, replaces=Replacement(old.effect.kind, old.effect.where, entry.effect, why))
            ver_after = verify(fit.model, fit.theta) if verify else None
            after, cost_after = ModelState(table, fit, ver_after, residuals), fit.cost_average
    step = LoopStep(screen.candidates, decision.tried, effect, trial.cost_before, cost_after,
                    verification_summary(current.verification), verification_summary(ver_after), current.residuals,
                    after.residuals)
    return _Added(step, after, history, n_fits)


def _later_tables(history, i, befores) -> list:
    """``history`` with the effects after ``history[i]`` given the tables ``befores`` (rebuilt
    without it), so a later re-test cannot bring it back."""
    return history[:i + 1] + [replace(h, table=t) for h, t in zip(history[i + 1:], befores)]


def _mark_removed(steps, entry: HistoryEntry, mark: dict) -> None:
    """Mark the effect of ``entry`` in the step that recorded it (the step's own effect, or the
    rival that step put in an earlier one's place) as taken out or replaced."""
    st = steps[entry.step]
    eff = st.effect
    if entry.replacement:
        eff = replace(eff, replaces=replace(eff.replaces, by=replace(eff.replaces.by, removed=mark)))
    else:
        eff = replace(eff, removed=mark)
    steps[entry.step] = replace(st, effect=eff)


def _finish(steps, current, unexplained, limits, any_significant, judge, n_fits) -> ResidualLoop:
    """The loop's result: the pairs still above noise, the rivals of each effect (one added at a
    later step was not an alternative but a second effect), the conclusion."""
    for r in current.residuals:                       # the final fit's residual
        if r.rms_noise_units > 2.0:
            unexplained.append({"pair": f"{r.output}/{r.input}", "rms_noise_units": round(r.rms_noise_units, 2)})
    found = {(e.kind, e.where) for e in added_effects(s.effect for s in steps)}
    for k, s in enumerate(steps):    # a rival added at a later step was not an alternative but a second effect
        if s.effect is not None and s.effect.removed is None and s.effect.ambiguous_with:
            rivals = tuple(a for a in s.effect.ambiguous_with if (a["kind"], a["where"]) not in found)
            steps[k] = replace(s, effect=replace(s.effect, ambiguous_with=rivals))
    removed = [s.effect for s in steps if s.effect is not None and s.effect.removed is not None]
    # a scale factor the loop added absorbs its own place's scale error: not a limit of the data
    limits = [x for x in limits if (x["kind"], x["where"]) not in found]
    conclusion = conclusion_text(added_effects(s.effect for s in steps), removed, any_significant, limits)
    criterion = {"false_alarm": judge.alpha, "effective_points": round(judge.n_points, 1),
                 "noise_inflation": NOISE_INFLATION}
    return ResidualLoop(tuple(steps), current.table, current.fit, tuple(unexplained), conclusion, n_fits,
                        tuple(limits), criterion)
