"""Salvage an unfinished or damaged MCAP log into a new, finished file (``livesweep recover``).

:func:`recover` reads the source's bytes record by record and copies everything it can read. Damage
does not end the copy: it is stepped over and counted.

* A chunk that does not decompress is skipped if its framing (opcode and length) is intact, and the
  walk goes on with the next record. A chunk that decompresses but fails its CRC check is kept:
  its records that parse are copied, and its messages are counted as *unverified* (their bytes
  may have changed since they were written). mcap's own reader, with its default
  ``validate_crcs=False``, returns such messages too.
* Where the framing is broken (an impossible length, an unknown opcode), a chunk is still read if
  the summary's chunk index places one there, or if its own fields (compression, records length)
  lay it out consistently; a schema, channel, metadata, attachment or header record is still read
  if its fields say where it ends. Otherwise the walk resynchronises: at the next record the
  summary section indexes (chunks, metadata, attachments) when the footer and summary are
  readable, or at the next byte where a plausible record starts, whichever comes first (a chunk:
  opcode 0x06, a length that fits in the file, compression ``""``, ``"zstd"`` or ``"lz4"`` filling
  that length exactly, and it is followed by a plausible record or decompresses; a schema,
  channel, message, metadata or attachment record that parses exactly and is followed by a
  plausible record).
* In a chunk that fails its CRC check, records after one that does not parse are found again at
  the offsets its message index records give.
* Schemas and channels whose records in the data section are damaged or missing are taken from
  the summary section, which repeats them. A damaged magic or header does not stop the walk.
* Messages lost are counted from the summary's statistics record when it is readable (expected
  minus written), else from the message indexes that follow each unreadable chunk; otherwise the
  number is unknown and said to be.
* Damaged content is never rewritten with fresh, valid CRCs silently: the output's metadata record
  ``"livesweep.recover"`` holds the counts (written, expected, lost, unverified) and the byte
  offsets in the source of the unverified and of the skipped chunks.

The output is written to ``<out_path>.partial`` and renamed onto ``out_path`` at the end, so it is
finished or absent.
"""

from __future__ import annotations

import mmap
import os
import re
import struct
import zlib
from bisect import bisect_right
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.writer import CompressionType, Writer

from livesweep.errors import LogFormatError
from livesweep.locks import check_file_free, install_file
from livesweep.telemetry.mcap_log import _MAGIC, _MAX_CHUNK_BYTES

__all__ = ["RECOVER_METADATA_NAME", "RecoverResult", "recover"]

#: Name of the metadata record :func:`recover` adds to its output.
RECOVER_METADATA_NAME = "livesweep.recover"

_HEADER, _FOOTER, _SCHEMA, _CHANNEL, _MESSAGE, _CHUNK, _MESSAGE_INDEX = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07
_CHUNK_INDEX, _ATTACHMENT, _ATTACHMENT_INDEX, _STATISTICS = 0x08, 0x09, 0x0A, 0x0B
_METADATA, _METADATA_INDEX, _SUMMARY_OFFSET, _DATA_END = 0x0C, 0x0D, 0x0E, 0x0F
_NAMES = {_HEADER: "header", _FOOTER: "footer", _SCHEMA: "schema", _CHANNEL: "channel", _MESSAGE: "message",
          _CHUNK: "chunk", _MESSAGE_INDEX: "message index", _CHUNK_INDEX: "chunk index", _ATTACHMENT: "attachment",
          _ATTACHMENT_INDEX: "attachment index", _STATISTICS: "statistics", _METADATA: "metadata",
          _METADATA_INDEX: "metadata index", _SUMMARY_OFFSET: "summary offset", _DATA_END: "data end"}
_PARSERS = {_HEADER: Header.read, _FOOTER: Footer.read, _SCHEMA: Schema.read, _CHANNEL: Channel.read,
            _MESSAGE_INDEX: MessageIndex.read, _CHUNK_INDEX: ChunkIndex.read, _ATTACHMENT: Attachment.read,
            _ATTACHMENT_INDEX: AttachmentIndex.read, _STATISTICS: Statistics.read, _METADATA: Metadata.read,
            _METADATA_INDEX: MetadataIndex.read, _SUMMARY_OFFSET: SummaryOffset.read, _DATA_END: DataEnd.read}
_HEAD = struct.Struct("<BQ")              # opcode, record length
_MSG = struct.Struct("<HIQQ")             # channel id, sequence, log time, publish time
_MSG_HEAD = 22
_CHUNK_HEAD = struct.Struct("<QQQII")     # start, end, uncompressed size, uncompressed crc, compression length
_CHUNK_MIN = 8 + 8 + 8 + 4 + 4 + 8        # a chunk body without compression name and records [bytes]
_FOOTER_BYTES = 9 + 20                    # footer record [bytes]
_COMPRESSIONS = (b"", b"zstd", b"lz4")
#: A record start the resynchronising scan considers: a record opcode and a length under 4 GiB.
_CANDIDATE = re.compile(rb"[\x03\x04\x05\x06\x09\x0c].{4}\x00\x00\x00\x00", re.DOTALL)
_OUT_CHUNK_BYTES = 256 * 1024


