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
(:func:`_rivals`). When the best candidate fails alone, the strongest are tried in pairs, and a
pair is kept only if each partner is significant on top of the other alone; after each step, an
effect added earlier that is no longer significant with the later ones in is taken out
(:func:`_backward`). When the fit is inadequate (J_ave above the guideline, or a whitened mean
square above ``NOISE_INFLATION``) the screen underrates what refits explain: the best-ranked are
refitted whatever their screening test and, if none explains the residual (:func:`_explained`),
every missing derivative and every control-path effect once. A coherent pair the model has no path
for (no residual in dB to screen) is first given one (:mod:`livesweep.ident.coupling`). The loop
repeats until nothing significant remains or ``max_steps``.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from statistics import NormalDist

import numpy as np

from livesweep.effects import EFFECT_KINDS, SEARCHED_KINDS, Candidate, parameter_role
from livesweep.effects.table import normalised, restart_from
from livesweep.errors import ConfigError
from livesweep.ident.accuracy import (MAX_COST_AVERAGE, MAX_CRAMER_RAO_PCT, MAX_INSENSITIVITY_PCT, guideline_failures,
                                      parameter_report, pct_text)
from livesweep.ident.coupling import find_coupling, no_path_pairs
from livesweep.ident.residual_space import (PairResidual, ResidualSpace, band_of, pair_residuals,
                                            whitened_ss)
from livesweep.ident.selection import (FALSE_ALARM, NOISE_INFLATION, effective_points, indistinguishable, prefers,
                                       significance)
from livesweep.ident.state_space import StateSpaceFit, StateSpaceModel, fit_state_space, refit_state_space
from livesweep.numeric import finite_or_none

__all__ = ["KINDS", "FALSE_ALARM", "MIN_RELATIVE_COST_DROP", "FIXABLE_ROLES", "FREQUENCY_ROLES",
           "CLEAR_EVIDENCE_FACTOR", "ONLY_PARAMETER_CR_PCT", "PARTIAL", "PairResidual", "Candidate", "LoopStep",
           "ResidualLoop", "pair_residuals", "diagnose", "augment_table", "run_residual_loop", "table_with_fit", "effect_text",
           "model_effects"]

#: The kinds the loop looks for (the catalogue's searched kinds).
KINDS = SEARCHED_KINDS
MIN_RELATIVE_COST_DROP = 0.10
N_OMEGA_LOOP = 100
VERIFICATION_BLOCK_S = 2.0


def diagnose(table: dict, fit: StateSpaceFit, pairs, frs, *, kinds=KINDS, residuals=None) -> list[Candidate]:
    """Rank the catalogue's effects by how much of the residual each explains (module docstring).

    Parameters
    ----------
    table : dict
        The ``[state_space]`` table the fit's model was built from (:func:`table_with_fit`).
    fit : StateSpaceFit
    pairs : list of PairData
    frs : FrequencyResponseSet
    kinds : sequence of str
        Which kinds to consider.
    residuals : list of PairResidual, optional
        :func:`pair_residuals` of the fit when the caller has them already.

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


def table_with_fit(table: dict, fit: StateSpaceFit) -> dict:
    """A copy of ``table`` whose parameter values (and fixed flags) are the fit's."""
    t = copy.deepcopy(table)
    t["parameters"] = {n: {"value": float(v), **({"fixed": True} if f else {})}
                       for n, v, f in zip(fit.model.parameters, fit.theta, fit.model.fixed)}
    return t


def augment_table(table: dict, candidate: Candidate) -> tuple[dict, list[str]]:
    """The ``[state_space]`` table with ``candidate``'s effect added.

    Returns
    -------
    table : dict
        A new table (the input is not modified).
    new_parameters : list of str
        Names of the parameters the effect added (or freed).
    """
    cls = EFFECT_KINDS.get(candidate.kind)
    if cls is None or not cls.searched:
        raise ConfigError(f"unknown effect kind {candidate.kind!r}; known: {', '.join(KINDS)}")
    return cls.augment(normalised(table), candidate.where, dict(candidate.parameters))


# ------------------------------------------------------------------------------------------------
# the loop
# ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class LoopStep:
    """One step of the residual loop (docs/outputs.md, report.json ``residual_loop.steps``).

    Attributes
    ----------
    candidates : tuple of Candidate
        The ranking before this step (best first).
    tried : tuple of dict
        Each re-identified candidate: kind, where, cost_after, evidence_after, verification_after,
        parameters (name, value, CR%, I%), accepted, reason.
    effect : dict or None
        The accepted effect (kind, where, parameters), None when nothing was accepted.
    cost_before, cost_after : float
        J_ave before and after (after = before when nothing was accepted).
    verification_before, verification_after : dict or None
        ``{"j_rms", "tic": {output: value}}`` from the verification callback.
    residuals_before, residuals_after : tuple of PairResidual
    """

    candidates: tuple
    tried: tuple
    effect: dict | None
    cost_before: float
    cost_after: float
    verification_before: dict | None
    verification_after: dict | None
    residuals_before: tuple
    residuals_after: tuple

    def to_dict(self) -> dict:
        return {"effect": self.effect, "cost_before": round(self.cost_before, 4), "cost_after": round(self.cost_after, 4),
                "verification_before": self.verification_before, "verification_after": self.verification_after,
                "candidates": [c.to_dict() for c in self.candidates[:8]],
                "tried": [{**t, "cost_after": finite_or_none(t.get("cost_after"))} for t in self.tried]}


