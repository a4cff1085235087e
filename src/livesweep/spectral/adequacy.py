"""Excitation adequacy of a pair: where the response is accurate enough to fit (docs/method.md §2.5)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.spectral.criteria import DEFAULT_CRITERIA, Criteria
from livesweep.spectral.response import FrequencyResponse

__all__ = ["PairAdequacy", "pair_adequacy", "input_power_slope_db_per_decade", "PULSE_LIKE_SLOPE_DB_PER_DECADE", "MIN_COHERENCE", "MAX_RANDOM_ERROR", "REQUIRED_FRACTION"]

#: The method's criteria, for code that has no settings to take them from (the defaults of
#: :class:`~livesweep.spectral.criteria.Criteria`; stages and the monitor use the case's or map's).
MIN_COHERENCE = DEFAULT_CRITERIA.min_coherence
MAX_RANDOM_ERROR = DEFAULT_CRITERIA.max_random_error
REQUIRED_FRACTION = DEFAULT_CRITERIA.required_fraction
#: Input power falling faster than this across the band [dB/decade] looks pulse-like (doublets),
#: not swept (measured: the shipped XV-15 sweeps -9, their verification doublets -19 and -26 over
#: 1-20 rad/s; a constant-amplitude exponential sweep falls 10 in theory).
PULSE_LIKE_SLOPE_DB_PER_DECADE = -14.0


@dataclass(frozen=True)
class PairAdequacy:
    """Where one pair's response is adequate by its criteria (gamma^2 >= 0.6 and eps_r <= 0.2 by default).

    Attributes
    ----------
    output, input : str
    bands_rad_s : tuple of (float, float)
        Contiguous adequate stretches of the frequency grid [rad/s].
    widest_band_rad_s : (float, float) or None
        The widest stretch (in decades), or None when nothing is adequate.
    fraction : float
        Fraction of the grid (log-spaced, so of the decades) that is adequate.
    median_coherence : float
        Over the whole grid.
    criteria : Criteria
        The criteria that judged it.
    """

    output: str
    input: str
    bands_rad_s: tuple
    widest_band_rad_s: tuple | None
    fraction: float
    median_coherence: float
    criteria: Criteria = DEFAULT_CRITERIA

    def to_dict(self) -> dict:
        return {"output": self.output, "input": self.input,
                "bands_rad_s": [list(b) for b in self.bands_rad_s],
                "widest_band_rad_s": None if self.widest_band_rad_s is None else list(self.widest_band_rad_s),
                "fraction_of_band": round(self.fraction, 4), "median_coherence": round(self.median_coherence, 4),
                "criteria": {"min_coherence": self.criteria.min_coherence,
                             "max_random_error": self.criteria.max_random_error}}


def pair_adequacy(resp: FrequencyResponse, criteria: Criteria = DEFAULT_CRITERIA) -> PairAdequacy:
    """Adequate stretches of one response by ``criteria``."""
    ok = criteria.adequate(resp.coherence, resp.random_error)
    w = resp.omega
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))
    bands = tuple((float(w[a]), float(w[b - 1])) for a, b in zip(edges[::2], edges[1::2]))
    widest = max(bands, key=lambda b: np.log10(b[1] / b[0]), default=None)
    return PairAdequacy(resp.output, resp.input, bands, widest, float(np.mean(ok)) if ok.size else 0.0,
                        float(np.median(resp.coherence)) if resp.coherence.size else 0.0, criteria)


def input_power_slope_db_per_decade(windows, name: str, band_rad_s) -> float:
    """How fast an input's power density falls across the band [dB/decade] (negative: it falls).

    Median autospectrum over the top third of the band (log frequency; from the shortest window,
    which has the most averages there) minus the median over the bottom third (from the longest
    window, the only one that resolves it). A constant-amplitude exponential sweep dwells
    ``1/w`` as long at each frequency, so it falls about 10 dB per decade (the shipped XV-15
    sweeps: -9); doublets fall faster above their pulse frequency, with nulls (the XV-15
    verification doublets: -19 and -26 over 1-20 rad/s).

    Parameters
    ----------
    windows : sequence of WindowSpectra
    name : str
        The input's signal name.
    band_rad_s : (float, float)
    """
    lo, hi = float(band_rad_s[0]), float(band_rad_s[1])
    third = (hi / lo) ** (1.0 / 3.0)
    by_len = sorted(windows, key=lambda w: w.window_s)

    def median_power(ws, a, b):
        k = ws.names.index(name)
        sel = (ws.omega >= a) & (ws.omega <= b)
        return float(np.median(ws.G[k, k, sel].real)) if np.any(sel) else float("nan")

    top = median_power(by_len[0], hi / third, hi)
    bottom = median_power(by_len[-1], lo, lo * third)
    if not (top > 0 and bottom > 0):
        return float("nan")
    decades = math.log10(hi / lo) * 2.0 / 3.0          # between the thirds' centres
    return 10.0 * float(np.log10(top / bottom)) / decades
