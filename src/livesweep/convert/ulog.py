"""PX4 ULog (``.ulg``) to livesweep's MCAP, with pyulog (the optional extra ``livesweep[ulog]``).

Channels
--------
* ``/ulog/<topic>``: one message per logged sample of the uORB topic, fields flattened as pyulog
  gives them (``gyro_rad[0]``, ``control[3]``, nested ``estimator_status.states[2]`` as written
  by pyulog); padding fields are not written. ``timestamp`` (µs since boot) stays a field, so a
  case file reads vehicle time with ``stamp = "timestamp"``, ``stamp_scale = 1e-6``.
* Multi-instance topics (several sensors of a kind, ``multi_id``): a topic whose only instance
  is 0 is ``/ulog/<topic>``; a topic with any other instance is written as
  ``/ulog/<topic>/<multi_id>`` for **every** instance (also 0), so the instances never mix and a
  name never changes meaning between logs that have one or several instances of that topic.
  The channel metadata holds ``ulog_topic`` and ``multi_id``.
* ``/ulog/_logged_messages``: the log's text messages (``timestamp``, ``level``, ``level_name``,
  ``message``, and ``tag`` for tagged messages); ``/ulog/_parameter_changes``: parameters changed
  in flight (``timestamp``, ``name``, ``value``). The leading underscore keeps them apart from
  uORB topics, whose names start with a letter.

Times
-----
``publish_time`` is the sample's ``timestamp`` (boot time) in ns. ``log_time`` is the same boot
time shifted onto UTC when the log knows UTC: the median over the GPS samples with a valid
``time_utc_usec`` (``vehicle_gps_position`` or ``sensor_gps``, instance 0 first) of
``time_utc_usec - timestamp``; without such samples ``log_time == publish_time`` (boot clock).
The offset used and its source are in the ``ulog`` metadata record. Messages are written in
time order over all channels (stable: file order within a topic).

:class:`UlogLog` gives the same topics, times and values column-wise, as numpy arrays, without
writing them (``livesweep inspect``).

Metadata
--------
The converter's ``source``/``conversion`` records (format version ``"ULog v<n>, <sys_name>
<release or ver_sw> on <ver_hw>"``), plus ``ulog`` (time base, file version, topics),
``ulog.info`` (the log's info messages; multi-info as JSON lists) and ``ulog.parameters``
(the initial parameters).

What is counted
---------------
``skipped["dropout_events"]``: the logger's own dropouts (data lost on the vehicle, with their
total duration in a warning); ``skipped["corrupt_data"]``: 1 when pyulog found corrupt data and
resynchronised (how much was lost it cannot say: a warning says so);
``skipped["truncated_tail"]``: 1 when the file ends inside a message (the partial message is
dropped, as pyulog does); ``skipped["implausible_timestamp"]``: samples, text messages and
parameter changes whose ``timestamp`` is beyond 10**15 us since boot (~32 years: a corrupt block
pyulog read as data), dropped with a warning. A UTC offset that would put log times outside
2000..2100 is not used (``log_time`` stays boot time, with a warning).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
from pathlib import Path

import numpy as np

from livesweep.convert.common import (MAX_BOOT_US, MIN_RECORD_FRACTION, UNIX_RANGE_S, ConversionResult,
                                      ConversionWriter, refuse_options)
from livesweep.errors import ConfigError, LogFormatError
from livesweep.numeric import float_json_schema

__all__ = ["convert_ulog", "ulog_topic_name", "UlogLog"]

_GPS_TOPICS = ("vehicle_gps_position", "sensor_gps")
_UTC_MIN_US, _UTC_MAX_US = (s * 10**6 for s in UNIX_RANGE_S)   # below: "no fix yet"; above: corrupt
_LOG_TOPIC = "/ulog/_logged_messages"
_PARAM_TOPIC = "/ulog/_parameter_changes"
_LEVELS = {0: "EMERG", 1: "ALERT", 2: "CRIT", 3: "ERR", 4: "WARNING", 5: "NOTICE", 6: "INFO", 7: "DEBUG"}
_PROGRESS_BYTES = 1 << 20           # bytes read between two progress calls


def _import_pyulog():
    try:
        from pyulog import ULog
    except ImportError as e:
        raise ConfigError("converting PX4 ULog (.ulg) needs pyulog, an optional dependency: "
                          "pip install 'livesweep[ulog]'") from e
    return ULog


class _TrackedFile:
    """A read-only file that remembers its last read, so a file cut inside a message is noticed
    (pyulog stops there silently); ``progress(bytes read, bytes in all, "bytes")`` is called
    every ``_PROGRESS_BYTES`` read."""

    def __init__(self, path: Path, progress=None):
        self._f = open(path, "rb")  # noqa: SIM115 - pyulog closes it
        self.last_read = (0, 0)
        self._progress = progress
        self._size = os.fstat(self._f.fileno()).st_size if progress is not None else 0
        self._next = _PROGRESS_BYTES

    def read(self, n=-1):
        b = self._f.read(n)
        self.last_read = (n, len(b))
        if self._progress is not None and self._f.tell() >= self._next:
            self._next = self._f.tell() + _PROGRESS_BYTES
            self._progress(self._f.tell(), self._size, "bytes")
        return b

    def seek(self, *args):
        return self._f.seek(*args)

    def tell(self):
        return self._f.tell()

    def close(self):
        self._f.close()


def ulog_topic_name(topic: str, multi_id: int, instances) -> str:
    """The MCAP topic of one instance of a uORB topic (the rule in the module docstring).

    Parameters
    ----------
    topic : str
        uORB topic name, e.g. ``"sensor_gyro"``.
    multi_id : int
    instances : collection of int
        Every ``multi_id`` of that topic in the log.
    """
    if set(instances) == {0}:
        return f"/ulog/{topic}"
    return f"/ulog/{topic}/{int(multi_id)}"


def _json_type(dtype: np.dtype) -> dict:
    if dtype.kind in "iub":
        return {"type": "integer"}
    return float_json_schema()


def _utc_offset_us(ulog) -> tuple[int, str]:
    """(offset [µs] to add to boot time for UTC, where it came from); (0, "boot") without GPS time."""
    for name in _GPS_TOPICS:
        for d in sorted((d for d in ulog.data_list if d.name == name), key=lambda d: d.multi_id):
            if "time_utc_usec" not in d.data:
                continue
            utc, ts = d.data["time_utc_usec"], d.data["timestamp"]
            u = utc.astype(np.float64)                     # range checks in float: uint64 garbage wraps in int64
            ok = (u > _UTC_MIN_US) & (u < _UTC_MAX_US) & _plausible_us(ts)
            if ok.any():
                off = int(np.median(utc[ok].astype(np.int64) - ts[ok].astype(np.int64)))
                return off, (f"utc: {name} instance {d.multi_id} time_utc_usec - timestamp, median of "
                             f"{int(ok.sum())} samples")
    return 0, "boot: no GPS UTC time in the log; log_time is boot time"


def _plausible_us(ts: np.ndarray) -> np.ndarray:
    """Mask of boot times [us] in [0, MAX_BOOT_US]; larger ones are corrupt data read as a sample."""
    t = np.asarray(ts).astype(np.float64)
    return (t >= 0) & (t <= MAX_BOOT_US)


def _format_version(ulog) -> str:
    version = getattr(ulog, "_file_version", None)
    text = f"ULog v{version if version is not None else '?'}"
    info = ulog.msg_info_dict
    parts = []
    if info.get("sys_name"):
        parts.append(str(info["sys_name"]))
    try:
        release = ulog.get_version_info_str()
    except Exception:  # noqa: BLE001 - a malformed release field only loses the release text
        release = None
    if release:
        parts.append(release)
    if info.get("ver_sw"):
        parts.append(str(info["ver_sw"]) if not release else f"({info['ver_sw']})")
    if info.get("ver_hw"):
        parts.append(f"on {info['ver_hw']}")
    return text + (", " + " ".join(parts) if parts else "")


def _info_strings(info: dict) -> dict:
    out = {}
    for k, v in info.items():
        if isinstance(v, (list, tuple)):
            out[k] = json.dumps([x if isinstance(x, (int, float, str)) else str(x) for x in v])
        else:
            out[k] = str(v)
    return out


def _data_bytes(ulog) -> int:
    """Bytes of the file that pyulog read as data samples (3-byte header, msg_id, fields)."""
    return sum(len(d.data["timestamp"]) * (5 + sum(v.dtype.itemsize for v in d.data.values()))
               for d in ulog.data_list)


def _read_ulog(ULog, src: Path, topics, progress=None):
    """pyulog's reading of ``src``, what it printed (its warnings), and the tracked file."""
    handle = _TrackedFile(src, progress)
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            ulog = ULog(handle, message_name_filter_list=topics, disable_str_exceptions=True)
    except Exception as e:  # noqa: BLE001 - pyulog raises ULogException, struct.error, IndexError, ...
        raise LogFormatError(f"{src}: not a readable ULog file: {type(e).__name__}: {e}") from e
    finally:
        handle.close()
    return ulog, printed.getvalue(), handle


