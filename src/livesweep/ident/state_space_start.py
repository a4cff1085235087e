"""Initial values for a state-space fit by frequency-domain equation error (docs/method.md §8.3).

The state equations ``M x' = F x + G u`` are affine in the parameters; with every state read from
the measured responses (a constant multiple of one output, or a parameter-free kinematic row) they
give one complex linear least-squares problem per row, weighted by coherence. Its solution is a
start for :func:`~livesweep.ident.state_space.fit_state_space`, not a result.
"""

from __future__ import annotations

import numpy as np

from livesweep.errors import ConfigError
from livesweep.ident.cost import MIN_COHERENCE
from livesweep.ident.state_space_model import StateSpaceModel

__all__ = ["equation_error_start"]


def equation_error_start(model: StateSpaceModel, frs, *, band_rad_s=None, min_coherence: float = MIN_COHERENCE):
    """Quick initial values by frequency-domain equation error (docs/method.md §8.3's third source).

    Works when every state can be read from the responses: each state is either a constant,
    parameter-free multiple of one output (``H`` row with a single constant non-zero entry and a
    zero ``J`` row), or follows from a parameter-free state equation (``x_i = x_j / (jw)``-type
    kinematics). The state equations, affine in the parameters, then give one complex linear
    least-squares problem per row, weighted by coherence, solved for the free parameters of
    ``M``, ``F`` and ``G`` at every grid frequency where the pair has usable coherence (inputs
    delayed by the initial delays). Parameters appearing only in ``H``/``J``/delays keep their
    initial values.

    Parameters
    ----------
    model : StateSpaceModel
    frs : FrequencyResponseSet
    band_rad_s : (float, float), optional
        Frequencies to use [rad/s]; default the whole set.
    min_coherence : float

    Returns
    -------
    ndarray
        Full parameter vector (a start for :func:`~livesweep.ident.state_space.fit_state_space`).

    Raises
    ------
    ConfigError
        When some state cannot be reconstructed from the outputs or an equation row is not affine.
    """
    n, m = len(model.states), len(model.inputs)
    theta = np.array(model.initial, float)
    omega = np.asarray(frs.omega, float)
    keep = np.ones(omega.size, bool) if band_rad_s is None else (omega >= band_rad_s[0]) & (omega <= band_rad_s[1])
    w = omega[keep]
    s = 1j * w
    Ms, Fs, Gs, Hs, Js, tau = model.matrices(theta)
    # state responses X[i] (f, m) and their coherence weights
    X = [None] * n
    C = [None] * n
    for r, o in enumerate(model.outputs):
        if o not in frs.outputs:
            continue
        hrow, jrow = model.H[r], model.J[r]
        nz = [j for j, e in enumerate(hrow) if not (e.is_constant and e.value(theta) == 0.0)]
        if len(nz) != 1 or not hrow[nz[0]].is_constant or any(not (e.is_constant and e.value(theta) == 0.0) for e in jrow):
            continue
        i = nz[0]
        if X[i] is not None:
            continue
        a = frs.outputs.index(o)
        if not all(u in frs.inputs for u in model.inputs):
            break
        b = [frs.inputs.index(u) for u in model.inputs]
        X[i] = frs.H[a][b][:, keep].T / hrow[i].value(theta)
        C[i] = frs.coherence[a][b][:, keep].T
    for _ in range(n):                                   # kinematic rows: x_i from the others
        for i in range(n):
            if X[i] is not None:
                continue
            row = [model.M[i][j] for j in range(n)] + [model.F[i][j] for j in range(n)] + list(model.G[i])
            if any(not e.is_constant for e in row):
                continue
            others = [j for j in range(n) if j != i and (Fs[i, j] != 0 or Ms[i, j] != 0)]
            if any(X[j] is None for j in others):
                continue
            den = s * Ms[i, i] - Fs[i, i]
            num = sum((Fs[i, j] - s * Ms[i, j])[:, None] * X[j] for j in others) + Gs[i][None, :]
            X[i] = num / den[:, None]
            C[i] = np.min([C[j] for j in others], axis=0) if others else np.ones((w.size, m))
    missing = [model.states[i] for i in range(n) if X[i] is None]
    if missing:
        raise ConfigError(f"equation-error start: state(s) {', '.join(missing)} cannot be read from the outputs")
    Xa = np.stack(X, axis=0)                              # (n, f, m)
    Wc = np.min(np.stack(C, axis=0), axis=0)              # (f, m)
    good = np.all(np.isfinite(Xa), axis=0) & np.isfinite(Wc)
    Xa = np.where(good[None], Xa, 0.0)
    Wc = np.where(good, Wc, 0.0)
    U = np.exp(-s[:, None] * tau[None, :])                # (f, m) delayed unit inputs
    free = model.free
    fpos = {k: a for a, k in enumerate(free)}
    for i in range(n):
        entries = ([("M", j, model.M[i][j]) for j in range(n)] + [("F", j, model.F[i][j]) for j in range(n)]
                   + [("G", j, model.G[i][j]) for j in range(m)])
        if all(e.is_constant for _, _, e in entries):
            continue
        if any(e.affine is None for _, _, e in entries):
            raise ConfigError(f"equation-error start: state equation {i} ({model.states[i]}) is not affine in the "
                              "parameters")
        # sum_j (s M_ij - F_ij) X_j - G_i U = 0, each entry = c0 + sum c_k theta_k
        A = np.zeros((w.size, m, free.size), complex)
        bvec = np.zeros((w.size, m), complex)
        for kind, j, e in entries:
            if kind == "M":
                base = s[:, None] * Xa[j]
            elif kind == "F":
                base = -Xa[j]
            else:
                base = np.zeros((w.size, m), complex)
                base[:, j] = -U[:, j]
            c0, terms = e.affine
            bvec -= c0 * base
            for k, c in terms:
                if k in fpos:
                    A[:, :, fpos[k]] += c * base
                else:
                    bvec -= c * theta[k] * base
        wt = np.sqrt(np.where(Wc >= min_coherence, Wc, 0.0))
        A = (A * wt[..., None]).reshape(-1, free.size)
        bvec = (bvec * wt).reshape(-1)
        cols = np.flatnonzero(np.any(A != 0, axis=0))
        if cols.size == 0:
            continue
        Ar = np.concatenate([A[:, cols].real, A[:, cols].imag])
        br = np.concatenate([bvec.real, bvec.imag])
        sol, *_ = np.linalg.lstsq(Ar, br, rcond=None)
        theta[free[cols]] = sol
    return theta
