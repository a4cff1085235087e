"""Decoding MAVLink frames into :class:`~livesweep.telemetry.frames.Frame` with every byte accounted for.

One job: :class:`MavlinkDecoder`, the bare pymavlink parsers plus the checks and counters shared by
the live source, the tlog replay and the recorder process: CRC and garbage counting, signing (its
checks in :mod:`livesweep.telemetry.mavlink_signing`), sequence gaps per (sysid, compid), vehicle
clock plausibility, and the Frame built for each good message. The counters are described in
:mod:`livesweep.telemetry.mavlink_in`.
"""

from __future__ import annotations

import collections
import logging
import time
from typing import Any

from livesweep.errors import LivesweepError
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.clock import UINT64_NS_MAX, StampCheck
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mavlink_codec import _dialect  # imported with MAVLINK20=1
from livesweep.telemetry.mavlink_signing import _SIGNING_EPOCH_S, _SigningChecks

__all__ = ["MavlinkDecoder"]

log = logging.getLogger(__name__)

_MARKER_V1 = 0xFE
_MARKER_V2 = 0xFD
_SIG_LEN = _dialect.MAVLINK_SIGNATURE_BLOCK_LEN  # 13
_IFLAG_SIGNED = _dialect.MAVLINK_IFLAG_SIGNED


def _empty_counts() -> dict[str, Any]:
    return {
        "received": {},
        "by_system": {},
        "bad_crc": 0,
        "bad_prefix_or_garbage": 0,
        "rejected_unsigned": 0,
        "unsigned_accepted": 0,
        "bad_signature": 0,
        "replayed_signature": 0,
        "bad_other": 0,
        "unknown_message": 0,
        "seq_gaps": {},
        "seq_repeats": 0,
        "clock_unrepresentable": 0,
        "clock_implausible": 0,
        "kernel_drops": 0,
        "bytes": 0,
    }


