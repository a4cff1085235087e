"""Composite window optimisation: one response from several window lengths (method.md §5).

At each frequency of a common log-spaced grid, every window's spectral matrix is interpolated
(linearly, real and imaginary parts; the CZT grids are twice as dense as the window resolution)
and the composite spectra are the minimisers of the random-error-weighted quadratic cost

    J(w) = sum_i W_i(w) * [ |Gxx_c - Gxx_i|^2 + |Gyy_c - Gyy_i|^2 + |Gxy_c - Gxy_i|^2 ],
    W_i = 1 / eps_i(w)^2      (inverse variance; 0 where window i cannot resolve w),

whose closed-form solution is the W-weighted mean of each spectrum. Form chosen over the
published PYAI interpretation (BFGS per frequency with a coherence-consistency term): the
coherence term is unnecessary here because H_c = Gxy_c / Gxx_c and gamma^2_c = |Gxy_c|^2 /
(Gxx_c Gyy_c) are computed from the same composite spectra and so are consistent by
construction, and the closed form costs nothing. Short windows dominate where they have many
averages (high frequency), long windows where only they resolve the response (low frequency);
leakage near sharp features lowers a short window's coherence and so its weight.

The composite random error is reported conservatively as the smallest eps_i (the windows reuse
the same data, so 1/sum(1/eps_i^2) would be optimistic).

MISO: for one output, the whole (q+1)x(q+1) spectral block of (inputs, output) is combined with
weights from that output's multiple coherence (n_eff - q + 1 degrees of freedom), then conditioned
(conditioning commutes with the weighted average of a spectral matrix estimate).
"""

from __future__ import annotations

import numpy as np

from livesweep.spectral.miso import condition_output
from livesweep.spectral.spectra import WindowSpectra, coherence, random_error

__all__ = ["interpolate_window", "composite_pair", "composite_output_miso"]


def interpolate_window(ws: WindowSpectra, omega: np.ndarray, rows=None) -> tuple[np.ndarray, np.ndarray]:
    """A window's spectral block on ``omega``, and where that window can resolve it.

    Parameters
    ----------
    ws : WindowSpectra
    omega : ndarray
        Target frequencies [rad/s].
    rows : list of int, optional
        Signal indices of the block (default all).

    Returns
    -------
    G : ndarray, complex, shape (len(rows), len(rows), n)
    usable : ndarray of bool, shape (n,)
        ``omega`` inside the window's grid and at or above two periods per window.
    """
    rows = list(range(len(ws.names))) if rows is None else list(rows)
    G = ws.G[np.ix_(rows, rows)]
    pos = np.interp(omega, ws.omega, np.arange(ws.omega.size))
    k = np.clip(np.floor(pos).astype(int), 0, ws.omega.size - 2)
    f = pos - k
    Gi = G[..., k] * (1.0 - f) + G[..., k + 1] * f
    usable = (omega >= max(ws.omega[0], ws.omega_min_usable) - 1e-12) & (omega <= ws.omega[-1] + 1e-12)
    return Gi, usable


def _weighted(blocks, weights):
    W = np.asarray(weights)
    total = W.sum(axis=0)
    Gc = np.einsum("w...f,wf->...f", np.asarray(blocks), W)
    with np.errstate(divide="ignore", invalid="ignore"):
        return Gc / np.where(total > 0, total, np.nan), total > 0


def composite_pair(windows: list[WindowSpectra], omega: np.ndarray, i_in: int, i_out: int):
    """Composite SISO response of signal ``i_out`` to ``i_in``.

    Returns
    -------
    H : ndarray, complex
    coh : ndarray
        gamma^2 of the composite spectra.
    eps : ndarray
        min over windows of eps_r.
    """
    blocks, weights, eps_all = [], [], []
    for ws in windows:
        G, usable = interpolate_window(ws, omega, [i_in, i_out])
        eps = random_error(coherence(G, 0, 1), ws.n_eff)
        eps = np.where(usable, eps, np.inf)
        blocks.append(G)
        weights.append(np.where(np.isfinite(eps), 1.0 / eps**2, 0.0))
        eps_all.append(eps)
    Gc, ok = _weighted(blocks, weights)
    with np.errstate(divide="ignore", invalid="ignore"):
        H = np.where(ok, Gc[0, 1] / Gc[0, 0].real, np.nan + 0j)
    coh = np.where(ok, coherence(np.nan_to_num(Gc), 0, 1), 0.0)
    return H, coh, np.min(eps_all, axis=0)


def composite_output_miso(windows: list[WindowSpectra], omega: np.ndarray, inputs: list[int], output: int,
                          max_input_coherence: float = 0.5):
    """Composite MISO-conditioned responses of one output to all inputs.

    Returns
    -------
    H : ndarray, complex, shape (q, n)
    partial : ndarray, shape (q, n)
    multiple : ndarray, shape (n,)
    eps : ndarray, shape (q, n)
        min over windows of eps_r from each window's partial coherence with n_eff - q + 1 averages.
    ill : ndarray of bool, shape (n,)
    """
    q = len(inputs)
    rows = list(inputs) + [output]
    blocks, weights, eps_all = [], [], []
    for ws in windows:
        G, usable = interpolate_window(ws, omega, rows)
        c = condition_output(G, list(range(q)), q, max_input_coherence=max_input_coherence)
        dof = max(ws.n_eff - q + 1, 1.0)
        w_eps = np.where(usable, random_error(c.multiple_coherence, dof), np.inf)
        blocks.append(G)
        weights.append(np.where(np.isfinite(w_eps), 1.0 / w_eps**2, 0.0))
        eps_all.append(np.where(usable[None, :], random_error(c.partial_coherence, dof), np.inf))
    Gc, ok = _weighted(blocks, weights)
    c = condition_output(np.nan_to_num(Gc), list(range(q)), q, max_input_coherence=max_input_coherence)
    H = np.where(ok[None, :], c.H, np.nan + 0j)
    return (H, np.where(ok, c.partial_coherence, 0.0), np.where(ok, c.multiple_coherence, 0.0),
            np.min(eps_all, axis=0), c.ill_conditioned | ~ok)
