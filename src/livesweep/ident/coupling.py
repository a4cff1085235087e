"""A coupling the model lacks: a coherent pair the model has no path for, given one.

:func:`~livesweep.ident.state_space.select_pairs` skips a pair whose model response is zero by
the model's structure (no entry of F or G leads from the input to the output) while the data
are coherent there. No residual in dB exists for such a pair, so the residual loop's screen cannot
see it. Here every absent entry of a dynamic row of F or G (and every fixed derivative) that
would give the pair a path is tried: its value started on a log grid against the pair's data
alone, then the whole model refitted on all pairs, the new one included. The entry kept is the
one whose refit converges, meets the accuracy guidelines (CR% <= 20, I% <= 10) and the method's
J_ave <= 100, at the lowest J_ave; entries whose J_ave is within 10 % of it are reported as hard
to tell apart.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from livesweep.effects.derivative import derivative_slots
from livesweep.effects.table import add_entry, normalised, restart_from
from livesweep.errors import ConfigError
from livesweep.ident.accuracy import MAX_COST_AVERAGE, guideline_failures, parameter_report
from livesweep.ident.cost import MIN_COHERENCE
from livesweep.ident.residual_space import model_misfit
from livesweep.ident.state_space import StateSpaceFit, StateSpaceModel, refit_state_space, select_pairs

__all__ = ["Coupling", "no_path_pairs", "find_coupling", "START_GRID", "RIVAL_COST_RATIO"]

#: Magnitudes at which a new entry's starting value is tried, both signs (units of the entry).
START_GRID = 10.0 ** np.arange(-4.0, 2.01, 0.25)
_STARTS = np.concatenate([START_GRID, -START_GRID])
#: Entries whose refit's J_ave is within this ratio of the best one's are reported as rivals.
RIVAL_COST_RATIO = 1.10


@dataclass(frozen=True)
class Coupling:
    """The entry added for pairs the model had no path for.

    Attributes
    ----------
    where : str
        ``"F[row][col]"``, ``"G[row][col]"`` or the freed parameter's name.
    pairs : tuple of (str, str)
        (output, input) pairs that had no path.
    table : dict
        The ``[state_space]`` table with the entry, the model's own parameters at the case's values.
    fit : StateSpaceFit
        The refit on every pair, the new ones included.
    parameter : dict
        The new parameter: name, value, cramer_rao_pct, insensitivity_pct.
    tried : tuple of dict
        Every entry tried: where, cost_after (J_ave, None when the refit failed), reason, parameter.
    rivals : tuple of str
        Entries that fit within :data:`RIVAL_COST_RATIO` of the kept one.
    """

    where: str
    pairs: tuple
    table: dict
    fit: StateSpaceFit
    parameter: dict
    tried: tuple
    rivals: tuple


def no_path_pairs(skipped) -> list[tuple[str, str]]:
    """(output, input) of the pairs :func:`select_pairs` skipped for having no path in the model."""
    return [(o, i) for o, i, why in skipped if "no path" in why]


def _log_misfit(model, theta, pairs) -> float:
    """Sum over ``pairs`` of |ln(data/model)|^2 (magnitude in nepers, phase in rad): how far the
    model is from them."""
    total = 0.0
    for p in pairs:
        with np.errstate(all="ignore"):
            mag_db, ph_deg = model_misfit(model, theta, p)
        total += float(np.sum((mag_db * (np.log(10.0) / 20.0)) ** 2 + np.deg2rad(ph_deg) ** 2))
    return total if np.isfinite(total) else np.inf


def _candidate_table(table, where, name):
    t = normalised(table)
    if where == name and name in t["parameters"]:          # a fixed derivative: freed
        t["parameters"][name] = {"value": float(t["parameters"][name]["value"])}
    else:
        add_entry(t, where, name)
    return t


def find_coupling(table: dict, origin: dict, fit: StateSpaceFit, frs, skipped, *, n_omega: int,
                  progress=None, min_coherence: float = MIN_COHERENCE) -> Coupling | None:
    """The entry that best gives the no-path pairs of ``skipped`` a path, or None.

    Parameters
    ----------
    table : dict
        ``[state_space]`` table of ``fit`` (its parameters at the fitted values).
    origin : dict
        The case's own table (its starting values, for the refit).
    fit : StateSpaceFit
    frs : FrequencyResponseSet
    skipped : list of (output, input, reason)
        From :func:`select_pairs` on ``fit.model``.
    n_omega : int
        Fitting points per pair.
    progress : callable, optional
    min_coherence : float
        The fit bands' coherence threshold (the case's criteria).
    """
    targets = no_path_pairs(skipped)
    if not targets:
        return None
    model = fit.model
    tried, kept = [], []
    for name, _k, where in derivative_slots(table, model):
        t = _candidate_table(table, where, name)
        t0 = restart_from(t, origin)
        try:
            m = StateSpaceModel.from_table(t0)
            k = m.index(name)
            th = np.array(m.initial, float)
            th[k] = 1.0
            probe = m.with_values(th)
            pairs, _ = select_pairs(frs, probe, n_omega=n_omega, min_coherence=min_coherence)
        except (ConfigError, np.linalg.LinAlgError, ValueError) as exc:
            tried.append({"where": where, "cost_after": None, "reason": f"could not build the model: {exc}"})
            continue
        new = [p for p in pairs if (p.output, p.input) in targets]
        if not new:
            continue                                  # gives none of them a path
        costs = []
        for v in _STARTS:
            th[k] = v
            costs.append(_log_misfit(m, th, new))
        th[k] = _STARTS[int(np.argmin(costs))]
        if progress:
            progress(f"residual loop: a path for {', '.join(f'{o}/{i}' for o, i in targets)} through {where}")
        try:
            new_fit = refit_state_space(m.with_values(th), pairs)
        except (ConfigError, np.linalg.LinAlgError, ValueError) as exc:
            tried.append({"where": where, "cost_after": None, "reason": f"could not identify: {exc}"})
            continue
        (par,) = parameter_report(new_fit, [name])
        why = []
        if not new_fit.converged:
            why.append("fit did not converge")
        why += guideline_failures([par])
        if not new_fit.cost_average <= MAX_COST_AVERAGE:
            why.append(f"J_ave {new_fit.cost_average:.1f} > {MAX_COST_AVERAGE:g}")
        got = {"where": where, "cost_after": float(new_fit.cost_average), "reason": "; ".join(why) or "acceptable",
               "parameter": par}
        tried.append(got)
        if not why:
            gained = tuple(sorted({(p.output, p.input) for p in new}))
            kept.append((new_fit.cost_average, where, t0, new_fit, par, gained))
    if not kept:
        return None
    kept.sort(key=lambda x: x[0])
    cost, where, t0, new_fit, par, pairs = kept[0]
    rivals = tuple(w for c, w, *_ in kept[1:] if c <= RIVAL_COST_RATIO * cost)
    t0 = copy.deepcopy(t0)
    t0["parameters"][par["name"]] = {"value": float(par["value"])}
    return Coupling(where, pairs, t0, new_fit, par, tuple(tried), rivals)
