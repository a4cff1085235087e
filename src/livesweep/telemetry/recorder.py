"""Live MCAP recording: every received message as it came, plus livesweep's results (docs/outputs.md, MCAP recordings).

The file is written directly (not atomically: a recording must survive the process being
killed) and the open chunk is closed and handed to the OS every ``flush_interval_s`` of wall
time, so a kill loses at most that much (default 1 s) plus what the OS had not written.
Ctrl-C, SIGTERM, SIGHUP or ``--duration`` end with :meth:`McapRecorder.close`, which finishes the
file (summary, index) so any MCAP reader opens it.

An existing file is never replaced unless ``overwrite=True`` (``--force``), and the file is locked
while it is written, so two monitors cannot record into one file. The recorder may be called from
two threads (the monitor's ingest thread records frames, its analysis thread records results): a
lock serialises the writes.

Results go on ``/livesweep/<name>`` channels, each with a full JSON Schema (:data:`RESULT_SCHEMAS`)
so Foxglove and other viewers offer their fields for plotting.
"""

from __future__ import annotations

import json
import logging
import threading
import time

from livesweep import __version__
from livesweep.telemetry.clock import UINT64_NS_MAX
from livesweep.telemetry.frames import Frame
from livesweep.errors import LogFormatError
from livesweep.numeric import float_json_schema
from livesweep.telemetry.mcap_log import McapLogWriter

__all__ = ["McapRecorder", "RESULT_PREFIX", "RESULT_SCHEMAS", "COUNTERS_METADATA", "RAW_TOPIC"]

log = logging.getLogger(__name__)

RESULT_PREFIX = "/livesweep"
#: The live link's datagrams exactly as received, written by the recorder process before decoding
#: (:mod:`livesweep.telemetry.capture`): ``{"src": k, "b64": ...}``, ``src`` indexing the channel's
#: ``sources`` metadata. A replay takes the decoded channels instead.
RAW_TOPIC = "/link/mavlink"
#: Metadata record with the final link and pipeline counters (JSON text per source), written on close.
COUNTERS_METADATA = "livesweep.counters"
_GENERIC = {"type": "object", "description": "JSON object as received"}

_COUNT = {"type": "integer", "minimum": 0}
_COUNT_MAP = {"type": "object", "additionalProperties": _COUNT}

#: A value of a test point's model with its Cramer-Rao bound (``/livesweep/model``).
_FIGURE = {"type": "object", "properties": {
    "name": {"type": "string"}, "value": {"type": ["number", "null"]},
    "cramer_rao": {"type": ["number", "null"], "description": "its Cramer-Rao bound, in its units"},
    "units": {"type": "string"},
    "flags": {"type": "array", "items": {"type": "string"},
              "description": "why the method's guidelines say not to trust it"}},
    "required": ["name", "value", "cramer_rao"]}

