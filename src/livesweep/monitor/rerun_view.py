"""The live Rerun view of the sweep monitor: one recording stream, its sinks, and what is logged.

What the engineer sees, and how each item is represented (entity paths: :mod:`.blueprint`):

* **Time series** of inputs and outputs: ``rr.Scalars`` per signal, sent in blocks with
  ``send_columns`` on the ``flight_time`` timeline (a duration; ``round(t_s * 1e9)`` ns; a
  timestamp when the data's clock is seconds since the UNIX epoch, as a receive-time map's is,
  so the time axis reads as the UTC clock rather than 20 000 days). The legend names carry the
  units (``"da [deg]"``).
* **Frequency plots** per pair (coherence, |H| [dB] and phase [deg] against ``log10 omega``, grey
  and thin where gamma^2 is below the criteria's threshold) and the **coherence waterfall** per pair: drawn by
  :mod:`.rerun_plots`, which describes them.
* **Status**: a markdown ``rr.TextDocument`` (verdict, which coherence was judged, the sweep
  frequency and time still needed per input, the reasons, and the adequacy table with
  percentages from :func:`livesweep.monitor.text.percent`), ``status/adequacy_fraction`` (one
  series per pair), ``status/sweep_frequency/<input>`` [rad/s] and ``status/time_remaining/<input>``
  [s] (NaN while unknown).
* **Test points**: a markdown ``rr.TextDocument`` with the open test point and the closed ones.
* **Alerts**: ``rr.TextLog`` at level WARN, text ``"[kind] message"``.
* **Model** of each closed test point (its fit over the data's Bode plots, its numbers, the trend
  over the flight): drawn by :mod:`.rerun_model`, which describes them.

Costs: ``rr.log`` with archetype objects costs ~0.3-1.4 ms per spectral entity (the Python-side
conversion), i.e. >100 ms per update for 48 pairs. The hot path therefore logs ready Arrow arrays
with their component descriptors; :mod:`.rerun_compat` builds them (directly from rerun-sdk
internals for the versions it knows, else through the public API).

Viewer modes: ``save_path`` (an ``.rrd`` file with the blueprint), ``spawn`` (the desktop viewer;
blocks ~11 s and fails without a display), ``serve`` (the bundled ``rerun`` CLI as a child process
serving the web viewer and a gRPC proxy bound to ``bind_host`` only: :mod:`.rerun_server`). Sinks
combine: saving and serving at once is fine.
"""

from __future__ import annotations

import logging
import math
import os
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr

from livesweep.monitor import rerun_compat, rerun_model
from livesweep.monitor.blueprint import (
    ADEQUACY_PATH, ALERTS_PATH, BAND_EDGE_PATHS, FOCUS_PATH, FRACTION_PATH, TEST_POINTS_PATH, TIMELINE, check_names,
    default_blueprint, pair_label, sweep_frequency_path, telemetry_path, time_remaining_path,
)
from livesweep.monitor.freq_plot import frequency_extent, reference_phase
from livesweep.monitor.rerun_plots import ArrowBatch, FrequencyPlots, PairState, descriptors
from livesweep.monitor.rerun_server import WebViewerServer, find_rerun_cli, serve_banner
from livesweep.monitor.text import EPOCH_MIN_S, adequacy_markdown, coherence_kind_text, markdown_test_points
from livesweep.spectral.criteria import DEFAULT_CRITERIA

__all__ = ["RerunView", "find_rerun_cli", "series_label", "adequacy_markdown", "serve_banner"]

log = logging.getLogger(__name__)

_BAND_EDGE_COLOR = (90, 90, 90)        # the judged band's edges on the sweep-frequency plot: seen at a glance
_TITLE_COLOR = (40, 40, 40)


def _tensor_array(values: np.ndarray, dim_names: tuple | None = None) -> pa.Array:
    """One ``TensorData`` Arrow array of ``values`` as the view logs it (:func:`.rerun_compat.arrays`),
    identical to ``rr.components.TensorDataBatch(values).as_arrow_array()``."""
    return rerun_compat.arrays().tensor(values, dim_names)


def _ns(t_s) -> np.ndarray:
    """Seconds -> int64 nanoseconds, rounded (Rerun truncates float arrays; we round everywhere)."""
    return np.rint(np.asarray(t_s, dtype=np.float64) * 1e9).astype(np.int64)


