"""The criteria that judge a frequency response: where it is adequate, and what a GO needs.

One :class:`Criteria` is used by everything that judges or shows adequacy: the live verdict and
the test point's judgement, the fit bands of the transfer-function and state-space stages, the
report's shading and text, the Rerun view's threshold line and legend, and the console. A case or
a channel map sets it in its ``[criteria]`` table (docs/case-file.md); every recorded test point
and every report carries the criteria that judged it (:meth:`Criteria.to_dict`).

The defaults are the method's (Tischler & Remple, docs/method.md §2.5): a response is adequate
where gamma^2 >= 0.6 and its normalised random error eps_r <= 0.2, and a test point is GO when
each required pair is adequate over 60 % of the band (in decades).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from livesweep.settings_schema import number, setting

__all__ = ["Criteria", "DEFAULT_CRITERIA"]


@dataclass(frozen=True)
class Criteria:
    """Adequacy and GO criteria (a case's or map's ``[criteria]`` table).

    Attributes
    ----------
    min_coherence : float
        gamma^2 at least this where a response is adequate; also the fit bands' and the report's
        and viewer's coherence threshold.
    max_random_error : float
        Normalised random error eps_r at most this where a response is adequate.
    required_fraction : float
        Fraction of the band (decades) each required pair must be adequate over, and the swept
        input excited over, for a GO.
    """

    min_coherence: float = setting(0.6, number(0.0, 1.0, lo_open=True, hi_open=True),
                                   "γ² at least this where a response is adequate; the fit bands of the "
                                   "transfer-function and state-space stages, the report's shading and the "
                                   "viewer's threshold line use it too")
    max_random_error: float = setting(0.2, number(0.0, lo_open=True),
                                      "normalised random error ε_r at most this where a response is adequate",
                                      units="fraction")
    required_fraction: float = setting(0.6, number(0.0, 1.0, lo_open=True),
                                       "fraction of the band (decades) each required pair must be adequate "
                                       "over, and the swept input excited over, for a GO", units="fraction")

    def adequate(self, coherence, random_error) -> np.ndarray:
        """Boolean mask: gamma^2 >= ``min_coherence`` and eps_r <= ``max_random_error`` (NaN: not)."""
        g = np.asarray(coherence, float)
        e = np.asarray(random_error, float)
        with np.errstate(invalid="ignore"):
            return (g >= self.min_coherence) & (e <= self.max_random_error)

    def coherent(self, coherence) -> np.ndarray:
        """Boolean mask: gamma^2 >= ``min_coherence`` (NaN: not)."""
        with np.errstate(invalid="ignore"):
            return np.asarray(coherence, float) >= self.min_coherence

    @property
    def loss_reason_fraction(self) -> float:
        """Lost frames from which the loss is a test point's first reason: where the coherence bias
        ``(1 - (1 - L)^2) gamma^2`` at the threshold reaches the coherence estimate's own random error
        there, ``2 gamma^2 eps_r sqrt(1 - gamma^2)`` (13.6 % with the defaults)."""
        return 1.0 - math.sqrt(max(0.0, 1.0 - 2.0 * self.max_random_error * math.sqrt(1.0 - self.min_coherence)))

    @property
    def loss_link_fraction(self) -> float:
        """Lost frames from which a NO-GO reads "NO-GO (link)": ``(1 - L)^2 = min_coherence``
        (22.5 % with the defaults): even a perfect pair reads no better than the threshold."""
        return 1.0 - math.sqrt(self.min_coherence)

    def text(self) -> str:
        """``"γ² ≥ 0.6, ε_r ≤ 0.2"``: the adequacy rule as the report and viewer state it."""
        return f"γ² ≥ {self.min_coherence:g}, ε_r ≤ {self.max_random_error:g}"

    def ascii(self) -> str:
        """``"gamma^2 >= 0.6, eps <= 0.2"``: the rule for consoles without Unicode."""
        return f"gamma^2 >= {self.min_coherence:g}, eps <= {self.max_random_error:g}"

    def to_dict(self) -> dict:
        """The criteria as recorded in report.json and on ``/livesweep/test_point`` (every field)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, d) -> Criteria:
        """The criteria of :meth:`to_dict` (missing keys: the defaults; unknown keys ignored)."""
        d = d or {}
        return cls(**{f.name: float(d[f.name]) for f in fields(cls) if f.name in d})


#: The method's criteria (docs/method.md §2.5).
DEFAULT_CRITERIA = Criteria()
