"""A state-space fit judged: its cost, accuracy and result (docs/method.md §8.2, §8.4).

:class:`StateSpaceFit` is what a fit returns: the parameters with their Cramer-Rao bounds and
insensitivities, the correlation of the free ones, the cost of every pair and ``J_ave``, the
eigenvalues. It is computed at a parameter vector from the stacked residuals of
:func:`livesweep.ident.cost.residuals` and their exact Jacobian (``_Problem``: derivatives of the
matrices' entries times linear solves with ``jw M - F``) through
:func:`livesweep.ident.accuracy.accuracy_from_jacobian`. :func:`evaluate_state_space` judges a
fit on other frequency points with its parameters unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.ident.accuracy import accuracy_from_jacobian
from livesweep.ident.cost import W_G, W_P, residuals
from livesweep.ident.state_space_model import StateSpaceModel
from livesweep.numeric import finite_or_none as _num, frozen_array as _frozen

__all__ = ["FittedParameter", "StateSpaceFit", "evaluate_state_space"]

_DB = 20.0 / math.log(10.0)
_DEG = 180.0 / math.pi


@dataclass(frozen=True)
class FittedParameter:
    """One identified parameter.

    Attributes
    ----------
    name : str
    value : float
        Identified (or held) value, in the units the case's matrices give it.
    fixed : bool
    cramer_rao, insensitivity : float
        1-sigma bounds in the parameter's units (raw normalisation, see
        :mod:`livesweep.ident.accuracy`); NaN for fixed parameters, inf when not identifiable.
    cramer_rao_pct, insensitivity_pct : float
        Relative to ``|value|`` [%].
    """

    name: str
    value: float
    fixed: bool
    cramer_rao: float
    cramer_rao_pct: float
    insensitivity: float
    insensitivity_pct: float


@dataclass(frozen=True)
class StateSpaceFit:
    """Result of :func:`~livesweep.ident.state_space.fit_state_space` (and of
    :func:`~livesweep.ident.state_space.reduce_structure`).

    Attributes
    ----------
    model : StateSpaceModel
        The model as fitted (fixed flags as used; initial values = the start of this fit).
    theta : ndarray
        Full parameter vector at the solution.
    parameters : tuple of FittedParameter
        In model order.
    correlation : ndarray, shape (n_free, n_free)
        Correlation of the free parameters (order of :attr:`correlation_names`).
    correlation_names : tuple of str
    cost_pairs : tuple of (output, input, J)
        Cost of each fitted pair.
    cost_average : float
        ``J_ave`` (guideline <= 100; <= 50 excellent).
    eigenvalues : ndarray, complex
        Eigenvalues of the identified model [rad/s].
    converged : bool
        The optimiser met a convergence test (False: stopped at its evaluation limit or failed).
    message : str
    n_iterations : int
        Cost evaluations the optimiser used.
    removed : tuple of dict
        Structure-reduction log (empty for a plain fit): one dict per attempted deletion.
    skipped_pairs : tuple of (output, input, reason)
    bands : tuple of (output, input, lo, hi)
        The fitted pairs' bands [rad/s].
    """

    model: StateSpaceModel
    theta: np.ndarray
    parameters: tuple
    correlation: np.ndarray
    correlation_names: tuple
    cost_pairs: tuple
    cost_average: float
    eigenvalues: np.ndarray
    converged: bool
    message: str
    n_iterations: int
    removed: tuple = ()
    skipped_pairs: tuple = ()
    bands: tuple = ()

    def parameter(self, name: str) -> FittedParameter:
        """The parameter called ``name``."""
        return self.parameters[self.model.index(name)]

    def value(self, name: str) -> float:
        return self.parameter(name).value

    @property
    def removed_parameters(self) -> tuple:
        """Parameters the structure reduction eliminated (held at 0), in order."""
        return tuple(step["parameter"] for step in self.removed if step.get("accepted"))

    def frequency_response(self, omega) -> np.ndarray:
        """Identified model's response ``(n_outputs, n_inputs, n_freq)`` at ``omega`` [rad/s]."""
        return self.model.frequency_response(self.theta, omega)

    def matrices(self) -> dict:
        """``A = M^-1 F``, ``B = M^-1 G``, ``C = H``, ``D = J`` at the fitted values (new arrays),
        with ``states``, ``inputs``, ``outputs`` and the input delays ``tau_s`` [s]."""
        M, F, G, H, J, tau = self.model.matrices(self.theta)
        return {"A": np.linalg.solve(M, F), "B": np.linalg.solve(M, G), "C": np.array(H), "D": np.array(J),
                "tau_s": np.array(tau, float), "states": self.model.states, "inputs": self.model.inputs,
                "outputs": self.model.outputs}

    def to_ss(self, *, pade_order: int | None = None):
        """This model as ``control.StateSpace`` (needs python-control); delays left out unless
        ``pade_order`` is given. See :func:`livesweep.interop.state_space_to_ss`."""
        from livesweep.interop import state_space_to_ss

        return state_space_to_ss(self, pade_order=pade_order)

    def to_dict(self) -> dict:
        """The ``report.json`` ``state_space`` form (docs/outputs.md, report.json), JSON-ready (non-finite -> null)."""
        return {
            "parameters": [{"name": q.name, "value": _num(q.value), "fixed": bool(q.fixed),
                            "cramer_rao": _num(q.cramer_rao), "cramer_rao_pct": _num(q.cramer_rao_pct),
                            "insensitivity": _num(q.insensitivity), "insensitivity_pct": _num(q.insensitivity_pct)}
                           for q in self.parameters],
            "cost": {"average": _num(self.cost_average),
                     "pairs": [{"output": o, "input": i, "cost": _num(c)} for o, i, c in self.cost_pairs]},
            "eigenvalues": [[float(e.real), float(e.imag)] for e in self.eigenvalues],
            "removed_parameters": list(self.removed_parameters),
            "reduction_log": [dict(step) for step in self.removed],
            "correlation": {"names": list(self.correlation_names),
                            "matrix": [[_num(x) for x in row] for row in self.correlation]},
            "bands": [{"output": o, "input": i, "band_rad_s": [lo, hi]} for o, i, lo, hi in self.bands],
            "skipped_pairs": [{"output": o, "input": i, "reason": r} for o, i, r in self.skipped_pairs],
            "converged": bool(self.converged),
            "message": self.message,
            "n_iterations": int(self.n_iterations),
        }


