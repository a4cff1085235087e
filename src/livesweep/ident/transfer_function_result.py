"""The result of a transfer-function fit: gain, zeros, poles, delay, cost and accuracy.

:class:`FittedTransferFunction` is one pair's result, read off the solution of the (joint) fit by
``_fitted``: the factors' values, their roots [rad/s], the Cramer-Rao bounds and insensitivities
of docs/method.md §8.4 (see :mod:`livesweep.ident.transfer_function` for their normalisation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from livesweep.ident.transfer_function_problem import _quad_roots
from livesweep.numeric import frozen_array

__all__ = ["FittedTransferFunction"]


def _jsonf(v):
    v = float(v)
    return v if math.isfinite(v) else None


def _frozen(a):
    return frozen_array(a, dtype=None)


@dataclass(frozen=True)
class FittedTransferFunction:
    """A fitted transfer function ``T(s) = gain * prod(s - z) / prod(s - p) * e^(-delay_s s)``.

    Attributes
    ----------
    name, output, input : str
    gain : float
        K of the factored form (output units per input unit times s^-(n_poles - n_zeros)).
    zeros, poles : ndarray, complex
        Roots [rad/s], numerator/denominator factors in the written order.
    delay_s : float
        tau [s] (0 when the model has no delay).
    cost : float
        J of this pair (docs/method.md §7.1).
    parameters : dict
        Key -> value: ``"gain"``, ``"tau"`` [s] (with a delay), ``"1/T"`` [rad/s], ``zeta`` [-],
        ``w`` [rad/s]; fixed values are not parameters.
    cramer_rao : dict
        Key -> CR_i = sqrt((H^-1)_ii), H = 2 D^T D (absolute, parameter units; see module docs for
        the normalisation); ``inf`` when the parameter is not identifiable.
    cramer_rao_pct : dict
        Key -> 100 CR_i / |theta_i|.
    factors : list of dict
        Readable factors: ``{"where", "kind": "s", "power"}``, ``{"where", "kind": "first", "name",
        "inverse_time_constant" [rad/s], "time_constant_s", "fixed"}``, ``{"where", "kind": "second",
        "names", "zeta", "omega" [rad/s], "fixed"}``.
    converged : bool
    message : str
    numerator, denominator : str
        The structures (shorthand).
    insensitivity_pct : dict
        Key -> 100 I_i/|theta_i|, I_i = 1/sqrt(H_ii).
    residual_variance : float
        J_total / (N_residuals - n_parameters) of the (joint) fit; ``sqrt(2 residual_variance) *
        CR_i`` is the statistical 1-sigma scatter for white fitting-point noise.
    fit_group : tuple of str
        Names of the transfer functions fitted together (shared denominator), this one included.
    band_rad_s : tuple
        The pair's fitting band [rad/s].
    covariance : ndarray or None
        ``H^-1`` over :attr:`parameters`, in their order (CIFER normalisation, as the bounds:
        ``sqrt(diag)`` is :attr:`cramer_rao`); what the bound of a figure derived from several
        parameters is propagated through (:mod:`livesweep.ident.test_point_model`).
    """

    name: str
    output: str
    input: str
    gain: float
    zeros: np.ndarray
    poles: np.ndarray
    delay_s: float
    cost: float
    parameters: dict
    cramer_rao: dict
    cramer_rao_pct: dict
    factors: list
    converged: bool
    message: str
    numerator: str = ""
    denominator: str = ""
    insensitivity_pct: dict = field(default_factory=dict)
    residual_variance: float = float("nan")
    fit_group: tuple = ()
    band_rad_s: tuple = ()
    covariance: np.ndarray | None = None

    def response(self, omega) -> np.ndarray:
        """Model response T(j omega) at ``omega`` [rad/s] (complex, output units per input unit)."""
        s = 1j * np.asarray(omega, float)
        T = np.full(s.shape, complex(self.gain))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for z in self.zeros:
                T = T * (s - z)
            for p in self.poles:
                T = T / (s - p)
            return T * np.exp(-s * self.delay_s)

    def to_tf(self, *, pade_order: int | None = None):
        """This fit as ``control.TransferFunction`` (needs python-control); the delay is left out
        unless ``pade_order`` is given. See :func:`livesweep.interop.transfer_function_to_tf`."""
        from livesweep.interop import transfer_function_to_tf

        return transfer_function_to_tf(self, pade_order=pade_order)

    def to_dict(self) -> dict:
        """The ``report.json`` entry (docs/outputs.md, report.json): roots as ``[re, im]`` pairs [rad/s]."""
        return {
            "name": self.name, "output": self.output, "input": self.input,
            "gain": _jsonf(self.gain),
            "zeros": [[_jsonf(z.real), _jsonf(z.imag)] for z in self.zeros],
            "poles": [[_jsonf(p.real), _jsonf(p.imag)] for p in self.poles],
            "delay_s": _jsonf(self.delay_s),
            "cost": _jsonf(self.cost),
            "numerator": self.numerator, "denominator": self.denominator,
            "parameters": {k: _jsonf(v) for k, v in self.parameters.items()},
            "cramer_rao": {k: _jsonf(v) for k, v in self.cramer_rao.items()},
            "cramer_rao_pct": {k: _jsonf(v) for k, v in self.cramer_rao_pct.items()},
            "insensitivity_pct": {k: _jsonf(v) for k, v in self.insensitivity_pct.items()},
            "residual_variance": _jsonf(self.residual_variance),
            "factors": [{k: (_jsonf(v) if isinstance(v, float) else v) for k, v in f.items()} for f in self.factors],
            "converged": bool(self.converged), "message": self.message,
            "fit_group": list(self.fit_group),
            "band_rad_s": [_jsonf(b) for b in self.band_rad_s],
        }


def _fitted(prob, p, names, x, cr, Hdiag, cost, resid_var, converged, msg, cov=None) -> FittedTransferFunction:
    """Pair ``p``'s result at the solution ``x`` of the fit ``prob`` (a ``_Problem``): its
    parameters with their bounds (``cr``: Cramer-Rao bounds, ``Hdiag``: the Hessian's diagonal,
    both over all of ``x``), factors and roots."""
    m, pair = prob.models[p], prob.pairs[p]
    params, crs, crp, insp = {}, {}, {}, {}
    idxs = list(range(prob.n_den)) + list(range(prob.slices[p].start, prob.slices[p].stop))
    for i in idxs:
        key = prob.keys[i][1]
        v = float(x[i])
        params[key] = v
        crs[key] = float(cr[i])
        with np.errstate(divide="ignore", invalid="ignore"):
            crp[key] = float(100.0 * cr[i] / abs(v)) if v != 0 else float("inf")
            ins = 1.0 / math.sqrt(Hdiag[i]) if Hdiag[i] > 0 else float("inf")
            insp[key] = float(100.0 * ins / abs(v)) if v != 0 else float("inf")
    factors, zeros, poles = [], [], []
    for where, facs, st, roots in (("numerator", prob.num[p], m.numerator, zeros),
                                   ("denominator", prob.den, m.denominator, poles)):
        for (kind, power, idx, fixed), f in zip(facs, st.factors):
            vals = [float(x[i]) if i >= 0 else float(fixed[j]) for j, i in enumerate(idx)]
            if kind == "s":
                factors.append({"where": where, "kind": "s", "power": power})
                roots += [0j] * power
            elif kind == "first":
                a = vals[0]
                factors.append({"where": where, "kind": "first", "name": f.names[0], "inverse_time_constant": a,
                                "time_constant_s": (1.0 / a) if a != 0 else float("inf"), "fixed": idx[0] < 0})
                roots.append(complex(-a))
            else:
                z, w = vals
                factors.append({"where": where, "kind": "second", "names": list(f.names), "zeta": z, "omega": w,
                                "fixed": [i < 0 for i in idx]})
                roots += list(_quad_roots(z, w))
    tau = float(x[prob.tau_idx[p]]) if prob.tau_idx[p] >= 0 else 0.0
    return FittedTransferFunction(
        name=names[p], output=pair.output, input=pair.input, gain=float(x[prob.gain_idx[p]]),
        zeros=_frozen(np.array(zeros, complex)), poles=_frozen(np.array(poles, complex)), delay_s=tau,
        cost=float(cost), parameters=params, cramer_rao=crs, cramer_rao_pct=crp, factors=factors,
        converged=bool(converged), message=msg, numerator=str(m.numerator), denominator=str(m.denominator),
        insensitivity_pct=insp, residual_variance=float(resid_var), fit_group=tuple(names),
        band_rad_s=tuple(float(b) for b in pair.band_rad_s),
        covariance=None if cov is None else _frozen(np.asarray(cov, float)[np.ix_(idxs, idxs)]))
