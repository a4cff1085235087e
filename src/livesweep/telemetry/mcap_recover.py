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

Modules: this module holds :func:`recover` (open the source, write to ``<out_path>.partial``,
install it). The work is done in :mod:`~livesweep.telemetry.mcap_recover_scan` (the walk over the
damaged file), :mod:`~livesweep.telemetry.mcap_recover_records` (records read from damaged bytes),
:mod:`~livesweep.telemetry.mcap_recover_summary` (the footer and summary section),
:mod:`~livesweep.telemetry.mcap_recover_copy` (the finished copy's records) and
:mod:`~livesweep.telemetry.mcap_recover_losses` (what was lost, :class:`RecoverResult`).
"""

from __future__ import annotations

import mmap
import os
from pathlib import Path

from mcap.writer import CompressionType, Writer

from livesweep.errors import LogFormatError
from livesweep.locks import check_file_free, install_file
from livesweep.telemetry.mcap_log import _MAGIC, _MAX_CHUNK_BYTES
from livesweep.telemetry.mcap_recover_copy import _SalvageCopy
from livesweep.telemetry.mcap_recover_losses import RecoverResult, _offsets, _ranges, _SalvageLosses
from livesweep.telemetry.mcap_recover_records import (_ATTACHMENT, _ATTACHMENT_INDEX, _CANDIDATE, _CHANNEL, _CHUNK,
                                                      _CHUNK_HEAD, _CHUNK_INDEX, _CHUNK_MIN, _COMPRESSIONS, _DATA_END,
                                                      _FOOTER, _FOOTER_BYTES, _HEAD, _HEADER, _MESSAGE,
                                                      _MESSAGE_INDEX, _METADATA, _METADATA_INDEX, _MSG, _MSG_HEAD,
                                                      _NAMES, _PARSERS, _SCHEMA, _SELF_DELIMITED, _STATISTICS,
                                                      _SUMMARY_OFFSET, _ChunkAt, _crc, _inflate, _parse,
                                                      _parse_by_fields, _View)
from livesweep.telemetry.mcap_recover_scan import _Salvage
from livesweep.telemetry.mcap_recover_summary import _read_summary, _stats_count, _Summary

__all__ = ["RECOVER_METADATA_NAME", "RecoverResult", "recover"]

#: Name of the metadata record :func:`recover` adds to its output.
RECOVER_METADATA_NAME = "livesweep.recover"
_OUT_CHUNK_BYTES = 256 * 1024

#: Names defined in the modules above that are also importable from here.
_MOVED = (
    _MAX_CHUNK_BYTES,
    _HEADER, _FOOTER, _SCHEMA, _CHANNEL, _MESSAGE, _CHUNK, _MESSAGE_INDEX, _CHUNK_INDEX, _ATTACHMENT,
    _ATTACHMENT_INDEX, _STATISTICS, _METADATA, _METADATA_INDEX, _SUMMARY_OFFSET, _DATA_END, _NAMES, _PARSERS,
    _HEAD, _MSG, _MSG_HEAD, _CHUNK_HEAD, _CHUNK_MIN, _FOOTER_BYTES, _COMPRESSIONS, _CANDIDATE, _SELF_DELIMITED,
    _parse, _View, _parse_by_fields, _inflate, _crc, _ChunkAt,
    _Summary, _read_summary, _stats_count,
    _SalvageCopy, _SalvageLosses,
)


def _install(tmp: Path, out_p: Path, overwrite: bool) -> None:
    """Put the finished ``tmp`` in place at ``out_p``: never over a file another process is writing
    (a recording), nor over an existing one unless ``overwrite`` (:func:`livesweep.locks.install_file`)."""
    install_file(tmp, out_p, overwrite=overwrite, what="recover output", error=LogFormatError)


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
