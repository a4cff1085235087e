"""``livesweep inspect LOG``: what a log holds, the channel maps that fit it, its SystemID test points.

Any log livesweep reads, in one pass over its messages: a MAVLink ``.tlog`` frame by frame (no
conversion), MCAP directly; a DataFlash ``.bin``, PX4 ``.px4log``, ULog or table is converted to a
temporary MCAP first (tables need ``--columns``, as for ``convert``). For every topic: messages,
rate, time span and numeric fields with their units (MAVLink's message definitions, DataFlash
FMTU, a column map's units). Then:

* **the shipped channel-map presets that fit**, best first: every signal's messages are there and
  vary, the vehicle is the one the map is made for (its ``[map.vehicle]`` against the log's
  parameters, "Frame:" text and HEARTBEAT type), and every signal arrives fast enough for the band
  it must show (2.5 x its top frequency: the band a SystemID run was told to sweep, else the
  map's). A preset that almost fits is listed with why it does not;
* for an ArduCopter DataFlash log, the presets for its telemetry as ``livesweep stream`` sends it
  (the live path), at the stream rate suggested;
* **the ArduPilot SystemID test points**: each start ("SystemID Starting: axis=N" in STATUSTEXT or
  MSG, SIDS) with its axis, band and magnitude (from SIDS or the ``SID_*`` parameters), its end
  ("SystemID Finished", or the mode leaving SYSTEMID), and whether the log holds telemetry during it.

This is an edge module (files); it only reads.
"""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from livesweep.errors import ConfigError
from livesweep.monitor.systemid import SAME_START_S, SystemIdWatch, better_injection
from livesweep.spectral.test_point import NYQUIST_FRACTION

__all__ = ["TopicInfo", "MapFit", "SystemIdRun", "LogInspection", "inspect_log", "format_inspection",
           "STREAM_RATE_HZ"]

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
#: What ``livesweep stream`` makes of a DataFlash log: MAVLink topic -> the DataFlash records it comes
#: from (its rate is the slowest of them, capped at the stream rate); PID_TUNING per axis.
_STREAM_OF_DATAFLASH = {"/mavlink/ATTITUDE": ("/dataflash/ATT", "/dataflash/RATE"),
                        "/mavlink/SERVO_OUTPUT_RAW": ("/dataflash/RCOU",),
                        "/mavlink/RAW_IMU": ("/dataflash/IMU",), "/mavlink/HEARTBEAT": (),
                        "/mavlink/STATUSTEXT": ("/dataflash/MSG",), "/mavlink/PARAM_VALUE": ("/dataflash/PARM",)}
