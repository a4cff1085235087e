"""Frame intake of the monitor pipeline: what happens to each frame the analysis takes.

:class:`FrameIntake` is a part of :class:`~livesweep.monitor.pipeline.MonitorPipeline` (a mixin on
its state): it hands each frame to the aligner, the map check and the test-point tracker, tells
recorder-process sources what the analysis wants, counts the frames received and shed, keeps the
data's pace (data seconds per receive second) to place frames without a stamp on the data's
clock, and closes a test point whose vehicle has gone silent for ``LOST_AFTER_S``.
"""

from __future__ import annotations

from livesweep.monitor.ingest import Ingest
from livesweep.monitor.testpoints import CLOSE_WAIT_S, LOST_AFTER_S, LOST_TOPIC
from livesweep.telemetry.clock import receive_ns

__all__ = ["FrameIntake", "PACE_SPAN_S"]

PACE_SPAN_S = 30.0            # the data's pace (data s per receive s) is measured over this much receive time [s]


class FrameIntake:
    """Frames into the analysis (mixin of :class:`~livesweep.monitor.pipeline.MonitorPipeline`,
    whose ``__init__`` sets the state these methods use: ``sources``, ``aligner``,
    ``test_points``, ``recorder``, ``settings`` and the intake's private fields)."""

    def _take(self, f) -> None:
        """One frame from the queue: to the aligner, and to the test-point tracker when it is evidence."""
        entry = self._topics_seen.get(f.topic)
        self._topics_seen[f.topic] = (1, f.data) if entry is None else (entry[0] + 1, entry[1])
        analysed = self._analysed.get(f.topic)
        if analysed is None:
            analysed = self._analysed[f.topic] = f.topic in self._wanted or self.test_points.wants(f.topic)
        if not analysed:                     # the first frame of a topic the map does not use: seen, no more
            if self.map_problems is None:
                self._map_check(f.receive_ns)
            return
        if self._cause_rx is None:
            self._cause_rx = f.receive_ns            # the oldest frame whose effects are not shown yet
        self._newest_rx = f.receive_ns
        before = self.aligner.k_frontier
        self.aligner.push(f)
        if self.aligner.system != self._told_system:
            self._tell_sources()
        if self.aligner.k_frontier != before:
            self._rx_to_data = (f.receive_ns, self.aligner.frontier_s)
            hist = self._rx_history
            hist.append(self._rx_to_data)
            while len(hist) > 2 and (hist[-1][0] - hist[1][0]) * 1e-9 > PACE_SPAN_S:
                hist.popleft()
        if self.conditions is not None and f.topic in self.conditions.topics:
            self.conditions.take(f, self._data_time(f.receive_ns), self.aligner.system)
        if self.map_problems is None or self._map_missing:
            self._map_check(f.receive_ns)
        if self.test_points.wants(f.topic):
            self.test_points.learn(f, self.aligner.system)
            t = self._data_time(f.receive_ns)
            if t is None:
                return                       # no data yet: nothing a test point could hold
            for ev in self.test_points.events_of(f, t, self.aligner.system):
                self._drain_blocks()         # the samples up to the event first (they may belong to it)
                self._test_point_records(self.test_points.event(ev))
                self._update_verdict(ev.t_s)
                if ev.action == "lost":      # nothing more will come: judge what ended or was cut now
                    self._test_point_records(self.test_points.expire(t, lost=True), log_time_ns=f.receive_ns)
            if self.settings.vehicle and self._unfit is None:
                self._check_vehicle(f.receive_ns)
        if (self.test_points.closing and (t := self._data_time(f.receive_ns)) is not None
                and t >= min(tp.end_s for tp in self.test_points.closing) + CLOSE_WAIT_S):
            # an ended test point no samples reach (no telemetry at all): judged on what it has
            self._drain_blocks()
            if records := self.test_points.expire(t):
                self._test_point_records(records, log_time_ns=f.receive_ns)

    def _frames_received(self, ingest: Ingest) -> int:
        """Frames received from every source: a recorder process counts all it read (it forwards only
        those the analysis takes)."""
        own = sum(sum((src.counts.get("received") or {}).values()) for src in self.sources
                  if getattr(src, "recorded", False))
        return ingest.received - ingest.received_recorded + own

    def _tell_sources(self) -> None:
        """A recorder process forwards only what the analysis takes: the map's messages, and once the
        aligner follows a vehicle, only that vehicle's data (the test-point evidence always:
        :data:`~livesweep.telemetry.capture.EVENT_MESSAGES`)."""
        self._told_system = self.aligner.system
        for src in self.sources:
            if hasattr(src, "want"):
                src.want(self._wanted, self.aligner.system)

    def _sources_shed(self) -> int:
        """Frames a recorder process could not hand to the analysis (recorded all the same)."""
        return sum(int(getattr(src, "shed", 0) or 0) for src in self.sources)

    def _last_rx(self, ingest: Ingest) -> dict:
        """Receive time [ns] of the latest frame per system: what reached the analysis, or, from a
        recorder process, what reached the recorder (a busy analysis is not a lost link)."""
        last = dict(ingest.last_rx)
        for src in self.sources:
            for k, v in (getattr(src, "last_rx", None) or {}).items():
                last[k] = max(last.get(k, 0), v)
        return last

    def _watch_link(self, ingest: Ingest) -> None:
        """A test point whose vehicle has sent nothing for :data:`LOST_AFTER_S` of receive time is
        closed NO-GO, "telemetry lost": the event is recorded (``LOST_TOPIC``) and taken like any
        frame, so a replay closes it where the live run did."""
        tracker = self.test_points
        if tracker.current is None and not tracker.closing:
            return
        sysid = self.aligner.system
        seen = self._last_rx(ingest)
        last = seen.get(sysid) if sysid is not None else max(seen.values(), default=None)
        if last is None:
            return
        now = receive_ns()
        if now - last < LOST_AFTER_S * 1e9:
            self._lost_said = False
            return
        if self._lost_said:
            return
        self._lost_said = True
        from livesweep.telemetry.frames import Frame

        frame = Frame(LOST_TOPIC, now, None, {"silent_s": round((now - last) * 1e-9, 3), "last_rx_ns": int(last),
                                              "sysid": sysid})
        if self.recorder is not None:
            self.recorder.record([frame])
        self._take(frame)

    def _source_rates(self) -> dict:
        """The rate each aligned signal arrives at [Hz] (from its first samples' spacing)."""
        return {n: 1.0 / c.dt for n, c in self.aligner.ch.items() if c.dt}

    def _data_time(self, receive_ns: int) -> float | None:
        """The data time [s] of a frame without a usable stamp (a STATUSTEXT, a marker): the aligner's
        frontier when it last moved, plus the receive time since at the data's own pace (data seconds
        per receive second over the last ``PACE_SPAN_S`` of receive time: 1 live, N for a log
        streamed at N x), so a SystemID text during a stretch without samples keeps its place."""
        if self._rx_to_data is None:
            return None
        rx, t = self._rx_to_data
        return t + (receive_ns - rx) * 1e-9 * self._pace()

    def _pace(self) -> float:
        """Data seconds per receive second: 1 unless the recent frontier moves say otherwise."""
        hist = self._rx_history
        if len(hist) < 2:
            return 1.0
        (rx0, t0), (rx1, t1) = hist[0], hist[-1]
        if rx1 - rx0 < 1e9 or t1 - t0 < 1.0:
            return 1.0
        pace = (t1 - t0) / ((rx1 - rx0) * 1e-9)
        return pace if 0.2 <= pace <= 200.0 else 1.0
