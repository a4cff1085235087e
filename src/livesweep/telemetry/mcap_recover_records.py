"""MCAP records as :func:`~livesweep.telemetry.mcap_recover.recover` reads them from damaged bytes.

One job: the record layer of the salvage. Opcodes and their names and parsers, the record and chunk
headers, a record parsed only when it fills its body exactly (:func:`_parse`) or read by its own
fields whatever its length prefix says (:func:`_parse_by_fields`), a chunk's records decompressed
within a bound (:func:`_inflate`), CRC-32 over a large range (:func:`_crc`), and a chunk's layout in
the source (:class:`_ChunkAt`).
"""

from __future__ import annotations

import re
import struct
import zlib
from dataclasses import dataclass
from io import BytesIO

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

from livesweep.telemetry.mcap_log import _MAX_CHUNK_BYTES

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