@dataclass(frozen=True)
class RecoverResult:
    """What :func:`recover` wrote and what it could not.

    Attributes
    ----------
    source : str
        The file read.
    output : str
        The finished file written.
    messages_written : int
        Messages copied to ``output`` (unverified ones included).
    messages_expected : int or None
        Messages the source's statistics record counts; None when the source has no readable
        statistics record (an unfinished recording, a damaged summary).
    messages_lost : int or None
        Messages of the source not in ``output``: ``messages_expected - messages_written`` when the
        expected count is known, else counted from the message indexes of the unreadable chunks;
        None when some unreadable bytes hold an unknown number of messages.
    messages_unverified : int
        Messages in ``output`` copied from chunks that fail their CRC check (or whose decompressed
        size differs from the one declared): their bytes may differ from what was written.
    damaged_chunks : tuple of int
        Byte offsets in the source of the chunks skipped whole (they do not decompress).
    unverified_chunks : tuple of int
        Byte offsets in the source of the chunks whose messages are unverified.
    skipped_bytes : tuple of (int, int)
        Byte ranges ``[start, end)`` of the source that were not copied: unreadable chunks and
        records, and the bytes stepped over to find the next readable record.
    unreadable : tuple of str
        One line per thing that could not be read or was lost (a chunk, a record cut off at the
        end, a metadata record, a channel without a definition ...), with its byte offset.
    complete_source : bool
        True when the source was finished (its footer and summary section were readable).
    notes : tuple of str
        Other facts worth reporting that lost nothing: a damaged magic, header, summary or
        message index, a data-section CRC mismatch, an unfinished source.

    Notes
    -----
    :attr:`clean` is True only when nothing was lost and nothing is unverified.
    """

    source: str
    output: str
    messages_written: int
    messages_expected: int | None
    messages_lost: int | None
    messages_unverified: int
    damaged_chunks: tuple[int, ...] = ()
    unverified_chunks: tuple[int, ...] = ()
    skipped_bytes: tuple[tuple[int, int], ...] = ()
    unreadable: tuple[str, ...] = ()
    complete_source: bool = True
    notes: tuple[str, ...] = ()

    @property
    def clean(self) -> bool:
        """True when every message was copied, none is unverified and nothing was unreadable."""
        return self.messages_lost == 0 and self.messages_unverified == 0 and not self.unreadable


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------


def _parse(op: int, body: bytes):
    """The record of opcode ``op`` whose body is ``body``; None unless it parses and fills it exactly."""
    stream = ReadDataStream(BytesIO(body))
    try:
        rec = _PARSERS[op](stream)
    except Exception:  # noqa: BLE001 - EndOfFile, struct.error, UnicodeDecodeError ...: damaged bytes
        return None
    return rec if stream.count == len(body) else None


class _View:
    """A read-only file over ``buf[start:stop]`` (the source's map or a chunk's records), without copying it."""

    def __init__(self, buf, start: int, stop: int) -> None:
        self.buf, self.p, self.stop = buf, start, stop

    def read(self, n: int) -> bytes:
        out = self.buf[self.p:min(self.stop, self.p + n)]
        self.p += len(out)
        return out


#: Records whose fields say where they end (so a damaged length prefix can be stepped over).
_SELF_DELIMITED = (_HEADER, _SCHEMA, _CHANNEL, _METADATA, _ATTACHMENT)


def _parse_by_fields(op: int, buf, start: int, stop: int):
    """(record, body length) of the record of opcode ``op`` whose body starts at ``start``, read by its
    fields whatever its length prefix says (``stop`` bounds it); None when it does not parse."""
    stream = ReadDataStream(_View(buf, start, stop))
    try:
        rec = _PARSERS[op](stream)
    except Exception:  # noqa: BLE001 - EndOfFile, struct.error, UnicodeDecodeError ...: damaged bytes
        return None
    if op == _ATTACHMENT:                            # its data must not run past ``stop``
        (declared,) = struct.unpack_from("<Q", buf, start + stream.count - 12 - len(rec.data))
        if declared != len(rec.data):
            return None
    return rec, stream.count


def _inflate(kind: str, data: bytes, size: int) -> bytes:
    """A chunk's records, decompressed; raises when they do not decompress.

    The output may differ in length from ``size`` (the chunk's declared uncompressed size), as
    mcap's reader allows; it never exceeds ``_MAX_CHUNK_BYTES`` (a damaged frame may declare
    gigabytes).
    """
    if kind == "":
        return data
    if kind == "zstd":
        import zstandard

        declared = zstandard.frame_content_size(data)          # -1: the frame does not say
        if declared > _MAX_CHUNK_BYTES:
            raise ValueError(f"its zstd frame declares {declared} bytes")
        limit = declared if declared >= 0 else min(size, _MAX_CHUNK_BYTES)
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=limit)
    if kind == "lz4":
        import lz4.frame

        declared = lz4.frame.get_frame_info(data).get("content_size") or 0
        if declared > _MAX_CHUNK_BYTES:
            raise ValueError(f"its lz4 frame declares {declared} bytes")
        return lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=declared or min(size, _MAX_CHUNK_BYTES))
    raise ValueError(f"unknown compression {kind!r}")


def _crc(buf, a: int, b: int) -> int:
    """CRC-32 of ``buf[a:b]``, 16 MiB at a time."""
    crc = 0
    for p in range(a, b, 1 << 24):
        crc = zlib.crc32(buf[p:min(b, p + (1 << 24))], crc)
    return crc


