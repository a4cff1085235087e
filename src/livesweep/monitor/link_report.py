"""The link counters of the monitor pipeline, recorded and raised as ``link`` alerts.

:class:`LinkReport` is a part of :class:`~livesweep.monitor.pipeline.MonitorPipeline` (a mixin on
its state). Every counter the sources, the aligner and the pipeline keep (frames per type and
system, bad CRC, garbage, unknown messages, unsigned and bad signatures, sequence gaps, kernel
drops, clock anomalies, frames shed) is recorded about once a second on ``/livesweep/link``,
raised as a ``link`` alert when it grows (:data:`LINK_ANOMALIES`; view, ``/livesweep/alert``,
Zenoh), and written into the recording's ``livesweep.counters`` metadata when it is closed.
"""

from __future__ import annotations

from livesweep.monitor.alerts import ALERT_INTERVAL_S
from livesweep.monitor.testpoints import GCS_SYSID
from livesweep.spectral.excitation import Alert
from livesweep.telemetry.clock import receive_ns

__all__ = ["LinkReport", "LINK_ANOMALIES"]

#: Counters whose growth is a ``link`` alert: (where, key, words).
LINK_ANOMALIES = (
    ("source", "bad_crc", "bad CRC"), ("source", "bad_prefix_or_garbage", "garbage"),
    ("source", "bad_other", "undecodable"), ("source", "unknown_message", "unknown message"),
    ("source", "rejected_unsigned", "unsigned (rejected)"), ("source", "bad_signature", "bad signature"),
    ("source", "clock_unrepresentable", "unrepresentable time stamp"),
    ("source", "clock_implausible", "implausible time stamp"), ("source", "kernel_drops", "dropped by the kernel"),
    ("source", "malformed", "malformed JSON"), ("source", "non_object", "not a JSON object"),
    ("source", "bad_stamp", "bad stamp"), ("source", "dropped_queue_full", "dropped (queue full)"),
    ("source", "clients_refused", "TCP client refused"), ("source", "keys_over_limit", "sample on a key beyond the limit"),
    ("source", "skipped_messages", "damaged message skipped (replay)"),
    ("pipeline", "analysis_shed", "skipped by the analysis (recorded)"),
    ("pipeline", "unrecordable", "frame that could not be recorded"),
    ("aligner", "clock_rejected", "sample with an implausible stamp"), ("aligner", "resets", "clock reset"),
    ("aligner", "other_system", "frame of another system"), ("aligner", "samples_skipped", "grid sample skipped"),
    ("aligner", "late_dropped", "late sample"), ("aligner", "not_a_number", "non-numeric value"),
    ("aligner", "missing_field", "missing field"),
)


def source_name(src) -> str:
    """How a source names itself in counters: its bound url, path or key expression."""
    for attr in ("description", "url", "path", "key_expr"):
        v = getattr(src, attr, None)
        if v is not None:
            return str(v)
    return type(src).__name__


