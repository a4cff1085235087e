"""Live MAVLink input (UDP, TCP, serial) and ``.tlog`` replay as :class:`~livesweep.telemetry.frames.Source`.

Both sources turn each decoded MAVLink message into a :class:`~livesweep.telemetry.frames.Frame`:

* ``topic``      ``/mavlink/<MSGNAME>`` (docs/outputs.md, MCAP recordings);
* ``receive_ns`` ``time.time_ns()`` when the datagram / bytes were read (live), or the tlog
  record's own time stamp (µs -> ns) for :class:`TlogSource`;
* ``vehicle_ns`` :func:`~livesweep.telemetry.mavlink_codec.vehicle_time_ns` (``time_usec`` or
  ``time_boot_ms``; ``None`` when the message has no time field);
* ``data``       :func:`~livesweep.telemetry.mavlink_codec.record_from_message`, the canonical
  record (``sysid``/``compid`` are fields, so several systems share one topic).

Nothing is dropped silently: every byte that does not become a frame is counted in
:attr:`MavlinkSource.counts` / :attr:`TlogSource.counts`::

    received               {msgname: frames}
    by_system              {sysid: frames}
    bad_crc                frames whose CRC failed (corrupted on the wire)
    bad_prefix_or_garbage  runs of bytes that cannot start a frame, incomplete frames at the
                           end of a UDP datagram, and non-MAVLink tlog records
    rejected_unsigned      unsigned frames refused because a signing key is set (and
                           ``allow_unsigned`` is False)
    unsigned_accepted      unsigned frames let through by ``allow_unsigned=True``
    bad_signature          signed frames refused: a wrong signature (forged, or another key),
                           or a correct one whose signing time stamp is not newer than its
                           stream's (a replay)
    replayed_signature     the part of ``bad_signature`` with a correct signature (replays)
    bad_other              other BAD_DATA (bad incompat flags, undecodable payload)
    unknown_message        frames with a message id the dialect does not know
    seq_gaps               {"sysid/compid": estimated lost frames}, from the 8-bit ``seq`` (signed
                           frames refused in between arrived: they are not counted as lost)
    seq_repeats            frames that repeat the previous ``seq`` of their source
    clock_unrepresentable  frames whose time stamp does not fit an MCAP time (uint64 ns): recorded
                           with their receive time as publish time
    clock_implausible      frames whose time stamp is ahead of every clock their (system,
                           component, message type) stream has shown
                           (:class:`~livesweep.telemetry.clock.StampCheck`): likewise
    kernel_drops           datagrams the kernel dropped because the socket buffer was full (UDP
                           on Linux: ``SO_RXQ_OVFL`` on every datagram read, and
                           ``/proc/net/udp`` when :meth:`MavlinkSource.refresh_kernel_drops` is
                           called, as the monitor does once a second and at close)
    bytes                  bytes read

Signing (MAVLink 2): with ``signing_key`` set, every signed frame is checked here, not by
pymavlink's ``check_signature``: pymavlink stores a frame's signing time stamp as its stream's
newest *before* it compares the signature, so one forged frame with time stamp 2**48-1 would make
every later genuine frame of that stream look like a replay. This module compares the signature
first (SHA-256 of key and frame, constant time) and only then checks and advances the stream's
time stamp (a new stream may be at most one minute older than the newest time stamp seen, as in
the MAVLink signing specification). pymavlink itself rejects unsigned frames *without counting
them* when no ``allow_unsigned_callback`` is installed (docs/user-guide.md, MAVLink), so this
module installs its own callback that counts them and answers ``allow_unsigned``. pymavlink also
calls that callback for signed frames whose check failed; those are always refused here
(``allow_unsigned`` never lets a forged signature through) and counted in ``bad_signature`` only.
Without a key, signatures are ignored and everything is accepted.

Time: ``receive_ns`` comes from :func:`~livesweep.telemetry.clock.receive_ns` (UNIX time that
does not step with the wall clock). A ``vehicle_ns`` outside what MCAP can hold, or that does not
no clock of its (sysid, compid, message type) stream can have
(:class:`~livesweep.telemetry.clock.StampCheck`), is replaced by None and counted
(``clock_unrepresentable``, ``clock_implausible``): the frame is still recorded, with its receive
time as publish time, and its fields unchanged.

Warnings: each kind of problem is logged once per source (the first occurrence, with an example);
after that it is only counted.

Loss: ``seq_gaps`` is estimated per (sysid, compid) from ``msg.get_seq()`` (8 bits, wraps at
256). **A gap that is a multiple of 256 frames is invisible**, and a burst of lost frames is
only known modulo 256 (docs/user-guide.md, MAVLink: pymavlink's ``mav_loss`` reported 0 for a
true loss of 1 358). Corrupted frames (``bad_crc``) also appear as gaps. The monitor must also
check time-stamp continuity (``vehicle_ns``) to detect loss.

Files are never handed to ``mavutil.mavlink_connection``: it picks a reader from the file
*name* (``*.bin`` -> DataFlash) and executes existing files whose path contains ``/bin/``.
:class:`TlogSource` reads the bytes itself and feeds a bare pymavlink parser.
"""

