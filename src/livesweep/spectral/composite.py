"""Composite window optimisation: one response from several window lengths (method.md §5).

At each frequency of a common log-spaced grid, every window's spectral matrix is interpolated
(linearly, real and imaginary parts; the zero-padded FFT grids are twice as dense as the window
resolution)
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

Every pair and every output is composited at once (:func:`composite_siso`, :func:`composite_miso`),
from one interpolation of each window's whole spectral matrix (:func:`interpolate_windows`).
"""

from __future__ import annotations

import numpy as np

from livesweep.spectral.miso import blocks, coherences, condition_blocks
from livesweep.spectral.spectra import WindowSpectra, random_error

__all__ = ["interpolate_window", "interpolate_windows", "composite_pair", "composite_output_miso", "composite_siso",
           "composite_miso"]


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
        ``omega`` inside the window's grid and at or above ``MIN_PERIODS_PER_WINDOW`` periods per
        window.
    """
    G = ws.G if rows is None else ws.G[np.ix_(list(rows), list(rows))]
    pos = np.interp(omega, ws.omega, np.arange(ws.omega.size))
    k = np.clip(np.floor(pos).astype(int), 0, ws.omega.size - 2)
    f = pos - k
    Gi = G[..., k] * (1.0 - f) + G[..., k + 1] * f
    usable = (omega >= max(ws.omega[0], ws.omega_min_usable) - 1e-12) & (omega <= ws.omega[-1] + 1e-12)
    return Gi, usable


def interpolate_windows(windows, omega: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`interpolate_window` of every window's whole spectral matrix (computed once, shared by
    the SISO, MISO and input-coherence composites)."""
    return [interpolate_window(ws, omega) for ws in windows]


def _inverse_variance(eps: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(eps), 1.0 / eps**2, 0.0)


def _normalise(total: np.ndarray):
    """``1 / total`` where some window has weight (NaN elsewhere), and where that is."""
    ok = total > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        return 1.0 / np.where(ok, total, np.nan), ok