class RerunView:
    """Live Rerun view of the sweep monitor (see the module docstring for what is shown).

    Parameters
    ----------
    inputs, outputs : sequence of str
        Signal names; they fix the default blueprint and the pairs (output/input).
    application_id, recording_id : str
        Rerun identifiers (recording_id None: a random one).
    save_path : path or None
        Write an ``.rrd`` file (with the default blueprint). Finalised by :meth:`close`.
    spawn : bool
        Start the desktop viewer (``rr.spawn``) on ``grpc_port`` and stream to it. Needs a display.
    serve : bool
        Start the bundled ``rerun`` CLI serving the web viewer on ``bind_host:web_port`` and a gRPC
        proxy on ``bind_host:grpc_port``; :attr:`web_url` is the address to open. Not together
        with ``spawn`` (both would use ``grpc_port``; open :attr:`web_url` instead).
    waterfall_rows : int
        Estimates kept in each coherence waterfall (0: no waterfall).
    waterfall_every : int
        Re-log the waterfalls every k-th estimate (rows are still added on every estimate).
    flush_timeout_s : float
        Upper bound for :meth:`flush` (an unreachable gRPC sink must not hang shutdown).
    test_point_history : int
        Closed test points kept in the test-point document (the oldest drop out).
    min_coherence : float
        The criteria's coherence threshold: the line and legend on the coherence plots, grey below
        it, and the status text (the settings' ``criteria``).

    With no sink at all the data goes to an in-memory recording, :attr:`memory`
    (``rr.MemoryRecording``; drain it or it grows).
    """

    def __init__(self, inputs: Sequence[str], outputs: Sequence[str], *, application_id: str = "livesweep",
                 recording_id: str | None = None, save_path: str | os.PathLike | None = None, spawn: bool = False,
                 serve: bool = False, bind_host: str = "127.0.0.1", grpc_port: int = 9876, web_port: int = 9090,
                 waterfall_rows: int = 30, waterfall_every: int = 1, flush_timeout_s: float = 10.0,
                 test_point_history: int = 50, min_coherence: float = DEFAULT_CRITERIA.min_coherence) -> None:
        self.inputs, self.outputs = list(inputs), list(outputs)
        check_names(self.inputs, self.outputs)
        if spawn and serve:
            raise ValueError("spawn=True and serve=True both use grpc_port; use serve=True and open web_url")
        if waterfall_rows < 0 or waterfall_every < 1:
            raise ValueError(f"waterfall_rows must be >= 0 and waterfall_every >= 1, got "
                             f"{waterfall_rows} and {waterfall_every}")
        self.waterfall_rows, self.waterfall_every = int(waterfall_rows), int(waterfall_every)
        self.flush_timeout_s = float(flush_timeout_s)
        self.test_point_history = max(0, int(test_point_history))
        self.min_coherence = float(min_coherence)
        self.blueprint = default_blueprint(self.inputs, self.outputs, min_coherence=self.min_coherence)
        self.save_path = None if save_path is None else Path(save_path)
        self.web_url: str | None = None
        self.grpc_url: str | None = None
        self.memory = None
        self._server: WebViewerServer | None = None
        self._lock = threading.RLock()
        self._closed = False
        self._series_labels: dict[str, str] = {}
        self._sweep_inputs: set[str] = set()
        self._test_points: dict[tuple, tuple[int, dict]] = {}   # (start_s, swept_input) -> (number, record)
        self._n_test_points = 0
        self._epoch: bool | None = None       # flight_time as a UNIX timestamp (decided by the first time)
        self._focus: PairState | None = None  # the swept pair of the test point (focus/)
        self._model: rerun_model.ModelPanel | None = None   # the "Model" tab
        self._early_alerts: list = []          # alerts before any flight time: logged at the first one
        self._band_named = False
        self._status: dict | None = None              # the last estimate's status table (re-shown on a verdict change)

        self.rec = rr.RecordingStream(application_id, recording_id=recording_id)
        self.rec.set_log_time_enabled(False)   # flight_time is the only timeline: replay == live
        self.rec.set_log_tick_enabled(False)

        sinks = []
        try:
            if self.save_path is not None:
                self.save_path.parent.mkdir(parents=True, exist_ok=True)
                sinks.append(rr.FileSink(str(self.save_path)))
            if serve:
                self._server = WebViewerServer(bind_host, grpc_port, web_port)
                self.grpc_url, self.web_url = self._server.grpc_url, self._server.web_url
                sinks.append(rr.GrpcSink(self.grpc_url))
                log.info("Rerun web viewer at %s (gRPC %s)", self.web_url, self.grpc_url)
                print(serve_banner(bind_host, web_port, grpc_port, self.web_url), file=sys.stderr, flush=True)
            if spawn:
                self.rec.spawn(port=int(grpc_port), connect=False, hide_welcome_screen=True)
                self.grpc_url = f"rerun+http://127.0.0.1:{int(grpc_port)}/proxy"
                sinks.append(rr.GrpcSink(self.grpc_url))
            if sinks:
                self.rec.set_sinks(*sinks, default_blueprint=self.blueprint)
            else:
                self.memory = self.rec.memory_recording()
                self.rec.send_blueprint(self.blueprint)
        except BaseException:
            if self._server is not None:
                self._server.stop()
            raise

        # the frequency plots (their descriptors are built here, paying Rerun's one-off lazy
        # initialisation, ~100 ms, before the first estimate) and the time series' descriptor
        self._plots = FrequencyPlots(self.rec, len(self.inputs), self.waterfall_rows, self.waterfall_every,
                                     rerun_compat.arrays(), min_coherence=self.min_coherence)
        self._d_scalars = descriptors(rr.Scalars([0.0]))["Scalars:scalars"]

        for name in self.inputs:
            self._ensure_series(telemetry_path("input", name), name)
        for name in self.outputs:
            self._ensure_series(telemetry_path("output", name), name)
        self._fraction_pairs: list = []        # the pairs of the adequacy rows (series names logged for them)
        for o in self.outputs:
            for i in self.inputs:
                self._plots.pair(o, i)

    # ---------------------------------------------------------------- helpers

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError("RerunView is closed")

    def _ensure_series(self, path: str, label: str) -> None:
        """The series' name in the legend (static), logged again only when it changes."""
        if self._series_labels.get(path) != label:
            self.rec.log(path, rr.SeriesLines(names=label), static=True)
            self._series_labels[path] = label

    def _is_epoch(self, t_s: float) -> bool:
        """Whether flight_time is a timestamp: decided by the first time logged, kept after (a
        timeline has one type)."""
        if self._epoch is None:
            self._epoch = abs(float(t_s)) >= EPOCH_MIN_S
        return self._epoch

    def _set_time(self, t_s: float) -> None:
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"flight time must be finite, got {t_s!r}")
        if self._is_epoch(t):
            self.rec.set_time(TIMELINE, timestamp=np.datetime64(int(_ns(t)), "ns"))
        else:
            self.rec.set_time(TIMELINE, duration=np.timedelta64(int(_ns(t)), "ns"))
        if self._early_alerts:
            early, self._early_alerts = self._early_alerts, []
            for kind, message in early:
                self.rec.log(ALERTS_PATH, rr.TextLog(f"[{kind}] {message}", level=rr.TextLogLevel.WARN))

    # ---------------------------------------------------------------- public API

    def log_timeseries(self, t_s: np.ndarray, names: Sequence[str], values: np.ndarray,
                       kinds: Sequence[str], units: Sequence[str | None] | None = None) -> None:
        """One block of samples: ``values[k]`` is signal ``names[k]`` at the flight times ``t_s`` [s].

        Parameters
        ----------
        t_s : array (n,)
            Flight time [s], finite.
        names : sequence of str
        values : array (len(names), n)
            Samples in each signal's own unit.
        kinds : sequence of str
            ``"input"`` or ``"output"`` per name.
        units : sequence of str or None, optional
            Unit per name (``"deg"``, ``"deg/s"``, ``"ft/s^2"``); the series is named
            ``"<name> [<unit>]"`` in the legend. None (or an empty unit): the bare name.
        """
        with self._lock:
            self._check_open()
            t = np.asarray(t_s, dtype=np.float64)
            v = np.array(values, dtype=np.float64, copy=True)   # private copy: pyarrow wraps it
            names, kinds = list(names), list(kinds)
            units = [None] * len(names) if units is None else list(units)
            if v.ndim == 1 and len(names) == 1:
                v = v[None, :]
            if t.ndim != 1:
                raise ValueError(f"t_s must be 1-D, got shape {t.shape}")
            if len(kinds) != len(names) or len(units) != len(names) or v.shape != (len(names), t.size):
                raise ValueError(f"values must have shape (len(names), len(t_s)) = ({len(names)}, {t.size}) with one "
                                 f"kind and one unit per name; got values {v.shape}, {len(names)} names, "
                                 f"{len(kinds)} kinds, {len(units)} units")
            paths = [telemetry_path(kind, name) for name, kind in zip(names, kinds)]
            for path, name, unit in zip(paths, names, units):
                self._ensure_series(path, series_label(name, unit))
            if t.size == 0:
                return
            if not np.all(np.isfinite(t)):
                bad = int(np.flatnonzero(~np.isfinite(t))[0])
                raise ValueError(f"t_s[{bad}] = {t[bad]!r} is not a finite flight time")
            times = (rr.TimeColumn(TIMELINE, timestamp=_ns(t).astype("datetime64[ns]")) if self._is_epoch(t[0])
                     else rr.TimeColumn(TIMELINE, duration=_ns(t).astype("timedelta64[ns]")))
            for path, row in zip(paths, v):
                col = rr.ComponentColumn(self._d_scalars, ArrowBatch(pa.array(row)))
                self.rec.send_columns(path, indexes=[times], columns=[col])

    def log_estimate(self, t_s: float, omega: np.ndarray, outputs: Sequence[str], inputs: Sequence[str],
                     coherence: np.ndarray, magnitude_db: np.ndarray, phase_deg: np.ndarray,
                     adequacy_rows: Sequence[dict], verdict: str, reasons: Sequence[str], *,
                     coherence_kind: str = "ordinary", sweep: dict | None = None, spectra: bool = True,
                     band_rad_s: tuple | None = None, lag_s: float | None = None) -> None:
        """One spectral estimate at flight time ``t_s`` [s].

        Parameters
        ----------
        t_s : float
            Flight time of the estimate [s].
        omega : array (n_f,)
            Frequency grid [rad/s], > 0.
        outputs, inputs : sequence of str
        coherence, magnitude_db, phase_deg : arrays (n_out, n_in, n_f)
            gamma^2 (the one the verdict judged), |H| [dB] and phase [deg]. The phase is drawn
            unwrapped along frequency and moved by whole turns so its value at the lowest
            coherent frequency lies in (-180, 180] (:func:`reference_phase`).
        adequacy_rows : sequence of dict
            ``{"output", "input", "band": (lo, hi) [rad/s] or None, "fraction": 0..1}`` per pair.
        verdict : str
        reasons : sequence of str
        coherence_kind : str
            ``"ordinary"`` or ``"partial"`` (MISO-conditioned): which coherence ``coherence`` is;
            shown in each coherence plot and in the status text.
        sweep : dict, optional
            ``{input: (omega [rad/s] or None, time remaining [s] or None)}``: the sweep frequency
            and the sweep time still needed to reach the band's top, logged as scalars (NaN when
            None) and written in the status text.
        spectra : bool
            Draw every pair's frequency plots and waterfall (the "All pairs" tab); False: only the
            status, fractions and sweep (a web viewer that must keep up gets the heavy part less often).
        band_rad_s : (float, float), optional
            The band the running test point is judged over [rad/s], drawn with the sweep frequency
            (NaN when None).
        lag_s : float, optional
            How far behind the link this estimate is [s] (receive time of the newest frame in it to
            now), said in the status text.
        """
        with self._lock:
            self._check_open()
            coherence_kind_text(coherence_kind)      # ValueError for anything but ordinary/partial
            outputs, inputs = list(outputs), list(inputs)
            w = np.array(omega, dtype=np.float64, copy=True).ravel()
            if w.size == 0 or not np.all(np.isfinite(w)) or np.any(w <= 0):
                raise ValueError("omega must be a non-empty 1-D array of finite frequencies > 0 rad/s")
            shape = (len(outputs), len(inputs), w.size)
            arrays = []
            for what, a in (("coherence", coherence), ("magnitude_db", magnitude_db), ("phase_deg", phase_deg)):
                a = np.array(a, dtype=np.float64, copy=True)
                if a.shape != shape:
                    raise ValueError(f"{what} must have shape (n_outputs, n_inputs, n_f) = {shape}, got {a.shape}")
                arrays.append(a)
            sweep = {str(k): _sweep_pair(k, v) for k, v in (sweep or {}).items()}
            self._set_time(t_s)
            rec = self.rec
            if spectra:
                self._plots.draw_all(w, outputs, inputs, *arrays, coherence_kind)
            pairs = [(r.get("output"), r.get("input")) for r in adequacy_rows]
            if pairs and pairs != self._fraction_pairs:
                self._fraction_pairs = pairs
                rec.log(FRACTION_PATH, rr.SeriesLines(names=[pair_label(o, i) for o, i in pairs]), static=True)
            if pairs:
                frac = np.array([np.nan if r.get("fraction") is None else float(r["fraction"])
                                 for r in adequacy_rows])
                rec.log(FRACTION_PATH, rr.Scalars(frac))
            for name, (f_rad_s, remaining_s) in sweep.items():
                if name not in self._sweep_inputs:
                    self._sweep_inputs.add(name)
                    rec.log(sweep_frequency_path(name), rr.SeriesLines(names=f"{name} [rad/s]"), static=True)
                    rec.log(time_remaining_path(name), rr.SeriesLines(names=f"{name} [s]"), static=True)
                rec.log(sweep_frequency_path(name), rr.Scalars(np.nan if f_rad_s is None else f_rad_s))
                rec.log(time_remaining_path(name), rr.Scalars(np.nan if remaining_s is None else remaining_s))
            if not self._band_named:
                self._band_named = True
                for path, name in zip(BAND_EDGE_PATHS, ("band judged: bottom", "band judged: top")):
                    rec.log(path, rr.SeriesLines(names=name, colors=[_BAND_EDGE_COLOR], widths=[2.0]), static=True)
            for path, edge in zip(BAND_EDGE_PATHS, band_rad_s or (None, None)):
                rec.log(path, rr.Scalars(np.nan if edge is None else float(edge)))
            self._status = {"rows": list(adequacy_rows), "coherence_kind": coherence_kind, "sweep": sweep}
            rec.log(ADEQUACY_PATH, rr.TextDocument(
                adequacy_markdown(t_s, adequacy_rows, verdict, reasons, coherence_kind=coherence_kind, sweep=sweep,
                                  lag_s=lag_s, min_coherence=self.min_coherence),
                media_type=rr.MediaType.MARKDOWN))

    def log_verdict(self, t_s: float, verdict: str, reasons: Sequence[str]) -> None:
        """A change of the operator's verdict between estimates (a test point closed after the last
        samples): the status document shows it at once, with the last estimate's table."""
        with self._lock:
            self._check_open()
            if self._status is None or t_s is None:      # before the first estimate: it will show the verdict
                return
            self._set_time(t_s)
            st = self._status
            sweep = {k: (None, None) for k in (st["sweep"] or {})}     # no sweep is tracked without samples
            self.rec.log(ADEQUACY_PATH, rr.TextDocument(
                adequacy_markdown(t_s, st["rows"], verdict, reasons, coherence_kind=st["coherence_kind"],
                                  sweep=sweep, min_coherence=self.min_coherence), media_type=rr.MediaType.MARKDOWN))

    def log_focus(self, t_s: float, response, title: str) -> None:
        """The swept pair of a test point as its verdict judged it, over the judged band (the "Test
        point" tab's plots): ``response`` a :class:`~livesweep.spectral.response.FrequencyResponse`
        (its coherence, |H| and phase), ``title`` what it is ("TP 2 p/roll: GO so far")."""
        with self._lock:
            self._check_open()
            w = np.asarray(response.omega, float)
            if w.size < 2:
                return
            if self._focus is None:
                self._focus = self._plots.new_pair(FOCUS_PATH, 1, None)
            self._set_time(t_s)
            c = np.asarray(response.coherence, float)
            H = np.asarray(response.H, complex)
            ok = np.isfinite(c) & (c >= self.min_coherence)
            with np.errstate(divide="ignore", invalid="ignore"):
                mag = 20.0 * np.log10(np.abs(H))
            pha = reference_phase(np.degrees(np.angle(H)), ok)
            kind = "partial" if getattr(response, "conditioned", False) else "ordinary"
            x0, x1 = frequency_extent(w)
            self._plots.draw_pair(self._focus, {"logw": np.log10(w), "x": (x0, x1)}, c, mag, pha, ok, kind)
            _, _, top, _ = self._focus.coh.margins
            bx, by, bw, _ = self._focus.coh.box          # centred above the coherence plot
            self.rec.log(f"{FOCUS_PATH}/title", rr.Points2D([[bx + 0.5 * bw, by - 0.7 * top]], labels=[title],
                                                            show_labels=True, radii=rr.Radius.ui_points(0.5),
                                                            colors=[_TITLE_COLOR]))

    def log_test_point(self, t_s: float, tp: dict) -> None:
        """A test point opened, was judged, or closed: the test-point document at flight time ``t_s`` [s].

        Parameters
        ----------
        t_s : float
            Flight time [s].
        tp : dict
            The monitor's ``/livesweep/test_point`` record: ``{"state": "open"|"closed", "start_s",
            "end_s" (None while open), "source", "swept_input", "verdict", "pairs": [{"output",
            "input", "adequate_fraction", "band_rad_s": [lo, hi] or None, "coherence":
            "ordinary"|"partial"}], "missing": [str, ...]}``.

        The document (``status/test_points``, markdown) lists the open test point first, then the
        others newest first, each with its table (pair, coherence kind, adequate band, fraction,
        verdict, what is still missing); a record with the same start and swept input replaces
        the earlier one, so each test point appears once. At most ``test_point_history`` closed
        ones are kept.
        """
        with self._lock:
            self._check_open()
            if not isinstance(tp, dict):
                raise TypeError(f"tp must be a dict (the /livesweep/test_point record), got {type(tp).__name__}")
            key = tp.get("start_s")                  # one test point, whatever its record learns later
            if tp.get("state") in ("ignored", "superseded"):
                self._test_points.pop(key, None)     # not a test point after all: no phantom stays
            else:
                if key in self._test_points:
                    number = self._test_points[key][0]
                else:
                    self._n_test_points += 1
                    number = self._n_test_points
                self._test_points[key] = (number, dict(tp))
            closed = [k for k, (_, r) in self._test_points.items() if r.get("state") != "open"]
            for k in closed[:max(0, len(closed) - self.test_point_history)]:
                del self._test_points[k]
            entries = sorted(self._test_points.values(),
                             key=lambda e: (e[1].get("state") != "open", -e[0]))
            self._set_time(t_s)
            self.rec.log(TEST_POINTS_PATH, rr.TextDocument(markdown_test_points(entries, t_s),
                                                           media_type=rr.MediaType.MARKDOWN))

    def log_model(self, t_s: float, record: dict) -> None:
        """The model of a closed test point at flight time ``t_s`` [s] (the "Model" tab): ``record``
        the monitor's ``/livesweep/model`` record (docs/outputs.md), drawn by
        :class:`.rerun_model.ModelPanel` in place of the one before. Optional parts may be missing."""
        with self._lock:
            self._check_open()
            if not isinstance(record, dict):
                raise TypeError(f"record must be a dict (the /livesweep/model record), got {type(record).__name__}")
            self._set_time(t_s)
            if self._model is None:
                self._model = rerun_model.ModelPanel(self.rec)
            self._model.log(record)

    def log_alerts(self, t_s: float | None, alerts: Sequence[tuple[str, str]]) -> None:
        """Alerts as WARN text-log lines ``"[kind] message"`` at flight time ``t_s``; alerts before
        any data (``t_s`` None) wait for the first flight time (a placeholder time would decide the
        timeline's type wrongly: a duration where the data's clock is the UTC one)."""
        with self._lock:
            self._check_open()
            alerts = list(alerts)
            if not alerts:
                return
            if t_s is None or not math.isfinite(float(t_s)):
                self._early_alerts.extend(alerts)
                return
            self._set_time(t_s)
            for kind, message in alerts:
                self.rec.log(ALERTS_PATH, rr.TextLog(f"[{kind}] {message}", level=rr.TextLogLevel.WARN))

    def flush(self) -> None:
        """Block until everything logged so far reached the sinks (at most ``flush_timeout_s``)."""
        with self._lock:
            if not self._closed:
                self.rec.flush(timeout_sec=self.flush_timeout_s)

    def close(self) -> None:
        """Flush, disconnect (finalises the .rrd footer) and stop the web-viewer child. Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self.rec.flush(timeout_sec=self.flush_timeout_s)
                self.rec.disconnect()
            finally:
                if self._server is not None:
                    self._server.stop()

    @property
    def server_pid(self) -> int | None:
        """Process id of the web-viewer child (serve=True), else None."""
        return None if self._server is None else self._server.proc.pid

    def __enter__(self) -> RerunView:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def series_label(name: str, unit: str | None) -> str:
    """A time series' legend name: ``"da [deg]"``, or the bare name without a unit."""
    return f"{name} [{unit}]" if unit else str(name)


def _sweep_pair(name, v) -> tuple[float | None, float | None]:
    try:
        f, rem = v
    except (TypeError, ValueError):
        raise ValueError(f"sweep[{name!r}] must be (omega_rad_s or None, time_remaining_s or None), got {v!r}") from None
    f = None if f is None or not math.isfinite(float(f)) else float(f)
    rem = None if rem is None or not math.isfinite(float(rem)) else float(rem)
    return f, rem

