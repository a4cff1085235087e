"""The flight conditions of each test point: signals the map names, averaged over it.

A map's ``[test_points] conditions`` lists signals of its ``[signals]`` that say where in the
envelope a test point was flown (airspeed, altitude, a mode). They are not analysed: each frame
that carries one gives a value at a data time (its own stamp when it has one on the map's clock,
else the data time the monitor gives a frame of its receive time), and the mean over a test
point's span goes with its model, so the model's trend can be read against the condition.
"""

from __future__ import annotations

import math
from collections import deque

from livesweep.telemetry.extract import compile_signal

__all__ = ["ConditionMeans", "KEEP_S"]

#: Values kept [s of data]: the longest test point and the stretch before it.
KEEP_S = 960.0


class ConditionMeans:
    """Recent values of the condition signals, and their means over a span.

    Parameters
    ----------
    specs : dict of str -> SignalSpec
        The condition signals.
    """

    def __init__(self, specs: dict):
        self.extractors = {n: compile_signal(s) for n, s in specs.items()}
        self.topics = {s.topic for s in specs.values()}
        self.values = {n: deque() for n in specs}

    def take(self, frame, data_time_s, system) -> None:
        """One frame of a condition topic; ``data_time_s`` its data time [s] when it carries no
        stamp of its own (None: not known yet); ``system`` the vehicle analysed (None: any)."""
        d = frame.data
        if not isinstance(d, dict) or (system is not None and d.get("sysid", system) != system):
            return
        for n, ex in self.extractors.items():
            if ex.spec.topic != frame.topic or (ex.conditions and not ex.selects(d)):
                continue
            v, problem = ex.value(d)
            spec = ex.spec
            t = data_time_s
            if spec.stamp and not spec.stamp_topic:
                raw = d.get(spec.stamp)
                t = raw * spec.stamp_scale if isinstance(raw, (int, float)) and not isinstance(raw, bool) else None
            if problem is not None or t is None or not math.isfinite(t):
                continue
            q = self.values[n]
            q.append((float(t), float(v)))
            while q and q[-1][0] - q[0][0] > KEEP_S:
                q.popleft()

    def means(self, start_s: float, end_s: float) -> dict:
        """Each condition's mean over ``[start_s, end_s]`` [s of data] (None: no value there)."""
        out = {}
        for n, q in self.values.items():
            vs = [v for t, v in q if start_s <= t <= end_s]
            out[n] = sum(vs) / len(vs) if vs else None
        return out