@dataclass(frozen=True)
class ResidualLoop:
    """Result of :func:`run_residual_loop`.

    Attributes
    ----------
    steps : tuple of LoopStep
        Accepted steps, then the final step that found nothing (or nothing acceptable). A step's
        effect carries ``removes`` (kind, where, reason) when the backward step took an earlier
        effect out after it was added, or ``replaces`` (kind, where, ``by``: the simpler effect put
        in its place, reason) when it put a simpler rival in an earlier effect's place; that
        earlier effect carries ``removed`` (why, at which step, ``replaced_by``).
    table : dict
        The final ``[state_space]`` table (with every accepted effect, values = final fit).
    fit : StateSpaceFit
        The final fit.
    unexplained : tuple of dict
        Pairs whose residual stays above noise (rms in noise units > 2) and candidates that had
        evidence but were rejected.
    conclusion : str
        One line: what was added, or "nothing to add: residual within noise".
    n_fits : int
        Re-identifications run.
    criterion : dict
        The selection criterion's settings: ``false_alarm``, ``effective_points`` (independent
        values in the fitted pairs), ``noise_inflation``.
    limits : tuple of dict
        Effects the data cannot show in this band (kind, where, smallest_detectable_pct): a scale
        factor the model's derivatives absorb is reported, not guessed.
    """

    steps: tuple
    table: dict
    fit: StateSpaceFit
    unexplained: tuple
    conclusion: str
    n_fits: int
    limits: tuple = ()
    criterion: dict = field(default_factory=dict)

    @property
    def added(self) -> tuple:
        """Every effect in the final model, in the order added (the partners of a pair added
        together as their own entries; one taken out at a later step, marked ``removed`` in its
        step, is not listed)."""
        return tuple({k: v for k, v in e.items() if k not in ("with", "replaces")}
                     for e in model_effects(s.effect for s in self.steps))

    def to_dict(self) -> dict:
        return {"steps": [s.to_dict() for s in self.steps], "unexplained": list(self.unexplained),
                "conclusion": self.conclusion, "re_identifications": self.n_fits, "limits": list(self.limits),
                "criterion": self.criterion}


@dataclass
class _Judge:
    """What every re-identification in one loop is judged against."""

    pairs: list
    frs: object
    verify: object
    n_points: float
    alpha: float
    n_tests: int = 1
    origin: dict | None = None        # the case's own table: its starting values

    def test(self, ss_before, ss_after, k, n_model):
        return significance(ss_before, ss_after, k, self.n_points, n_model, self.n_tests, self.alpha)


#: A fixed-shape effect (a scale factor) whose smallest detectable size exceeds this [%] is
#: reported as not identifiable in the band.
UNDETECTABLE_PCT = 10.0


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


def _n_free(fit) -> int:
    return int(np.sum(~np.asarray(fit.model.fixed)))


