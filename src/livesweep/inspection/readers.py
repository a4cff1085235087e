"""Reading each log format into :class:`~livesweep.inspection.stats._Stats`, in one pass.

One job: the per-format readers of ``livesweep inspect``: a MAVLink tlog frame by frame (types no
one reads only counted), an MCAP file's messages in file order (JSON decoded where it matters,
other encodings counted), a DataFlash or ULog log column-wise (records only where the vehicle and
the SystemID watch need them), and a table converted to a temporary MCAP file first. Each adds
what the reader noticed (damage, skipped messages, an unfinished recording) to the notes.
"""

from __future__ import annotations

import re
from pathlib import Path

from livesweep.errors import ConfigError
from livesweep.inspection.fields import _channel_units, _schema_fields
from livesweep.inspection.stats import _Stats

#: Messages between two progress reports while reading an MCAP file.
_PROGRESS_MESSAGES = 50_000
#: How an MCAP channel's messages are read after its first: counted only (not JSON), read one by
#: one (:meth:`_Stats.take`), counted with their system id (:meth:`_Stats.tick`), counted as
#: records of no system (JSON without ``sysid``, as its first message).
_COUNT, _READ, _TICK, _PLAIN = 0, 1, 2, 3
#: A recorder's JSON record starts with its system id: read without decoding the message.
_SYSID_PREFIX = re.compile(rb'\{"sysid":\s*(-?\d+)\s*[,}]')


def _read_tlog(path: Path, stats: _Stats, notes: list, progress) -> None:
    """Every frame of a tlog, as :class:`TlogSource` frames and checks it. A message type that no
    map, vehicle check or SystemID watch reads is counted from its pymavlink message (its first one
    read as a record, for its fields), without building a record per frame."""
    from livesweep.telemetry.mavlink_in import TlogSource

    size = path.stat().st_size
    src = TlogSource(path)
    take, tick = stats.take, stats.tick
    dec = getattr(src, "decoder", None)  # the source's decoder: the checks and counts poll() applies to a frame

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
    from livesweep.telemetry.mcap_json import BadMessage, json_object
    from livesweep.telemetry.mcap_log import SkippedMessages, read_summary
    from livesweep.telemetry.mcap_source import open_source
    from livesweep.telemetry.mcap_walk import walk_messages

    src = open_source(path)
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
    messages = walk_messages(src, chans, skipped)
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
            obj = json_object(data)
        except BadMessage as bad:
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
    from livesweep.telemetry.mcap_json import BadMessage, json_object

    try:
        return json_object(data).get("sysid")
    except BadMessage:
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
