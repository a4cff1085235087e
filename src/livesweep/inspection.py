"""``livesweep inspect LOG``: what a log holds, the channel maps that fit it, its SystemID test points.

Any log livesweep reads, in one pass: a MAVLink ``.tlog`` frame by frame (no conversion); an MCAP
file directly (JSON channels decoded, other encodings counted and their fields listed from the
schema when it is a ROS message definition); a DataFlash ``.bin``, PX4 ``.px4log`` or ULog read
column-wise (only the records the SystemID texts and the vehicle's parameters need become Python
records); a table (it needs ``--columns``, as for ``convert``) converted to a temporary MCAP first.
For every topic: messages, rate, time span and numeric fields with their units (MAVLink's message
definitions, DataFlash FMTU, a column map's units). Then:

* **the shipped channel-map presets that fit**, best first: every signal's messages are there and
  vary, the vehicle is the one the map is made for (its ``[map.vehicle]`` against the log's
  parameters, "Frame:" text and HEARTBEAT type), and every signal arrives fast enough for the band
  the map's monitor judges: 2.5 x its top frequency (the band a SystemID run was told to sweep,
  else the map's; never above 0.8 of the map's grid Nyquist frequency, where the judged band ends).
  A signal's rate is the median of its samples per second on its own clock (its stamp field, the
  vehicle's time, when the map gives one: a ground station's bursty receive times do not count),
  over the SystemID runs when there are any. A preset whose signals are there but too slow is
  listed, in one line, with each slow message's rate against the rate needed;
* for an ArduCopter DataFlash log, the presets for its telemetry as ``livesweep stream`` sends it
  (the live path), at the stream rate suggested;
* **the ArduPilot SystemID test points**: each start ("SystemID Starting: axis=N" in STATUSTEXT or
  MSG, SIDS) with its axis, band and magnitude (from SIDS or the ``SID_*`` parameters) and its end
  ("SystemID Finished", or the mode leaving SYSTEMID). A test point is listed when the signals a
  preset needs for it (the input its axis sweeps and the outputs required with it) cover it at the
  rate its band needs; the others, announced by the autopilot but without such data (a log
  filtered around one run keeps the others' texts), are named in one line.

Progress: :func:`inspect_log` reports how far it has read through ``progress``;
:func:`stderr_progress` writes that to stderr for the command line.

This is an edge module (files); it only reads.
"""

from __future__ import annotations

import json
import math
import re
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from livesweep.errors import ConfigError
from livesweep.monitor.systemid import SAME_START_S, SystemIdWatch, better_injection
from livesweep.spectral.verdict import NYQUIST_FRACTION

__all__ = ["TopicInfo", "MapFit", "SystemIdRun", "LogInspection", "inspect_log", "format_inspection",
           "stderr_progress", "STREAM_RATE_HZ"]

#: Fields listed per topic at most (a DataFlash PARM or a ULog topic can have hundreds).
MAX_FIELDS = 40
#: A log shorter than this [s] is said to be too short for a frequency response.
SHORT_S = 10.0
#: A signal must arrive at this many times the top frequency it must show (2.5: the verdict judges
#: a signal up to NYQUIST_FRACTION = 0.8 of its Nyquist frequency, and one sampled slower aliases
#: what lies above).
RATE_PER_TOP_FREQUENCY = 2.0 / NYQUIST_FRACTION
#: The stream rate suggested for a DataFlash log's telemetry (``livesweep stream --rate-hz``; a
#: telemetry stream rate such as SRx_EXTRA1 = 50) [Hz].
STREAM_RATE_HZ = 50.0
#: Share of a SystemID test point (receive time) a signal's samples must span for it to count as
#: covered.
COVER_FRACTION = 0.9
#: What ``livesweep stream`` makes of a DataFlash log: MAVLink topic -> the DataFlash records it comes
#: from (its rate is the slowest of them, capped at the stream rate); PID_TUNING per axis.
_STREAM_OF_DATAFLASH = {"/mavlink/ATTITUDE": ("/dataflash/ATT", "/dataflash/RATE"),
                        "/mavlink/SERVO_OUTPUT_RAW": ("/dataflash/RCOU",),
                        "/mavlink/RAW_IMU": ("/dataflash/IMU",), "/mavlink/HEARTBEAT": (),
                        "/mavlink/STATUSTEXT": ("/dataflash/MSG",), "/mavlink/PARAM_VALUE": ("/dataflash/PARM",)}
_PID_RECORDS = {1: "/dataflash/PIDR", 2: "/dataflash/PIDP", 3: "/dataflash/PIDY"}
#: Topics whose every message the vehicle checks and the SystemID watch read (in file order).
_VEHICLE_TOPICS = frozenset(("/mavlink/PARAM_VALUE", "/dataflash/PARM", "/dataflash/SIDS", "/mavlink/STATUSTEXT",
                             "/dataflash/MSG", "/mavlink/HEARTBEAT", "/dataflash/MODE"))
