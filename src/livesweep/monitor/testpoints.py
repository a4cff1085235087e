"""Test points: where a sweep starts and ends, which input it sweeps, and the verdict over all of it.

The monitor segments the flight into test points from three kinds of evidence, in this order of
authority (``sources`` in a map's ``[test_points]`` table selects them):

* **autopilot**: ArduPilot's SystemID mode. Over MAVLink its STATUSTEXT "SystemID Starting:
  axis=N" opens a test point sweeping the input the map's ``axes`` table names for axis N, and
  "SystemID Finished", or the HEARTBEAT's custom mode leaving SYSTEMID (25), closes it; in a
  DataFlash log the same texts come as MSG, the start as SIDS (``Ax``) and the mode as MODE.
  The sweep the autopilot was told to fly comes with it (the SIDS record, or the ``SID_*``
  parameters the vehicle sent as PARAM_VALUE / logged as PARM: :mod:`livesweep.monitor.vehicle`),
  so the test point is judged over that band. An axis the map names no input for (a mixer axis
  on a map that sees the rate loops) is a test point too, judged NO-GO with that reason.
  Only the vehicle the aligner analyses counts (a second system's texts are ignored).
* **marker**: the operator says so: a line typed in the monitor's terminal (``s roll`` / ``e``,
  recorded as ``/marker/terminal``), a JSON message ``{"action": "start", "input": "roll"}`` on a
  Zenoh key ending in ``/marker``, a MAVLink STATUSTEXT "livesweep start roll" / "livesweep end", or a
  NAMED_VALUE_INT "LS_TP" (value k > 0: start sweeping input k, 1-based; 0: end), from the
  vehicle analysed or from a ground station (system id 255, or any system whose HEARTBEAT says
  MAV_TYPE_GCS); another vehicle's markers are ignored.
* **sweep**: no one said so, but an input oscillates well above its quiet level (its standard
  deviation over each second stands ``4x`` above its recent quiet level for 3 seconds and it
  crosses its mean at least 3 times: a motor spooling up or a trim change is not a sweep); the
  test point ends after 5 quiet seconds, and one shorter than ``min_duration_s`` (a doublet) is
  ignored. Used only until an autopilot or marker event is seen.

While a test point is open its aligned samples are kept (up to ``MAX_TEST_POINT_S``) and judged
every ``JUDGE_EVERY_S`` of data over the band swept so far (a *running* verdict: "GO so far, 0.5-2.9
Hz of 0.5-12 Hz swept"); when it closes it is judged once, over all of it and the whole band
(:func:`livesweep.spectral.verdict.judge_test_point`). A closing verdict that differs from the
last running one says why. The monitor closes a test point whose telemetry stopped
(:data:`LOST_TOPIC`: no frame of the vehicle for ``LOST_AFTER_S``) NO-GO with "telemetry lost",
unless its sweep was already over (the autopilot's chirp had ended, or a detected sweep's input had
been quiet for a while): then it is judged on what it holds.
Everything depends on the frames and samples alone, so a replay reproduces the test points exactly.

**Data loss.** Each block comes with the times of the samples each signal brought to it (on the
vehicle clock), so a test point knows, over its own span, how many frames each of its signals
missed (:func:`~livesweep.spectral.verdict.frames_missing`) and how many of its grid samples
fell in gaps; a live monitor also reads its link counters (kernel drops, MAVLink sequence gaps,
frames the analysis skipped) when the test point opens and each time it is judged. The verdict says
the loss first when it is large enough to matter (:class:`~livesweep.spectral.verdict.DataLoss`);
the counts from the samples are what a replay of the recording finds again, the link counters are
the live run's alone (a file has no link).
"""

from __future__ import annotations

import math
import re
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from livesweep.monitor.systemid import SAME_START_S, SystemIdWatch, better_injection
from livesweep.monitor.systemid import TOPICS as SYSTEMID_TOPICS
from livesweep.monitor.vehicle import VehicleInfo, axis_name
from livesweep.spectral.criteria import DEFAULT_CRITERIA, Criteria
from livesweep.spectral.injection import SweepInjection
from livesweep.spectral.recommend import Recommendation, recommend_next
from livesweep.spectral.verdict import DataLoss, TestPointJudgement, judge_test_point
from livesweep.telemetry.frames import Frame

__all__ = ["TestPointEvent", "TestPoint", "TestPointTracker", "SOURCES", "MARKER_TOPIC", "LOST_TOPIC",
           "JUDGE_EVERY_S", "MAX_TEST_POINT_S", "LOST_AFTER_S"]

