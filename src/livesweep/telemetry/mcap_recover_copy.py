"""Writing the finished copy of a salvaged MCAP log.

One job: turn what the salvage walk reads into records of the new file: the header (the source's
profile and library when its header record reads), each schema and channel registered once with
the best definition found (a data-section record from verified bytes first, then the summary's
when it can be trusted), and each message on its channel, held back until its channel is defined.
Part of :func:`~livesweep.telemetry.mcap_recover.recover`.
"""

from __future__ import annotations

from mcap.records import Schema


class _SalvageCopy:
    """The output side of :class:`~livesweep.telemetry.mcap_recover_scan._Salvage`.

    Used as its base class; the state lives on the salvage: ``w`` (the :class:`mcap.writer.Writer`),
    ``started``, ``summary``, the definitions found (``data_schemas``, ``data_channels``,
    ``late_schemas``, ``late_channels``), the output ids given (``out_schema``, ``out_channel``),
    ``undefined``, ``pending``, ``written``, ``unverified`` and ``unreadable``.
    """

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