#: A stamp that steps back by more than this [s] starts a new stretch of its clock (a reboot, a wrap).
_CLOCK_BREAK_S = 1.0
#: SystemID runs without data named at most in their line.
_MAX_NAMED = 8
#: Messages between two progress reports while reading an MCAP file.
_PROGRESS_MESSAGES = 50_000
#: How an MCAP channel's messages are read after its first: counted only (not JSON), read one by
#: one (:meth:`_Stats.take`), counted with their system id (:meth:`_Stats.tick`), counted as
#: records of no system (JSON without ``sysid``, as its first message).
_COUNT, _READ, _TICK, _PLAIN = 0, 1, 2, 3
#: A recorder's JSON record starts with its system id: read without decoding the message.
_SYSID_PREFIX = re.compile(rb'\{"sysid":\s*(-?\d+)\s*[,}]')


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
        the log declares none). For a topic livesweep does not decode (``decoded`` False): every
        field its schema declares and the schema's type (``stamp.sec``, ``"int32"``).
    encoding : str
        The message encoding (``json``; ``cdr``, ``protobuf`` ... in an MCAP file).
    decoded : bool
        livesweep reads the messages' values (False: counted, not decoded; no map can use them).
    fields_note : str
        Why the fields cannot be listed ("" when they are, or when the topic simply has none).
    """

    topic: str
    messages: int
    rate_hz: float
    start_s: float
    end_s: float
    fields: tuple = ()
    encoding: str = "json"
    decoded: bool = True
    fields_note: str = ""


@dataclass(frozen=True)
class MapFit:
    """How a preset fits the log.

    Attributes
    ----------
    name : str
    pairs, total : int
        (output, input) pairs whose signals the log holds and vary, of all the map's pairs.
    why : str
        Why it does not fit ("" when it does): another vehicle, signals too slow for the band
        (each slow message with its rate [Hz] and the rate needed [Hz]).
    live : bool
        A preset for the log's telemetry as ``livesweep stream`` sends it (a DataFlash log).
    """

    name: str
    pairs: int
    total: int
    why: str = ""
    live: bool = False

    @property
    def fits(self) -> bool:
        return not self.why


@dataclass(frozen=True)
class SystemIdRun:
    """One ArduPilot SystemID run the log announces.

    Attributes
    ----------
    start_s, end_s : float
        Relative to the log's first message [s]; ``end_s`` NaN when the log does not say.
    axis : int or None
    what : str
        Axis, band and magnitude in words.
    data : bool
        The signals a fitting preset needs for this run (its swept input and required outputs)
        cover it at the rate its band needs; False for a run the log only announces (a log
        filtered around one run keeps the others' texts).
    """

    start_s: float
    end_s: float
    axis: int | None
    what: str
    data: bool = True


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
        Presets that fit: ``(name, pairs with data, pairs)``, best first.
    test_points : tuple of (float, float, str)
        ``(start_s, end_s, what)`` of the SystemID runs with data (``SystemIdRun.data``), relative
        to the first message [s].
    notes : tuple of str
    fits : tuple of MapFit
        Every preset that holds signals of the log, fitting or not (with why).
    live_maps : tuple of str
        For a DataFlash log: the presets for its telemetry as ``livesweep stream --rate-hz``
        :data:`STREAM_RATE_HZ` sends it, best first.
    systemid : tuple of SystemIdRun
        Every SystemID run the log announces, with or without data.
    """

    path: Path
    format: str
    duration_s: float
    topics: tuple
    maps: tuple = ()
    test_points: tuple = ()
    notes: tuple = field(default_factory=tuple)
    fits: tuple = ()
    live_maps: tuple = ()
    systemid: tuple = ()


# ------------------------------------------------------------------------------------- progress


def stderr_progress(path, *, stream=None, after_s: float = 1.0):
    """A ``progress`` for :func:`inspect_log` that writes how far it has read to stderr.

    Nothing for the first ``after_s``; then, on a terminal, one line rewritten in place at most
    four times a second (cleared at the end); otherwise a line every 5 s at most.
    ``reading flight.bin: 40 % (3.2 of 8.0 MB)``.

    Parameters
    ----------
    path : str or Path
        The log (its name is shown).
    stream : file, optional
        Default ``sys.stderr``.
    after_s : float
        Quiet time [s] before the first report.
    """
    out = sys.stderr if stream is None else stream
    tty = bool(getattr(out, "isatty", lambda: False)())
    every = 0.25 if tty else 5.0
    t0 = time.monotonic()
    state = {"next": t0 + after_s, "shown": False}
    name = Path(path).name

    def report(done: int, total: int, unit: str) -> None:
        now = time.monotonic()
        end = total > 0 and done >= total
        if end:
            if tty and state["shown"]:
                out.write("\r\033[K")
                out.flush()
            return
        if now < state["next"]:
            return
        state["next"] = now + every
        if unit == "bytes":
            amount = f"{done / 1e6:.1f} of {total / 1e6:.1f} MB"
        else:
            amount = f"{done} of {total} {unit}"
        pct = f"{100 * done / total:.0f} % " if total > 0 else ""
        text = f"reading {name}: {pct}({amount})"
        out.write(("\r\033[K" + text) if tty else text + "\n")
        out.flush()
        state["shown"] = True

    return report


# ------------------------------------------------------------------------------------- fields


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


def _mavlink_units(topic: str) -> dict:
    if not topic.startswith("/mavlink/"):
        return {}
    try:
        from livesweep.telemetry.mavlink_codec import message_class

        cls = message_class(topic.split("/")[2])
    except (ConfigError, IndexError):
        return {}
    return dict(getattr(cls, "fieldunits_by_name", {}) or {})


def _channel_units(metadata) -> dict:
    """``{field: unit}`` from a channel's ``units`` metadata (DataFlash, tables); {} without."""
    raw = (metadata or {}).get("units")
    if raw:
        try:
            return {str(k): str(v) for k, v in json.loads(raw).items()}
        except (ValueError, AttributeError):
            pass
    return {}


#: ROS message definition types that are one number each (``bool`` is left out, as in JSON messages).
_ROS_NUMBERS = frozenset(("byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
                          "uint32", "int64", "uint64"))
_ROS_PRIMITIVES = _ROS_NUMBERS | {"bool", "string", "wstring"}
#: ROS 1 built-in types that are messages of two fields.
_ROS1_TIME = {"time": (("secs", "uint32"), ("nsecs", "uint32")), "duration": (("secs", "int32"), ("nsecs", "int32"))}
_ROS_TYPE = re.compile(r"^([A-Za-z_][\w/]*)(?:<=\d+)?(\[(?:<=)?(\d*)\])?$")


def _ros_fields(schema_name: str, text: str) -> tuple[list[tuple[str, str]] | None, str]:
    """Every field of a ``ros2msg`` / ``ros1msg`` definition, flattened (``stamp.sec``), with its
    type; ``(None, why)`` when the text cannot be read as one message definition."""
    if re.search(r"^---\s*$", text, flags=re.M):
        return None, "its schema is a service or action definition, not the message's own fields"
    sections = re.split(r"^={20,}\s*$", text, flags=re.M)
    defs: dict[str, str] = {}
    for sec in sections[1:]:
        body = sec.lstrip("\n")
        head, _, rest = body.partition("\n")
        if head.startswith("MSG:"):
            full = head[4:].strip()
            pkg, _, short = full.rpartition("/")
            for key in (full, f"{pkg.split('/')[0]}/msg/{short}", f"{pkg.split('/')[0]}/{short}"):
                defs.setdefault(key, rest)
    pkg = schema_name.split("/")[0] if "/" in schema_name else ""
    out: list[tuple[str, str]] = []

    def walk(body: str, prefix: str, package: str, depth: int) -> None:
        for line in body.splitlines():
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            parts = line.split()
            if len(parts) < 2 or "=" in parts[1] or "=" in parts[0]:
                continue                                   # a constant (NAME=value), not a field
            typ, name = parts[0], parts[1]
            m = _ROS_TYPE.match(typ)
            path = f"{prefix}.{name}" if prefix else name
            if m is None:
                out.append((path, typ))
                continue
            base, array = m.group(1), m.group(2)
            if array or base in _ROS_PRIMITIVES:
                out.append((path, typ))
                continue
            if base in _ROS1_TIME:
                out.extend((f"{path}.{n}", t) for n, t in _ROS1_TIME[base])
                continue
            own = base if "/" in base else f"{package}/{base}"
            full = own if own in defs else base.replace("/msg/", "/") if base.replace("/msg/", "/") in defs else ""
            if base == "Header" and not full:
                full = "std_msgs/Header" if "std_msgs/Header" in defs else ""
            if not full or depth > 8:
                out.append((path, typ))
                continue
            walk(defs[full], path, full.split("/")[0], depth + 1)

    walk(sections[0], "", pkg, 0)
    return out, ""


def _schema_fields(encoding: str, schema) -> tuple[tuple, str]:
    """``(fields, why not)`` of a channel livesweep does not decode, from its schema."""
    what = f"{encoding} messages" + (f" with a {schema.encoding} schema" if schema is not None and schema.encoding
                                     else " without a schema")
    if schema is None or schema.encoding not in ("ros2msg", "ros1msg"):
        return (), f"{what}: livesweep cannot list their fields"
    try:
        text = bytes(schema.data).decode("utf-8")
    except UnicodeDecodeError:
        return (), f"{what}: the schema is not UTF-8 text, its fields cannot be listed"
    fields, why = _ros_fields(schema.name, text)
    if fields is None:
        return (), f"{what} ({schema.name}): {why}, so they cannot be listed"
    return tuple(fields), ""


# ------------------------------------------------------------------------------------- the pass


def _candidate_maps():
    """``(name, ChannelMap, whole)`` of the shipped presets and the packaged XV-15 map (the demo's,
    which counts only when all of it fits)."""
    from livesweep.config import read_channel_map
    from livesweep.maps import list_maps, load_map

    out = [(info.name, load_map(info.name), False) for info in list_maps()]
    xv15 = Path(__file__).resolve().parent / "data" / "xv15_channels.toml"
    out.append((str(xv15), read_channel_map(xv15, one_clock=False), True))
    return out


def _key(spec) -> str:
    return f"{spec.topic}|{spec.field}|{spec.where}|{spec.sysid}|{spec.compid}|{spec.stamp}|{spec.stamp_topic}"


class _Signal:
    """The samples one signal of the maps has in the log: receive time [ns], its stamp [s] (NaN
    without one), the system that sent it (-1: none said), and the range of its values."""

    __slots__ = ("extractor", "spec", "n", "lo", "hi", "_rx", "_stamp", "_sysid", "_blocks", "_arrays")

    def __init__(self, spec):
        from livesweep.telemetry.extract import compile_signal

        self.spec = spec
        self.extractor = compile_signal(spec)
        self.n = 0
        self.lo, self.hi = math.inf, -math.inf
        self._rx: list[int] = []
        self._stamp: list[float] = []
        self._sysid: list[int] = []
        self._blocks: list[tuple] = []
        self._arrays = None

    def add(self, rx_ns: int, value: float, stamp: float, sysid: int) -> None:
        self.n += 1
        if value < self.lo:
            self.lo = value
        if value > self.hi:
            self.hi = value
        self._rx.append(rx_ns)
        self._stamp.append(stamp)
        self._sysid.append(sysid)

    def add_block(self, rx_ns: np.ndarray, values: np.ndarray, stamps: np.ndarray) -> None:
        if not rx_ns.size:
            return
        self.n += int(rx_ns.size)
        self.lo = min(self.lo, float(values.min()))
        self.hi = max(self.hi, float(values.max()))
        self._blocks.append((rx_ns.astype(np.int64), stamps.astype(np.float64),
                             np.full(rx_ns.size, -1, dtype=np.int64)))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(receive ns, stamp s, sysid)`` of every sample, in the order taken."""
        if self._arrays is None:
            parts = [(np.asarray(self._rx, dtype=np.int64), np.asarray(self._stamp, dtype=np.float64),
                      np.asarray(self._sysid, dtype=np.int64))] + self._blocks
            self._arrays = tuple(np.concatenate([p[k] for p in parts]) for k in range(3))
        return self._arrays


class _Stats:
    """Per-topic and per-signal statistics gathered in one pass over a log."""

    def __init__(self, maps):
        from livesweep.monitor.vehicle import VehicleInfo

        self.topics: dict[str, list] = {}            # topic -> [n, earliest ns, latest ns, first data]
        self.meta: dict[str, tuple] = {}             # topic -> (encoding, decoded, schema fields, why not, units)
        self._vehicles: dict = {}                    # sysid -> VehicleInfo: the log's main system is judged
        self._frames_by_system: dict = {}            # sysid -> frames (the main system sends the most)
        self._new_vehicle = VehicleInfo
        self.runs: list[dict] = []                   # SystemID runs: start ns, end ns, axis, injection
        self._watches: dict = {}                     # sysid -> SystemIdWatch
        self.t_end: int | None = None
        self.signals: dict[str, _Signal] = {}
        self.by_topic: dict[str, list[_Signal]] = {}
        self._stamp_sources: dict[str, set] = {}    # topic -> its fields other signals borrow their stamp from
        self._last_stamp: dict[tuple, tuple] = {}    # (sysid, topic, field) -> (receive ns, value)
        for _name, m, _ in maps:
            for spec in m.signals.values():
                key = _key(spec)
                if key not in self.signals:
                    self.signals[key] = sig = _Signal(spec)
                    self.by_topic.setdefault(spec.topic, []).append(sig)
                    if spec.stamp and spec.stamp_topic:
                        self._stamp_sources.setdefault(spec.stamp_topic, set()).add(spec.stamp)
        #: topic -> [(selection or None, a spec giving the stamp, the signals)]
        self._groups: dict[str, list] = {}
        for topic, sigs in self.by_topic.items():
            groups: dict[tuple, tuple] = {}
            for sig in sigs:
                sp, ex = sig.spec, sig.extractor
                g = (ex.conditions, sp.stamp, sp.stamp_scale, sp.stamp_topic)
                if g not in groups:
                    groups[g] = (ex if ex.conditions else None, sp, [])
                groups[g][2].append(sig)
            self._groups[topic] = list(groups.values())

    def wants_records(self, topic: str, columns: bool = False) -> bool:
        """Whether every message of ``topic`` must be taken as a record (:meth:`take`, in file
        order): the vehicle's and the SystemID watch's, the stamps signals borrow, and (unless the
        reader gives ``columns``, :meth:`take_columns`) the signals'."""
        return (topic in _VEHICLE_TOPICS or topic in self._stamp_sources
                or (not columns and topic in self.by_topic))

    def _span(self, topic: str, first_ns: int, last_ns: int, n: int, data) -> None:
        st = self.topics.get(topic)
        if st is None:
            self.topics[topic] = [n, first_ns, last_ns, data]
        else:
            st[0] += n
            if last_ns > st[2]:
                st[2] = last_ns
            if first_ns < st[1]:
                st[1] = first_ns
        if self.t_end is None or last_ns > self.t_end:
            self.t_end = last_ns

    def _count(self, topic: str, t_ns: int, data) -> None:
        """``topic``'s count and time span (``data``: its first message's, to list its fields)."""
        st = self.topics.get(topic)
        if st is None:
            self.topics[topic] = [1, t_ns, t_ns, data]
        else:                                    # the span: file order need not be time order
            st[0] += 1
            if t_ns > st[2]:
                st[2] = t_ns
            elif t_ns < st[1]:
                st[1] = t_ns
        if self.t_end is None or t_ns > self.t_end:
            self.t_end = t_ns

    def tick(self, topic: str, t_ns: int, sysid=None, data=None, system: bool = True) -> None:
        """One message of ``topic`` counted, not read (``data``: the first one's, to list its
        fields); ``system``: counted for system ``sysid`` (False: a message that is no record)."""
        self._count(topic, t_ns, data)
        if system:
            self._frames_by_system[sysid] = self._frames_by_system.get(sysid, 0) + 1

    def take(self, topic: str, t_ns: int, data) -> None:
        """One message of ``topic`` read: counted, its signals' samples, the vehicle and SystemID."""
        self._count(topic, t_ns, data)
        if not isinstance(data, dict):
            return
        sysid = data.get("sysid")
        self._frames_by_system[sysid] = self._frames_by_system.get(sysid, 0) + 1
        borrowed = self._stamp_sources.get(topic)
        if borrowed:
            for f in borrowed:
                v = data.get(f)
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    self._last_stamp[(sysid, topic, f)] = (t_ns, v)
        groups = self._groups.get(topic)
        if groups:
            sys_code = sysid if isinstance(sysid, int) and not isinstance(sysid, bool) else -1
            for selector, spec, sigs in groups:          # signals that take the same messages and stamp
                if selector is not None and not selector.selects(data):
                    continue
                stamp = self._stamp_of(spec, data, sysid, t_ns)
                for s in sigs:
                    v, problem = s.extractor.value(data)
                    if problem is None:
                        s.add(t_ns, v, stamp, sys_code)
        if topic in _VEHICLE_TOPICS:
            self._systemid(topic, t_ns, data)

    def _stamp_of(self, spec, data: dict, sysid, t_ns: int) -> float:
        """The sample's stamp [s] (its own field, or the latest of ``stamp_topic`` received at most
        ``BORROW_WITHIN_S`` before), NaN without one."""
        if not spec.stamp:
            return math.nan
        if spec.stamp_topic:
            from livesweep.telemetry.align import BORROW_WITHIN_S

            got = self._last_stamp.get((sysid, spec.stamp_topic, spec.stamp))
            if got is None or t_ns - got[0] > BORROW_WITHIN_S * 1e9:
                return math.nan
            raw = got[1]
        else:
            raw = data.get(spec.stamp)
            if not isinstance(raw, (int, float)) or isinstance(raw, bool):
                return math.nan
        return float(raw) * spec.stamp_scale

    def take_columns(self, topic: str, times_ns: np.ndarray, first, column) -> None:
        """Every message of ``topic`` at once: ``times_ns`` (file order), the first message's data,
        and ``column(field)``, the float64 values of one field (None when the topic lacks it)."""
        if not times_ns.size:
            return
        self._span(topic, int(times_ns.min()), int(times_ns.max()), int(times_ns.size), first)
        sysid = first.get("sysid") if isinstance(first, dict) else None
        self._frames_by_system[sysid] = self._frames_by_system.get(sysid, 0) + int(times_ns.size)
        for s in self.by_topic.get(topic, ()):
            ex = s.extractor
            cols = {}
            for f in ex.read_fields:
                c = column(f)
                if c is not None:
                    cols[f] = c
            if any(op not in cols for op in ex.expression.operands) or any(k not in cols for k, _ in ex.conditions):
                continue                                  # a field the topic lacks: no samples
            values = ex.values(cols)
            ok = np.isfinite(values)
            mask = ex.select_columns(cols)
            if mask is not None:
                ok &= mask
            spec = s.spec
            if spec.stamp and not spec.stamp_topic and spec.stamp in cols:
                stamps = cols[spec.stamp][ok] * spec.stamp_scale
            else:
                stamps = np.full(int(ok.sum()), np.nan)
            s.add_block(times_ns[ok], values[ok], stamps)

    def _main(self):
        """The system id that sent the most messages (a tlog may hold a ground station's too)."""
        return max(self._frames_by_system, key=self._frames_by_system.get) if self._frames_by_system else None

    @property
    def vehicle(self):
        """What the main system said of itself."""
        return self._vehicles.get(self._main()) or self._new_vehicle()

    def _systemid(self, topic: str, t_ns: int, d: dict) -> None:
        sysid = d.get("sysid")
        v = self._vehicles.get(sysid)
        if v is None:
            v = self._vehicles[sysid] = self._new_vehicle()
            self._watches[sysid] = SystemIdWatch()
        v.take(_Frame(topic, d))
        ev = self._watches[sysid].feed(topic, d, v)
        if ev is None or (sysid is not None and sysid != self._main()):
            return                               # SystemID runs of the main system only
        last = self.runs[-1] if self.runs and self.runs[-1]["end"] is None else None
        if ev.action == "end":
            if last is not None:
                last["end"] = t_ns
        elif last is not None and abs(t_ns - last["start"]) < SAME_START_S * 1e9:    # the same start, said again
            last["axis"] = ev.axis if last["axis"] is None else last["axis"]
            last["injection"] = better_injection(last["injection"], ev.injection)
        else:
            self.runs.append({"start": t_ns, "end": None, "axis": ev.axis, "injection": ev.injection})

    def signal(self, spec) -> _Signal:
        return self.signals[_key(spec)]

    def samples(self, sig: _Signal) -> tuple[np.ndarray, np.ndarray]:
        """``(receive ns, stamp s)`` of a signal's samples from the main system (every sample when
        the signal names its own system, or the main system sent none)."""
        rx, stamp, sysid = sig.arrays()
        main = self._main()
        if sig.spec.sysid is None and isinstance(main, int) and not isinstance(main, bool):
            mine = sysid == main
            if mine.any() and not mine.all():
                return rx[mine], stamp[mine]
        return rx, stamp


@dataclass(frozen=True)
class _Frame:
    topic: str
    data: dict


# ------------------------------------------------------------------------------------- readers


def _read_tlog(path: Path, stats: _Stats, notes: list, progress) -> None:
    """Every frame of a tlog, as :class:`TlogSource` frames and checks it. A message type that no
    map, vehicle check or SystemID watch reads is counted from its pymavlink message (its first one
    read as a record, for its fields), without building a record per frame."""
    from livesweep.telemetry.mavlink_in import TlogSource

    size = path.stat().st_size
    src = TlogSource(path)
    take, tick = stats.take, stats.tick
    dec = getattr(src, "_dec", None)     # the source's decoder: the checks and counts poll() applies to a frame

    def report() -> None:
        c = src.counts
        progress(min(size, 8 * c.get("records", 0) + c.get("bytes", 0) + c.get("garbage_bytes", 0)), size, "bytes")

    try:
        if dec is None or not hasattr(dec, "handle"):
            while not src.finished:
                for f in src.poll(max_frames=20_000):
                    take(f.topic, f.receive_ns, f.data)
                if progress is not None:
                    report()
        else:
            counted: dict[str, str] = {}         # message type -> topic, for the types only counted
            frames: list = []
            handle = dec.handle
            for k, (ts, _frame, msg) in enumerate(src.raw_records()):
                mtype = msg.get_type()
                topic = counted.get(mtype)
                if topic is not None:
                    tick(topic, ts * 1000, msg.get_srcSystem())
                else:
                    handle(msg, ts * 1000, frames)
                    for f in frames:
                        take(f.topic, f.receive_ns, f.data)
                        if not stats.wants_records(f.topic):
                            counted[mtype] = f.topic
                    frames.clear()
                if progress is not None and k % 20_000 == 0:
                    report()
    finally:
        c = src.counts
        if c.get("bad_prefix_or_garbage") or c.get("bad_crc"):
            notes.append(f"{c.get('bad_crc', 0)} frames with a bad CRC and {c.get('bad_prefix_or_garbage', 0)} "
                         "runs of garbage skipped")
        if c.get("clock_implausible") or c.get("clock_unrepresentable"):
            notes.append(f"{c.get('clock_implausible', 0) + c.get('clock_unrepresentable', 0)} time stamps that do "
                         "not follow their stream's clock (a monitor would record those frames with their receive "
                         "time)")
        src.close()


def _read_dataflash(path: Path, stats: _Stats, notes: list, progress) -> None:
    from livesweep.convert.dataflash import DataflashLog

    log = DataflashLog(path, progress=progress)
    for topic in log.topics:
        stats.meta[topic] = ("json", True, (), "", log.units(topic))
    # the records the vehicle and the SystemID watch read, in file order, as records
    for topic, t_ns, data in log.iter_records([t for t in log.topics if stats.wants_records(t, columns=True)]):
        stats.take(topic, t_ns, data)
    # everything else column-wise: times, the first record (its fields), the signals' columns
    for k, topic in enumerate(log.topics):
        if progress is not None:
            progress(k, len(log.topics), "topics")
        if not stats.wants_records(topic, columns=True):
            stats.take_columns(topic, log.times_ns(topic), log.first(topic),
                               lambda f, topic=topic: log.column(topic, f))
    notes.append(f"read as dataflash: {log.records} records")
    notes.extend(log.warnings)


def _read_ulog(path: Path, stats: _Stats, notes: list, progress) -> None:
    from livesweep.convert.ulog import UlogLog

    log = UlogLog(path, progress=progress)
    for topic in log.topics:
        stats.meta[topic] = ("json", True, (), "", {})
        stats.take_columns(topic, log.times_ns(topic), log.first(topic), lambda f, topic=topic: log.column(topic, f))
    notes.append(f"read as ULog: {log.messages} messages")
    notes.extend(log.warnings)


def _read_mcap(path: Path, stats: _Stats, notes: list, progress, *, converted: bool = False) -> None:
    """Every message of an MCAP file in file order: JSON messages that matter decoded, the others
    counted (their first one decoded, for its fields); other encodings counted."""
    # the fast raw walk of mcap_log (file order, CRC checks, damaged chunks skipped and counted) without
    # decoding every message: shared on purpose, as convert.tlog shares the recorder's schema rule
    from livesweep.telemetry.mcap_log import SkippedMessages, _BadMessage, _json_object, _open, _walk, read_summary

    src = _open(path)
    chans = src.channels
    schemas = src.schemas
    summary = None if converted else read_summary(path)
    for ch in chans.values():
        schema = schemas.get(ch.schema_id)
        if ch.message_encoding == "json":
            stats.meta.setdefault(ch.topic, ("json", True, (), "", _channel_units(ch.metadata)))
        else:
            fields, why = _schema_fields(ch.message_encoding, schema)
            stats.meta.setdefault(ch.topic, (ch.message_encoding, False, fields, why, {}))
    skipped = SkippedMessages()
    messages = _walk(src, chans, skipped)
    total = len(messages) if isinstance(messages, list) else \
        sum(summary.message_counts.values()) if summary is not None else 0
    plan: dict[int, int] = {}          # channel id -> how its messages after the first are read
    take, tick = stats.take, stats.tick
    for k, (cid, log_t, _pub, data) in enumerate(messages):
        if progress is not None and k % _PROGRESS_MESSAGES == 0:
            progress(k, total, "messages")
        how = plan.get(cid)
        if how == _COUNT:
            tick(chans[cid].topic, log_t, None, None, False)
            continue
        if how == _PLAIN:
            tick(chans[cid].topic, log_t)
            continue
        if how == _TICK:
            m = _SYSID_PREFIX.match(data)
            tick(chans[cid].topic, log_t, int(m.group(1)) if m is not None else _sysid_of(data))
            continue
        ch = chans[cid]
        if how is None and ch.message_encoding != "json":
            plan[cid] = _COUNT
            tick(ch.topic, log_t, None, None, False)
            continue
        try:
            obj = _json_object(data)
        except _BadMessage as bad:
            skipped.add(bad.reason, f"{path}: topic {ch.topic!r}: message at log_time {log_t} ns {bad}")
            continue
        if how == _READ:
            take(ch.topic, log_t, obj)
        elif stats.wants_records(ch.topic):       # the channel's first message
            plan[cid] = _READ
            take(ch.topic, log_t, obj)
        else:
            plan[cid] = _TICK if "sysid" in obj else _PLAIN
            tick(ch.topic, log_t, obj.get("sysid"), obj)
    if skipped.total:
        notes.append(f"{skipped.total} message(s) livesweep cannot decode: "
                     + ", ".join(f"{n} {why}" for why, n in sorted(skipped.counts.items())))
    if summary is not None and not summary.complete:
        notes.append(f"unfinished recording ({summary.tail_error or 'no footer'}): `livesweep recover {path}` "
                     "makes a finished copy")
    other = sorted({(stats.meta[t][0], t) for t in stats.topics if t in stats.meta and not stats.meta[t][1]})
    if other:
        encodings = sorted({e for e, _ in other})
        notes.append(f"{len(other)} topic(s) in {', '.join(encodings)}, which livesweep does not decode (it reads "
                     "JSON channels): counted, and their fields listed from the schema where it is a ROS message "
                     "definition")


def _sysid_of(data: bytes):
    """The ``sysid`` of a JSON message (None without, or when it does not decode)."""
    from livesweep.telemetry.mcap_log import _BadMessage, _json_object

    try:
        return _json_object(data).get("sysid")
    except _BadMessage:
        return None


def _read_table(path: Path, fmt: str, stats: _Stats, notes: list, progress, columns, tmp: Path) -> None:
    from livesweep.convert import convert

    options = {"column_map": columns} if columns else {}
    try:
        result = convert(path, tmp / "log.mcap", **options)
    except ConfigError as exc:
        if columns is None and "column" in str(exc).lower():
            raise ConfigError(f"{path}: a {fmt} table: give its column map with --columns MAP.toml "
                              f"(as for livesweep convert): {exc}") from None
        raise
    notes.append(f"read as {fmt}: {result.messages_written} rows of {result.messages_read}")
    _read_mcap(tmp / "log.mcap", stats, notes, progress, converted=True)


# ------------------------------------------------------------------------------------- rates and fits


def _arrival_rate(rx: np.ndarray, stamp: np.ndarray) -> float:
    """The rate samples arrive at [Hz]: the median of the samples per whole second of their clock
    (their stamps when every sample has one and they advance, else the receive times), so a gap,
    a stream rate raised later or a ground station's bursts do not pull it; the mean rate over
    their span when they cover fewer than 5 whole seconds."""
    n = rx.size
    if n < 2:
        return 0.0
    clock = stamp
    if not np.isfinite(stamp).all() or not np.median(np.diff(stamp)) > 0:
        clock = rx * 1e-9
    sec = np.floor(clock).astype(np.int64)
    stretch = np.concatenate(([0], np.cumsum(np.diff(clock) < -_CLOCK_BREAK_S)))    # a reboot, a clock wrap
    key = stretch * (1 << 40) + (sec - sec.min())
    _, counts = np.unique(key, return_counts=True)
    counts = counts[1:-1]                                                          # whole seconds only
    if counts.size >= 3:
        return float(np.sort(counts)[counts.size // 2])
    span = float(clock.max() - clock.min())
    return (n - 1) / span if span > 0 else 0.0


def _signal_rate(stats: _Stats, sig: _Signal) -> float:
    """The rate a signal arrives at [Hz] (:func:`_arrival_rate` of the main system's samples), over
    the SystemID runs that ended when it has samples there (what the verdict judges)."""
    rx, stamp = stats.samples(sig)
    ended = [(r["start"], r["end"]) for r in stats.runs if r["end"] is not None]
    if ended:
        inside = np.zeros(rx.size, dtype=bool)
        for a, b in ended:
            inside |= (rx >= a) & (rx <= b)
        if inside.sum() >= 5:
            r = _arrival_rate(rx[inside], stamp[inside])
            if r > 0:
                return r
    return _arrival_rate(rx, stamp)


def _rate(n: int, first, last) -> float:
    span = (last - first) * 1e-9 if first is not None and last is not None else 0.0
    return (n - 1) / span if n > 1 and span > 0 else 0.0


def _judged_top_hz(top_hz: float, what: str, m) -> tuple[float, str]:
    """The top of a band [Hz] as the map's monitor judges it: at most NYQUIST_FRACTION of its
    grid's Nyquist frequency."""
    grid_top = NYQUIST_FRACTION * m.spectral.sample_rate_hz / 2
    if top_hz > grid_top:
        return grid_top, f"the map's {m.spectral.sample_rate_hz:g} Hz grid (judged up to {grid_top:.3g} Hz)"
    return top_hz, what


def _band_top_hz(stats: _Stats, m) -> tuple[float, str]:
    """The top frequency a map's signals must show [Hz], and where it comes from."""
    tops = [r["injection"].omega_stop_rad_s / (2 * math.pi) for r in stats.runs if r.get("injection") is not None]
    if tops:
        return _judged_top_hz(max(tops), "the SystemID band", m)
    return _judged_top_hz(m.spectral.band_rad_s[1] / (2 * math.pi), "the map's band", m)


def _fit(stats: _Stats, name: str, m, whole: bool, rates: dict | None = None, live: bool = False) -> MapFit | None:
    """How map ``m`` fits: None when it holds no signal of the log; ``rates`` (signal -> Hz) replaces
    the measured rates (a stream's)."""
    sp = m.spectral
    if sp is None:
        return None
    have = {}
    for sig in (*sp.inputs, *sp.outputs, *(sp.references or ())):
        spec = m.signals[sig]
        if rates is not None:
            r = rates.get(sig)
            have[sig] = None if r is None else (True, r)
            continue
        s = stats.signal(spec)
        have[sig] = None if s.n == 0 else (s.hi > s.lo, _signal_rate(stats, s))
    if not all(have[r] is not None and have[r][0] for r in sp.references or ()):
        return None
    ins = [i for i in sp.inputs if have[i] is not None and have[i][0]]
    outs = [o for o in sp.outputs if have[o] is not None and have[o][0]]
    n, total = len(ins) * len(outs), len(sp.inputs) * len(sp.outputs)
    if not n or (whole and n != total):
        return None
    why = stats.vehicle.contradiction(m.vehicle) or ""
    if not why:
        top_hz, what = _band_top_hz(stats, m)
        need = RATE_PER_TOP_FREQUENCY * top_hz
        slow = sorted((have[s][1], s) for s in (*ins, *outs) if have[s][1] < need)
        if slow:
            per_message: dict[str, tuple[float, str]] = {}
            for rate, sig in slow:                          # the slowest signal of each message
                per_message.setdefault(m.signals[sig].topic.rsplit("/", 1)[-1], (rate, sig))
            parts = [f"{sig} ({msg}) {('would go at' if live else 'arrives at') if k == 0 else 'at'} {rate:.3g} Hz"
                     for k, (msg, (rate, sig)) in enumerate(per_message.items())]
            why = f"{', '.join(parts)}: {what} up to {top_hz:.3g} Hz needs {need:.3g} Hz"
    return MapFit(name, n, total, why, live)


def _stream_rates(stats: _Stats, m, rate_hz: float) -> dict | None:
    """The rate each signal of MAVLink map ``m`` would arrive at when ``livesweep stream --rate-hz``
    sends this DataFlash log; None when the stream lacks one of the map's topics."""
    def rec_rate(topic):
        st = stats.topics.get(topic)
        return 0.0 if st is None else _rate(st[0], st[1], st[2])

    out = {}
    for sig, spec in m.signals.items():
        if spec.topic == "/mavlink/PID_TUNING":
            axis = dict(spec.where).get("axis")
            src = _PID_RECORDS.get(int(axis)) if axis is not None else None
            r = rec_rate(src) if src else 0.0
        elif spec.topic in _STREAM_OF_DATAFLASH:
            srcs = _STREAM_OF_DATAFLASH[spec.topic]
            r = min(rec_rate(x) for x in srcs) if srcs else 1.0
        else:
            return None
        if r <= 0:
            return None
        out[sig] = min(r, rate_hz)
    return out


def inspect_log(path, *, columns=None, progress=None) -> LogInspection:
    """Read a log and describe it (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The log.
    columns : str or Path, optional
        Column map, for tables (``.npy``, ``.mat``, Parquet, text).
    progress : callable, optional
        ``progress(done, total, unit)`` now and then while the log is read: ``unit`` is
        ``"bytes"`` or ``"messages"``, ``total`` 0 when not known; a last call with ``done ==
        total`` at the end. :func:`stderr_progress` makes one for the command line.

    Raises
    ------
    LogFormatError, ConfigError
        A file that is not a log livesweep reads, or a table without a column map (one line
        naming the file and what to give).
    """
    from livesweep.convert.common import sniff_format

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such file")
    fmt = sniff_format(path)
    notes: list[str] = []
    maps = _candidate_maps()
    stats = _Stats(maps)
    import logging

    quiet = logging.getLogger("livesweep")       # readers' per-record warnings: counted in the notes
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        if fmt == "tlog":
            _read_tlog(path, stats, notes, progress)
        elif fmt == "mcap":
            _read_mcap(path, stats, notes, progress)
        elif fmt == "dataflash":
            _read_dataflash(path, stats, notes, progress)
        elif fmt == "ulog":
            _read_ulog(path, stats, notes, progress)
        else:
            with tempfile.TemporaryDirectory(prefix="livesweep-inspect-") as tmp:
                _read_table(path, fmt, stats, notes, progress, columns, Path(tmp))
    finally:
        quiet.setLevel(level)
        if progress is not None:
            progress(1, 1, "bytes")
    firsts = [st[1] for st in stats.topics.values()]
    t0 = min(firsts) if firsts else 0            # file order is receive order, not always time order
    infos = []
    for topic, (n, first, last, sample) in sorted(stats.topics.items()):
        encoding, decoded, schema_fields, why, units = stats.meta.get(topic, ("json", True, (), "", {}))
        if decoded:
            names = list(_numeric_fields(sample)) if isinstance(sample, dict) else []
            u = {**_mavlink_units(topic), **units}
            fields = tuple((f, u.get(f, "")) for f in names)
        else:
            fields = schema_fields
        infos.append(TopicInfo(topic, n, _rate(n, first, last), (first - t0) / 1e9, (last - t0) / 1e9, fields,
                               encoding, decoded, why))
    duration = ((stats.t_end or t0) - t0) / 1e9
    fits = [f for name, m, whole in maps if (f := _fit(stats, name, m, whole)) is not None]
    fits.sort(key=lambda f: (not f.fits, -f.pairs / f.total, -f.pairs, f.name))
    live = []
    if fmt == "dataflash":
        for name, m, whole in maps:
            if whole or not all(s.topic.startswith("/mavlink/") for s in m.signals.values()):
                continue
            rates = _stream_rates(stats, m, STREAM_RATE_HZ)
            if rates is not None and (f := _fit(stats, name, m, whole, rates=rates, live=True)) is not None:
                live.append(f)
        live.sort(key=lambda f: (not f.fits, -f.pairs / f.total, f.name))
    runs = _runs(stats, t0, maps)
    return LogInspection(path, fmt, duration, tuple(infos),
                         maps=tuple((f.name, f.pairs, f.total) for f in fits if f.fits),
                         test_points=tuple((r.start_s, r.end_s, r.what) for r in runs if r.data),
                         notes=tuple(notes), fits=tuple(fits + live), live_maps=tuple(f.name for f in live if f.fits),
                         systemid=tuple(runs))


# ------------------------------------------------------------------------------------- SystemID runs


def _run_signals(m, axis) -> list[str] | None:
    """The signals map ``m`` needs for a SystemID run on ``axis``: the input the axis sweeps and the
    outputs required with it; None when the map names no axes, or not this one."""
    sp = m.spectral
    tp = m.test_points
    if tp is None or not tp.axes:
        return None
    swept = tp.axes.get(int(axis)) if axis is not None else None
    if swept is None:
        return None
    outs = tp.required.get(swept)
    if not outs:
        k = list(sp.inputs).index(swept) if swept in sp.inputs else len(sp.outputs)
        outs = (sp.outputs[k],) if k < len(sp.outputs) else tuple(sp.outputs)
    return [swept, *outs]


def _covers(stats: _Stats, sig: _Signal, start: int, end: int, need_hz: float) -> bool:
    """Whether a signal's samples (the main system's) span :data:`COVER_FRACTION` of
    ``start..end`` [receive ns] and arrive there at ``need_hz`` at least."""
    rx, stamp = stats.samples(sig)
    inside = (rx >= start) & (rx <= end)
    if inside.sum() < 2:
        return False
    r = rx[inside]
    if (r.max() - r.min()) < COVER_FRACTION * (end - start):
        return False
    return _arrival_rate(r, stamp[inside]) >= need_hz


def _run_has_data(stats: _Stats, maps, start: int, end: int, axis, inj) -> bool:
    """Whether a preset that holds the log's signals (and fits its vehicle) has every signal it
    needs for the run covering it at the rate the run's band needs."""
    for _name, m, whole in maps:
        if m.spectral is None or whole or stats.vehicle.contradiction(m.vehicle):
            continue
        names = _run_signals(m, axis)
        if names is None:                   # no axis table: an input and an output the log holds
            have = [x for x in (*m.spectral.inputs, *m.spectral.outputs) if stats.signal(m.signals[x]).n]
            if not (set(have) & set(m.spectral.inputs) and set(have) & set(m.spectral.outputs)):
                continue
            names = have
        top = inj.omega_stop_rad_s / (2 * math.pi) if inj is not None else m.spectral.band_rad_s[1] / (2 * math.pi)
        need = RATE_PER_TOP_FREQUENCY * _judged_top_hz(top, "", m)[0]
        if all(_covers(stats, stats.signal(m.signals[n]), start, end, need) for n in names):
            return True
    return False


def _runs(stats: _Stats, t0: int, maps) -> list[SystemIdRun]:
    """The SystemID runs, each with whether the log holds the data a preset needs over it."""
    from livesweep.monitor.vehicle import axis_name

    out = []
    for r in stats.runs:
        start = r["start"]
        end = r["end"]
        inj = r["injection"]
        if end is None and inj is not None:
            end = start + int(inj.duration_s * 1e9)
        what = f"SystemID {axis_name(r['axis'])}"
        if inj is not None:
            what += f", magnitude {inj.magnitude:g}, {inj.describe()}"
        window_end = end if end is not None else start + int(SHORT_S * 1e9)
        has_data = _run_has_data(stats, maps, start, window_end, r["axis"], inj)
        out.append(SystemIdRun((start - t0) / 1e9, math.nan if end is None else (end - t0) / 1e9, r["axis"], what,
                               has_data))
    return out


# ------------------------------------------------------------------------------------- the text


def _fields_line(t: TopicInfo) -> str:
    shown = t.fields[:MAX_FIELDS]
    if t.decoded:
        text = ", ".join(f"{f} [{u}]" if u else f for f, u in shown)
    else:
        text = ", ".join(f"{f} ({typ})" for f, typ in shown)
    more = f", ... ({len(t.fields)} fields in all)" if len(t.fields) > MAX_FIELDS else ""
    return "      " + text + more


def format_inspection(ins: LogInspection) -> str:
    """The text ``livesweep inspect`` prints."""
    decoded = [t for t in ins.topics if t.decoded]
    count = (f"{len(ins.topics)} topics livesweep reads" if len(decoded) == len(ins.topics) else
             f"{len(ins.topics)} topics, {len(decoded)} of them in JSON, which livesweep reads")
    lines = [f"{ins.path}: {ins.format}, {ins.duration_s:.1f} s, {count}"]
    lines += [f"  note: {n}" for n in ins.notes]
    for t in ins.topics:
        enc = "" if t.decoded else f" ({t.encoding}, not decoded)"
        lines.append(f"  {t.topic}: {t.messages} messages, {t.rate_hz:.1f} Hz, {t.start_s:.1f}-{t.end_s:.1f} s{enc}")
        if t.fields:
            lines.append(_fields_line(t))
        elif t.fields_note:
            lines.append(f"      {t.topic}: {t.fields_note}")
    if ins.systemid:
        with_data = [r for r in ins.systemid if r.data]
        without = [r for r in ins.systemid if not r.data]
        lines.append("test points (ArduPilot SystemID):")
        for r in with_data:
            span = f"{r.start_s:.1f}-{r.end_s:.1f} s" if math.isfinite(r.end_s) else f"from {r.start_s:.1f} s"
            lines.append(f"  {span}: {r.what}")
        if without:
            named = ", ".join(f"{r.what.split(',')[0].removeprefix('SystemID ')} at {r.start_s:.1f} s"
                              for r in without[:_MAX_NAMED])
            more = f", ... ({len(without)} in all)" if len(without) > _MAX_NAMED else ""
            cover = "them at the rates their bands need" if len(without) > 1 else "it at the rate its band needs"
            lines.append(f"  {'' if with_data else 'all '}{len(without)} announced but without data (no preset's "
                         f"signals cover {cover}): {named}{more}")
    fitting = [f for f in ins.fits if f.fits and not f.live]
    if fitting and ins.duration_s < SHORT_S:
        lines.append(f"only {ins.duration_s:.1f} s of data: too short for a frequency response (a sweep's lowest "
                     "frequency needs windows of tens of seconds)")
    if fitting:
        best = fitting[0].name
        lines.append("channel-map presets whose signals this log holds (pairs with data / pairs):")
        lines += [f"  {f.name}: {f.pairs}/{f.total}" for f in fitting]
        how = (f"livesweep replay {ins.path} --map {best}" if ins.format == "mcap" else
               f"livesweep convert {ins.path} --out LOG.mcap && livesweep replay LOG.mcap --map {best}")
        lines.append(f"suggested: {how}")
        lines.append(f"  a case for identify: livesweep new-case {ins.path} --map {best} --out CASE.toml")
    elif not decoded:
        encodings = sorted({t.encoding for t in ins.topics})
        lines.append("no topic livesweep decodes (it reads JSON MCAP channels"
                     + (f"; these are {', '.join(encodings)}: convert them to JSON first" if encodings else "")
                     + "): no channel map can be suggested")
    else:
        lines.append("no shipped channel map fits this log: write one ([signals], [spectral]) from the fields above "
                     "(docs/case-file.md, Channel maps)")
    unfit = [f for f in ins.fits if not f.fits and not f.live]
    if unfit:
        lines.append("presets that hold this log's signals but do not fit it:")
        lines += [f"  {f.name}: {f.why}" for f in unfit]
    live = [f for f in ins.fits if f.live]
    if live:
        lines.append(f"live, as ArduCopter's telemetry (livesweep stream {ins.path} --mavlink udpout:127.0.0.1:14550 "
                     f"--rate-hz {STREAM_RATE_HZ:g}):")
        lines += [f"  {f.name}: {f.pairs}/{f.total}" if f.fits else f"  not {f.name}: {f.why}" for f in live]
        if ins.live_maps:
            lines.append(f"  monitor it with: livesweep monitor --mavlink udpin:127.0.0.1:14550 --map {ins.live_maps[0]}")
    return "\n".join(lines)
