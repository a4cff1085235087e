"""``livesweep inspect LOG``: what a log holds, and a channel map that fits it.

Any log livesweep reads: MCAP directly; a MAVLink ``.tlog``, DataFlash ``.bin``, PX4 ``.px4log``
or ULog is converted to a temporary MCAP first (tables need ``--columns``, as for ``convert``).
For every topic: messages, rate, time span and numeric fields with their units (MAVLink's
message definitions, DataFlash FMTU, a column map's units). Then the shipped channel-map
presets whose signals the log holds, best first (the one whose inputs and outputs all have data),
and, for logs from ArduPilot's SystemID mode, the test points its SIDS records mark.

This is an edge module (files); it only reads.
"""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from livesweep.errors import ConfigError, LivesweepError

__all__ = ["TopicInfo", "LogInspection", "inspect_log", "format_inspection"]

#: Fields listed per topic at most (a DataFlash PARM or a ULog topic can have hundreds).
MAX_FIELDS = 40
#: A log shorter than this [s] is said to be too short for a frequency response.
SHORT_S = 10.0


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a log.

    Attributes
    ----------
    topic : str
    messages : int
    rate_hz : float
        Messages per second over the topic's own span (0 for a single message).
    start_s, end_s : float
        First and last receive time [s] relative to the log's first message.
    fields : tuple of (str, str)
        Numeric fields (dotted paths for nested values, ``controls.0``) and their units ("" when
        the log declares none).
    """

    topic: str
    messages: int
    rate_hz: float
    start_s: float
    end_s: float
    fields: tuple = ()


@dataclass(frozen=True)
class LogInspection:
    """What :func:`inspect_log` found.

    Attributes
    ----------
    path : Path
        The log asked about.
    format : str
        ``mcap``, ``tlog``, ``dataflash``, ``ulog``, ...
    duration_s : float
    topics : tuple of TopicInfo
    maps : tuple of (str, int, int)
        Presets whose signals the log holds: ``(name, pairs with data, pairs)``, best first.
    test_points : tuple of (float, float, str)
        ``(start_s, end_s, what)`` from ArduPilot SystemID records, relative to the first message.
    notes : tuple of str
    """

    path: Path
    format: str
    duration_s: float
    topics: tuple
    maps: tuple = ()
    test_points: tuple = ()
    notes: tuple = field(default_factory=tuple)


def _numeric_fields(obj, prefix=""):
    if isinstance(obj, bool):
        return
    if isinstance(obj, (int, float)):
        yield prefix
    elif isinstance(obj, dict):
        for k, v in obj.items():
            yield from _numeric_fields(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(obj, list) and len(obj) <= 32:
        for i, v in enumerate(obj):
            yield from _numeric_fields(v, f"{prefix}.{i}" if prefix else str(i))


def _channel_units(path: Path) -> dict:
    """Topic -> {field: units} from the channels' ``units`` metadata (DataFlash, tables)."""
    from mcap.reader import make_reader

    out = {}
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:          # an unfinished file has no summary: units come from elsewhere
        return out
    for ch in (summary.channels.values() if summary else ()):
        raw = (ch.metadata or {}).get("units")
        if raw:
            try:
                out[ch.topic] = {str(k): str(v) for k, v in json.loads(raw).items()}
            except (ValueError, AttributeError):
                pass
    return out


def _mavlink_units(topic: str) -> dict:
    if not topic.startswith("/mavlink/"):
        return {}
    try:
        from livesweep.telemetry.mavlink_codec import message_class

        cls = message_class(topic.split("/")[2])
    except (ConfigError, IndexError):
        return {}
    return dict(getattr(cls, "fieldunits_by_name", {}) or {})


def _candidate_maps():
    """``(name, ChannelMap)`` of the shipped presets and the packaged XV-15 map (the demo's)."""
    from livesweep.config import read_channel_map
    from livesweep.maps import list_maps, load_map

    out = [(info.name, load_map(info.name), False) for info in list_maps()]
    xv15 = Path(__file__).resolve().parent / "data" / "xv15_channels.toml"
    out.append((str(xv15), read_channel_map(xv15, one_clock=False), True))      # only when all of it fits
    return out


#: ArduCopter presets and the FRAME_CLASS / FRAME_TYPE parameters they are for (AP_Motors: class 1
#: quad, 2 hexa; type 0 plus, 1 X), and the MAVLink HEARTBEAT types (MAV_TYPE) each preset flies.
_FRAMES = {"ardupilot-copter-quad-plus": (1, 0), "ardupilot-copter-quad-x": (1, 1), "ardupilot-copter-hexa-x": (2, 1)}
_MAV_TYPES = {"ardupilot-copter-quad-plus": {2}, "ardupilot-copter-quad-x": {2}, "ardupilot-copter-hexa-x": {13},
              "ardupilot-plane": {1}}


