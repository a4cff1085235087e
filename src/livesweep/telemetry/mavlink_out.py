"""Live MAVLink 2 output (UDP, TCP or serial) for the simulator.

:class:`MavlinkSender` encodes canonical records (see
:mod:`livesweep.telemetry.mavlink_codec`) with pymavlink and writes MAVLink 2 frames
(magic 0xFD). :func:`stream_records` paces a time-ordered stream of records to wall time.

Accepted connection strings (anything else is a :class:`ConfigError`; pymavlink is never
handed an arbitrary path, because it *executes* existing files whose path contains
``/bin/`` or ends in ``.elf``)::

    udpout:HOST:PORT    send datagrams to HOST:PORT (the usual choice)
    udpin:HOST:PORT     bind HOST:PORT; send to the peers that have sent us a datagram
    udp:HOST:PORT       same as udpin (pymavlink's legacy form)
    tcp:HOST:PORT       connect to a TCP server
    tcpin:HOST:PORT     listen on HOST:PORT; send to the one accepted client
    /dev/ttyXXX[,BAUD]  serial device (needs pyserial); symlinks such as
                        /dev/serial/by-id/... are resolved to their /dev/tty* target
    COMn[,BAUD]         serial device on Windows

Frames that cannot be written (no peer yet on ``udpin``/``tcpin``, socket errors on UDP)
are counted in :attr:`MavlinkSender.send_errors`, never silently lost; a broken TCP
connection raises :class:`LivesweepError`.
"""

from __future__ import annotations

import logging
import math
import os
import re
import select
import socket
import stat
import struct
import time
from typing import Any, Callable, Iterable, Mapping

from livesweep.errors import ConfigError, LivesweepError
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.mavlink_codec import mavutil  # imported with MAVLINK20=1

__all__ = ["MavlinkSender", "parse_url", "stream_records"]

log = logging.getLogger(__name__)

SNDBUF_BYTES = 4 << 20
_TCP_SEND_TIMEOUT_S = 5.0

_NET_RE = re.compile(r"^(udpout|udpin|udp|tcp|tcpin):([A-Za-z0-9](?:[A-Za-z0-9.\-]*[A-Za-z0-9])?):(\d{1,5})$")
_TTY_RE = re.compile(r"^/dev/(tty[A-Za-z0-9_.\-]+|cu\.[A-Za-z0-9_.\-]+)$")
_COM_RE = re.compile(r"^COM\d{1,3}$", re.IGNORECASE)
_BAUDS = {
    1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800,
    500000, 921600, 1000000, 1500000, 2000000, 3000000,
}


def parse_url(url: str) -> dict[str, Any]:
    """Validate a MAVLink connection string for output.

    Returns ``{"kind", "host", "port"}`` for network links or ``{"kind": "serial",
    "device", "baud"}``. Raises :class:`ConfigError` naming the string otherwise.
    """
    if not isinstance(url, str) or not url or url != url.strip():
        raise ConfigError(f"MAVLink output url {url!r} is empty or has surrounding spaces")
    m = _NET_RE.match(url)
    if m:
        kind, host, port_s = m.groups()
        port = int(port_s)
        if not 1 <= port <= 65535:
            raise ConfigError(f"MAVLink output url {url!r}: port {port} is not in 1..65535")
        return {"kind": "udpin" if kind == "udp" else kind, "host": host, "port": port}
    scheme = url.split(":", 1)[0]
    if ":" in url and not url.startswith("/") and not _COM_RE.match(scheme):
        raise ConfigError(
            f"MAVLink output url {url!r} is not udpout:HOST:PORT, udpin:HOST:PORT, udp:HOST:PORT, "
            "tcp:HOST:PORT, tcpin:HOST:PORT or a serial device (/dev/tty*, COMn) with optional ,BAUD"
        )
    device, _, baud_s = url.partition(",")
    baud = 115200
    if baud_s:
        if not baud_s.isdigit() or int(baud_s) not in _BAUDS:
            raise ConfigError(f"MAVLink output url {url!r}: baud rate {baud_s!r} is not one of {sorted(_BAUDS)}")
        baud = int(baud_s)
    if _COM_RE.match(device):
        return {"kind": "serial", "device": device.upper(), "baud": baud}
    if "/bin/" in device or device.endswith(".elf") or not device.startswith("/dev/"):
        raise ConfigError(
            f"MAVLink output url {url!r} is not a network url or a serial device under /dev "
            "(file paths are refused: pymavlink would read, write or even execute them)"
        )
    real = os.path.realpath(device)
    if not _TTY_RE.match(real) or "/bin/" in real:
        raise ConfigError(f"MAVLink output url {url!r}: {real!r} is not a /dev/tty* serial device")
    try:
        st = os.stat(real)
    except OSError as e:
        raise ConfigError(f"MAVLink output url {url!r}: serial device {real!r} is not usable ({e.strerror})") from None
    if not stat.S_ISCHR(st.st_mode):
        raise ConfigError(f"MAVLink output url {url!r}: {real!r} is not a character device")
    return {"kind": "serial", "device": real, "baud": baud}