def _streams(ulog, warn) -> tuple[list, int]:
    """Every logged stream as ``(topic, pyulog data, field names, {field: array}, timestamps [µs,
    int64])``, the samples with an implausible timestamp left out, and how many were left out."""
    instances: dict[str, set] = {}
    for d in ulog.data_list:
        instances.setdefault(d.name, set()).add(int(d.multi_id))
    out = []
    implausible = 0
    seen_topic_fields: dict[str, tuple] = {}
    for d in ulog.data_list:
        topic = ulog_topic_name(d.name, d.multi_id, instances[d.name])
        names = [f.field_name for f in d.field_data if f.field_name in d.data]
        names += [k for k in d.data if k not in names]
        names = [k for k in names if not k.startswith("_padding")]
        if topic in seen_topic_fields and seen_topic_fields[topic] != tuple(names):
            # the same topic and instance subscribed twice with different formats: keep them apart
            k = 2
            while f"{topic}~{k}" in seen_topic_fields:
                k += 1
            warn(f"{topic}: subscribed twice with different fields; the second is written to {topic}~{k}")
            topic = f"{topic}~{k}"
        seen_topic_fields[topic] = tuple(names)
        keep = _plausible_us(d.data["timestamp"])
        implausible += int(keep.size - keep.sum())
        arrays = {k: (d.data[k].astype(np.uint8) if d.data[k].dtype == bool else d.data[k])[keep] for k in names}
        out.append((topic, d, names, arrays, d.data["timestamp"][keep].astype(np.int64)))
    return out, implausible