_PID_RECORDS = {1: "/dataflash/PIDR", 2: "/dataflash/PIDP", 3: "/dataflash/PIDY"}


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
class MapFit:
    """How a preset fits the log.

    Attributes
    ----------
    name : str
    pairs, total : int
        (output, input) pairs whose signals the log holds and vary, of all the map's pairs.
    why : str
        Why it does not fit ("" when it does): another vehicle, signals too slow for the band.
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
    """One ArduPilot SystemID run in the log.

    Attributes
    ----------
    start_s, end_s : float
        Relative to the log's first message [s]; ``end_s`` NaN when the log does not say.
    axis : int or None
    what : str
        Axis, band and magnitude in words.
    data : bool
        The log holds telemetry during it (a log filtered around one run lists the others' texts only).
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
        ``(start_s, end_s, what)`` of the SystemID runs, relative to the first message.
    notes : tuple of str
    fits : tuple of MapFit
        Every preset that holds signals of the log, fitting or not (with why).
    live_maps : tuple of str
        For a DataFlash log: the presets for its telemetry as ``livesweep stream --rate-hz``
        :data:`STREAM_RATE_HZ` sends it, best first.
    systemid : tuple of SystemIdRun
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
    """``(name, ChannelMap, whole)`` of the shipped presets and the packaged XV-15 map (the demo's,
    which counts only when all of it fits)."""
    from livesweep.config import read_channel_map
    from livesweep.maps import list_maps, load_map

    out = [(info.name, load_map(info.name), False) for info in list_maps()]
    xv15 = Path(__file__).resolve().parent / "data" / "xv15_channels.toml"
    out.append((str(xv15), read_channel_map(xv15, one_clock=False), True))
    return out


class _Stats:
    """Per-topic and per-signal statistics gathered in one pass over a log's frames."""

    def __init__(self, maps):
        from livesweep.monitor.vehicle import VehicleInfo
        from livesweep.telemetry.extract import compile_signal

        self.topics: dict[str, list] = {}            # topic -> [n, earliest ns, latest ns, first data]
        self._vehicles: dict = {}                    # sysid -> VehicleInfo: the log's main system is judged
        self._frames_by_system: dict = {}            # sysid -> frames (the main system sends the most)
        self._new_vehicle = VehicleInfo
        self.runs: list[dict] = []                   # SystemID runs: start ns, end ns, axis, injection
        self._watches: dict = {}                     # sysid -> SystemIdWatch
        self._run_seconds: list | None = None
        self.t0: int | None = None
        self.t_end: int | None = None
        #: key -> [extractor, n, min, max, first ns, last ns, {second: samples in it}]
        self.signals: dict[str, list] = {}
        self.by_topic: dict[str, list[str]] = {}
        for name, m, _ in maps:
            for sig, spec in m.signals.items():
                key = f"{spec.topic}|{spec.field}|{spec.where}|{spec.sysid}|{spec.compid}"
                if key not in self.signals:
                    self.signals[key] = [compile_signal(spec), 0, math.inf, -math.inf, None, None, {}]
                    self.by_topic.setdefault(spec.topic, []).append(key)

    def take(self, topic: str, t_ns: int, data) -> None:
        if self.t0 is None:
            self.t0 = t_ns
        self.t_end = t_ns if self.t_end is None else max(self.t_end, t_ns)
        st = self.topics.get(topic)
        if st is None:
            self.topics[topic] = [1, t_ns, t_ns, data]
        else:                                    # the span: file order need not be time order
            st[0] += 1
            if t_ns > st[2]:
                st[2] = t_ns
            elif t_ns < st[1]:
                st[1] = t_ns
        if not isinstance(data, dict):
            return
        sysid = data.get("sysid")
        self._frames_by_system[sysid] = self._frames_by_system.get(sysid, 0) + 1
        for key in self.by_topic.get(topic, ()):
            s = self.signals[key]
            v, problem = s[0].value(data)
            if problem is None:
                s[1] += 1
                s[2] = min(s[2], v)
                s[3] = max(s[3], v)
                s[4] = t_ns if s[4] is None else s[4]
                s[5] = t_ns
                sec = t_ns // 1_000_000_000
                s[6][sec] = s[6].get(sec, 0) + 1
        if topic in ("/mavlink/PARAM_VALUE", "/dataflash/PARM", "/dataflash/SIDS", "/mavlink/STATUSTEXT",
                     "/dataflash/MSG", "/mavlink/HEARTBEAT", "/dataflash/MODE"):
            self._systemid(topic, t_ns, data)

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

    def run_seconds(self) -> list[int]:
        """The whole seconds [s of receive time] inside the SystemID runs that ended (computed once, after the pass)."""
        if self._run_seconds is None:
            self._run_seconds = [k for r in self.runs if r["end"] is not None
                                 for k in range(r["start"] // 1_000_000_000 + 1, r["end"] // 1_000_000_000)]
        return self._run_seconds

    def signal(self, spec):
        return self.signals[f"{spec.topic}|{spec.field}|{spec.where}|{spec.sysid}|{spec.compid}"]


@dataclass(frozen=True)
class _Frame:
    topic: str
    data: dict


def _frames(path: Path, fmt: str, tmp: Path, columns, notes: list):
    """(topic, receive ns, data) of every message, in file order."""
    if fmt == "tlog":
        from livesweep.telemetry.mavlink_in import TlogSource

        src = TlogSource(path)
        try:
            while not src.finished:
                for f in src.poll(max_frames=20_000):
                    yield f.topic, f.receive_ns, f.data
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
        return
    mcap = path
    if fmt != "mcap":
        from livesweep.convert import convert

        options = {"column_map": columns} if columns else {}
        try:
            result = convert(path, tmp / "log.mcap", **options)
        except ConfigError as exc:
            if columns is None and "column" in str(exc).lower():
                raise ConfigError(f"{path}: a {fmt} table: give its column map with --columns MAP.toml "
                                  f"(as for livesweep convert): {exc}") from None
            raise
        mcap = tmp / "log.mcap"
        notes.append(f"read as {fmt} and converted in memory ({result.messages_written} messages of "
                     f"{result.messages_read} read)")
    from livesweep.telemetry.mcap_log import SkippedMessages, iter_file_order

    skipped = SkippedMessages()
    for m in iter_file_order(mcap, skipped=skipped):
        yield m.topic, m.log_time_ns, m.data
    if skipped.total:
        notes.append(f"{skipped.total} message(s) livesweep does not decode: "
                     + ", ".join(f"{n} {why}" for why, n in sorted(skipped.counts.items())))


def _signal_rate(stats: _Stats, s: list) -> float:
    """The rate a signal arrives at [Hz]: the median of its samples per second over the seconds of
    the SystemID runs (what the verdict judges), else over the seconds it arrives in; a stream rate
    raised after connecting, or a gap, does not pull it down."""
    per_second = s[6]
    counts = [per_second[k] for k in stats.run_seconds() if k in per_second]
    if len(counts) < 3:
        counts = list(per_second.values())[1:-1]          # whole seconds only
    if len(counts) < 3:
        return _rate(s[1], s[4], s[5])
    return float(sorted(counts)[len(counts) // 2])


def _rate(n: int, first, last) -> float:
    span = (last - first) * 1e-9 if first is not None and last is not None else 0.0
    return (n - 1) / span if n > 1 and span > 0 else 0.0


def _band_top_hz(stats: _Stats, m) -> tuple[float, str]:
    """The top frequency a map's signals must show [Hz], and where it comes from."""
    tops = [r["injection"].omega_stop_rad_s / (2 * math.pi) for r in stats.runs if r.get("injection") is not None]
    if tops:
        return max(tops), "the SystemID band"
    return m.spectral.band_rad_s[1] / (2 * math.pi), "the map's band"


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
        have[sig] = None if s[1] == 0 else (s[3] > s[2], _signal_rate(stats, s))
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
            rate, sig = slow[0]
            spec = m.signals[sig]
            why = (f"{sig} ({spec.topic.rsplit('/', 1)[-1]}) {'would go' if live else 'arrives'} at {rate:.3g} Hz: "
                   f"{what} up to {top_hz:.3g} Hz needs {need:.3g} Hz")
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

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such file")
    fmt = sniff_format(path)
    notes: list[str] = []
    summary_duration = 0.0
    maps = _candidate_maps()
    stats = _Stats(maps)
    import logging

    quiet = logging.getLogger("livesweep.telemetry")       # a reader's per-frame warnings: counted in the notes
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        with tempfile.TemporaryDirectory(prefix="livesweep-inspect-") as tmp:
            for topic, t_ns, data in _frames(path, fmt, Path(tmp), columns, notes):
                stats.take(topic, t_ns, data)
            units = _channel_units(Path(tmp) / "log.mcap") if fmt not in ("mcap", "tlog") else \
                _channel_units(path) if fmt == "mcap" else {}
            if fmt == "mcap":
                from livesweep.telemetry.mcap_log import read_summary

                s = read_summary(path)
                summary_duration = s.duration_s
                if not s.complete:
                    notes.append(f"unfinished recording ({s.tail_error or 'no footer'}): `livesweep recover {path}` "
                                 "makes a finished copy")
                undecoded = {t: n for t, n in s.message_counts.items() if n and t not in stats.topics}
                if undecoded:
                    notes.append(f"{len(undecoded)} topic(s) not in JSON, which livesweep does not read: "
                                 + ", ".join(f"{t} ({n} messages)" for t, n in sorted(undecoded.items())[:8])
                                 + (" ..." if len(undecoded) > 8 else ""))
    finally:
        quiet.setLevel(level)
    firsts = [st[1] for st in stats.topics.values()]
    t0 = min(firsts) if firsts else 0            # file order is receive order, not always time order
    infos = []
    for topic, (n, first, last, sample) in sorted(stats.topics.items()):
        names = list(_numeric_fields(sample))[:MAX_FIELDS] if isinstance(sample, dict) else []
        u = {**_mavlink_units(topic), **units.get(topic, {})}
        infos.append(TopicInfo(topic, n, _rate(n, first, last), (first - t0) / 1e9, (last - t0) / 1e9,
                               tuple((f, u.get(f, "")) for f in names)))
    duration = ((stats.t_end or t0) - t0) / 1e9
    if fmt == "mcap" and not stats.topics:
        duration = summary_duration                # nothing decoded (ROS 2 CDR): the file's own span
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
    runs = _runs(stats, t0)
    return LogInspection(path, fmt, duration, tuple(infos),
                         maps=tuple((f.name, f.pairs, f.total) for f in fits if f.fits),
                         test_points=tuple((r.start_s, r.end_s, r.what) for r in runs), notes=tuple(notes),
                         fits=tuple(fits + live), live_maps=tuple(f.name for f in live if f.fits), systemid=tuple(runs))


def _runs(stats: _Stats, t0: int) -> list[SystemIdRun]:
    """The SystemID runs, each with whether telemetry covers it (the map topics with data then)."""
    from livesweep.monitor.vehicle import axis_name

    data_topics = {spec.topic for key in stats.signals for spec in (stats.signals[key][0].spec,)}
    spans = [(st[1], st[2]) for topic, st in stats.topics.items() if topic in data_topics and st[0] > 1]
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
        has_data = any(a <= (end or start) and b >= start for a, b in spans)
        out.append(SystemIdRun((start - t0) / 1e9, math.nan if end is None else (end - t0) / 1e9, r["axis"], what,
                               has_data))
    return out


def format_inspection(ins: LogInspection) -> str:
    """The text ``livesweep inspect`` prints."""
    lines = [f"{ins.path}: {ins.format}, {ins.duration_s:.1f} s, {len(ins.topics)} topics livesweep reads"]
    lines += [f"  note: {n}" for n in ins.notes]
    for t in ins.topics:
        lines.append(f"  {t.topic}: {t.messages} messages, {t.rate_hz:.1f} Hz, {t.start_s:.1f}-{t.end_s:.1f} s")
        if t.fields:
            lines.append("      " + ", ".join(f"{f} [{u}]" if u else f for f, u in t.fields))
    if ins.systemid:
        lines.append("test points (ArduPilot SystemID):")
        for r in ins.systemid:
            span = f"{r.start_s:.1f}-{r.end_s:.1f} s" if math.isfinite(r.end_s) else f"from {r.start_s:.1f} s"
            lines.append(f"  {span}: {r.what}" + ("" if r.data else " (no telemetry in the log during it)"))
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
    elif not ins.topics:
        lines.append("no topic livesweep decodes (it reads JSON MCAP channels; ROS 2 CDR needs converting to JSON "
                     "first): no channel map can be suggested")
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
