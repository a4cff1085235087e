"""Numeric columns of MCAP logs: :func:`read_fields` and :func:`read_topics_fields` (one pass over the file
for several topics, messages decoded a batch at a time) and :func:`get_field` (a dotted field path).

The contract is in :mod:`livesweep.telemetry.mcap_log` (the facade: import from there).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from mcap.well_known import MessageEncoding

from livesweep.errors import LogFormatError, quote
from livesweep.numeric import NONFINITE_STRINGS
from livesweep.telemetry.mcap_json import _JSON_KINDS, _at, _BadMessage, _json_object
from livesweep.telemetry.mcap_read import _read_metadata
from livesweep.telemetry.mcap_source import _open, _Source
from livesweep.telemetry.mcap_walk import _walk


def get_field(data: Any, field: str) -> tuple[bool, Any]:
    """Look up ``field`` in a message: an exact key first, else a dotted path
    (``"a.b.0"``: dict keys and list indices). Returns (found, value)."""
    if isinstance(data, dict) and field in data:
        return True, data[field]
    cur = data
    for part in field.split("."):
        if isinstance(cur, dict) and part in cur:
            cur = cur[part]
        elif isinstance(cur, list) and part.lstrip("-").isdigit() and -len(cur) <= int(part) < len(cur):
            cur = cur[int(part)]
        else:
            return False, None
    return True, cur


def read_fields(
    path: str | os.PathLike[str],
    topic: str,
    fields: list[str],
    time: str = "log",
    *,
    missing: str = "error",
) -> dict[str, np.ndarray]:
    """Columns of numeric fields of one topic, in log-time order.

    Parameters
    ----------
    path : str or os.PathLike
        MCAP file, finished or unfinished.
    topic : str
        The channel topic.
    fields : list of str
        Field names; an exact key, or a dotted path into nested objects and lists
        (``"servo.0"``). Units are whatever the messages carry.
    time : {"log", "publish"}
        Which MCAP time goes into ``"t_ns"``.
    missing : {"error", "nan"}
        What to do when a message lacks a field: raise (default) or put NaN.

    Returns
    -------
    dict[str, numpy.ndarray]
        One float64 array per field (``null`` and the recorded non-finite strings ``"NaN"``,
        ``"Infinity"``, ``"-Infinity"`` -> NaN, a missing sample; booleans -> 0.0/1.0) and
        ``"t_ns"`` (int64 nanoseconds). Arrays are empty when the topic has no messages.

    Raises
    ------
    LogFormatError
        If the topic is not in the file (the message lists the topics present), a field is
        missing (naming file, topic and field), or a value is not a number.
    """
    if isinstance(fields, str):
        fields = [fields]
    return read_topics_fields(path, {topic: list(fields)}, time, missing=missing)[topic]


def _topic_messages(src: _Source, topics: list[str]) -> dict[str, tuple[list[int], list[int], list[bytes]]]:
    """Per topic: log times, publish times and message bytes, in file order.

    Finished files take the fast walk; anything else goes through the linear scan or mcap's reader.
    """
    chans = {cid: c for cid, c in src.channels.items() if c.topic in topics}
    for c in chans.values():
        if c.message_encoding != MessageEncoding.JSON:
            raise LogFormatError(f"{src.path}: topic {c.topic!r} has message encoding {c.message_encoding!r}, "
                                 "not 'json'")
    raw: dict[str, tuple[list[int], list[int], list[bytes]]] = {t: ([], [], []) for t in topics}
    for cid, log_t, pub_t, data in _walk(src, chans):
        lt, pt, datas = raw[chans[cid].topic]
        lt.append(log_t)
        pt.append(pub_t)
        datas.append(data)
    return raw


#: Messages decoded to Python objects at a time: their columns are kept, the objects dropped (a
#: decoded message takes ten times its bytes, so a long log is never held decoded all at once).
_DECODE_BATCH = 65_536


def _objects(path: Path, topic: str, log_times: list[int], datas: list[bytes], first: int) -> list[dict]:
    """The JSON objects of messages ``first, first + 1, ...`` of a topic: one C-speed decode of them
    all as an array, else message by message, naming the first that is not a JSON object."""
    try:
        objs = json.loads(b"[" + b",".join(datas) + b"]")
    except (ValueError, RecursionError):
        objs = None
    if objs is not None and len(objs) == len(datas) and all(type(o) is dict for o in objs):
        return objs
    out = []
    for k, data in enumerate(datas, first):
        try:
            out.append(_json_object(data))
        except _BadMessage as bad:
            raise LogFormatError(f"{_at(path, topic, k, log_times[k])} {bad}") from None
    return out


def _topic_columns(path: Path, topic: str, fields: list[str], missing: str, log_times: list[int],
                   datas: list[bytes]) -> dict[str, np.ndarray]:
    """float64 columns of ``fields`` over one topic's messages (file order), decoded a batch at a time."""
    where = f"{path}: topic {topic!r}"
    parts: dict[str, list[np.ndarray]] = {f: [np.zeros(0)] for f in fields}
    for a in range(0, len(datas), _DECODE_BATCH):
        objs = _objects(path, topic, log_times, datas[a:a + _DECODE_BATCH], a)
        for f in fields:
            parts[f].append(_column(objs, f, missing, where, log_times, a))
    return {f: np.concatenate(p) for f, p in parts.items()}


_MISSING = object()


