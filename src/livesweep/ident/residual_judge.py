"""What every re-identification in a residual loop is judged against.

The F-test of the whitened sums of squares (:func:`~livesweep.ident.selection.significance`, with the
loop's false-alarm level, effective number of points and candidates screened) and, when the loop
has a verification callback, the paired comparison of two models' time-domain errors on the same
verification records.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from livesweep.ident.selection import FALSE_ALARM, significance
from livesweep.numeric import finite_or_none

__all__ = ["VERIFICATION_BLOCK_S", "Judge", "n_free", "verification_summary", "verification_change"]

#: Block length [s] over which the verification comparison averages (turbulence makes neighbouring
#: samples correlated).
VERIFICATION_BLOCK_S = 2.0


@dataclass
class Judge:
    """What every re-identification in one loop is judged against.

    Attributes
    ----------
    pairs : list of PairData
        The loop's pairs (its fitting points).
    frs : FrequencyResponseSet
    verify : callable or None
        The loop's verification callback.
    n_points : float
        Effective number of independent frequency values in the pairs.
    alpha : float
        The loop's false-alarm probability.
    n_tests : int
        Candidates screened at this step (the screening test's multiplicity).
    origin : dict or None
        The case's own table: its starting values.
    """

    pairs: list
    frs: object
    verify: object
    n_points: float
    alpha: float
    n_tests: int = 1
    origin: dict | None = None

    def test(self, ss_before, ss_after, k, n_model):
        """The F-test of a drop of the whitened sum of squares from ``ss_before`` to ``ss_after``
        for ``k`` parameters added to a model of ``n_model`` free ones, at this step's multiplicity."""
        return significance(ss_before, ss_after, k, self.n_points, n_model, self.n_tests, self.alpha)


def n_free(fit) -> int:
    """Free parameters of a fit's model."""
    return int(np.sum(~np.asarray(fit.model.fixed)))


def _as_list(v):
    return list(v) if isinstance(v, (list, tuple)) else [v]


def verification_summary(v):
    """``{"j_rms", "tic": {output: value}, "passed"}`` (records pooled: J_rms over all samples, the
    worst TIC per output), or None."""
    if v is None:
        return None
    vs = _as_list(v)
    n = [float(np.sum(np.isfinite(x.measured - x.predicted))) for x in vs]
    j = math.sqrt(sum(x.j_rms ** 2 * k for x, k in zip(vs, n)) / max(sum(n), 1.0))
    tic = {}
    for x in vs:
        for o in x.outputs:
            tic[o.name] = max(tic.get(o.name, 0.0), float(o.tic))
    return {"j_rms": finite_or_none(j, 3), "tic": {k: finite_or_none(t, 3) for k, t in tic.items()},
            "passed": all(x.passed for x in vs)}


def verification_change(before, after, alpha: float = FALSE_ALARM):
    """Paired comparison of two models on the same verification records.

    ``d(t) = sum_o (r_after,o(t)^2 - r_before,o(t)^2)``; its mean against the scatter of its means
    over :data:`VERIFICATION_BLOCK_S` blocks (turbulence makes neighbouring samples correlated).
    Verdict ``improved`` / ``worse`` beyond ``z`` sigma, the one-sided normal quantile at
    ``alpha`` (the loop's false-alarm level, 2.33 sigma at 1 %), else ``unchanged``. A correct
    effect is refused by chance with probability ``alpha`` per comparison: turbulence the model
    cannot predict enters ``d`` through the cross term ``2 e_turb (m_after - m_before)``, whose
    mean is zero but whose scatter on a few seconds of low-frequency gusts is as large as a
    genuine improvement (a 12 rad/s mode on p in cruise: +2.2 sigma at turbulence 0.3, -2.5 sigma
    on the same manoeuvres in calm air).
    """
    if before is None or after is None:
        return None
    ds, means = [], []
    for b, a in zip(_as_list(before), _as_list(after)):
        with np.errstate(over="ignore", invalid="ignore"):    # a diverging model's huge residuals
            ra, rb = a.measured - a.predicted, b.measured - b.predicted
            ok = np.all(np.isfinite(ra) & np.isfinite(rb), axis=0)
            d = np.sum(ra[:, ok] ** 2 - rb[:, ok] ** 2, axis=0)
        dt = float(np.median(np.diff(b.t_s))) if b.t_s.size > 1 else 1.0
        n_block = max(1, int(round(VERIFICATION_BLOCK_S / dt)))
        n_b = d.size // n_block
        means.extend(d[:n_b * n_block].reshape(n_b, n_block).mean(axis=1).tolist())
        ds.append(d)
    d = np.concatenate(ds) if ds else np.zeros(0)
    with np.errstate(over="ignore", invalid="ignore"):
        noise = float(np.std(means, ddof=1) / math.sqrt(len(means))) if len(means) >= 3 else float("inf")
        mean = float(d.mean()) if d.size else 0.0
    sb, sa = verification_summary(before), verification_summary(after)
    limit = min(v.guidelines["j_rms_max"] for v in _as_list(after))
    diverges = (sa["j_rms"] is None or not np.isfinite(mean) or (len(means) >= 3 and not np.isfinite(noise))
                or (sb["j_rms"] is not None and sb["j_rms"] <= limit < sa["j_rms"]))
    if diverges:
        # the new model diverges open loop (or predicts nothing), or fails the method's J_rms
        # guideline the model before met: worse, whatever the noise (a model growing as e^(2t)
        # over the record has block means that grow with it, so their scatter is as large as
        # their mean and a paired test alone would call it unchanged)
        return {"j_rms_before": sb["j_rms"], "j_rms_after": sa["j_rms"], "mean_change": None, "noise": None,
                "verdict": "worse" if sb["j_rms"] is not None else "unchanged"}
    z = NormalDist().inv_cdf(1.0 - alpha)
    verdict = "improved" if mean < -z * noise else ("worse" if mean > z * noise else "unchanged")
    return {"j_rms_before": sb["j_rms"], "j_rms_after": sa["j_rms"], "mean_change": mean, "noise": noise,
            "z": round(z, 3), "verdict": verdict}