def run_residual_loop(table: dict, fit: StateSpaceFit, frs, *, verify=None, max_steps: int = 3,
                      n_refit: int = 3, false_alarm: float = FALSE_ALARM, n_omega: int = N_OMEGA_LOOP,
                      kinds=KINDS, progress=None) -> ResidualLoop:
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
    """
    from livesweep.ident.state_space import select_pairs

    if not (0.0 < float(false_alarm) < 1.0):
        raise ConfigError(f"residual loop: false_alarm = {false_alarm!r} must be between 0 and 1")
    pairs, skipped = select_pairs(frs, fit.model, n_omega=n_omega)
    if not pairs:
        raise ConfigError("residual loop: no pair of the model has usable coherence")
    fit = fit_state_space(fit.model.with_values(fit.theta), pairs)
    origin, table = table, table_with_fit(table, fit)
    steps, n_fits, ver = [], 1, None
    if max_steps > 0 and no_path_pairs(skipped):
        # coherent pairs the model has no path for: no residual in dB, so no screen sees them
        coupling = find_coupling(table, origin, fit, frs, skipped, n_omega=n_omega, progress=progress)
        n_fits += 1 if coupling is None else len(coupling.tried)
        if coupling is not None:
            old_pairs, before = pairs, tuple(pair_residuals(fit.model, fit.theta, pairs, frs))
            pairs, _ = select_pairs(frs, coupling.fit.model, n_omega=n_omega)
            cost_before, ver_before = fit.cost_average, verify(fit.model, fit.theta) if verify else None
            fit, origin = coupling.fit, coupling.table
            table = table_with_fit(origin, fit)
            effect = {"kind": "missing_derivative", "where": coupling.where, "parameters": [coupling.parameter],
                      "gives_a_path_for": [f"{o}/{i}" for o, i in coupling.pairs]}
            if coupling.rivals:
                effect["ambiguous_with"] = [{"kind": "missing_derivative", "where": w} for w in coupling.rivals]
            tried = tuple({"kind": "missing_derivative", "where": t["where"], "cost_after": t["cost_after"],
                           "accepted": t["where"] == coupling.where,
                           "reason": ("kept: the lowest J_ave within the guidelines" if t["where"] == coupling.where
                                      else f"within the guidelines, but J_ave above {coupling.where}'s"
                                      if t["reason"] == "acceptable" else t["reason"]),
                           "parameters": [t["parameter"]] if "parameter" in t else []} for t in coupling.tried)
            ver = verify(fit.model, fit.theta) if verify else None
            # residuals on the pairs the model had before (the new ones had none to compare)
            steps.append(LoopStep((), tried, effect, cost_before, fit.cost_average, _ver_summary(ver_before),
                                  _ver_summary(ver), before,
                                  tuple(pair_residuals(fit.model, fit.theta, old_pairs, frs))))
    judge = _Judge(pairs, frs, verify, effective_points(pairs, getattr(frs, "settings", {})), float(false_alarm),
                   origin=origin)
    unexplained = []
    if ver is None and verify:
        ver = verify(fit.model, fit.theta)
    before = tuple(pair_residuals(fit.model, fit.theta, pairs, frs))
    for r in before:
        if not (np.all(np.isfinite(r.magnitude_db)) and np.all(np.isfinite(r.phase_deg))):
            raise ConfigError(f"residual loop: the fitted model's response {r.output}/{r.input} is zero or not finite "
                              f"at some fitting points; the loop cannot compare it with the data in dB")
    any_significant, limits = False, []
    history = []          # each effect this loop added: the table before it, its candidates, parameters, record
    for _ in range(max_steps + 1):
        ss_before = whitened_ss(before)
        cands = diagnose(table, fit, pairs, frs, kinds=kinds, residuals=before)
        judge.n_tests = max(len(cands), 1)
        n_model = _n_free(fit)
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
        n_values = sum(2 * r.omega.size for r in before)
        inadequate = fit.cost_average > MAX_COST_AVERAGE or ss_before > NOISE_INFLATION * n_values
        any_significant = bool(strong) or inadequate
        if not strong and inadequate:
            strong = ranked
        limits = _limits(cands, judge.test(ss_before, ss_before, 1, n_model).needed)
        tried, best, accepted, singles, cand_of = [], None, [], {}, {}

        def single(c):
            """Re-identify with ``c`` alone (once per kind and place); its (record, result)."""
            if (c.kind, c.where) not in singles:
                if progress:
                    progress(f"residual loop: re-identifying with {c.kind} at {c.where} (evidence {c.evidence:.0f})")
                rec, new = singles[(c.kind, c.where)] = _try(table, c, fit, judge, ss_before, ver)
                cand_of[id(rec)] = [c]
                tried.append(rec)
                if rec["accepted"]:
                    accepted.append((rec, new))
            return singles[(c.kind, c.where)]

        if len(steps) < max_steps:
            for c in strong:
                if len(singles) >= n_refit:
                    break
                single(c)
            for c in _best_per_place(strong, n_refit):
                # one place's rival kinds (a delay, a lag and a second-order actuator on one
                # input) must not take every refit from the next place's best (a skew on an output)
                single(c)
            if inadequate and not _explained(tried):
                # a derivative the fit compensated elsewhere screens far below what its refit
                # (restarted from the case's values) explains: each is re-identified once
                for c in ranked:
                    if c.kind == "missing_derivative":
                        single(c)
            if inadequate and not _explained(tried):
                # so does a control-path effect (a 6 rad/s second-order actuator on a yaw axis the
                # fit bent its derivatives to: screened as 0.2 rad/s notches and 10 s lags)
                for c in ranked:
                    if EFFECT_KINDS[c.kind].acts_on == "input":
                        single(c)
            for rec_, _ in list(accepted):
                # simplest first needs the simpler kinds at an accepted effect's place refitted too,
                # whatever their screen said (a delay screened below its test beside an accepted
                # second-order actuator on the same input)
                if not rec_.get("with"):
                    for c in ranked:
                        if c.where == rec_["where"] and c.kind != rec_["kind"] and c.n_parameters < len(rec_["parameters"]):
                            single(c)
            leader = max(tried, key=lambda t: t.get("evidence_after", -np.inf), default=None)
            duo = []
            if leader is not None and not leader["accepted"] and len(steps) + 2 <= max_steps:
                # the best explanation fails alone: two effects may overlap (a mode and an actuator
                # lag); try the strongest candidates in pairs at different places, each pair judged
                # as one effect. The partners come from the whole ranking: while one effect
                # dominates the residual, another is not significant on its own at screening. A pair
                # is kept only if each partner lowers S significantly on top of the other alone
                # (:func:`_partners_needed`; the partners not yet refitted alone are refitted).
                duo = _pair_search(ranked, table, fit, judge, ss_before, ver, progress)
                cand_of.update({id(rec): list(members) for members, rec, _ in duo})
                tried += [rec for _, rec, _ in duo]
                for members, rec, _ in duo:
                    if rec["accepted"]:
                        _partners_needed(rec, [single(m)[0] for m in members], judge, n_model)
            n_fits += len(singles) + len(duo)
            best = _choose(accepted, judge, n_model)
            if duo:
                pick = _choose([(rec, new) for _, rec, new in duo if rec["accepted"]], judge, n_model)
                if pick is not None and (best is None or prefers(
                        ss_before - best[0]["evidence_after"], _size(best),
                        ss_before - pick[0]["evidence_after"], _size(pick), judge.n_points, n_model, judge.alpha)):
                    best = pick
            # An accepted candidate that explains less than half of what the best-explaining one
            # does (even if that one failed a guideline) is a partial explanation, not the effect.
            top = _top_evidence(tried)
            if best is not None and best[0]["evidence_after"] < PARTIAL * top:
                best[0]["accepted"] = False
                best[0]["reason"] = (f"explains {best[0]['evidence_after']:.0f}, less than half of the best candidate's "
                                     f"{top:.0f}: a partial explanation")
                best = None
        if best is None:
            steps.append(LoopStep(tuple(cands), tuple(tried), None, fit.cost_average, fit.cost_average,
                                  _ver_summary(ver), _ver_summary(ver), before, before))
            unexplained += [{"kind": t["kind"], "where": t["where"], "reason": t["reason"]} for t in tried]
            break
        table_before = table
        rec, (table, fit, ver_after, after) = best
        rec["ambiguous_with"] = _rivals(rec, tried, judge, n_model)
        effect = {"kind": rec["kind"], "where": rec["where"], "parameters": rec["parameters"],
                  "significance": rec["significance"]}
        if rec.get("ambiguous_with"):
            effect["ambiguous_with"] = rec["ambiguous_with"]
        if rec.get("with"):
            effect["with"] = rec["with"]
        history.append({"table": table_before, "cands": cand_of[id(rec)], "effect": effect,
                        "names": [p["name"] for p in rec["parameters"]]
                        + [p["name"] for w in rec.get("with", ()) for p in w["parameters"]],
                        "simpler": [cand_of[id(t)][0] for t in tried
                                    if not rec.get("with") and not t.get("with") and t.get("parameters")
                                    and t["where"] == rec["where"] and t["kind"] != rec["kind"]
                                    and len(t["parameters"]) < len(rec["parameters"])]})
        cost_after = rec["cost_after"]
        n_fits += sum(len(h["cands"]) == 1 for h in history[:-1])
        out, untested = (_backward(history, table, fit, whitened_ss(after), judge, progress)
                         if len(history) > 1 else (None, []))
        if untested:
            effect["not_retested"] = untested
        if out is not None:
            # an effect added earlier is not significant any more: the later one explains what it did
            i, table, fit, after, why, befores = out
            for h, t in zip(history[i + 1:], befores):
                h["table"] = t                    # a later re-test must not bring it back
            old = history.pop(i)["effect"]
            old["removed"] = {"at_step": len(steps) + 1, "reason": why}
            effect["removes"] = {"kind": old["kind"], "where": old["where"], "reason": why}
            ver_after = verify(fit.model, fit.theta) if verify else None
            cost_after = fit.cost_average
        elif len(history) > 1:
            swap = _rechoose(history, table, fit, whitened_ss(after), judge, progress)
            n_fits += sum(len(h["simpler"]) for h in history[:-1] if len(h["cands"]) == 1)
            if swap is not None:
                # an earlier effect's simpler rival explains as much once the later effects are in
                i, table, fit, after, entry, why, befores = swap
                for h, t in zip(history[i + 1:], befores):
                    h["table"] = t
                old = history[i]["effect"]
                history[i] = entry
                old["removed"] = {"at_step": len(steps) + 1, "reason": why,
                                  "replaced_by": f"{entry['effect']['kind']} at {entry['effect']['where']}"}
                effect["replaces"] = {"kind": old["kind"], "where": old["where"], "by": entry["effect"], "reason": why}
                ver_after = verify(fit.model, fit.theta) if verify else None
                cost_after = fit.cost_average
        steps.append(LoopStep(tuple(cands), tuple(tried), effect, rec["cost_before"], cost_after,
                              _ver_summary(ver), _ver_summary(ver_after), before, after))
        ver, before = ver_after, after
    for r in before:                                  # the final fit's residual
        if r.rms_noise_units > 2.0:
            unexplained.append({"pair": f"{r.output}/{r.input}", "rms_noise_units": round(r.rms_noise_units, 2)})
    added = model_effects(s.effect for s in steps)
    removed = [s.effect for s in steps if s.effect is not None and "removed" in s.effect]
    found = {(e["kind"], e["where"]) for e in added}
    for e in added:              # a rival added at a later step was not an alternative but a second effect
        if "ambiguous_with" in e:
            e["ambiguous_with"] = [a for a in e["ambiguous_with"] if (a["kind"], a["where"]) not in found]
            if not e["ambiguous_with"]:
                del e["ambiguous_with"]
    if added:
        conclusion = "added " + "; ".join(
            f"{e['kind']} at {e['where']}" + "".join(f" (hard to tell from {a['kind']} at {a['where']} in this band)"
                                                      for a in e.get("ambiguous_with", ()))
            for e in added)
        conclusion += "".join(f"; took out {e['kind']} at {e['where']} added before ({e['removed']['reason']})"
                              for e in removed if not e["removed"].get("replaced_by"))
        conclusion += "".join(f"; {e['kind']} at {e['where']} added before replaced by {e['removed']['replaced_by']} "
                              f"({e['removed']['reason']})" for e in removed if e["removed"].get("replaced_by"))
        conclusion += "".join(f"; could not re-test {u['kind']} at {u['where']} once {e['kind']} at {e['where']} was "
                              f"added ({u['error']}): kept" for e in added for u in e.get("not_retested", ()))
    elif any_significant:
        conclusion = "residual above noise, but no candidate effect passed the acceptance tests"
    else:
        conclusion = "nothing to add: residual within noise"
    # a scale factor the loop added absorbs its own place's scale error: not a limit of the data
    limits = [x for x in limits if (x["kind"], x["where"]) not in found]
    if limits:
        conclusion += ("; scale errors these data cannot show (the derivatives absorb them): "
                       + ", ".join(f"{x['where']} " + ("any size" if x["smallest_detectable_pct"] >= 100 else
                                                       f"up to {x['smallest_detectable_pct']:.0f} %")
                                   for x in sorted(limits, key=lambda x: -x["smallest_detectable_pct"])))
    criterion = {"false_alarm": judge.alpha, "effective_points": round(judge.n_points, 1),
                 "noise_inflation": NOISE_INFLATION}
    return ResidualLoop(tuple(steps), table, fit, tuple(unexplained), conclusion, n_fits, tuple(limits), criterion)


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


#: An accepted effect that explains less than this fraction of the whitened residual drop the
#: best-explaining refit gives (accepted or not) is a partial explanation, not the effect.
PARTIAL = 0.5


def _explained(tried) -> bool:
    """Whether some accepted refit in ``tried`` explains the residual, not just part of it
    (:data:`PARTIAL`)."""
    top = _top_evidence(tried)
    return any(t["accepted"] and t["evidence_after"] >= PARTIAL * top for t in tried)


def _top_evidence(tried) -> float:
    """The largest drop of the whitened residual a refit in ``tried`` gave, accepted or not."""
    return max((t.get("evidence_after", -np.inf) for t in tried), default=-np.inf)


def effect_text(effect: dict) -> str:
    """One line for an added effect: ``"structural_mode at p: w_mode_p = 12.01 (CR 0.9 %), zeta_mode_p
    = 0.05158 (fixed: poorly determined), ..."``, and the effects it could not be told from."""
    def par(p):
        if p.get("fixed"):
            return f"{p['name']} = {p['value']:.4g} (fixed: poorly determined)"
        cr = pct_text(p["cramer_rao_pct"], ".4g")
        return f"{p['name']} = {p['value']:.4g} (CR {cr}{'' if cr == 'not determined' else ' %'})"
    text = f"{effect['kind']} at {effect['where']}: " + ", ".join(par(p) for p in effect["parameters"])
    for w in effect.get("with", ()):
        text += f"; together with {w['kind']} at {w['where']}: " + ", ".join(par(p) for p in w["parameters"])
    for a in effect.get("ambiguous_with", ()):
        text += f"; hard to tell from {a['kind']} at {a['where']} in this band"
    if "removes" in effect:
        r = effect["removes"]
        text += f"; took out {r['kind']} at {r['where']}, added before: {r['reason']}"
    if "replaces" in effect:
        r = effect["replaces"]
        text += (f"; replaced {r['kind']} at {r['where']}, added before, by {r['by']['kind']} at {r['by']['where']}: "
                 + ", ".join(par(p) for p in r["by"]["parameters"]) + f" ({r['reason']})")
    if "removed" in effect:
        r = effect["removed"]
        how = f"replaced by {r['replaced_by']}" if r.get("replaced_by") else "taken out"
        text += f" ({how} at step {r['at_step']}: {r['reason']})"
    return text