def _ranges(ranges: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """``ranges`` sorted, with touching and overlapping ranges merged."""
    out: list[list[int]] = []
    for a, b in sorted(ranges):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def _install(tmp: Path, out_p: Path, overwrite: bool) -> None:
    """Put the finished ``tmp`` in place at ``out_p``: never over a file another process is writing
    (a recording), nor over an existing one unless ``overwrite`` (:func:`livesweep.locks.install_file`)."""
    install_file(tmp, out_p, overwrite=overwrite, what="recover output", error=LogFormatError)


@dataclass
class _Summary:
    """What the footer and summary section at the end of the source say (empty if unreadable)."""

    footer_at: int | None = None        # byte offset of the footer record
    data_end: int | None = None         # where the data section ends (the summary's start)
    crc_ok: bool | None = None          # summary CRC: True/False, None when not stored or no summary
    damaged: bool = False               # some summary records do not parse
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    chunk_indexes: list[ChunkIndex] = field(default_factory=list)
    metadata_indexes: list[MetadataIndex] = field(default_factory=list)
    attachment_indexes: list[AttachmentIndex] = field(default_factory=list)
    statistics: Statistics | None = None


def _read_summary(buf, size: int) -> _Summary:
    """The footer and the summary section it points at; an empty _Summary when the footer is unreadable."""
    s = _Summary()
    fpos = size - len(_MAGIC) - _FOOTER_BYTES
    if fpos < len(_MAGIC):
        return s
    op, length = _HEAD.unpack_from(buf, fpos)
    if op != _FOOTER or length != 20:
        return s
    start, offsets_start, crc = struct.unpack_from("<QQI", buf, fpos + 9)
    s.footer_at = fpos
    if start == 0:                       # a finished file without a summary section
        s.data_end = fpos
        return s
    if not len(_MAGIC) <= start <= fpos:
        return s
    s.data_end = start
    stop = offsets_start if start <= offsets_start <= fpos else fpos
    if crc:
        s.crc_ok = _crc(buf, start, fpos + 9 + 16) == crc
    groups: list[int] = []               # group starts from the summary offsets: resync points
    p = stop
    while p + 9 <= fpos:
        op, length = _HEAD.unpack_from(buf, p)
        if op != _SUMMARY_OFFSET or p + 9 + length > fpos:
            break
        rec = _parse(op, bytes(buf[p + 9:p + 9 + length]))
        if rec is not None and start <= rec.group_start < stop:
            groups.append(rec.group_start)
        p += 9 + length
    groups.sort()
    p = start
    while p < stop:
        op, length = _HEAD.unpack_from(buf, p) if p + 9 <= stop else (0, 0)
        end = p + 9 + length
        if p + 9 > stop or end > stop or op not in _PARSERS:
            s.damaged = True
            k = bisect_right(groups, p)
            if k == len(groups):
                break
            p = groups[k]
            continue
        rec = _parse(op, bytes(buf[p + 9:end]))
        if rec is None:
            s.damaged = True
        elif op == _SCHEMA:
            s.schemas.setdefault(rec.id, rec)
        elif op == _CHANNEL:
            s.channels.setdefault(rec.id, rec)
        elif op == _CHUNK_INDEX:
            s.chunk_indexes.append(rec)
        elif op == _METADATA_INDEX:
            s.metadata_indexes.append(rec)
        elif op == _ATTACHMENT_INDEX:
            s.attachment_indexes.append(rec)
        elif op == _STATISTICS:
            s.statistics = rec
        p = end
    return s


def _stats_count(stats: Statistics | None, crc_ok: bool | None) -> int | None:
    """The statistics' message count when it can be trusted: the summary's CRC matches, or the
    count equals the sum of the per-channel counts (one damaged field breaks that)."""
    if stats is None:
        return None
    if crc_ok or stats.message_count == sum(stats.channel_message_counts.values()):
        return stats.message_count
    return None


@dataclass
class _ChunkAt:
    """A chunk record's layout in the source."""

    pos: int                 # byte offset of the record
    end: int                 # byte offset after it
    t0: int
    t1: int
    size: int                # declared uncompressed size [bytes]
    crc: int
    compression: str
    data: int                # byte offset of the compressed records
    data_len: int
    index: ChunkIndex | None = None


# --------------------------------------------------------------------------------------------
# the salvage walk
# --------------------------------------------------------------------------------------------


class _Salvage:
    """One walk over the source ``buf`` that writes what it reads to ``w``."""

    def __init__(self, buf, w: Writer) -> None:
        self.buf, self.size, self.w = buf, len(buf), w
        self.summary = _read_summary(buf, self.size)
        s = self.summary
        self.data_end = s.data_end if s.data_end is not None else self.size
        trust_index = s.crc_ok is not False
        self.anchors = {c.chunk_start_offset: c for c in s.chunk_indexes
                        if len(_MAGIC) <= c.chunk_start_offset < self.data_end and trust_index}
        starts = set(self.anchors)
        starts.update(m.offset for m in s.metadata_indexes)
        starts.update(a.offset for a in s.attachment_indexes)
        self.known_starts = sorted(p for p in starts if len(_MAGIC) <= p < self.data_end)
        self.started = False
        self.header_read = False
        self.in_summary = False              # walked past a data end record (no readable footer)
        self.summary_from: int | None = None  # where the summary section starts, found so
        self.late_stats: Statistics | None = None
        self.late_schemas: dict[int, Schema] = {}
        self.late_channels: dict[int, Channel] = {}
        self.data_schemas: dict[int, tuple[Schema, bool]] = {}     # id -> (record, from verified bytes)
        self.data_channels: dict[int, tuple[Channel, bool]] = {}
        self.out_schema: dict[int, int] = {}
        self.out_channel: dict[int, int] = {}
        self.pending: list[tuple] = []       # messages of channels not (yet) defined
        self.no_channel: dict[int, int] = {}
        self.written = 0
        self.unverified = 0
        self.top_level = 0                   # messages outside chunks
        self.chunk_losses: list[int | None] = []
        self.gaps: list[tuple[int, int, str]] = []       # unread byte ranges and why
        self.unknown = 0                     # unread regions that may have held an unknown number of messages
        self.undefined: set[int] = set()     # channel ids looked up without a definition since the last one
        self.damaged_chunks: list[int] = []
        self.unverified_chunks: list[int] = []
        self.skipped: list[tuple[int, int]] = []
        self.unreadable: list[str] = []
        self.notes: list[str] = []
        self.unverified_attachments: list[int] = []
        self.metadata_seen: set[int] = set()
        self.attachment_seen: set[int] = set()
        self.records_found = 0
        self.stopped = "end of file"

    # -- output --------------------------------------------------------------------------------

    def _start(self, profile: str = "", library: str = "livesweep") -> None:
        if not self.started:
            self.w.start(profile=profile, library=library)
            self.started = True

    @staticmethod
    def _best(key: int, data: dict, summary: dict, trusted: bool):
        d = data.get(key)
        if d is not None and d[1]:
            return d[0]
        if trusted and key in summary:
            return summary[key]
        if d is not None:
            return d[0]
        return summary.get(key)

    def _schema_id(self, sid: int, topic: str) -> int:
        if sid == 0:
            return 0
        out = self.out_schema.get(sid)
        if out is None:
            late = {**self.late_schemas, **self.summary.schemas}
            sch = self._best(sid, self.data_schemas, late, self.summary.crc_ok is not False)
            if sch is None:
                self.unreadable.append(f"schema id {sid} of topic {topic!r}: no readable schema record; the channel "
                                       "is written without a schema")
                out = 0
            else:
                self._start()
                out = self.w.register_schema(sch.name, sch.encoding, sch.data)
            self.out_schema[sid] = out
        return out

    def _channel_id(self, cid: int) -> int | None:
        out = self.out_channel.get(cid)
        if out is None:
            if cid in self.undefined:
                return None
            late = {**self.late_channels, **self.summary.channels}
            ch = self._best(cid, self.data_channels, late, self.summary.crc_ok is not False)
            if ch is None:
                self.undefined.add(cid)
                return None
            sid = self._schema_id(ch.schema_id, ch.topic)
            self._start()
            out = self.out_channel[cid] = self.w.register_channel(ch.topic, ch.message_encoding, sid,
                                                                   dict(ch.metadata))
        return out

    def _message(self, cid: int, seq: int, log_t: int, pub_t: int, data: bytes, unverified: bool) -> None:
        out = self._channel_id(cid)
        if out is None:
            self.pending.append((cid, seq, log_t, pub_t, data, unverified))
            return
        self.w.add_message(out, log_t, data, pub_t, seq)
        self.written += 1
        self.unverified += unverified

    def _define(self, rec, verified: bool) -> None:
        table = self.data_schemas if isinstance(rec, Schema) else self.data_channels
        self.undefined.clear()
        old = table.get(rec.id)
        if old is None or (verified and not old[1]):
            table[rec.id] = (rec, verified)

    # -- records -------------------------------------------------------------------------------

    def _plausible(self, p: int) -> bool:
        """Whether a record can start at ``p`` (or the data section ends there)."""
        if p == self.data_end or p in self.anchors:
            return True
        if p + 9 > self.data_end:
            return False
        op, length = _HEAD.unpack_from(self.buf, p)
        return op in _NAMES and p + 9 + length <= self.data_end

    def _followed(self, p: int) -> bool:
        """Whether two plausible records start at ``p`` (one where the data section ends there): the
        check before trusting a length read from fields rather than from the record's prefix."""
        if not self._plausible(p):
            return False
        if p == self.data_end or p in self.anchors:
            return True
        return self._plausible(p + 9 + _HEAD.unpack_from(self.buf, p)[1])

    def _chunk_at(self, pos: int, index: ChunkIndex | None = None) -> _ChunkAt | None:
        """The chunk record at ``pos`` read from its own fields, which must fill its length (from its
        prefix, or from ``index`` when given) exactly; or, when only its records length disagrees and a
        plausible record follows, with its records running to that length; else laid out by ``index``.
        None when none of these gives a consistent layout."""
        buf = self.buf
        body = pos + 9
        length = index.chunk_length - 9 if index is not None else _HEAD.unpack_from(buf, pos)[1]
        end = body + length
        if length >= _CHUNK_MIN and end <= self.data_end:
            t0, t1, size, crc, clen = _CHUNK_HEAD.unpack_from(buf, body)
            kind = bytes(buf[body + 32:body + 32 + clen]) if clen <= 4 else None
            if kind in _COMPRESSIONS and body + 32 + clen + 8 <= end:
                (rlen,) = struct.unpack_from("<Q", buf, body + 32 + clen)
                data = body + 32 + clen + 8
                if data + rlen == end:
                    return _ChunkAt(pos, end, t0, t1, size, crc, kind.decode(), data, rlen, index)
                if self._followed(end):              # its records length is damaged: the record's length says
                    return _ChunkAt(pos, end, t0, t1, size, crc, kind.decode(), data, end - data, index)
        if index is not None and end <= self.data_end and index.compressed_size <= length - _CHUNK_MIN:
            # the chunk's own fields are damaged: its layout from the chunk index (the CRC stays its own)
            crc = struct.unpack_from("<I", buf, body + 24)[0]
            return _ChunkAt(pos, end, index.message_start_time, index.message_end_time, index.uncompressed_size,
                            crc, index.compression, end - index.compressed_size, index.compressed_size, index)
        return None

    def _indexes(self, c: _ChunkAt) -> list[MessageIndex] | None:
        """The message index records of chunk ``c`` (from the chunk index, else those right after it)."""
        out = []
        if c.index is not None:
            for off in c.index.message_index_offsets.values():
                if not (0 < off and off + 9 <= self.data_end):
                    return None
                op, length = _HEAD.unpack_from(self.buf, off)
                rec = _parse(op, bytes(self.buf[off + 9:off + 9 + length])) if op == _MESSAGE_INDEX else None
                if rec is None or off + 9 + length > self.data_end:
                    return None
                out.append(rec)
            return out
        q = c.end
        while q + 9 <= self.data_end and self.buf[q] == _MESSAGE_INDEX:
            length = _HEAD.unpack_from(self.buf, q)[1]
            if q + 9 + length > self.data_end:
                return None
            rec = _parse(_MESSAGE_INDEX, bytes(self.buf[q + 9:q + 9 + length]))
            if rec is None:
                return None
            out.append(rec)
            q += 9 + length
        return out or None

    def _chunk_text(self, c: _ChunkAt) -> str:
        return f"the chunk at byte {c.pos} ({c.end - c.pos} bytes, log times {c.t0} to {c.t1} ns)"

    def _chunk(self, c: _ChunkAt) -> None:
        """Copy chunk ``c``: whole when it decompresses and matches its CRC; what parses, unverified, when
        it decompresses but fails its CRC; nothing (its messages counted as lost) when it does not
        decompress."""
        self.records_found += 1
        try:
            data = _inflate(c.compression, bytes(self.buf[c.data:c.data + c.data_len]), c.size)
        except Exception as e:  # noqa: BLE001 - zstd/lz4 errors, ValueError: damaged bytes
            idx = self._indexes(c)
            n = None if idx is None else sum(len(m.records) for m in idx)
            self.chunk_losses.append(n)
            self.damaged_chunks.append(c.pos)
            self.skipped.append((c.pos, c.end))
            lost = (f"its {n} messages are lost" if n is not None
                    else "the messages in it are lost (how many is unknown)")
            self.unreadable.append(f"{self._chunk_text(c)} does not decompress "
                                   f"({c.compression or 'uncompressed'}: {type(e).__name__}: {e}); {lost}")
            return
        verified = len(data) == c.size and (c.crc == 0 or zlib.crc32(data) == c.crc)
        before = self.written + len(self.pending)
        parsed, broke = self._chunk_records(data, 0, len(data), verified)
        if verified and broke is None:
            return
        # the chunk fails its CRC check (or its records do not parse): what parses is kept, unverified
        idx = self._indexes(c)
        if broke is not None and idx is not None:
            offsets = sorted({off for m in idx for _t, off in m.records if off >= broke})
            for k, off in enumerate(offsets):
                parsed += self._indexed_message(data, off, offsets[k + 1] if k + 1 < len(offsets) else len(data))
        elif broke is not None:
            parsed += self._overlong_message(data, broke)
        if verified:                                 # CRC matches but the records do not parse
            self.notes.append(f"{self._chunk_text(c)} matches its CRC but its records stop parsing at byte {broke} "
                              "of its uncompressed records")
        n = None if idx is None else sum(len(m.records) for m in idx)
        lost_here = None if n is None and broke is not None else max(0, (n or 0) - parsed)
        self.chunk_losses.append(lost_here)
        if not verified:
            self.unverified_chunks.append(c.pos)
            why = (f"decompresses to {len(data)} bytes, not the {c.size} it declares" if len(data) != c.size
                   else f"fails its CRC check (stored {c.crc:#010x}, computed {zlib.crc32(data):#010x})")
            kept = self.written + len(self.pending) - before
            self.notes.append(f"{self._chunk_text(c)} {why}: {kept} of its messages were kept, unverified")
        if lost_here:
            self.unreadable.append(f"{self._chunk_text(c)}: {lost_here} of its messages do not parse and are lost")
        elif lost_here is None:
            self.unreadable.append(f"{self._chunk_text(c)}: its records stop parsing at byte {broke} of {len(data)}; "
                                   "the messages after that are lost (how many is unknown: no message index)")

    def _chunk_records(self, data: bytes, p: int, stop: int, verified: bool) -> tuple[int, int | None]:
        """Copy the records of a decompressed chunk; (message records parsed, offset where parsing
        broke or None)."""
        n = 0
        unverified = not verified
        while p < stop:
            if p + 9 > stop:
                return n, p
            op, length = _HEAD.unpack_from(data, p)
            end = p + 9 + length
            if op in (_SCHEMA, _CHANNEL):
                rec = _parse(op, data[p + 9:end]) if end <= stop else None
                if rec is None and (end == stop or end + 9 <= stop and data[end] in (_SCHEMA, _CHANNEL, _MESSAGE)):
                    p = end                          # damaged, but its length prefix is not: skipped
                    continue
                if rec is None:                      # a damaged length? the record's fields say where it ends
                    got = _parse_by_fields(op, data, p + 9, stop)
                    if got is None:
                        return n, p
                    rec, blen = got
                    end = p + 9 + blen
                    if end < stop and (data[end] not in (_SCHEMA, _CHANNEL, _MESSAGE) or end + 9 > stop):
                        return n, p
                self._define(rec, verified)
                p = end
                continue
            if end > stop:
                return n, p
            if op == _MESSAGE:
                if length < _MSG_HEAD:
                    return n, p
                cid, seq, log_t, pub_t = _MSG.unpack_from(data, p + 9)
                self._message(cid, seq, log_t, pub_t, data[p + 9 + _MSG_HEAD:end], unverified)
                n += 1
            p = end                                  # other records in a chunk: skipped, as MCAP readers do
        return n, None

    def _indexed_message(self, data: bytes, off: int, bound: int) -> int:
        """Copy the message a message index places at ``off`` (bounded by the next indexed one), unverified."""
        if off + 9 + _MSG_HEAD > len(data) or data[off] != _MESSAGE:
            return 0
        length = _HEAD.unpack_from(data, off)[1]
        end = off + 9 + length if _MSG_HEAD <= length and off + 9 + length <= bound else bound
        cid, seq, log_t, pub_t = _MSG.unpack_from(data, off + 9)
        self._message(cid, seq, log_t, pub_t, data[off + 9 + _MSG_HEAD:end], True)
        return 1

    def _overlong_message(self, data: bytes, off: int) -> int:
        """A message record whose length runs past its chunk: its bytes up to the chunk's end, unverified
        (what mcap's reader returns for it)."""
        if off + 9 + _MSG_HEAD > len(data) or data[off] != _MESSAGE:
            return 0
        if _HEAD.unpack_from(data, off)[1] < _MSG_HEAD:
            return 0
        cid, seq, log_t, pub_t = _MSG.unpack_from(data, off + 9)
        self._message(cid, seq, log_t, pub_t, data[off + 9 + _MSG_HEAD:], True)
        return 1

    def _record(self, pos: int, op: int, length: int) -> bool:
        """Read the record (not a chunk) at ``pos``; False when it does not parse."""
        buf = self.buf
        end = pos + 9 + length
        if op == _MESSAGE:
            if length < _MSG_HEAD:
                return False
            cid, seq, log_t, pub_t = _MSG.unpack_from(buf, pos + 9)
            self.top_level += 1
            self._message(cid, seq, log_t, pub_t, bytes(buf[pos + 9 + _MSG_HEAD:end]), False)
            self.records_found += 1
            return True
        if op == _MESSAGE_INDEX:                     # rebuilt by the writer: only its framing is checked
            return length >= 6 and struct.unpack_from("<I", buf, pos + 11)[0] == length - 6 and (length - 6) % 16 == 0
        if op not in _PARSERS:
            return False
        rec = _parse(op, bytes(buf[pos + 9:end]))
        if rec is None:
            return False
        self.records_found += 1
        if op == _HEADER:
            if not self.started:
                self._start(rec.profile, rec.library)
                self.header_read = True
        elif op in (_SCHEMA, _CHANNEL):
            if self.in_summary:
                (self.late_schemas if op == _SCHEMA else self.late_channels).setdefault(rec.id, rec)
                self.undefined.clear()
            else:
                self._define(rec, True)
        elif op == _METADATA:
            self._start()
            self.metadata_seen.add(pos)
            self.w.add_metadata(rec.name, dict(rec.metadata))
        elif op == _ATTACHMENT:
            self._start()
            self.attachment_seen.add(pos)
            (stored,) = struct.unpack_from("<I", buf, end - 4)
            if stored and zlib.crc32(buf[pos + 9:end - 4]) != stored:
                self.unverified_attachments.append(pos)
                self.unreadable.append(f"the attachment {rec.name!r} at byte {pos} fails its CRC check (copied as it "
                                       "is; its contents may be wrong)")
            self.w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, bytes(rec.data))
        elif op == _DATA_END:
            if rec.data_section_crc and _crc(buf, 0, pos) != rec.data_section_crc:
                if self.top_level:
                    self.unverified += self.top_level
                    self.notes.append(f"the data section fails its CRC check: the {self.top_level} messages "
                                      "outside chunks are unverified")
                else:
                    self.notes.append("the data section fails its CRC check (the chunks are checked one by one)")
            if self.summary.data_end is None:
                self.in_summary = True
                self.summary_from = end
        elif op == _STATISTICS and self.in_summary:
            self.late_stats = rec
        return True

    def _acceptable(self, q: int) -> _ChunkAt | bool:
        """Whether the scan can resume at ``q``: a chunk (returned) or another record that parses
        exactly and is followed by a plausible record."""
        op, length = _HEAD.unpack_from(self.buf, q)
        end = q + 9 + length
        if end > self.data_end:
            return False
        if op == _CHUNK:
            c = self._chunk_at(q)
            return c if c is not None and self._looks_like_chunk(c) else False
        if not self._plausible(end):
            return False
        if op == _MESSAGE:
            if length < _MSG_HEAD:
                return False
            cid = struct.unpack_from("<H", self.buf, q + 9)[0]
            return cid in self.data_channels or cid in self.summary.channels
        return _parse(op, bytes(self.buf[q + 9:end])) is not None

    def _resync(self, pos: int, why: str) -> int:
        """The offset where reading resumes after the unreadable record at ``pos``; notes the gap."""
        k = bisect_right(self.known_starts, pos)
        limit = self.known_starts[k] if k < len(self.known_starts) else self.data_end
        q = pos + 1
        nxt = limit
        while q < limit:
            m = _CANDIDATE.search(self.buf, q, limit)
            if m is None or m.start() + 9 > limit:
                break
            q = m.start()
            if self._acceptable(q):
                nxt = q
                break
            q += 1
        self._gap(pos, nxt, why)
        return nxt

    def _gap(self, a: int, b: int, why: str) -> None:
        """Note the unread bytes ``[a, b)``; whether anything was lost in them is decided in :meth:`finish`."""
        self.skipped.append((a, b))
        self.gaps.append((a, b, why))

    def walk(self) -> None:
        """Read the data section record by record, copying what reads and stepping over what does not."""
        buf, data_end = self.buf, self.data_end
        if self.size < len(_MAGIC) or bytes(buf[:len(_MAGIC)]) != _MAGIC:
            self.notes.append("the file does not start with the MCAP magic bytes (damaged); records after them "
                              "were read")
        pos = len(_MAGIC)
        while pos < data_end:
            index = self.anchors.get(pos)
            if index is not None:
                c = self._chunk_at(pos, index)
                if c is not None:
                    op, length = _HEAD.unpack_from(buf, pos)
                    if op != _CHUNK or length != c.end - pos - 9:
                        self.notes.append(f"the chunk at byte {pos} has a damaged opcode or length; "
                                          "read where the summary's chunk index places it")
                    self._chunk(c)
                    pos = c.end
                    continue
            if pos + 9 > data_end:
                pos = self._resync(pos, "a record cut off")
                continue
            op, length = _HEAD.unpack_from(buf, pos)
            end = pos + 9 + length
            framed = end <= data_end and (0 < op <= 0x0F or op >= 0x80)
            if framed and op == _CHUNK:
                c = self._chunk_at(pos)
                if c is not None:
                    self._chunk(c)
                    pos = c.end
                    continue
            elif framed and op == _FOOTER and end + len(_MAGIC) >= self.size and self._record(pos, op, length):
                self.stopped = "the footer"
                return
            elif framed and op not in (_FOOTER, _CHUNK) and op < 0x80 and self._record(pos, op, length):
                pos = end
                continue
            c = self._chunk_by_fields(pos)           # a chunk whose opcode or length is damaged?
            if c is not None:
                self.notes.append(f"the chunk at byte {pos} has a damaged opcode or length (opcode {op:#04x}, "
                                  f"length {length}); read with the length its own fields give")
                self._chunk(c)
                pos = c.end
                continue
            what = _NAMES.get(op, f"opcode {op:#04x}")
            if framed and self._plausible(end):      # the record is damaged, its length prefix is not
                if op < 0x80:                        # a private record (0x80 and up) is skipped, as readers do
                    self.skipped.append((pos, end))
                    self._lost_record(pos, end, op, what)
                pos = end
                continue
            if op in _SELF_DELIMITED:                # a damaged length? the record's fields say where it ends
                got = _parse_by_fields(op, buf, pos + 9, data_end)
                if got is not None and self._followed(pos + 9 + got[1]) and self._record(pos, op, got[1]):
                    self.notes.append(f"the {what} record at byte {pos} has a damaged length ({length}); "
                                      f"read with the length its fields give ({got[1]})")
                    pos += 9 + got[1]
                    continue
            if end > data_end:
                why = f"a length of {length} bytes that runs past the end"
            elif not framed:
                why = f"an unknown opcode {op:#04x}"
            else:
                why = f"a {what} record that does not parse"
            pos = self._resync(pos, why)

    def _chunk_by_fields(self, pos: int) -> _ChunkAt | None:
        """The chunk at ``pos`` laid out by its own fields (compression, records length) whatever its
        opcode and length prefix say; None unless it ends where a plausible record starts or decompresses."""
        buf, body = self.buf, pos + 9
        if body + _CHUNK_MIN > self.data_end:
            return None
        t0, t1, size, crc, clen = _CHUNK_HEAD.unpack_from(buf, body)
        if clen > 4 or body + _CHUNK_MIN + clen > self.data_end \
                or bytes(buf[body + 32:body + 32 + clen]) not in _COMPRESSIONS:
            return None
        (rlen,) = struct.unpack_from("<Q", buf, body + 32 + clen)
        data = body + 32 + clen + 8
        if data + rlen > self.data_end:
            return None
        c = _ChunkAt(pos, data + rlen, t0, t1, size, crc, bytes(buf[body + 32:body + 32 + clen]).decode(), data, rlen)
        return c if self._looks_like_chunk(c) else None

    def _looks_like_chunk(self, c: _ChunkAt) -> bool:
        """Whether ``c``, found by its fields rather than by its framing, is a chunk: it holds records, its
        time range is ordered, and a plausible record follows it or its records decompress and start
        with a schema, channel or message record."""
        if c.data_len == 0 or c.t0 > c.t1:
            return False
        if self._followed(c.end):
            return True
        if c.compression == "":
            return False
        try:
            out = _inflate(c.compression, bytes(self.buf[c.data:c.end]), c.size)
        except Exception:  # noqa: BLE001 - not a chunk after all
            return False
        return len(out) >= 9 and out[0] in (_SCHEMA, _CHANNEL, _MESSAGE) and 9 + _HEAD.unpack_from(out)[1] <= len(out)

    def _lost_record(self, pos: int, end: int, op: int, what: str) -> None:
        """Account for the record at ``pos`` that does not parse (its framing is intact)."""
        if op in (_MESSAGE_INDEX, _HEADER, _FOOTER, _DATA_END, _CHUNK_INDEX, _STATISTICS, _SUMMARY_OFFSET,
                  _METADATA_INDEX, _ATTACHMENT_INDEX):
            self.notes.append(f"the {what} record at byte {pos} ({end - pos} bytes) does not parse; skipped "
                              "(it holds no data)")
        elif op in (_SCHEMA, _CHANNEL):
            self.notes.append(f"the {what} record at byte {pos} does not parse; skipped (a channel it defined "
                              "is taken from the summary when that repeats it)")
        elif op == _METADATA:
            self.metadata_seen.add(pos)
            name = next((m.name for m in self.summary.metadata_indexes if m.offset == pos), None)
            self.unreadable.append(f"the metadata record {name!r} at byte {pos} does not parse: lost" if name else
                                   f"a metadata record at byte {pos} does not parse: lost")
        elif op == _ATTACHMENT:
            self.attachment_seen.add(pos)
            name = next((a.name for a in self.summary.attachment_indexes if a.offset == pos), None)
            self.unreadable.append(f"the attachment {name!r} at byte {pos} does not parse: lost" if name else
                                   f"an attachment at byte {pos} does not parse: lost")
        else:                                        # a message outside chunks
            self.unknown += 1
            self.unreadable.append(f"the {what} record at byte {pos} ({end - pos} bytes) does not parse: lost")

    def finish(self) -> tuple[int | None, int | None]:
        """Write what is pending and the channels without messages; (expected, lost)."""
        if not self.header_read:
            self.unreadable.append(f"the header record at byte {len(_MAGIC)} (the writer's profile and library) "
                                   "could not be read: the output's header says profile '' and library 'livesweep'")
        self._start()
        for cid, seq, log_t, pub_t, data, unverified in self.pending:
            out = self._channel_id(cid)
            if out is None:
                self.no_channel[cid] = self.no_channel.get(cid, 0) + 1
                continue
            self.w.add_message(out, log_t, data, pub_t, seq)
            self.written += 1
            self.unverified += unverified
        for cid, n in sorted(self.no_channel.items()):
            self.unreadable.append(f"{n} messages on channel id {cid}, which has no readable channel record "
                                   "(its topic is unknown): lost")
        verified = {cid for cid, (_c, ok) in self.data_channels.items() if ok}
        for cid in sorted({*verified, *self.summary.channels, *self.late_channels}):
            self._channel_id(cid)                    # channels without messages are kept too
        missing = 0
        for m in self.summary.metadata_indexes:
            if m.offset not in self.metadata_seen:
                missing += 1
                self.unreadable.append(f"the metadata record {m.name!r} at byte {m.offset} was not found: lost")
        for a in self.summary.attachment_indexes:
            if a.offset not in self.attachment_seen:
                missing += 1
                self.unreadable.append(f"the attachment {a.name!r} at byte {a.offset} was not found: lost")
        s = self.summary
        expected = _stats_count(s.statistics, s.crc_ok)
        if expected is None and s.statistics is None and self.late_stats is not None:
            expected = _stats_count(self.late_stats, None)
        accounted = expected is not None and self.written >= expected and not missing
        for a, b, why in self.gaps:
            self._account_gap(a, b, why, accounted)
        if expected is not None:
            lost = max(0, expected - self.written)
            if self.written > expected:
                self.notes.append(f"{self.written} messages written, more than the {expected} the statistics "
                                  "record counts: some unverified messages may be damaged copies")
        elif self.unknown or any(n is None for n in self.chunk_losses):
            lost = None
        else:
            lost = sum(self.chunk_losses) + sum(self.no_channel.values())
        if s.footer_at is None:
            self.notes.append("the source has no readable footer: it is unfinished (its writer stopped before "
                              "closing it: messages not yet written to disk are not in it) or its end is damaged")
        elif s.data_end is None:
            self.notes.append("the source's footer points at no readable summary section")
        if s.crc_ok is False or s.damaged:
            self.notes.append("the source's summary section is damaged (CRC mismatch or records that do not "
                              "parse); its chunk indexes were used only where a chunk is found")
        return expected, lost

    def _account_gap(self, a: int, b: int, why: str, accounted: bool) -> None:
        """Say what the unread bytes ``[a, b)`` cost; ``accounted``: the summary shows nothing was lost."""
        at_tail = b == self.size and self.summary.footer_at is None
        op = self.buf[a] if a < self.size else None
        what = _NAMES.get(op, "record")
        if at_tail:
            self.stopped = f"{why} at byte {a}"
        if at_tail and op in (_MESSAGE_INDEX, _DATA_END, _CHUNK_INDEX, _STATISTICS, _SUMMARY_OFFSET, _FOOTER,
                              _METADATA_INDEX, _ATTACHMENT_INDEX):
            self.notes.append(f"the last {b - a} bytes (a {what} record cut off at byte {a}) could not be read; "
                              "they hold index or summary records only: no data lost")
        elif self.summary_from is not None and a >= self.summary_from:
            self.notes.append(f"bytes {a} to {b} ({b - a} bytes) of the summary section could not be read ({why} "
                              f"at byte {a}); they hold no data")
        elif accounted:
            self.notes.append(f"bytes {a} to {b} ({b - a} bytes) could not be read ({why} at byte {a}); the "
                              "summary accounts for every message, metadata record and attachment: nothing lost")
        elif at_tail:
            self.unknown += 1
            self.unreadable.append(f"the last {b - a} bytes, from byte {a} ({why}), could not be read (a {what} "
                                   "record cut off when the writer stopped, or damaged bytes): the messages in "
                                   "them are lost (how many is unknown)")
        else:
            self.unknown += 1
            self.unreadable.append(f"bytes {a} to {b} ({b - a} bytes) could not be read ({why} at byte {a})")


