"""What one log file brings to a campaign: its identity (SHA-256 of its bytes) and its test points.

One job, no database: :func:`scan_file` reads a log and returns a :class:`ScannedFile`, or raises
:class:`~livesweep.errors.LivesweepError` (``LogFormatError``) with one line saying why the file
cannot be added (damaged, unreadable, not a log). :mod:`livesweep.campaign.db` writes the result
in one transaction.

Test points come from two places:

* an MCAP recording made by the monitor: its ``/livesweep/test_point`` channel (the closed test
  points, with their verdicts), ``source = "recorded"``;
* any other log livesweep reads (DataFlash ``.bin``, ``.tlog``, converted MCAP, ULog): the
  ArduPilot SystemID runs :func:`livesweep.inspection.inspect_log` recognises from the autopilot's
  texts, ``source = "autopilot"``, verdict None (found offline, not judged).

Times: a recorded test point keeps the monitor's ``start_s``/``end_s`` (the vehicle clock). A
SystemID run found in a DataFlash log is put on the vehicle's boot clock (the log's own ``TimeUS``):
``inspect_log`` gives times relative to the log's first record, and the first record's ``TimeUS``
is read back with the same column reader (:class:`livesweep.convert.dataflash.DataflashLog`,
``gps_time=False``). For other formats the run's times are on the log's own time stamps (first
message time + relative time; ``record["clock"]`` says which clock).
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from livesweep.errors import LivesweepError, LogFormatError

__all__ = ["ScannedFile", "scan_file", "sha256_of", "TEST_POINT_TOPIC"]

#: The monitor's test-point channel in its recordings.
TEST_POINT_TOPIC = "/livesweep/test_point"
#: The monitor's model channel: its ``test_point.conditions`` (the map's conditions averaged over
#: each test point) join the test point's conditions.
MODEL_TOPIC = "/livesweep/model"
_CHUNK = 1 << 20

_WHAT = re.compile(r"magnitude (?P<mag>[-+0-9.eE]+), (?P<f0>[0-9.eE+-]+)-(?P<f1>[0-9.eE+-]+) Hz .*? in "
                   r"(?P<T>[0-9.eE+-]+) s")


def sha256_of(path, chunk: int = _CHUNK) -> str:
    """SHA-256 of a file's bytes (hex), read in chunks (constant memory)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while b := f.read(chunk):
            h.update(b)
    return h.hexdigest()


@dataclass(frozen=True)
class ScannedFile:
    """One log, read: what a campaign stores about it.

    Attributes
    ----------
    path : str
        Absolute path (where it was found; the identity is ``sha256``).
    sha256 : str
    format : str
        ``mcap``, ``dataflash``, ``tlog``, ``ulog``, ...
    vehicle : str or None
        The system id (as text) when the log says, else None.
    date : str or None
        ISO date of the flight when known (not read yet: None).
    test_points : tuple of dict
        Each with ``number, start_s, end_s, swept_input, axis, source, verdict, label,
        conditions (dict name -> float), record (dict)``.
    """

    path: str
    sha256: str
    format: str
    vehicle: str | None = None
    date: str | None = None
    test_points: tuple = field(default_factory=tuple)


def _finite(x):
    return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else float(x)