#: Candidates (best evidence first, distinct kind and place) combined in pairs when the best one
#: fails alone.
N_PAIR = 4


def _pair_search(strong, table, fit, judge, ss_before, ver, progress):
    """Re-identify the pairs of the :data:`N_PAIR` most significant distinct candidates (``strong``: the
    ranking, most significant first) at different places."""
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
            out.append(((a, b), *_try(table, [a, b], fit, judge, ss_before, ver)))
    return out


def _partners_needed(rec, alone, judge, n_model) -> None:
    """Refuse an accepted pair (``rec``) unless each partner lowers the whitened sum of squares
    significantly on top of the other partner alone (``alone``: the single records, in the pair's
    order), an F-test at ``false_alarm`` with the partner's parameters counted, the other nested
    in the pair. A pair one of whose partners only patches what the other leaves (a spurious
    notch next to the real actuator) is not two effects."""
    ss_pair = rec["ss_before"] - rec["evidence_after"]
    sizes = [len(rec["parameters"])] + [len(w["parameters"]) for w in rec.get("with", ())]
    labels = [f"{rec['kind']} at {rec['where']}"] + [f"{w['kind']} at {w['where']}" for w in rec.get("with", ())]
    for i, (k, label) in enumerate(zip(sizes, labels)):
        other = alone[1 - i]
        ss_other = rec["ss_before"] - (other.get("evidence_after") if other.get("evidence_after") is not None
                                       else -math.inf)
        sig = significance(ss_other, ss_pair, k, judge.n_points, n_model + sizes[1 - i], 1, judge.alpha)
        if not sig.significant:
            rec["accepted"] = False
            rec["reason"] = (f"{label} adds {max(ss_other - ss_pair, 0.0):.0f} to {labels[1 - i]} alone, "
                             f"< {sig.needed:.0f} needed for its {k} parameter(s): not a second effect")
            return