SOURCES = ("autopilot", "marker", "sweep")
#: Topic of the operator's terminal markers (recorded, so a replay sees them).
MARKER_TOPIC = "/marker/terminal"
#: Topic of the monitor's own "telemetry lost" event (recorded, so a replay closes the test point
#: where the live run did): ``{"silent_s": s, "last_rx_ns": ns}``.
LOST_TOPIC = "/marker/telemetry_lost"
#: No frame of the analysed vehicle for this long [s of receive time] during a test point: telemetry lost.
LOST_AFTER_S = 2.0
#: A detected sweep's input quiet this long [s] when the telemetry stops: the sweep was over.
_QUIET_BEFORE_LOSS_S = 2
#: Samples to within this of the end of the autopilot's chirp [s] (its fade-out) when the telemetry
#: stops: the chirp was over.
_CHIRP_END_TOL_S = 0.5
#: A ground station's system id by convention (QGroundControl, Mission Planner, MAVProxy).
GCS_SYSID = 255
#: HEARTBEAT ``type`` of a ground station.
MAV_TYPE_GCS = 6
#: How near a grid sample a time may be and still count as on it [fraction of a sample period].
#: Times are seconds on the vehicle clock or, for receive-time maps, since the UNIX epoch, where
#: float64 resolves 2.4e-7 s: a grid time computed two ways (a block's start plus k / fs, a record's
#: rounded end) differs by up to ~1e-5 of a sample at 50 Hz, which must not move a sample in or
#: out of a test point (the live run and its replay would then disagree).
GRID_TOL = 1e-3

#: An open test point is judged this often [s of data].
JUDGE_EVERY_S = 5.0
#: A test point that ended is judged on the samples it has once this much data time has passed
#: since its end with none reaching it [s] (no telemetry at all: the judgement must not wait for
#: data that never comes). The aligner marks a silent signal invalid after 2 s, so samples that
#: exist arrive well within it.
CLOSE_WAIT_S = 3.0
#: A test point is closed when it reaches this length [s] (bounds memory).
MAX_TEST_POINT_S = 900.0
#: Samples kept before a test point [s]: a start event that arrives after the samples it opens
#: (a STATUSTEXT behind the telemetry, a sweep confirmed after 3 s) still finds them, and the
#: input that moved most is told against this stretch when the evidence does not name it.
PRE_TEST_S = 20.0
#: Sweep detection confirms a start within this long of it, or gives up (a slow ramp is no sweep) [s].
_MAX_DETECTION_S = 60.0

_MARKER_TEXT = re.compile(r"^\s*(?:livesweep|testpoint)\s*:?\s*(start|end)(?:\s+(\S+))?", re.I)


@dataclass(frozen=True)
class TestPointEvent:
    """A start or an end of a test point, on the data clock.

    Attributes
    ----------
    t_s : float
        Data time [s].
    action : str
        ``"start"``, ``"end"`` or ``"lost"`` (the telemetry stopped).
    source : str
        ``"autopilot"``, ``"marker"``, ``"sweep"`` or ``"monitor"``.
    swept_input : str or None
        The input swept (start only; None when the evidence does not say).
    note : str
        What was seen ("SystemID Starting: axis=7", "terminal: s roll", ...).
    injection : SweepInjection or None
        The sweep the autopilot was told to fly (an autopilot start whose parameters are known).
    axis : int or None
        The autopilot's SystemID axis (an autopilot start).
    """

    t_s: float
    action: str
    source: str
    swept_input: str | None = None
    note: str = ""
    injection: SweepInjection | None = None
    axis: int | None = None