def _check_source_id(name: str, v: Any, lo: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= 255:
        raise ConfigError(f"MAVLink {name} {v!r} is not an integer in [{lo}, 255]")
    return v


class MavlinkSender:
    """Send canonical records as MAVLink 2 frames.

    ``source_system``/``source_component`` are used for heartbeats and for records
    without ``sysid``/``compid``; a record's own ``sysid``/``compid`` are honoured, with
    a separate 8-bit sequence counter per (sysid, compid) so receivers' loss accounting
    stays right. ``signing_key`` (32 bytes) signs every outgoing frame (MAVLink 2 signing).

    Attributes: ``sent_counts`` (frames written, per message name), ``send_errors``
    (frames that could not be written), ``bytes_sent``, ``url``.
    """

    def __init__(
        self,
        url: str,
        *,
        source_system: int = 1,
        source_component: int = 1,
        signing_key: bytes | None = None,
    ) -> None:
        self.url = url
        self._target = parse_url(url)
        self.source_system = _check_source_id("source_system", source_system, 1)
        self.source_component = _check_source_id("source_component", source_component, 0)
        if signing_key is not None and (not isinstance(signing_key, (bytes, bytearray)) or len(signing_key) != 32):
            raise ConfigError(
                f"MAVLink signing key must be 32 bytes (e.g. hashlib.sha256(passphrase).digest()), "
                f"got {type(signing_key).__name__} of length {len(signing_key) if hasattr(signing_key, '__len__') else '?'}"
            )
        self.sent_counts: dict[str, int] = {}
        self.send_errors = 0
        self.bytes_sent = 0
        self.last_error: str | None = None
        self._seq: dict[tuple[int, int], int] = {}
        self._encoders: dict[str, tuple[Any, ...]] = {}
        self._closed = False
        self._writes_since_poll = 0

        codec.ensure_mavlink2()
        kind = self._target["kind"]
        try:
            if kind == "serial":
                conn = mavutil.mavlink_connection(
                    self._target["device"], baud=self._target["baud"],
                    source_system=self.source_system, source_component=self.source_component,
                )
            else:
                norm = f"{kind}:{self._target['host']}:{self._target['port']}"
                extra: dict[str, Any] = {"retries": 1} if kind in ("tcp", "tcpin") else {}
                conn = mavutil.mavlink_connection(
                    norm, source_system=self.source_system, source_component=self.source_component, **extra
                )
        except ModuleNotFoundError as e:
            raise LivesweepError(f"MAVLink output {url!r} needs the {e.name!r} package (pip install pyserial)") from None
        except (OSError, ValueError) as e:
            raise LivesweepError(f"MAVLink output {url!r} cannot be opened: {e}") from None
        self._conn = conn
        if not conn.mavlink20():  # pragma: no cover - ensure_mavlink2 guarantees it
            conn.close()
            raise LivesweepError(f"MAVLink output {url!r}: pymavlink did not select MAVLink 2")
        if signing_key is not None:
            conn.setup_signing(bytes(signing_key), sign_outgoing=True)

        self._dest: tuple[str, int] | None = None
        self._sock: socket.socket | None = getattr(conn, "port", None) if kind != "tcpin" else None
        if kind == "udpout":
            try:
                self._dest = (socket.gethostbyname(self._target["host"]), self._target["port"])
            except OSError as e:
                conn.close()
                raise ConfigError(f"MAVLink output url {url!r}: host {self._target['host']!r} does not resolve ({e})") from None
        if kind == "tcp" and self._sock is not None:
            self._sock.settimeout(_TCP_SEND_TIMEOUT_S)  # blocking sendall: no torn frames
        for s in (self._sock, getattr(conn, "listen", None)):
            if isinstance(s, socket.socket):
                try:
                    s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SNDBUF_BYTES)
                except OSError:  # pragma: no cover - best effort
                    pass

    # ---------------------------------------------------------------- properties
    @property
    def connection(self) -> Any:
        """The underlying pymavlink connection (for advanced use)."""
        return self._conn

    @property
    def mav(self) -> Any:
        return self._conn.mav

    # ---------------------------------------------------------------- sending
    def _encoder(self, msgname: str):
        enc = self._encoders.get(msgname)
        if enc is None:
            spec = codec._spec(msgname)  # ConfigError for unknown names
            fn = getattr(self._conn.mav, msgname.lower() + "_encode", None)
            if fn is None:
                raise ConfigError(f"MAVLink message {msgname!r} cannot be encoded by dialect {mavutil.current_dialect!r}")
            names = tuple(f.name for f in spec.fields)
            floats = tuple(f.name for f in spec.fields if f.kind in ("f32", "f64") and not f.length)
            farrays = tuple(f.name for f in spec.fields if f.kind in ("f32", "f64") and f.length)
            chars = tuple(f.name for f in spec.fields if f.kind == "char")
            enc = (fn, names, frozenset(names), floats, farrays, chars)
            self._encoders[msgname] = enc
        return enc

    def send_record(self, msgname: str, record: Mapping[str, Any]) -> None:
        """Encode ``record`` (canonical form) as ``msgname`` and send one MAVLink 2 frame.

        ``None`` float values (stored nulls) are sent as NaN. Records that are not canonical
        (missing fields, values that need coercion) go through
        :func:`~livesweep.telemetry.mavlink_codec.record_from_fields` first; unknown fields
        and values the wire cannot carry raise :class:`ConfigError` naming field and value.
        """
        if self._closed:
            raise LivesweepError(f"MAVLink output {self.url!r} is closed")
        fn, names, fieldset, floats, farrays, chars = self._encoder(msgname)
        sysid = record.get("sysid", self.source_system)
        compid = record.get("compid", self.source_component)
        canonical = False
        keys = record.keys()
        if not (fieldset <= keys and len(keys) - ("sysid" in keys) - ("compid" in keys) == len(names)):
            record = self._canonical(msgname, record, sysid, compid)
            canonical = True
        if not (type(sysid) is int and type(compid) is int and 0 <= sysid <= 255 and 0 <= compid <= 255):
            sysid, compid = self._ids(msgname, sysid, compid)
        while True:
            kw = {n: record[n] for n in names}
            for n in floats:
                if kw[n] is None:
                    kw[n] = math.nan
            for n in farrays:
                v = kw[n]
                if any(x is None for x in v):
                    kw[n] = [math.nan if x is None else x for x in v]
            try:
                for n in chars:
                    v = kw[n]
                    if isinstance(v, str):
                        kw[n] = v.encode("ascii")
                buf = self._pack(fn(**kw), sysid, compid)
                break
            except (struct.error, TypeError, ValueError, OverflowError, IndexError, UnicodeEncodeError) as e:
                if canonical:
                    raise ConfigError(f"MAVLink {msgname}: record cannot be encoded ({e}): {dict(record)!r}") from None
                # not canonical after all (e.g. 3.0 for an integer field): coerce with the
                # codec, which names a bad field and value, then try once more
                record = self._canonical(msgname, record, sysid, compid)
                canonical = True
        self._emit(buf, msgname)

    @staticmethod
    def _canonical(msgname: str, record: Mapping[str, Any], sysid: Any, compid: Any) -> dict[str, Any]:
        fields = {k: v for k, v in record.items() if k not in ("sysid", "compid")}
        return codec.record_from_fields(msgname, fields, sysid=sysid, compid=compid)

    @staticmethod
    def _ids(msgname: str, sysid: Any, compid: Any) -> tuple[int, int]:
        ok = all(
            not isinstance(v, bool) and isinstance(v, (int,)) and 0 <= v <= 255 for v in (sysid, compid)
        )
        if not ok:
            try:
                sysid, compid = int(sysid), int(compid)
            except (TypeError, ValueError):
                ok = False
            else:
                ok = 0 <= sysid <= 255 and 0 <= compid <= 255
            if not ok:
                raise ConfigError(f"MAVLink {msgname}: sysid {sysid!r} / compid {compid!r} not integers in [0, 255]")
        return int(sysid), int(compid)

    def send_frame(self, frame: bytes, msgname: str) -> None:
        """Send one MAVLink frame that is already encoded (a tlog's record), as it is, with this
        sender's retries on a full send buffer and its counters (``sent_counts[msgname]``)."""
        if self._closed:
            raise LivesweepError(f"MAVLink output {self.url!r} is closed")
        self._emit(bytes(frame), msgname)

    def send_heartbeat(self) -> None:
        """Send a HEARTBEAT (MAV_TYPE_FIXED_WING, MAV_AUTOPILOT_GENERIC, MAV_STATE_ACTIVE)."""
        if self._closed:
            raise LivesweepError(f"MAVLink output {self.url!r} is closed")
        m = mavutil.mavlink
        msg = self._conn.mav.heartbeat_encode(
            m.MAV_TYPE_FIXED_WING, m.MAV_AUTOPILOT_GENERIC, 0, 0, m.MAV_STATE_ACTIVE
        )
        self._emit(self._pack(msg, self.source_system, self.source_component), "HEARTBEAT")
        self._poll_peers()

    def _pack(self, msg: Any, sysid: int, compid: int) -> bytes:
        """MAVLink 2 frame of ``msg`` from (sysid, compid), with that source's own sequence."""
        mav = self._conn.mav
        key = (sysid, compid)
        seq = self._seq.get(key, 0)
        mav.srcSystem, mav.srcComponent, mav.seq = sysid, compid, seq
        buf = msg.pack(mav)
        self._seq[key] = (seq + 1) & 0xFF
        return buf

    def _emit(self, buf: bytes, msgname: str) -> None:
        if self._write(buf):
            self.sent_counts[msgname] = self.sent_counts.get(msgname, 0) + 1
            self.bytes_sent += len(buf)
        else:
            self.send_errors += 1

    def _error(self, what: str) -> bool:
        if self.last_error is None:
            log.warning("MAVLink output %s: %s (further errors are only counted)", self.url, what)
        self.last_error = what
        return False

    def _write(self, buf: bytes) -> bool:
        kind = self._target["kind"]
        if kind == "udpout":
            sock = self._sock
            assert sock is not None and self._dest is not None
            for _ in range(50):
                try:
                    sock.sendto(buf, self._dest)
                    return True
                except BlockingIOError:  # send buffer full: wait instead of dropping
                    select.select([], [sock], [], 0.1)
                except OSError as e:
                    return self._error(f"sendto {self._dest}: {e}")
            return self._error(f"sendto {self._dest}: send buffer stayed full for 5 s")
        if kind == "udpin":
            self._writes_since_poll += 1
            if self._writes_since_poll >= 64 or not self._conn.clients:
                self._poll_peers()
            clients = list(self._conn.clients)
            if not clients:
                return self._error("no peer has sent a datagram yet (udpin sends only to known peers)")
            ok = True
            for addr in clients:
                try:
                    self._conn.port.sendto(buf, addr)
                except OSError as e:
                    ok = self._error(f"sendto {addr}: {e}")
            return ok
        if kind == "tcp":
            try:
                self._sock.sendall(buf)  # type: ignore[union-attr]
                return True
            except OSError as e:
                raise LivesweepError(f"MAVLink output {self.url!r}: TCP send failed ({e})") from None
        if kind == "tcpin":
            conn = self._conn
            if conn.port is None:
                self._poll_peers()
            if conn.port is None:
                return self._error("no TCP client connected yet")
            try:
                conn.port.sendall(buf)
                return True
            except OSError as e:
                try:
                    conn.port.close()
                finally:
                    conn.port = None
                    conn.fd = conn.listen.fileno()
                return self._error(f"TCP client lost ({e})")
        self._conn.write(buf)  # serial
        return True

    def _poll_peers(self) -> None:
        """udpin: learn peers from incoming datagrams; tcpin: accept a waiting client."""
        kind = self._target["kind"]
        self._writes_since_poll = 0
        if kind == "udpin":
            for _ in range(256):
                try:
                    data, addr = self._conn.port.recvfrom(65535)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    break
                self._conn.clients.add(addr)
                self._conn.clients_last_alive[addr] = time.time()
        elif kind == "tcpin" and self._conn.port is None:
            try:
                client, _addr = self._conn.listen.accept()
            except (BlockingIOError, InterruptedError, OSError):
                return
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client.settimeout(_TCP_SEND_TIMEOUT_S)
            self._conn.port = client
            self._conn.fd = client.fileno()

    def close(self) -> None:
        """Close the link (idempotent)."""
        if not self._closed:
            self._closed = True
            try:
                self._conn.close()
            except OSError:  # pragma: no cover
                pass

    def __enter__(self) -> "MavlinkSender":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"MavlinkSender({self.url!r}, sent={sum(self.sent_counts.values())}, errors={self.send_errors})"


