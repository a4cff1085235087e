"""Automatic starting values of a transfer-function fit.

Sanathanan-Koerner (iterated Levy) rational fits of the data for a few delay guesses, and
denominators with break frequencies log-spread over the band whose numerators are solved linearly
from the data; each gain read from the data's mean dB offset, its sign from the phase offset
(:func:`~livesweep.ident.transfer_function.fit_transfer_function` scores them all). Roots and
break frequencies in rad/s.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from livesweep.ident.cost import PairData
from livesweep.ident.transfer_function_problem import _Problem, _quad_roots

__all__ = []          # the fit's internals: nothing public

def _data(pair: PairData) -> np.ndarray:
    return 10.0 ** (pair.magnitude_db / 20.0) * np.exp(1j * np.deg2rad(pair.phase_deg))


def _fixed_product(facs, s):
    """Product of the s powers and the fully fixed factors at s."""
    out = np.ones(s.shape, complex)
    for kind, power, idx, fixed in facs:
        if kind == "s":
            out = out * s ** power
        elif all(i < 0 for i in idx):
            if kind == "first":
                out = out * (s + fixed[0])
            else:
                out = out * (s * s + 2 * fixed[0] * fixed[1] * s + fixed[1] ** 2)
    return out


def _free_factors(facs):
    return [(k, idx) for k, (kind, power, idx, fixed) in enumerate(facs)
            if kind != "s" and any(j >= 0 for j in idx)]


def _n_free_roots(facs) -> int:
    return sum(1 if facs[k][0] == "first" else 2 for k, _ in _free_factors(facs))


def _match_roots(roots, facs) -> list[tuple]:
    """Per-factor values for ``facs`` (compiled) from polynomial roots [rad/s]; non-free factors keep
    their fixed values. Surplus complex pairs become two real roots of the same modulus, surplus real
    roots are paired into quadratics (zeta may exceed 1)."""
    free = _free_factors(facs)
    n1 = sum(1 for k, _ in free if facs[k][0] == "first")
    n2 = len(free) - n1
    roots = np.asarray(roots, complex)
    roots = roots[np.isfinite(roots)]
    is_real = np.abs(roots.imag) <= 1e-8 * (np.abs(roots) + 1e-12)
    reals = sorted((float(r) for r in roots[is_real].real), key=abs)
    quads = [(-r.real / abs(r), abs(r)) for r in sorted(roots[~is_real & (roots.imag > 0)], key=abs)]
    while len(quads) > n2 and len(reals) < n1:
        z, w = max(quads, key=lambda q: q[0])
        quads.remove((z, w))
        reals += [-w if z >= 0 else w] * 2
    reals.sort(key=abs)
    while len(reals) > n1 and len(reals) >= 2 and len(quads) < n2:
        r1, r2 = reals.pop(0), reals.pop(0)
        w = math.sqrt(max(abs(r1 * r2), 1e-12))
        quads.append((-(r1 + r2) / (2 * w), w))
    quads.sort(key=lambda q: q[1])
    # pad (deficient polynomial degree) with values spread high
    while len(reals) < n1:
        reals.append(-(abs(reals[-1]) * 3 if reals else 1.0))
    while len(quads) < n2:
        quads.append((0.7, quads[-1][1] * 3 if quads else 1.0))
    vals = [tuple(f[3]) if f[0] != "s" else () for f in facs]
    it1, it2 = iter(reals), iter(quads)
    for k, _ in free:
        kind, power, idx, fixed = facs[k]
        if kind == "first":
            v = (-next(it1),)
        else:
            v = next(it2)
        vals[k] = tuple(fixed[j] if idx[j] < 0 else v[j] for j in range(len(idx)))
    return vals


def _factor_values_poly(facs, vals, s):
    """Value of the free factors' product at s, given per-factor values."""
    out = np.ones(s.shape, complex)
    for k, _ in _free_factors(facs):
        v = vals[k]
        if facs[k][0] == "first":
            out = out * (s + v[0])
        else:
            out = out * (s * s + 2 * v[0] * v[1] * s + v[1] ** 2)
    return out


