"""Frequency responses through a common exogenous reference (method.md §4.6).

In a closed loop (a pilot or a SCAS stabilising the vehicle during the sweep) disturbances reach
the control inputs through the feedback, so the inputs are correlated with the output noise and
``G_xy / G_xx`` is biased towards the inverse of the feedback path wherever the disturbance
dominates (low frequency in turbulence). The sweep injection ``r`` is uncorrelated with the
disturbance; with one reference per input,

    y = T_yr r,   u = T_ur r   =>   T_yu = T_yr T_ur^-1

is unbiased. ``T_yr`` (outputs over references) and ``T_ur`` (inputs over references) are each a
composite MISO estimate (:func:`livesweep.spectral.composite.composite_miso`), then the
matrix ratio is taken per frequency.

Coherence and random error of a derived pair ``y_a / u_b``: reference ``b`` is injected on input
``b``, so the pair is as good as the weaker of its two legs. We report
``gamma^2 = gamma^2(y_a : r_b | other refs) * gamma^2(u_b : r_b | other refs)`` (product of the
partial coherences; the SISO form of the common-reference coherence product) and
``eps^2 = eps(y_a : r_b)^2 + eps(u_b : r_b)^2`` (method.md §4.6 propagation). Both are design
choices; CIFER's own assignment for derived responses is not documented (method.md §4.6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from livesweep.spectral.composite import composite_miso

__all__ = ["ReferencedResponses", "reference_responses", "combine_legs"]


@dataclass(frozen=True)
class ReferencedResponses:
    """Responses of outputs to inputs formed through references.

    Attributes
    ----------
    H : ndarray, complex, shape (n_out, n_in, n_freq)
        ``T_yr T_ur^-1`` [output units / input units].
    coherence : ndarray, shape (n_out, n_in, n_freq)
        Product of the two legs' partial coherences (see module docstring).
    random_error : ndarray, shape (n_out, n_in, n_freq)
        Normalised random error, the two legs added in quadrature.
    multiple_coherence : ndarray, shape (n_out, n_freq)
        Multiple coherence of each output on all references.
    ill_conditioned : ndarray of bool, shape (n_freq,)
        References cross-correlated above the limit, or ``T_ur`` singular.
    input_over_reference : ndarray, complex, shape (n_in, n_ref, n_freq)
        ``T_ur`` (for a sensitivity / broken-loop reading: ``u_b / r_b`` is the loop's S).
    """

    H: np.ndarray
    coherence: np.ndarray
    random_error: np.ndarray
    multiple_coherence: np.ndarray
    ill_conditioned: np.ndarray
    input_over_reference: np.ndarray


def reference_responses(windows, omega: np.ndarray, references: list[int], inputs: list[int], outputs: list[int],
                        max_input_coherence: float = 0.5, interpolated=None) -> ReferencedResponses:
    """Outputs over inputs through one reference per input.

    Parameters
    ----------
    windows : list of WindowSpectra
        Per-window spectral matrices holding every referenced signal.
    omega : ndarray
        Common grid [rad/s].
    references, inputs, outputs : list of int
        Signal indices into the windows' spectral matrices; ``references[b]`` is injected on
        ``inputs[b]``.
    max_input_coherence : float
        Reference cross-coherence above which a frequency is flagged ill-conditioned.
    interpolated : list of (ndarray, ndarray), optional
        :func:`livesweep.spectral.composite.interpolate_windows` of ``windows`` on ``omega``,
        when already computed.

    Returns
    -------
    ReferencedResponses
    """
    q = len(references)
    if len(inputs) != q:
        raise ValueError(f"one reference per input: {q} references for {len(inputs)} inputs")
    Tur, pc_u, _, eps_u, ill_u = composite_miso(windows, omega, references, inputs, max_input_coherence, interpolated)
    Tyr, pc_y, mc, eps_y, ill_y = composite_miso(windows, omega, references, outputs, max_input_coherence,
                                                 interpolated)
    ill = np.any(ill_u, axis=0) | np.any(ill_y, axis=0)
    return combine_legs(Tur, pc_u, eps_u, Tyr, pc_y, eps_y, mc, ill)


def combine_legs(Tur, pc_u, eps_u, Tyr, pc_y, eps_y, multiple, ill) -> ReferencedResponses:
    """``T_yu = T_yr T_ur^-1`` per frequency, with the coherence and error rules of the module
    docstring (shared by the batch composite and the live sliding window).

    Parameters
    ----------
    Tur, pc_u, eps_u : ndarray, shape (n_in, n_ref, n_freq)
        Inputs over references: responses, partial coherences, random errors.
    Tyr, pc_y, eps_y : ndarray, shape (n_out, n_ref, n_freq)
        Outputs over references.
    multiple : ndarray, shape (n_out, n_freq)
        Multiple coherence of each output on the references.
    ill : ndarray of bool, shape (n_freq,)
        Frequencies already flagged (reference cross-coherence).
    """
    q = Tur.shape[1]
    n = Tur.shape[-1]
    n_out, n_in = Tyr.shape[0], Tur.shape[0]
    A = np.moveaxis(Tur, -1, 0)                       # (n, n_in, q)
    B = np.moveaxis(Tyr, -1, 0)                       # (n, n_out, q)
    # Each output's row of T_yu = T_yr T_ur^-1 needs only its own row of T_yr: an output no
    # window resolves at a frequency (an accelerometer with no coherence there) loses that
    # frequency alone, not every other output's pairs with it.
    finite = np.all(np.isfinite(A), axis=(1, 2))
    rows = np.all(np.isfinite(B), axis=2)             # (n, n_out)
    with np.errstate(all="ignore"):
        cond = np.where(finite, np.linalg.cond(np.where(finite[:, None, None], A, np.eye(q))), np.inf)
    ok = finite & (cond < 1e8)
    good = (ok[:, None] & rows).T                     # (n_out, n)
    H = np.full((n_out, n_in, n), np.nan + 0j)
    if np.any(ok):
        # T_yu A = B  <=>  A^T T_yu^T = B^T, solved per frequency.
        Bz = np.where(rows[ok][:, :, None], B[ok], 0.0)
        X = np.linalg.solve(np.swapaxes(A[ok], 1, 2), np.swapaxes(Bz, 1, 2))   # (m, q=n_in, n_out)
        H[:, :, ok] = np.moveaxis(np.swapaxes(X, 1, 2), 0, -1)
        H = np.where(good[:, None, :], H, np.nan + 0j)
    diag_pc_u = np.array([pc_u[b, b] for b in range(q)])        # (n_in, n)
    diag_eps_u = np.array([eps_u[b, b] for b in range(q)])
    coh = np.where(good[:, None, :], pc_y * diag_pc_u[None, :, :], 0.0)
    eps = np.where(good[:, None, :], np.sqrt(eps_y**2 + diag_eps_u[None, :, :] ** 2), np.inf)
    return ReferencedResponses(H, coh, eps, np.where(good, multiple, 0.0), ill | ~ok, Tur)
