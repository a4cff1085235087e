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
"""

from __future__ import annotations

import bisect
import logging
import math
import sys
import threading
import time
from collections import deque
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from livesweep.errors import ConfigError, quote, require_number
from livesweep.monitor.alerts import ALERT_INTERVAL_S, AlertGate
from livesweep.monitor.ingest import FrameQueue, Ingest
from livesweep.monitor.testpoints import (CLOSE_WAIT_S, GCS_SYSID, GRID_TOL, LOST_AFTER_S, LOST_TOPIC, SOURCES,
                                         TestPointTracker)
from livesweep.monitor.text import time_text
from livesweep.spectral import DEFAULT_WINDOW_S
from livesweep.spectral.excitation import Alert, ExcitationMonitor
from livesweep.spectral.online import OnlineSpectralEstimator
from livesweep.telemetry.align import GridAligner
from livesweep.telemetry.clock import receive_ns

__all__ = ["MonitorSettings", "Estimate", "MonitorPipeline", "LINK_ANOMALIES"]

log = logging.getLogger(__name__)

PROCESS_EVERY_S = 0.02        # align and estimate at most this often [s of wall time] ...
PROCESS_EVERY_FRAMES = 500    # ... unless this many frames are waiting
REPORT_EVERY_S = 1.0          # link counters recorded and checked for alerts this often [s of wall time]
TIMESERIES_EVERY_S = 0.2      # time series go to the view in batches this often [s of wall time]: each Rerun
                              # call holds the interpreter, and one per 20 ms block slowed the recording thread
QUEUE_LIMIT_FRAMES = 50_000   # frames waiting for the analysis at most (about 50 MB)
ALL_PAIRS_EVERY = 5           # every pair's spectra go to the view every this many view updates (the heavy part)
SWITCH_INTERVAL_S = 0.001     # the GIL changes hands at least this often while the monitor runs
DIAGNOSE_AFTER_S = 5.0        # a map's signals that found nothing are named this long after the first frame [s of receive time]
PACE_SPAN_S = 30.0            # the data's pace (data s per receive s) is measured over this much receive time [s]
ON_GRID_S = 1e-7              # a sample time within this of a grid time is on it [s] (as the aligner has it)

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
        live responses and coherences are then formed through them (docs/method.md §4.6), free of the
        feedback bias; while a reference is silent the direct estimate is shown.
    test_points : livesweep.config.TestPointSettings, optional
        Where test points come from, which input each SystemID axis sweeps and which pairs each
        swept input must cover (a map's ``[test_points]`` table); None: every source, the
        on-axis output of the swept input, 10 s at least.
    map_name : str, optional
        The channel map's name (what a ``map`` alert calls it).
    vehicle : dict of str -> tuple of float, optional
        The vehicle the map is made for (its ``[map.vehicle]``: ``FRAME_CLASS``, ``FRAME_TYPE``,
        ``MAV_TYPE``); checked against what the vehicle says of itself.
    system : (int, int or None), optional
        The MAVLink system and component to analyse (``--sysid``, ``[map].sysid``); None: the first
        vehicle that sends every mapped message (:mod:`livesweep.telemetry.vehicle_choice`).
    """

    signals: dict
    inputs: tuple
    outputs: tuple
    band_rad_s: tuple
    sample_rate_hz: float = 50.0
    window_s: float = DEFAULT_WINDOW_S
    segment_s: float | None = None
    update_period_s: float = 0.2
    results_every: int = 5
    saturation_limits: dict | None = None
    required_pairs: tuple | None = None
    view_period_s: float = 1.0
    references: tuple | None = None
    test_points: object | None = None
    map_name: str | None = None
    vehicle: dict | None = None
    system: tuple | None = None

    def to_dict(self) -> dict:
        """Everything a replay needs to run as the live monitor did (the recording's settings attachment)."""
        tp = self.test_points
        return {
            "signals": {n: asdict(s) for n, s in self.signals.items()},
            "inputs": list(self.inputs), "outputs": list(self.outputs), "band_rad_s": list(self.band_rad_s),
            "sample_rate_hz": self.sample_rate_hz, "window_s": self.window_s, "segment_s": self.segment_s,
            "update_period_s": self.update_period_s,
            "required_pairs": None if self.required_pairs is None else [list(p) for p in self.required_pairs],
            "references": None if not self.references else list(self.references),
            "saturation_limits": None if not self.saturation_limits else
            {k: list(v) for k, v in self.saturation_limits.items()},
            "test_points": None if tp is None else {
                "sources": list(tp.sources), "axes": {str(k): v for k, v in tp.axes.items()},
                "required": {k: list(v) for k, v in tp.required.items()}, "min_duration_s": tp.min_duration_s},
            "map_name": self.map_name,
            "vehicle": None if not self.vehicle else {k: list(v) for k, v in self.vehicle.items()},
            "system": None if self.system is None else list(self.system),
        }

    @classmethod
    def from_dict(cls, d: dict, *, where: str = "settings", path=None) -> "MonitorSettings":
        """The settings :meth:`to_dict` wrote (a recording's ``livesweep_settings.json``).

        Validated as a channel map file is (:func:`livesweep.config.channel_map_from_tables`: names,
        fields, band, ``sample_rate_hz`` and every other limit a map gets) and then against the
        monitor's own limits (:meth:`check_limits`), so a crafted recording cannot ask for more than
        a map or the command line could.

        Parameters
        ----------
        d : dict
            The decoded JSON.
        where : str
            How messages name the settings, e.g. ``"rec.mcap: livesweep_settings.json"``.
        path : str or os.PathLike, optional
            The file they came from (default ``where``).

        Raises
        ------
        ConfigError
            One line naming ``where``, the key (as the JSON spells it) and the value.
        """
        from livesweep.config import channel_map_from_tables

        if not isinstance(d, dict):
            raise ConfigError(f"{where}: must be a JSON object of monitor settings, got {quote(d)}")
        try:
            m = channel_map_from_tables(_map_tables(d), path if path is not None else where, where=where)
        except ConfigError as e:           # the map's key paths, as the settings' JSON spells them
            text = str(e)
            for table, key in ((f"{where}: spectral: ", f"{where}: "), (f"{where}: spectral.", f"{where}: "),
                               (f"{where}: map.vehicle", f"{where}: vehicle")):
                if text.startswith(table):
                    text = key + text[len(table):]
                    break
            raise ConfigError(text) from None
        if m.spectral is None:
            raise ConfigError(f"{where}: missing the spectral settings (inputs, outputs, band_rad_s, sample_rate_hz)")
        sp = m.spectral
        map_name = d.get("map_name")
        if map_name is not None and not isinstance(map_name, str):
            raise ConfigError(f"{where}: map_name: must be a string, got {quote(map_name)}")
        try:
            system = _system(d.get("system"))
        except (TypeError, ValueError) as e:
            raise ConfigError(f"{where}: not monitor settings livesweep can use ({type(e).__name__}: {e})") from None
        segment = d.get("segment_s")
        settings = cls(
            signals=m.signals, inputs=sp.inputs, outputs=sp.outputs, band_rad_s=sp.band_rad_s,
            sample_rate_hz=sp.sample_rate_hz,
            window_s=require_number(d["window_s"] if "window_s" in d else None, f"{where}: window_s"),
            segment_s=None if segment is None else require_number(segment, f"{where}: segment_s"),
            update_period_s=require_number(d.get("update_period_s", 0.2), f"{where}: update_period_s"),
            references=sp.references, test_points=m.test_points, map_name=map_name,
            vehicle=dict(m.vehicle) or None, system=system,
        ).check_limits(where)
        return replace(settings,
                       required_pairs=_saved_pairs(d.get("required_pairs"), sp, f"{where}: required_pairs"),
                       saturation_limits=_saved_saturation(d.get("saturation_limits"), sp,
                                                           f"{where}: saturation_limits"))

    def check_limits(self, where: str = "", names: dict | None = None) -> "MonitorSettings":
        """These settings, or ConfigError when they ask for more than :mod:`livesweep.limits` allows
        the live monitor: a window of at most ``MAX_WINDOW_S`` [s] holding at most
        ``MAX_RECORD_VALUES`` samples x signals, with segment transforms of at most
        ``MAX_SPECTRAL_VALUES`` values; a segment [s] no longer than the window; an update period of
        at least ``MIN_UPDATE_PERIOD_S`` [s]; a grid of at most ``MAX_MONITOR_RATE_HZ`` [Hz]; at most
        ``MAX_MONITOR_PAIRS`` pairs.

        Parameters
        ----------
        where : str
            What the message names first (the file the settings came from); may be empty.
        names : dict of str -> str, optional
            How the message calls a setting instead of ``"<where>: <attribute>"``, e.g.
            ``{"update_period_s": "--update-period"}`` (``"outputs"`` names the pair count).

        Returns
        -------
        MonitorSettings
            ``self``.
        """
        import inspect

        from livesweep import limits
        from livesweep.spectral.online import default_segment_s

        def error(key, problem, value):
            label = (names or {}).get(key) or (f"{where}: {key}" if where else key)
            return ConfigError(f"{label}: {problem}, got {quote(value)}")

        window = self.window_s
        if not (isinstance(window, (int, float)) and math.isfinite(window) and 0 < window <= limits.MAX_WINDOW_S):
            raise error("window_s", f"the sliding window must be > 0 and at most {limits.MAX_WINDOW_S:g} s", window)
        seg = self.segment_s
        if seg is not None and not (isinstance(seg, (int, float)) and math.isfinite(seg) and 0 < seg <= window):
            raise error("segment_s", f"a segment must be > 0 s and at most the sliding window ({window:g} s)", seg)
        period = self.update_period_s
        if not (isinstance(period, (int, float)) and math.isfinite(period) and period >= limits.MIN_UPDATE_PERIOD_S):
            raise error("update_period_s", f"must be at least {limits.MIN_UPDATE_PERIOD_S:g} s", period)
        fs = self.sample_rate_hz
        if not (isinstance(fs, (int, float)) and math.isfinite(fs) and 0 < fs <= limits.MAX_MONITOR_RATE_HZ):
            raise error("sample_rate_hz", f"the live monitor's grid runs at most at {limits.MAX_MONITOR_RATE_HZ:g} Hz",
                        fs)
        pairs = len(self.inputs) * len(self.outputs)
        if pairs > limits.MAX_MONITOR_PAIRS:
            raise error("outputs", f"{len(self.outputs)} outputs x {len(self.inputs)} inputs = {pairs} pairs; the "
                        f"monitor analyses at most {limits.MAX_MONITOR_PAIRS}", len(self.outputs))
        n_signals = len(set((*self.inputs, *self.outputs, *(self.references or ()))))
        samples = int(round(window * fs))
        if samples * n_signals > limits.MAX_RECORD_VALUES:
            raise error("window_s", f"{window:g} s x {fs:g} Hz x {n_signals} signals = {samples * n_signals} samples "
                        f"in the sliding window; at most {limits.MAX_RECORD_VALUES}", window)
        overlap = inspect.signature(OnlineSpectralEstimator).parameters["overlap"].default    # what the pipeline uses
        values = limits.window_spectra_values(n_signals, samples, fs, seg or default_segment_s(self.band_rad_s, window),
                                              overlap, self.band_rad_s)
        if values > limits.MAX_SPECTRAL_VALUES:
            raise error("window_s", f"its segment transforms hold {values} values; at most "
                        f"{limits.MAX_SPECTRAL_VALUES} (a shorter window or fewer signals)", window)
        return self


