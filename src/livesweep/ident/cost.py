"""The frequency-response identification criterion (docs/method.md §7.1), in one place for every fitter.

For one pair, at ``n_omega`` = 20 log-spaced frequencies over that pair's band::

    J = (20 / n_omega) * sum_k W_gamma(w_k) * [ W_g (|T_data|dB - |T|dB)^2 + W_p (angle(T_data) - angle(T))^2_deg ]
    W_gamma = [1.58 (1 - exp(-gamma^2))]^2,   W_g = 1,   W_p = 0.01745

The phase error is wrapped into (-180, 180]. Fitters minimise the sum of squares of
:func:`residuals`, whose squares add up to exactly J, so ``J = sum(r^2)`` for any stacking of pairs.
Guidelines (docs/method.md §7.2): J <= 100 acceptable, J <= 50 excellent; multi-pair J_ave <= 100.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.spectral.criteria import DEFAULT_CRITERIA
from livesweep.spectral.response import FrequencyResponse

__all__ = ["W_G", "W_P", "N_OMEGA", "MIN_COHERENCE", "coherence_weight", "PairData", "select_band",
           "fit_points", "residuals", "pair_cost"]

W_G = 1.0
W_P = 0.01745
N_OMEGA = 20
#: The default fit-band threshold: the method's adequacy criterion (a case's ``[criteria]``
#: min_coherence reaches the fits through the stages' ``min_coherence`` arguments).
MIN_COHERENCE = DEFAULT_CRITERIA.min_coherence


def coherence_weight(coherence) -> np.ndarray:
    """``W_gamma = [1.58 (1 - exp(-gamma^2))]^2`` (gamma^2 is the coherence, not squared again)."""
    c = np.clip(np.asarray(coherence, float), 0.0, 1.0)
    return (1.58 * (1.0 - np.exp(-c))) ** 2


@dataclass(frozen=True)
class PairData:
    """One pair's data at its fitting points.

    Attributes
    ----------
    output, input : str
    omega : ndarray
        Fitting frequencies [rad/s], ``n_omega`` log-spaced over ``band_rad_s``.
    magnitude_db, phase_deg : ndarray
        Data response there (phase unwrapped along frequency).
    coherence : ndarray
    weight : ndarray
        W_gamma at each point.
    band_rad_s : (float, float)
    """

    output: str
    input: str
    omega: np.ndarray
    magnitude_db: np.ndarray
    phase_deg: np.ndarray
    coherence: np.ndarray
    weight: np.ndarray
    band_rad_s: tuple

    @property
    def n_omega(self) -> int:
        return int(self.omega.size)


def select_band(resp: FrequencyResponse, min_coherence: float = MIN_COHERENCE, band_rad_s=None):
    """The pair's fitting band: ``band_rad_s`` when given (clipped to the data), else the widest
    contiguous stretch (in decades) where gamma^2 >= ``min_coherence``. None when there is none
    spanning at least two grid points."""
    w = resp.omega
    if band_rad_s is not None:
        lo, hi = max(float(band_rad_s[0]), float(w[0])), min(float(band_rad_s[1]), float(w[-1]))
        return (lo, hi) if lo < hi else None
    ok = np.isfinite(resp.H) & (resp.coherence >= min_coherence)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))
    best = None
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a >= 2:
            span = np.log10(w[b - 1] / w[a])
            if best is None or span > best[0]:
                best = (span, float(w[a]), float(w[b - 1]))
    return None if best is None else (best[1], best[2])


def fit_points(resp: FrequencyResponse, band_rad_s=None, n_omega: int = N_OMEGA,
               min_coherence: float = MIN_COHERENCE) -> PairData:
    """The pair's data at ``n_omega`` log-spaced points of its band (interpolated in log frequency).

    Raises
    ------
    ConfigError
        When the pair has no usable coherence (naming the pair).
    """
    band = select_band(resp, min_coherence, band_rad_s)
    if band is None:
        raise ConfigError(f"pair {resp.output}/{resp.input} has no band with coherence >= {min_coherence:g}: "
                          "it cannot be fitted (drop it from the model's pairs or fly more excitation)")
    w = np.geomspace(band[0], band[1], n_omega)
    lw = np.log10(resp.omega)
    ok = np.isfinite(resp.H)
    mag = np.interp(np.log10(w), lw[ok], resp.magnitude_db[ok])
    ph = np.interp(np.log10(w), lw[ok], resp.phase_deg[ok])
    coh = np.interp(np.log10(w), lw[ok], resp.coherence[ok])
    return PairData(resp.output, resp.input, w, mag, ph, coh, coherence_weight(coh), band)


def residuals(pair: PairData, T_model) -> np.ndarray:
    """Weighted residuals whose squares sum to the pair's cost J (magnitude block, then phase block).

    Parameters
    ----------
    pair : PairData
    T_model : ndarray, complex
        Model response at ``pair.omega``.
    """
    T = np.asarray(T_model, complex)
    with np.errstate(divide="ignore"):
        mag = 20.0 * np.log10(np.abs(T))
    dphase = np.angle(np.exp(1j * np.deg2rad(pair.phase_deg)) / T, deg=True)   # wrapped to (-180, 180]
    scale = np.sqrt(20.0 / pair.n_omega * pair.weight)
    return np.concatenate([scale * np.sqrt(W_G) * (pair.magnitude_db - mag), scale * np.sqrt(W_P) * dphase])


def pair_cost(pair: PairData, T_model) -> float:
    """J of one pair (docs/method.md §7.1)."""
    r = residuals(pair, T_model)
    return float(np.dot(r, r))