def _recorded(path: Path) -> list[dict] | None:
    """The monitor's closed test points of an MCAP recording, or None when it has no such channel."""
    from livesweep.telemetry.mcap_read import read_messages, read_summary

    counts = read_summary(path).message_counts
    if TEST_POINT_TOPIC not in counts:
        return None
    measured = {}                 # start_s -> the map's conditions averaged over it (its recorded model)
    if MODEL_TOPIC in counts:
        for m in read_messages(path, topics=MODEL_TOPIC):
            tp = m.data.get("test_point") if isinstance(m.data, dict) else None
            if isinstance(tp, dict) and isinstance(tp.get("conditions"), dict):
                measured[tp.get("start_s")] = {k: float(v) for k, v in tp["conditions"].items()
                                               if isinstance(v, (int, float)) and not isinstance(v, bool)
                                               and math.isfinite(v)}
    out = []
    for m in read_messages(path, topics=TEST_POINT_TOPIC):
        d = m.data
        if d.get("state", "closed") != "closed":
            continue
        inj = d.get("injection") or {}
        cond = {k: float(v) for k, v in inj.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
        for k in ("excited_fraction", "duration_s", "loss_fraction"):
            v = d.get(k)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                cond[k] = float(v)
        cond.update(measured.get(d.get("start_s"), {}))
        axis = d.get("axis")
        out.append({"start_s": _finite(d.get("start_s")), "end_s": _finite(d.get("end_s")),
                    "swept_input": d.get("swept_input"), "axis": axis if isinstance(axis, int) else None,
                    "source": "recorded", "verdict": d.get("verdict"), "label": d.get("label"),
                    "conditions": cond, "record": d})
    return out


def _time_base_s(path: Path, fmt: str) -> tuple[float, str]:
    """The time of the log's first record on its own clock [s], and that clock's name."""
    if fmt == "dataflash":
        from livesweep.convert.dataflash import DataflashLog

        log = DataflashLog(path, gps_time=False)
        firsts = [int(t[0]) for topic in log.topics if (t := log.times_ns(topic)).size]
        return (min(firsts) / 1e9 if firsts else 0.0), "boot (TimeUS)"
    if fmt == "mcap":
        from livesweep.telemetry.mcap_read import read_summary

        return read_summary(path).start_ns / 1e9, "log time"
    return 0.0, "relative to the first message"


def _autopilot(path: Path, fmt: str) -> list[dict]:
    """The SystemID runs the log announces (every one, with ``record["data"]`` saying whether the
    log holds the signals over it)."""
    from livesweep.inspection import inspect_log

    li = inspect_log(path)
    if not li.topics or not li.duration_s > 0:
        # nothing time-stamped: a file cut short before its first data record, or not a log at all
        why = [n for n in li.notes if not n.startswith("read as ")]
        raise LogFormatError(f"{path}: damaged or empty: no time-stamped records"
                             + (f" ({'; '.join(why)})" if why else ""))
    if not li.systemid:
        return []
    t0, clock = _time_base_s(path, fmt)
    out = []
    for r in li.systemid:
        cond = {}
        if (m := _WHAT.search(r.what)) is not None:
            cond = {"magnitude": float(m["mag"]), "f_start_hz": float(m["f0"]), "f_stop_hz": float(m["f1"]),
                    "chirp_s": float(m["T"])}
        end = _finite(r.end_s)
        out.append({"start_s": round(t0 + r.start_s, 6), "end_s": None if end is None else round(t0 + end, 6),
                    "swept_input": None, "axis": r.axis, "source": "autopilot", "verdict": None, "label": None,
                    "conditions": cond,
                    "record": {"what": r.what, "data": bool(r.data), "clock": clock,
                               "relative_start_s": r.start_s, "relative_end_s": end}})
    return out


def scan_file(path) -> ScannedFile:
    """Read one log: its SHA-256, format and test points (see the module docstring).

    Raises
    ------
    LivesweepError
        The file is missing, not a log livesweep reads, or damaged (one line naming it).
    """
    from livesweep.convert.common import sniff_format

    path = Path(path).resolve()
    if not path.is_file():
        raise LogFormatError(f"{path}: no such file")
    digest = sha256_of(path)
    fmt = sniff_format(path)
    if fmt not in ("mcap", "dataflash", "tlog", "ulog"):
        raise LogFormatError(f"{path}: a {fmt} table, not a flight log (convert it to MCAP first)")
    try:
        tps = _recorded(path) if fmt == "mcap" else None
        if tps is None:
            tps = _autopilot(path, fmt)
    except LivesweepError:
        raise
    except (OSError, ValueError, KeyError, IndexError, EOFError, TypeError, RuntimeError) as e:
        raise LogFormatError(f"{path}: unreadable ({type(e).__name__}: {e})") from e
    tps.sort(key=lambda d: (d["start_s"] is None, d["start_s"] or 0.0))
    for k, d in enumerate(tps, 1):
        d["number"] = k
    vehicle = None
    sysids = {d["record"].get("sysid") for d in tps if isinstance(d["record"].get("sysid"), int)}
    if len(sysids) == 1:
        vehicle = str(sysids.pop())
    return ScannedFile(str(path), digest, fmt, vehicle, None, tuple(tps))
