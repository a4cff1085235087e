"""The model of each closed test point, its trend over the flight, and the limits it is held to.

:class:`ModelKeeper` belongs to the monitor pipeline: when a test point closes it fits the pairs
the test point judged (:func:`livesweep.ident.test_point_model.model_test_point`, the same fit
and criteria as ``livesweep identify``), sets each pair's values beside those of the earlier test
points of the flight (the trend) and returns the ``/livesweep/model`` record. The limits and
predictions of the map or case (``[limits]``, ``[predictions.*]``) are checked there; each
breach becomes a ``limit`` alert and a line of the operator's verdict.

Everything depends on the test point's samples alone, so a replay of the recording gives the
same models.
"""

from __future__ import annotations

import math

from livesweep.ident.test_point_model import TestPointModel, model_test_point

__all__ = ["ModelKeeper", "MODEL_SETTINGS_KEYS", "trend_notes"]

#: What the monitor's settings hold for the models (saved with a recording for its replay).
MODEL_SETTINGS_KEYS = ("transfer_functions", "predictions", "limits")
#: A parameter that moved by more than this many of its combined Cramer-Rao bounds
#: (``sqrt(CR_1^2 + CR_2^2)``) from the previous test point of the pair is said to have moved.
MOVED_BOUNDS = 2.0


def trend_notes(pair: str, rows: list) -> list[str]:
    """Lines saying which parameters of ``pair`` moved beyond :data:`MOVED_BOUNDS` of their combined
    bounds between the last two rows (``{"test_point", "parameters": {k: [value, cr]}}``)."""
    if len(rows) < 2:
        return []
    a, b = rows[-2], rows[-1]
    out = []
    for k, (v1, c1) in b["parameters"].items():
        if k not in a["parameters"]:
            continue
        v0, c0 = a["parameters"][k]
        if None in (v0, v1, c0, c1):
            continue
        bound = math.hypot(c0, c1)
        if bound > 0 and abs(v1 - v0) > MOVED_BOUNDS * bound:
            out.append(f"{pair}: {k} moved from {v0:.4g} (TP{a['test_point']}) to {v1:.4g} (TP{b['test_point']}), "
                       f"{abs(v1 - v0) / bound:.1f} times their combined bound")
    return out


class ModelKeeper:
    """Models of the closed test points of one monitor run, and their trend.

    Parameters
    ----------
    settings : MonitorSettings
        ``signals`` (units), ``criteria``, ``models`` (:class:`~livesweep.monitor.monitor_settings.ModelSettings`).
    """

    def __init__(self, settings):
        self.settings = settings
        self.units = {n: s.units for n, s in settings.signals.items()}
        self.rows: dict[str, list] = {}          # pair -> trend rows, in test-point order
        self.models: list[dict] = []             # every /livesweep/model record, in order

    def model_of(self, number: int, rec: dict, judgement, conditions: dict | None = None
                 ) -> tuple[dict, TestPointModel] | None:
        """The ``/livesweep/model`` record of closed test point ``number`` (1-based: its place among the
        closed ones) with record ``rec``, closing judgement ``judgement`` and the means of the map's
        conditions over it (name -> value or None), and the model; None when no pair of it has a
        response to fit (too short, lost, not judged)."""
        if judgement is None or not judgement.final or not any(getattr(p, "response", None) is not None
                                                                 for p in judgement.pairs):
            return None
        ms = self.settings.models
        model = model_test_point(judgement, units=self.units, specs=ms.specs, criteria=self.settings.criteria,
                                 predictions=ms.predictions, limits=ms.limits)
        if not model.pairs and not model.skipped:
            return None
        record = model.to_dict()
        trend, notes = [], []
        for p in model.pairs:
            rows = self.rows.setdefault(p.name, [])
            rows.append({"test_point": number, "start_s": rec["start_s"], "verdict": rec["verdict"],
                         "conditions": dict(conditions or {}),
                         "parameters": {f.name: [f.value, f.cramer_rao] for f in p.parameters},
                         "figures": {f.name: [f.value, f.cramer_rao] for f in p.figures},
                         "cost": p.fit.cost})
            trend.append({"pair": p.name, "rows": [dict(r) for r in rows]})
            notes += trend_notes(p.name, rows)
        record = {**record, "test_point": {"number": number, **{k: rec.get(k) for k in (
            "start_s", "end_s", "swept_input", "axis", "source", "verdict", "label")},
                                    "conditions": dict(conditions or {})},
                  "trend": trend, "trend_notes": notes}
        self.models.append(record)
        return record, model
