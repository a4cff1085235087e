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

__all__ = ["Conditioned", "condition_output", "condition_outputs", "condition_blocks", "coherences", "blocks",
           "input_coherence_max"]


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
    """Largest ordinary coherence between any two inputs, per frequency (0 for one input).

    Parameters
    ----------
    G : ndarray, complex, shape (..., n_signals, n_signals, n_freq)
        Spectral matrix or matrices (leading axes are kept).
    inputs : list of int
        Indices of the inputs on G's signal axes.

    Returns
    -------
    ndarray, shape (..., n_freq)
        In [0, 1]; 1 where an input has no power (the coherence is then undefined).
    """
    q = len(inputs)
    if q < 2:
        return np.zeros(G.shape[:-3] + G.shape[-1:])
    a, b = np.triu_indices(q, 1)
    ia, ib = np.asarray(inputs)[a], np.asarray(inputs)[b]
    g = G[..., ia, ib, :]                                           # (..., pairs, n_freq)
    den = G[..., ia, ia, :].real * G[..., ib, ib, :].real
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(den > 0, (g.real**2 + g.imag**2) / den, 1.0)
    return np.clip(c, 0, 1).max(axis=-2)


def coherences(S: np.ndarray, q: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Partial and multiple coherences of the last signal of each (q+1)x(q+1) block on the first q.

    From ``C = S_n^-1`` with ``S_n`` the block scaled to unit diagonal: partial coherence of input
    i ``|C_iy|^2 / (C_ii C_yy)``, multiple coherence ``1 - 1 / C_yy``.

    Parameters
    ----------
    S : ndarray, complex, shape (..., q + 1, q + 1, n_freq)
        Spectral blocks over ``(x_1 .. x_q, y)`` (conjugate on the first index).
    q : int
        Inputs per block.

    Returns
    -------
    partial : ndarray, shape (..., n_freq, q)
        0 where a block has a signal without power.
    multiple : ndarray, shape (..., n_freq)
    ok : ndarray of bool, shape (..., n_freq)
        Every signal of the block has power (elsewhere the coherences are 0).
    """
    M = np.moveaxis(S, -1, -3)                        # (..., n_freq, q+1, q+1)
    lead = M.shape[:-2]
    pc = np.zeros(lead + (q,))
    mc = np.zeros(lead)
    scale = np.sqrt(np.abs(np.diagonal(M, axis1=-2, axis2=-1).real))
    ok = np.all(scale > 0, axis=-1)
    if np.any(ok):
        # Scale to unit diagonal (coherence matrix) before inverting: the condition number then
        # measures input correlation, not units.
        D = scale[ok]
        C = np.linalg.inv(M[ok] / (D[:, :, None] * D[:, None, :]))
        Cyy = C[:, q, q].real
        Cii = np.diagonal(C[:, :q, :q], axis1=1, axis2=2).real
        Ciy = C[:, :q, q]
        with np.errstate(divide="ignore", invalid="ignore"):
            pc[ok] = np.clip(np.abs(Ciy) ** 2 / (Cii * Cyy[:, None]), 0, 1)
            mc[ok] = np.clip(1.0 - 1.0 / Cyy, 0, 1)
    return pc, mc, ok


def condition_blocks(S: np.ndarray, q: int, *, max_input_coherence: float = 0.5) -> Conditioned:
    """Condition the last signal of each (q+1)x(q+1) spectral block on the first q.

    The batched form of :func:`condition_output` (same arithmetic, any number of blocks).

    Parameters
    ----------
    S : ndarray, complex, shape (..., q + 1, q + 1, n_freq)
        Spectral blocks over ``(x_1 .. x_q, y)`` (conjugate on the first index).
    q : int
        Inputs per block.
    max_input_coherence : float
        Above this input-input coherence the frequency is flagged ill-conditioned.

    Returns
    -------
    Conditioned
        With the leading axes of ``S`` in front: ``H`` and ``partial_coherence`` (..., q, n_freq),
        ``multiple_coherence`` and ``ill_conditioned`` (..., n_freq).
    """
    pc, mc, ok = coherences(S, q)
    M = np.moveaxis(S, -1, -3)                        # (..., n_freq, q+1, q+1)
    H = np.full(ok.shape + (q,), np.nan + 0j)
    if np.any(ok):
        Mk = M[ok]
        H[ok] = np.linalg.solve(Mk[:, :q, :q], Mk[:, :q, q:])[..., 0]
    ill = input_coherence_max(S, list(range(q))) > max_input_coherence
    return Conditioned(H=np.moveaxis(H, -1, -2), partial_coherence=np.moveaxis(pc, -1, -2), multiple_coherence=mc,
                       ill_conditioned=ill | ~ok)


def blocks(G: np.ndarray, inputs: list[int], outputs: list[int]) -> np.ndarray:
    """The (q+1)x(q+1) block over ``(inputs, output)`` of G for every output.

    Parameters
    ----------
    G : ndarray, complex, shape (..., n_signals, n_signals, n_freq)
    inputs, outputs : list of int
        Indices on G's signal axes.

    Returns
    -------
    ndarray, complex, shape (..., n_outputs, q + 1, q + 1, n_freq)
    """
    idx = np.array([list(inputs) + [o] for o in outputs], dtype=np.intp)      # (n_out, q+1)
    return G[..., idx[:, :, None], idx[:, None, :], :]


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
    return condition_blocks(G[np.ix_(idx, idx)], len(inputs), max_input_coherence=max_input_coherence)


def condition_outputs(G: np.ndarray, inputs: list[int], outputs: list[int], *,
                      max_input_coherence: float = 0.5) -> Conditioned:
    """:func:`condition_output` for several outputs at once.

    Parameters
    ----------
    G : ndarray, complex, shape (n_signals, n_signals, n_freq)
    inputs, outputs : list of int
    max_input_coherence : float

    Returns
    -------
    Conditioned
        ``H``, ``partial_coherence`` (n_outputs, q, n_freq); ``multiple_coherence``,
        ``ill_conditioned`` (n_outputs, n_freq).
    """
    return condition_blocks(blocks(G, inputs, outputs), len(inputs), max_input_coherence=max_input_coherence)
