"""Test points and the operator's verdict in the monitor pipeline.

:class:`Verdicts` is a part of :class:`~livesweep.monitor.pipeline.MonitorPipeline` (a mixin on its
state): it shows, publishes and records the test points the tracker opens, judges and closes,
and derives from them the operator's verdict (GO, NO-GO or WAIT with its reasons), never from
the sliding window. :func:`tracker_for` makes the tracker a settings object asks for.
"""

from __future__ import annotations

import time

from livesweep.config import TestPointSettings
from livesweep.monitor.monitor_settings import MonitorSettings
from livesweep.monitor.testpoints import SOURCES, TestPointTracker
from livesweep.monitor.text import time_text
from livesweep.spectral.excitation import Alert
from livesweep.telemetry.clock import receive_ns

__all__ = ["Verdicts", "tracker_for"]


def tracker_for(settings: MonitorSettings, names) -> TestPointTracker:
    """The test-point tracker a settings object asks for (``--require OUT/IN`` names required pairs)."""
    tp = settings.test_points
    required = dict(tp.required) if tp is not None else {}
    named: dict[str, list] = {}
    for o, i in settings.required_pairs or ():        # --require replaces the map's pairs of its inputs
        named.setdefault(i, []).append(o)
    required.update({i: tuple(dict.fromkeys(v)) for i, v in named.items()})
    refs = dict(zip(settings.inputs, settings.references)) if settings.references else None
    return TestPointTracker(names, settings.inputs, settings.outputs, settings.sample_rate_hz, settings.band_rad_s,
                            sources=tp.sources if tp is not None else SOURCES, axes=tp.axes if tp is not None else None,
                            required=required,
                            min_duration_s=(tp if tp is not None else TestPointSettings()).min_duration_s,
                            references=refs, criteria=settings.criteria)


def _next_lines(rec: dict) -> list:
    """What to fly next, when the test point needs more (its record's ``next``)."""
    nxt = rec.get("next")
    return list(nxt["lines"]) if nxt and nxt.get("needed") else []


