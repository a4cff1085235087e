"""Where the monitor pipeline's results go: the recording, the ``results`` callback, the Rerun
view, the Zenoh publisher and the terminal status line.

:class:`ResultSinks` is a part of :class:`~livesweep.monitor.pipeline.MonitorPipeline` (a mixin on
its state): every live result is recorded on ``/livesweep/<name>`` and handed to ``results``; an
alert also goes to the view's alert log and to the publisher; the aligned time series go to the
view in batches (``TIMESERIES_EVERY_S``); the status line gets one line about once a second.
"""

from __future__ import annotations

import numpy as np

from livesweep.spectral.excitation import Alert
from livesweep.telemetry.clock import receive_ns

__all__ = ["ResultSinks", "TIMESERIES_EVERY_S"]

TIMESERIES_EVERY_S = 0.2      # time series go to the view in batches this often [s of wall time]: each Rerun
                              # call holds the interpreter, and one per 20 ms block slowed the recording thread


class ResultSinks:
    """The pipeline's outputs (mixin of :class:`~livesweep.monitor.pipeline.MonitorPipeline`, whose
    ``__init__`` sets the state these methods use: ``recorder``, ``results``, ``view``,
    ``publisher``, ``status_line``, ``sources`` and the sinks' private fields)."""

    def _record_alert(self, t_s: float | None, alert: Alert, log_time_ns: int | None = None) -> None:
        """An alert at data time ``t_s`` [s] counted, recorded on ``/livesweep/alert`` and handed to ``results``."""
        self.alerts_raised += 1
        self._result("alert", {"t_s": t_s, "kind": alert.kind, "message": alert.message, "value": float(alert.value)},
                     log_time_ns)

    def _say_alert(self, t_s: float | None, alert: Alert, log_time_ns: int | None = None) -> None:
        """An alert at data time ``t_s`` [s] to every sink: recorded (at ``log_time_ns`` [ns], else
        now), the view's alert log and the publisher."""
        self._record_alert(t_s, alert, log_time_ns)
        if self.view is not None:
            self.view.log_alerts(t_s, [(alert.kind, alert.message)])
        if self.publisher is not None:
            self.publisher.publish("alert", {"t_s": t_s, "kind": alert.kind, "message": alert.message})

    def _result(self, name: str, payload: dict, log_time_ns: int | None = None, *, flush: bool = False) -> None:
        """A live result: recorded on ``/livesweep/<name>`` (at ``log_time_ns``, else now) and handed
        to ``results``."""
        if self.recorder is not None:
            self.recorder.record_result(name, payload, log_time_ns=receive_ns() if log_time_ns is None else log_time_ns,
                                        flush=flush)
        if self.results is not None:
            self.results(name, payload)

    def _flush_timeseries(self, now: float, force: bool = False) -> None:
        """Send the buffered time series to the view in one call per signal (every TIMESERIES_EVERY_S)."""
        if not self._ts_buffer or (not force and now - self._ts_sent < TIMESERIES_EVERY_S):
            return
        t = np.concatenate([b[0] for b in self._ts_buffer])
        values = np.concatenate([b[1] for b in self._ts_buffer], axis=1)
        self._ts_buffer.clear()
        self._ts_sent = now
        self.view.log_timeseries(t, list(self.names), values,
                                 ["output" if x in self.settings.outputs else "input" for x in self.names],
                                 units=[self.settings.signals[x].units for x in self.names])

    def _status(self, now: float, anomalies: dict) -> None:
        """The one-line terminal status (:mod:`livesweep.monitor.status_line`)."""
        t_prev, n_prev = self._status_frames
        self._status_frames = (now, self.totals.frames)
        cur = self.test_points.current
        # a frame the kernel dropped also leaves a MAVLink sequence gap: count the larger, not both
        lost = max(sum(self._packets_lost().values()), anomalies.get("kernel_drops", 0)) + self.analysis_shed
        last = self.last_status
        self.status_line.update({
            "frames_per_s": (self.totals.frames - n_prev) / max(now - t_prev, 1e-9),
            "frames_lost": lost,
            "test_point": None if cur is None else f"TP{len(self.test_points.closed) + 1} {cur.swept_input or '?'}",
            "test_point_elapsed_s": None if cur is None or self._t_data is None else self._t_data - cur.start_s,
            "test_point_loss": None if cur is None or cur.running is None or cur.running.loss is None
            else cur.running.loss.fraction,
            "verdict": self._verdict_label(),
            "sweep": {} if last is None else dict(last.sweep_frequency_rad_s),
            "alerts": self.alerts_raised,
        })

    def _verdict_label(self) -> str:
        """The operator's verdict as the last closed test point labels it ("NO-GO (link)", "GO
        (marginal)"), else as it is ("WAIT")."""
        closed = self.test_points.closed
        if self.verdict in ("GO", "NO-GO") and closed and closed[-1]["verdict"] == self.verdict:
            return closed[-1]["label"]
        return self.verdict or "WAIT"

    def close(self) -> None:
        """Close sources, recording (finished), view and publisher."""
        for src in self.sources:
            try:
                src.close()
            except Exception:  # noqa: BLE001 - closing must not hide the run's own error
                pass
        if self.recorder is not None:
            self.recorder.close()
        if self.view is not None:
            self.view.close()
        if self.publisher is not None:
            self.publisher.close()