def _offsets(values: list[int]) -> str:
    return " ".join(str(v) for v in values)


def recover(path: str | os.PathLike[str], out_path: str | os.PathLike[str], *, overwrite: bool = True) -> RecoverResult:
    """Copy everything readable of an unfinished or damaged MCAP log into a new, finished log.

    Schemas, channels, messages (bytes, times and sequence numbers unchanged), metadata and
    attachments are copied in file order; the header's profile and library are kept. Damage is
    stepped over (see the module documentation): chunks that do not decompress are skipped,
    chunks that fail their CRC check are kept with their messages counted as unverified, and
    reading resumes after broken framing at the next readable record. A metadata record
    ``"livesweep.recover"`` in the output holds the source file, ``messages_recovered``,
    ``messages_expected``, ``messages_lost`` and ``messages_unverified`` (``"unknown"`` when not
    known), the source byte offsets of the ``unverified_chunks`` and ``damaged_chunks``, the
    ``skipped_bytes`` ranges and ``stopped_at`` (where reading of an unfinished file ended). The
    output is written to ``<out_path>.partial`` and renamed, so it is finished or absent.

    Parameters
    ----------
    path : str or os.PathLike
        The unfinished, damaged or finished MCAP file.
    out_path : str or os.PathLike
        Where to write the finished copy; must differ from ``path``.
    overwrite : bool
        Replace an existing ``out_path``; never one another process is writing (a recording in
        progress), whatever this says.

    Returns
    -------
    RecoverResult
        What was written, lost and kept unverified.

    Raises
    ------
    LogFormatError
        The source does not exist, is empty, or holds no MCAP magic and no readable MCAP record;
        the output is the source; the output cannot be written.
    """
    src_p = Path(path)
    out_p = Path(out_path)
    if not src_p.exists():
        raise LogFormatError(f"MCAP log {src_p} does not exist")
    if not src_p.is_file():
        raise LogFormatError(f"MCAP log {src_p} is not a regular file")
    if out_p.exists() and out_p.resolve() == src_p.resolve():
        raise LogFormatError(f"recover: output {out_p} is the input file; choose another path")
    check_file_free(out_p, overwrite=overwrite, what="recover output", error=LogFormatError)
    try:
        size = src_p.stat().st_size
        fi = open(src_p, "rb")  # noqa: SIM115 - closed below
    except OSError as e:
        raise LogFormatError(f"cannot read MCAP log {src_p}: {e.strerror or e}") from e
    if size == 0:
        fi.close()
        raise LogFormatError(f"{src_p} is empty (0 bytes), not an MCAP file")
    tmp = out_p.with_name(out_p.name + ".partial")
    try:
        buf = mmap.mmap(fi.fileno(), 0, access=mmap.ACCESS_READ)
    except (OSError, ValueError) as e:
        fi.close()
        raise LogFormatError(f"cannot read MCAP log {src_p}: {e}") from e
    try:
        try:
            fo = open(tmp, "wb")  # noqa: SIM115 - closed below
        except OSError as e:
            raise LogFormatError(f"cannot write recovered MCAP log {out_p}: {e.strerror or e}") from e
        try:
            w = Writer(fo, chunk_size=_OUT_CHUNK_BYTES, compression=CompressionType.ZSTD)
            sal = _Salvage(buf, w)
            sal.walk()
            if sal.records_found == 0 and bytes(buf[:len(_MAGIC)]) != _MAGIC:
                raise LogFormatError(f"{src_p} is not an MCAP file (it does not start with the MCAP magic bytes "
                                     "and holds no readable MCAP record)")
            expected, lost = sal.finish()
            skipped = _ranges(sal.skipped)
            result = RecoverResult(
                source=str(src_p), output=str(out_p), messages_written=sal.written,
                messages_expected=expected, messages_lost=lost, messages_unverified=sal.unverified,
                damaged_chunks=tuple(sal.damaged_chunks), unverified_chunks=tuple(sal.unverified_chunks),
                skipped_bytes=tuple(skipped), unreadable=tuple(sal.unreadable),
                complete_source=sal.summary.footer_at is not None and sal.summary.data_end is not None,
                notes=tuple(sal.notes),
            )
            w.add_metadata(RECOVER_METADATA_NAME, {
                "source": str(src_p),
                "messages_recovered": str(sal.written),
                "messages_expected": "unknown" if expected is None else str(expected),
                "messages_lost": "unknown" if lost is None else str(lost),
                "messages_unverified": str(sal.unverified),
                "unverified_chunks": _offsets(sal.unverified_chunks),
                "damaged_chunks": _offsets(sal.damaged_chunks),
                "unverified_attachments": _offsets(sal.unverified_attachments),
                "skipped_bytes": " ".join(f"{a}-{b}" for a, b in skipped),
                "stopped_at": sal.stopped,
            })
            w.finish()
            fo.flush()
            os.fsync(fo.fileno())
            fo.close()
            _install(tmp, out_p, overwrite)
        except BaseException as e:
            fo.close()
            tmp.unlink(missing_ok=True)
            if isinstance(e, OSError):
                raise LogFormatError(f"cannot write recovered MCAP log {out_p}: {e}") from e
            raise
    finally:
        buf.close()
        fi.close()
    return result
