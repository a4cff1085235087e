"""MCAP logs of JSON messages with JSON Schemas: a small writer and reader.

Contract (docs/outputs.md, MCAP recordings): one channel per telemetry stream, message encoding ``json``, schema
encoding ``jsonschema``, so Foxglove and other MCAP viewers plot the logs as they are.
``log_time`` is the receive time and ``publish_time`` the vehicle time when the message carries
one. Both are integer nanoseconds (uint64) on whatever epoch the producer uses.

Writing
-------
:class:`McapLogWriter` wraps :class:`mcap.writer.Writer`:

* Messages are encoded as compact JSON (``separators=(",", ":")``, ``allow_nan=False``).
  Non-finite floats, also nested in lists and dicts, are written as the strings ``"NaN"``,
  ``"Infinity"`` and ``"-Infinity"`` (:mod:`livesweep.numeric`: JSON has no such numbers, and
  ``null`` would lose which one it was) and counted per topic
  (:attr:`McapLogWriter.nonfinite_counts`); the counts go into a metadata record named
  ``"livesweep.writer"`` when the writer is closed. The column readers read these strings as NaN
  (a missing sample, as ``null``).
* The output is byte-for-byte deterministic for identical calls: no wall clock, no randomness
  (attachment ``create_time`` is the given ``log_time_ns``).
* ``atomic=True`` (default, for simulators and batch tools) writes ``<path>.partial`` and renames
  it onto ``path`` in :meth:`McapLogWriter.close`; an exception inside the ``with`` block, or
  :meth:`McapLogWriter.abort`, deletes the partial file. ``atomic=False`` (live recording)
  writes ``path`` directly and calls ``file.flush()`` every ``flush_every`` messages, so a
  killed process loses at most the open chunk (``chunk_size`` bytes, uncompressed) plus the
  messages since the last flush. Such an unfinished file can be read by the readers below
  (``LogSummary.complete`` is False) and turned into a finished file by
  :func:`livesweep.telemetry.mcap_recover.recover`. A live
  recording is never deleted: :meth:`McapLogWriter.abort`, an exception, or a failure while
  finishing (a full disk) leave it unfinished on disk.

Reading
-------
:func:`read_messages`, :func:`read_summary`, :func:`read_metadata`, :func:`read_attachments` and
:func:`read_fields` accept any MCAP file with JSON channels, not only files
written here. A finished file is read through its summary and indexes
(:func:`mcap.reader.make_reader`); an unfinished file (no footer: the writer was killed before
``finish()``), on which ``make_reader`` fails, is read by streaming every record up to the
truncated tail.

The readers are total: they yield JSON objects or raise
:class:`~livesweep.errors.LogFormatError` naming the file, topic, message (index in its topic
and log time) and field: a message that is not JSON, nests too deeply for the decoder or is not
an object, a field value beyond the float64 range. Chunk CRCs (and the data-section CRC) are
checked whenever the writer stored them: a mismatch means the bytes changed after they were
written, and is an error naming the chunk's byte offset and log-time range rather than a silent
gap or silently wrong values (the damage cannot be bounded below a chunk).
:func:`iter_file_order` (the replay's source) can instead skip and count bad messages and chunks
(:class:`SkippedMessages`). :func:`read_topics_fields` can report, as notes, that a log was
unfinished or recovered.

Modules
-------
This module is the facade: import from here. The work is done in

* :mod:`~livesweep.telemetry.mcap_write`: :class:`McapLogWriter` (schemas and channels, metadata,
  attachments, atomic install or live flushing); its hot path, a message record written straight
  into mcap's open chunk, is :mod:`~livesweep.telemetry.mcap_write_fast`;
* :mod:`~livesweep.telemetry.mcap_read`: :func:`read_messages`, :func:`iter_file_order`,
  :func:`read_metadata`, :func:`read_attachments`, :func:`read_summary` and their records;
* :mod:`~livesweep.telemetry.mcap_columns`: :func:`read_fields`, :func:`read_topics_fields`,
  :func:`get_field`;
* :mod:`~livesweep.telemetry.mcap_walk`: the message walk in file order (the hand-written chunk
  walk with its CRC and decompression checks, mcap's reader when it declines a file);
* :mod:`~livesweep.telemetry.mcap_source`: opening a log (its summary and indexes when finished, a
  linear scan of the records up to the torn tail when not);
* :mod:`~livesweep.telemetry.mcap_json`: message bytes as JSON objects, :class:`SkippedMessages`;
* :mod:`~livesweep.telemetry.mcap_common`: the MCAP magic, the nanosecond check, CRC error texts.

Recovery of unfinished or damaged logs is :mod:`livesweep.telemetry.mcap_recover`.
"""

from __future__ import annotations

from livesweep.telemetry.mcap_columns import (_DECODE_BATCH, _MISSING, _column, _condition_notes, _not_a_number,
                                              _objects, _topic_columns, _topic_messages, get_field, read_fields,
                                              read_topics_fields)
from livesweep.telemetry.mcap_common import _MAGIC, _UINT64_MAX, _check_time_ns, _crc_error_text, _crc_text
from livesweep.telemetry.mcap_json import (_JSON_KINDS, _MAX_SKIP_EXAMPLES, SKIP_REASONS, SkippedMessages, _at,
                                           _BadMessage, _json_object)
from livesweep.telemetry.mcap_read import (LogMessage, LogSummary, _decode, _iter_messages, _metadata_dict,
                                           _read_metadata, iter_file_order, read_attachments, read_messages,
                                           read_metadata, read_summary)
from livesweep.telemetry.mcap_source import _check_file, _open, _Scan, _scan, _Source, _topic_list
from livesweep.telemetry.mcap_walk import (_MAX_CHUNK_BYTES, _MESSAGE_HEAD, _OP_CHUNK, _OP_DATA_END, _OP_FOOTER,
                                           _OP_MESSAGE, _decompress, _fast_message_walk, _reference_walk, _walk)
from livesweep.telemetry.mcap_write import (_COMPRESSION, _JSON_SEPARATORS, WRITER_METADATA_NAME, McapLogWriter,
                                            _open_locked, _str_map)
from livesweep.telemetry.mcap_write_fast import _FastMessages

__all__ = [
    "WRITER_METADATA_NAME",
    "McapLogWriter",
    "LogMessage",
    "LogSummary",
    "read_messages",
    "read_summary",
    "read_metadata",
    "read_attachments",
    "read_fields",
    "read_topics_fields",
    "iter_file_order",
    "SkippedMessages",
    "SKIP_REASONS",
    "get_field",
]

#: Private names still importable from here for the modules and tests that read them
#: (mcap_recover _MAGIC and _MAX_CHUNK_BYTES; tests _decompress and _DECODE_BATCH).
_PRIVATE = (
    _MAGIC, _UINT64_MAX, _check_time_ns, _crc_text, _crc_error_text,
    _MAX_SKIP_EXAMPLES, _BadMessage, _JSON_KINDS, _json_object, _at,
    _Scan, _Source, _scan, _check_file, _open, _topic_list,
    _reference_walk, _walk, _OP_MESSAGE, _OP_CHUNK, _OP_FOOTER, _OP_DATA_END, _MESSAGE_HEAD, _MAX_CHUNK_BYTES,
    _decompress, _fast_message_walk,
    _decode, _iter_messages, _metadata_dict, _read_metadata,
    _topic_messages, _DECODE_BATCH, _objects, _topic_columns, _MISSING, _not_a_number, _column, _condition_notes,
    _COMPRESSION, _JSON_SEPARATORS, _open_locked, _str_map, _FastMessages,
)