def _not_a_number(col: list) -> tuple[int, str] | None:
    """(index, what is wrong) of the first value of ``col`` that is neither null nor a finite
    float64 (numbers beyond the float64 range, strings, arrays, objects); None if there is none."""
    for k, v in enumerate(col):
        if v is None or isinstance(v, bool):
            continue
        if not isinstance(v, (int, float, str)):
            return k, f"is a JSON {_JSON_KINDS.get(type(v), 'object')}, not a number"
        try:
            x = np.float64(v)
        except OverflowError:
            return k, "is a number beyond the float64 range (|x| > 1.8e308)"
        except (TypeError, ValueError):
            return k, "is not a number"
        if np.isinf(x):
            return k, "is a number beyond the float64 range (|x| > 1.8e308)"
    return None


def _column(objs: list, field: str, missing: str, where: str, log_times: list[int], first: int) -> np.ndarray:
    """One float column of ``field`` over ``objs``, messages ``first, first + 1, ...`` of the topic
    (null and recorded non-finite strings -> NaN); errors name the message.

    A value beyond the float64 range (a 400-digit integer, ``1e400``) is an error, not NaN: no
    sensor logs it, so it marks a damaged or crafted message, and the message is named so the
    record can be cropped around it.
    """
    if "." in field:
        col = [v if found else _MISSING for found, v in (get_field(o, field) for o in objs)]
    else:
        col = [o.get(field, _MISSING) for o in objs]
    if col.count(_MISSING):
        k = next(i for i, v in enumerate(col) if v is _MISSING)
        if missing == "error":
            raise LogFormatError(f"{where}: field {field!r} is missing from message {first + k} (log_time "
                                 f"{log_times[first + k]} ns); fields present: {quote(sorted(objs[k]))}")
        col = [math.nan if v is _MISSING else v for v in col]
    if any(type(v) is str for v in col):               # recorded non-finite values: missing samples
        col = [math.nan if type(v) is str and v in NONFINITE_STRINGS else v for v in col]
    try:
        arr = np.array(col, dtype=np.float64)          # None -> nan, bool -> 0/1
    except (TypeError, ValueError, OverflowError):
        arr = None
    if arr is None or arr.ndim != 1 or np.isinf(arr).any():
        bad = _not_a_number(col)
        if bad is None:                  # numpy refused what each value alone passes: name the field
            raise LogFormatError(f"{where}: field {field!r}: the values cannot be read as float64 numbers")
        k, what = bad
        raise LogFormatError(f"{where}: field {field!r} of message {first + k} (log_time {log_times[first + k]} ns) "
                             f"{what}: {quote(col[k])}")
    return arr


def _condition_notes(src: _Source) -> list[str]:
    """Notes for a log that was unfinished (read up to its torn end) or recovered from one."""
    notes = []
    if not src.complete and src.scan is not None:
        stopped = src.scan.tail_error or "no footer"
        notes.append(f"log {src.path} is unfinished (truncated: the writer stopped before closing it); read up to "
                     f"its torn end ({stopped}): {len(src.scan.messages)} messages read")
    rec = _read_metadata(src).get("livesweep.recover")
    if rec is not None:
        lost, unverified = rec.get("messages_lost", "?"), rec.get("messages_unverified", "0")
        notes.append(f"log {src.path} was recovered from {rec.get('source', '?')} (livesweep recover: "
                     f"{rec.get('messages_recovered', '?')} messages kept, {lost} lost"
                     + (f", {unverified} kept from chunks that failed their CRC check" if unverified not in ("0", 0) else "")
                     + ")")
    return notes


def read_topics_fields(
    path: str | os.PathLike[str],
    requests: Mapping[str, list[str]],
    time: str = "log",
    *,
    missing: str = "error",
    notes: list[str] | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """:func:`read_fields` for several topics in one pass over the file.

    Each chunk is decompressed and parsed once whatever the number of topics (reading four
    topics of a sample log this way is about 4x faster than four ``read_fields`` calls).
    Columns of each topic are in log-time order (stable for equal times).

    Parameters
    ----------
    path : str or os.PathLike
    requests : mapping of topic -> list of field names
    time, missing
        As for :func:`read_fields`.
    notes : list of str, optional
        Receives one line per condition of the log a report should mention: unfinished (no
        footer, read up to its torn end; with the number of messages read) or recovered by
        :func:`livesweep.telemetry.mcap_recover.recover` (with the number of messages it kept).

    Returns
    -------
    dict
        ``{topic: {field: float64 array, "t_ns": int64 array}}``.

    Raises
    ------
    LogFormatError
        As :func:`read_fields`; also a message that is not a JSON object, a value beyond the
        float64 range, or a damaged chunk (CRC mismatch), naming file, topic, message and field.
    """
    if time not in ("log", "publish"):
        raise LogFormatError(f"{path}: time must be 'log' or 'publish', got {time!r}")
    if missing not in ("error", "nan"):
        raise LogFormatError(f"{path}: missing must be 'error' or 'nan', got {missing!r}")
    requests = {t: ([f] if isinstance(f, str) else list(f)) for t, f in requests.items()}
    for fields in requests.values():
        if "t_ns" in fields:
            raise LogFormatError(f"{path}: 't_ns' is the time column and cannot be asked for as a field")
    src = _open(path)
    present = src.topics()
    for topic in requests:
        if topic not in present:
            raise LogFormatError(f"{src.path}: topic {topic!r} is not in the log; topics present: {present}")
    gathered = _topic_messages(src, list(requests))
    result = {}
    for topic, fields in requests.items():
        log_t, pub_t, datas = gathered.pop(topic)
        cols = _topic_columns(src.path, topic, fields, missing, log_t, datas)
        order = np.argsort(np.asarray(log_t, dtype=np.int64), kind="stable")
        out = {f: cols[f][order] for f in fields}
        out["t_ns"] = np.asarray(log_t if time == "log" else pub_t, dtype=np.int64)[order]
        result[topic] = out
    if notes is not None:
        notes.extend(_condition_notes(src))
    return result