def _vehicle(mcap: Path, topics: dict) -> dict:
    """What the log says about its airframe: ``FRAME_CLASS``, ``FRAME_TYPE`` (parameters) and the
    HEARTBEAT ``type`` of the autopilot (MAVLink component 1), where present."""
    from livesweep.telemetry.mcap_log import read_messages

    found = {}
    if "/mavlink/PARAM_VALUE" in topics:
        for m in read_messages(mcap, ["/mavlink/PARAM_VALUE"]):
            name = str(m.data.get("param_id", "")).strip("\x00 ")
            if name in ("FRAME_CLASS", "FRAME_TYPE"):
                found[name] = int(round(float(m.data.get("param_value", -1))))
    if "/dataflash/PARM" in topics:
        for m in read_messages(mcap, ["/dataflash/PARM"]):
            name = str(m.data.get("Name", "")).strip()
            if name in ("FRAME_CLASS", "FRAME_TYPE"):
                found[name] = int(round(float(m.data.get("Value", -1))))
    if "/mavlink/HEARTBEAT" in topics:
        types = {}
        for m in read_messages(mcap, ["/mavlink/HEARTBEAT"]):
            if m.data.get("autopilot") not in (None, 8):          # 8: MAV_AUTOPILOT_INVALID (a GCS)
                types[m.data.get("type")] = types.get(m.data.get("type"), 0) + 1
        if types:
            found["MAV_TYPE"] = max(types, key=types.get)
    return found


def _contradicted(name: str, vehicle: dict) -> bool:
    if name in _FRAMES and "FRAME_CLASS" in vehicle:
        cls, typ = _FRAMES[name]
        if vehicle["FRAME_CLASS"] != cls or vehicle.get("FRAME_TYPE", typ) != typ:
            return True
    if name in _MAV_TYPES and "MAV_TYPE" in vehicle and vehicle["MAV_TYPE"] not in _MAV_TYPES[name]:
        return True
    return False


def _map_fit(mcap: Path, topics: dict) -> list:
    """Maps ranked by the (output, input) pairs whose signals the log holds and that vary (a
    constant signal, e.g. the unused motors of a hexa mix on a quad, gives no response)."""
    from livesweep.config import RecordSpec
    from livesweep.telemetry.signals import read_signals

    out = []
    vehicle = _vehicle(mcap, topics)
    for name, m, whole in _candidate_maps():
        sp = m.spectral
        if sp is None or _contradicted(name, vehicle):
            continue

        def has(sig):
            s = m.signals.get(sig)
            return s is not None and s.topic in topics and all(op in topics[s.topic] for op in _field_operands(s.field))

        def varies(sig):
            try:
                read_signals(RecordSpec(log=mcap, label="", start_s=None, end_s=None), m.signals, [sig])
            except LivesweepError:
                return False
            return True

        if not all(has(r) for r in sp.references or ()):
            continue
        ins = [i for i in sp.inputs if has(i)]
        outs = [o for o in sp.outputs if has(o)]
        if not ins or not outs:
            continue
        ins, outs = [i for i in ins if varies(i)], [o for o in outs if varies(o)]
        n, total = len(ins) * len(outs), len(sp.inputs) * len(sp.outputs)
        if n and (n == total or not whole):
            out.append((name, n, total))
    out.sort(key=lambda x: (-x[1] / x[2], -x[1], x[0]))
    return out


def _field_operands(text: str) -> list:
    """The field paths an expression reads (``servo2_raw - servo1_raw`` -> both)."""
    from livesweep.telemetry.extract import parse_field

    try:
        expr = parse_field(text, "inspect")
    except ConfigError:
        return [text]
    return list(expr.operands)


def _sysid_test_points(mcap: Path, t0_ns: int, topics: dict) -> list:
    """ArduPilot SystemID: each SIDS record starts a test point (axis, magnitude, band, duration)."""
    from livesweep.telemetry.mcap_log import read_messages

    topic = "/dataflash/SIDS"
    if topic not in topics:
        return []
    out = []
    for m in read_messages(mcap, [topic]):
        d = m.data
        start = (m.log_time_ns - t0_ns) / 1e9
        dur = float(d.get("TR", 0) or 0) + float(d.get("TC", 0) or 0) + float(d.get("TFO", 0) or 0)
        what = (f"SystemID axis {d.get('Ax')}, magnitude {d.get('Mag')}, {d.get('FSt')}-{d.get('FSp')} Hz")
        out.append((start, start + dur if dur else math.nan, what))
    return out


