"""Model selection for the residual loop: is an added effect supported by the data, counting its
parameters and the correlation of neighbouring frequency points?

The residual loop compares whitened sums of squares (residual over the data's random error, in
dB and deg, summed over the fitting points of every pair). Neighbouring points of a spectral
estimate are not independent: a window of length ``T`` resolves ``B = 1.5 (2 pi / T)`` rad/s
(the equivalent noise bandwidth of the Hann taper), so a pair fitted at ``n`` log-spaced points
holds about ``sum_i min(1, d omega_i / B(omega_i))`` independent ones. At each frequency the
composite response weights every window that resolves it by its inverse variance, which at equal
coherence is its number of averages, so ``B(omega)`` is that weighted mean of the windows'
``B``. Points below the coherence threshold are not fitted and do not count.

With ``N`` independent points (magnitude and phase counted apart), ``p`` free model parameters and
an effect of ``k`` parameters that lowers the whitened sum of squares from ``S0`` to ``S1``,

    F = ((S0 - S1) / k) / (S1 / (N - p - k))

would follow Fisher's F(k, N - p - k) if the residual of a model without the effect were white
noise at that resolution: the correlation of the points scales numerator and denominator alike
and cancels, and so does any error in the random-error estimate's level. It is not quite white:
bias errors of the spectral estimates and the shape grids' search over frequency make a clean
residual project onto effect signatures more than noise would. On 28 clean simulated cruise logs
(XV-15, seeds 30-43 at full and half turbulence; ``benchmarks/residual_confusion.py
--calibrate``) the plain test called half of them significant, the largest drop 4.8 times what it
needed. So ``F / NOISE_INFLATION`` is tested (:data:`NOISE_INFLATION` = 6, 1.25 times that
largest): an effect must lower the sum of squares six times as much as white noise of the
residual's level would at the test's level. The false-alarm rate on held-out clean logs (other
seeds, the hover airframe, the quadrotor) is stated in the README. The residual loop screens ``m`` candidates (kinds x places) and keeps the
best, so each is tested at ``alpha / m`` (Bonferroni): the probability of adding an effect to a
clean log is at most about :data:`FALSE_ALARM` per step.

Rivals (two candidates that both pass) are compared the same way: the one with more parameters
is preferred only if its extra parameters lower the sum of squares significantly
(:func:`prefers`); two whose sums of squares differ by less than the noise of one parameter are
reported as hard to tell apart (:func:`indistinguishable`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

__all__ = ["FALSE_ALARM", "ENBW_HANN", "NOISE_INFLATION", "effective_points", "Significance", "significance", "prefers",
           "indistinguishable"]

#: Family-wise probability, per loop step, of adding an effect to a log that has none.
FALSE_ALARM = 0.01
#: Equivalent noise bandwidth of the Hann taper [bins].
ENBW_HANN = 1.5
#: How much more a clean residual projects onto an effect's signature than white noise would,
#: measured on clean simulated cruise logs (module docstring): the F statistic is divided by it.
NOISE_INFLATION = 6.0


def _resolution(omega, settings) -> np.ndarray | None:
    """Composite resolution bandwidth at ``omega`` [rad/s] from the analysis settings, or None."""
    avgs = settings.get("averages") if isinstance(settings, dict) else None
    if not avgs:
        return None
    from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW

    T = np.array([float(a["window_s"]) for a in avgs])
    n = np.array([max(float(a.get("n_eff", 1.0)), 1e-9) for a in avgs])
    B = ENBW_HANN * 2 * np.pi / T
    usable = omega[:, None] >= MIN_PERIODS_PER_WINDOW * 2 * np.pi / T[None, :] - 1e-12
    w = np.where(usable, n[None, :], 0.0)
    w[~usable.any(axis=1), int(np.argmax(T))] = 1.0          # below every window's reach: the longest
    return (w @ B) / w.sum(axis=1)


def effective_points(pairs, settings) -> float:
    """Independent values (magnitude and phase apart) in the fitting points of ``pairs``.

    Parameters
    ----------
    pairs : list of PairData
        The fitted pairs (their ``omega`` [rad/s], increasing).
    settings : dict
        The analysis settings of their frequency responses (``FrequencyResponseSet.settings``);
        without windows every point counts as independent.

    Returns
    -------
    float
    """
    total = 0.0
    for p in pairs:
        w = np.asarray(p.omega, float)
        B = _resolution(w, settings)
        if B is None or w.size < 2:
            total += w.size
            continue
        edges = np.sqrt(w[1:] * w[:-1])
        lo = np.concatenate([[w[0] - (edges[0] - w[0])], edges])
        hi = np.concatenate([edges, [w[-1] + (w[-1] - edges[-1])]])
        total += float(np.sum(np.minimum(1.0, (hi - lo) / B)))
    return 2.0 * total


@dataclass(frozen=True)
class Significance:
    """The F-test of an effect (module docstring).

    Attributes
    ----------
    statistic : float
        F (before :data:`NOISE_INFLATION`).
    k, dof : int
        Parameters of the effect; residual degrees of freedom ``N - p - k``.
    p_value : float
        Probability of ``F / NOISE_INFLATION`` at least this large without the effect (one test).
    level : float
        The level it is tested at (``alpha / m``).
    needed : float
        The drop of the whitened sum of squares the effect needs to pass (noise units).
    """

    statistic: float
    k: int
    dof: int
    p_value: float
    level: float
    needed: float

    @property
    def significant(self) -> bool:
        return self.p_value < self.level

    @property
    def margin(self) -> float:
        """``-log10`` of the p-value over the level (> 0: significant)."""
        return -math.log10(max(self.p_value, 1e-300)) + math.log10(self.level)

    def to_dict(self) -> dict:
        return {"F": round(self.statistic, 3), "k": self.k, "dof": self.dof, "p_value": float(f"{self.p_value:.3g}"),
                "level": float(f"{self.level:.3g}"), "needed": round(self.needed, 2)}


def f_isf(level: float, k: int, dof: int) -> float:
    """The F(k, dof) value exceeded with probability ``level`` (``scipy.stats.f.isf``, through the
    incomplete beta function: ``scipy.stats`` costs a quarter of a second to import)."""
    z = float(special.betaincinv(dof / 2.0, k / 2.0, level))
    return dof * (1.0 - z) / (k * z)


def significance(ss_before: float, ss_after: float, k: int, n_points: float, n_model: int, n_tests: int = 1,
                 alpha: float = FALSE_ALARM) -> Significance:
    """F-test of an effect of ``k`` parameters that lowers the whitened sum of squares.

    Parameters
    ----------
    ss_before, ss_after : float
        Whitened sums of squares without and with the effect (noise units).
    k : int
        Its parameters (fixed ones included: their value came from the data).
    n_points : float
        :func:`effective_points`.
    n_model : int
        Free parameters of the model without the effect.
    n_tests : int
        Candidates screened (Bonferroni).
    alpha : float
        Family-wise false-alarm probability.
    """
    k = max(int(k), 1)
    dof = max(int(round(n_points)) - int(n_model) - k, 1)
    s2 = max(ss_after, 1e-300) / dof
    F = max(ss_before - ss_after, 0.0) / k / s2
    level = alpha / max(int(n_tests), 1)
    crit = f_isf(level, k, dof)
    return Significance(float(F), k, dof, float(special.fdtrc(k, dof, F / NOISE_INFLATION)), level,
                        NOISE_INFLATION * crit * k * s2)


def prefers(ss_simple: float, k_simple: int, ss_rich: float, k_rich: int, n_points: float, n_model: int,
            alpha: float = FALSE_ALARM) -> bool:
    """Whether the richer of two rival effects is preferred: its extra parameters lower the sum
    of squares beyond noise (an F-test at ``alpha`` as if the simpler were nested in it; with as
    many parameters, whichever explains more)."""
    if k_rich <= k_simple:
        return ss_rich < ss_simple
    return significance(ss_simple, ss_rich, k_rich - k_simple, n_points, n_model + k_simple, 1, alpha).significant


def indistinguishable(ss_a: float, ss_b: float, n_points: float, n_model: int, k: int,
                      alpha: float = FALSE_ALARM, n_tests: int = 1) -> bool:
    """Whether two rival effects explain the data equally within noise: their sums of squares
    differ by less than one parameter's F-test at ``alpha / n_tests`` would need (with
    ``n_tests`` the candidates screened, the difference must be what adding an effect needs)."""
    lo, hi = sorted((ss_a, ss_b))
    return not significance(hi, lo, 1, n_points, n_model + k, n_tests, alpha).significant