from __future__ import annotations

import collections
import errno
import hashlib
import hmac
import logging
import math
import mmap
import os
import re
import select
import socket
import struct
import sys
import time
from pathlib import Path
from typing import Any, Iterator

from livesweep.errors import ConfigError, LivesweepError, LogFormatError
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.clock import UINT64_NS_MAX, StampCheck, receive_ns
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mavlink_codec import _dialect, mavutil  # imported with MAVLINK20=1
from livesweep.telemetry.mavlink_out import parse_url

__all__ = ["MavlinkSource", "TlogSource", "MavlinkDecoder", "udp_kernel_drops"]

log = logging.getLogger(__name__)

_MARKER_V1 = 0xFE
_MARKER_V2 = 0xFD
_SIG_LEN = _dialect.MAVLINK_SIGNATURE_BLOCK_LEN  # 13
_IFLAG_SIGNED = _dialect.MAVLINK_IFLAG_SIGNED

# tlog time stamps: plausible absolute range (2000-01-01 .. 2100-01-01, µs since the epoch)
_TS_MIN_US = 946_684_800 * 1_000_000
_TS_MAX_US = 4_102_444_800 * 1_000_000
# a record time stamp more than this away from the previous one is taken for misalignment
_TS_WINDOW_US = 24 * 3600 * 1_000_000
# how far into a file the format check looks for the first MAVLink record
_PROBE_BYTES = 64 * 1024
# signing time stamps count 10 µs units since 2015-01-01
_SIGNING_EPOCH_S = 1_420_070_400
# a new signing stream may be this much older than the newest time stamp seen (1 min in 10 µs units)
_SIGNING_NEW_STREAM_UNITS = 6_000_000
#: Linux: the socket option that reports the kernel's drop count with every datagram.
SO_RXQ_OVFL = 40
#: Whether the kernel says how many datagrams it dropped (Linux).
KERNEL_DROPS_KNOWN = sys.platform.startswith("linux")
# tcpin: the most clients served at once (more are refused and counted)
_MAX_TCP_CLIENTS = 16

_SHORT_URL_RE = re.compile(r"^(udpin|udp|tcpin):(?::)?(\d{1,5})$")
_NET_PREFIX_RE = re.compile(r"^(udpout|udpin|udp|tcp|tcpin):")
_FILE_SUFFIXES = (".tlog", ".bin", ".log", ".mavlink", ".raw", ".px4log", ".ulg", ".mcap", ".elf")


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


def _check_key(signing_key: Any) -> bytes | None:
    if signing_key is None:
        return None
    if not isinstance(signing_key, (bytes, bytearray)) or len(signing_key) != 32:
        n = len(signing_key) if hasattr(signing_key, "__len__") else "?"
        raise ConfigError(
            "MAVLink signing key must be 32 bytes (e.g. hashlib.sha256(passphrase).digest()), "
            f"got {type(signing_key).__name__} of length {n}"
        )
    return bytes(signing_key)