class Verdicts:
    """Test points shown, published and recorded, and the operator's verdict (mixin of
    :class:`~livesweep.monitor.pipeline.MonitorPipeline`, whose ``__init__`` sets the state these
    methods use: ``test_points``, ``view``, ``publisher``, ``verdict``, ``verdict_reasons``,
    ``totals`` and the verdicts' private fields)."""

    def _test_point_records(self, records, log_time_ns: int | None = None) -> None:
        """Show, publish and (when closed) record test points, each followed by the operator's verdict
        at its own data time (so a replay changes the verdict where the live run did). A closed
        record is logged at ``log_time_ns`` (the receipt of the frame that decided it), else now."""
        for t_s, rec in records:
            if rec["state"] in ("ignored", "superseded"):
                if self.view is not None and hasattr(self.view, "log_test_point"):
                    self.view.log_test_point(t_s, rec)          # gone from the view's table
                continue
            if self.view is not None and hasattr(self.view, "log_test_point"):
                self.view.log_test_point(t_s, rec)
                self._show_focus(t_s, rec)
            made = self._model_of(rec) if rec["state"] == "closed" else None
            if rec["state"] == "closed":
                self._result("test_point", rec, log_time_ns, flush=True)
                if self.publisher is not None:
                    self.publisher.publish("test_point", rec)
            if made is not None:
                self._say_model(t_s, made)
            self._update_verdict(t_s, rec)

    def _model_of(self, rec: dict) -> dict | None:
        """The ``/livesweep/model`` record of the closed test point ``rec`` (None: nothing to fit);
        its limit breaches go into ``rec`` (``limits``), so the verdict says them first."""
        start = time.perf_counter()
        conditions = None if self.conditions is None else self.conditions.means(rec["start_s"], rec["end_s"])
        made = self.models.model_of(len(self.test_points.closed), rec,
                                    self.test_points.judgements.get(rec["start_s"]), conditions)
        if made is None:
            return None
        self.totals.model_s.append(time.perf_counter() - start)
        record, _ = made
        rec["limits"] = list(record["breaches"])
        rec["model_pairs"] = [p["name"] for p in record["pairs"]]
        return record

    def _say_model(self, t_s: float, record: dict) -> None:
        """A test point's model to every sink, and a ``limit`` alert per breach."""
        self._result("model", record, flush=True)
        if self.publisher is not None:
            self.publisher.publish("model", record)
        if self.view is not None and hasattr(self.view, "log_model"):
            self.view.log_model(t_s, record)
        for pair in record["pairs"]:
            for c in pair["limits"]:
                if not c["ok"]:
                    self._say_alert(t_s, Alert("limit", c["text"], 0.0 if c["value"] is None else float(c["value"])))

    def _show_focus(self, t_s: float, rec: dict) -> None:
        """The swept pair of a test point as its verdict judged it, in the view's "Test point" tab."""
        j = self.test_points.judgements.get(rec["start_s"])
        if j is None or not j.pairs or getattr(j.pairs[0], "response", None) is None or \
                not hasattr(self.view, "log_focus"):
            return
        p = j.pairs[0]
        label = rec["label"] if rec["state"] == "closed" else (rec.get("running") or j.label)   # as the record says
        self.view.log_focus(t_s, p.response, f"{p.output}/{p.input}: {label} ({j.progress()})")

    def _operator_verdict(self, rec: dict | None = None) -> tuple[str, tuple, dict | None]:
        """(verdict, reasons, the test point it is about): from the test point record just made, else
        from the tracker's state; never from the sliding window. A running test point is WAIT with
        its running verdict ("GO so far, 0.5-2.9 Hz of 0.5-12 Hz swept"): GO and NO-GO are said once,
        when it closes, and hold until the next one."""
        tracker = self.test_points
        if rec is None:
            if tracker.current is not None:
                rec = tracker.current.record("open")
            elif tracker.closing:
                rec = tracker.closing[-1].record("open")
                return "WAIT", (f"test point ended at {time_text(tracker.closing[-1].end_s)}: judging",), rec
            elif tracker.closed:
                rec = tracker.closed[-1]
            else:
                return "WAIT", ("no test point yet: waiting for a sweep, the autopilot's SystemID or an operator "
                                "marker",), None
        who = f"{rec['swept_input'] or 'an input'} swept"
        if rec["state"] == "open":
            who += f" since {time_text(rec['start_s'])} ({rec['source']})"
            if rec.get("running") is None:
                return "WAIT", (f"test point running: {who}",), rec
            return "WAIT", (f"test point running: {who}: {rec['running']}, {rec.get('progress', '')}".rstrip(", "),
                            *rec["reasons"]), rec
        return rec["verdict"], (f"last test point ({who} {time_text(rec['start_s'])} - {time_text(rec['end_s'])}): "
                                f"{rec['label']}", *rec.get("limits", ()), *rec["missing"], *_next_lines(rec),
                                *rec["reasons"]), rec

    def _update_verdict(self, t_s: float, rec: dict | None = None) -> None:
        verdict, reasons, rec = self._operator_verdict(rec)
        self.verdict_reasons = reasons
        if verdict == self.verdict:
            return
        payload = {"t_s": round(t_s, 6), "verdict": verdict, "previous": self.verdict, "reasons": list(reasons),
                   "test_point": None if rec is None else {k: rec[k] for k in ("start_s", "end_s", "source",
                                                                                "swept_input", "state")}}
        self.verdict = verdict
        self._result("verdict", payload, flush=True)
        if self.publisher is not None:
            self.publisher.publish("verdict", payload)
        if self.view is not None:
            self.view.log_alerts(t_s, [("verdict", f"{verdict}: {reasons[0] if reasons else ''}")])
            if hasattr(self.view, "log_verdict"):
                self.view.log_verdict(t_s, verdict, reasons)
        if self._cause_rx is not None and self._live:   # receipt of the oldest frame behind it -> shown and recorded
            self.totals.verdict_latency_s.append((receive_ns() - self._cause_rx) * 1e-9)