def _texts(ulog) -> tuple[list, list, int]:
    """The logged text messages (sorted by time) and the parameter changes, each as ``(timestamp
    [µs], record)``, and how many were left out for an implausible timestamp."""
    implausible = 0
    logged = []
    for m in ulog.logged_messages:
        if not 0 <= int(m.timestamp) <= MAX_BOOT_US:
            implausible += 1
            continue
        logged.append((int(m.timestamp), {"timestamp": int(m.timestamp), "level": int(m.log_level),
                                          "level_name": _LEVELS.get(int(m.log_level) & 7, str(m.log_level)),
                                          "message": str(m.message)}))
    for tag, msgs in (ulog.logged_messages_tagged or {}).items():
        for m in msgs:
            if not 0 <= int(m.timestamp) <= MAX_BOOT_US:
                implausible += 1
                continue
            logged.append((int(m.timestamp), {"timestamp": int(m.timestamp), "level": int(m.log_level),
                                              "level_name": _LEVELS.get(int(m.log_level) & 7, str(m.log_level)),
                                              "message": str(m.message), "tag": int(tag)}))
    logged.sort(key=lambda x: x[0])
    params = [(int(t), {"timestamp": int(t), "name": str(n), "value": v if isinstance(v, (int, float)) else str(v)})
              for t, n, v in ulog.changed_parameters if 0 <= int(t) <= MAX_BOOT_US]
    implausible += len(ulog.changed_parameters) - len(params)
    return logged, params, implausible