class MavlinkDecoder:
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

    def _check_signature(self, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        """The signature first, then the stream's time stamp (MAVLink 2 signing, replay protection)."""
        key = self._key
        assert key is not None
        expected = hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6]
        arrived = self._refused_arrivals
        if not hmac.compare_digest(expected, bytes(msgbuf[-6:])):
            self._refuse_signed("bad_signature", "signed MAVLink frame with a wrong signature refused "
                                "(forged, or signed with another key)")
            arrived[(src_system, src_component)] = arrived.get((src_system, src_component), 0) + 1
            return False
        stamp = int.from_bytes(bytes(msgbuf[-12:-6]), "little")
        stream = (msgbuf[-13], src_system, src_component)
        last = self._sign_streams.get(stream)
        if (stamp <= last) if last is not None else (stamp + _SIGNING_NEW_STREAM_UNITS < self._sign_time):
            self.counts["replayed_signature"] += 1
            self._refuse_signed("bad_signature", "signed MAVLink frame refused: its signing time stamp is not newer "
                                "than its stream's (a replay)")
            arrived[(src_system, src_component)] = arrived.get((src_system, src_component), 0) + 1
            return False
        self._sign_streams[stream] = stamp
        self._sign_time = max(self._sign_time, stamp)
        return True

    def _refuse_signed(self, counter: str, text: str) -> None:
        self.counts[counter] += 1
        self._refused_signed = True
        self._warn_once(counter, text + "; further ones are only counted")

    # pymavlink calls this for unsigned frames AND for signed frames whose check failed
    def _unsigned_callback(self, mav: Any, msgid: int) -> bool:
        if self._refused_signed:
            self._refused_signed = False
            return False  # a bad signature is never accepted, not even with allow_unsigned
        if self._allow_unsigned:
            self.counts["unsigned_accepted"] += 1
            return True
        self.counts["rejected_unsigned"] += 1
        self._warn_once("unsigned", "unsigned MAVLink frame rejected (signing key set); further ones are only counted")
        return False

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


# ======================================================================================
# Live source
# ======================================================================================


def udp_kernel_drops(sock: socket.socket) -> int | None:
    """The datagrams the kernel dropped for a full receive buffer of ``sock``, from ``/proc/net/udp``
    (Linux; None elsewhere or when it cannot be read). The count the kernel stamps on each datagram
    (``SO_RXQ_OVFL``) only arrives with the next one: this also counts drops at the end of a burst."""
    if not KERNEL_DROPS_KNOWN:
        return None
    try:
        inode = str(os.fstat(sock.fileno()).st_ino)
    except (OSError, ValueError):
        return None
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            with open(table) as f:
                next(f)
                for line in f:
                    cols = line.split()
                    if len(cols) >= 13 and cols[9] == inode:
                        return int(cols[12])
        except (OSError, ValueError, StopIteration):
            continue
    return None


def _looks_like_file(url: str) -> bool:
    if url.startswith("/dev/") or _NET_PREFIX_RE.match(url) or "://" in url:
        return False
    return (
        os.sep in url
        or "/" in url
        or url.lower().endswith(_FILE_SUFFIXES)
        or os.path.exists(url)
    )


def parse_source_url(url: str) -> dict[str, Any]:
    """Validate a live MAVLink input url; returns ``{"kind", "host", "port"}`` or serial info.

    Accepted: ``udpin:HOST:PORT`` (``udp:`` is the same), ``tcp:HOST:PORT`` (connect to a
    server such as SITL), ``tcpin:HOST:PORT`` (listen for one client), a serial device
    (``/dev/tty*[,BAUD]``, ``COMn[,BAUD]``). ``udpin:PORT`` / ``udpin::PORT`` (and ``tcpin:``)
    bind 127.0.0.1; any other host must be written out (``udpin:0.0.0.0:14550`` listens on
    all interfaces, deliberately). Port 0 on ``udpin``/``tcpin`` picks a free port. File paths
    raise :class:`ConfigError` pointing to :class:`TlogSource`; ``udpout`` is refused (a
    monitor receives). Validation is :func:`~livesweep.telemetry.mavlink_out.parse_url`'s.
    """
    if not isinstance(url, str):
        raise ConfigError(f"MAVLink input url {url!r} is not a string")
    m = _SHORT_URL_RE.match(url)
    if m:
        url = f"{m.group(1)}:127.0.0.1:{m.group(2)}"
    if _looks_like_file(url):
        raise ConfigError(
            f"MAVLink input url {url!r} is a file path, not a live link: read .tlog files with "
            "livesweep.telemetry.mavlink_in.TlogSource(path) (never via pymavlink's "
            "mavlink_connection, which picks a reader by file name and executes paths containing /bin/)"
        )
    probe = url
    zero_port = False
    nm = re.match(r"^(udpin|udp|tcpin):(.*):0+$", url)
    if nm:  # parse_url wants 1..65535; port 0 = "any free port" is fine for a listener
        zero_port = True
        probe = f"{nm.group(1)}:{nm.group(2)}:1"
    try:
        t = parse_url(probe)
    except ConfigError as e:
        raise ConfigError(str(e).replace("MAVLink output url", "MAVLink input url").replace(repr(probe), repr(url))) from None
    if t["kind"] == "udpout":
        raise ConfigError(
            f"MAVLink input url {url!r}: udpout sends; a monitor receives. Use udpin:HOST:PORT "
            "(e.g. udpin:127.0.0.1:14550) and point the vehicle's output at it"
        )
    if zero_port:
        t["port"] = 0
    return t