@dataclass
class TestPoint:
    """One test point (open while ``end_s`` is None or its samples have not reached it)."""

    start_s: float
    source: str
    swept_input: str | None
    note: str
    end_s: float | None = None
    end_note: str = ""
    injection: SweepInjection | None = None
    axis: int | None = None
    unjudged: str = ""                           # why it cannot be judged (an axis the map has no input for)
    lost: str = ""                               # "telemetry lost ..." when the monitor closed it for that
    t0: list = field(default_factory=list)       # per kept block: start time [s]
    values: list = field(default_factory=list)   # per kept block: (n_signals, n) samples
    valid: list = field(default_factory=list)
    raw: list = field(default_factory=list)      # per block: {signal: times of the samples it received [s]}
    link0: dict | None = None                    # the link counters when it opened (a live monitor)
    pre: np.ndarray | None = None                # the samples before it (n_signals, n_pre)
    next_judge_s: float = math.inf               # data time of its next judgement while open
    judgement: TestPointJudgement | None = None
    running: TestPointJudgement | None = None    # the last running judgement
    criteria: Criteria = DEFAULT_CRITERIA        # what judges it (the map's [criteria])
    recommendation: Recommendation | None = None   # what to fly next (the closing judgement's)

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """Its samples so far, (values (n_signals, n), valid (n,))."""
        return np.concatenate(self.values, axis=1), np.concatenate(self.valid)

    def trim(self, fs: float) -> None:
        """Drop the samples after ``end_s`` (a block that opened it may have run past its end)."""
        if self.end_s is None:
            return
        for k, t0 in enumerate(self.t0):
            keep = max(int(math.floor((self.end_s - t0) * fs + GRID_TOL)) + 1, 0)
            self.values[k], self.valid[k] = self.values[k][:, :keep], self.valid[k][:keep]

    def duration_s(self, fs: float) -> float:
        return sum(v.shape[1] for v in self.values) / fs

    def record(self, state: str) -> dict:
        """The ``/livesweep/test_point`` record (docs/outputs.md, live result channels), also shown
        while it is open: ``verdict`` is the closing verdict (WAIT while open), ``running`` the
        last running one ("GO so far", ...)."""
        j = self.judgement if state == "closed" else self.running
        out = {"state": state, "start_s": round(self.start_s, 6),
               "end_s": None if self.end_s is None else round(self.end_s, 6), "source": self.source,
               "swept_input": self.swept_input, "note": self.note, "end_note": self.end_note,
               "axis": self.axis, "verdict": "WAIT", "label": "WAIT", "marginal": False,
               "running": None if self.running is None else self.running.label,
               "injection": None if self.injection is None else self.injection.to_dict(),
               "pairs": [], "missing": [], "reasons": [], "criteria": self.criteria.to_dict(),
               "next": None}
        if state == "closed":
            out["verdict"] = out["label"] = "NO-GO" if j is None or self.lost or self.unjudged else j.verdict
        if j is not None:
            d = j.to_dict()
            out.update(pairs=d["pairs"], missing=d["missing"], reasons=d["reasons"],
                       excited_fraction=d["excited_fraction"], duration_s=d["duration_s"],
                       judged_band_rad_s=d["judged_band_rad_s"], swept_band_rad_s=d["swept_band_rad_s"],
                       excitation=d["excitation"], progress=j.progress(), loss_fraction=d["loss_fraction"])
            if state == "closed" and out["verdict"] == j.verdict:
                out.update(label=j.label, marginal=j.marginal)
        if state == "closed" and self.recommendation is not None and not self.unjudged:
            out["next"] = self.recommendation.to_dict()
        if state == "closed":
            why = [x for x in (self.unjudged, self.lost) if x]
            if why:
                out["missing"] = [*why, *out["missing"]]
            elif j is None:
                out["missing"] = ["no samples of the map's signals during the test point"]
            if self.running is not None and j is not None and self.running.verdict == "GO" and out["verdict"] != "GO":
                out["reasons"] = [f"NO-GO over the whole test point, although the running verdict was "
                                  f"{self.running.label} ({self.running.progress()}): see below", *out["reasons"]]
        return out