class LinkReport:
    """Link counters, their record and their alerts (mixin of
    :class:`~livesweep.monitor.pipeline.MonitorPipeline`, whose ``__init__`` sets the state these
    methods use: ``sources``, ``aligner``, ``totals``, ``analysis_shed``, ``recorder`` and the
    report's private fields)."""

    def counters(self) -> dict:
        """Every counter now: per source, of the aligner and of the pipeline."""
        ingest = self._ingest
        return {
            "sources": [{"name": source_name(src), **src.counts} for src in self.sources],
            "aligner": dict(self.aligner.counts),
            "pipeline": {"frames_received": self.totals.frames, "frames_analysed": self.totals.analysed,
                         "analysis_shed": self.analysis_shed, "ticks_skipped": self.totals.ticks_skipped,
                         "drained_at_stop": 0 if ingest is None else ingest.drained,
                         "not_taken_at_stop": 0 if ingest is None else ingest.not_taken_at_stop,
                         "bad_publish_time": 0 if self.recorder is None else self.recorder.bad_publish_time,
                         "unrecordable": 0 if self.recorder is None else self.recorder.unrecordable},
        }

    def _anomalies(self, c: dict) -> dict[str, int]:
        """Each :data:`LINK_ANOMALIES` counter of :meth:`counters` ``c``, summed over the sources."""
        out: dict[str, int] = {}
        for where, key, _words in LINK_ANOMALIES:
            if where == "source":
                v = sum(int(s.get(key, 0) or 0) for s in c["sources"] if isinstance(s.get(key, 0), (int, float)))
            else:
                v = int(c[where].get(key, 0))
            out[key] = v
        return out

    def _report(self, now: float, final: bool = False) -> None:
        """Record the counters on ``/livesweep/link`` and raise a ``link`` alert for what grew."""
        self._last_report = now
        if final and self.map_problems is None and self._topics_seen:
            self._diagnose(receive_ns())     # a run shorter than DIAGNOSE_AFTER_S
        for src in self.sources:
            refresh = getattr(src, "refresh_kernel_drops", None)
            if refresh is not None:
                refresh()
        c = self.counters()
        counts = self._anomalies(c)
        grew = {k: v - self._seen_anomalies.get(k, 0) for k, v in counts.items() if v > self._seen_anomalies.get(k, 0)}
        self._seen_anomalies = counts
        systems = {str(k) for s in c["sources"] for k in (s.get("by_system") or {})}
        # a ground station on the link is normal (its markers count): another vehicle is worth saying
        # each system other than the one analysed, named once it is chosen
        analysed = self.aligner.system
        new_systems = [] if analysed is None else sorted(systems - self._seen_systems - {str(GCS_SYSID), str(analysed)},
                                                         key=lambda k: (len(k), k))
        self._seen_systems |= set(new_systems)
        words = {key: w for _, key, w in LINK_ANOMALIES}
        alerts = []
        for k, n in grew.items():                 # said at most every ALERT_INTERVAL_S, with all that grew since
            self._link_unsaid[k] = self._link_unsaid.get(k, 0) + n
        if self._link_unsaid and (final or now - self._link_said >= ALERT_INTERVAL_S):
            text = ", ".join(f"{n} {words[k]}" for k, n in self._link_unsaid.items())
            alerts.append(Alert("link", f"link: {text} in the last {min(now - self._link_said, now - self._t_start):.0f} s "
                                "(counted, see the summary)", float(sum(self._link_unsaid.values()))))
            self._link_unsaid, self._link_said = {}, now
        if new_systems:
            al = self.aligner
            follows = f"the analysis follows system {al.system} ({al.choice})"
            alerts.append(Alert("link", f"link: another system on the link (system id {', '.join(new_systems)}): "
                                f"recorded, not analysed; {follows}; --sysid names another",
                                float(len(new_systems))))
        for a in alerts:
            self._say_alert(self._t_data, a)
        if self.status_line is not None:
            self._status(now, counts)
        if self.recorder is not None or self.results is not None:
            self._result("link", {"t_s": self._t_data, "wall_s": round(now - self._t_start, 3),
                                  "frames_recorded": self.totals.frames, "analysis_shed": self.analysis_shed,
                                  "sources": c["sources"], "aligner": c["aligner"]})
        if final and self.recorder is not None:
            self.recorder.set_counters(c)

    def _link_counts(self) -> dict:
        """The live link's loss counters now, cumulative: datagrams the kernel dropped, MAVLink
        sequence gaps of the system analysed (every system's until one is), frames the analysis
        skipped and frames received. A test point's loss is their growth while it is open."""
        drops = gaps = 0
        system = self.aligner.system
        for src in self.sources:
            c = src.counts if isinstance(src.counts, dict) else {}
            v = c.get("kernel_drops", 0)
            drops += int(v) if isinstance(v, (int, float)) else 0
            for key, v in (c.get("seq_gaps") or {}).items():
                if system is None or str(key).split("/")[0] == str(system):
                    gaps += int(v)
        return {"kernel_drops": drops, "seq_gaps": gaps, "analysis_shed": int(self.analysis_shed),
                "received": int(self.totals.frames)}

    def _packets_lost(self) -> dict:
        """MAVLink sequence gaps per source (index -> frames), every system's."""
        out = {}
        for k, src in enumerate(self.sources):
            gaps = src.counts.get("seq_gaps") if isinstance(src.counts, dict) else None
            if isinstance(gaps, dict):
                out[k] = sum(int(v) for v in gaps.values())
        return out