class MavlinkSource:
    """Live MAVLink frames from UDP, TCP or a serial port (implements ``frames.Source``).

    Parameters
    ----------
    url : str
        ``udpin:127.0.0.1:14550`` (also ``udp:``, ``tcp:``, ``tcpin:``, ``/dev/ttyUSB0,57600``);
        see :func:`parse_source_url`. A file path raises :class:`ConfigError` (use
        :class:`TlogSource`).
    signing_key : bytes, optional
        32-byte MAVLink 2 signing key. When set, unsigned frames are rejected (and counted)
        unless ``allow_unsigned``; bad and replayed signatures are rejected and counted.
    allow_unsigned : bool
        Accept unsigned frames although a key is set (counted in ``unsigned_accepted``).
    rcvbuf_bytes : int
        ``SO_RCVBUF`` asked for (the 212 KB Linux default loses bursts, docs/user-guide.md, MAVLink); the
        kernel may grant less (``net.core.rmem_max``): :attr:`rcvbuf_granted` says what it gave.

    UDP datagrams are parsed one by one; each may hold several frames, and a frame cut at the
    end of a datagram is counted (``bad_prefix_or_garbage``) and discarded so it cannot eat
    the next datagram's frames. On Linux every datagram also carries the kernel's count of
    datagrams dropped for a full socket buffer (``kernel_drops``). ``tcpin`` serves up to 16
    clients at once, each parsed as its own byte stream, so an idle or slow client never blinds
    the others (more clients are refused and counted in ``clients_refused``). See the module
    docstring for counters and loss caveats.
    """

    #: A live link: the monitor records it and may shed analysis load, never recording.
    live = True

    def __init__(
        self,
        url: str,
        *,
        signing_key: bytes | None = None,
        allow_unsigned: bool = False,
        rcvbuf_bytes: int = 4 << 20,
    ) -> None:
        self.url = url
        self._target = parse_source_url(url)
        key = _check_key(signing_key)
        if isinstance(rcvbuf_bytes, bool) or not isinstance(rcvbuf_bytes, int) or rcvbuf_bytes <= 0:
            raise ConfigError(f"rcvbuf_bytes {rcvbuf_bytes!r} must be a positive integer")
        self._dec = MavlinkDecoder(key, allow_unsigned, live=True)
        self._pending: collections.deque[Frame] = collections.deque()
        self._closed = False
        self._clients: dict[socket.socket, Any] = {}  # tcpin: accepted client -> its own parser
        self._eof = False
        self.link_events = 0  # tcp: disconnects seen; tcpin: clients accepted/lost
        self._refused = 0     # tcpin: clients beyond the limit
        self._proc_drops = 0  # udpin: the kernel's drop count read from /proc/net/udp
        self.rcvbuf_granted: int | None = None

        codec.ensure_mavlink2()
        t = self._target
        kind = t["kind"]
        try:
            if kind == "serial":
                conn = mavutil.mavlink_connection(t["device"], baud=t["baud"])
            else:
                extra: dict[str, Any] = {"retries": 1} if kind in ("tcp", "tcpin") else {}
                conn = mavutil.mavlink_connection(f"{kind}:{t['host']}:{t['port']}", **extra)
        except ModuleNotFoundError as e:
            raise LivesweepError(f"MAVLink input {url!r} needs the {e.name!r} package (pip install pyserial)") from None
        except (OSError, ValueError) as e:
            raise LivesweepError(f"MAVLink input {url!r} cannot be opened: {e}") from None
        self._conn = conn
        self._kind = kind
        for sock in (getattr(conn, "port", None), getattr(conn, "listen", None)):
            if isinstance(sock, socket.socket):
                self.rcvbuf_granted = self._tune(sock, rcvbuf_bytes)
        if kind == "tcpin":
            conn.listen.listen(_MAX_TCP_CLIENTS)   # pymavlink's backlog of 1 would stall a third client
        if kind == "udpin" and KERNEL_DROPS_KNOWN:
            try:
                conn.port.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            except OSError:  # pragma: no cover - an old kernel: drops stay unknown
                pass
        self._rcvbuf = rcvbuf_bytes
        #: The url as bound (``udpin:127.0.0.1:0`` becomes the port the kernel picked).
        self.description = self._bound_url()

    @staticmethod
    def _tune(sock: socket.socket, rcvbuf_bytes: int) -> int | None:
        """Ask for ``rcvbuf_bytes`` of receive buffer; returns what the kernel granted [bytes]."""
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf_bytes)
            return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        except OSError:  # pragma: no cover - best effort
            return None

    # ------------------------------------------------------------------ properties
    @property
    def connection(self) -> Any:
        """The pymavlink connection (its ``port`` / ``listen`` socket; do not read from it)."""
        return self._conn

    @property
    def local_address(self) -> tuple[str, int] | None:
        """(host, port) the socket is bound to (network links), e.g. after binding port 0."""
        s = getattr(self._conn, "listen", None) if self._kind == "tcpin" else getattr(self._conn, "port", None)
        if isinstance(s, socket.socket):
            return s.getsockname()[:2]
        return None

    def _bound_url(self) -> str:
        """The url as bound: ``udpin:127.0.0.1:0`` shows the port the kernel picked."""
        addr = self.local_address
        if addr is None or self._kind not in ("udpin", "tcpin"):
            return self.url
        return f"{self._kind}:{addr[0]}:{addr[1]}"

    @property
    def counts(self) -> dict:
        c = self._dec.snapshot()
        # the count stamped on datagrams (ingest thread) and the one in /proc (refresh_kernel_drops):
        # each written by one thread only, the larger is the truth
        c["kernel_drops"] = max(c["kernel_drops"], self._proc_drops)
        if self._kind == "tcpin":
            c["clients"] = len(self._clients)
            c["clients_refused"] = self._refused
        return c

    @property
    def finished(self) -> bool:
        return False

    # ------------------------------------------------------------------ reading
    def _fds(self) -> list[Any]:
        k = self._kind
        if k in ("udpin", "tcp"):
            return [self._conn.port]
        if k == "tcpin":
            return [self._conn.listen, *self._clients]
        return [self._conn.fd]

    def refresh_kernel_drops(self) -> None:
        """Read the UDP socket's drop count from ``/proc/net/udp`` (Linux).

        The count the kernel stamps on datagrams only arrives with the next datagram queued, so
        drops at the end of a burst stay unseen until more data comes; the monitor calls this
        about once a second and before the socket is closed, so every drop is counted.
        """
        if self._kind != "udpin" or not KERNEL_DROPS_KNOWN:
            return
        drops = udp_kernel_drops(self._conn.port)
        if drops is not None:
            self._proc_drops = drops

    def _recv_udp(self) -> tuple[bytes, Any] | None:
        sock = self._conn.port
        try:
            if KERNEL_DROPS_KNOWN:
                data, anc, _flags, addr = sock.recvmsg(65535, 64)
                for level, kind, payload in anc:
                    if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(payload) >= 4:
                        self._dec.counts["kernel_drops"] = struct.unpack("I", payload[:4])[0]
            else:  # pragma: no cover - not Linux
                data, addr = sock.recvfrom(65535)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError as e:
            if e.errno == errno.ECONNREFUSED:
                return None
            raise LivesweepError(f"MAVLink input {self.url!r}: recvfrom failed ({e})") from None
        return data, addr

    def _parse(self, data: bytes, mav: Any, out: collections.deque) -> None:
        dec = self._dec
        now = receive_ns()
        dec.counts["bytes"] += len(data)
        for m in mav.parse_buffer(data) or ():
            dec.handle(m, now, out)

    def _accept_clients(self) -> bool:
        got = False
        while True:
            try:
                sock, _addr = self._conn.listen.accept()
            except (BlockingIOError, InterruptedError, OSError):
                return got
            got = True
            self.link_events += 1
            if len(self._clients) >= _MAX_TCP_CLIENTS:
                self._refused += 1
                self._dec._warn_once("tcp_clients", f"MAVLink input {self.url}: more than {_MAX_TCP_CLIENTS} TCP "
                                     "clients; further ones are refused and counted")
                sock.close()
                continue
            sock.setblocking(False)
            self._tune(sock, self._rcvbuf)
            self._clients[sock] = self._dec.parser()

    def _read_stream(self, sock: socket.socket, mav: Any, out: collections.deque) -> bool:
        """One recv from a TCP stream into ``out``; False when nothing was there or it closed."""
        try:
            data = sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return False
        except OSError as e:
            data = b""
            log.warning("MAVLink input %s: connection error (%s)", self.url, e)
        if data:
            self._parse(data, mav, out)
            return True
        self.link_events += 1                         # the peer closed
        if self._kind == "tcpin":
            log.warning("MAVLink input %s: a TCP client disconnected (%d left)", self.url, len(self._clients) - 1)
            self._clients.pop(sock, None)
            sock.close()
        else:
            log.warning("MAVLink input %s: TCP server closed the connection", self.url)
            self._eof = True
        return False

    def _read_once(self, out: collections.deque) -> bool:
        """Read what one datagram / each stream holds and decode it into ``out``; False when nothing was there."""
        dec = self._dec
        k = self._kind
        if k == "udpin":
            got = self._recv_udp()
            if got is None:
                return False
            data, _addr = got          # (pymavlink's set of peers is not kept: a monitor never sends)
            dec.datagram(data, receive_ns(), out)
            return True
        if k == "tcpin":
            got = self._accept_clients()
            for sock, mav in list(self._clients.items()):
                got = self._read_stream(sock, mav, out) or got
            return got
        if k == "tcp":
            if self._eof:
                return False
            return self._read_stream(self._conn.port, dec.mav, out)
        data = self._conn.recv(65536)   # serial
        if not data:
            return False
        self._parse(data, dec.mav, out)
        return True

    def _drain(self, out: list[Frame], max_frames: int) -> None:
        pend = self._pending
        while pend and len(out) < max_frames:
            out.append(pend.popleft())
        while len(out) < max_frames:
            if not self._read_once(pend):
                break
            while pend and len(out) < max_frames:
                out.append(pend.popleft())

    def poll(self, timeout_s: float = 0.05, max_frames: int = 10_000) -> list[Frame]:
        """Everything received since the last call (at most ``max_frames``; the rest is kept).

        Does not block while data is available; waits up to ``timeout_s`` only when nothing
        is there.
        """
        if self._closed:
            raise LivesweepError(f"MAVLink input {self.url!r} is closed")
        out: list[Frame] = []
        self._drain(out, max_frames)
        if out or timeout_s is None or timeout_s <= 0:
            return out
        deadline = time.monotonic() + float(timeout_s)
        while not out:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            if self._eof:
                time.sleep(left)
                break
            try:
                select.select(self._fds(), [], [], left)
            except (OSError, ValueError):  # pragma: no cover - fd closed underneath
                break
            self._drain(out, max_frames)
        return out

    def close(self) -> None:
        """Close the link (idempotent)."""
        if self._closed:
            return
        self.refresh_kernel_drops()
        self._closed = True
        for sock in self._clients:
            try:
                sock.close()
            except OSError:  # pragma: no cover
                pass
        self._clients.clear()
        try:
            self._conn.close()
        except (OSError, AttributeError):  # pragma: no cover
            pass

    def __enter__(self) -> "MavlinkSource":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"MavlinkSource({self.url!r}, received={sum(self._dec.counts['received'].values())})"


# ======================================================================================
# tlog replay
# ======================================================================================


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