class _SweepDetector:
    """Per input: is it being swept? (1-s standard deviations against the recent quiet level)."""

    def __init__(self, inputs, fs: float, *, ratio: float = 4.0, start_s: int = 3, quiet_end_s: int = 5,
                 min_crossings: int = 3, baseline_s: int = 30):
        self.inputs, self.fs = tuple(inputs), float(fs)
        self.n_sec = max(int(round(fs)), 1)
        self.ratio, self.start_s, self.quiet_end_s = ratio, start_s, quiet_end_s
        self.min_crossings = min_crossings
        self._buf = {i: [] for i in self.inputs}             # samples of the current second
        self._t_sec: float | None = None                     # start time of the current second
        self._quiet = {i: deque(maxlen=baseline_s) for i in self.inputs}   # recent quiet 1-s std's
        self._run = {i: [] for i in self.inputs}             # (t, std, samples) of the current active run
        self.active: str | None = None
        self.quiet_for = 0
        self.last_active_t = 0.0

    def _baseline(self, i: str) -> float | None:
        q = self._quiet[i]
        return float(np.median(q)) if len(q) >= 5 else None

    def feed(self, t: np.ndarray, rows: dict[str, np.ndarray]) -> list[TestPointEvent]:
        events = []
        n = t.size
        k = 0
        while k < n:
            if self._t_sec is None:
                self._t_sec = float(t[k])
            take = min(self.n_sec - len(self._buf[self.inputs[0]]), n - k)
            for i in self.inputs:
                self._buf[i].extend(rows[i][k:k + take].tolist())
            k += take
            if len(self._buf[self.inputs[0]]) >= self.n_sec:
                events += self._second(self._t_sec)
                self._t_sec = None
                for i in self.inputs:
                    self._buf[i] = []
        return events

    def _second(self, t_sec: float) -> list[TestPointEvent]:
        events = []
        stds = {}
        for i in self.inputs:
            x = np.asarray(self._buf[i], float)
            x = x[np.isfinite(x)]
            stds[i] = float(np.std(x)) if x.size > 1 else 0.0
        if self.active is None:
            best, best_ratio = None, 0.0
            for i in self.inputs:
                base = self._baseline(i)
                loud = base is not None and stds[i] > self.ratio * max(base, 1e-12)
                if loud:
                    self._run[i].append((t_sec, np.asarray(self._buf[i], float)))
                    run = self._run[i]
                    if len(run) > _MAX_DETECTION_S:      # loud for a minute without oscillating: no sweep
                        run.pop(0)
                    if len(run) >= self.start_s:
                        x = np.concatenate([r[1] for r in run])
                        x = x[np.isfinite(x)]
                        crossings = int(np.count_nonzero(np.diff(np.signbit(x - x.mean()))))
                        r = stds[i] / max(base, 1e-12)
                        if crossings >= self.min_crossings and r > best_ratio:
                            best, best_ratio = i, r
                else:
                    self._run[i] = []
                    self._quiet[i].append(stds[i])
            if best is not None:
                self.active = best
                self.quiet_for = 0
                self.last_active_t = t_sec + 1.0
                events.append(TestPointEvent(self._run[best][0][0], "start", "sweep", best,
                                             f"{best} oscillates {best_ratio:.0f}x above its quiet level"))
                for i in self.inputs:
                    self._run[i] = []
            return events
        i = self.active
        base = self._baseline(i)
        if base is not None and stds[i] > 2.0 * max(base, 1e-12):
            self.quiet_for = 0
            self.last_active_t = t_sec + 1.0
        else:
            self.quiet_for += 1
            if self.quiet_for >= self.quiet_end_s:
                events.append(TestPointEvent(self.last_active_t, "end", "sweep", i,
                                             f"{i} quiet for {self.quiet_end_s} s"))
                self.active = None
        return events


