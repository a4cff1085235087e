"""The estimate step of the monitor pipeline: aligned blocks, tick by tick, to estimates.

:class:`EstimateStep` is a part of :class:`~livesweep.monitor.pipeline.MonitorPipeline` (a mixin
on its state): it takes the aligner's ready blocks, feeds the test points and the sliding-window
estimator up to each tick of the data's clock (``update_period_s``), and at each tick makes an
:class:`Estimate` with the excitation status, sends it to the Rerun view (every
``view_period_s``), the publisher and the recording, and raises the window's alerts. Ticks are
on the data's clock and the estimator is fed exactly up to each one, so the estimates do not
depend on how the frames were batched (a replay reproduces the live run).
"""

from __future__ import annotations

import bisect
import math
import time
from dataclasses import dataclass

import numpy as np

from livesweep.monitor.testpoints import GRID_TOL
from livesweep.telemetry.clock import receive_ns

__all__ = ["Estimate", "EstimateStep", "ALL_PAIRS_EVERY", "ON_GRID_S"]

ALL_PAIRS_EVERY = 5           # every pair's spectra go to the view every this many view updates (the heavy part)
ON_GRID_S = 1e-7              # a sample time within this of a grid time is on it [s] (as the aligner has it)


@dataclass(frozen=True)
class Estimate:
    """One live estimate (what the view shows at ``t_s``).

    Attributes
    ----------
    t_s : float
        Data time of the tick [s].
    omega : ndarray (n_f,)
        Frequency grid [rad/s].
    coherence : ndarray (n_out, n_in, n_f)
        gamma^2 (the one the adequacy judged: see ``coherence_kind``).
    magnitude_db, phase_deg : ndarray (n_out, n_in, n_f)
        |H| [dB] and phase [deg, unwrapped along frequency].
    conditioned : bool
        The responses are conditioned on the other inputs (MISO).
    status : livesweep.spectral.excitation.ExcitationStatus
        The sliding window's excitation status at ``t_s``.
    n_segments : int
        Segments averaged in the window.
    coherence_kind : str
        ``"ordinary"`` or ``"partial"``.
    """

    t_s: float
    omega: np.ndarray
    coherence: np.ndarray
    magnitude_db: np.ndarray
    phase_deg: np.ndarray
    conditioned: bool
    status: object
    n_segments: int
    coherence_kind: str = "ordinary"      # "ordinary" or "partial": the coherence the adequacy judged


