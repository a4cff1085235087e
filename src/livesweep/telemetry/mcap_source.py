"""Opening an MCAP log: check it is one, then read a finished file through its summary section (and indexes)
or stream the records of an unfinished one up to its torn tail.

:func:`open_source` returns a :class:`_Source`: ``summary`` set for a finished file that
``mcap.reader.make_reader`` reads, else ``scan`` (every schema, channel, message, metadata and attachment
record a linear pass found).
Part of :mod:`livesweep.telemetry.mcap_log` (the facade: import from there).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.summary import Summary

from livesweep.errors import LogFormatError
from livesweep.telemetry.mcap_common import _MAGIC, _crc_error_text


@dataclass
class _Scan:
    """Everything a linear pass over the records found (for unfinished or summary-less files)."""

    header: Header | None
    schemas: dict[int, Schema]
    channels: dict[int, Channel]
    messages: list[Message]
    metadata: list[Metadata]
    attachments: list[Attachment]
    tail_error: str
    saw_footer: bool


@dataclass
class _Source:
    path: Path
    complete: bool
    summary: Summary | None  # finished file with a summary section
    scan: _Scan | None  # linear pass (unfinished file, or finished without summary)

    @property
    def channels(self) -> dict[int, Channel]:
        if self.summary is not None:
            return dict(self.summary.channels)
        assert self.scan is not None
        return self.scan.channels

    @property
    def schemas(self) -> dict[int, Schema]:
        if self.summary is not None:
            return dict(self.summary.schemas)
        assert self.scan is not None
        return self.scan.schemas

    def topics(self) -> list[str]:
        return sorted({c.topic for c in self.channels.values()})


def _scan(path: Path) -> _Scan:
    """Stream every record of ``path`` until the end or the first unreadable record."""
    header = None
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    metadata: list[Metadata] = []
    attachments: list[Attachment] = []
    tail_error = ""
    saw_footer = False
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, skip_magic=False, validate_crcs=True).records:
                if isinstance(rec, Message):
                    if rec.channel_id in channels:
                        messages.append(rec)
                elif isinstance(rec, Channel):
                    channels.setdefault(rec.id, rec)
                elif isinstance(rec, Schema):
                    schemas.setdefault(rec.id, rec)
                elif isinstance(rec, Metadata):
                    metadata.append(rec)
                elif isinstance(rec, Attachment):
                    attachments.append(rec)
                elif isinstance(rec, Header):
                    header = rec
                elif isinstance(rec, Footer):
                    saw_footer = True
        except CRCValidationError as e:   # a whole record whose bytes changed: damage, not a torn tail
            raise LogFormatError(_crc_error_text(path, e, f"ending at byte {f.tell()}")) from None
        except Exception as e:  # noqa: BLE001 - truncated tail: EndOfFile, torn zstd/lz4 frame, ...
            tail_error = type(e).__name__ + (f": {e}" if str(e) else "")
    return _Scan(header, schemas, channels, messages, metadata, attachments, tail_error,
                 saw_footer and not tail_error)


def _check_file(p: Path) -> bool:
    """LogFormatError unless ``p`` is a readable file starting with the MCAP magic; whether it also
    ends with it (finished files do)."""
    if not p.exists():
        raise LogFormatError(f"MCAP log {p} does not exist")
    if not p.is_file():
        raise LogFormatError(f"MCAP log {p} is not a regular file")
    try:
        size = p.stat().st_size
        with open(p, "rb") as f:
            head = f.read(len(_MAGIC))
            tail = b""
            if size >= 2 * len(_MAGIC):
                f.seek(-len(_MAGIC), os.SEEK_END)
                tail = f.read(len(_MAGIC))
    except OSError as e:
        raise LogFormatError(f"cannot read MCAP log {p}: {e.strerror or e}") from e
    if size == 0:
        raise LogFormatError(f"{p} is empty (0 bytes), not an MCAP file")
    if head != _MAGIC:
        raise LogFormatError(f"{p} is not an MCAP file (it does not start with the MCAP magic bytes)")
    return tail == _MAGIC


def open_source(path: str | os.PathLike[str]) -> _Source:
    """Check ``path`` is an MCAP file and decide how to read it."""
    p = Path(path)
    if _check_file(p):
        try:
            with open(p, "rb") as f:
                summary = make_reader(f).get_summary()
        except Exception:  # noqa: BLE001 - a torn file that happens to end in the magic bytes
            summary = None
        if summary is not None:
            return _Source(p, True, summary, None)
    # unfinished (no footer), or finished without a summary section: stream the records
    scan = _scan(p)
    return _Source(p, scan.saw_footer, None, scan)


#: The name the MCAP modules use for :func:`open_source`.
_open = open_source


def _topic_list(topics: str | Iterable[str] | None) -> list[str] | None:
    if topics is None:
        return None
    if isinstance(topics, str):
        return [topics]
    return list(topics)