def inspect_log(path, *, columns=None) -> LogInspection:
    """Read a log and describe it (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The log.
    columns : str or Path, optional
        Column map, for tables (``.npy``, ``.mat``, Parquet, text).

    Raises
    ------
    LogFormatError, ConfigError
        A file that is not a log livesweep reads, or a table without a column map (one line
        naming the file and what to give).
    """
    from livesweep.convert.common import sniff_format
    from livesweep.telemetry.mcap_log import read_messages, read_summary

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such file")
    fmt = sniff_format(path)
    notes = []
    with tempfile.TemporaryDirectory(prefix="livesweep-inspect-") as tmp:
        mcap = path
        if fmt != "mcap":
            from livesweep.convert import convert

            options = {"column_map": columns} if columns else {}
            try:
                result = convert(path, Path(tmp) / "log.mcap", **options)
            except ConfigError as exc:
                if columns is None and "column" in str(exc).lower():
                    raise ConfigError(f"{path}: a {fmt} table: give its column map with --columns MAP.toml "
                                      f"(as for livesweep convert): {exc}") from None
                raise
            mcap = Path(tmp) / "log.mcap"
            notes.append(f"read as {fmt} and converted in memory ({_counts(result)})")
        s = read_summary(mcap)
        if not s.complete:
            notes.append(f"unfinished recording ({s.tail_error or 'no footer'}): `livesweep recover {path}` "
                         "makes a finished copy")
        units = _channel_units(mcap)
        infos, fields_by_topic = [], {}
        other = {}
        for topic, n in sorted(s.message_counts.items()):
            if n == 0:
                continue
            first = last = None
            sample = None
            try:
                for m in read_messages(mcap, [topic]):
                    if first is None:
                        first, sample = m.log_time_ns, m.data
                    last = m.log_time_ns
            except LivesweepError as exc:            # a channel livesweep does not decode (ROS 2 CDR, protobuf)
                other[topic] = (n, str(exc).split(": ")[-1] if "encoding" not in str(exc) else
                                str(exc)[str(exc).find("message encoding"):].split(";")[0])
                continue
            names = list(_numeric_fields(sample))[:MAX_FIELDS] if isinstance(sample, dict) else []
            fields_by_topic[topic] = set(_numeric_fields(sample)) if isinstance(sample, dict) else set()
            u = {**_mavlink_units(topic), **units.get(topic, {})}
            span = (last - first) / 1e9
            infos.append(TopicInfo(topic, n, (n - 1) / span if span > 0 else 0.0, (first - s.start_ns) / 1e9,
                                   (last - s.start_ns) / 1e9, tuple((f, u.get(f, "")) for f in names)))
        if other:
            notes.append(f"{len(other)} topic(s) not in JSON, which livesweep does not read: "
                         + ", ".join(f"{t} ({n} messages, {why})" for t, (n, why) in sorted(other.items())[:8])
                         + (" ..." if len(other) > 8 else ""))
        maps = _map_fit(mcap, fields_by_topic)
        tps = _sysid_test_points(mcap, s.start_ns, fields_by_topic)
    return LogInspection(path, fmt, s.duration_s, tuple(infos), tuple(maps), tuple(tps), tuple(notes))


def _counts(result) -> str:
    return f"{result.messages_written} messages of {result.messages_read} read"


def format_inspection(ins: LogInspection) -> str:
    """The text ``livesweep inspect`` prints."""
    lines = [f"{ins.path}: {ins.format}, {ins.duration_s:.1f} s, {len(ins.topics)} topics livesweep reads"]
    lines += [f"  note: {n}" for n in ins.notes]
    for t in ins.topics:
        lines.append(f"  {t.topic}: {t.messages} messages, {t.rate_hz:.1f} Hz, {t.start_s:.1f}-{t.end_s:.1f} s")
        if t.fields:
            lines.append("      " + ", ".join(f"{f} [{u}]" if u else f for f, u in t.fields))
    if ins.test_points:
        lines.append("test points:")
        lines += [f"  {a:.1f}-{b:.1f} s: {what}" if math.isfinite(b) else f"  from {a:.1f} s: {what}"
                  for a, b, what in ins.test_points]
    if ins.maps and ins.duration_s < SHORT_S:
        lines.append(f"only {ins.duration_s:.1f} s of data: too short for a frequency response (a sweep's lowest "
                     "frequency needs windows of tens of seconds)")
    if ins.maps:
        best = ins.maps[0][0]
        lines.append("channel-map presets whose signals this log holds (pairs with data / pairs):")
        lines += [f"  {name}: {n}/{total}" for name, n, total in ins.maps]
        how = (f"livesweep replay {ins.path} --map {best}" if ins.format == "mcap" else
               f"livesweep convert {ins.path} --out LOG.mcap && livesweep replay LOG.mcap --map {best}")
        lines.append(f"suggested: {how}")
        lines.append(f"  a case for identify: livesweep new-case {ins.path} --map {best} --out CASE.toml")
    else:
        lines.append("no shipped channel map fits this log: write one ([signals], [spectral]) from the fields above")
    return "\n".join(lines)
