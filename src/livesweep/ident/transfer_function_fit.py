"""Fitting transfer functions to frequency responses with NAVFIT's cost (docs/method.md §7.1, §8.4).

:func:`fit_transfer_function` fits gain, zeros, poles and delay to one pair, or to several pairs
with a shared denominator (Tischler & Remple's Eq. 2.7), with ``scipy.optimize.least_squares``
(trust-region reflective, ``x_scale='jac'``, analytic Jacobian) from the best of many starts
(:mod:`livesweep.ident.transfer_function_start` and the user's); accuracy from the Gauss-Newton
Hessian at the solution.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np
from scipy.optimize import least_squares

from livesweep.errors import ConfigError
from livesweep.ident.cost import PairData, fit_points
from livesweep.ident.transfer_function_problem import _Problem
from livesweep.ident.transfer_function_result import FittedTransferFunction, _fitted
from livesweep.ident.transfer_function_start import _auto_starts, _gain_from_data
from livesweep.ident.transfer_function_structure import TransferFunctionModel
from livesweep.spectral.response import FrequencyResponse

__all__ = ["fit_transfer_function"]


def _canonical(prob: _Problem, x: np.ndarray) -> np.ndarray:
    """Same-kind, fully free factors of a structure in ascending |root| frequency, in the written order."""
    x = x.copy()
    for facs in [prob.den] + prob.num:
        for kind in ("first", "second"):
            grp = [idx for (k, power, idx, fixed) in facs if k == kind and all(i >= 0 for i in idx)]
            if len(grp) < 2:
                continue
            vals = [x[list(idx)].copy() for idx in grp]
            vals.sort(key=(lambda v: abs(v[0])) if kind == "first" else (lambda v: v[1]))
            for idx, v in zip(grp, vals):
                x[list(idx)] = v
    return x


def _covariance(J: np.ndarray):
    """``(CR bounds, diag(H), H^-1)`` with H = 2 J^T J; parameters in an (almost) null direction
    get an infinite bound (and an infinite variance in H^-1)."""
    H = 2.0 * J.T @ J
    n = H.shape[0]
    d = np.sqrt(np.clip(np.diag(H), 1e-300, None))
    Hs = H / np.outer(d, d)                                # scale-free for the rank decision
    ev, V = np.linalg.eigh(Hs)
    tol = max(ev.max(), 1e-300) * 1e-12
    good = ev > tol
    Cs = (V[:, good] / ev[good]) @ V[:, good].T
    C = Cs / np.outer(d, d)
    bad = np.zeros(n, bool)
    if not np.all(good):
        bad = np.any(np.abs(V[:, ~good]) > 1e-3, axis=1)
    var = np.diag(C).copy()
    var[bad] = np.inf
    C[bad, bad] = np.inf
    return np.sqrt(np.clip(var, 0.0, None)), np.diag(H), C


def _parse_user_start(prob: _Problem, names: list[str], spec: Mapping, base: np.ndarray) -> np.ndarray:
    """x from a user start: ``key`` sets that parameter wherever it exists, ``"<tf name>.<key>"`` only in
    that transfer function; the rest comes from ``base``; each gain not given is read from the data."""
    x = base.copy()
    gain_given = set()
    for k_full, v in spec.items():
        tf, _, key = str(k_full).rpartition(".")
        try:
            val = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"start value {k_full!r} must be a number, got {v!r}") from None
        hit = False
        for i, (scope, key_i) in enumerate(prob.keys):
            if key_i != key or (tf and not (tf in names and (scope is None or names[scope] == tf))):
                continue
            x[i] = val
            hit = True
            if key == "gain":
                gain_given.add(scope)
        if not hit:
            raise ConfigError(f"start value {k_full!r} names no parameter of the fit "
                              f"(parameters: {sorted({k for _, k in prob.keys})})")
    x = np.clip(x, prob.lower, prob.upper)
    for p in range(len(prob.pairs)):
        if p not in gain_given:
            x[prob.gain_idx[p]] = _gain_from_data(prob, x, p)
    return x


def fit_transfer_function(pairs, models, *, starts: Sequence[Mapping] | None = None, auto_starts: bool = True,
                          n_refine: int = 8, n_polish: int = 2, tau_max_s: float = np.inf,
                          sort_factors: bool = True, max_nfev: int = 2000) -> list[FittedTransferFunction]:
    """Fit gain, zeros, poles and delay to one pair, or to several pairs with a shared denominator.

    Parameters
    ----------
    pairs : PairData, FrequencyResponse or list of them
        The data (a FrequencyResponse is reduced with :func:`livesweep.ident.cost.fit_points` defaults).
    models : TransferFunctionModel or list of them
        One model (used for every pair; with several pairs the results are named
        ``<name>_<output>_<input>``) or one per pair, all with the same denominator (shared:
        Tischler & Remple's Eq. 2.7); each pair has its own gain, numerator and delay.
    starts : list of mapping, optional
        Extra starting values, key -> value (keys as in ``parameters``; ``"<tf name>.<key>"`` for one
        transfer function only). Missing keys are taken from the best automatic start; the gain,
        unless given, is read from the data.
    auto_starts : bool
        Also use the automatic starts: Sanathanan-Koerner (iterated Levy) rational fits for delay
        guesses 0, 0.5/w_top, 1/w_top; denominators with break frequencies log-spread over the band
        (three shifts, every first/second-order arrangement, damping 0.3/0.7) with the numerators
        solved linearly from the data; the gain from the data's mean dB offset and its sign from
        the phase offset.
    n_refine, n_polish : int
        The ``n_refine`` starts of lowest initial cost get a short optimisation; the best
        ``n_polish`` of those are run to convergence; the best result is kept.
    tau_max_s : float
        Upper bound on the delay [s] (lower bound 0).
    sort_factors : bool
        Report same-kind free factors of a structure in ascending root frequency in the written
        order (write them slowest first, e.g. ``"(1/Ts) (1/Tr)"``).
    max_nfev : int
        Function-evaluation limit of the final optimisation.

    Returns
    -------
    list of FittedTransferFunction
        One per pair, in order.

    Raises
    ------
    ConfigError
        Mismatched pairs/models, different denominators, a model whose output/input do not match
        its pair, bad start values.
    """
    if isinstance(pairs, (PairData, FrequencyResponse)):
        pairs = [pairs]
    pairs = [fit_points(p) if isinstance(p, FrequencyResponse) else p for p in pairs]
    if not pairs:
        raise ConfigError("fit_transfer_function: no pairs to fit")
    for p in pairs:
        if not isinstance(p, PairData):
            raise ConfigError(f"fit_transfer_function: pairs must be PairData or FrequencyResponse, got {type(p).__name__}")
    if isinstance(models, TransferFunctionModel):
        if len(pairs) == 1:
            models, names = [models], [models.name]
        else:
            names = [f"{models.name}_{p.output}_{p.input}" for p in pairs]
            models = [models] * len(pairs)
    else:
        models = list(models)
        if len(models) != len(pairs):
            raise ConfigError(f"fit_transfer_function: {len(models)} models for {len(pairs)} pairs (give one, or one per pair)")
        names = [m.name for m in models]
        if len(set(names)) != len(names):
            raise ConfigError(f"fit_transfer_function: model names must differ, got {names}")
    for m, p in zip(models, pairs):
        if m.denominator != models[0].denominator:
            raise ConfigError(f"transfer function {m.name!r}: denominator {str(m.denominator)!r} differs from "
                              f"{models[0].name!r}'s {str(models[0].denominator)!r}; a joint fit shares one denominator")
        if (m.output is not None and m.output != p.output) or (m.input is not None and m.input != p.input):
            raise ConfigError(f"transfer function {m.name!r} is for {m.output}/{m.input}, but its pair is {p.output}/{p.input}")
    tau_max = float(tau_max_s)
    if not tau_max >= 0:
        raise ConfigError(f"tau_max_s must be >= 0, got {tau_max_s!r}")
    prob = _Problem(pairs, models, tau_max)

    cands: list[tuple[float, np.ndarray, bool]] = []
    all_keys = {k for _, k in prob.keys}
    need_auto = auto_starts or any(not all_keys <= {str(k).rpartition(".")[2] for k in spec} | {"gain"}
                                   for spec in starts or [])
    auto = _auto_starts(prob, tau_max) if need_auto else []
    auto_scored = sorted(((prob.cost(x), i) for i, x in enumerate(auto)), key=lambda t: t[0])
    if auto_starts:
        cands += [(c, auto[i], False) for c, i in auto_scored]
    base = auto[auto_scored[0][1]] if auto_scored else prob.pack(
        [tuple(f[3]) for f in prob.den], [[tuple(f[3]) for f in n] for n in prob.num], [1.0] * len(pairs),
        [0.0] * len(pairs))
    for spec in starts or []:
        x = _parse_user_start(prob, names, spec, base)
        cands.append((prob.cost(x), x, True))
    if not cands:
        raise ConfigError("fit_transfer_function: no starting values (auto_starts=False and no starts)")

    def run(x0, nfev):
        x0 = np.clip(x0, prob.lower, prob.upper)
        try:
            return least_squares(prob.resid, x0, jac=prob.jac, bounds=(prob.lower, prob.upper), x_scale="jac",
                                 method="trf", max_nfev=nfev, xtol=1e-10, ftol=1e-10, gtol=1e-10)
        except (ValueError, np.linalg.LinAlgError):
            return None

    chosen = [x for c, x, user in cands if user]
    chosen += [x for c, x, user in sorted((t for t in cands if not t[2]), key=lambda t: t[0])[:max(1, n_refine)]]
    short = []
    for x0 in chosen:
        r = run(x0, 40 * (prob.n + 1))
        if r is not None and np.isfinite(r.cost):
            short.append((2 * r.cost, r.x))
    if not short:
        short = [(c, x) for c, x, _ in cands]
    short.sort(key=lambda t: t[0])
    best = None
    for _, x0 in short[:max(1, n_polish)]:
        r = run(x0, max_nfev)
        if r is not None and (best is None or r.cost < best.cost):
            best = r
    if best is None:
        x, success, msg = short[0][1], False, "optimiser failed from every start"
    else:
        x, success, msg = best.x, bool(best.success), str(best.message)
    if sort_factors:
        x = _canonical(prob, x)

    J = prob.jac(x)
    cr, Hdiag, cov = _covariance(J)
    total = prob.cost(x)
    dof = max(prob.n_resid - prob.n, 1)
    resid_var = total / dof
    costs = prob.pair_costs(x)
    if not np.all(np.isfinite(cr)):
        bad = [f"{k}" for (sc, k), c in zip(prob.keys, cr) if not np.isfinite(c)]
        msg += f"; not identifiable (CR undefined): {', '.join(sorted(set(bad)))}"
    converged = success and math.isfinite(total)
    return [_fitted(prob, p, names, x, cr, Hdiag, costs[p], resid_var, converged, msg, cov) for p in range(len(pairs))]