def _size(a) -> int:
    """Parameters an accepted ``(record, result)`` adds (fixed ones included)."""
    return len(a[0]["parameters"]) + sum(len(w["parameters"]) for w in a[0].get("with", ()))


def _choose(accepted, judge, n_model):
    """The effect to add among the accepted ``(record, result)``: the one that explains most,
    unless a simpler one (fewer new parameters, fixed ones included) explains nearly as much,
    i.e. the richer one's extra parameters are not significant (:func:`~livesweep.ident.selection.prefers`):
    then the simpler one, as CIFER practice prefers the simplest structure the data support (a
    delay before a second-order actuator, a first-order before a second-order one). Candidates
    that explain the data as well as the chosen one are listed by :func:`_rivals`."""
    if not accepted:
        return None
    ss0 = accepted[0][0]["ss_before"]
    ss = {id(a): ss0 - a[0]["evidence_after"] for a in accepted}
    order = sorted(accepted, key=lambda a: (_size(a), ss[id(a)]))
    chosen = order[0]
    for a in order[1:]:
        if prefers(ss[id(chosen)], _size(chosen), ss[id(a)], _size(a), judge.n_points, n_model, judge.alpha):
            chosen = a
    rec = chosen[0]
    best = min(accepted, key=lambda a: ss[id(a)])
    if chosen is not best:
        rec["reason"] += (f"; preferred to {best[0]['kind']} at {best[0]['where']} (whitened residual lower by only "
                          f"{ss[id(chosen)] - ss[id(best)]:.0f}, not significant for its "
                          f"{_size(best) - _size(chosen)} more parameter(s))")
    return chosen


