"""Fitting a state-space model's parameters to frequency responses (docs/method.md §8.3, §8.5).

:func:`fit_state_space` minimises the NAVFIT cost summed over the pairs with
:func:`scipy.optimize.least_squares` (trust-region reflective) on the stacked residuals of
:func:`livesweep.ident.cost.residuals`, with the exact Jacobian, Jacobian-based parameter scaling and
delays bounded to ``>= 0``, from one or several starts. :func:`reduce_structure` is the
structure-reduction loop: delete the most insensitive (or least accurate) parameter while the
average cost rises by no more than :data:`MAX_DELTA_COST`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.optimize import least_squares

from livesweep.errors import ConfigError
from livesweep.ident.accuracy import MAX_CRAMER_RAO_PCT, MAX_INSENSITIVITY_PCT
from livesweep.ident.state_space_model import StateSpaceModel
from livesweep.ident.state_space_pairs import select_pairs
from livesweep.ident.state_space_result import StateSpaceFit, _Problem, _result
from livesweep.ident.state_space_start import equation_error_start
from livesweep.numeric import finite_or_none as _num

__all__ = ["fit_state_space", "reduce_structure", "MAX_DELTA_COST"]

#: A deletion is kept when the average cost rises by no more than this (docs/method.md §8.5).
MAX_DELTA_COST = 2.0


def fit_state_space(model: StateSpaceModel, pairs, *, theta0=None, max_nfev: int | None = 200,
                    method: str = "trf", x_scale="jac", ftol: float = 1e-10, xtol: float = 1e-10,
                    gtol: float = 1e-10, extra_starts=(), skipped_pairs=()) -> StateSpaceFit:
    """Fit the free parameters of ``model`` to the pairs' frequency responses.

    Parameters
    ----------
    model : StateSpaceModel
    pairs : list of PairData or FrequencyResponseSet
        The pairs to fit (from :func:`~livesweep.ident.state_space.select_pairs` /
        :func:`livesweep.ident.cost.fit_points`). A FrequencyResponseSet is turned into pairs with
        :func:`~livesweep.ident.state_space.select_pairs` (pairs without usable coherence are
        skipped and reported in the result).
    theta0 : array_like or dict, optional
        Start: full parameter vector, or name -> value overrides; default the model's initial
        values (with :func:`~livesweep.ident.state_space.equation_error_start` values for
        :attr:`StateSpaceModel.unset` parameters when ``pairs`` is a FrequencyResponseSet). Fixed
        parameters keep the model's values.
    max_nfev : int, optional
        Limit on cost evaluations; a fit stopped by it has ``converged = False``.
    method : {"trf", "lm"}
        :func:`scipy.optimize.least_squares` method; "lm" takes no bounds, so delay parameters
        are then unbounded.
    x_scale : "jac" or array_like
        Parameter scaling for :func:`scipy.optimize.least_squares` (free parameters).
    ftol, xtol, gtol : float
        Convergence tolerances (see :func:`scipy.optimize.least_squares`).
    extra_starts : sequence of array_like or dict
        Further starting points (multi-start, docs/method.md §8.3: e.g. transfer-function results,
        a priori values, :func:`~livesweep.ident.state_space.equation_error_start`); the solution
        with the lowest cost wins.
    skipped_pairs : sequence of (output, input, reason)
        Carried into the result (what :func:`~livesweep.ident.state_space.select_pairs` skipped).

    Returns
    -------
    StateSpaceFit
        ``converged`` is False, with the reason in ``message``, when the optimiser stopped at
        ``max_nfev`` or failed; ``n_iterations`` counts cost evaluations over all starts.
    """
    start = None
    if not isinstance(pairs, (list, tuple)):
        if theta0 is None and model.unset:
            start = equation_error_start(model, pairs)
        pairs, skipped = select_pairs(pairs, model)
        skipped_pairs = tuple(skipped_pairs) + tuple(skipped)
    if method not in ("trf", "lm"):
        raise ConfigError(f"state-space fit method {method!r}: use 'trf' or 'lm'")
    if not pairs:
        raise ConfigError("no pairs to fit: the model's outputs and inputs cover no usable frequency response")
    problem = _Problem(model, pairs)
    if theta0 is None:
        theta = np.array(model.initial if start is None else start, float)
    elif isinstance(theta0, dict):
        theta = model.theta(theta0)
    else:
        theta = np.array(theta0, float)
        if theta.shape != (len(model.parameters),):
            raise ConfigError(f"theta0 has {theta.size} values, the model has {len(model.parameters)} parameters")
    fixed = np.asarray(model.fixed, bool)
    theta[fixed] = np.asarray(model.initial)[fixed]
    free = model.free
    if free.size == 0:
        return _result(model, problem, theta, True, "no free parameters: cost evaluated", 1, (), skipped_pairs)
    lower = np.full(free.size, -np.inf)
    for k in model.delay_parameter_indices():
        if k in free:
            lower[np.flatnonzero(free == k)[0]] = 0.0
    if method == "lm":
        lower[:] = -np.inf
    cache = {}

    def full(x, base):
        th = base.copy()
        th[free] = x
        return th

    def both(x, base):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            try:
                r, D = problem.residuals_and_jacobian(full(x, base), free)
            except np.linalg.LinAlgError:                  # j w M - F singular at a fitting frequency
                r, D = np.full(problem.n_residuals, 1e6), np.zeros((problem.n_residuals, free.size))
            if not np.all(np.isfinite(r)):
                r = np.where(np.isfinite(r), r, 1e6)
                D = np.where(np.isfinite(D), D, 0.0)
            cache[key] = (r, D)
        return cache[key]

    starts = [theta]
    for st in extra_starts:
        st = model.theta(st) if isinstance(st, dict) else np.array(st, float)
        if st.shape != theta.shape:
            raise ConfigError(f"extra start has {st.size} values, the model has {theta.size} parameters")
        st[fixed] = theta[fixed]
        starts.append(st)
    best, nfev, failures = None, 0, []
    for base in starts:
        x0 = np.clip(base[free], lower, np.inf)
        try:
            res = least_squares(lambda x: both(x, base)[0], x0, jac=lambda x: both(x, base)[1],
                                bounds=(lower, np.inf), method=method, x_scale=x_scale, ftol=ftol, xtol=xtol,
                                gtol=gtol, max_nfev=max_nfev)
        except (np.linalg.LinAlgError, ValueError) as exc:
            failures.append(str(exc))
            continue
        cache.clear()
        nfev += res.nfev
        if best is None or res.cost < best[0].cost:
            best = (res, base)
    if best is None:
        return _result(model, problem, theta, False, f"optimiser failed: {'; '.join(failures)}", 0, (), skipped_pairs)
    res, base = best
    th = full(res.x, base)
    converged = bool(res.status > 0)
    msg = res.message if converged else f"did not converge: {res.message} (after {res.nfev} cost evaluations)"
    if len(starts) > 1:
        msg += f" (best of {len(starts)} starts)"
    return _result(model, problem, th, converged, msg, nfev, (), skipped_pairs)




def reduce_structure(model: StateSpaceModel, pairs, fit: StateSpaceFit | None = None, *,
                     max_insensitivity_pct: float = MAX_INSENSITIVITY_PCT,
                     max_cramer_rao_pct: float = MAX_CRAMER_RAO_PCT, max_delta_cost: float = MAX_DELTA_COST,
                     keep=(), max_steps: int = 50, **fit_kw) -> StateSpaceFit:
    """Model-structure reduction (docs/method.md §8.5).

    Repeatedly: if some free parameter has I% > ``max_insensitivity_pct``, try deleting the most
    insensitive one; otherwise, if some has CR% > ``max_cramer_rao_pct``, try deleting the one with
    the largest CR%. A deletion fixes the parameter at 0 and reconverges from the current values;
    it is kept when ``J_ave`` rises by at most ``max_delta_cost``, else the parameter is restored
    and not tried again. Stops when every remaining candidate meets the guidelines.

    Parameters
    ----------
    model : StateSpaceModel
    pairs : list of PairData or FrequencyResponseSet
        As for :func:`fit_state_space`.
    fit : StateSpaceFit, optional
        A converged fit of ``model`` (fitted here when omitted).
    keep : sequence of str
        Parameters never to delete.
    max_steps : int
        At most this many deletion attempts.
    **fit_kw
        Passed to :func:`fit_state_space`.

    Returns
    -------
    StateSpaceFit
        The final fit; ``removed`` logs every attempt (parameter, reason, the I% or CR% that
        triggered it, J_ave before and after, delta, accepted).
    """
    if not isinstance(pairs, (list, tuple)):
        pairs, skipped = select_pairs(pairs, model)
        fit_kw.setdefault("skipped_pairs", tuple(skipped))
    if fit is None:
        fit = fit_state_space(model, list(pairs), **fit_kw)
    fit_kw.pop("skipped_pairs", None)
    current = fit
    log = list(fit.removed)
    tried = set(keep)
    for _ in range(max_steps):
        cands = [q for q in current.parameters if not q.fixed and q.name not in tried]
        ins = [q for q in cands if not q.insensitivity_pct <= max_insensitivity_pct]
        if ins:
            q = max(ins, key=lambda q: (q.insensitivity_pct if math.isfinite(q.insensitivity_pct) else math.inf))
            reason, crit = "insensitivity", q.insensitivity_pct
        else:
            crs = [q for q in cands if not q.cramer_rao_pct <= max_cramer_rao_pct]
            if not crs:
                break
            q = max(crs, key=lambda q: (q.cramer_rao_pct if math.isfinite(q.cramer_rao_pct) else math.inf))
            reason, crit = "cramer_rao", q.cramer_rao_pct
        tried.add(q.name)
        trial_model = current.model.with_values(current.theta, fixed={q.name: 0.0})
        trial = fit_state_space(trial_model, list(pairs), skipped_pairs=current.skipped_pairs, **fit_kw)
        delta = trial.cost_average - current.cost_average
        accepted = bool(trial.converged and delta <= max_delta_cost)
        log.append({"step": len(log) + 1, "parameter": q.name, "value_before": _num(q.value), "reason": reason,
                    "criterion_pct": _num(crit), "cost_before": _num(current.cost_average),
                    "cost_after": _num(trial.cost_average), "delta_cost": _num(delta), "accepted": accepted})
        if accepted:
            current = trial
    return replace(current, removed=tuple(log))