class MavlinkDecoder(_SigningChecks):
    """Bare pymavlink parsers plus the checking, counting and Frame building shared by the sources
    (and by the recorder process, :mod:`livesweep.telemetry.capture`)."""

    def __init__(self, signing_key: bytes | None, allow_unsigned: bool, *, live: bool) -> None:
        self.counts = _empty_counts()
        self._key = signing_key
        self._last_seq: dict[tuple[int, int], int] = {}
        #: (sysid, compid) -> signed frames refused since that source's last good one: they arrived,
        #: so the sequence numbers they used are no loss
        self._refused_arrivals: dict[tuple[int, int], int] = {}
        self._allow_unsigned = bool(allow_unsigned)
        self._warned: set[str] = set()
        self._stamp_clocks: dict[tuple[int, int, str], StampCheck] = {}
        self._time_specs: dict[str, tuple[str, int, int | None] | None] = {}   # msgname -> (field, ns/unit, wrap ns)
        # signing: newest time stamp per (link id, sysid, compid) and overall [10 µs since 2015].
        # Live: like mavutil.setup_signing, a *new* stream must not be more than one minute older
        # than now (rejects replays of old captures). A tlog is old by nature: 0.
        self._sign_streams: dict[tuple[int, int, int], int] = {}
        self._sign_time = int(max(time.time() - _SIGNING_EPOCH_S, 0) * 100_000) if live else 0
        self._refused_signed = False
        self.mav = self.parser()

    def parser(self) -> Any:
        """A new pymavlink parser (one per byte stream) that checks signatures through this decoder."""
        mav = _dialect.MAVLink(None, srcSystem=0, srcComponent=0)
        mav.robust_parsing = True  # BAD_DATA messages instead of MAVError exceptions
        if self._key is not None:
            s = mav.signing
            s.secret_key = self._key
            s.sign_outgoing = False
            s.allow_unsigned_callback = self._unsigned_callback
            mav.check_signature = self._check_signature   # pymavlink's own trusts the time stamp first
        return mav

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            log.warning("%s", text)

    def reset(self, mav: Any = None) -> int:
        """Drop a partial frame left in a parser (end of a datagram); returns its length."""
        mav = self.mav if mav is None else mav
        left = len(mav.buf) - mav.buf_index
        mav.buf = bytearray()
        mav.buf_index = 0
        mav.expected_length = _dialect.HEADER_LEN_V1 + 2
        return left

    def decode_frame(self, frame: bytes) -> Any:
        """Decode one complete frame exactly as ``parse_char`` with ``robust_parsing`` would.

        (What ``MAVLink.parse_char`` does for a whole frame, without its byte-buffer
        bookkeeping, which costs about a quarter of the parse time.)
        """
        mav = self.mav
        buf = bytearray(frame)
        try:
            if buf[0] == _MARKER_V2 and (buf[2] & ~_IFLAG_SIGNED) != 0:
                raise _dialect.MAVError("invalid incompat_flags 0x%x 0x%x %u" % (buf[2], buf[0], len(buf)))
            return mav.decode(buf)
        except _dialect.MAVError as reason:
            mav.total_receive_errors += 1
            return _dialect.MAVLink_bad_data(buf, reason.message)

    def pending_bytes(self, mav: Any = None) -> int:
        mav = self.mav if mav is None else mav
        return len(mav.buf) - mav.buf_index

    def _vehicle_ns(self, rec: dict, mtype: str, receive_ns: int) -> int | None:
        """The record's vehicle time [ns], or None when it has none or it cannot be trusted (counted)."""
        spec = self._time_specs.get(mtype)
        if spec is None:
            tf = codec.vehicle_time_field(mtype)
            wrap = None if tf is None else codec.stamp_wrap_units(mtype, tf[0])
            spec = self._time_specs[mtype] = None if tf is None else (tf[0], tf[1], None if wrap is None else wrap * tf[1])
        if spec is None:
            return None
        field, ns_per_unit, wrap_ns = spec
        raw = rec[field]
        vns = raw * ns_per_unit
        if not 0 <= vns <= UINT64_NS_MAX:
            self.counts["clock_unrepresentable"] += 1
            self._warn_once("clock_unrepresentable", f"MAVLink {mtype} from {rec['sysid']}/{rec['compid']}: {field} "
                            f"{raw} does not fit a log time in ns; recorded with its receive time (further ones are "
                            "only counted)")
            return None
        key = (rec["sysid"], rec["compid"], mtype)       # one clock per stream: a field's meaning varies by message
        check = self._stamp_clocks.get(key)
        if check is None:
            check = self._stamp_clocks[key] = StampCheck(wrap_ns=wrap_ns)
        if not check.check(vns, receive_ns):
            self.counts["clock_implausible"] += 1
            self._warn_once("clock_implausible", f"MAVLink {mtype} from {rec['sysid']}/{rec['compid']}: {field} "
                            f"{raw} does not follow the stream's clock; recorded with its receive time (further ones "
                            "are only counted)")
            return None
        return vns

    def handle(self, msg: Any, receive_ns: int, out: list[Frame] | collections.deque) -> None:
        """Count ``msg`` and append its Frame to ``out`` when it is a good message."""
        c = self.counts
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            reason = str(getattr(msg, "reason", ""))
            if reason.startswith("invalid MAVLink CRC"):
                c["bad_crc"] += 1
            elif reason.startswith("Bad prefix"):
                c["bad_prefix_or_garbage"] += 1
            elif reason.startswith("Invalid signature"):
                pass  # counted by the callback (rejected_unsigned) or in bad_signature
            else:
                c["bad_other"] += 1
                self._warn_once("bad_other", f"MAVLink BAD_DATA: {reason} (further BAD_DATA are only counted)")
            return
        if mtype.startswith("UNKNOWN_") or msg.get_msgId() < 0:
            c["unknown_message"] += 1
            return
        try:
            rec = codec.record_from_message(msg)
            vns = self._vehicle_ns(rec, mtype, receive_ns)
        except LivesweepError as e:  # a message outside the codec's dialect
            c["unknown_message"] += 1
            self._warn_once("conversion", f"MAVLink {mtype}: not converted ({e}); further such messages are only counted")
            return
        sysid, compid = rec["sysid"], rec["compid"]
        # sequence gaps per (sysid, compid); 8-bit wrap, multiples of 256 invisible
        key = (sysid, compid)
        seq = msg.get_seq()
        last = self._last_seq.get(key)
        refused = self._refused_arrivals.pop(key, 0) if self._refused_arrivals else 0
        if last is not None:
            gap = (seq - last - 1) & 0xFF
            if gap == 255:
                c["seq_repeats"] += 1
            elif gap > refused:
                gap -= refused
                k = f"{sysid}/{compid}"
                c["seq_gaps"][k] = c["seq_gaps"].get(k, 0) + gap
        self._last_seq[key] = seq
        rcv = c["received"]
        rcv[mtype] = rcv.get(mtype, 0) + 1
        bs = c["by_system"]
        bs[sysid] = bs.get(sysid, 0) + 1
        out.append(Frame(f"/mavlink/{mtype}", receive_ns, vns, rec))

    def snapshot(self) -> dict[str, Any]:
        return {k: (dict(v) if isinstance(v, dict) else v) for k, v in self.counts.items()}

    def datagram(self, data: bytes, receive_ns: int, out: list[Frame] | collections.deque) -> None:
        """Decode one UDP datagram into ``out``: each frame it holds counted and checked; a frame cut
        at its end is counted (``bad_prefix_or_garbage``) and dropped, so it cannot eat the next
        datagram's frames."""
        self.counts["bytes"] += len(data)
        for m in self.mav.parse_buffer(data) or ():
            self.handle(m, receive_ns, out)
        if self.pending_bytes():
            self.reset()
            self.counts["bad_prefix_or_garbage"] += 1

