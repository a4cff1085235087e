"""The live (and replay) monitor: sources -> recorder -> aligner -> online estimator -> view.

One loop polls every source, records every frame as received, aligns the channel map's signals
onto the estimator's grid, feeds the sliding-window estimator and, at fixed ticks of the
signals' clock (``update_period_s``), computes the estimate, the excitation status and alerts,
and sends them to the Rerun view, the Zenoh publisher and the recording.

Ticks are on the data's clock, never the wall clock, and the estimator is fed exactly up to each
tick, so the estimates depend only on the frames: replaying a recording reproduces the live
estimates (a test checks equality to 1e-9).
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import asdict, dataclass, field

import numpy as np

from livesweep.errors import ConfigError
from livesweep.spectral.excitation import ExcitationMonitor
from livesweep.spectral.online import OnlineSpectralEstimator
from livesweep.telemetry.align import GridAligner

__all__ = ["MonitorSettings", "Estimate", "MonitorPipeline"]

PROCESS_EVERY_S = 0.02        # align and estimate at most this often [s of wall time] ...
PROCESS_EVERY_FRAMES = 500    # ... unless this many frames are waiting


@dataclass(frozen=True)
class MonitorSettings:
    """What the monitor estimates, and how.

    Attributes
    ----------
    signals : dict of str -> SignalSpec
        The channel map.
    inputs, outputs : tuple of str
    band_rad_s : (float, float)
    sample_rate_hz : float
        Estimator grid [Hz].
    window_s : float
        Sliding window [s].
    segment_s : float or None
        Segment (FFT window) length [s]; None: the estimator's default.
    update_period_s : float
        Estimate every this much data time [s] (0.2 s = 5 updates/s).
    results_every : int
        Record every n-th estimate in the MCAP (1 = all).
    saturation_limits : dict of input -> (lo, hi), optional
        Actuator limits in input units.
    required_pairs : tuple of (output, input), optional
        The pairs this test point must excite for a GO (default: the on-axis pairs).
    view_period_s : float
        Send an estimate to the Rerun view at most this often [s of data]: every estimate re-logs
        every pair's curves and waterfall (about 0.3 MB for 4 x 12 pairs), so the view refreshes
        at 1 Hz by default while the estimates themselves run at ``update_period_s``.
    references : tuple of str, optional
        One exogenous reference per input (a closed-loop test point's logged sweep injection): the
        live responses and coherences are then formed through them (method.md §4.6), free of the
        feedback bias; while a reference is silent the direct estimate is shown.
    """

    signals: dict
    inputs: tuple
    outputs: tuple
    band_rad_s: tuple
    sample_rate_hz: float = 50.0
    window_s: float = 120.0
    segment_s: float | None = None
    update_period_s: float = 0.2
    results_every: int = 5
    saturation_limits: dict | None = None
    required_pairs: tuple | None = None
    view_period_s: float = 1.0
    references: tuple | None = None

    def to_dict(self) -> dict:
        return {
            "signals": {n: asdict(s) for n, s in self.signals.items()},
            "inputs": list(self.inputs), "outputs": list(self.outputs), "band_rad_s": list(self.band_rad_s),
            "sample_rate_hz": self.sample_rate_hz, "window_s": self.window_s, "segment_s": self.segment_s,
            "update_period_s": self.update_period_s,
            "required_pairs": None if self.required_pairs is None else [list(p) for p in self.required_pairs],
            "references": None if not self.references else list(self.references),
        }


@dataclass(frozen=True)
class Estimate:
    """One live estimate (what the view shows at ``t_s``)."""

    t_s: float
    omega: np.ndarray
    coherence: np.ndarray
    magnitude_db: np.ndarray
    phase_deg: np.ndarray
    conditioned: bool
    status: object
    n_segments: int


@dataclass
class _Totals:
    frames: int = 0
    blocks: int = 0
    estimates: int = 0
    wall_s: float = 0.0
    latency_s: list = field(default_factory=list)


class MonitorPipeline:
    """Runs the monitor over live or replayed sources.

    Parameters
    ----------
    settings : MonitorSettings
    sources : list of frames.Source
    recorder : McapRecorder, optional
    view : RerunView, optional
    publisher : ZenohPublisher, optional
    keep_estimates : bool
        Keep every Estimate in ``self.estimates`` (tests, replay comparison).
    """

    def __init__(self, settings: MonitorSettings, sources, *, recorder=None, view=None, publisher=None,
                 keep_estimates: bool = True):
        self.s = settings
        for n in (*settings.inputs, *settings.outputs, *(settings.references or ())):
            if n not in settings.signals:
                raise ConfigError(f"signal {n!r} is not in the channel map ({', '.join(settings.signals)})")
        self.sources = list(sources)
        self.recorder, self.view, self.publisher = recorder, view, publisher
        self.names = tuple(dict.fromkeys((*settings.inputs, *settings.outputs, *(settings.references or ()))))
        self.aligner = GridAligner(settings.signals, self.names, settings.sample_rate_hz)
        kw = {} if settings.segment_s is None else {"segment_s": settings.segment_s}
        self.estimator = OnlineSpectralEstimator(self.names, settings.inputs, settings.outputs,
                                                 settings.sample_rate_hz, settings.band_rad_s,
                                                 window_s=settings.window_s, references=settings.references or (),
                                                 **kw)
        self.excitation = ExcitationMonitor(settings.inputs, settings.outputs, settings.band_rad_s,
                                            settings.sample_rate_hz, saturation_limits=settings.saturation_limits,
                                            required_pairs=settings.required_pairs)
        self.keep_estimates = keep_estimates
        self.estimates: list[Estimate] = []
        self.totals = _Totals()
        self._fed_until: float | None = None         # data time fed to the estimator
        self._next_tick: float | None = None
        recent = int(round(30.0 * settings.sample_rate_hz))
        self._recent = {n: (deque(maxlen=recent), deque(maxlen=recent)) for n in settings.inputs}
        self._seen_gaps = self._seen_lost = 0
        self._last_view_t = -math.inf
        self._t_first: float | None = None
        self.last_status = None
        self._oldest_unlogged: float | None = None

    # -- the loop ---------------------------------------------------------------------------
    def run(self, duration_s: float | None = None, stop=None, clock=time.monotonic) -> dict:
        """Poll the sources until they finish, ``duration_s`` of wall time passes or ``stop()`` is true.

        Returns
        -------
        dict
            Summary: frames, estimates, counts per source and of the aligner, final verdict.
        """
        t_start = clock()
        timeout = 0.02 if len(self.sources) > 1 else 0.05
        pending = 0
        last_process = time.monotonic()
        try:
            while True:
                got = 0
                for src in self.sources:
                    frames = src.poll(timeout_s=timeout)
                    if not frames:
                        continue
                    got += len(frames)
                    if self._oldest_unlogged is None:
                        self._oldest_unlogged = time.monotonic()
                    if self.recorder is not None:
                        self.recorder.record(frames)
                    for f in frames:
                        self.aligner.push(f)
                self.totals.frames += got
                pending += got
                # align and estimate in batches: per-call costs (array conversions, Rerun calls) would
                # otherwise be paid for every few frames a live socket delivers
                now = time.monotonic()
                finished = all(s.finished for s in self.sources)
                if pending and (pending >= PROCESS_EVERY_FRAMES or now - last_process >= PROCESS_EVERY_S or finished):
                    self._process(now)
                    pending = 0
                    last_process = now
                if self.recorder is not None:
                    self.recorder.maybe_flush()
                if finished:
                    break
                if duration_s is not None and clock() - t_start >= duration_s:
                    break
                if stop is not None and stop():
                    break
            if pending:
                self._process(time.monotonic())
        finally:
            self.totals.wall_s = clock() - t_start
            self.close()
        return self.summary()

    def _process(self, t_rx: float) -> None:
        block = self.aligner.pop_ready()
        if block is None:
            return
        self.totals.blocks += 1
        fs = self.s.sample_rate_hz
        n = block.values.shape[1]
        t = block.t0_s + np.arange(n) / fs
        if self.view is not None:
            self.view.log_timeseries(t, list(self.names), block.values,
                                     ["output" if x in self.s.outputs else "input" for x in self.names])
        if self._next_tick is None:
            self._next_tick = block.t0_s + self.s.update_period_s
            self._t_first = block.t0_s
        # feed the estimator tick by tick so estimates depend on data time only
        start = 0
        while start < n:
            k_tick = int(math.floor((self._next_tick - block.t0_s) * fs + 1e-9)) + 1   # samples up to the tick
            stop = min(n, max(k_tick, start))
            if stop > start:
                self.estimator.update(block.values[:, start:stop], block.valid[start:stop])
                for name in self.s.inputs:
                    tt, vv = self._recent[name]
                    tt.extend(t[start:stop])
                    vv.extend(block.values[self.names.index(name), start:stop])
                start = stop
            if k_tick <= n:
                self._estimate(self._next_tick, t_rx)
                self._next_tick += self.s.update_period_s
            else:
                break

    def _estimate(self, t_s: float, t_rx: float) -> None:
        res = self.estimator.result()
        if res is None:
            return
        frs = res.best
        recent = {n: (np.asarray(tt), np.asarray(vv)) for n, (tt, vv) in self._recent.items()}
        lost = sum(self._packets_lost().values())
        gaps = self.aligner.counts["samples_invalid"]
        status = self.excitation.update(res, recent, gaps=gaps - self._seen_gaps, packets_lost=lost - self._seen_lost)
        self._seen_gaps, self._seen_lost = gaps, lost
        mag = 20 * np.log10(np.maximum(np.abs(frs.H), 1e-300))
        phase = np.rad2deg(np.unwrap(np.angle(frs.H), axis=-1))
        est = Estimate(t_s, frs.omega, frs.coherence, mag, phase, frs.conditioned, status, res.n_segments)
        self.totals.estimates += 1
        self.last_status = status
        if self.keep_estimates:
            self.estimates.append(est)
        rows = [{"output": p.output, "input": p.input, "band": p.adequate_band_rad_s, "fraction": p.fraction}
                for p in status.pairs]
        if self.view is not None and t_s - self._last_view_t >= self.s.view_period_s - 1e-9:
            self._last_view_t = t_s
            self.view.log_estimate(t_s, frs.omega, list(frs.outputs), list(frs.inputs), frs.coherence, mag, phase,
                                   rows, status.verdict, list(status.reasons))
            if status.alerts:
                self.view.log_alerts(t_s, [(a.kind, a.message) for a in status.alerts])
            if self._oldest_unlogged is not None:     # arrival of the oldest frame this estimate includes
                self.totals.latency_s.append(time.monotonic() - self._oldest_unlogged)
                self._oldest_unlogged = None
        payload = self._payload(est, rows)
        if self.publisher is not None:
            self.publisher.publish("estimate", payload)
        if self.recorder is not None and self.totals.estimates % max(1, self.s.results_every) == 0:
            self.recorder.record_result("estimate", payload, log_time_ns=time.time_ns())

    def _payload(self, est: Estimate, rows) -> dict:
        st = est.status
        return {
            "t_s": est.t_s, "n_segments": est.n_segments, "conditioned": est.conditioned,
            "omega_rad_s": est.omega.tolist(),
            "coherence": {f"{o}/{i}": est.coherence[a, b].tolist() for a, o in enumerate(self.s.outputs)
                          for b, i in enumerate(self.s.inputs)},
            "adequacy": [{**r, "band": None if r["band"] is None else list(r["band"])} for r in rows],
            "verdict": st.verdict, "reasons": list(st.reasons),
            "alerts": [{"kind": a.kind, "message": a.message} for a in st.alerts],
        }

    def _packets_lost(self) -> dict:
        out = {}
        for k, src in enumerate(self.sources):
            gaps = src.counts.get("seq_gaps") if isinstance(src.counts, dict) else None
            if isinstance(gaps, dict):
                out[k] = sum(int(v) for v in gaps.values())
        return out

    # -- end --------------------------------------------------------------------------------
    def close(self) -> None:
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

    def summary(self) -> dict:
        last = self.last_status
        lat = np.asarray(self.totals.latency_s)
        return {
            "frames": self.totals.frames, "blocks": self.totals.blocks, "estimates": self.totals.estimates,
            "wall_s": round(self.totals.wall_s, 3),
            "data_s": None if self._next_tick is None else round(self._next_tick - self.s.update_period_s - self._t_first, 3),
            "aligner": dict(self.aligner.counts),
            "sources": [src.counts for src in self.sources],
            "recorded": None if self.recorder is None else dict(self.recorder.message_counts),
            "verdict": None if last is None else last.verdict,
            "reasons": [] if last is None else list(last.reasons),
            "adequacy": [] if last is None else [
                {"output": p.output, "input": p.input, "band": p.adequate_band_rad_s, "fraction": p.fraction}
                for p in last.pairs],
            "latency_p50_s": float(np.percentile(lat, 50)) if lat.size else None,
            "latency_p99_s": float(np.percentile(lat, 99)) if lat.size else None,
        }