def composite_siso(windows, omega: np.ndarray, inputs: list[int], outputs: list[int], interpolated=None):
    """Composite SISO responses of every output to every input.

    Per pair and frequency the composite spectra ``G_xx, G_yy, G_xy`` are the inverse-variance
    weighted means over the windows (weights ``1 / eps_r^2`` from that window's coherence of the
    pair, 0 where it cannot resolve the frequency); ``H = G_xy / G_xx``.

    Parameters
    ----------
    windows : list of WindowSpectra
    omega : ndarray, shape (n,)
        Common grid [rad/s].
    inputs, outputs : list of int
        Signal indices into the windows' spectral matrices.
    interpolated : list of (ndarray, ndarray), optional
        :func:`interpolate_windows` of ``windows`` on ``omega``, when already computed.

    Returns
    -------
    H : ndarray, complex, shape (n_out, n_in, n)
        NaN where no window resolves the frequency.
    coh : ndarray, shape (n_out, n_in, n)
        gamma^2 of the composite spectra.
    eps : ndarray, shape (n_out, n_in, n)
        Smallest eps_r over the windows.
    """
    inputs, outputs = list(inputs), list(outputs)
    interpolated = interpolate_windows(windows, omega) if interpolated is None else interpolated
    shape = (len(outputs), len(inputs), omega.size)
    sxy, total = np.zeros(shape, complex), np.zeros(shape)
    sxx, syy = np.zeros(shape), np.zeros(shape)
    eps_min = np.full(shape, np.inf)
    for ws, (G, usable) in zip(windows, interpolated):
        gxx = np.einsum("iif->if", G).real
        gxy = G[np.ix_(inputs, outputs)].transpose(1, 0, 2)          # (n_out, n_in, n): G[x, y]
        den = gxx[inputs][None, :, :] * gxx[outputs][:, None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            coh = np.clip(np.where(den > 0, (gxy.real**2 + gxy.imag**2) / den, 0.0), 0.0, 1.0)
        eps = np.where(usable, random_error(coh, ws.n_eff), np.inf)
        W = _inverse_variance(eps)
        total += W
        sxy += W * gxy
        sxx += W * gxx[inputs][None, :, :]
        syy += W * gxx[outputs][:, None, :]
        np.minimum(eps_min, eps, out=eps_min)
    inv, ok = _normalise(total)
    gxx_c, gyy_c, gxy_c = sxx * inv, syy * inv, sxy * inv
    with np.errstate(divide="ignore", invalid="ignore"):
        H = np.where(ok, gxy_c / gxx_c, np.nan + 0j)
        gxx0, gyy0 = np.nan_to_num(gxx_c), np.nan_to_num(gyy_c)
        den = gxx0 * gyy0
        num = np.abs(np.nan_to_num(gxy_c)) ** 2
        coh = np.where(ok, np.clip(np.where(den > 0, num / den, 0.0), 0.0, 1.0), 0.0)
    return H, coh, eps_min


def composite_miso(windows, omega: np.ndarray, inputs: list[int], outputs: list[int],
                   max_input_coherence: float = 0.5, interpolated=None):
    """Composite MISO-conditioned responses of every output to all inputs.

    For each output the whole (q+1)x(q+1) spectral block over (inputs, output) is averaged over
    the windows with weights ``1 / eps_r^2`` from that window's multiple coherence
    (``n_eff - q + 1`` degrees of freedom), then conditioned.

    Parameters
    ----------
    windows : list of WindowSpectra
    omega : ndarray, shape (n,)
        Common grid [rad/s].
    inputs, outputs : list of int
        Signal indices into the windows' spectral matrices.
    max_input_coherence : float
        Input cross-coherence above which a frequency is flagged ill-conditioned.
    interpolated : list of (ndarray, ndarray), optional
        :func:`interpolate_windows` of ``windows`` on ``omega``, when already computed.

    Returns
    -------
    H : ndarray, complex, shape (n_out, q, n)
    partial : ndarray, shape (n_out, q, n)
    multiple : ndarray, shape (n_out, n)
    eps : ndarray, shape (n_out, q, n)
        Smallest eps_r over the windows, from each window's partial coherence with ``n_eff - q + 1``
        averages.
    ill : ndarray of bool, shape (n_out, n)
    """
    inputs, outputs = list(inputs), list(outputs)
    q = len(inputs)
    interpolated = interpolate_windows(windows, omega) if interpolated is None else interpolated
    n_out = len(outputs)
    S = np.zeros((n_out, q + 1, q + 1, omega.size), complex)
    total = np.zeros((n_out, omega.size))
    eps_min = np.full((n_out, q, omega.size), np.inf)
    for ws, (G, usable) in zip(windows, interpolated):
        B = blocks(G, inputs, outputs)                                  # (n_out, q+1, q+1, n)
        pc, mc, _ = coherences(B, q)                                    # (n_out, n, q), (n_out, n)
        dof = max(ws.n_eff - q + 1, 1.0)
        W = _inverse_variance(np.where(usable, random_error(mc, dof), np.inf))
        total += W
        S += W[:, None, None, :] * B
        np.minimum(eps_min, np.where(usable, random_error(np.moveaxis(pc, -1, -2), dof), np.inf), out=eps_min)
    inv, ok = _normalise(total)
    c = condition_blocks(np.nan_to_num(S * inv[:, None, None, :]), q, max_input_coherence=max_input_coherence)
    H = np.where(ok[:, None, :], c.H, np.nan + 0j)
    return (H, np.where(ok[:, None, :], c.partial_coherence, 0.0), np.where(ok, c.multiple_coherence, 0.0),
            eps_min, c.ill_conditioned | ~ok)


def composite_pair(windows: list[WindowSpectra], omega: np.ndarray, i_in: int, i_out: int):
    """Composite SISO response of signal ``i_out`` to ``i_in`` (:func:`composite_siso` of one pair).

    Returns
    -------
    H : ndarray, complex
    coh : ndarray
        gamma^2 of the composite spectra.
    eps : ndarray
        min over windows of eps_r.
    """
    H, coh, eps = composite_siso(windows, omega, [i_in], [i_out])
    return H[0, 0], coh[0, 0], eps[0, 0]


def composite_output_miso(windows: list[WindowSpectra], omega: np.ndarray, inputs: list[int], output: int,
                          max_input_coherence: float = 0.5):
    """Composite MISO-conditioned responses of one output to all inputs (:func:`composite_miso`
    of one output).

    Returns
    -------
    H : ndarray, complex, shape (q, n)
    partial : ndarray, shape (q, n)
    multiple : ndarray, shape (n,)
    eps : ndarray, shape (q, n)
        min over windows of eps_r from each window's partial coherence with n_eff - q + 1 averages.
    ill : ndarray of bool, shape (n,)
    """
    H, pc, mc, eps, ill = composite_miso(windows, omega, inputs, [output], max_input_coherence)
    return H[0], pc[0], mc[0], eps[0], ill[0]