class EstimateStep:
    """Aligned blocks to estimates (mixin of :class:`~livesweep.monitor.pipeline.MonitorPipeline`,
    whose ``__init__`` sets the state these methods use: ``aligner``, ``estimator``,
    ``excitation``, ``test_points``, ``settings``, ``totals``, ``estimates`` and the step's
    private fields)."""

    def _drain_blocks(self) -> None:
        """Every block the aligner has ready, now: what follows (a test-point event, a map alert)
        then sees the same samples whatever the batch sizes (a replay takes thousands of frames at
        once, a live link a few)."""
        while (got := self._pop_ready())[0] is not None:
            self._process_block(*got, time.monotonic())

    def _process(self, t_rx: float) -> None:
        """Every block the aligner has ready, through the estimator tick by tick."""
        while (got := self._pop_ready())[0] is not None:
            self._process_block(*got, t_rx)
        self._flush_timeseries(t_rx)
        self._cause_rx = None

    def _pop_ready(self) -> tuple:
        """``(block, raw)``: the aligner's next block (None: none ready) and, on the vehicle clock,
        per signal the times [s] of the samples it received for the block's grid samples (those in
        ``(t_k - 1/fs, t_k]`` of each grid time ``t_k``), read before the aligner lets them go: a
        test point counts the frames its signals lost from them. ``raw`` is None on receive time
        (arrival times say nothing of what was sent)."""
        al = self.aligner
        if al.clock != "vehicle" or al.t0 is None:
            return al.pop_ready(), None
        fs = self.settings.sample_rate_hz
        after = al.t0 + (al.next_k - 1) / fs + ON_GRID_S          # the grid emitted so far ends here
        held = {n: al.ch[n].t[bisect.bisect_right(al.ch[n].t, after):] for n in self.names}
        block = al.pop_ready()
        if block is None:
            return None, None
        n = block.values.shape[1]
        t = block.t_s if block.t_s is not None else block.t0_s + np.arange(n) / fs
        return block, self._raw_between(held, t[0] - 1.0 / fs + ON_GRID_S, t[-1] + ON_GRID_S)

    @staticmethod
    def _raw_between(raw: dict, lo: float, hi: float) -> dict:
        """Each signal's sample times [s] in ``(lo, hi]`` (``raw``'s are sorted, as the aligner keeps them)."""
        out = {}
        for name, ts in raw.items():
            ts = np.asarray(ts, float)
            out[name] = ts[np.searchsorted(ts, lo, "right"):np.searchsorted(ts, hi, "right")]
        return out

    def _process_block(self, block, raw: dict | None, t_rx: float) -> None:
        """One aligned block (:meth:`_pop_ready`) into the test points and the estimator, with an
        estimate at every tick it reaches; ``t_rx`` the wall time [s] it is processed at."""
        self.totals.blocks += 1
        fs = self.settings.sample_rate_hz
        n = block.values.shape[1]
        t = block.t_s if block.t_s is not None else block.t0_s + np.arange(n) / fs
        self._t_data = float(t[-1])
        if self.view is not None:
            self._ts_buffer.append((t, block.values))
        if self.verdict is None:
            self._update_verdict(block.t0_s)
        if self._next_tick is None:
            self._next_tick = block.t0_s + self.settings.update_period_s
            self._t_first = block.t0_s
        elif self._next_tick < block.t0_s - self.settings.update_period_s:
            # the data clock jumped (a long gap, or the aligner skipped a jump): no estimates for ticks
            # before this block, whose samples are gone
            skip = int(math.floor((block.t0_s - self._next_tick) / self.settings.update_period_s))
            self._next_tick += skip * self.settings.update_period_s
            self.totals.ticks_skipped += skip
        # feed the test points and the estimator tick by tick, so estimates, and the verdict shown
        # with them, depend on data time only (a replay's long blocks must not show an estimate with
        # a verdict judged later in its block)
        start = 0
        while start < n:
            # samples up to the tick; GRID_TOL: a tick on a sample stays on it whatever block it falls in
            k_tick = int(math.floor((self._next_tick - block.t0_s) * fs + GRID_TOL)) + 1
            stop = min(n, max(k_tick, start))
            if stop > start:
                sub = None if raw is None else self._raw_between(raw, t[start] - 1.0 / fs + ON_GRID_S,
                                                                 t[stop - 1] + ON_GRID_S)
                self._test_point_records(self.test_points.block(float(t[start]), block.values[:, start:stop],
                                                                block.valid[start:stop], t[start:stop], sub))
                self.estimator.update(block.values[:, start:stop], block.valid[start:stop])
                self._invalid_fed += int(np.sum(~block.valid[start:stop]))
                for name in self.settings.inputs:
                    tt, vv = self._recent[name]
                    tt.extend(t[start:stop])
                    vv.extend(block.values[self.names.index(name), start:stop])
                start = stop
            if k_tick <= n:
                self._estimate(self._next_tick, t_rx)
                self._next_tick += self.settings.update_period_s
            else:
                break

    def _estimate(self, t_s: float, t_rx: float) -> None:
        """The estimate at tick ``t_s`` [s of data time] to the view, the publisher, the recording
        and ``estimates``, with the window's alerts."""
        res = self.estimator.result()
        if res is None:
            return
        frs, coherence_kind = self.excitation.judged(res)      # shown = judged
        recent = {n: (np.asarray(tt), np.asarray(vv)) for n, (tt, vv) in self._recent.items()}
        lost = sum(self._packets_lost().values())
        # gaps counted as the estimator meets them, so a tick reports the same gaps whatever the block sizes
        # (a replay's blocks are longer than the live link's)
        gaps = self._invalid_fed
        status = self.excitation.update(res, recent, gaps=gaps - self._seen_gaps, packets_lost=lost - self._seen_lost,
                                        sweeping=self._sweep_in_window(t_s))
        self._seen_gaps, self._seen_lost = gaps, lost
        mag = 20 * np.log10(np.maximum(np.abs(frs.H), 1e-300))
        phase = np.rad2deg(np.unwrap(np.angle(frs.H), axis=-1))
        est = Estimate(t_s, frs.omega, frs.coherence, mag, phase, frs.conditioned, status, res.n_segments,
                       coherence_kind)
        self.totals.estimates += 1
        self.last_status = status
        if self.keep_estimates is not False:
            self.estimates.append(est)
        rows = [{"output": p.output, "input": p.input, "band": p.adequate_band_rad_s, "fraction": p.fraction}
                for p in status.pairs]
        if self.view is not None and t_s - self._last_view_t >= self.settings.view_period_s - 1e-9:
            self._last_view_t = t_s
            self._view_updates += 1
            sweep, band = self._sweep_now(t_s, status)
            self.view.log_estimate(t_s, frs.omega, list(frs.outputs), list(frs.inputs), frs.coherence, mag, phase,
                                   [r for r, p in zip(rows, status.pairs) if p.required],
                                   self.verdict or "WAIT", list(self.verdict_reasons),
                                   coherence_kind=coherence_kind, sweep=sweep, band_rad_s=band,
                                   spectra=(self._view_updates - 1) % ALL_PAIRS_EVERY == 0,
                                   lag_s=self._lag_s())
            if self._oldest_unlogged is not None:     # receipt of the oldest frame this estimate includes
                self.totals.latency_s.append((receive_ns() - self._oldest_unlogged) * 1e-9)
                self._oldest_unlogged = None
        for a in self._said(t_s, status.alerts):
            self._say_alert(t_s, a)
        payload = self._payload(est, rows)
        if self.publisher is not None:
            self.publisher.publish("estimate", payload)
        if self.totals.estimates % max(1, self.settings.results_every) == 0:
            self._result("estimate", payload)

    def _sweep_in_window(self, t_s: float) -> bool:
        """A test point's data is in the sliding window: while one runs, and until its data has left."""
        tracker = self.test_points
        last_end = max((tp["end_s"] for tp in tracker.closed[-1:]), default=None)
        return tracker.current is not None or bool(tracker.closing) or \
            (last_end is not None and t_s - last_end < self.settings.window_s)

    def _said(self, t_s: float, alerts) -> list:
        """The sliding window's alerts an operator should read now: each subject at most every
        ``ALERT_INTERVAL_S`` of data time."""
        return [a for a in (self._alert_gate.admit(t_s, a) for a in alerts) if a is not None]

    def _lag_s(self) -> float | None:
        """How far the analysis is behind the link [s]: now minus the receipt of the newest frame it
        took (live only: a replay's receive times are the recording's)."""
        if not self._live or self._newest_rx is None:
            return None
        return max((receive_ns() - self._newest_rx) * 1e-9, 0.0)

    def _sweep_now(self, t_s: float, status) -> tuple[dict, tuple | None]:
        """Per input (sweep frequency [rad/s], time to the band top [s]) and the band the running test
        point is judged over: the injection's own schedule when the autopilot said what it injects
        (a closed-loop input's zero crossings would say less), else the input's tracked sweep."""
        sweep = {i: (status.sweep_frequency_rad_s.get(i), status.time_remaining_s.get(i)) for i in self.settings.inputs}
        cur = self.test_points.current
        if cur is None:              # between test points an input's oscillation is no sweep to report
            return {i: (None, None) for i in sweep}, None
        if cur.swept_input in sweep:                 # the other inputs are the controller's reaction
            sweep = {i: v if i == cur.swept_input else (None, None) for i, v in sweep.items()}
        inj = cur.injection
        if inj is None:
            return sweep, self.settings.band_rad_s
        elapsed = t_s - cur.start_s
        if cur.swept_input in sweep and inj.delay_s < elapsed < inj.duration_s:
            sweep[cur.swept_input] = (float(inj.omega_at(elapsed)), inj.duration_s - elapsed)
        return sweep, inj.band_rad_s

    def _payload(self, est: Estimate, rows) -> dict:
        st = est.status
        return {
            "t_s": est.t_s, "n_segments": est.n_segments, "conditioned": est.conditioned,
            "coherence_kind": est.coherence_kind,
            "omega_rad_s": est.omega.tolist(),
            "coherence": {f"{o}/{i}": est.coherence[a, b].tolist() for a, o in enumerate(self.settings.outputs)
                          for b, i in enumerate(self.settings.inputs)},
            "adequacy": [{**r, "band": None if r["band"] is None else list(r["band"])} for r in rows],
            "pairs": self._pair_payload(est, rows),
            "verdict": self.verdict or "WAIT", "reasons": list(self.verdict_reasons),
            "go": 1 if self.verdict == "GO" else 0,
            "window_verdict": st.verdict,
            "alerts": [{"kind": a.kind, "message": a.message} for a in st.alerts],
        }

    def _pair_payload(self, est: Estimate, rows) -> list:
        """Per pair: the estimate over the grid and two numbers to plot against time (Foxglove:
        ``/livesweep/estimate.pairs[:]{name=="p/da"}.median_coherence``)."""
        frac = {(r["output"], r["input"]): r["fraction"] for r in rows}
        out = []
        for a, o in enumerate(self.settings.outputs):
            for b, i in enumerate(self.settings.inputs):
                coh = np.asarray(est.coherence[a, b], float)
                ok = np.isfinite(coh)
                out.append({"name": f"{o}/{i}", "output": o, "input": i,
                            "omega_rad_s": est.omega.tolist(),
                            "magnitude_db": np.asarray(est.magnitude_db[a, b], float).tolist(),
                            "phase_deg": np.asarray(est.phase_deg[a, b], float).tolist(),
                            "coherence": coh.tolist(),
                            "median_coherence": float(np.median(coh[ok])) if ok.any() else float("nan"),
                            "adequate_fraction": float(frac.get((o, i), 0.0))})
        return out
