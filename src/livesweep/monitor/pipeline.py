"""The live (and replay) monitor: sources -> recorder -> aligner -> online estimator -> view.

Two threads. The ingest thread (:mod:`livesweep.monitor.ingest`) polls every source and records
every frame as received; it never waits for the analysis. The caller's thread takes the frames
the channel map needs, aligns them onto the estimator's grid, feeds the sliding-window estimator
and, at fixed ticks of the signals' clock (``update_period_s``), computes the estimate, the
excitation status and alerts, and sends them to the Rerun view, the Zenoh publisher and the
recording. When a live link brings more than the analysis can take, the analysis skips frames
(counted in ``analysis_shed``, a gap to the estimator); the recording keeps every one.

Ticks are on the data's clock, never the wall clock, and the estimator is fed exactly up to each
tick, so the estimates depend only on the frames: replaying a recording reproduces the live
estimates (a test checks equality to 1e-9).

Every counter the sources, the aligner and the pipeline keep (frames per type and system, bad
CRC, garbage, unknown messages, unsigned and bad signatures, sequence gaps, kernel drops, clock
anomalies, frames shed) is recorded about once a second on ``/livesweep/link``, raised as a
``link`` alert when it grows (view, ``/livesweep/alert``, Zenoh), printed in the summary and
written into the recording's ``livesweep.counters`` metadata when it is closed.

Memory is bounded for any flight length: the aligner by the window, the estimator by design, the
estimates kept for inspection by ``keep_estimates``, the hand-over queue by ``queue_limit``.

The pipeline is made of parts with one job each, mixed into :class:`MonitorPipeline` (they share
its state): :mod:`.intake` (each frame the analysis takes), :mod:`.estimate_step` (aligned blocks,
tick by tick, to estimates), :mod:`.verdicts` (test points and the operator's verdict),
:mod:`.map_check` (``map`` alerts), :mod:`.link_report` (link counters and ``link`` alerts) and
:mod:`.sinks` (recording, view, publisher, status line). The settings are :mod:`.monitor_settings`.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from livesweep.errors import ConfigError
from livesweep.monitor.alerts import AlertGate
from livesweep.monitor.conditions import ConditionMeans
from livesweep.monitor.estimate_step import ALL_PAIRS_EVERY, ON_GRID_S, Estimate, EstimateStep
from livesweep.monitor.ingest import FrameQueue, Ingest
from livesweep.monitor.intake import PACE_SPAN_S, FrameIntake
from livesweep.monitor.link_report import LINK_ANOMALIES, LinkReport
from livesweep.monitor.map_check import DIAGNOSE_AFTER_S, MapCheck
from livesweep.monitor.monitor_settings import MonitorSettings
from livesweep.monitor.models import ModelKeeper
from livesweep.monitor.sinks import TIMESERIES_EVERY_S, ResultSinks
from livesweep.monitor.verdicts import Verdicts, tracker_for
from livesweep.spectral.excitation import ExcitationMonitor
from livesweep.spectral.online import OnlineSpectralEstimator
from livesweep.telemetry.align import GridAligner

# the parts' tunables are importable from here too
__all__ = ["MonitorSettings", "Estimate", "MonitorPipeline", "LINK_ANOMALIES", "ALL_PAIRS_EVERY", "DIAGNOSE_AFTER_S",
           "ON_GRID_S", "PACE_SPAN_S", "TIMESERIES_EVERY_S"]

PROCESS_EVERY_S = 0.02        # align and estimate at most this often [s of wall time] ...
PROCESS_EVERY_FRAMES = 500    # ... unless this many frames are waiting
REPORT_EVERY_S = 1.0          # link counters recorded and checked for alerts this often [s of wall time]
QUEUE_LIMIT_FRAMES = 50_000   # frames waiting for the analysis at most (about 50 MB)
SWITCH_INTERVAL_S = 0.001     # the GIL changes hands at least this often while the monitor runs


@dataclass
class _Totals:
    """What the run counted (the summary's numbers); latencies [s] of the newest 10 000."""

    frames: int = 0                 # frames received from the sources (all recorded, when recording)
    analysed: int = 0               # frames the analysis took
    blocks: int = 0
    estimates: int = 0
    ticks_skipped: int = 0          # estimate ticks skipped over a jump of the data clock
    wall_s: float = 0.0
    latency_s: deque = field(default_factory=lambda: deque(maxlen=10_000))
    verdict_latency_s: deque = field(default_factory=lambda: deque(maxlen=10_000))
    model_s: deque = field(default_factory=lambda: deque(maxlen=10_000))   # wall time to fit each model [s]


class MonitorPipeline(FrameIntake, EstimateStep, Verdicts, MapCheck, LinkReport, ResultSinks):
    """Runs the monitor over live or replayed sources.

    Parameters
    ----------
    settings : MonitorSettings
    sources : list of frames.Source
    recorder : McapRecorder, optional
    view : RerunView, optional
    publisher : ZenohPublisher, optional
    keep_estimates : bool or int
        Estimates kept in ``self.estimates`` for inspection: True all (tests, replay comparisons
        of a bounded log), False none, an int the newest that many (the default 100; a flight of
        hours at 5 estimates/s would otherwise keep gigabytes).
    queue_limit : int
        Frames that may wait for the analysis; beyond it a live source's frames are skipped by
        the analysis (recorded all the same) and counted in ``analysis_shed``.
    status_line : livesweep.monitor.status_line.StatusLine, optional
        Gets a one-line status (frames/s, losses, test point, verdict, sweep frequency, alerts)
        about once a second, for an operator without Rerun.
    results : callable, optional
        ``results(name, payload)`` gets every live result as the recording's ``/livesweep/<name>``
        channel would (``test_point``, ``verdict``, ``alert``, ``link``, every ``results_every``-th
        ``estimate``), with or without a recorder, in the caller's thread
        (:func:`livesweep.monitor.session.replay` keeps them).
    """


    def __init__(self, settings: MonitorSettings, sources, *, recorder=None, view=None, publisher=None,
                 keep_estimates: bool | int = 100, queue_limit: int = QUEUE_LIMIT_FRAMES, status_line=None,
                 results=None):
        self.settings = settings
        for n in (*settings.inputs, *settings.outputs, *(settings.references or ())):
            if n not in settings.signals:
                raise ConfigError(f"signal {n!r} is not in the channel map ({', '.join(settings.signals)})")
        self.sources = list(sources)
        self.recorder, self.view, self.publisher = recorder, view, publisher
        self.status_line = status_line
        self.results = results
        self._status_frames = (time.monotonic(), 0)
        self.names = tuple(dict.fromkeys((*settings.inputs, *settings.outputs, *(settings.references or ()))))
        self.aligner = GridAligner(settings.signals, self.names, settings.sample_rate_hz, max_fill_s=settings.window_s,
                                   system=settings.system)
        kw = {} if settings.segment_s is None else {"segment_s": settings.segment_s}
        self.estimator = OnlineSpectralEstimator(self.names, settings.inputs, settings.outputs,
                                                 settings.sample_rate_hz, settings.band_rad_s,
                                                 window_s=settings.window_s, references=settings.references or (),
                                                 **kw)
        self.excitation = ExcitationMonitor(settings.inputs, settings.outputs, settings.band_rad_s,
                                            settings.sample_rate_hz, saturation_limits=settings.saturation_limits,
                                            required_pairs=settings.required_pairs, criteria=settings.criteria)
        self.test_points = tracker_for(settings, self.names)
        self.test_points.source_rates = self._source_rates
        self.test_points.link_counts = self._link_counts      # what the link lost while a test point is open
        self.models = ModelKeeper(settings)                    # each closed test point's model, and the trend
        self.verdict, self.verdict_reasons = None, ()          # the operator's verdict (test points)
        self._rx_to_data: tuple[int, float] | None = None       # (receive ns, data s) at the aligner's frontier
        self._rx_history: deque = deque()            # (receive ns, data s) of recent frontier moves (the data's pace)
        self.keep_estimates = keep_estimates
        if keep_estimates is True:
            self.estimates: list[Estimate] | deque = []
        else:
            self.estimates = deque(maxlen=max(int(keep_estimates), 0))
        self.queue_limit = int(queue_limit)
        self.totals = _Totals()
        self.analysis_shed = 0
        self._fed_until: float | None = None         # data time fed to the estimator
        self._next_tick: float | None = None
        recent = int(round(30.0 * settings.sample_rate_hz))
        self._recent = {n: (deque(maxlen=recent), deque(maxlen=recent)) for n in settings.inputs}
        self._seen_gaps = self._seen_lost = 0
        self._invalid_fed = 0            # invalid samples fed to the estimator so far (data time, not block time)
        self._last_view_t = -math.inf
        self._view_updates = 0
        self._newest_rx: int | None = None            # receive time [ns] of the newest frame analysed
        self._told_system = None                       # the vehicle the sources were told the analysis follows
        self._t_first: float | None = None
        self._t_data: float | None = None             # newest data time analysed [s]
        self.last_status = None
        self._oldest_unlogged: int | None = None      # receive time [ns] of the oldest frame not yet shown
        self._cause_rx: int | None = None             # receive time [ns] of the oldest frame not yet processed
        self._live = False
        self._ts_buffer: list[tuple[np.ndarray, np.ndarray]] = []   # time series not yet sent to the view
        self._ts_sent = -math.inf
        self._stop = threading.Event()
        self._ingest: Ingest | None = None
        self._t_start = time.monotonic()
        self._last_report = -math.inf
        self._seen_anomalies: dict[str, int] = {}
        self._link_unsaid: dict[str, int] = {}         # link counters grown since the last link alert
        self._link_said = -math.inf                     # wall time of the last link alert
        self._alert_gate = AlertGate()
        self._seen_systems: set = set()
        self.alerts_raised = 0
        self.map_problems: list[str] | None = None    # signals that found nothing, once diagnosed
        self._map_missing: list[str] = []              # ... of which not found since
        self._first_rx: int | None = None               # receive time of the first frame [ns]
        self._topics_seen: dict = {}                    # topic -> (frames taken, the first one's data)
        self._analysed: dict[str, bool] = {}            # topic -> the analysis uses it
        self._wanted = {spec.topic for spec in self.aligner.specs.values()} | set(self.aligner.stamp_topics)
        named = getattr(settings.test_points, "conditions", ()) if settings.test_points is not None else ()
        self.conditions = ConditionMeans({n: settings.signals[n] for n in named}) if named else None
        if self.conditions is not None:
            self._wanted |= self.conditions.topics
        self._unfit: str | None = None                  # why the map does not fit the vehicle, once said
        self._lost_said = False                         # the telemetry-lost event of this silence was made

    def request_stop(self) -> None:
        """Stop at the next turn of the loop (safe from a signal handler or another thread)."""
        self._stop.set()

    @property
    def stop_requested(self) -> bool:
        """True once :meth:`request_stop` was called."""
        return self._stop.is_set()

    def run(self, duration_s: float | None = None, stop=None, clock=time.monotonic) -> dict:
        """Run until the sources finish, ``duration_s`` of wall time passes, ``stop()`` is true or
        :meth:`request_stop` is called.

        Returns
        -------
        dict
            Summary: frames, estimates, counts per source and of the aligner, final verdict.
        """
        t_start = clock()
        self._t_start = time.monotonic()
        live = self._live = any(getattr(src, "live", False) for src in self.sources)
        queue = FrameQueue(self.queue_limit, shed=live)
        ingest = self._ingest = Ingest(self.sources, queue, recorder=self.recorder, wanted_topics=self._wanted,
                                       also_wanted=self.test_points.wants)
        self._tell_sources()
        switch = sys.getswitchinterval()
        sys.setswitchinterval(min(switch, SWITCH_INTERVAL_S))   # the ingest thread gets the GIL promptly
        ingest.start()
        pending = 0
        last_process = time.monotonic()
        try:
            while True:
                frames = queue.get(timeout_s=0.02)
                for f in frames:
                    self._take(f)
                self.totals.analysed += len(frames)
                self.totals.frames = self._frames_received(ingest)
                self.analysis_shed = queue.shed + self._sources_shed()
                if frames and live and self._oldest_unlogged is None:
                    self._oldest_unlogged = frames[0].receive_ns
                pending += len(frames)
                # align and estimate in batches: per-call costs (array conversions, Rerun calls) would
                # otherwise be paid for every few frames a live socket delivers
                now = time.monotonic()
                ended = queue.ended
                if pending and (pending >= PROCESS_EVERY_FRAMES or now - last_process >= PROCESS_EVERY_S or ended):
                    self._process(now)
                    pending = 0
                    last_process = now
                if now - self._last_report >= REPORT_EVERY_S:
                    self._report(now)
                if live:
                    self._watch_link(ingest)
                ingest.check()
                if ended or self._stop.is_set():
                    break
                if duration_s is not None and clock() - t_start >= duration_s:
                    break
                if stop is not None and stop():
                    break
        finally:
            sys.setswitchinterval(switch)
            ingest.stop(drain=live)
            queue.close()
            ingest.join()
            self.totals.frames = self._frames_received(ingest)
            self.analysis_shed = queue.shed + self._sources_shed()
            try:
                while frames := queue.get(timeout_s=0):      # what the analysis had not taken yet
                    for f in frames:
                        self._take(f)
                    self.totals.analysed += len(frames)
                    pending += len(frames)
                self.aligner.settle_choice()                 # a stream too short to choose in: its frames count
                self._process(time.monotonic())
                self._test_point_records(self.test_points.finish(self._t_data))
                if self.view is not None:
                    self._flush_timeseries(time.monotonic(), force=True)
                self._report(time.monotonic(), final=True)
            finally:
                self.totals.wall_s = clock() - t_start
                self.close()
            ingest.check()
        return self.summary()

    def summary(self) -> dict:
        last = self.last_status
        lat = np.asarray(self.totals.latency_s)
        return {
            "frames": self.totals.frames if self._ingest is None else self._frames_received(self._ingest),
            "blocks": self.totals.blocks, "estimates": self.totals.estimates,
            "wall_s": round(self.totals.wall_s, 3),
            "data_s": None if self._next_tick is None else round(self._next_tick - self.settings.update_period_s - self._t_first, 3),
            "aligner": dict(self.aligner.counts),
            "system": self.aligner.system, "system_choice": self.aligner.choice,
            "sources": [src.counts for src in self.sources],
            "counters": self.counters(),
            "alerts_recorded": self.alerts_raised,
            # the map's problems that still stand (a signal found later is not a problem any more)
            "map_problems": [line for line in (self.map_problems or ())
                             if any(line.startswith(f"signal {n}:") for n in self._map_missing)],
            "recorded": None if self.recorder is None else dict(self.recorder.message_counts),
            "verdict": self.verdict,
            "reasons": list(self.verdict_reasons),
            "test_points": list(self.test_points.closed),
            "window_verdict": None if last is None else last.verdict,
            "adequacy": [] if last is None else [
                {"output": p.output, "input": p.input, "band": p.adequate_band_rad_s, "fraction": p.fraction}
                for p in last.pairs],
            "latency_p50_s": float(np.percentile(lat, 50)) if lat.size else None,
            "latency_p99_s": float(np.percentile(lat, 99)) if lat.size else None,
            "verdict_latency_s": [round(x, 4) for x in self.totals.verdict_latency_s],
            "models": list(self.models.models),
            "model_s": [round(x, 4) for x in self.totals.model_s],
        }
