"""Accuracy of identified parameters from the residual Jacobian (docs/method.md §8.4).

With ``r(theta)`` the stacked weighted residuals of :func:`livesweep.ident.cost.residuals` (so the
total cost is ``J = sum(r^2)``, dimensionless) and ``D = dr/dtheta`` at the solution::

    H      = 2 D^T D                               Gauss-Newton Hessian of J
    CR_i   = sqrt((H^-1)_ii)                       Cramer-Rao bound (1 sigma), parameter units
    I_i    = 1 / sqrt(H_ii)                        insensitivity (others held fixed), parameter units
    rho_ij = (H^-1)_ij / sqrt((H^-1)_ii (H^-1)_jj) correlation
    CR_i%  = 100 CR_i / |theta_i|,   I_i% = 100 I_i / |theta_i|

Normalisation
-------------
This is the *raw* normalisation of docs/method.md §8.4: no residual-variance factor, no ``dec_span``
factor, i.e. the weighted residuals are treated as if each had variance 1/2. CIFER's absolute
scaling is not public, so the bounds were calibrated against Monte-Carlo scatter instead
(``tests/test_state_space.py::test_cramer_rao_monte_carlo``: the XV-15 cruise test point flown in
the simulator with turbulence, sensor noise and off-axis pilot noise, MISO-conditioned composite
responses, 8 pairs, J_ave ~ 5). Measured over 80 realisations:

* standard deviation of the estimates / mean raw CR bound: median **0.68** over the 15 free
  parameters, range 0.34 (tau_a) to 1.50 (Ldr) -- :data:`MONTE_CARLO_SCATTER_OVER_CR`. So the raw
  bound is about right on average, conservative by ~1.5x for most parameters and optimistic by up
  to 1.5x for a few; no single constant factor makes it exact;
* rms error about the truth / mean CR bound: median 0.98, but 2.4-2.5 for the yaw-axis Nv, Nr,
  Ndr, whose estimates carry a systematic bias of 3-7 % (about 2.5 CR) that appears with
  turbulence in the spectral chain (it is not scatter, and no CR normalisation can cover it).

The factor depends on the data (coherence, residual level, how strongly neighbouring fitting
points are correlated by the spectral smoothing), so it is a calibration for data like livesweep's
sample logs, not a constant of nature. The guidelines (CR% <= 20, I% <= 10) are applied to the
raw values, as CIFER users apply them to CIFER's.

Always ``CR_i >= I_i``; a large ratio flags a parameter that is sensitive but correlated with
others. Parameters with no effect on the cost get infinite bounds.
"""

from __future__ import annotations

from dataclasses import dataclass

import math

import numpy as np

from livesweep.numeric import finite_or_none
from livesweep.numeric import frozen_array as _frozen

__all__ = ["Accuracy", "accuracy_from_jacobian", "MONTE_CARLO_SCATTER_OVER_CR", "MAX_CRAMER_RAO_PCT",
           "parameter_report", "guideline_failures", "pct_text", "NOT_DETERMINED_PCT", "MAX_INSENSITIVITY_PCT",
           "MAX_CORRELATION", "MAX_COST", "MAX_COST_AVERAGE", "MAX_QUADRATIC_ZETA"]

#: Observed scatter (std) of Monte-Carlo estimates divided by the mean raw Cramer-Rao bound, median
#: over parameters (module docstring; XV-15 cruise simulator, 80 realisations).
MONTE_CARLO_SCATTER_OVER_CR = 0.68

#: Guidelines (docs/method.md §8.4, M): CR% <= 20, I% <= 10, |rho| above 0.9 flags a trade-off.
MAX_CRAMER_RAO_PCT = 20.0
MAX_INSENSITIVITY_PCT = 10.0
MAX_CORRELATION = 0.9
#: A bound beyond this many % of the value says the data do not determine the parameter (it sits
#: at a bound, or the responses carry nothing of it); it is shown as "not determined", not as a number.
NOT_DETERMINED_PCT = 1000.0
#: Cost guidelines (docs/method.md §7.2, §8.2): J <= 100 for one pair, J_ave <= 100 over the pairs of
#: a state-space fit; above them the model does not describe the data well enough to use.
MAX_COST = 100.0
MAX_COST_AVERAGE = 100.0
#: A second-order factor more damped than this is two first-order ones (its fit is degenerate: the
#: data cannot tell the quadratic from the two real roots it stands for).
MAX_QUADRATIC_ZETA = 2.0


@dataclass(frozen=True)
class Accuracy:
    """Accuracy metrics of a set of (free) parameters.

    Attributes
    ----------
    values : ndarray
        Parameter values at the solution (parameter units).
    hessian : ndarray, shape (n, n)
        ``2 D^T D`` [cost units / parameter units^2].
    cramer_rao : ndarray
        CR bounds (parameter units, 1 sigma; inf when not identifiable).
    insensitivity : ndarray
        Insensitivities (parameter units; inf when the cost does not depend on the parameter).
    cramer_rao_pct, insensitivity_pct : ndarray
        Relative to ``|value|`` [%] (inf for a zero value).
    correlation : ndarray, shape (n, n)
        Parameter correlation (NaN rows for non-identifiable parameters).
    """

    values: np.ndarray
    hessian: np.ndarray
    cramer_rao: np.ndarray
    insensitivity: np.ndarray
    cramer_rao_pct: np.ndarray
    insensitivity_pct: np.ndarray
    correlation: np.ndarray


