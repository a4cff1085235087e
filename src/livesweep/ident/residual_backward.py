"""The residual loop's second look at the effects it added before, once a later one is in.

The backward step of stepwise selection (:func:`backward_step`) takes out an earlier effect that
no longer lowers the whitened sum of squares significantly on top of the others; the re-choice
(:func:`rechoose`) puts an earlier effect's simpler rival in its place when, with the later
effects in, the earlier effect's extra parameters are no longer significant. Both rebuild the
model without the earlier effect from the table before it, the later effects added again at their
fitted values (:func:`_rebuild`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.ident.accuracy import guideline_failures, parameter_report
from livesweep.ident.residual_judge import n_free
from livesweep.ident.residual_records import EffectRecord
from livesweep.ident.residual_space import pair_residuals, whitened_ss
from livesweep.ident.residual_tables import augment_table, table_with_fit
from livesweep.ident.selection import prefers, significance
from livesweep.ident.state_space import StateSpaceModel, refit_state_space

__all__ = ["HistoryEntry", "backward_step", "rechoose"]


@dataclass(frozen=True)
class HistoryEntry:
    """An effect the loop added, as its later re-tests need it.

    Attributes
    ----------
    table : dict
        The ``[state_space]`` table before it (rebuilt without an effect taken out since).
    candidates : tuple of Candidate
        What it was added as (two for a pair).
    names : tuple of str
        Its parameters' names (a pair's partners' included).
    simpler : tuple of Candidate
        The simpler kinds at its place refitted at its step.
    effect : EffectRecord
        Its record (for its kind, place and parameters).
    step : int
        Index of the loop step that recorded it.
    replacement : bool
        It is the simpler rival that step put in an earlier effect's place (recorded in that
        step's ``effect.replaces.by``), not the step's own effect.
    """

    table: dict
    candidates: tuple
    names: tuple
    simpler: tuple
    effect: EffectRecord
    step: int = -1
    replacement: bool = False

    @classmethod
    def from_dict(cls, d) -> "HistoryEntry":
        """From the dict form ``{"table", "cands", "names", "simpler", "effect"}``."""
        return cls(d["table"], tuple(d["cands"]), tuple(d["names"]), tuple(d.get("simpler", ())),
                   EffectRecord.from_dict(d["effect"]))


def backward_step(history, table, fit, ss_with, judge, progress):
    """The backward step of stepwise selection: re-test each effect added before the last one.

    An earlier single effect is taken out (the model rebuilt from the table before it, the later
    effects added again at their fitted values, and refitted) when it no longer lowers the
    whitened sum of squares significantly on top of the others: the F-test at ``false_alarm``
    with its parameters counted, the model without it nested in the current one, as
    :func:`~livesweep.ident.residual_choice.pair_refusal` tests the partners of a pair (a delay
    added first, explained away by the second-order actuator added at the same input later). The
    least significant one goes.

    Parameters
    ----------
    history : list of HistoryEntry
        Each effect added, in order.
    table, fit
        The current table and fit (every effect in).
    ss_with : float
        The current fit's whitened sum of squares.
    judge : Judge
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
    n_with = n_free(fit)
    out = None
    untested = []
    for i, h in enumerate(history[:-1]):
        if len(h.candidates) != 1:
            continue                              # a pair stays a pair
        if progress:
            progress(f"residual loop: is {h.effect.kind} at {h.effect.where} still needed?")
        try:
            t, befores, _ = _rebuild(history, i, table)
            f = refit_state_space(StateSpaceModel.from_table(t), judge.pairs)
        except (ConfigError, np.linalg.LinAlgError, ValueError, KeyError) as exc:
            untested.append({"kind": h.effect.kind, "where": h.effect.where, "error": f"{type(exc).__name__}: {exc}"})
            continue
        res = tuple(pair_residuals(f.model, f.theta, judge.pairs, judge.frs))
        ss = whitened_ss(res)
        k = len(h.names)
        sig = significance(ss, ss_with, k, judge.n_points, n_with - k, 1, judge.alpha)
        if not sig.significant and (out is None or sig.p_value > out[0]):
            why = (f"with the later effects in, it lowers the whitened residual by {max(ss - ss_with, 0.0):.0f}, "
                   f"< {sig.needed:.0f} needed for its {k} parameter(s)")
            out = (sig.p_value, i, table_with_fit(t, f), f, res, why, befores)
    return (None if out is None else out[1:]), untested


def _rebuild(history, i, table, replacement=None):
    """The current model without ``history[i]`` (or with ``replacement``, a Candidate, in its
    place): the table before it, every other parameter at its current value, the later effects
    added again at their fitted values. Returns the table and each later effect's table before
    it (rebuilt the same way), and the replacement's parameter names."""
    h = history[i]
    t = copy.deepcopy(h.table)
    for name in t["parameters"]:          # everything else where the current fit has it
        if name in table["parameters"] and name not in h.names:
            t["parameters"][name] = copy.deepcopy(table["parameters"][name])
    names = []
    if replacement is not None:
        t, names = augment_table(t, replacement)
    befores = []
    for later in history[i + 1:]:
        befores.append(copy.deepcopy(t))
        for c in later.candidates:
            t, _ = augment_table(t, c)
        for name in later.names:
            t["parameters"][name] = copy.deepcopy(table["parameters"][name])
    return t, befores, names


def rechoose(history, table, fit, ss_with, judge, progress):
    """Re-choose an earlier effect's kind once the later effects are in.

    At its step an effect was chosen over simpler rivals at the same place (a second-order
    actuator on da over a delay) by what it explained then; an effect added later (a sharp mode
    on p the actuator's resonance had partly stood in for) can take that advantage away. Each
    earlier single effect's simpler rivals refitted at its step (whatever that refit's own test
    said: alone, before the later effects, it may have explained too little) are refitted in its place
    with the later effects in; when the earlier effect's extra parameters are then not
    significant (:func:`~livesweep.ident.selection.prefers`, the test
    :func:`~livesweep.ident.residual_choice.choose` chose by), the simpler rival replaces it,
    provided its refit converges and meets the accuracy guidelines. The best such replacement
    (lowest sum of squares) is returned.

    Returns
    -------
    tuple or None
        ``(index in history, table, fit, residuals, the replacement's HistoryEntry, reason,
        befores)``, or None.
    """
    n_with = n_free(fit)
    best = None
    for i, h in enumerate(history[:-1]):
        if len(h.candidates) != 1:
            continue
        k = len(h.names)
        for alt in h.simpler:
            if progress:
                progress(f"residual loop: would {alt.kind} at {alt.where} do for {h.effect.kind} now?")
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
                       f"residual than {h.effect.kind}, not significant for {k - len(names)} parameter(s) more")
                entry = HistoryEntry(h.table, (alt,), tuple(names), (),
                                     EffectRecord(alt.kind, alt.where, tuple(params)))
                best = (ss, i, table_with_fit(t, f), f, res, entry, why, befores)
    return None if best is None else best[1:]
