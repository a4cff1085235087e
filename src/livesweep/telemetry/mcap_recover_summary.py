"""The footer and summary section at the end of an MCAP file, read for a salvage.

One job: what the end of the source says (:func:`_read_summary`): where the data section ends,
whether the summary's CRC matches, and the schemas, channels, chunk, metadata and attachment
indexes and statistics it repeats, read record by record past damage (resuming at the group starts
its summary offsets give); and the statistics' message count when it can be trusted
(:func:`_stats_count`). Part of :func:`~livesweep.telemetry.mcap_recover.recover`.
"""

from __future__ import annotations

import struct
from bisect import bisect_right
from dataclasses import dataclass, field

from mcap.records import AttachmentIndex, Channel, ChunkIndex, MetadataIndex, Schema, Statistics

from livesweep.telemetry.mcap_log import _MAGIC
from livesweep.telemetry.mcap_recover_records import (_ATTACHMENT_INDEX, _CHANNEL, _CHUNK_INDEX, _FOOTER, _FOOTER_BYTES,
                                                      _HEAD, _METADATA_INDEX, _PARSERS, _SCHEMA, _STATISTICS,
                                                      _SUMMARY_OFFSET, _crc, _parse)

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