def _rivals(rec, tried, judge, n_model) -> list[dict]:
    """The single effects re-identified alone that the chosen single effect (``rec``) cannot be
    told from (none for a pair): rival explanations of the same feature (the same place, or the
    same kind elsewhere: a scale factor on phi or on p) whose shape held (converged, significant, not worse in
    verification; accepted or failing only the accuracy guidelines, e.g. a lag whose corner lies
    above the band, where it is a delay) and whose whitened sum of squares differs from the
    chosen one's by less than one parameter's F-test needs
    (:func:`~livesweep.ident.selection.indistinguishable`). A rival with no more parameters than
    the chosen one is held to the loop's screening level (the candidates screened counted: the
    data prefer one to the other no more than they would prefer an effect to nothing); a richer
    one is a rival when it was accepted and its extra parameters are not significant
    (:func:`~livesweep.ident.selection.prefers`, the test by which :func:`_choose` took the
    simpler one: a notch that explains a little more than a lag), never when it was not accepted
    (a second-order actuator whose damping the data cannot pin down is the chosen lag with a
    useless parameter, not an alternative)."""
    if rec.get("with"):
        return []
    out, seen, k = [], {(rec["kind"], rec["where"])}, _size((rec, None))
    for t in tried:
        if (t is rec or not t.get("shape_held") or t.get("with") or (t["kind"], t["where"]) in seen
                or (t["kind"] != rec["kind"] and t["where"] != rec["where"])):
            continue
        ss_t, ss_rec = t["ss_before"] - t["evidence_after"], rec["ss_before"] - rec["evidence_after"]
        if len(t["parameters"]) > k:
            # a richer rival: the chosen shape with parameters the data cannot pin down (not
            # accepted) is no alternative; an accepted one is when its extra parameters are not
            # significant, the very reason _choose took the simpler
            tie = t["accepted"] and not prefers(ss_rec, k, ss_t, len(t["parameters"]), judge.n_points, n_model,
                                                judge.alpha)
        else:
            tie = indistinguishable(ss_t, ss_rec, judge.n_points, n_model, k, judge.alpha, judge.n_tests)
        if tie:
            seen.add((t["kind"], t["where"]))
            out.append({"kind": t["kind"], "where": t["where"], "evidence_after": t["evidence_after"],
                        "cost_after": t["cost_after"], "parameters": t["parameters"], "accepted": t["accepted"]})
    return out


def _backward(history, table, fit, ss_with, judge, progress):
    """The backward step of stepwise selection: re-test each effect added before the last one.

    An earlier single effect is taken out (the model rebuilt from the table before it, the later
    effects added again at their fitted values, and refitted) when it no longer lowers the
    whitened sum of squares significantly on top of the others: the F-test at ``false_alarm``
    with its parameters counted, the model without it nested in the current one, as
    :func:`_partners_needed` tests the partners of a pair (a delay added first, explained away by
    the second-order actuator added at the same input later). The least significant one goes.

    Parameters
    ----------
    history : list of dict
        Each effect added: the table before it, its candidates, its parameter names, its record.
    table, fit
        The current table and fit (every effect in).
    ss_with : float
        The current fit's whitened sum of squares.
    judge : _Judge
    progress : callable or None

    Returns
    -------
    removal : tuple or None
        ``(index in history, table, fit, residuals, reason, befores)`` of the model without it
        (``befores``: the table before each later effect, rebuilt without it), or None.
    untested : list of dict
        ``{"kind", "where", "error"}`` of each earlier effect whose re-test could not be run (the
        model without it failed to build or fit): it stays in, and the record says so.
    """
    n_with = _n_free(fit)
    out = None
    untested = []
    for i, h in enumerate(history[:-1]):
        if len(h["cands"]) != 1:
            continue                              # a pair stays a pair
        if progress:
            progress(f"residual loop: is {h['effect']['kind']} at {h['effect']['where']} still needed?")
        try:
            t, befores, _ = _rebuild(history, i, table)
            f = refit_state_space(StateSpaceModel.from_table(t), judge.pairs)
        except (ConfigError, np.linalg.LinAlgError, ValueError, KeyError) as exc:
            untested.append({"kind": h["effect"]["kind"], "where": h["effect"]["where"],
                             "error": f"{type(exc).__name__}: {exc}"})
            continue
        res = tuple(pair_residuals(f.model, f.theta, judge.pairs, judge.frs))
        ss = whitened_ss(res)
        k = len(h["names"])
        sig = significance(ss, ss_with, k, judge.n_points, n_with - k, 1, judge.alpha)
        if not sig.significant and (out is None or sig.p_value > out[0]):
            why = (f"with the later effects in, it lowers the whitened residual by {max(ss - ss_with, 0.0):.0f}, "
                   f"< {sig.needed:.0f} needed for its {k} parameter(s)")
            out = (sig.p_value, i, table_with_fit(t, f), f, res, why, befores)
    return (None if out is None else out[1:]), untested


def model_effects(effects) -> list[dict]:
    """The effects in the final model from the steps' ``effect`` records (None for a step that
    added nothing), in the order added: each step's effect, the partners of a pair as their own
    entries, and the simpler effect a step put in an earlier one's place (:func:`_rechoose`);
    none that a later step took out or replaced (``removed``). Works on the records of a
    :class:`ResidualLoop` and on those read back from report.json."""
    return [e for eff in effects if eff is not None
            for e in (eff, *eff.get("with", ()), *((eff["replaces"]["by"],) if eff.get("replaces") else ()))
            if "removed" not in e]


def _rebuild(history, i, table, replacement=None):
    """The current model without ``history[i]`` (or with ``replacement``, a Candidate, in its
    place): the table before it, every other parameter at its current value, the later effects
    added again at their fitted values. Returns the table and each later effect's table before
    it (rebuilt the same way), and the replacement's parameter names."""
    h = history[i]
    t = copy.deepcopy(h["table"])
    for name in t["parameters"]:          # everything else where the current fit has it
        if name in table["parameters"] and name not in h["names"]:
            t["parameters"][name] = copy.deepcopy(table["parameters"][name])
    names = []
    if replacement is not None:
        t, names = augment_table(t, replacement)
    befores = []
    for later in history[i + 1:]:
        befores.append(copy.deepcopy(t))
        for c in later["cands"]:
            t, _ = augment_table(t, c)
        for name in later["names"]:
            t["parameters"][name] = copy.deepcopy(table["parameters"][name])
    return t, befores, names