def _check_speed(speed: Any) -> float:
    try:
        s = float(speed)
    except (TypeError, ValueError):
        raise ConfigError(f"replay speed {speed!r} is not a number") from None
    if math.isnan(s) or s < 0:
        raise ConfigError(f"replay speed {speed!r} must be > 0 (or inf/0 for as fast as possible)")
    return s


def stream_records(
    sender: Any,
    timed_records: Iterable[tuple[float, str, Mapping[str, Any]]],
    *,
    speed: float,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], Any] = time.sleep,
    heartbeat_period_s: float | None = 1.0,
) -> dict[str, Any]:
    """Send ``(vehicle_time_s, msgname, record)`` items paced to wall time.

    Wall time elapsed tracks ``(vehicle_time - first_vehicle_time) / speed``.
    ``speed=math.inf`` sends as fast as possible; ``speed=0`` is accepted as the same
    (the usual command-line convention). Negative or NaN speeds raise :class:`ConfigError`.
    Items must come in non-decreasing vehicle time (a step back raises ConfigError naming
    it). A HEARTBEAT is sent before the first record and then every
    ``heartbeat_period_s`` of vehicle time (``None`` disables heartbeats).

    Returns ``{"counts": {msgname: n, "HEARTBEAT": n}, "n_records", "wall_duration_s",
    "vehicle_duration_s", "max_lateness_s", "speed", "send_errors"}`` where lateness is how
    long after its due wall time an item was handed to the sender (0 when unpaced), and
    ``send_errors`` the frames the sender could not write during this call.
    """
    speed = _check_speed(speed)
    paced = speed != 0 and not math.isinf(speed)
    if heartbeat_period_s is not None:
        try:
            hb = float(heartbeat_period_s)
        except (TypeError, ValueError):
            raise ConfigError(f"heartbeat period {heartbeat_period_s!r} is not a number") from None
        if not (hb > 0 and math.isfinite(hb)):
            raise ConfigError(f"heartbeat period {heartbeat_period_s!r} s must be a positive number (or None)")
    else:
        hb = 0.0
    errors0 = getattr(sender, "send_errors", 0)
    counts: dict[str, int] = {}
    n = 0
    t_first: float | None = None
    t_prev = -math.inf
    next_hb = math.inf
    max_late = 0.0
    wall0 = clock()
    for item in timed_records:
        t_raw, msgname, record = item
        t = float(t_raw)
        if not math.isfinite(t):
            raise ConfigError(f"record {n} ({msgname}): vehicle time {t_raw!r} is not finite")
        if t < t_prev:
            raise ConfigError(
                f"record {n} ({msgname}): vehicle time {t!r} s is before the previous record's {t_prev!r} s "
                "(records must be in non-decreasing time order)"
            )
        t_prev = t
        if t_first is None:
            t_first = t
            next_hb = t if hb else math.inf
        if paced:
            target = wall0 + (t - t_first) / speed
            now = clock()
            if now < target:
                sleep(target - now)
                now = clock()
            if now - target > max_late:
                max_late = now - target
        if t >= next_hb:
            sender.send_heartbeat()
            counts["HEARTBEAT"] = counts.get("HEARTBEAT", 0) + 1
            next_hb = t_first + hb * (math.floor((t - t_first) / hb) + 1)
        sender.send_record(msgname, record)
        counts[msgname] = counts.get(msgname, 0) + 1
        n += 1
    wall = clock() - wall0
    return {
        "counts": counts,
        "n_records": n,
        "wall_duration_s": wall,
        "vehicle_duration_s": 0.0 if t_first is None else t_prev - t_first,
        "max_lateness_s": max_late,
        "speed": speed,
        "send_errors": getattr(sender, "send_errors", 0) - errors0,
    }