class TestPointTracker:
    """Opens, judges and closes test points from frames and aligned samples.

    Parameters
    ----------
    names : sequence of str
        The aligned signals, in block row order.
    inputs, outputs : sequence of str
    sample_rate_hz : float
    band_rad_s : (float, float)
    sources : sequence of str
        Which evidence opens test points (:data:`SOURCES`).
    axes : dict of int -> str
        ArduPilot SystemID axis -> the input it sweeps.
    required : dict of str -> sequence of str
        Input -> the outputs whose pairs must be adequate when it is swept (default: the output
        at the input's list position, else every output).
    min_duration_s : float
        Shortest test point that can be GO [s].
    references : dict of input -> reference, optional
        The logged injection of an input.
    source_rates : callable, optional
        ``source_rates() -> {signal: Hz}``: the rate each signal arrives at (a pair whose signals
        arrive too slowly for the top of the band is told so).
    link_counts : callable, optional
        ``link_counts() -> {counter: cumulative count}``: the live link's loss counters
        (``kernel_drops``, ``seq_gaps``, ``analysis_shed``, ``received``), read when a test point
        opens and when it is judged; None for a file.
    criteria : Criteria
        What judges each test point and is recorded with it (the map's ``[criteria]``).
    """

    def __init__(self, names, inputs, outputs, sample_rate_hz: float, band_rad_s, *, sources=SOURCES,
                 axes: dict | None = None, required: dict | None = None, min_duration_s: float = 10.0,
                 references: dict | None = None, source_rates=None, link_counts=None,
                 criteria: Criteria = DEFAULT_CRITERIA):
        self.names, self.inputs, self.outputs = tuple(names), tuple(inputs), tuple(outputs)
        self.fs, self.band = float(sample_rate_hz), (float(band_rad_s[0]), float(band_rad_s[1]))
        self.sources = tuple(sources)
        self.axes = {int(k): v for k, v in (axes or {}).items()}
        self.required = {i: tuple(v) for i, v in (required or {}).items()}
        self.min_duration_s = float(min_duration_s)
        self.criteria = criteria
        self.references = dict(references or {})     # input -> its logged injection
        self.source_rates = source_rates
        self.link_counts = link_counts
        self.vehicle = VehicleInfo()                 # parameters, frame, SystemID settings of the vehicle
        self.unfit: str = ""                         # why the map does not fit the vehicle (judged NO-GO)
        self.current: TestPoint | None = None
        self.closing: list[TestPoint] = []           # ended, waiting for their last samples
        self.closed: list[dict] = []                 # records of the closed test points, in order
        self.explicit = False                        # an autopilot or marker event was seen
        self._pre = deque()                          # (t0, values, valid, raw) blocks of the recent past
        self._sweep = _SweepDetector(self.inputs, self.fs) if "sweep" in self.sources else None
        self._systemid = SystemIdWatch()             # the analysed vehicle's SystemID runs
        self._ground_stations: set = {GCS_SYSID}     # systems whose HEARTBEAT says MAV_TYPE_GCS
        self.ignored = 0                             # detected activity shorter than a test point
        #: the latest judgement of each recent test point, by its record's ``start_s`` (what a view draws)
        self.judgements: dict = {}

    # -- what it watches ------------------------------------------------------------------------
    def wants(self, topic: str) -> bool:
        """Whether frames of ``topic`` can carry a test-point event or what the vehicle says of itself."""
        if topic == LOST_TOPIC or VehicleInfo.wants(topic):
            return True
        if "autopilot" in self.sources and topic in ("/dataflash/MODE",):
            return True
        return "marker" in self.sources and (topic == MARKER_TOPIC or topic.endswith("/marker")
                                             or topic in ("/mavlink/STATUSTEXT", "/mavlink/NAMED_VALUE_INT"))

    def learn(self, frame: Frame, system) -> None:
        """What a frame says about the vehicle analysed (``system``; None: not known yet): its
        parameters, frame and type (:class:`~livesweep.monitor.vehicle.VehicleInfo`). Taken from the
        first frame on, before any sample exists (a ground station fetches the parameters first)."""
        sysid = frame.data.get("sysid") if isinstance(frame.data, dict) else None
        if VehicleInfo.wants(frame.topic) and (sysid is None or system is None or sysid == system):
            self.vehicle.take(frame)

    def required_outputs(self, swept: str) -> tuple:
        if swept in self.required:
            return self.required[swept]
        k = self.inputs.index(swept)
        return (self.outputs[k],) if k < len(self.outputs) else self.outputs

    # -- frames -> events -----------------------------------------------------------------------
    def events_of(self, frame: Frame, t_s: float, system) -> list[TestPointEvent]:
        """The events ``frame`` carries, at data time ``t_s``; ``system`` is the vehicle analysed."""
        d = frame.data
        topic = frame.topic
        sysid = d.get("sysid")
        auto, marker = "autopilot" in self.sources, "marker" in self.sources
        if sysid is not None and system is not None and sysid != system:
            # another system: a ground station's markers count (the operator's), nothing else does
            if topic == "/mavlink/HEARTBEAT" and d.get("type") == MAV_TYPE_GCS:
                self._ground_stations.add(sysid)
            if sysid != GCS_SYSID and sysid not in self._ground_stations:
                return []
            auto = False
        out = []
        if topic == LOST_TOPIC:
            silent = d.get("silent_s")
            silent = f" (no frame for {silent:.1f} s)" if isinstance(silent, (int, float)) else ""
            out.append(TestPointEvent(t_s, "lost", "monitor", note=f"telemetry lost{silent}"))
        elif auto and topic in SYSTEMID_TOPICS and (ev := self._systemid.feed(topic, d, self.vehicle)) is not None:
            out.append(TestPointEvent(t_s, ev.action, "autopilot", None if ev.axis is None else self.axes.get(ev.axis),
                                      ev.note, injection=ev.injection, axis=ev.axis))
        elif topic in ("/mavlink/STATUSTEXT", "/dataflash/MSG"):
            text = str(d.get("text", d.get("Message", "")))
            if marker and (m := _MARKER_TEXT.match(text)):
                out.append(self._marker(t_s, m.group(1), m.group(2), f"text: {text}"))
        elif topic == "/mavlink/NAMED_VALUE_INT" and marker and str(d.get("name", "")).strip() == "LS_TP":
            v = d.get("value")
            if isinstance(v, int):
                swept = self.inputs[v - 1] if 0 < v <= len(self.inputs) else None
                out.append(self._marker(t_s, "start" if v > 0 else "end", swept, f"NAMED_VALUE_INT LS_TP = {v}"))
        elif marker and (topic == MARKER_TOPIC or topic.endswith("/marker")):
            action = str(d.get("action", "")).lower()
            if action in ("start", "end"):
                out.append(self._marker(t_s, action, d.get("input"), f"{topic}: {d.get('note', '')}".strip()))
        return out

    def _ended_before(self, tp: TestPoint) -> tuple[float, str] | None:
        """When the telemetry stops during ``tp``: whether its sweep was already over, as
        ``(end [s], why)``: the chirp the autopilot was told to fly had ended, or the input a
        detected sweep follows had been quiet for ``_QUIET_BEFORE_LOSS_S``. None: it was cut short."""
        inj = tp.injection
        last = tp.t0[-1] + tp.values[-1].shape[1] / self.fs if tp.values else tp.start_s   # its last sample [s]
        if tp.source == "autopilot" and inj is not None and last - tp.start_s >= inj.duration_s - _CHIRP_END_TOL_S:
            return tp.start_s + inj.duration_s, "the injection had ended"
        det = self._sweep
        if (tp.source == "sweep" and det is not None and det.active == tp.swept_input
                and det.quiet_for >= _QUIET_BEFORE_LOSS_S):
            return det.last_active_t, f"{tp.swept_input} quiet for {det.quiet_for} s"
        return None

    def _marker(self, t_s, action, swept, note) -> TestPointEvent:
        swept = swept if swept in self.inputs else None
        return TestPointEvent(t_s, action.lower(), "marker", swept, note)

    # -- the state machine ----------------------------------------------------------------------
    def event(self, ev: TestPointEvent) -> list[tuple[float, dict]]:
        """Apply an event; returns ``(data time [s], record)`` of the test points it opened."""
        if ev.action == "lost":
            cur = self.current
            if cur is not None:
                done = self._ended_before(cur)
                if done is not None:                 # the sweep was over: judged as it is
                    cur.end_s, cur.end_note = max(done[0], cur.start_s), f"{done[1]}; then {ev.note} at {ev.t_s:.1f} s"
                else:
                    cur.end_s, cur.end_note = max(ev.t_s, cur.start_s), ev.note
                    cur.lost = f"{ev.note} at {ev.t_s:.1f} s: the test point is incomplete; fly it again"
                self.closing.append(cur)
                self.current = None
                if self._sweep is not None:
                    self._sweep.active = None
            return []
        out = []
        if ev.source != "sweep":
            if not self.explicit and self.current is not None and self.current.source == "sweep" \
                    and ev.action == "start":
                # an explicit event supersedes sweep detection from now on: the detected one is dropped
                out.append((ev.t_s, {**self.current.record("open"), "state": "superseded"}))
                self.current = None
            self.explicit = True
        elif self.explicit:
            return []
        cur = self.current
        if ev.action == "end":
            if cur is not None:
                cur.end_s, cur.end_note = max(ev.t_s, cur.start_s), ev.note
                self.closing.append(cur)
                self.current = None
            return out
        if cur is not None:
            if cur.start_s >= ev.t_s - SAME_START_S:
                # the same start seen twice (a STATUSTEXT and a mode change, MSG and SIDS): keep the
                # first, take the input, the axis and the sweep from whichever names them (SIDS
                # carries the sweep's own parameters: it wins)
                if cur.swept_input is None and ev.swept_input is not None:
                    cur.swept_input = ev.swept_input
                if cur.axis is None and ev.axis is not None:
                    cur.axis = ev.axis
                    cur.unjudged = self._unjudged(ev)
                cur.injection = better_injection(cur.injection, ev.injection)
                return out + [(ev.t_s, cur.record("open"))]
            cur.end_s, cur.end_note = ev.t_s, f"a new test point started ({ev.note})"
            self.closing.append(cur)
        return out + self._open(ev)

    def _unjudged(self, ev: TestPointEvent) -> str:
        """Why an autopilot start cannot be judged with this map ('' when it can)."""
        if ev.source != "autopilot" or ev.axis is None or ev.swept_input is not None or not self.axes:
            return ""
        return (f"SystemID {axis_name(ev.axis)}: the map names no input for it (its [test_points] axes: "
                f"{', '.join(str(a) for a in sorted(self.axes))}), so this test point is not judged")

    def _open(self, ev: TestPointEvent) -> list[tuple[float, dict]]:
        tp = TestPoint(ev.t_s, ev.source, ev.swept_input, ev.note, injection=ev.injection, axis=ev.axis,
                       criteria=self.criteria,
                       unjudged=self._unjudged(ev))
        before = []
        for t0, values, valid, raw in self._pre:      # split the recent samples at the start
            k = int(np.clip(math.ceil((ev.t_s - t0) * self.fs - GRID_TOL), 0, values.shape[1]))
            before.append(values[:, :k])
            if k < values.shape[1]:
                tp.t0.append(t0 + k / self.fs)
                tp.values.append(values[:, k:])
                tp.valid.append(valid[k:])
                if raw is not None:
                    tp.raw.append(raw)           # counted over its span only (DataLoss.measure)
        if self.link_counts is not None:
            tp.link0 = dict(self.link_counts())
        tp.pre = np.concatenate(before, axis=1)[:, -int(round(PRE_TEST_S * self.fs)):] if before else None
        tp.next_judge_s = ev.t_s + max(self.min_duration_s, JUDGE_EVERY_S)
        self.current = tp
        return [(ev.t_s, tp.record("open"))]

    def block(self, t0: float, values: np.ndarray, valid: np.ndarray,
              t: np.ndarray | None = None, raw: dict | None = None) -> list[tuple[float, dict]]:
        """Take one aligned block (start time [s], (n_signals, n), (n,), and optionally its sample
        times [s], :attr:`AlignedBlock.t_s`, and per signal the times [s] of the samples it
        received for the block's grid samples, those within a grid period before each: what its
        data lost is counted from them); returns ``(data time [s], record)`` of the test points it
        opened (sweep detection), judged while open, or closed."""
        out = []
        n = values.shape[1]
        if t is None:
            t = t0 + np.arange(n) / self.fs
        self._pre.append((t0, values, valid, raw))    # first: a test point opened by this block splits it
        keep_from = t0 - PRE_TEST_S - _MAX_DETECTION_S  # by time, so what is kept does not depend on block sizes
        while self._pre and self._pre[0][0] + self._pre[0][1].shape[1] / self.fs < keep_from:
            self._pre.popleft()
        if self._sweep is not None and not self.explicit:
            rows = {i: values[self.names.index(i)] for i in self.inputs}
            for ev in self._sweep.feed(t, rows):
                out += self.event(ev)
        for tp in [*self.closing, *([self.current] if self.current is not None else [])]:
            tol = GRID_TOL / self.fs
            start = int(np.searchsorted(t, tp.start_s - tol))
            stop = n if tp.end_s is None else int(np.searchsorted(t, tp.end_s + tol))
            if stop > start and (not tp.t0 or t[start] > tp.t0[-1] + tol):
                tp.t0.append(float(t[start]))
                tp.values.append(values[:, start:stop])
                tp.valid.append(valid[start:stop])
                if raw is not None:
                    tp.raw.append(raw)
        for tp in list(self.closing):
            if t[-1] >= tp.end_s:
                out += self._close(tp)
        cur = self.current
        if cur is not None:
            # judged at fixed ticks of data time, on the samples up to the tick: what it says, and
            # when, depends on the data alone (a replay's blocks are longer than a live run's)
            while cur.next_judge_s <= t[-1] and cur.next_judge_s - cur.start_s < MAX_TEST_POINT_S:
                self._judge(cur, until_s=cur.next_judge_s)
                out.append((cur.next_judge_s, cur.record("open")))
                cur.next_judge_s += JUDGE_EVERY_S
            if cur.next_judge_s - cur.start_s >= MAX_TEST_POINT_S:
                cur.end_s, cur.end_note = cur.start_s + MAX_TEST_POINT_S, f"closed at {MAX_TEST_POINT_S:g} s"
                self.current = None
                self.closing.append(cur)
                if t[-1] >= cur.end_s:
                    out += self._close(cur)
        return out

    def expire(self, t_s: float, *, lost: bool = False) -> list[tuple[float, dict]]:
        """Close the test points that ended more than :data:`CLOSE_WAIT_S` before data time ``t_s``
        (told by a frame that carries no samples: a HEARTBEAT, a STATUSTEXT) and are still waiting
        for their last samples, or, with ``lost`` (the telemetry stopped: nothing more will come),
        every one; returns their ``(data time [s], record)``."""
        out = []
        for tp in list(self.closing):
            if lost or tp.lost or t_s >= tp.end_s + CLOSE_WAIT_S:
                out += self._close(tp)
        return out

    def finish(self, t_end_s: float | None = None) -> list[tuple[float, dict]]:
        """Close every test point still open or closing (the monitor stops, a replay ends)."""
        out = []
        cur = self.current
        if cur is not None:
            cur.end_s = t_end_s if t_end_s is not None else cur.start_s + cur.duration_s(self.fs)
            cur.end_note = "the data ended"
            self.closing.append(cur)
            self.current = None
        for tp in list(self.closing):
            out += self._close(tp)
        return out

    def _close(self, tp: TestPoint) -> list[tuple[float, dict]]:
        self.closing.remove(tp)
        tp.trim(self.fs)
        if tp.source == "sweep" and tp.duration_s(self.fs) < self.min_duration_s:
            self.ignored += 1                     # a doublet or a trim change, not a sweep
            return [(tp.end_s, {**tp.record("closed"), "state": "ignored"})]
        if self.unfit and not tp.unjudged:
            tp.unjudged = f"the map does not fit the vehicle ({self.unfit}): this test point is not judged"
        self._judge(tp)
        rec = tp.record("closed")
        self.closed.append(rec)
        return [(tp.end_s, rec)]

    def _judge(self, tp: TestPoint, until_s: float | None = None) -> None:
        """The closing judgement (``until_s`` None) or a running one over the samples up to ``until_s``."""
        final = until_s is None
        if not tp.values or (tp.unjudged and tp.swept_input is None):
            if final:
                tp.judgement = None
            return
        values, valid = tp.samples()
        if until_s is not None:
            n = max(int(math.floor((until_s - tp.t0[0]) * self.fs + GRID_TOL)) + 1, 0)
            values, valid = values[:, :n], valid[:n]
        if values.shape[1] == 0:
            return
        swept = tp.swept_input
        if swept is None:                      # the evidence did not say: the input that moved most
            spread = [np.nanstd(values[self.names.index(i)]) for i in self.inputs]
            pre = [np.nanstd(tp.pre[self.names.index(i)]) if tp.pre is not None and tp.pre.shape[1] > 1 else 0.0
                   for i in self.inputs]
            ratios = [s / max(p, 1e-12) if p > 0 else s for s, p in zip(spread, pre)]
            swept = tp.swept_input = self.inputs[int(np.nanargmax(ratios))]
        last = tp.t0[0] + (values.shape[1] - 1) / self.fs
        rates = self.source_rates() if self.source_rates is not None else None
        outputs = self.required_outputs(swept)
        j = judge_test_point(values, self.names, self.fs, swept, outputs, self.band,
                             valid=valid, references=self.references, injection=tp.injection,
                             elapsed_s=last - tp.start_s, final=final, min_duration_s=self.min_duration_s,
                             criteria=self.criteria,
                             source_rates_hz=rates, loss=self._loss(tp, (swept, self.references.get(swept), *outputs),
                                                                    valid, last, rates))
        if final:
            tp.judgement = j
            row = self.references.get(swept) or swept          # where the sweep itself is seen
            tp.recommendation = recommend_next(j, input_samples=(values[self.names.index(row)], self.fs)) \
                if row in self.names else recommend_next(j)
        else:
            tp.running = j
        self.judgements[round(tp.start_s, 6)] = j
        while len(self.judgements) > 10:
            self.judgements.pop(next(iter(self.judgements)))

    def _loss(self, tp: TestPoint, signals, valid: np.ndarray, last_s: float, rates: dict | None) -> DataLoss:
        """What ``tp`` lost of the data of ``signals`` (the swept input, its reference, the outputs
        judged) from its first grid sample to ``last_s`` [s]: the frames missing from each
        signal's time stamps, the grid samples in gaps and, live, the link counters since it opened."""
        lo = tp.t0[0] - (1 - GRID_TOL) / self.fs     # a grid sample stands for the period up to it
        hi = last_s + GRID_TOL / self.fs
        names = [s for s in dict.fromkeys(signals) if s is not None]
        times = {} if not tp.raw else {s: np.concatenate([r[s] for r in tp.raw if s in r] or [np.empty(0)])
                                        for s in names}
        spacings = {s: 1.0 / r for s, r in (rates or {}).items() if r}
        link = None
        if self.link_counts is not None and tp.link0 is not None:
            now = self.link_counts()
            link = {k: now.get(k, 0) - tp.link0.get(k, 0) for k in now}
        return DataLoss.measure(times, lo, hi, valid, spacings_s=spacings, link=link)
