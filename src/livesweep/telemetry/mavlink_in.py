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
every later genuine frame of that stream look like a replay.
:mod:`~livesweep.telemetry.mavlink_signing` compares the signature first (SHA-256 of key and frame,
constant time) and only then checks and advances the stream's time stamp (a new stream may be at
most one minute older than the newest time stamp seen, as in the MAVLink signing specification).
pymavlink itself rejects unsigned frames *without counting them* when no
``allow_unsigned_callback`` is installed (docs/user-guide.md, MAVLink), so the decoder installs its
own callback that counts them and answers ``allow_unsigned``. pymavlink also calls that callback
for signed frames whose check failed; those are always refused here (``allow_unsigned`` never lets
a forged signature through) and counted in ``bad_signature`` only.
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

Modules: this module holds the live source, :class:`MavlinkSource`, and is where the sources are
imported from. The work is shared with

* :mod:`~livesweep.telemetry.mavlink_decode`: :class:`MavlinkDecoder`, the parsers, checks and
  counters every source applies to a frame;
* :mod:`~livesweep.telemetry.mavlink_signing`: the MAVLink 2 signature and replay checks;
* :mod:`~livesweep.telemetry.mavlink_tlog`: :class:`TlogSource`, the tlog replay;
* :mod:`~livesweep.telemetry.mavlink_url`: :func:`parse_source_url`, the live urls accepted;
* :mod:`~livesweep.telemetry.udp_drops`: the kernel's count of dropped datagrams.
"""

from __future__ import annotations

import collections
import errno
import logging
import select
import socket
import struct
import time
from typing import Any

from livesweep.errors import ConfigError, LivesweepError
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.clock import receive_ns
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mavlink_codec import mavutil  # imported with MAVLINK20=1
from livesweep.telemetry.mavlink_decode import (_IFLAG_SIGNED, _MARKER_V1, _MARKER_V2, _SIG_LEN, MavlinkDecoder,
                                                _empty_counts)
from livesweep.telemetry.mavlink_signing import _SIGNING_EPOCH_S, _SIGNING_NEW_STREAM_UNITS, _check_key
from livesweep.telemetry.mavlink_tlog import _PROBE_BYTES, _TS_MAX_US, _TS_MIN_US, _TS_WINDOW_US, TlogSource, _frame_len
from livesweep.telemetry.mavlink_url import (_FILE_SUFFIXES, _NET_PREFIX_RE, _SHORT_URL_RE, _looks_like_file,
                                             parse_source_url)
from livesweep.telemetry.udp_drops import KERNEL_DROPS_KNOWN, SO_RXQ_OVFL, udp_kernel_drops

__all__ = ["MavlinkSource", "TlogSource", "MavlinkDecoder", "udp_kernel_drops"]

log = logging.getLogger(__name__)

# tcpin: the most clients served at once (more are refused and counted)
_MAX_TCP_CLIENTS = 16

#: Names defined in the modules above that are also importable from here.
_MOVED = (
    _MARKER_V1, _MARKER_V2, _SIG_LEN, _IFLAG_SIGNED, _empty_counts,
    _SIGNING_EPOCH_S, _SIGNING_NEW_STREAM_UNITS,
    _TS_MIN_US, _TS_MAX_US, _TS_WINDOW_US, _PROBE_BYTES, _frame_len,
    _SHORT_URL_RE, _NET_PREFIX_RE, _FILE_SUFFIXES, _looks_like_file, parse_source_url,
    SO_RXQ_OVFL,
)


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