class _Problem:
    """Stacked residuals and their exact Jacobian for a model and its pairs."""

    def __init__(self, model: StateSpaceModel, pairs):
        self.model = model
        self.pairs = list(pairs)
        for pr in self.pairs:
            if pr.output not in model.outputs or pr.input not in model.inputs:
                raise ConfigError(f"pair {pr.output}/{pr.input} is not an output/input pair of the model "
                                  f"(outputs {', '.join(model.outputs)}; inputs {', '.join(model.inputs)})")
        self.omega = np.concatenate([pr.omega for pr in self.pairs])
        self.sl, k = [], 0
        for pr in self.pairs:
            self.sl.append(slice(k, k + pr.n_omega))
            k += pr.n_omega
        self.oi = [(model.outputs.index(pr.output), model.inputs.index(pr.input)) for pr in self.pairs]
        self.scale = [np.sqrt(20.0 / pr.n_omega * pr.weight) for pr in self.pairs]
        self.n_residuals = 2 * self.omega.size

    def residuals(self, theta):
        with np.errstate(all="ignore"):
            T = self.model.frequency_response(theta, self.omega)
        return np.concatenate([residuals(pr, T[o, i, sl]) for pr, (o, i), sl in zip(self.pairs, self.oi, self.sl)])

    def residuals_and_jacobian(self, theta, free):
        """Residuals (``sum r^2 = J``) and ``D = dr/dtheta[free]``, shape (n_residuals, n_free)."""
        with np.errstate(all="ignore"):
            T, dT = self.model._response(theta, self.omega, jacobian=True)
            r, D = [], []
            for pr, (o, i), sl, sc in zip(self.pairs, self.oi, self.sl, self.scale):
                t = T[o, i, sl]
                r.append(residuals(pr, t))
                rel = dT[free][:, o, i, sl] / t[None, :]                      # (k, f)
                dmag = -sc[None, :] * math.sqrt(W_G) * _DB * rel.real
                dph = -sc[None, :] * math.sqrt(W_P) * _DEG * rel.imag
                D.append(np.concatenate([dmag, dph], axis=1).T)
        return np.concatenate(r), np.concatenate(D, axis=0)

    def pair_costs(self, theta):
        """[(output, input, J)] at ``theta``."""
        r = self.residuals(theta)
        out, k = [], 0
        for pr in self.pairs:
            n = 2 * pr.n_omega
            out.append((pr.output, pr.input, float(np.dot(r[k:k + n], r[k:k + n]))))
            k += n
        return out


def _result(model, problem, theta, converged, message, nfev, removed=(), skipped=()):
    free = model.free
    with np.errstate(all="ignore"):
        r, D = problem.residuals_and_jacobian(theta, free)
        D = np.where(np.isfinite(D), D, 0.0)
        acc = accuracy_from_jacobian(D, theta[free])
        pc = problem.pair_costs(theta)
    params = []
    fpos = {k: a for a, k in enumerate(free)}
    for k, name in enumerate(model.parameters):
        if k in fpos:
            a = fpos[k]
            params.append(FittedParameter(name, float(theta[k]), False, float(acc.cramer_rao[a]),
                                          float(acc.cramer_rao_pct[a]), float(acc.insensitivity[a]),
                                          float(acc.insensitivity_pct[a])))
        else:
            params.append(FittedParameter(name, float(theta[k]), True, math.nan, math.nan, math.nan, math.nan))
    J_ave = float(np.mean([c for _, _, c in pc])) if pc else math.nan
    try:
        eig = model.eigenvalues(theta)
    except (np.linalg.LinAlgError, ValueError):
        eig = np.array([], complex)
    return StateSpaceFit(model, _frozen(theta), tuple(params), acc.correlation, model.free_names, tuple(pc), J_ave,
                         _frozen(eig, complex), bool(converged), message, int(nfev), tuple(removed), tuple(skipped),
                         tuple((pr.output, pr.input, float(pr.band_rad_s[0]), float(pr.band_rad_s[1]))
                               for pr in problem.pairs))


def evaluate_state_space(fit: StateSpaceFit, pairs) -> StateSpaceFit:
    """The fit ``fit`` judged on other frequency points, its parameters unchanged.

    J, the Cramer-Rao bounds and the insensitivities of
    :func:`~livesweep.ident.state_space.fit_state_space` are computed at ``fit.theta`` on
    ``pairs``, so models fitted on different points (the residual loop's denser grid) are
    compared on one set (the state-space stage's :data:`~livesweep.ident.cost.N_OMEGA`
    points per pair). Convergence, message, structure-reduction log and skipped pairs are
    ``fit``'s.

    Parameters
    ----------
    fit : StateSpaceFit
    pairs : list of PairData
        From :func:`~livesweep.ident.state_space.select_pairs` on ``fit.model``.

    Returns
    -------
    StateSpaceFit
        Same model and ``theta``; cost, bounds and bands of ``pairs``.
    """
    problem = _Problem(fit.model, pairs)
    return _result(fit.model, problem, np.array(fit.theta, float), fit.converged, fit.message, fit.n_iterations,
                   fit.removed, fit.skipped_pairs)
