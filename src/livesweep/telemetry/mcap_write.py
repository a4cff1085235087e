""":class:`McapLogWriter`: JSON messages on JSON-Schema channels written to an MCAP file, atomically
(``<path>.partial`` renamed into place) or live (flushed, readable and recoverable when killed).

The contract is in :mod:`livesweep.telemetry.mcap_log` (the facade: import from there).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, BinaryIO

from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, Writer

from livesweep.errors import LogFormatError
from livesweep.locks import check_file_free, install_file
from livesweep.numeric import json_safe
from livesweep.telemetry.mcap_common import _check_time_ns
from livesweep.telemetry.mcap_write_fast import _FastMessages


#: Name of the metadata record the writer adds on close (library and non-finite counts).
WRITER_METADATA_NAME = "livesweep.writer"

_COMPRESSION = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}

_JSON_SEPARATORS = (",", ":")


def _open_locked(path: Path, *, exclusive: bool, where: str) -> BinaryIO:
    """``path`` opened for writing from its start, with an exclusive ``flock`` held while it is open.

    The lock is taken before the file is truncated, so a second writer never damages the first
    one's file; it is released when the file is closed (also when the process dies).
    """
    import fcntl

    flags = os.O_WRONLY | os.O_CREAT | (os.O_EXCL if exclusive else 0)
    try:
        fd = os.open(path, flags, 0o644)
    except FileExistsError:
        raise LogFormatError(f"MCAP log {where} exists: it is not overwritten unless asked (--force)") from None
    except OSError as e:
        raise LogFormatError(f"cannot write MCAP log {where}: {e.strerror or type(e).__name__} ({path})") from e
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise LogFormatError(f"MCAP log {where}: another process is writing {path}") from None
    os.ftruncate(fd, 0)
    return os.fdopen(fd, "wb")


def _str_map(values: Mapping[Any, Any] | None, where: str) -> dict[str, str]:
    if values is None:
        return {}
    if not isinstance(values, Mapping):
        raise LogFormatError(f"{where}: expected a mapping of str to str, got {type(values).__name__}")
    return {str(k): str(v) for k, v in values.items()}


class McapLogWriter:
    """Write JSON messages on JSON-Schema channels to an MCAP file.

    Parameters
    ----------
    path : str or os.PathLike
        The final log file. Its directory must exist and be writable; otherwise
        :class:`~livesweep.errors.LogFormatError` is raised here, before anything is written.
    library : str
        Writer name stored in the MCAP header.
    chunk_size : int
        Uncompressed chunk size in bytes at which a chunk is compressed and written. Smaller
        chunks lose less data when the process is killed (non-atomic mode) and compress worse.
    compression : {"zstd", "lz4", "none"}
        Chunk compression.
    atomic : bool
        If True, write ``<path>.partial`` and rename it onto ``path`` in :meth:`close` (an
        existing ``path`` is replaced then, if ``overwrite``, but never one another process is
        writing: :func:`livesweep.locks.install_file`). On an exception in the ``with`` block or on
        :meth:`abort`, the partial file is deleted and nothing is left behind. A stale
        ``<path>.partial`` from an earlier run is overwritten.
        If False, write ``path`` directly (live recording; see ``flush_every``).
    flush_every : int
        Call ``file.flush()`` every this many messages (0: never). The open chunk is not
        finished by this, so a killed process loses at most that chunk plus the messages
        since the last flush.
    overwrite : bool
        False: an existing ``path`` is an error (a recording or a source log is never replaced
        unless asked); in non-atomic mode the file is also created exclusively, so two writers
        racing for one name cannot both get it. Whatever this says, the file being written is
        locked (``flock``) while it is open: a second writer on the same file fails at once with
        a clear error instead of interleaving its bytes.

    Attributes
    ----------
    message_counts : dict[str, int]
        Messages written per topic (a copy).
    nonfinite_counts : dict[str, int]
        Non-finite floats written as ``"NaN"`` / ``"Infinity"`` / ``"-Infinity"`` per topic (a copy).

    Notes
    -----
    Every call that can fail on bad input raises :class:`~livesweep.errors.LogFormatError`
    naming the file and what is wrong. The output is deterministic: the same calls give the
    same bytes.

    Used as a context manager, a normal exit calls :meth:`close` and an exception calls
    :meth:`abort` and re-raises: the partial file is deleted in atomic mode, and kept unfinished
    (readable, recoverable) in non-atomic mode.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        library: str = "livesweep",
        chunk_size: int = 256 * 1024,
        compression: str = "zstd",
        atomic: bool = True,
        flush_every: int = 1000,
        overwrite: bool = True,
    ) -> None:
        self._path = Path(path)
        where = str(self._path)
        if compression not in _COMPRESSION:
            raise LogFormatError(
                f"{where}: unknown compression {compression!r}; use one of {sorted(_COMPRESSION)}"
            )
        if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size <= 0:
            raise LogFormatError(f"{where}: chunk_size must be a positive int (bytes), got {chunk_size!r}")
        if isinstance(flush_every, bool) or not isinstance(flush_every, int) or flush_every < 0:
            raise LogFormatError(
                f"{where}: flush_every must be an int >= 0 (messages; 0 = never), got {flush_every!r}"
            )
        if not isinstance(library, str):
            raise LogFormatError(f"{where}: library must be a str, got {type(library).__name__}")
        if self._path.is_dir():
            raise LogFormatError(f"cannot write MCAP log {where}: it is a directory")
        self._atomic = bool(atomic)
        self._library = library
        self._flush_every = flush_every
        self._file_path = self._path.with_name(self._path.name + ".partial") if atomic else self._path
        if not overwrite and self._path.exists():
            raise LogFormatError(f"MCAP log {where} exists: it is not overwritten unless asked (--force)")
        self._overwrite = bool(overwrite)
        if atomic:
            check_file_free(self._path, overwrite=overwrite, what="MCAP log", error=LogFormatError)
        self._file: BinaryIO | None = None
        try:
            self._file = _open_locked(self._file_path, exclusive=not overwrite and not atomic, where=where)
            self._writer = Writer(
                self._file,
                chunk_size=chunk_size,
                compression=_COMPRESSION[compression],
            )
            self._writer.start(profile="", library=library)
        except LogFormatError:             # refused before anything was made (it exists, another writer has it)
            raise
        except BaseException:              # a signal or an I/O error half-way: leave no partial file behind
            if self._file is not None:
                self._file.close()
            if atomic:
                self._file_path.unlink(missing_ok=True)
            raise
        self._fast = _FastMessages.of(self._writer, chunk_size)
        self._state = "open"  # "open" | "closed" | "aborted"
        self._schemas: dict[tuple[str, bytes], int] = {}
        self._channels: dict[str, tuple[int, str, dict, dict[str, str]]] = {}
        self._sequence: dict[str, int] = {}
        self._message_counts: dict[str, int] = {}
        self._nonfinite_counts: dict[str, int] = {}
        self._metadata_names: set[str] = set()
        self._attachment_names: set[str] = set()
        self._since_flush = 0

    # -- properties --------------------------------------------------------------------------

    @property
    def path(self) -> Path:
        """The final log path (what :meth:`close` returns)."""
        return self._path

    @property
    def file_path(self) -> Path:
        """The file being written now (``<path>.partial`` in atomic mode, else ``path``)."""
        return self._file_path

    @property
    def closed(self) -> bool:
        """True after :meth:`close` or :meth:`abort`."""
        return self._state != "open"

    @property
    def message_counts(self) -> dict[str, int]:
        """Messages written per topic (0 for added topics without messages)."""
        return dict(self._message_counts)

    @property
    def nonfinite_counts(self) -> dict[str, int]:
        """Non-finite floats written as ``"NaN"`` / ``"Infinity"`` / ``"-Infinity"`` per topic."""
        return dict(self._nonfinite_counts)

    @property
    def topics(self) -> tuple[str, ...]:
        """Topics added so far, in the order they were added."""
        return tuple(self._channels)

    # -- writing -----------------------------------------------------------------------------

    def _check_open(self, what: str) -> None:
        if self._state != "open":
            raise LogFormatError(f"{self._path}: cannot {what}: the writer is {self._state}")

    def add_channel(
        self,
        topic: str,
        schema_name: str,
        schema: dict,
        metadata: dict[str, str] | None = None,
    ) -> int:
        """Add a JSON channel with a JSON Schema; idempotent per topic.

        Parameters
        ----------
        topic : str
            Channel topic, e.g. ``"/mavlink/ATTITUDE"`` or ``"/sim/truth"``.
        schema_name : str
            Schema name, e.g. ``"mavlink.ATTITUDE"``.
        schema : dict
            The JSON Schema (stored as compact JSON with schema encoding ``jsonschema``).
            Identical schemas (same name and content) are stored once.
        metadata : dict[str, str], optional
            Channel metadata; keys and values are converted with ``str()``.

        Returns
        -------
        int
            The MCAP channel id. Adding the same topic again with the same schema name and
            schema (and metadata, when given) returns the same id.

        Raises
        ------
        LogFormatError
            If the topic exists with a different schema or metadata, or an argument is invalid.
        """
        self._check_open("add a channel")
        where = f"{self._path}: channel {topic!r}"
        if not isinstance(topic, str) or not topic:
            raise LogFormatError(f"{self._path}: topic must be a non-empty str, got {topic!r}")
        if not isinstance(schema_name, str) or not schema_name:
            raise LogFormatError(f"{where}: schema_name must be a non-empty str, got {schema_name!r}")
        if not isinstance(schema, dict):
            raise LogFormatError(f"{where}: schema must be a dict (a JSON Schema), got {type(schema).__name__}")
        meta = _str_map(metadata, where + " metadata")
        if topic in self._channels:
            cid, old_name, old_schema, old_meta = self._channels[topic]
            if old_name != schema_name or old_schema != schema:
                raise LogFormatError(
                    f"{where} already exists with schema {old_name!r}; "
                    f"a different schema ({schema_name!r}) cannot be added on the same topic"
                )
            if metadata is not None and meta != old_meta:
                raise LogFormatError(
                    f"{where} already exists with metadata {old_meta}; got different metadata {meta}"
                )
            return cid
        try:
            schema_bytes = json.dumps(schema, separators=_JSON_SEPARATORS, allow_nan=False).encode("utf-8")
        except (TypeError, ValueError) as e:
            raise LogFormatError(f"{where}: schema {schema_name!r} is not JSON-serialisable: {e}") from e
        key = (schema_name, schema_bytes)
        sid = self._schemas.get(key)
        if sid is None:
            sid = self._writer.register_schema(
                name=schema_name, encoding=SchemaEncoding.JSONSchema, data=schema_bytes
            )
            self._schemas[key] = sid
        cid = self._writer.register_channel(
            topic=topic, message_encoding=MessageEncoding.JSON, schema_id=sid, metadata=meta
        )
        self._channels[topic] = (cid, schema_name, json.loads(schema_bytes), meta)
        self._sequence[topic] = 0
        self._message_counts[topic] = 0
        self._nonfinite_counts[topic] = 0
        return cid

    def _encode(self, topic: str, message: dict) -> tuple[bytes, int]:
        """Compact JSON of ``message`` and the number of non-finite floats written as strings."""
        try:
            return json.dumps(message, separators=_JSON_SEPARATORS, allow_nan=False).encode("utf-8"), 0
        except (TypeError, ValueError):
            pass  # non-finite floats or numpy types: take the slow path
        try:
            clean, nonfinite = json_safe(message)
            data = json.dumps(clean, separators=_JSON_SEPARATORS, allow_nan=False).encode("utf-8")
        except (TypeError, ValueError, RecursionError) as e:
            raise LogFormatError(
                f"{self._path}: topic {topic!r}: message cannot be encoded as JSON: {e}"
            ) from e
        return data, nonfinite

    def write(
        self,
        topic: str,
        message: dict,
        *,
        log_time_ns: int,
        publish_time_ns: int | None = None,
    ) -> None:
        """Write one message as compact JSON.

        Parameters
        ----------
        topic : str
            A topic added with :meth:`add_channel`.
        message : dict
            JSON object. Non-finite floats (also nested) are written as ``"NaN"`` / ``"Infinity"``
            / ``"-Infinity"`` and counted in
            :attr:`nonfinite_counts`; numpy arrays and scalars are converted; tuples become lists.
        log_time_ns : int
            Receive time, integer nanoseconds >= 0.
        publish_time_ns : int, optional
            Vehicle/publisher time, integer nanoseconds >= 0; defaults to ``log_time_ns``.

        Notes
        -----
        Sequence numbers count from 0 per channel (modulo 2**32, MCAP's field width).
        """
        self._check_open("write")
        if topic not in self._channels:
            raise LogFormatError(
                f"{self._path}: topic {topic!r} was not added with add_channel "
                f"(topics: {sorted(self._channels) or 'none'})"
            )
        where = f"{self._path}: topic {topic!r}"
        log_t = _check_time_ns(log_time_ns, "log_time_ns", where)
        pub_t = log_t if publish_time_ns is None else _check_time_ns(publish_time_ns, "publish_time_ns", where)
        if not isinstance(message, dict):
            raise LogFormatError(f"{where}: message must be a dict (JSON object), got {type(message).__name__}")
        data, nonfinite = self._encode(topic, message)
        cid = self._channels[topic][0]
        seq = self._sequence[topic]
        if self._fast is not None:
            self._fast.add(cid, log_t, pub_t, seq & 0xFFFFFFFF, data)
        else:
            self._writer.add_message(
                channel_id=cid, log_time=log_t, data=data, publish_time=pub_t, sequence=seq & 0xFFFFFFFF
            )
        self._sequence[topic] = seq + 1
        self._message_counts[topic] += 1
        self._nonfinite_counts[topic] += nonfinite
        if self._flush_every:
            self._since_flush += 1
            if self._since_flush >= self._flush_every:
                self._since_flush = 0
                assert self._file is not None
                self._file.flush()

    def write_encoded(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Write one message that is JSON already (the recorder's raw datagrams: the hot path of a
        live link, without :meth:`write`'s encoding and checks). ``topic`` must have been added and
        ``data`` be a JSON object; ``publish_time`` is the receive time."""
        cid = self._channels[topic][0]
        seq = self._sequence[topic]
        if self._fast is not None:
            self._fast.add(cid, log_time_ns, log_time_ns, seq & 0xFFFFFFFF, data)
        else:
            self._writer.add_message(channel_id=cid, log_time=log_time_ns, data=data, publish_time=log_time_ns,
                                     sequence=seq & 0xFFFFFFFF)
        self._sequence[topic] = seq + 1
        self._message_counts[topic] += 1

    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        """Add a metadata record (MCAP metadata is str -> str; values are converted with ``str()``).

        Parameters
        ----------
        name : str
            Record name, unique in the file. ``"livesweep.writer"`` is reserved.
        values : dict
            Key/value pairs; keys and values converted with ``str()``.
        """
        self._check_open("add metadata")
        if not isinstance(name, str) or not name:
            raise LogFormatError(f"{self._path}: metadata name must be a non-empty str, got {name!r}")
        if name == WRITER_METADATA_NAME:
            raise LogFormatError(f"{self._path}: metadata name {name!r} is reserved for the writer")
        self._add_metadata(name, _str_map(values, f"{self._path}: metadata {name!r}"))

    def _add_metadata(self, name: str, values: dict[str, str]) -> None:
        if name in self._metadata_names:
            raise LogFormatError(f"{self._path}: metadata record {name!r} was already added")
        self._metadata_names.add(name)
        self._writer.add_metadata(name, values)

    def add_attachment(self, name: str, data: bytes, media_type: str, log_time_ns: int = 0) -> None:
        """Add an attachment (e.g. the config used).

        Parameters
        ----------
        name : str
            Attachment name, unique in the file, e.g. ``"case.toml"``.
        data : bytes
            Contents.
        media_type : str
            E.g. ``"application/toml"`` or ``"application/json"``.
        log_time_ns : int
            Log time in integer nanoseconds; also used as ``create_time`` so the output does not
            depend on the wall clock.
        """
        self._check_open("add an attachment")
        if not isinstance(name, str) or not name:
            raise LogFormatError(f"{self._path}: attachment name must be a non-empty str, got {name!r}")
        if name in self._attachment_names:
            raise LogFormatError(f"{self._path}: attachment {name!r} was already added")
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise LogFormatError(
                f"{self._path}: attachment {name!r}: data must be bytes, got {type(data).__name__}"
            )
        if not isinstance(media_type, str):
            raise LogFormatError(f"{self._path}: attachment {name!r}: media_type must be a str")
        t = _check_time_ns(log_time_ns, "log_time_ns", f"{self._path}: attachment {name!r}")
        self._attachment_names.add(name)
        self._writer.add_attachment(create_time=t, log_time=t, name=name, media_type=media_type, data=bytes(data))

    # -- ending ------------------------------------------------------------------------------

    def flush(self) -> None:
        """Finish the open chunk and hand everything to the OS (bounds what a kill can lose)."""
        self._check_open("flush")
        self._writer.flush()
        self._since_flush = 0

    def close(self) -> Path:
        """Finish the file (summary, footer), flush, fsync and (atomic mode) rename it into place.

        Idempotent: a second call returns the same path.

        Returns
        -------
        pathlib.Path
            The finished log.

        Raises
        ------
        LogFormatError
            If the writer was aborted, or finishing fails (atomic mode: the partial file is
            deleted; non-atomic mode: the file is left unfinished, readable and recoverable).
        """
        if self._state == "closed":
            return self._path
        if self._state == "aborted":
            raise LogFormatError(f"{self._path}: cannot close: the writer was aborted")
        try:
            info = {"library": self._library,
                    "nonfinite_total": str(sum(self._nonfinite_counts.values()))}
            for topic, n in self._nonfinite_counts.items():
                info[f"nonfinite:{topic}"] = str(n)
            self._add_metadata(WRITER_METADATA_NAME, info)
            self._writer.finish()
            assert self._file is not None
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            self._file = None
            if self._atomic:
                install_file(self._file_path, self._path, overwrite=self._overwrite, what="MCAP log",
                             error=LogFormatError)
        except OSError as e:
            self.abort()
            kept = "" if self._atomic else "; it is left unfinished: livesweep's readers and recover() read it"
            raise LogFormatError(f"cannot finish MCAP log {self._path}: {e}{kept}") from e
        except BaseException:
            self.abort()
            raise
        self._state = "closed"
        return self._path

    def abort(self) -> None:
        """Close the file without finishing it. Atomic mode deletes ``<path>.partial``; non-atomic
        mode (a live recording) keeps ``path`` unfinished, as a killed process would: what was
        recorded is never deleted. No-op after :meth:`close` or a previous :meth:`abort`."""
        if self._state != "open":
            return
        self._state = "aborted"
        if self._file is not None:
            try:
                self._file.close()
            except OSError:
                pass
            self._file = None
        if self._atomic:
            try:
                os.unlink(self._file_path)
            except FileNotFoundError:
                pass

    def __enter__(self) -> McapLogWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close()
        else:
            self.abort()
        return False

    def __repr__(self) -> str:
        return (f"McapLogWriter({str(self._path)!r}, state={self._state!r}, "
                f"topics={len(self._channels)}, messages={sum(self._message_counts.values())})")
