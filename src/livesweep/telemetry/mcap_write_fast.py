"""The writer's hot path: a message record written straight into :class:`mcap.writer.Writer`'s open chunk.

Part of :mod:`livesweep.telemetry.mcap_log` (the facade: import from there).
"""

from __future__ import annotations

import struct

from mcap.writer import Writer


class _FastMessages:
    """``mcap.writer.Writer.add_message`` without its per-message objects and small writes.

    A live link writes tens of thousands of messages a second; the library builds a ``Message``
    dataclass and makes six ``struct.pack`` writes with seeks for each (about 7 us). This writes the
    same record bytes in one ``pack`` into the writer's open chunk and keeps the writer's statistics
    and the chunk's message index as ``add_message`` does (a test compares the files byte for byte).
    It reaches into the writer's internals, so :meth:`of` checks they are what it expects and
    returns None otherwise (``add_message`` is used then).
    """

    __slots__ = ("_writer", "_builder", "_stats", "_chunk_size", "_finalize", "_index")
    _HEAD = struct.Struct("<BQHIQQ")      # opcode, record length, channel, sequence, log time, publish time
    _OPCODE_MESSAGE = 0x05

    @classmethod
    def of(cls, writer: Writer, chunk_size: int) -> "_FastMessages | None":
        try:                              # mcap's internals: another version may have moved them
            from mcap._chunk_builder import ChunkBuilder
            from mcap.records import MessageIndex
        except ImportError:
            return None

        builder = getattr(writer, "_Writer__chunk_builder", None)
        stats = getattr(writer, "_Writer__statistics", None)
        finalize = getattr(writer, "_Writer__maybe_finalize_chunk", None)
        if not (isinstance(builder, ChunkBuilder) and stats is not None and callable(finalize)
                and hasattr(builder, "record_writer") and hasattr(builder.record_writer, "_buffer")
                and hasattr(builder, "message_indices") and hasattr(stats, "channel_message_counts")):
            return None
        fast = cls()
        fast._writer, fast._builder, fast._stats, fast._chunk_size = writer, builder, stats, chunk_size
        fast._finalize = finalize
        fast._index = MessageIndex
        return fast

    def add(self, cid: int, log_time: int, publish_time: int, sequence: int, data: bytes) -> None:
        st, cb = self._stats, self._builder
        if st.message_count == 0:
            st.message_start_time = log_time
        elif log_time < st.message_start_time:
            st.message_start_time = log_time
        if log_time > st.message_end_time:
            st.message_end_time = log_time
        st.channel_message_counts[cid] += 1
        st.message_count += 1
        if cb.num_messages == 0:
            cb.message_start_time = log_time
        elif log_time < cb.message_start_time:
            cb.message_start_time = log_time
        if log_time > cb.message_end_time:
            cb.message_end_time = log_time
        buf = cb.record_writer._buffer
        index = cb.message_indices.get(cid)
        if not index:
            index = cb.message_indices[cid] = self._index(channel_id=cid, records=[])
        index.records.append((log_time, buf.tell()))
        cb.num_messages += 1
        buf.write(self._HEAD.pack(self._OPCODE_MESSAGE, 22 + len(data), cid, sequence, log_time, publish_time))
        buf.write(data)
        if buf.tell() > self._chunk_size:
            self._finalize()
