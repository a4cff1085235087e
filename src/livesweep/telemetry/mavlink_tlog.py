"""``.tlog`` replay as a :class:`~livesweep.telemetry.frames.Source`: :class:`TlogSource`.

One job: frame a tlog file (``[uint64 big-endian µs time][raw MAVLink frame]`` repeated) by its
content, keep the record alignment through damage, and hand each frame to a
:class:`~livesweep.telemetry.mavlink_decode.MavlinkDecoder`, paced or as fast as possible. The
counters are described in :mod:`livesweep.telemetry.mavlink_in`.
"""

from __future__ import annotations

import collections
import logging
import math
import mmap
import os
import struct
import time
from pathlib import Path
from typing import Any, Iterator

from livesweep.errors import ConfigError, LivesweepError, LogFormatError
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mavlink_decode import _IFLAG_SIGNED, _MARKER_V1, _MARKER_V2, _SIG_LEN, MavlinkDecoder
from livesweep.telemetry.mavlink_signing import _check_key

__all__ = ["TlogSource"]

log = logging.getLogger(__name__)

# tlog time stamps: plausible absolute range (2000-01-01 .. 2100-01-01, µs since the epoch)
_TS_MIN_US = 946_684_800 * 1_000_000
_TS_MAX_US = 4_102_444_800 * 1_000_000
# a record time stamp more than this away from the previous one is taken for misalignment
_TS_WINDOW_US = 24 * 3600 * 1_000_000
# how far into a file the format check looks for the first MAVLink record
_PROBE_BYTES = 64 * 1024


def _frame_len(d: Any, i: int, n: int) -> int | None:
    """Length of the MAVLink frame whose magic byte is at ``d[i]``; None if the header is cut."""
    marker = d[i]
    if marker == _MARKER_V1:
        if i + 2 > n:
            return None
        return d[i + 1] + 8
    if i + 3 > n:
        return None
    ln = d[i + 1] + 12
    if d[i + 2] & _IFLAG_SIGNED:
        ln += _SIG_LEN
    return ln