class UlogLog:
    """A ULog read column-wise: every topic's times and values as numpy arrays, without a Python
    record per sample (what ``livesweep inspect`` reads).

    Topics, times and values are those :func:`convert_ulog` writes: ``/ulog/<topic>`` (the
    multi-instance rule), ``/ulog/_logged_messages``, ``/ulog/_parameter_changes``; log time [ns]
    (boot time shifted onto UTC when the log knows it).

    Parameters
    ----------
    src : str or Path
    partial : bool
        As for :func:`convert_ulog`.
    progress : callable, optional
        ``progress(bytes read, bytes in all, "bytes")``, called now and then while pyulog reads
        the file.

    Attributes
    ----------
    topics : tuple of str
    messages : int
        Samples, text messages and parameter changes read.
    warnings : tuple of str
        What :func:`convert_ulog` would warn of about the streams (a topic subscribed twice).

    Raises
    ------
    ConfigError, LogFormatError
        As :func:`convert_ulog`.
    """

    def __init__(self, src, *, partial: bool = False, progress=None):
        ULog = _import_pyulog()
        src = Path(src)
        ulog, _said, _handle = _read_ulog(ULog, src, None, progress)
        size, read = src.stat().st_size, _data_bytes(ulog)
        if ulog.file_corruption and read < MIN_RECORD_FRACTION * size and not partial:
            raise LogFormatError(f"{src}: pyulog found corruption and read only {100 * read / size:.1f} % of the "
                                 f"file ({read} of {size} bytes) as data samples (livesweep convert --partial "
                                 "converts what is readable)")
        warnings: list[str] = []
        streams, _ = _streams(ulog, warnings.append)
        logged, params, _ = _texts(ulog)
        offset_us, _ = _utc_offset_us(ulog)
        stamps = [ts for *_x, ts in streams] + [np.array([t for t, _ in x], np.int64) for x in (logged, params)]
        if any(int(ts.min()) + offset_us < 0 for ts in stamps if ts.size):
            offset_us = 0                         # what convert_ulog does: log time stays boot time
        self._offset_us = offset_us
        self._arrays = {topic: (arrays, ts) for topic, _d, _n, arrays, ts in streams}
        self._names = {topic: names for topic, _d, names, _a, _t in streams}
        self._texts = {}
        for topic, rows in ((_LOG_TOPIC, logged), (_PARAM_TOPIC, params)):
            if rows:
                self._texts[topic] = (np.array([t for t, _ in rows], np.int64), [r for _, r in rows])
        self.topics = tuple(self._arrays) + tuple(self._texts)
        self.messages = sum(ts.size for ts in stamps)
        self.warnings = tuple(warnings)

    def times_ns(self, topic: str) -> np.ndarray:
        """The log time [ns] of each sample of ``topic``, in file order (int64)."""
        ts = self._arrays[topic][1] if topic in self._arrays else self._texts[topic][0]
        return (ts + self._offset_us) * 1000

    def first(self, topic: str) -> dict:
        """The earliest sample of ``topic`` as ``{field: value}`` (the JSON record convert writes)."""
        if topic in self._texts:
            ts, rows = self._texts[topic]
            return dict(rows[int(np.argmin(ts))])
        arrays, ts = self._arrays[topic]
        i = int(np.argmin(ts))
        return {k: arrays[k][i].item() for k in self._names[topic]}

    def column(self, topic: str, name: str) -> np.ndarray | None:
        """Field ``name`` of ``topic`` as float64 values in file order; None when ``topic`` has no
        such numeric field."""
        if topic in self._texts:
            return None
        col = self._arrays[topic][0].get(name)
        if col is None or col.dtype.kind not in "iuf":
            return None
        return col.astype(np.float64)