#: JSON Schemas of livesweep's own channels (``/livesweep/<name>``).
RESULT_SCHEMAS: dict[str, dict] = {
    "link": {
        "type": "object",
        "description": "Link and pipeline counters (cumulative since the monitor started), about once a second",
        "properties": {
            "t_s": {"type": ["number", "null"], "description": "data time of the newest analysed sample [s]"},
            "wall_s": {"type": "number", "description": "seconds since the monitor started"},
            "frames_recorded": _COUNT,
            "analysis_shed": {**_COUNT, "description": "frames the analysis skipped to keep up (recorded all the same)"},
            "sources": {"type": "array", "items": {"type": "object", "properties": {
                "name": {"type": "string"},
                "received": _COUNT_MAP, "by_system": _COUNT_MAP, "seq_gaps": _COUNT_MAP,
                "bad_crc": _COUNT, "bad_prefix_or_garbage": _COUNT, "unknown_message": _COUNT,
                "rejected_unsigned": _COUNT, "bad_signature": _COUNT, "replayed_signature": _COUNT,
                "clock_unrepresentable": _COUNT, "clock_implausible": _COUNT, "kernel_drops": _COUNT,
                "malformed": _COUNT, "non_object": _COUNT, "bad_stamp": _COUNT, "dropped_queue_full": _COUNT,
            }, "additionalProperties": True}},
            "aligner": {**_COUNT_MAP, "description": "aligner counters (clock rejections, resets, gaps, other systems)"},
        },
        "required": ["wall_s", "frames_recorded", "analysis_shed", "sources", "aligner"],
    },
    "alert": {
        "type": "object",
        "description": "One alert raised by the live monitor",
        "properties": {
            "t_s": {"type": ["number", "null"], "description": "data time [s]"},
            "kind": {"type": "string"},
            "message": {"type": "string"},
            "value": {"type": "number"},
        },
        "required": ["kind", "message"],
    },
    "test_point": {
        "type": "object",
        "description": "One test point, recorded when it closes: where it ran, what was swept, the verdict over all of it",
        "properties": {
            "state": {"type": "string", "enum": ["closed"]},
            "start_s": {"type": "number", "description": "data time [s, the map's clock]"},
            "end_s": {"type": "number", "description": "data time [s, the map's clock]"},
            "source": {"type": "string", "enum": ["autopilot", "marker", "sweep"]},
            "swept_input": {"type": ["string", "null"]},
            "axis": {"type": ["integer", "null"], "description": "ArduPilot SystemID axis (SID_AXIS)"},
            "note": {"type": "string"}, "end_note": {"type": "string"},
            "verdict": {"type": "string", "enum": ["GO", "NO-GO"]},
            "label": {"type": "string", "description": "the verdict as shown: GO, NO-GO, GO (marginal), NO-GO (link)"},
            "marginal": {"type": "boolean", "description": "a deciding rule within its random error of the threshold"},
            "running": {"type": ["string", "null"], "description": "the last running verdict (GO so far, ...)"},
            "injection": {"type": ["object", "null"], "description": "the sweep the autopilot was told to inject",
                          "properties": {"band_rad_s": {"type": "array", "items": {"type": "number"}},
                                         "t_record_s": {"type": "number"}, "t_const_s": {"type": "number"},
                                         "t_fade_in_s": {"type": "number"}, "t_fade_out_s": {"type": "number"},
                                         "delay_s": {"type": "number"}, "magnitude": {"type": "number"},
                                         "axis": {"type": ["integer", "null"]}, "source": {"type": "string"}}},
            "judged_band_rad_s": {"type": "array", "items": {"type": "number"},
                                  "description": "the band judged [rad/s]: the injection's, else the map's"},
            "swept_band_rad_s": {"type": ["array", "null"], "items": {"type": "number"},
                                 "description": "the part of it swept [rad/s]"},
            "excitation": {"type": "string", "enum": ["injection", "reference", "input"],
                           "description": "what the sweep was judged from"},
            "progress": {"type": "string", "description": "0.5-2.9 Hz of 0.5-12 Hz swept"},
            "pairs": {"type": "array", "items": {"type": "object", "properties": {
                "output": {"type": "string"}, "input": {"type": "string"},
                "adequate_fraction": {"type": "number", "description": "fraction of the band (decades), 0..1"},
                "adequate_range": {"type": "array", "items": {"type": "number"},
                                   "description": "the fraction at -/+ the coherence's random error"},
                "band_rad_s": {"type": ["array", "null"], "items": {"type": "number"}},
                "coherence": {"type": "string", "enum": ["ordinary", "partial"]},
                "median_coherence": {"type": "number"}}}},
            "missing": {"type": "array", "items": {"type": "string"}},
            "reasons": {"type": "array", "items": {"type": "string"}},
            "excited_fraction": {"type": ["number", "null"]},
            "duration_s": {"type": "number"},
            "loss_fraction": {"type": ["number", "null"],
                              "description": "fraction of its frames lost over its span, 0..1: the worst of its "
                                             "signals' frames missing from their time stamps and its grid samples "
                                             "in gaps (the first reason from 0.136; a NO-GO from 0.225 is labelled "
                                             "NO-GO (link)), with the method's criteria"},
            "criteria": {"type": "object", "description": "the criteria that judged it (the map's [criteria])",
                         "properties": {"min_coherence": {"type": "number"}, "max_random_error": {"type": "number"},
                                        "required_fraction": {"type": "number"}}},
            "next": {"type": ["object", "null"], "description": "what to fly next for this input", "properties": {
                "verdict": {"type": "string"}, "needed": {"type": "boolean"},
                "missing": {"type": "array", "items": {"type": "object", "properties": {
                    "pair": {"type": "string"}, "band_rad_s": {"type": "array", "items": {"type": "number"}},
                    "band_hz": {"type": "array", "items": {"type": "number"}},
                    "cause": {"type": "string", "enum": ["not_swept", "short_record", "incoherent"]},
                    "detail": {"type": "string"}, "median_coherence": {"type": ["number", "null"]},
                    "amplitude_factor": {"type": ["number", "null"]},
                    "median_random_error": {"type": ["number", "null"]}}}},
                "sweep": {"type": ["object", "null"], "description": "the method's sweep design (band, duration, "
                                                                   "number of sweeps, amplitude, trims, fades)"},
                "ardupilot": {"type": ["object", "null"], "description": "SID_* parameters to set",
                              "additionalProperties": {"type": ["number", "null"]}},
                "ardupilot_changed": {"type": "array", "items": {"type": "string"}},
                "chirp_cut_s": {"type": ["array", "null"], "items": {"type": "number"}},
                "lines": {"type": "array", "items": {"type": "string"}}}},
            "limits": {"type": "array", "items": {"type": "string"},
                       "description": "the limits its model broke (operator lines)"},
            "model_pairs": {"type": "array", "items": {"type": "string"},
                            "description": "the pairs of its /livesweep/model"},
        },
        "required": ["start_s", "end_s", "source", "swept_input", "verdict", "pairs", "missing"],
    },
    "model": {
        "type": "object",
        "description": "The model of one closed test point: a low-order equivalent system per pair, on its coherent "
                       "band, with Cramer-Rao bounds, handling-qualities figures, limits and the trend over the flight",
        "properties": {
            "schema": {"type": "string", "description": "livesweep.model/1"},
            "test_point": {"type": "object", "description": "the test point modelled", "properties": {
                "number": {"type": "integer", "description": "its place among the closed test points, from 1"},
                "start_s": {"type": "number"}, "end_s": {"type": "number"},
                "swept_input": {"type": ["string", "null"]}, "axis": {"type": ["integer", "null"]},
                "source": {"type": "string"}, "verdict": {"type": "string"}, "label": {"type": "string"},
                "conditions": {"type": "object", "additionalProperties": {"type": ["number", "null"]},
                               "description": "the map's [test_points] conditions averaged over it"}}},
            "pairs": {"type": "array", "items": {"type": "object", "properties": {
                "name": {"type": "string", "description": "output/input"},
                "output": {"type": "string"}, "input": {"type": "string"},
                "structure": {"type": "string", "enum": ["first order", "second order", "case"]},
                "numerator": {"type": "string", "description": "shorthand, as [transfer_functions] writes it"},
                "denominator": {"type": "string"},
                "band_rad_s": {"type": "array", "items": {"type": ["number", "null"]},
                               "description": "the fitted band [rad/s]"},
                "cost": {"type": ["number", "null"], "description": "J of the fit"},
                "converged": {"type": "boolean"},
                "parameters": {"type": "array", "items": _FIGURE},
                "figures": {"type": "array", "items": _FIGURE},
                "flags": {"type": "array", "items": {"type": "string"},
                          "description": "the method's guidelines the fit fails"},
                "limits": {"type": "array", "items": {"type": "object", "properties": {
                    "pair": {"type": "string"}, "name": {"type": "string"},
                    "value": {"type": ["number", "null"]}, "limit": {"type": ["number", "array", "null"]},
                    "ok": {"type": "boolean"}, "text": {"type": "string"}}}},
                "curve": {"type": "object", "description": "data and model over the band: omega_rad_s, magnitude_db, "
                                                          "phase_deg, coherence, model_*, predicted_*",
                          "additionalProperties": {"type": "array", "items": {"type": ["number", "null"]}}},
            }, "required": ["name", "output", "input", "parameters", "figures", "cost"]}},
            "skipped": {"type": "array", "items": {"type": "string"}},
            "limits_ok": {"type": "boolean"},
            "breaches": {"type": "array", "items": {"type": "string"}},
            "criteria": {"type": "object"},
            "trend": {"type": "array", "items": {"type": "object", "properties": {
                "pair": {"type": "string"},
                "rows": {"type": "array", "items": {"type": "object"}}}}},
            "trend_notes": {"type": "array", "items": {"type": "string"}},
        },
        "required": ["schema", "test_point", "pairs", "limits_ok", "breaches"],
    },
    "verdict": {
        "type": "object",
        "description": "The operator's verdict, recorded on every change",
        "properties": {
            "t_s": {"type": "number", "description": "data time [s]"},
            "verdict": {"type": "string", "enum": ["WAIT", "GO", "NO-GO"]},
            "previous": {"type": ["string", "null"]},
            "reasons": {"type": "array", "items": {"type": "string"}},
            "test_point": {"type": ["object", "null"]},
        },
        "required": ["t_s", "verdict", "previous"],
    },
    "estimate": {
        "type": "object",
        "description": "One live estimate: coherence per pair over the frequency grid, adequacy and verdict",
        "properties": {
            "t_s": {"type": "number", "description": "data time [s]"},
            "n_segments": _COUNT,
            "conditioned": {"type": "boolean"},
            "coherence_kind": {"type": "string", "enum": ["ordinary", "partial"],
                               "description": "the coherence shown is the one the adequacy judged"},
            "omega_rad_s": {"type": "array", "items": {"type": "number"}},
            "coherence": {"type": "object", "description": "output/input -> coherence over omega_rad_s",
                          "additionalProperties": {"type": "array", "items": float_json_schema()}},
            "adequacy": {"type": "array", "items": {"type": "object", "properties": {
                "output": {"type": "string"}, "input": {"type": "string"},
                "band": {"type": ["array", "null"], "items": {"type": "number"}},
                "fraction": {"type": "number"}}}},
            "pairs": {"type": "array", "description": "per output/input pair: the estimate over the grid and "
                                                      "its summary, for plotting (Foxglove message paths)",
                      "items": {"type": "object", "properties": {
                          "name": {"type": "string", "description": "output/input"},
                          "output": {"type": "string"}, "input": {"type": "string"},
                          "omega_rad_s": {"type": "array", "items": {"type": "number"},
                                          "description": "frequency [rad/s]"},
                          "magnitude_db": {"type": "array", "items": float_json_schema(),
                                           "description": "magnitude [dB of output units per input unit]"},
                          "phase_deg": {"type": "array", "items": float_json_schema(), "description": "phase [deg]"},
                          "coherence": {"type": "array", "items": float_json_schema(),
                                        "description": "coherence (the kind in coherence_kind)"},
                          "median_coherence": float_json_schema(description="median over the band"),
                          "adequate_fraction": {"type": "number",
                                                "description": "fraction of the band (decades) adequate, 0..1"}},
                          "required": ["name", "omega_rad_s", "magnitude_db", "phase_deg", "coherence"]}},
            "go": {"type": "integer", "enum": [0, 1], "description": "1 while the verdict is GO (to plot)"},
            "verdict": {"type": "string", "enum": ["WAIT", "GO", "NO-GO"]},
            "window_verdict": {"type": "string", "enum": ["WAIT", "GO", "NO-GO"],
                               "description": "what the sliding window alone says (not the operator's verdict)"},
            "reasons": {"type": "array", "items": {"type": "string"}},
            "alerts": {"type": "array", "items": {"type": "object", "properties": {
                "kind": {"type": "string"}, "message": {"type": "string"}}}},
        },
        "required": ["t_s", "omega_rad_s", "coherence", "verdict"],
    },
}


