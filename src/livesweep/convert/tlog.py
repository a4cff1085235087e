"""MAVLink telemetry logs (``.tlog``) to livesweep MCAP: exactly what the live recorder writes.

A tlog is ``[uint64 big-endian µs UNIX time][raw MAVLink frame]`` repeated. It is read by
:class:`~livesweep.telemetry.mavlink_in.TlogSource` (by content; it keeps the record alignment
through BAD_DATA, non-MAVLink records, garbage and a cut last record) and written the way
:class:`~livesweep.telemetry.recorder.McapRecorder` writes a live link, so a converted tlog and a
live recording of the same traffic are interchangeable (docs/outputs.md, MCAP recordings):

* topic ``/mavlink/<MSGNAME>``, schema ``mavlink.<MSGNAME>`` (the recorder's own schema lookup:
  :func:`~livesweep.telemetry.mavlink_codec.json_schema`), message encoding ``json``;
* record: :func:`~livesweep.telemetry.mavlink_codec.record_from_message` (``sysid``, ``compid``
  and every field; several systems share one topic and are told apart by ``sysid``/``compid``);
* ``log_time`` = the tlog record's time stamp (µs -> ns): when the ground station received it;
* ``publish_time`` = the message's own vehicle time (``time_usec`` or ``time_boot_ms``, as sent,
  not unwrapped) when it has one, else ``log_time`` -- what the recorder does.

MAVLink 1 and 2 frames are both decoded (``format_version`` says ``"MAVLink 1"``,
``"MAVLink 2"`` or ``"MAVLink 1/2 mix"`` from the frames actually read).

``messages_read`` counts the MAVLink frames handed to the decoder (good or not). What did not
become a message is counted with :meth:`ConversionWriter.skip` under TlogSource's counter names,
each with one warning: ``bad_crc``, ``bad_prefix_or_garbage`` (runs of bytes that are not a
record, e.g. console text logged one byte per record), ``bad_other``, ``unknown_message``,
``bad_signature``, ``rejected_unsigned`` (only with a signing key) and ``truncated_tail`` (a cut
last record). Sequence gaps (frames the link lost before they reached the log, estimated from the
8-bit ``seq``) are not skips: they are reported as a warning.

Options: ``signing_key`` (32 bytes): verify MAVLink 2 signatures; unsigned frames are then
rejected and counted.
"""

from __future__ import annotations

from pathlib import Path

from livesweep.convert.common import ConversionResult, ConversionWriter, refuse_options
from livesweep.telemetry.mavlink_in import TlogSource
from livesweep.telemetry.recorder import _schema_for  # the recorder's topic -> schema rule, shared on purpose

__all__ = ["convert_tlog"]

_MARKER_V1, _MARKER_V2 = 0xFE, 0xFD

# TlogSource counter -> what the warning says; order = order of the warnings
_SKIPS = (
    ("bad_crc", "frames with a bad CRC (corrupted) skipped"),
    ("bad_prefix_or_garbage", "runs of bytes that are not MAVLink records skipped"),
    ("bad_other", "undecodable frames (bad flags or payload) skipped"),
    ("unknown_message", "frames with a message id unknown to the ardupilotmega dialect skipped"),
    ("bad_signature", "frames with a bad or replayed MAVLink 2 signature skipped"),
    ("rejected_unsigned", "unsigned frames rejected (a signing key was given)"),
    ("truncated_tail", "cut last record ignored (the log ends mid-frame)"),
)


def _version(v1: int, v2: int) -> str:
    if v1 and v2:
        return "MAVLink 1/2 mix"
    if v2:
        return "MAVLink 2"
    if v1:
        return "MAVLink 1"
    return "MAVLink (no frames)"


def convert_tlog(src, out, *, signing_key: bytes | None = None, **options) -> ConversionResult:
    """Convert the MAVLink tlog ``src`` to the MCAP file ``out`` (see the module docstring).

    Parameters
    ----------
    src, out : str or Path
    signing_key : bytes, optional
        32-byte MAVLink 2 signing key; when given, signatures are checked and unsigned frames
        rejected (counted in ``skipped["rejected_unsigned"]``).

    Returns
    -------
    ConversionResult

    Raises
    ------
    LogFormatError
        ``src`` is not a tlog (naming the file), or ``out`` cannot be written. Nothing is left
        at ``out`` then.
    ConfigError
        An option this converter does not take (e.g. ``column_map``), or a bad signing key.
    """
    src, out = Path(src), Path(out)
    refuse_options(src, "a MAVLink tlog", options, "signing_key only")
    markers = {_MARKER_V1: 0, _MARKER_V2: 0}
    with TlogSource(src, signing_key=signing_key) as source:      # LogFormatError naming the file
        # Count MAVLink 1/2 frames as they are decoded (TlogSource's frames do not say which):
        # wrap its decoder's per-frame call. If TlogSource's internals change, the version is
        # just reported as unknown.
        dec = getattr(source, "_dec", None)
        decode_frame = getattr(dec, "decode_frame", None)
        if decode_frame is not None:
            def counting_decode(frame, _decode=decode_frame, _m=markers):
                m0 = frame[0]
                if m0 in _m:
                    _m[m0] += 1
                return _decode(frame)

            dec.decode_frame = counting_decode
        with ConversionWriter(src, out, "tlog") as w:
            writer = w.writer
            known: set[str] = set()
            while not source.finished:
                for f in source.poll(max_frames=20_000):
                    topic = f.topic
                    if topic not in known:
                        name, schema = _schema_for(topic)
                        writer.add_channel(topic, name, schema)
                        known.add(topic)
                    vns = f.vehicle_ns
                    writer.write(topic, f.data, log_time_ns=f.receive_ns,
                                 publish_time_ns=vns if vns is not None and vns >= 0 else None)
            c = source.counts
            w.messages_read = int(c["records"])
            w.format_version = (_version(markers[_MARKER_V1], markers[_MARKER_V2]) if decode_frame is not None
                                else "MAVLink (version not determined)")
            for key, text in _SKIPS:
                n = int(c.get(key, 0))
                if n:
                    w.skip(key, n)
                    extra = f" ({c['garbage_bytes']} bytes in all)" if key == "bad_prefix_or_garbage" else ""
                    w.warn(f"{n} {text}{extra}")
            gaps = c.get("seq_gaps") or {}
            if sum(gaps.values()):
                w.warn("sequence gaps: about " + ", ".join(f"{n} frames from {k}" for k, n in sorted(gaps.items()))
                       + " were lost before they reached the log (estimated from the 8-bit seq; "
                         "multiples of 256 are invisible)")
            return w.finish()
