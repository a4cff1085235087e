"""The parameter layout, residuals and Jacobian of a (joint) transfer-function fit (docs/method.md §7.1).

The parameter vector is ``x = [shared denominator parameters] + per pair [gain, numerator
parameters, tau (if delay)]``; :class:`_Problem` evaluates each pair's response ``T(jw)`` and
``d ln T / dx`` factor by factor and maps them through the cost's own residual function
(:func:`livesweep.ident.cost.residuals`), so ``sum r^2`` is J summed over the pairs.
"""

from __future__ import annotations

import numpy as np

from livesweep.ident.cost import PairData, residuals
from livesweep.ident.transfer_function_structure import Structure, TransferFunctionModel

__all__ = []          # the fit's internals: nothing public

_EPS_CAL = 1e-6          # step [neper / rad] used to read the cost's residual map (exact: the map is linear)
_BIG = 1e6               # residual substituted where the model response is not finite


def _quad_roots(zeta: float, w: float) -> np.ndarray:
    d = np.sqrt(complex(zeta * zeta - 1.0))
    return np.array([-zeta * w + w * d, -zeta * w - w * d])


class _Problem:
    """Parameter layout and residuals of a (joint) fit.

    x = [shared denominator parameters] + per pair [gain, numerator parameters, tau (if delay)].
    A compiled factor is ``(kind, power, idx, fixed)``: ``idx`` holds an x index or -1 per value.
    """

    def __init__(self, pairs: list[PairData], models: list[TransferFunctionModel], tau_max: float):
        self.pairs, self.models = pairs, models
        self.keys: list[tuple] = []        # (pair index or None for shared, key)
        lo: list[float] = []
        hi: list[float] = []
        w_floor = 1e-6 * min(float(p.omega[0]) for p in pairs)

        def compile_structure(st: Structure, scope):
            out = []
            for f in st.factors:
                idx = []
                for j, key in enumerate(f.keys):
                    if key is None:
                        idx.append(-1)
                        continue
                    idx.append(len(self.keys))
                    self.keys.append((scope, key))
                    is_w = f.kind == "second" and j == 1
                    lo.append(w_floor if is_w else -np.inf)
                    hi.append(np.inf)
                out.append((f.kind, f.power, tuple(idx), f.fixed))
            return out

        self.den = compile_structure(models[0].denominator, None)
        self.n_den = len(self.keys)
        self.gain_idx, self.num, self.tau_idx, self.slices = [], [], [], []
        for p, m in enumerate(models):
            start = len(self.keys)
            self.gain_idx.append(len(self.keys))
            self.keys.append((p, "gain"))
            lo.append(-np.inf)
            hi.append(np.inf)
            self.num.append(compile_structure(m.numerator, p))
            if m.delay:
                self.tau_idx.append(len(self.keys))
                self.keys.append((p, "tau"))
                lo.append(0.0)
                hi.append(tau_max)
            else:
                self.tau_idx.append(-1)
            self.slices.append(slice(start, len(self.keys)))
        self.lower, self.upper = np.array(lo), np.array(hi)
        self.n = len(self.keys)
        self.n_resid = sum(2 * p.n_omega for p in pairs)

    # -- model

    @staticmethod
    def _factor(kind, power, idx, fixed, x, s, want_grad):
        vals = [x[i] if i >= 0 else fixed[j] for j, i in enumerate(idx)]
        if kind == "s":
            return s ** power, []
        if kind == "first":
            f = s + vals[0]
            return f, ([(idx[0], 1.0 / f)] if want_grad and idx[0] >= 0 else [])
        z, w = vals
        f = s * s + 2.0 * z * w * s + w * w
        g = []
        if want_grad:
            if idx[0] >= 0:
                g.append((idx[0], 2.0 * w * s / f))
            if idx[1] >= 0:
                g.append((idx[1], (2.0 * z * s + 2.0 * w) / f))
        return f, g

    def response(self, x, p, omega=None, want_grad=False):
        """T(j omega) of pair p and, optionally, d ln T / dx (complex, shape (n_omega, n))."""
        s = 1j * (self.pairs[p].omega if omega is None else np.asarray(omega, float))
        G = np.zeros((s.size, self.n), complex) if want_grad else None
        K = x[self.gain_idx[p]]
        T = np.full(s.shape, complex(K))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for sign, facs in ((1, self.num[p]), (-1, self.den)):
                for kind, power, idx, fixed in facs:
                    f, grads = self._factor(kind, power, idx, fixed, x, s, want_grad)
                    T = T * f if sign > 0 else T / f
                    for i, g in grads:
                        G[:, i] += sign * g
            if self.tau_idx[p] >= 0:
                T = T * np.exp(-s * x[self.tau_idx[p]])
                if want_grad:
                    G[:, self.tau_idx[p]] = -s
            if want_grad:
                G[:, self.gain_idx[p]] = 1.0 / K
        return T, G

    def _pair_resid(self, T, pair):
        if not np.all(np.isfinite(T)) or np.any(T == 0):
            return None
        return residuals(pair, T)

    def resid(self, x):
        out = []
        for p, pair in enumerate(self.pairs):
            T, _ = self.response(x, p)
            r = self._pair_resid(T, pair)
            out.append(np.full(2 * pair.n_omega, _BIG) if r is None else r)
        return np.concatenate(out)

    def jac(self, x):
        """dr/dx: the model's d ln T mapped through the cost's residual function, whose magnitude block
        depends on Re ln T and phase block on Im ln T point by point (read off with a tiny step, exact
        because the map is linear in ln T)."""
        rows = []
        for p, pair in enumerate(self.pairs):
            T, G = self.response(x, p, want_grad=True)
            n = pair.n_omega
            r0 = self._pair_resid(T, pair)
            if r0 is None:
                rows.append(np.zeros((2 * n, self.n)))
                continue
            a = (residuals(pair, T * np.exp(_EPS_CAL)) - r0) / _EPS_CAL
            b = (residuals(pair, T * np.exp(1j * _EPS_CAL)) - r0) / _EPS_CAL
            k = np.concatenate([np.arange(n), np.arange(n)])
            Jp = a[:, None] * G.real[k] + b[:, None] * G.imag[k]
            rows.append(np.where(np.isfinite(Jp), Jp, 0.0))
        return np.vstack(rows)

    def cost(self, x) -> float:
        r = self.resid(x)
        return float(np.dot(r, r))

    def pair_costs(self, x) -> list[float]:
        out = []
        for p, pair in enumerate(self.pairs):
            T, _ = self.response(x, p)
            r = self._pair_resid(T, pair)
            out.append(float("inf") if r is None else float(np.dot(r, r)))
        return out

    # -- assembling a start from factor values

    def pack(self, den_vals, num_vals, gains, taus) -> np.ndarray:
        """x from per-factor value tuples (den shared, num per pair), gains and delays per pair."""
        x = np.zeros(self.n)
        for facs, vals in [(self.den, den_vals)] + [(self.num[p], num_vals[p]) for p in range(len(self.pairs))]:
            for (kind, power, idx, fixed), v in zip(facs, vals):
                for i, val in zip(idx, v):
                    if i >= 0:
                        x[i] = val
        for p in range(len(self.pairs)):
            x[self.gain_idx[p]] = gains[p]
            if self.tau_idx[p] >= 0:
                x[self.tau_idx[p]] = taus[p]
        return np.clip(x, self.lower, self.upper)