def _sk_fit(prob: _Problem, tau: float, n_iter: int = 8):
    """Sanathanan-Koerner fit of data = B_p(s)/A(s) (A shared, monic; fixed factors, s powers and the
    delay guess divided out). Returns the den roots and the numerator roots per pair [rad/s]."""
    na = _n_free_roots(prob.den)
    omegas = [p.omega for p in prob.pairs]
    w0 = math.sqrt(min(o[0] for o in omegas) * max(o[-1] for o in omegas))
    Y, S, W, nb = [], [], [], []
    for p, pair in enumerate(prob.pairs):
        s = 1j * pair.omega
        tau_p = tau if prob.tau_idx[p] >= 0 else 0.0
        with np.errstate(all="ignore"):
            y = _data(pair) * np.exp(s * tau_p) * _fixed_product(prob.den, s) / _fixed_product(prob.num[p], s)
        Y.append(y)
        S.append(s / w0)
        W.append(np.sqrt(pair.weight))
        nb.append(_n_free_roots(prob.num[p]))
    n_unk = na + sum(b + 1 for b in nb)
    a = np.zeros(na)
    A_prev = [np.ones(len(y), complex) for y in Y]
    b_all = None
    for _ in range(n_iter):
        rows, rhs = [], []
        col = na
        for p, (y, sp, wp) in enumerate(zip(Y, S, W)):
            wt = wp / np.maximum(np.abs(y * A_prev[p]), 1e-300)
            M = np.zeros((len(y), n_unk), complex)
            for i in range(na):
                M[:, i] = y * sp ** i
            for j in range(nb[p] + 1):
                M[:, col + j] = -sp ** j
            col += nb[p] + 1
            r = -y * sp ** na
            rows.append(wt[:, None] * M)
            rhs.append(wt * r)
        M = np.vstack(rows)
        r = np.concatenate(rhs)
        Mr = np.vstack([M.real, M.imag])
        rr = np.concatenate([r.real, r.imag])
        if not (np.all(np.isfinite(Mr)) and np.all(np.isfinite(rr))):
            return None
        sol, *_ = np.linalg.lstsq(Mr, rr, rcond=None)
        a, b_all = sol[:na], sol[na:]
        A_prev = [np.polyval(np.concatenate([[1.0], a[::-1]]), sp) for sp in S]
    den_roots = np.roots(np.concatenate([[1.0], a[::-1]])) * w0 if na else np.array([])
    num_roots, col = [], 0
    for p in range(len(prob.pairs)):
        b = b_all[col:col + nb[p] + 1]
        col += nb[p] + 1
        num_roots.append(np.roots(b[::-1]) * w0 if nb[p] and np.any(b[1:] != 0) else np.array([]))
    return den_roots, num_roots


def _num_given_den(prob: _Problem, p: int, den_vals, tau: float):
    """Numerator roots of pair p by weighted linear least squares with the denominator and delay fixed."""
    pair = prob.pairs[p]
    s = 1j * pair.omega
    nb = _n_free_roots(prob.num[p])
    if nb == 0:
        return np.array([])
    w0 = math.sqrt(pair.omega[0] * pair.omega[-1])
    tau_p = tau if prob.tau_idx[p] >= 0 else 0.0
    with np.errstate(all="ignore"):
        den = _fixed_product(prob.den, s) * _factor_values_poly(prob.den, den_vals, s)
        y = _data(pair) * den * np.exp(s * tau_p) / _fixed_product(prob.num[p], s)
    wt = np.sqrt(pair.weight) / np.maximum(np.abs(y), 1e-300)
    sp = s / w0
    M = np.column_stack([sp ** j for j in range(nb + 1)]) * wt[:, None]
    rhs = y * wt
    Mr, rr = np.vstack([M.real, M.imag]), np.concatenate([rhs.real, rhs.imag])
    if not (np.all(np.isfinite(Mr)) and np.all(np.isfinite(rr))):
        return np.array([])
    b, *_ = np.linalg.lstsq(Mr, rr, rcond=None)
    return np.roots(b[::-1]) * w0 if np.any(b[1:] != 0) else np.array([])


