"""Exact discretisation of linear systems, shared by the simulator and time-domain verification."""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

__all__ = ["discretize_foh", "discretize_zoh"]


def discretize_foh(A: np.ndarray, B: np.ndarray, dt: float):
    """First-order hold, exact for inputs linear between samples.

    Returns
    -------
    Phi, Gamma0, Gamma1 : ndarray
        ``x[k+1] = Phi x[k] + Gamma0 u[k] + Gamma1 u[k+1]``; step ``dt`` [s].
    """
    n, m = A.shape[0], B.shape[1]
    Z = np.zeros((n + 2 * m, n + 2 * m))
    Z[:n, :n] = A * dt
    Z[:n, n:n + m] = B * dt
    Z[n:n + m, n + m:] = np.eye(m)
    E = expm(Z)
    Phi, Ga, Gb = E[:n, :n], E[:n, n:n + m], E[:n, n + m:]
    return Phi, Ga - Gb, Gb


def discretize_zoh(A: np.ndarray, B: np.ndarray, dt: float) -> np.ndarray:
    """Zero-order hold input matrix: ``x[k+1] = Phi x[k] + Gamma w[k]`` for ``w`` constant over a step."""
    n, q = A.shape[0], B.shape[1]
    Z = np.zeros((n + q, n + q))
    Z[:n, :n] = A * dt
    Z[:n, n:] = B * dt
    return expm(Z)[:n, n:]