def _map_tables(d: dict) -> dict:
    """The channel-map part of saved settings, shaped as a map file's TOML tables."""
    tables = {}
    if "signals" in d:
        sigs = d["signals"]
        tables["signals"] = {n: _signal_table(v) for n, v in sigs.items()} if isinstance(sigs, dict) else sigs
    spectral = {k: d[k] for k in ("inputs", "outputs", "band_rad_s", "sample_rate_hz", "references")
                if d.get(k) is not None}
    if spectral:
        tables["spectral"] = spectral
    if d.get("test_points") is not None:
        tables["test_points"] = d["test_points"]
    if d.get("vehicle"):
        tables["map"] = {"vehicle": d["vehicle"]}
    return tables


def _signal_table(v):
    """A saved :class:`~livesweep.config.SignalSpec` (``asdict``) as its ``[signals.NAME]`` table."""
    if not isinstance(v, dict):
        return v
    t = {k: x for k, x in v.items() if k != "name" and x is not None}
    if "stamp" not in t:
        t.pop("stamp_scale", None)          # 1.0, the field's default, for a signal on receive time
    where = t.get("where")
    if isinstance(where, list):
        if not where:
            del t["where"]
        elif all(isinstance(p, list) and len(p) == 2 and isinstance(p[0], str) for p in where):
            t["where"] = dict(where)
    return t


