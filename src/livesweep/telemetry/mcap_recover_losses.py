"""What a salvage of an MCAP log lost: the accounting and :class:`RecoverResult`.

One job: the report of :func:`~livesweep.telemetry.mcap_recover.recover`. Each record that does not
parse and each byte range left unread is said in words (lost, or holding no data) and counted; at the
end the messages still held back are written or counted as lost, and the messages expected (from a
statistics record that can be trusted) and lost are worked out. :class:`RecoverResult` is what the
caller gets back.
"""

from __future__ import annotations

from dataclasses import dataclass

from livesweep.telemetry.mcap_log import _MAGIC
from livesweep.telemetry.mcap_recover_records import (_ATTACHMENT, _ATTACHMENT_INDEX, _CHANNEL, _CHUNK_INDEX, _DATA_END,
                                                      _FOOTER, _HEADER, _MESSAGE_INDEX, _METADATA, _METADATA_INDEX,
                                                      _NAMES, _SCHEMA, _STATISTICS, _SUMMARY_OFFSET)
from livesweep.telemetry.mcap_recover_summary import _stats_count

__all__ = ["RecoverResult"]


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


def _ranges(ranges: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """``ranges`` sorted, with touching and overlapping ranges merged."""
    out: list[list[int]] = []
    for a, b in sorted(ranges):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def _offsets(values: list[int]) -> str:
    return " ".join(str(v) for v in values)


class _SalvageLosses:
    """The accounting side of :class:`~livesweep.telemetry.mcap_recover_scan._Salvage`.

    Used as its base class; it reads and extends the salvage's state: ``summary``, ``pending``,
    ``no_channel``, ``metadata_seen``, ``attachment_seen``, ``gaps``, ``chunk_losses``, ``unknown``,
    ``written``, ``unverified``, ``unreadable``, ``notes`` and ``stopped``.
    """

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