class TlogSource:
    """Frames from a ``.tlog`` file: ``[uint64 big-endian µs time][raw MAVLink frame]`` repeated.

    Parameters
    ----------
    path : str or Path
        The file. It is opened by *content*: the first 8 bytes must be a plausible UNIX time
        in µs (2000..2100) and a record ``[time][0xFD|0xFE ...]`` must follow within the
        first 64 KiB, else :class:`LogFormatError` naming the file. (Strictly the first
        record should be a MAVLink frame, but real logs such as ArduPilot's autotest tlog
        start with non-MAVLink records: console text logged one byte per record.)
    speed : float
        0 or inf: as fast as possible (each :meth:`poll` returns up to ``max_frames``).
        Otherwise frames are released when ``(t_record - t_first) / speed`` of wall time has
        passed since the first poll.
    signing_key : bytes, optional
        Verify MAVLink 2 signatures (unsigned frames are then rejected and counted).

    ``receive_ns`` of each frame is the record's time stamp (µs -> ns). Records are decoded
    one at a time with a fresh parser state, so a bad record never swallows the next one.
    A time stamp that is implausible (not within a day of the previous one) means the
    reader lost alignment (a corrupted length, or a non-MAVLink record of unknown length):
    it scans forward byte by byte to the next plausible time stamp and counts what it
    skipped (``bad_prefix_or_garbage`` once per skipped run, ``garbage_bytes``). A cut last
    record is counted in ``truncated_tail`` with one warning. Extra counters:
    ``records`` (tlog records with a MAVLink frame), ``garbage_bytes``, ``truncated_tail``.
    """

    #: A file: the monitor reads it at its own pace and never sheds analysis load.
    live = False

    def __init__(self, path: str | os.PathLike, *, speed: float = 0, signing_key: bytes | None = None) -> None:
        self.path = Path(path)
        try:
            s = float(speed)
        except (TypeError, ValueError):
            raise ConfigError(f"tlog replay speed {speed!r} is not a number") from None
        if math.isnan(s) or s < 0:
            raise ConfigError(f"tlog replay speed {speed!r} must be > 0 (or 0/inf for as fast as possible)")
        self.speed = s
        self._paced = s != 0 and not math.isinf(s)
        key = _check_key(signing_key)
        self._dec = MavlinkDecoder(key, False, live=False)
        self._dec.counts.update({"records": 0, "garbage_bytes": 0, "truncated_tail": 0})
        self._pending: collections.deque[Frame] = collections.deque()
        self._closed = False
        self._pos = 0
        self._last_ts: int | None = None
        self._resync_from: int | None = None  # after a bad frame: rescan from its marker + 1
        self._done = False
        self._t0_wall: float | None = None
        self._t0_ns: int | None = None

        try:
            f = open(self.path, "rb")
        except OSError as e:
            raise LogFormatError(f"tlog {str(self.path)!r} cannot be opened: {e.strerror or e}") from None
        self._f = f
        try:
            size = os.fstat(f.fileno()).st_size
            if size == 0:
                raise LogFormatError(f"{str(self.path)!r} is empty, not a MAVLink tlog")
            self._map: Any = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
            self._n = len(self._map)
            self._check_format()
            self._iter = self._records()
        except BaseException:
            self._release()
            raise

    # ------------------------------------------------------------------ format
    def _check_format(self) -> None:
        d, n = self._map, self._n
        name = str(self.path)
        if n < 8 + 8:
            raise LogFormatError(f"{name!r} is too short ({n} bytes) to be a MAVLink tlog")
        (ts0,) = struct.unpack_from(">Q", d, 0)
        if not _TS_MIN_US <= ts0 <= _TS_MAX_US:
            raise LogFormatError(
                f"{name!r} is not a MAVLink tlog: its first 8 bytes are not a plausible big-endian "
                f"µs UNIX time (got {bytes(d[:8]).hex()}); a tlog is [uint64 BE µs][MAVLink frame] repeated"
            )
        lim = min(n - 9, _PROBE_BYTES)
        for q in range(0, lim + 1):
            if d[q + 8] in (_MARKER_V1, _MARKER_V2):
                (ts,) = struct.unpack_from(">Q", d, q)
                if abs(ts - ts0) <= _TS_WINDOW_US:
                    return
        raise LogFormatError(
            f"{name!r} is not a MAVLink tlog: no [µs time][0xFD/0xFE frame] record in its first "
            f"{lim + 9} bytes"
        )

    # ------------------------------------------------------------------ decoding
    def _plausible(self, ts: int) -> bool:
        last = self._last_ts
        if last is None:
            return _TS_MIN_US <= ts <= _TS_MAX_US
        return abs(ts - last) <= _TS_WINDOW_US

    def _resync(self, start: int) -> int:
        """First offset >= start where a plausible record begins (or the end of the data)."""
        d, n = self._map, self._n
        q = start
        unpack = struct.unpack_from
        while q + 8 <= n:
            (ts,) = unpack(">Q", d, q)
            if self._plausible(ts):
                return q
            # a session appended after a long break: absolute-plausible time, a frame start,
            # and the record after that frame close in time
            if _TS_MIN_US <= ts <= _TS_MAX_US and q + 8 < n and d[q + 8] in (_MARKER_V1, _MARKER_V2):
                ln = _frame_len(d, q + 8, n)
                if ln is not None:
                    nxt = q + 8 + ln
                    if nxt >= n or (nxt + 8 <= n and abs(unpack(">Q", d, nxt)[0] - ts) <= _TS_WINDOW_US):
                        self._last_ts = ts
                        return q
            q += 1
        return n

    def _skip(self, frm: int, to: int) -> None:
        c = self._dec.counts
        c["bad_prefix_or_garbage"] += 1
        c["garbage_bytes"] += to - frm
        self._dec._warn_once("tlog-garbage", f"tlog {str(self.path)!r}: skipped non-MAVLink bytes at offset {frm} "
                                             "(further skips are only counted)")

    def _truncated(self, at: int) -> None:
        c = self._dec.counts
        c["truncated_tail"] += 1
        c["garbage_bytes"] += self._n - at
        log.warning("tlog %r: last record is cut (%d bytes at offset %d ignored)", str(self.path), self._n - at, at)

    def _records(self) -> Iterator[tuple[int, bytes, Any]]:
        """Each MAVLink frame record from the start: ``(time [µs], frame bytes, decoded message)``.

        The one place that frames the file: it keeps the record alignment through non-MAVLink
        records, garbage, corrupt lengths (after a frame whose CRC fails it rescans from that
        frame's second byte) and a cut last record, counting what it skips.
        """
        d, n = self._map, self._n
        dec = self._dec
        counts = dec.counts
        unpack = struct.unpack_from
        p = self._pos
        while p < n:
            if p + 8 > n:
                self._truncated(p)
                p = n
                continue
            (ts,) = unpack(">Q", d, p)
            if not self._plausible(ts):
                start = self._resync_from if self._resync_from is not None else p + 1
                self._resync_from = None
                q = self._resync(max(start, 1))
                self._skip(start if start < p else p, q)
                p = q
                continue
            self._resync_from = None
            i = p + 8
            if i >= n:
                self._truncated(p)
                p = n
                continue
            marker = d[i]
            if marker != _MARKER_V1 and marker != _MARKER_V2:
                # a record that is not a MAVLink frame (its length is unknown)
                self._last_ts = ts
                q = self._resync(i + 1)
                self._skip(i, q)
                p = q
                continue
            ln = _frame_len(d, i, n)
            if ln is None or i + ln > n:
                q = self._resync(i + 1)
                if q < n:  # a record follows: this frame's length byte is corrupt
                    self._skip(i, q)
                    p = q
                    continue
                self._truncated(p)
                p = n
                continue
            frame = d[i : i + ln]
            counts["bytes"] += ln
            counts["records"] += 1
            self._last_ts = ts
            msg = dec.decode_frame(frame)
            if msg.get_type() == "BAD_DATA" and str(getattr(msg, "reason", "")).startswith("invalid MAVLink CRC"):
                self._resync_from = i + 1  # the length byte itself may be what is corrupted
            p = self._pos = i + ln
            yield ts, frame, msg
        self._pos = p

    def _decode(self, limit: int) -> None:
        """Decode records into the pending queue until ``limit`` frames are pending or the end."""
        handle = self._dec.handle
        pend = self._pending
        records = self._iter
        while len(pend) < limit:
            rec = next(records, None)
            if rec is None:
                self._done = True
                break
            ts, _frame, msg = rec
            handle(msg, ts * 1000, pend)

    def raw_records(self) -> Iterator[tuple[int, bytes, Any]]:
        """The file's MAVLink frames as recorded, to send them on byte for byte (instead of :meth:`poll`).

        Yields
        ------
        time_us : int
            The record's time stamp [µs since the UNIX epoch] (when the ground station got it).
        frame : bytes
            The frame exactly as in the file (MAVLink 1 or 2, signature included).
        msg : pymavlink message
            pymavlink's decoding of it: ``BAD_DATA`` for a frame whose CRC fails or that cannot be
            decoded (and, with ``signing_key``, one whose signature is refused); ``UNKNOWN_<id>``
            for an id outside the dialect.

        The records and their order are :meth:`poll`'s (the same framing and resynchronisation);
        :attr:`counts` then holds ``records``, ``bytes`` and what was skipped, not the messages per
        type (those come from :meth:`poll`'s frames). :meth:`poll` and this share the read position.
        """
        while not self._closed:
            rec = next(self._iter, None)
            if rec is None:
                self._done = True
                return
            yield rec

    # ------------------------------------------------------------------ Source API
    @property
    def counts(self) -> dict:
        return self._dec.snapshot()

    @property
    def decoder(self) -> MavlinkDecoder:
        """The decoder that checks and counts this file's frames.

        A reader of :meth:`raw_records` hands it a record's message (``decoder.handle(msg,
        time_us * 1000, out)``) to get the frame :meth:`poll` would give, with the same checks and
        counters.
        """
        return self._dec

    @property
    def finished(self) -> bool:
        return self._closed or (self._done and not self._pending)

    def poll(self, timeout_s: float = 0.05, max_frames: int = 10_000) -> list[Frame]:
        """The next frames: up to ``max_frames`` (unpaced), or those due by now (paced)."""
        if self._closed:
            raise LivesweepError(f"tlog {str(self.path)!r} is closed")
        out: list[Frame] = []
        if max_frames <= 0:
            return out
        if not self._paced:
            if len(self._pending) < max_frames and not self._done:
                self._decode(max_frames)
            pend = self._pending
            while pend and len(out) < max_frames:
                out.append(pend.popleft())
            return out
        deadline = time.monotonic() + max(float(timeout_s or 0.0), 0.0)
        pend = self._pending
        while True:
            if not pend and not self._done:
                self._decode(min(max_frames, 1024))
            if not pend:
                return out  # end of the log
            now = time.monotonic()
            if self._t0_wall is None:  # the first poll starts the replay clock
                self._t0_wall, self._t0_ns = now, pend[0].receive_ns
            while pend and len(out) < max_frames and self._due(pend[0]) <= now:
                out.append(pend.popleft())
                if not pend and not self._done:
                    self._decode(min(max_frames, 1024))
            if out or not pend:
                return out
            # nothing due yet: sleep until the next frame is due, at most until the deadline
            if now >= deadline:
                return out
            time.sleep(max(min(self._due(pend[0]), deadline) - now, 0.0))

    def _due(self, frame: Frame) -> float:
        """Wall time (monotonic) at which a paced replay releases ``frame``."""
        return self._t0_wall + (frame.receive_ns - self._t0_ns) / 1e9 / self.speed

    def _release(self) -> None:
        m = getattr(self, "_map", None)
        if m is not None:
            try:
                m.close()
            except (BufferError, ValueError):  # pragma: no cover
                pass
            self._map = None
        f = getattr(self, "_f", None)
        if f is not None:
            f.close()

    def close(self) -> None:
        """Release the file (idempotent)."""
        if not self._closed:
            self._closed = True
            self._pending.clear()
            self._release()

    def __enter__(self) -> "TlogSource":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"TlogSource({str(self.path)!r}, speed={self.speed})"