def _pct(bound, value):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(value) > 0, 100.0 * bound / np.abs(value), np.inf)


def accuracy_from_jacobian(D, theta) -> Accuracy:
    """CR bounds, insensitivities and correlations from the residual Jacobian.

    Parameters
    ----------
    D : ndarray, shape (n_residuals, n_parameters)
        ``dr/dtheta`` at the solution (residual units per parameter unit).
    theta : ndarray, shape (n_parameters,)
        Parameter values at the solution.

    Returns
    -------
    Accuracy

    Notes
    -----
    ``H`` is inverted after scaling to unit diagonal (``S H S``, ``S = diag(H_ii^-1/2)``), which
    makes the inverse insensitive to the parameters' units. A (numerically) singular scaled
    Hessian gives infinite CR bounds for the parameters in its null space.
    """
    D = np.asarray(D, float)
    theta = np.asarray(theta, float)
    n = theta.size
    H = 2.0 * D.T @ D
    diag = np.diag(H).copy()
    active = diag > 0
    with np.errstate(divide="ignore"):
        ins = np.where(active, 1.0 / np.sqrt(np.where(active, diag, 1.0)), np.inf)
    cr = np.full(n, np.inf)
    corr = np.full((n, n), np.nan)
    idx = np.flatnonzero(active)
    if idx.size:
        s = 1.0 / np.sqrt(diag[idx])
        Hs = H[np.ix_(idx, idx)] * s[:, None] * s[None, :]
        w, V = np.linalg.eigh(Hs)
        tol = max(w.max(), 0.0) * 1e-12 * idx.size
        good = w > tol
        if np.all(good):
            Cs = (V / w) @ V.T
            cr[idx] = np.sqrt(np.diag(Cs)) * s
            d = np.sqrt(np.diag(Cs))
            corr[np.ix_(idx, idx)] = Cs / d[:, None] / d[None, :]
        else:
            # parameters touching the null space are not identifiable: infinite bounds
            null = np.any(np.abs(V[:, ~good]) > 1e-6, axis=1)
            Cs = (V[:, good] / w[good]) @ V[:, good].T
            d = np.sqrt(np.maximum(np.diag(Cs), 0.0))
            cr[idx] = np.where(null, np.inf, d * s)
            with np.errstate(divide="ignore", invalid="ignore"):
                c = Cs / d[:, None] / d[None, :]
            c[null, :] = np.nan
            c[:, null] = np.nan
            corr[np.ix_(idx, idx)] = c
    corr = np.clip(corr, -1.0, 1.0)
    return Accuracy(_frozen(theta), _frozen(H), _frozen(cr), _frozen(ins), _frozen(_pct(cr, theta)),
                    _frozen(_pct(ins, theta)), _frozen(corr))


def parameter_report(fit, names) -> list[dict]:
    """Name, value, CR% and I% (3 decimals, None when not finite) and fixed flag of the fit's
    parameters ``names``, as the residual loop reports them."""
    out = []
    for n in names:
        q = fit.parameter(n)
        out.append({"name": n, "value": float(q.value), "cramer_rao_pct": finite_or_none(q.cramer_rao_pct, 3),
                    "insensitivity_pct": finite_or_none(q.insensitivity_pct, 3), "fixed": bool(q.fixed)})
    return out


def pct_text(pct, spec: str = ".3g") -> str:
    """A Cramer-Rao bound or insensitivity [% of the value] for display: ``"12.3"``, or
    ``"not determined"`` when it is not finite or beyond :data:`NOT_DETERMINED_PCT`."""
    if pct is None or not math.isfinite(pct) or pct > NOT_DETERMINED_PCT:
        return "not determined"
    return format(pct, spec)


def guideline_failures(params) -> list[str]:
    """The accuracy guidelines (CR% <= 20, I% <= 10) each free parameter of ``params``
    (:func:`parameter_report` entries) fails, as reasons ("Nr CR% 31.2 > 20")."""
    out = []
    for p in params:
        if p.get("fixed"):
            continue
        if pct_text(p["cramer_rao_pct"]) == "not determined":
            out.append(f"{p['name']} not determined by the data (CR beyond {NOT_DETERMINED_PCT:g} %)")
            continue
        if p["cramer_rao_pct"] > MAX_CRAMER_RAO_PCT:
            out.append(f"{p['name']} CR% {pct_text(p['cramer_rao_pct'])} > {MAX_CRAMER_RAO_PCT:g}")
        if p["insensitivity_pct"] is None or p["insensitivity_pct"] > MAX_INSENSITIVITY_PCT:
            out.append(f"{p['name']} I% {pct_text(p['insensitivity_pct'])} > {MAX_INSENSITIVITY_PCT:g}")
    return out