def _schema_for(topic: str) -> tuple[str, dict]:
    if topic.startswith("/mavlink/"):
        from livesweep.telemetry import mavlink_codec

        name = topic.split("/", 2)[2]
        try:
            return f"mavlink.{name}", mavlink_codec.json_schema(name)
        except Exception:  # noqa: BLE001 - an unknown message still gets recorded
            return f"mavlink.{name}", _GENERIC
    return topic.strip("/").replace("/", "."), _GENERIC


class McapRecorder:
    """Records frames and results to ``path``.

    Parameters
    ----------
    path : str or Path
    flush_interval_s : float
        Wall-clock period of chunk flushes [s]: the most a kill can lose.
    settings : dict, optional
        Stored as the ``livesweep_settings.json`` attachment (the channel map and spectral
        settings the live results came from).
    metadata : dict of str -> dict, optional
        MCAP metadata records (test point: aircraft, condition, manoeuvre, notes).
    overwrite : bool
        Replace an existing file (``--force``); by default an existing file is an error.

    Raises
    ------
    LogFormatError
        If ``path`` exists and ``overwrite`` is False, or another process is writing it.
    """

    def __init__(self, path, *, flush_interval_s: float = 1.0, settings: dict | None = None,
                 metadata: dict | None = None, clock=time.monotonic, overwrite: bool = False):
        self.writer = McapLogWriter(path, library=f"livesweep {__version__} recorder", atomic=False,
                                    chunk_size=256 * 1024, flush_every=0, overwrite=overwrite)
        self.flush_interval_s = flush_interval_s
        self._clock = clock
        self._last_flush = clock()
        self._lock = threading.Lock()
        self.path = self.writer.path
        self.bad_publish_time = 0
        self.unrecordable = 0
        for name, values in (metadata or {}).items():
            self.writer.add_metadata(name, values)
        if settings is not None:
            self.writer.add_attachment("livesweep_settings.json", json.dumps(settings, indent=1).encode(),
                                       "application/json")
        self._known: set[str] = set()
        self._counters: dict[str, str] | None = None

    def _channel(self, topic: str, schema: tuple[str, dict] | None = None) -> None:
        if topic not in self._known:
            name, sch = schema or _schema_for(topic)
            self.writer.add_channel(topic, name, sch)
            self._known.add(topic)

    def record(self, frames: list[Frame]) -> None:
        """Write received frames (log_time = receive time, publish_time = vehicle time or receive time).

        A vehicle time an MCAP record cannot hold falls back to the receive time (counted in
        :attr:`bad_publish_time`; the sources normally catch it first): a frame is never lost to
        its stamp. A frame whose content cannot be encoded as JSON (the sources only deliver
        decoded JSON and MAVLink records, so this is a defence in depth) is counted in
        :attr:`unrecordable` and skipped: it never stops the recording.
        """
        with self._lock:
            for f in frames:
                self._channel(f.topic)
                pub = f.vehicle_ns
                if pub is not None and not 0 <= pub <= UINT64_NS_MAX:
                    self.bad_publish_time += 1
                    pub = None
                try:
                    self.writer.write(f.topic, f.data, log_time_ns=f.receive_ns, publish_time_ns=pub)
                except LogFormatError as e:          # this frame's content cannot be JSON: count, go on
                    self.unrecordable += 1
                    if self.unrecordable == 1:
                        log.warning("%s (further such frames are only counted)", e)
            self._maybe_flush()

    def record_result(self, name: str, payload: dict, log_time_ns: int, *, flush: bool = False) -> None:
        """Write a live result on ``/livesweep/<name>`` (schema from :data:`RESULT_SCHEMAS`).

        ``flush=True`` hands it to the OS at once (verdict changes and closed test points: rare,
        and what an operator acts on, so a kill right after must not lose them).
        """
        topic = f"{RESULT_PREFIX}/{name}"
        schema = RESULT_SCHEMAS.get(name, {"type": "object", "description": f"livesweep live {name}"})
        with self._lock:
            self._channel(topic, (f"livesweep.{name}", schema))
            self.writer.write(topic, payload, log_time_ns=log_time_ns)
            if flush:
                self.writer.flush()
                self._last_flush = self._clock()

    def set_counters(self, counters: dict) -> None:
        """The final counters, written as the :data:`COUNTERS_METADATA` record when the file is closed."""
        self._counters = {str(k): json.dumps(v, sort_keys=True, default=str) for k, v in counters.items()}

    def maybe_flush(self) -> None:
        """Hand the open chunk to the OS if ``flush_interval_s`` has passed since the last flush."""
        with self._lock:
            self._maybe_flush()

    def _maybe_flush(self) -> None:
        now = self._clock()
        if now - self._last_flush >= self.flush_interval_s:
            self.writer.flush()
            self._last_flush = now

    @property
    def message_counts(self) -> dict:
        return self.writer.message_counts

    def close(self):
        """Finish the file (idempotent)."""
        with self._lock:
            if not self.writer.closed:
                if self._counters is not None:
                    self.writer.add_metadata(COUNTERS_METADATA, self._counters)
                return self.writer.close()
            return self.writer.path