def convert_ulog(src: Path, out: Path, *, topics=None, partial: bool = False, **options) -> ConversionResult:
    """Convert a PX4 ULog file to MCAP (channels, times and counts in the module docstring).

    Parameters
    ----------
    src, out : Path
    topics : list of str, optional
        Convert only these uORB topics (pyulog's ``message_name_filter_list``); all by default.
    partial : bool
        Convert even when pyulog found corruption and less than
        :data:`~livesweep.convert.common.MIN_RECORD_FRACTION` of the file's bytes are data
        samples (by default that is refused: a damaged definitions section loses every sample).
        The check needs every topic: with ``topics`` it is not made.

    Raises
    ------
    ConfigError
        pyulog is not installed, or an unknown option.
    LogFormatError
        pyulog cannot read the file at all (bad header or definitions), or found corruption and
        read less than half of the file as data (without ``partial``), naming the file.
    """
    refuse_options(src, "a ULog", options, "topics and partial only")
    ULog = _import_pyulog()
    src, out = Path(src), Path(out)
    if topics is not None:
        if isinstance(topics, str) or not all(isinstance(t, str) for t in topics):
            raise ConfigError(f"convert_ulog: topics must be a list of uORB topic names, got {topics!r}")
        topics = list(topics)
    ulog, said, handle = _read_ulog(ULog, src, topics)
    size, read = src.stat().st_size, _data_bytes(ulog)
    if ulog.file_corruption and read < MIN_RECORD_FRACTION * size and not partial and topics is None:
        raise LogFormatError(f"{src}: pyulog found corruption and read only {100 * read / size:.1f} % of the file "
                             f"({read} of {size} bytes) as data samples: nothing converted; pass --partial to convert "
                             "what is readable")

    offset_us, time_source = _utc_offset_us(ulog)

    with ConversionWriter(src, out, "ulog", _format_version(ulog)) as cw:
        w = cw.writer
        # -- gather every stream: (topic, field names, column lists, timestamps [µs])
        streams = []
        gathered, implausible = _streams(ulog, cw.warn)
        for topic, d, names, arrays, ts in gathered:
            schema = {"type": "object", "title": f"ulog.{d.name}",
                      "properties": {k: _json_type(arrays[k].dtype) for k in names}}
            w.add_channel(topic, f"ulog.{d.name}", schema,
                          {"ulog_topic": d.name, "multi_id": str(int(d.multi_id)),
                           "timestamp": "us since boot", "fields": ",".join(names)})
            cols = [arrays[k].tolist() for k in names]
            streams.append((topic, names, cols, ts))
            cw.messages_read += len(ts)
        seen_topic_fields = {topic: tuple(names) for topic, _d, names, _a, _t in gathered}

        logged, params, dropped = _texts(ulog)
        implausible += dropped
        if logged:
            w.add_channel(_LOG_TOPIC, "ulog.logged_message", {
                "type": "object", "title": "ulog.logged_message",
                "properties": {"timestamp": {"type": "integer"}, "level": {"type": "integer"},
                               "level_name": {"type": "string"}, "message": {"type": "string"},
                               "tag": {"type": "integer"}}},
                {"timestamp": "us since boot"})
        if params:
            w.add_channel(_PARAM_TOPIC, "ulog.parameter_change", {
                "type": "object", "title": "ulog.parameter_change",
                "properties": {"timestamp": {"type": "integer"}, "name": {"type": "string"},
                               "value": {"type": ["number", "string"]}}},
                {"timestamp": "us since boot"})
        cw.messages_read += len(logged) + len(params)

        # -- one time order over every stream (stable: file order within a stream)
        all_ts = [s[3] for s in streams] + [np.array([t for t, _ in logged], np.int64),
                                            np.array([t for t, _ in params], np.int64)]
        which = np.concatenate([np.full(len(t), i, np.int64) for i, t in enumerate(all_ts)]) if all_ts else np.zeros(0)
        row = np.concatenate([np.arange(len(t), dtype=np.int64) for t in all_ts]) if all_ts else np.zeros(0)
        ts_all = np.concatenate(all_ts) if all_ts else np.zeros(0, np.int64)
        order = np.lexsort((row, which, ts_all))
        n_streams = len(streams)
        if (ts_all + offset_us < 0).any():
            cw.warn(f"time offset {offset_us} us would make some log times negative; log_time is boot time")
            offset_us, time_source = 0, "boot: the UTC offset gave negative times"
        which_l, row_l, ts_l = which.tolist(), row.tolist(), ts_all.tolist()
        for i in order.tolist():
            s, r, t_us = which_l[i], row_l[i], ts_l[i]
            if s < n_streams:
                topic, names, cols, _ = streams[s]
                msg = dict(zip(names, (c[r] for c in cols)))
            elif s == n_streams:
                topic, msg = _LOG_TOPIC, logged[r][1]
            else:
                topic, msg = _PARAM_TOPIC, params[r][1]
            w.write(topic, msg, log_time_ns=(t_us + offset_us) * 1000, publish_time_ns=t_us * 1000)

        # -- what was lost
        if implausible:
            cw.skip("implausible_timestamp", implausible)
            cw.warn(f"{implausible} samples or messages with a timestamp beyond {MAX_BOOT_US} us since boot (corrupt "
                    "data pyulog read as records) dropped")
        if ulog.dropouts:
            total_ms = sum(int(d.duration) for d in ulog.dropouts)
            cw.skip("dropout_events", len(ulog.dropouts))
            cw.warn(f"{len(ulog.dropouts)} logger dropout(s), {total_ms} ms of data lost on the vehicle "
                    f"(first at boot time {ulog.dropouts[0].timestamp / 1e6:.3f} s)")
        if ulog.file_corruption:
            cw.skip("corrupt_data", 1)
            cw.warn(f"pyulog found corrupt data and resynchronised; the messages in the corrupt part are lost "
                    f"(their number is unknown; {100 * read / size:.1f} % of the file's bytes read as data samples)")
        lines = [ln for ln in said.splitlines() if ln.strip()]
        if lines:
            cw.warn("pyulog: " + lines[0] + (f" (and {len(lines) - 1} more lines)" if len(lines) > 1 else ""))
        want, got = handle.last_read
        if 0 < got < want or (want == 3 and got in (1, 2)):
            cw.skip("truncated_tail", 1)
            cw.warn(f"the file ends inside a message (last {got} of {want} bytes read): the partial message is dropped")

        w.add_metadata("ulog", {
            "file_version": str(getattr(ulog, "_file_version", "")),
            "start_timestamp_us": str(int(ulog.start_timestamp)),
            "last_timestamp_us": str(int(ulog.last_timestamp)),
            "utc_offset_us": str(int(offset_us)), "time_base": time_source,
            "log_time": "timestamp (boot) + utc_offset_us, ns", "publish_time": "timestamp (boot), ns",
            "multi_instance_rule": "/ulog/<topic> when instance 0 is the only one, else /ulog/<topic>/<multi_id>",
            "topics": json.dumps(sorted(seen_topic_fields))})
        w.add_metadata("ulog.info", _info_strings({**ulog.msg_info_dict, **{
            k: v for k, v in (ulog.msg_info_multiple_dict or {}).items()}}))
        w.add_metadata("ulog.parameters", {str(k): str(v) for k, v in ulog.initial_parameters.items()})
        return cw.finish()