def _saved_pairs(value, spectral, where: str) -> tuple | None:
    """Saved ``required_pairs``: None or ``[[output, input], ...]`` of the spectral outputs and inputs."""
    if value is None:
        return None
    if not isinstance(value, list) or len(value) > len(spectral.inputs) * len(spectral.outputs):
        raise ConfigError(f"{where}: must be a list of [output, input] pairs of the spectral settings, got {quote(value)}")
    for i, p in enumerate(value):
        if not (isinstance(p, list) and len(p) == 2 and p[0] in spectral.outputs and p[1] in spectral.inputs):
            raise ConfigError(f"{where}[{i}]: must be [output, input] with an output of {quote(list(spectral.outputs))} "
                              f"and an input of {quote(list(spectral.inputs))}, got {quote(p)}")
    return tuple((str(o), str(i)) for o, i in value)


def _saved_saturation(value, spectral, where: str) -> dict | None:
    """Saved ``saturation_limits``: None or ``{input: [low, high]}`` in input units, ``low < high``."""
    if not value:
        return None
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: must be an object of input: [low, high], got {quote(value)}")
    out = {}
    for name, v in value.items():
        ok = (name in spectral.inputs and isinstance(v, list) and len(v) == 2
              and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
              and v[0] < v[1])
        if not ok:
            raise ConfigError(f"{where}.{quote(name)}: must be [low, high] with low < high, for an input of "
                              f"{quote(list(spectral.inputs))}, got {quote(v)}")
        out[name] = (float(v[0]), float(v[1]))
    return out