def _rechoose(history, table, fit, ss_with, judge, progress):
    """Re-choose an earlier effect's kind once the later effects are in.

    At its step an effect was chosen over simpler rivals at the same place (a second-order
    actuator on da over a delay) by what it explained then; an effect added later (a sharp mode
    on p the actuator's resonance had partly stood in for) can take that advantage away. Each
    earlier single effect's simpler rivals refitted at its step (whatever that refit's own test
    said: alone, before the later effects, it may have explained too little) are refitted in its place
    with the later effects in; when the earlier effect's extra parameters are then not
    significant (:func:`~livesweep.ident.selection.prefers`, the test :func:`_choose` chose by),
    the simpler rival replaces it, provided its refit converges and meets the accuracy
    guidelines. The best such replacement (lowest sum of squares) is returned.

    Returns
    -------
    tuple or None
        ``(index in history, table, fit, residuals, history entry of the replacement, reason,
        befores)``, or None.
    """
    n_with = _n_free(fit)
    best = None
    for i, h in enumerate(history[:-1]):
        if len(h["cands"]) != 1:
            continue
        k = len(h["names"])
        for alt in h["simpler"]:
            if progress:
                progress(f"residual loop: would {alt.kind} at {alt.where} do for {h['effect']['kind']} now?")
            try:
                t, befores, names = _rebuild(history, i, table, alt)
                f = refit_state_space(StateSpaceModel.from_table(t), judge.pairs)
            except (ConfigError, np.linalg.LinAlgError, ValueError, KeyError):
                continue                          # not a replacement; the effect stays as chosen
            params = parameter_report(f, names)
            if not f.converged or guideline_failures(params):
                continue
            res = tuple(pair_residuals(f.model, f.theta, judge.pairs, judge.frs))
            ss = whitened_ss(res)
            if prefers(ss, len(names), ss_with, k, judge.n_points, n_with - k, judge.alpha):
                continue
            if best is None or ss < best[0]:
                why = (f"with the later effects in, {alt.kind} leaves {max(ss - ss_with, 0.0):.0f} more whitened "
                       f"residual than {h['effect']['kind']}, not significant for {k - len(names)} parameter(s) more")
                entry = {"table": h["table"], "cands": [alt], "names": names, "simpler": [],
                         "effect": {"kind": alt.kind, "where": alt.where, "parameters": params}}
                best = (ss, i, table_with_fit(t, f), f, res, entry, why, befores)
    return None if best is None else best[1:]


def _as_list(v):
    return list(v) if isinstance(v, (list, tuple)) else [v]


def _ver_summary(v):
    """``{"j_rms", "tic": {output: value}, "passed"}`` (records pooled: J_rms over all samples, the
    worst TIC per output), or None."""
    if v is None:
        return None
    vs = _as_list(v)
    n = [float(np.sum(np.isfinite(x.measured - x.predicted))) for x in vs]
    j = math.sqrt(sum(x.j_rms ** 2 * k for x, k in zip(vs, n)) / max(sum(n), 1.0))
    tic = {}
    for x in vs:
        for o in x.outputs:
            tic[o.name] = max(tic.get(o.name, 0.0), float(o.tic))
    return {"j_rms": finite_or_none(j, 3), "tic": {k: finite_or_none(t, 3) for k, t in tic.items()},
            "passed": all(x.passed for x in vs)}


def _verification_change(before, after, alpha: float = FALSE_ALARM):
    """Paired comparison of two models on the same verification records.

    ``d(t) = sum_o (r_after,o(t)^2 - r_before,o(t)^2)``; its mean against the scatter of its means
    over :data:`VERIFICATION_BLOCK_S` blocks (turbulence makes neighbouring samples correlated).
    Verdict ``improved`` / ``worse`` beyond ``z`` sigma, the one-sided normal quantile at
    ``alpha`` (the loop's false-alarm level, 2.33 sigma at 1 %), else ``unchanged``. A correct
    effect is refused by chance with probability ``alpha`` per comparison: turbulence the model
    cannot predict enters ``d`` through the cross term ``2 e_turb (m_after - m_before)``, whose
    mean is zero but whose scatter on a few seconds of low-frequency gusts is as large as a
    genuine improvement (a 12 rad/s mode on p in cruise: +2.2 sigma at turbulence 0.3, -2.5 sigma
    on the same manoeuvres in calm air).
    """
    if before is None or after is None:
        return None
    ds, means = [], []
    for b, a in zip(_as_list(before), _as_list(after)):
        with np.errstate(over="ignore", invalid="ignore"):    # a diverging model's huge residuals
            ra, rb = a.measured - a.predicted, b.measured - b.predicted
            ok = np.all(np.isfinite(ra) & np.isfinite(rb), axis=0)
            d = np.sum(ra[:, ok] ** 2 - rb[:, ok] ** 2, axis=0)
        dt = float(np.median(np.diff(b.t_s))) if b.t_s.size > 1 else 1.0
        n_block = max(1, int(round(VERIFICATION_BLOCK_S / dt)))
        n_b = d.size // n_block
        means.extend(d[:n_b * n_block].reshape(n_b, n_block).mean(axis=1).tolist())
        ds.append(d)
    d = np.concatenate(ds) if ds else np.zeros(0)
    with np.errstate(over="ignore", invalid="ignore"):
        noise = float(np.std(means, ddof=1) / math.sqrt(len(means))) if len(means) >= 3 else float("inf")
        mean = float(d.mean()) if d.size else 0.0
    sb, sa = _ver_summary(before), _ver_summary(after)
    limit = min(v.guidelines["j_rms_max"] for v in _as_list(after))
    diverges = (sa["j_rms"] is None or not np.isfinite(mean) or (len(means) >= 3 and not np.isfinite(noise))
                or (sb["j_rms"] is not None and sb["j_rms"] <= limit < sa["j_rms"]))
    if diverges:
        # the new model diverges open loop (or predicts nothing), or fails the method's J_rms
        # guideline the model before met: worse, whatever the noise (a model growing as e^(2t)
        # over the record has block means that grow with it, so their scatter is as large as
        # their mean and a paired test alone would call it unchanged)
        return {"j_rms_before": sb["j_rms"], "j_rms_after": sa["j_rms"], "mean_change": None, "noise": None,
                "verdict": "worse" if sb["j_rms"] is not None else "unchanged"}
    z = NormalDist().inv_cdf(1.0 - alpha)
    verdict = "improved" if mean < -z * noise else ("worse" if mean > z * noise else "unchanged")
    return {"j_rms_before": sb["j_rms"], "j_rms_after": sa["j_rms"], "mean_change": mean, "noise": noise,
            "z": round(z, 3), "verdict": verdict}


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