def _gain_from_data(prob: _Problem, x: np.ndarray, p: int) -> float:
    """Gain magnitude from the weighted mean dB offset, sign from the weighted circular-mean phase offset
    (a negative gain is a 180 deg offset)."""
    pair = prob.pairs[p]
    x1 = x.copy()
    x1[prob.gain_idx[p]] = 1.0
    T1, _ = prob.response(x1, p)
    with np.errstate(all="ignore"):
        dmag = pair.magnitude_db - 20.0 * np.log10(np.abs(T1))
        dph = np.deg2rad(pair.phase_deg) - np.angle(T1)
    ok = np.isfinite(dmag) & np.isfinite(dph)
    if not np.any(ok):
        return 1.0
    w = pair.weight[ok]
    mag = 10.0 ** (np.sum(w * dmag[ok]) / np.sum(w) / 20.0)
    sign = 1.0 if np.real(np.sum(w * np.exp(1j * dph[ok]))) >= 0 else -1.0
    return sign * (mag if np.isfinite(mag) and mag > 0 else 1.0)


def _complete(prob: _Problem, den_vals, tau: float) -> np.ndarray:
    num_vals = [_match_roots(_num_given_den(prob, p, den_vals, tau), prob.num[p]) for p in range(len(prob.pairs))]
    taus = [tau] * len(prob.pairs)
    x = prob.pack(den_vals, num_vals, [1.0] * len(prob.pairs), taus)
    for p in range(len(prob.pairs)):
        x[prob.gain_idx[p]] = _gain_from_data(prob, x, p)
    return x


def _grid_den_candidates(prob: _Problem):
    """Denominator values from break frequencies log-spread over the band (shifted x1/3, x1, x3),
    every arrangement of first-order/quadratic kinds over the ascending slots (at most 6), damping 0.3/0.7."""
    free = _free_factors(prob.den)
    lo = min(p.omega[0] for p in prob.pairs)
    hi = max(p.omega[-1] for p in prob.pairs)
    if not free:
        return [[tuple(f[3]) if f[0] != "s" else () for f in prob.den]]
    kinds = [prob.den[k][0] for k, _ in free]
    arrangements = sorted(set(itertools.permutations(kinds)))[:6]
    m = len(free)
    out = []
    for shift in (1.0, 1.0 / 3.0, 3.0):
        slots = lo * (hi / lo) ** ((np.arange(m) + 0.5) / m) * shift
        for arr in arrangements:
            for zeta in (0.3, 0.7):
                firsts = [w for w, k in zip(slots, arr) if k == "first"]
                seconds = [w for w, k in zip(slots, arr) if k == "second"]
                roots = [-w for w in firsts] + [r for w in seconds for r in _quad_roots(zeta, w)]
                out.append(_match_roots(np.array(roots), prob.den))
    return out


def _auto_starts(prob: _Problem, tau_max: float) -> list[np.ndarray]:
    top = max(p.omega[-1] for p in prob.pairs)
    has_delay = any(i >= 0 for i in prob.tau_idx)
    taus = sorted({min(t, tau_max) for t in ((0.0, 0.5 / top, 1.0 / top) if has_delay else (0.0,))})
    starts = []
    for tau in taus:
        sk = _sk_fit(prob, tau)
        if sk is None:
            continue
        den_roots, num_roots = sk
        den_vals = _match_roots(den_roots, prob.den)
        starts.append(_complete(prob, den_vals, tau))
    for den_vals in _grid_den_candidates(prob):
        for tau in taus:
            starts.append(_complete(prob, den_vals, tau))
    return starts
