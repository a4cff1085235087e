"""The residual of a fitted model in noise units, and the space the residual loop screens it in.

Residuals are whitened by the data's random error (``sigma_dB = 20/ln10 eps``, ``sigma_deg =
180/pi eps``, eps floored at :data:`EPS_FLOOR`). The model's free parameters may re-adjust, so
:class:`ResidualSpace` projects the residual and every effect's signature off the span of the
model's own (whitened) log-response Jacobian; an effect's evidence is the drop of the whitened
sum of squares its best parameters give there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["EPS_FLOOR", "PairResidual", "model_misfit", "pair_residuals", "ResidualSpace", "whitened_ss", "band_of"]

EPS_FLOOR = 0.02
_DB = 20.0 / math.log(10.0)
_DEG = 180.0 / math.pi


@dataclass(frozen=True)
class PairResidual:
    """One pair's residual at its fitting points.

    Attributes
    ----------
    output, input : str
    omega : ndarray
        [rad/s]
    magnitude_db, phase_deg : ndarray
        Data minus model [dB], [deg] (phase wrapped to (-180, 180]).
    sigma_db, sigma_deg : ndarray
        1-sigma random error of the data there [dB], [deg].
    """

    output: str
    input: str
    omega: np.ndarray
    magnitude_db: np.ndarray
    phase_deg: np.ndarray
    sigma_db: np.ndarray
    sigma_deg: np.ndarray

    @property
    def rms_noise_units(self) -> float:
        """RMS of the whitened residual (about 1 when the residual is noise)."""
        z = np.concatenate([self.magnitude_db / self.sigma_db, self.phase_deg / self.sigma_deg])
        return float(np.sqrt(np.mean(z**2)))

    def to_dict(self) -> dict:
        return {"output": self.output, "input": self.input, "rms_noise_units": round(self.rms_noise_units, 3),
                "omega": self.omega.round(5).tolist(), "magnitude_db": self.magnitude_db.round(4).tolist(),
                "phase_deg": self.phase_deg.round(3).tolist(), "sigma_db": self.sigma_db.round(4).tolist(),
                "sigma_deg": self.sigma_deg.round(3).tolist()}


def _sigma(frs, pair):
    resp = frs.pair(pair.output, pair.input)
    ok = np.isfinite(resp.random_error)
    eps = np.interp(np.log10(pair.omega), np.log10(resp.omega[ok]), resp.random_error[ok])
    eps = np.maximum(eps, EPS_FLOOR)
    return _DB * eps, _DEG * eps


def model_misfit(model, theta, pair) -> tuple[np.ndarray, np.ndarray]:
    """Data minus model on one pair at its fitting points: magnitude [dB] and phase [deg, wrapped
    to (-180, 180]] (infinite magnitude where the model's response is zero)."""
    T = model.frequency_response(theta, pair.omega)[model.outputs.index(pair.output), model.inputs.index(pair.input)]
    mag = pair.magnitude_db - _DB * np.log(np.abs(T))
    ph = np.angle(np.exp(1j * np.deg2rad(pair.phase_deg)) / T, deg=True)
    return mag, ph


def pair_residuals(model: StateSpaceModel, theta, pairs, frs) -> list[PairResidual]:
    """Data minus model for every fitted pair, with the data's random error.

    Parameters
    ----------
    model : StateSpaceModel
    theta : array_like
        Full parameter vector.
    pairs : list of PairData
        The fitted pairs (:func:`livesweep.ident.state_space.select_pairs`).
    frs : FrequencyResponseSet
        The responses the pairs came from (for the random error).
    """
    out = []
    for p in pairs:
        mag, ph = model_misfit(model, theta, p)
        sdb, sdeg = _sigma(frs, p)
        out.append(PairResidual(p.output, p.input, p.omega, mag, ph, sdb, sdeg))
    return out


class ResidualSpace:
    """Stacked, whitened residual space of the fitted pairs with the model's Jacobian projected out."""

    def __init__(self, model, theta, pairs, frs, residuals=None):
        self.pairs = pairs
        self.res = residuals if residuals is not None else pair_residuals(model, theta, pairs, frs)
        self.sig = np.concatenate([np.concatenate([r.sigma_db, r.sigma_deg]) for r in self.res])
        self.r = np.concatenate([np.concatenate([r.magnitude_db, r.phase_deg]) for r in self.res]) / self.sig
        self.model, self.theta = model, theta
        self.band = band_of(pairs)
        self.free_names = {n for n, f in zip(model.parameters, model.fixed) if not f}
        self.full = self.log_jacobian_all(model, theta)
        # free parameters that may re-adjust; a delay held at its bound 0 cannot go negative, so
        # it does not absorb a phase lead (it stays out of the projection)
        at_bound = {k for k in model.delay_parameter_indices() if theta[k] <= 1e-9}
        free = [k for k in np.flatnonzero(~np.asarray(model.fixed)) if k not in at_bound]
        D = self.full[:, free]
        if D.shape[1]:
            D = D / np.maximum(np.linalg.norm(D, axis=0), 1e-300)
            U, s, _ = np.linalg.svd(D, full_matrices=False)
            self.Q = U[:, s > 1e-9 * s[0]]
        else:
            self.Q = D
        self.pr = self.project(self.r)
        self.base = float(self.pr @ self.pr)

    def project(self, v):
        v = np.asarray(v, float)
        return v - self.Q @ (self.Q.T @ v) if self.Q.shape[1] else v

    def log_jacobian_all(self, model, theta):
        """Whitened d(dB, deg)/d theta of the model, shape (n_points, n_parameters)."""
        parts = []
        for p in self.pairs:
            T, dT = model._response(theta, p.omega, jacobian=True)
            i, j = model.outputs.index(p.output), model.inputs.index(p.input)
            g = dT[:, i, j] / T[i, j][None, :]                       # (P, f)
            parts.append(np.concatenate([_DB * g.real, _DEG * g.imag], axis=1))
        return np.concatenate(parts, axis=1).T / self.sig[:, None]

    def log_jacobian(self, model, theta, k):
        """Column ``k`` of :meth:`log_jacobian_all` (cached for the space's own model)."""
        if model is self.model:
            return self.full[:, k]
        return self.log_jacobian_all(model, theta)[:, k]

    def evidence_at(self, model, theta) -> float:
        """Evidence of moving to ``model`` at ``theta`` (the space's model with a parameter changed
        or added): the drop of the whitened sum of squares from the exact residual there (not
        linearised in the change), after the space's model parameters re-adjust linearly."""
        parts = [np.concatenate(model_misfit(model, theta, p)) for p in self.pairs]
        pr = self.project(np.concatenate(parts) / self.sig)
        return self.base - float(pr @ pr)

    def signature(self, factor_fn, select):
        """Whitened (dB, deg) of ``ln factor(omega)`` on the selected pairs, zero elsewhere.

        ``factor_fn(omega) -> complex log-factor`` (array); ``select(pair) -> bool``.
        """
        parts = []
        for p in self.pairs:
            n = p.omega.size
            if select(p):
                L = factor_fn(p.omega)
                parts.append(np.concatenate([_DB * L.real, _DEG * L.imag]))
            else:
                parts.append(np.zeros(2 * n))
        return np.concatenate(parts) / self.sig

    def linear(self, v):
        """Best amplitude and evidence of a signature linear in one parameter."""
        pv = self.project(v)
        den = float(pv @ pv)
        if den <= 1e-12 * max(1.0, float(v @ v)):
            return 0.0, 0.0
        a = float(pv @ self.pr) / den
        return a, a * a * den

    def sensitivity(self, v) -> float:
        """Evidence of a signature of unit amplitude once the model's own parameters have taken up
        what they can (0: it cannot be told from a change of the model's parameters)."""
        pv = self.project(np.asarray(v, float))
        return float(pv @ pv)

    def shape(self, s):
        """Evidence of a fixed signature (no free amplitude)."""
        ps = self.project(s)
        return float(2 * ps @ self.pr - ps @ ps)

    def linear_grid(self, V):
        """Best amplitude and evidence per column of V (vectorised :meth:`linear`)."""
        PV = V - self.Q @ (self.Q.T @ V) if self.Q.shape[1] else V
        den = np.sum(PV**2, axis=0)
        num = PV.T @ self.pr
        with np.errstate(divide="ignore", invalid="ignore"):
            a = np.where(den > 1e-12, num / den, 0.0)
        return a, a * num


def band_of(pairs):
    """Lowest and highest fitting frequency of ``pairs`` [rad/s]."""
    lo = min(p.omega[0] for p in pairs)
    hi = max(p.omega[-1] for p in pairs)
    return lo, hi


def whitened_ss(residuals) -> float:
    """Sum of squares of the whitened residual of every pair (noise units)."""
    return float(sum(np.sum((r.magnitude_db / r.sigma_db) ** 2) + np.sum((r.phase_deg / r.sigma_deg) ** 2)
                     for r in residuals))