def _try(table, cand, fit, judge, ss_before, ver_before):
    """Re-identify with ``cand`` (a Candidate, or several added together) added and judge it;
    returns (record, (table, fit, verification, residuals)) with the record's ``accepted`` and
    ``reason``. Several candidates are judged as one effect with all their parameters; the
    record's ``with`` lists the others (kind, where, their parameters).

    When the effect's shape is supported (the fit converges, the whitened residual and J_ave fall
    beyond noise, verification is not worse) but one of its parameters misses the accuracy
    guidelines (a sharp mode's damping, a notch's depth), the structure-reduction step of the
    method is taken inside the effect: that parameter (one, a shape parameter: a damping or a
    gain) is fixed at its fitted value and the rest refitted, when the effect is clearly there
    (:data:`CLEAR_EVIDENCE_FACTOR`) and another of its parameters stays free. The record
    says which were fixed (``fixed``: name, value and why) and the effect is accepted with them.
    """
    cands = list(cand) if isinstance(cand, (list, tuple)) else [cand]
    cand = cands[0]
    pairs, frs, verify = judge.pairs, judge.frs, judge.verify
    n_model = _n_free(fit)
    rec = {"kind": cand.kind, "where": cand.where, "evidence": round(float(sum(c.evidence for c in cands)), 2),
           "cost_before": float(fit.cost_average), "ss_before": float(ss_before), "fixed": []}
    try:
        aug, new, own = table, [], []
        for c in cands:
            aug, names = augment_table(aug, c)
            new += names
            own.append(names)
        model = StateSpaceModel.from_table(aug)
        new_fit = refit_state_space(model, pairs)
        if not new_fit.converged and judge.origin is not None:
            # the model's derivatives had bent to make up for the missing effect and the refit from
            # them is stuck: start them again where the case starts them (a second start)
            again = refit_state_space(StateSpaceModel.from_table(restart_from(aug, judge.origin)), pairs)
            if again.converged or again.cost_average < new_fit.cost_average:
                new_fit = again
    except (ConfigError, np.linalg.LinAlgError, ValueError) as exc:
        rec.update(accepted=False, reason=f"could not re-identify: {exc}", cost_after=float("nan"), parameters=[])
        return rec, None
    while True:
        res_after = tuple(pair_residuals(new_fit.model, new_fit.theta, pairs, frs))
        ss_after = whitened_ss(res_after)
        sig = judge.test(ss_before, ss_after, len(new), n_model)
        params = parameter_report(new_fit, new)
        ver_after = verify(new_fit.model, new_fit.theta) if verify else None
        change = _verification_change(ver_before, ver_after, judge.alpha)
        shape = []                                    # the effect's shape, whatever its parameters' accuracy
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
        accuracy = guideline_failures(params)
        worst = _worst(params)
        lo, hi = band_of(pairs)
        outside = any(_role(p["name"]) in FREQUENCY_ROLES and not lo <= p["value"] <= hi for p in params)
        if (shape or not accuracy or worst is None or rec["fixed"] or outside
                or ss_before - ss_after < CLEAR_EVIDENCE_FACTOR * sig.needed):
            break
        # the shape is there; one parameter is poorly determined: fix it where it is, refit the rest
        try:
            refit = refit_state_space(new_fit.model.with_values(new_fit.theta, fixed={worst["name"]: worst["value"]}), pairs)
        except (ConfigError, np.linalg.LinAlgError, ValueError):
            break
        why = (f"CR% {pct_text(worst['cramer_rao_pct'])}, I% {pct_text(worst['insensitivity_pct'])}: poorly determined, "
               f"fixed at its fitted value")
        rec["fixed"].append({"name": worst["name"], "value": float(worst["value"]),
                             "cramer_rao_pct": worst["cramer_rao_pct"], "insensitivity_pct": worst["insensitivity_pct"],
                             "reason": why})
        new_fit = refit
    by_name = {p["name"]: p for p in params}
    rec.update(cost_after=float(new_fit.cost_average), evidence_after=round(ss_before - ss_after, 2),
               parameters=[by_name[n] for n in own[0]], verification_after=_ver_summary(ver_after),
               verification_change=change, significance=sig.to_dict())
    if len(cands) > 1:
        rec["with"] = [{"kind": c.kind, "where": c.where, "parameters": [by_name[n] for n in names]}
                       for c, names in zip(cands[1:], own[1:])]
    reasons = shape + accuracy
    rec["shape_held"] = not shape
    rec["accepted"] = not reasons
    rec["reason"] = "; ".join(reasons) if reasons else (
        "accepted" + "".join(f"; {f['name']} fixed at {f['value']:.4g} ({f['reason'].split(':')[0]})"
                             for f in rec["fixed"]))
    return rec, (table_with_fit(aug, new_fit), new_fit, ver_after, res_after)