def _system(value) -> tuple | None:
    """Saved ``system``: None or [sysid, compid or None], each a MAVLink id (0-255)."""
    if value is None:
        return None
    sysid, compid = value
    for v in (sysid, compid):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 255):
            raise ValueError(f"system {value!r}: a MAVLink id is an integer from 0 to 255")
    if sysid is None:
        raise ValueError(f"system {value!r}: needs a system id")
    return int(sysid), None if compid is None else int(compid)


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
    coherence_kind: str = "ordinary"      # "ordinary" or "partial": the coherence the adequacy judged


@dataclass
class _Totals:
    frames: int = 0                 # frames received from the sources (all recorded, when recording)
    analysed: int = 0               # frames the analysis took
    blocks: int = 0
    estimates: int = 0
    ticks_skipped: int = 0          # estimate ticks skipped over a jump of the data clock
    wall_s: float = 0.0
    latency_s: deque = field(default_factory=lambda: deque(maxlen=10_000))
    verdict_latency_s: deque = field(default_factory=lambda: deque(maxlen=10_000))


def _tracker(settings: MonitorSettings, names) -> TestPointTracker:
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
                            required=required, min_duration_s=tp.min_duration_s if tp is not None else 10.0,
                            references=refs)


def _source_name(src) -> str:
    """How a source names itself in counters: its bound url, path or key expression."""
    for attr in ("description", "url", "path", "key_expr"):
        v = getattr(src, attr, None)
        if v is not None:
            return str(v)
    return type(src).__name__


