"""The salvage walk over a damaged MCAP file: :class:`_Salvage`.

One job: read the source's data section record by record and hand what reads to the copy
(:mod:`~livesweep.telemetry.mcap_recover_copy`), stepping over damage: chunks found by their
framing, by the summary's chunk index or by their own fields; a chunk that does not decompress
skipped, one that fails its CRC check copied as far as its records parse (and again from its
message index); records read by their fields when their length prefix is damaged; and, where
nothing reads, a resynchronising scan to the next plausible record. What is stepped over is
noted for :mod:`~livesweep.telemetry.mcap_recover_losses`. The rules are described in
:mod:`livesweep.telemetry.mcap_recover`.
"""

from __future__ import annotations

import struct
import zlib
from bisect import bisect_right

from mcap.records import Channel, ChunkIndex, MessageIndex, Schema, Statistics
from mcap.writer import Writer

from livesweep.telemetry.mcap_log import _MAGIC
from livesweep.telemetry.mcap_recover_copy import _SalvageCopy
from livesweep.telemetry.mcap_recover_losses import _SalvageLosses
from livesweep.telemetry.mcap_recover_records import (_ATTACHMENT, _CANDIDATE, _CHANNEL, _CHUNK, _CHUNK_HEAD,
                                                      _CHUNK_MIN, _COMPRESSIONS, _DATA_END, _FOOTER, _HEAD, _HEADER,
                                                      _MESSAGE, _MESSAGE_INDEX, _METADATA, _MSG, _MSG_HEAD, _NAMES,
                                                      _PARSERS, _SCHEMA, _SELF_DELIMITED, _STATISTICS, _ChunkAt,
                                                      _crc, _inflate, _parse, _parse_by_fields)
from livesweep.telemetry.mcap_recover_summary import _read_summary

__all__ = ["_Salvage"]


class _Salvage(_SalvageCopy, _SalvageLosses):
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
