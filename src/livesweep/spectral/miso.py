"""MISO conditioning for partially correlated inputs (method.md §6; Bendat & Piersol ch. 7).

For one output y and q inputs, per frequency, from the (q+1)x(q+1) spectral matrix S over
(x_1 .. x_q, y):

* conditioned responses ``H = Gxx^-1 g`` with ``g_i = G_{x_i y}`` (solved, never inverted);
* partial coherence of input i given all others ``|C_iy|^2 / (C_ii C_yy)`` with ``C = S^-1``;
* multiple coherence ``1 - G_nn / G_yy`` with ``G_nn = 1 / C_yy`` the output noise not explained by
  any input;
* a flag where the input matrix is ill-conditioned: the largest input-input coherence above
  ``max_input_coherence`` (0.5 by default: conditioning becomes unreliable, method.md §6.2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Conditioned", "condition_output", "input_coherence_max"]


@dataclass(frozen=True)
class Conditioned:
    """Conditioned result for one output.

    Attributes
    ----------
    H : ndarray, complex, shape (q, n_freq)
        Conditioned responses y/x_i with the other inputs removed.
    partial_coherence : ndarray, shape (q, n_freq)
    multiple_coherence : ndarray, shape (n_freq,)
    ill_conditioned : ndarray of bool, shape (n_freq,)
    """

    H: np.ndarray
    partial_coherence: np.ndarray
    multiple_coherence: np.ndarray
    ill_conditioned: np.ndarray


def input_coherence_max(G: np.ndarray, inputs: list[int]) -> np.ndarray:
    """Largest ordinary coherence between any two inputs, per frequency (0 for one input)."""
    best = np.zeros(G.shape[-1])
    for a in range(len(inputs)):
        for b in range(a + 1, len(inputs)):
            i, j = inputs[a], inputs[b]
            den = G[i, i].real * G[j, j].real
            with np.errstate(divide="ignore", invalid="ignore"):
                c = np.where(den > 0, np.abs(G[i, j]) ** 2 / den, 1.0)
            best = np.maximum(best, np.clip(c, 0, 1))
    return best


def condition_output(G: np.ndarray, inputs: list[int], output: int, *, max_input_coherence: float = 0.5) -> Conditioned:
    """Condition output ``output`` on the inputs ``inputs`` (indices into G's signal axis).

    Parameters
    ----------
    G : ndarray, complex, shape (n_signals, n_signals, n_freq)
        Spectral matrix (conjugate on the first index).
    inputs : list of int
    output : int
    max_input_coherence : float
        Above this input-input coherence the frequency is flagged ill-conditioned.

    Returns
    -------
    Conditioned
    """
    idx = list(inputs) + [output]
    q = len(inputs)
    S = np.moveaxis(G[np.ix_(idx, idx)], -1, 0)  # (n_freq, q+1, q+1)
    Gxx, g = S[:, :q, :q], S[:, :q, q]
    n_f = S.shape[0]
    H = np.full((n_f, q), np.nan + 0j)
    pc = np.zeros((n_f, q))
    mc = np.zeros(n_f)
    scale = np.sqrt(np.abs(np.diagonal(S, axis1=1, axis2=2).real))
    ok = np.all(scale > 0, axis=1)
    if np.any(ok):
        # Scale to unit diagonal (coherence matrix) before solving: the condition number then measures
        # input correlation, not units.
        D = scale[ok]
        Sn = S[ok] / (D[:, :, None] * D[:, None, :])
        C = np.linalg.inv(Sn)
        Cyy = C[:, q, q].real
        Cii = np.diagonal(C[:, :q, :q], axis1=1, axis2=2).real
        Ciy = C[:, :q, q]
        with np.errstate(divide="ignore", invalid="ignore"):
            pc[ok] = np.clip(np.abs(Ciy) ** 2 / (Cii * Cyy[:, None]), 0, 1)
            mc[ok] = np.clip(1.0 - 1.0 / Cyy, 0, 1)
        H[ok] = np.linalg.solve(Gxx[ok], g[ok][..., None])[..., 0]
    ill = input_coherence_max(G, list(inputs)) > max_input_coherence
    return Conditioned(H=H.T, partial_coherence=pc.T, multiple_coherence=mc, ill_conditioned=ill | ~ok)
