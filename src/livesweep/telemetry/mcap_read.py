"""The message, metadata, attachment and summary readers of MCAP logs (:func:`read_messages`,
:func:`iter_file_order`, :func:`read_metadata`, :func:`read_attachments`, :func:`read_summary`) and
the records they return (:class:`LogMessage`, :class:`LogSummary`).

The contract is in :mod:`livesweep.telemetry.mcap_log` (the facade: import from there).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata
from mcap.stream_reader import CRCValidationError
from mcap.well_known import MessageEncoding

from livesweep.errors import LogFormatError
from livesweep.telemetry.mcap_common import _check_time_ns, _crc_error_text
from livesweep.telemetry.mcap_json import SkippedMessages, _at, _BadMessage, _json_object
from livesweep.telemetry.mcap_source import _open, _Source, _topic_list
from livesweep.telemetry.mcap_walk import _walk


@dataclass(frozen=True)
class LogMessage:
    """One decoded JSON message.

    Attributes
    ----------
    topic : str
        Channel topic.
    log_time_ns : int
        Receive time, integer nanoseconds.
    publish_time_ns : int
        Publisher (vehicle) time, integer nanoseconds.
    sequence : int
        Per-channel sequence number.
    data : dict
        The decoded JSON object (``null`` -> None).
    """

    topic: str
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    data: dict


@dataclass(frozen=True)
class LogSummary:
    """What a log holds.

    Attributes
    ----------
    path : str
        The file.
    message_counts : dict[str, int]
        Messages per topic (0 for channels without messages).
    start_ns, end_ns : int
        Smallest and largest message ``log_time`` in integer nanoseconds (0, 0 if no messages).
    duration_s : float
        ``(end_ns - start_ns) / 1e9`` seconds.
    schemas : dict[str, str]
        Topic -> schema name ("" for schemaless channels).
    metadata : dict[str, dict[str, str]]
        Metadata records by name.
    attachments : tuple[str, ...]
        Attachment names in file order.
    complete : bool
        False when the file was unfinished (writer killed before close) and was read by
        streaming up to its truncated tail.
    library : str
        Writer library from the MCAP header ("" if unknown).
    tail_error : str
        For an unfinished file, why streaming stopped (e.g. ``"EndOfFile"``); "" otherwise.
    """

    path: str
    message_counts: dict[str, int]
    start_ns: int
    end_ns: int
    duration_s: float
    schemas: dict[str, str]
    metadata: dict[str, dict[str, str]]
    attachments: tuple[str, ...]
    complete: bool
    library: str = ""
    tail_error: str = ""


def _decode(src: _Source, channel: Channel, msg: Message) -> LogMessage:
    if channel.message_encoding != MessageEncoding.JSON:
        raise LogFormatError(
            f"{src.path}: topic {channel.topic!r} has message encoding "
            f"{channel.message_encoding!r}, not 'json'; select JSON topics with topics=[...]"
        )
    try:
        data = _json_object(msg.data)
    except _BadMessage as bad:
        raise LogFormatError(f"{src.path}: topic {channel.topic!r}: message at log_time {msg.log_time} ns "
                             f"(sequence {msg.sequence}) {bad}") from None
    return LogMessage(channel.topic, msg.log_time, msg.publish_time, msg.sequence, data)


def read_messages(
    path: str | os.PathLike[str],
    topics: str | Iterable[str] | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> Iterator[LogMessage]:
    """Yield the JSON messages of a log in log-time order.

    Parameters
    ----------
    path : str or os.PathLike
        MCAP file, finished or unfinished.
    topics : str or list of str, optional
        Only these topics (unknown topics simply match nothing). All topics when None.
    start_ns : int, optional
        First log time to include, integer nanoseconds (inclusive).
    end_ns : int, optional
        Log time to stop before, integer nanoseconds (exclusive).

    Yields
    ------
    LogMessage
        Ties in log time keep file order.

    Raises
    ------
    LogFormatError
        If the file is missing, empty or not MCAP, a selected channel is not JSON, a message is
        not a JSON object (not JSON, nested too deeply, an array ...), or a chunk fails its CRC
        check; naming the file, topic and log time (or the chunk's log-time range).
    """
    src = _open(path)
    where = str(src.path)
    if start_ns is not None:
        start_ns = _check_time_ns(start_ns, "start_ns", where)
    if end_ns is not None:
        end_ns = _check_time_ns(end_ns, "end_ns", where)
    wanted = _topic_list(topics)
    return _iter_messages(src, wanted, start_ns, end_ns)


def _iter_messages(
    src: _Source, wanted: list[str] | None, start_ns: int | None, end_ns: int | None,
) -> Iterator[LogMessage]:
    if src.scan is not None:
        chans = src.scan.channels
        sel = [
            m for m in src.scan.messages
            if (wanted is None or chans[m.channel_id].topic in wanted)
            and (start_ns is None or m.log_time >= start_ns)
            and (end_ns is None or m.log_time < end_ns)
        ]
        sel.sort(key=lambda m: m.log_time)  # stable: ties keep file order
        for m in sel:
            yield _decode(src, chans[m.channel_id], m)
        return
    try:
        with open(src.path, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            for _schema, channel, msg in reader.iter_messages(
                topics=wanted, starting_at=start_ns, ending_before=end_ns, log_time_order=True
            ):
                yield _decode(src, channel, msg)
    except LogFormatError:
        raise
    except CRCValidationError as e:
        raise LogFormatError(_crc_error_text(src.path, e)) from None
    except Exception as e:  # noqa: BLE001 - McapError, OSError, zstd/lz4 errors on a damaged file
        raise LogFormatError(f"cannot read messages from MCAP log {src.path}: {type(e).__name__}: {e}") from e


def _metadata_dict(records: Iterable[Metadata]) -> dict[str, dict[str, str]]:
    out: dict[str, dict[str, str]] = {}
    for rec in records:
        out.setdefault(rec.name, {}).update(rec.metadata)  # repeated names merge, later wins
    return out


def _read_metadata(src: _Source) -> dict[str, dict[str, str]]:
    if src.scan is not None:
        return _metadata_dict(src.scan.metadata)
    try:
        with open(src.path, "rb") as f:
            return _metadata_dict(make_reader(f).iter_metadata())
    except Exception as e:  # noqa: BLE001 - McapError, OSError, zstd/lz4 errors on a damaged file
        raise LogFormatError(f"cannot read metadata from MCAP log {src.path}: {e}") from e


def read_metadata(path: str | os.PathLike[str]) -> dict[str, dict[str, str]]:
    """Metadata records of a log by name (records with the same name are merged, later wins)."""
    return _read_metadata(_open(path))


def read_attachments(path: str | os.PathLike[str]) -> dict[str, bytes]:
    """Attachments of a log, name -> contents (a repeated name keeps the later attachment)."""
    src = _open(path)
    if src.scan is not None:
        return {a.name: bytes(a.data) for a in src.scan.attachments}
    try:
        with open(src.path, "rb") as f:
            return {a.name: bytes(a.data) for a in make_reader(f).iter_attachments()}
    except Exception as e:  # noqa: BLE001 - McapError, OSError, zstd/lz4 errors on a damaged file
        raise LogFormatError(f"cannot read attachments from MCAP log {src.path}: {e}") from e


def read_summary(path: str | os.PathLike[str]) -> LogSummary:
    """Summarise a log: counts per topic, time bounds, schemas, metadata, attachments.

    For a finished file the counts and bounds come from the MCAP statistics record (the file is
    not decoded); an unfinished file is streamed and ``complete`` is False.
    """
    src = _open(path)
    chans = src.channels
    schemas = src.schemas
    topic_schema: dict[str, str] = {}
    counts: dict[str, int] = {}
    for c in chans.values():
        s = schemas.get(c.schema_id)
        topic_schema.setdefault(c.topic, s.name if s is not None else "")
        counts.setdefault(c.topic, 0)
    library = ""
    tail_error = ""
    if src.summary is not None:
        stats = src.summary.statistics
        attachments = tuple(a.name for a in src.summary.attachment_indexes)
        try:
            with open(src.path, "rb") as f:
                reader = make_reader(f)
                library = reader.get_header().library
                if stats is not None:
                    for cid, n in stats.channel_message_counts.items():
                        if cid in chans:
                            counts[chans[cid].topic] += n
                    total = stats.message_count
                    start, end = stats.message_start_time, stats.message_end_time
                else:  # no statistics record: count by reading
                    total, start, end = 0, None, None
                    for _s, ch, m in reader.iter_messages(log_time_order=False):
                        counts[ch.topic] += 1
                        total += 1
                        start = m.log_time if start is None else min(start, m.log_time)
                        end = m.log_time if end is None else max(end, m.log_time)
        except Exception as e:  # noqa: BLE001 - McapError, OSError, zstd/lz4 errors on a damaged file
            raise LogFormatError(f"cannot read summary of MCAP log {src.path}: {e}") from e
    else:
        assert src.scan is not None
        scan = src.scan
        attachments = tuple(a.name for a in scan.attachments)
        library = scan.header.library if scan.header is not None else ""
        tail_error = "" if src.complete else (scan.tail_error or "no footer")
        for m in scan.messages:
            counts[scan.channels[m.channel_id].topic] += 1
        total = len(scan.messages)
        start = min((m.log_time for m in scan.messages), default=0)
        end = max((m.log_time for m in scan.messages), default=0)
    if not total:
        start, end = 0, 0
    return LogSummary(
        path=str(src.path),
        message_counts=counts,
        start_ns=int(start),
        end_ns=int(end),
        duration_s=(int(end) - int(start)) / 1e9,
        schemas=topic_schema,
        metadata=_read_metadata(src),
        attachments=attachments,
        complete=src.complete,
        library=library,
        tail_error=tail_error,
    )


def iter_file_order(path: str | os.PathLike[str], topics: str | Iterable[str] | None = None, *,
                    skipped: SkippedMessages | None = None) -> Iterator[LogMessage]:
    """Every message (or those of ``topics``) in file order, as JSON objects; the fast walk when possible.

    File order is the order a livesweep recorder received the messages in, which is what a replay
    must reproduce.

    Parameters
    ----------
    path : str or os.PathLike
        MCAP file, finished or unfinished.
    topics : str or iterable of str, optional
        Only these topics; all when None.
    skipped : SkippedMessages, optional
        Lenient mode, for a replay: a message that is not a JSON object (not JSON, nested too
        deeply, an array ...), a message on a channel whose encoding is not JSON, and a chunk
        that fails its CRC check or does not decompress are skipped and counted in
        ``skipped.counts`` (reasons in :data:`SKIP_REASONS`) instead of raising. Read the counts
        during or after the iteration.

    Yields
    ------
    LogMessage
        ``data`` is always a dict. ``sequence`` is the message's index among its topic's messages
        in file order, counted here; skipped messages take their index too, so a replayed
        sequence shows where messages were skipped.

    Raises
    ------
    LogFormatError
        The file is missing or not MCAP; without ``skipped``, the first bad message (naming file,
        topic, index in its topic and log time) or damaged chunk (byte offset and log-time range).
        In both modes: a damaged chunk that only mcap's reader can reach (an unfinished file, or
        a finished one in a layout the fast walk declines), which cannot be stepped over.
    """
    src = _open(path)
    wanted = _topic_list(topics) or src.topics()
    chans = {cid: c for cid, c in src.channels.items() if c.topic in wanted}
    index: dict[int, int] = {}
    for cid, log_t, pub_t, data in _walk(src, chans, skipped):
        k = index.get(cid, 0)
        index[cid] = k + 1
        ch = chans[cid]
        try:
            if ch.message_encoding != MessageEncoding.JSON:
                raise _BadMessage("not_json_encoding", f"is on a channel with message encoding "
                                                       f"{ch.message_encoding!r}, not 'json'")
            obj = _json_object(data)
        except _BadMessage as bad:
            text = f"{_at(src.path, ch.topic, k, log_t)} {bad}"
            if skipped is None:
                raise LogFormatError(text) from None
            skipped.add(bad.reason, text)
            continue
        yield LogMessage(ch.topic, log_t, pub_t, k, obj)