class MonitorPipeline:
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
        self.s = settings
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
                                            required_pairs=settings.required_pairs)
        self.test_points = _tracker(settings, self.names)
        self.test_points.source_rates = self._source_rates
        self.test_points.link_counts = self._link_counts      # what the link lost while a test point is open
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
        self._unfit: str | None = None                  # why the map does not fit the vehicle, once said
        self._lost_said = False                         # the telemetry-lost event of this silence was made

    def request_stop(self) -> None:
        """Stop at the next turn of the loop (safe from a signal handler or another thread)."""
        self._stop.set()

    @property
    def stop_requested(self) -> bool:
        """True once :meth:`request_stop` was called."""
        return self._stop.is_set()

    # -- the loop ---------------------------------------------------------------------------
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

    # -- frames and test points ------------------------------------------------------------------
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
            if self.s.vehicle and self._unfit is None:
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

    def _check_vehicle(self, receive_ns: int) -> None:
        """Say once, as a ``map`` alert, that the vehicle is not the one the map is made for (its
        parameters, "Frame:" text or HEARTBEAT type contradict ``[map.vehicle]``); every test point
        from then on is NO-GO for it."""
        why = self.test_points.vehicle.contradiction(self.s.vehicle)
        if why is None:
            return
        from livesweep.maps import presets_for

        self._unfit = self.test_points.unfit = why
        c, t = self.test_points.vehicle.frame()
        better = [n for n in presets_for(c, t, self.test_points.vehicle.mav_type) if n != self.s.map_name]
        name = f"map {self.s.map_name}" if self.s.map_name else "the map"
        self._map_alert(f"{name} does not fit: {why}" + (f"; use {' or '.join(better)}" if better else ""),
                        receive_ns)

    def _source_rates(self) -> dict:
        """The rate each aligned signal arrives at [Hz] (from its first samples' spacing)."""
        return {n: 1.0 / c.dt for n, c in self.aligner.ch.items() if c.dt}

    def _drain_blocks(self) -> None:
        """Every block the aligner has ready, now: what follows (a test-point event, a map alert)
        then sees the same samples whatever the batch sizes (a replay takes thousands of frames at
        once, a live link a few)."""
        while (got := self._pop_ready())[0] is not None:
            self._process_block(*got, time.monotonic())

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
            if rec["state"] == "closed":
                self._result("test_point", rec, log_time_ns, flush=True)
                if self.publisher is not None:
                    self.publisher.publish("test_point", rec)
            self._update_verdict(t_s, rec)

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
                                f"{rec['label']}", *rec["missing"], *rec["reasons"]), rec

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

    def _process(self, t_rx: float) -> None:
        """Every block the aligner has ready, through the estimator tick by tick."""
        while (got := self._pop_ready())[0] is not None:
            self._process_block(*got, t_rx)
        self._flush_timeseries(t_rx)
        self._cause_rx = None

    def _flush_timeseries(self, now: float, force: bool = False) -> None:
        """Send the buffered time series to the view in one call per signal (every TIMESERIES_EVERY_S)."""
        if not self._ts_buffer or (not force and now - self._ts_sent < TIMESERIES_EVERY_S):
            return
        t = np.concatenate([b[0] for b in self._ts_buffer])
        values = np.concatenate([b[1] for b in self._ts_buffer], axis=1)
        self._ts_buffer.clear()
        self._ts_sent = now
        self.view.log_timeseries(t, list(self.names), values,
                                 ["output" if x in self.s.outputs else "input" for x in self.names],
                                 units=[self.s.signals[x].units for x in self.names])

    def _pop_ready(self) -> tuple:
        """``(block, raw)``: the aligner's next block (None: none ready) and, on the vehicle clock,
        per signal the times [s] of the samples it received for the block's grid samples (those in
        ``(t_k - 1/fs, t_k]`` of each grid time ``t_k``), read before the aligner lets them go: a
        test point counts the frames its signals lost from them. ``raw`` is None on receive time
        (arrival times say nothing of what was sent)."""
        al = self.aligner
        if al.clock != "vehicle" or al.t0 is None:
            return al.pop_ready(), None
        fs = self.s.sample_rate_hz
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

    def _process_block(self, block, raw: dict | None, t_rx: float) -> None:
        self.totals.blocks += 1
        fs = self.s.sample_rate_hz
        n = block.values.shape[1]
        t = block.t_s if block.t_s is not None else block.t0_s + np.arange(n) / fs
        self._t_data = float(t[-1])
        if self.view is not None:
            self._ts_buffer.append((t, block.values))
        if self.verdict is None:
            self._update_verdict(block.t0_s)
        if self._next_tick is None:
            self._next_tick = block.t0_s + self.s.update_period_s
            self._t_first = block.t0_s
        elif self._next_tick < block.t0_s - self.s.update_period_s:
            # the data clock jumped (a long gap, or the aligner skipped a jump): no estimates for ticks
            # before this block, whose samples are gone
            skip = int(math.floor((block.t0_s - self._next_tick) / self.s.update_period_s))
            self._next_tick += skip * self.s.update_period_s
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
        if self.view is not None and t_s - self._last_view_t >= self.s.view_period_s - 1e-9:
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
            self._record_alert(t_s, a)
            if self.view is not None:
                self.view.log_alerts(t_s, [(a.kind, a.message)])
            if self.publisher is not None:
                self.publisher.publish("alert", {"t_s": t_s, "kind": a.kind, "message": a.message})
        payload = self._payload(est, rows)
        if self.publisher is not None:
            self.publisher.publish("estimate", payload)
        if self.totals.estimates % max(1, self.s.results_every) == 0:
            self._result("estimate", payload)

    def _sweep_in_window(self, t_s: float) -> bool:
        """A test point's data is in the sliding window: while one runs, and until its data has left."""
        tracker = self.test_points
        last_end = max((tp["end_s"] for tp in tracker.closed[-1:]), default=None)
        return tracker.current is not None or bool(tracker.closing) or \
            (last_end is not None and t_s - last_end < self.s.window_s)

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
        sweep = {i: (status.sweep_frequency_rad_s.get(i), status.time_remaining_s.get(i)) for i in self.s.inputs}
        cur = self.test_points.current
        if cur is None:              # between test points an input's oscillation is no sweep to report
            return {i: (None, None) for i in sweep}, None
        if cur.swept_input in sweep:                 # the other inputs are the controller's reaction
            sweep = {i: v if i == cur.swept_input else (None, None) for i, v in sweep.items()}
        inj = cur.injection
        if inj is None:
            return sweep, self.s.band_rad_s
        elapsed = t_s - cur.start_s
        if cur.swept_input in sweep and inj.delay_s < elapsed < inj.duration_s:
            sweep[cur.swept_input] = (float(inj.omega_at(elapsed)), inj.duration_s - elapsed)
        return sweep, inj.band_rad_s

    def _record_alert(self, t_s: float | None, alert: Alert, log_time_ns: int | None = None) -> None:
        self.alerts_raised += 1
        self._result("alert", {"t_s": t_s, "kind": alert.kind, "message": alert.message, "value": float(alert.value)},
                     log_time_ns)

    def _result(self, name: str, payload: dict, log_time_ns: int | None = None, *, flush: bool = False) -> None:
        """A live result: recorded on ``/livesweep/<name>`` (at ``log_time_ns``, else now) and handed
        to ``results``."""
        if self.recorder is not None:
            self.recorder.record_result(name, payload, log_time_ns=receive_ns() if log_time_ns is None else log_time_ns,
                                        flush=flush)
        if self.results is not None:
            self.results(name, payload)

    # -- link counters ------------------------------------------------------------------------
    def counters(self) -> dict:
        """Every counter now: per source, of the aligner and of the pipeline."""
        ingest = self._ingest
        return {
            "sources": [{"name": _source_name(src), **src.counts} for src in self.sources],
            "aligner": dict(self.aligner.counts),
            "pipeline": {"frames_received": self.totals.frames, "frames_analysed": self.totals.analysed,
                         "analysis_shed": self.analysis_shed, "ticks_skipped": self.totals.ticks_skipped,
                         "drained_at_stop": 0 if ingest is None else ingest.drained,
                         "not_taken_at_stop": 0 if ingest is None else ingest.not_taken_at_stop,
                         "bad_publish_time": 0 if self.recorder is None else self.recorder.bad_publish_time,
                         "unrecordable": 0 if self.recorder is None else self.recorder.unrecordable},
        }

    def _anomalies(self, c: dict) -> dict[str, int]:
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
            self._record_alert(self._t_data, a)
            if self.view is not None:
                self.view.log_alerts(self._t_data, [(a.kind, a.message)])
            if self.publisher is not None:
                self.publisher.publish("alert", {"t_s": self._t_data, "kind": a.kind, "message": a.message})
        if self.status_line is not None:
            self._status(now, counts)
        if self.recorder is not None or self.results is not None:
            self._result("link", {"t_s": self._t_data, "wall_s": round(now - self._t_start, 3),
                                  "frames_recorded": self.totals.frames, "analysis_shed": self.analysis_shed,
                                  "sources": c["sources"], "aligner": c["aligner"]})
        if final and self.recorder is not None:
            self.recorder.set_counters(c)

    def _map_check(self, receive_ns: int) -> None:
        """Diagnose the map DIAGNOSE_AFTER_S of receive time after the first frame; after that, watch
        for the signals it found missing. Driven by the frames' own receive times, so a replay
        raises the same ``map`` alerts at the same data times as the live run did."""
        if self.map_problems is None:
            if self._first_rx is None:
                self._first_rx = receive_ns
            elif receive_ns - self._first_rx >= DIAGNOSE_AFTER_S * 1e9:
                self._diagnose(receive_ns)
        else:
            self._map_found_later(receive_ns)

    def _diagnose(self, receive_ns: int) -> None:
        """Every signal of the map that found nothing, and why (an absent topic, a misspelt field, a
        selection nothing matches), as a ``map`` alert, a warning on stderr and ``map_problems``
        in the summary."""
        from livesweep.telemetry.extract import diagnose

        signals = {n: self.s.signals[n] for n in self.names}
        self.aligner.settle_choice()
        self.map_problems = diagnose(signals, self.aligner.signal_counts, self._topics_seen)
        self._map_missing = [n for n in self.names if self.aligner.signal_counts[n]["samples"] == 0]
        if self.map_problems:
            self._drain_blocks()
        for line in self.map_problems:
            self._map_alert(line, receive_ns)

    def _map_found_later(self, receive_ns: int) -> None:
        """A signal the diagnosis found missing that has samples now (a vehicle that starts its
        streams once armed): say so, so the early warning does not stand."""
        found = [n for n in self._map_missing if self.aligner.signal_counts[n]["samples"] > 0]
        if found:
            self._drain_blocks()             # the alert's data time: every sample taken so far
        for n in found:
            self._map_missing.remove(n)
            left = len(self._map_missing)
            self._map_alert(f"signal {n}: found now ({'every signal found' if not left else f'{left} still missing'})",
                            receive_ns)

    def _map_alert(self, line: str, receive_ns: int) -> None:
        """A ``map`` alert, recorded at the receive time of the frame that raised it (not when a busy
        process got to write it), so its time says when the link showed the problem."""
        log.warning("monitor: %s", line)
        a = Alert("map", line, 1.0)
        self._record_alert(self._t_data, a, log_time_ns=receive_ns)
        if self.view is not None:
            self.view.log_alerts(self._t_data, [(a.kind, a.message)])
        if self.publisher is not None:
            self.publisher.publish("alert", {"t_s": self._t_data, "kind": a.kind, "message": a.message})

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

    def _payload(self, est: Estimate, rows) -> dict:
        st = est.status
        return {
            "t_s": est.t_s, "n_segments": est.n_segments, "conditioned": est.conditioned,
            "coherence_kind": est.coherence_kind,
            "omega_rad_s": est.omega.tolist(),
            "coherence": {f"{o}/{i}": est.coherence[a, b].tolist() for a, o in enumerate(self.s.outputs)
                          for b, i in enumerate(self.s.inputs)},
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
        for a, o in enumerate(self.s.outputs):
            for b, i in enumerate(self.s.inputs):
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

    def _packets_lost(self) -> dict:
        out = {}
        for k, src in enumerate(self.sources):
            gaps = src.counts.get("seq_gaps") if isinstance(src.counts, dict) else None
            if isinstance(gaps, dict):
                out[k] = sum(int(v) for v in gaps.values())
        return out

    # -- end --------------------------------------------------------------------------------
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

    def summary(self) -> dict:
        last = self.last_status
        lat = np.asarray(self.totals.latency_s)
        return {
            "frames": self.totals.frames if self._ingest is None else self._frames_received(self._ingest),
            "blocks": self.totals.blocks, "estimates": self.totals.estimates,
            "wall_s": round(self.totals.wall_s, 3),
            "data_s": None if self._next_tick is None else round(self._next_tick - self.s.update_period_s - self._t_first, 3),
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
        }
