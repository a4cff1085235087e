"""The live recording in a process of its own: no analysis, no busy machine can starve it.

A field laptop also runs a ground station and video; the monitor's analysis (aligner, spectra,
Rerun) may fall behind. The recording must not. :class:`LiveCapture` starts a *recorder process*
(``python -m livesweep.telemetry.capture``) that owns the monitor's UDP sockets and its MCAP file:

* **The bytes first.** A loop that does nothing else takes every datagram off its socket (a kernel
  buffer sized to ``KILL_LOSS_S`` of the measured stream, :data:`RCVBUF_BYTES` until the rate is
  known, forced past ``net.core.rmem_max`` where the process may) and writes it, as received, to the MCAP (``/link/mavlink``: the datagram in
  base64 with its receive time) before any parsing: nothing the link delivered is lost to a slow
  decoder, and a kill loses at most what the buffer holds (``KILL_LOSS_S`` of the stream) and the
  last second of the file.
* **Then the decoded messages.** Between reads it decodes the datagrams into the usual
  ``/mavlink/<MSG>`` JSON channels (:class:`~livesweep.telemetry.mavlink_in.MavlinkDecoder`, the
  live source's own checks and counters: CRC, signing, sequence gaps, clock plausibility), so
  Foxglove and every livesweep reader find the messages as they always do. Under a burst it
  falls behind and catches up; at the end it decodes everything left before finishing the file.
* **Then the analysis.** The datagrams the analysis needs (the map's messages, test-point
  evidence, the first of every message type) go to the monitor process over a socket that never
  blocks the recorder: when the analysis is behind they are skipped *for the analysis only* and
  counted (``analysis_shed``), except the test-point evidence (STATUSTEXT, HEARTBEAT, PARAM_VALUE,
  NAMED_VALUE_INT), which waits and is never skipped, so a busy analysis never moves a test
  point's edges. The monitor's results (``/livesweep/...``), its other sources' frames (Zenoh,
  markers) and its counters come back over a second socket and are written to the same file.
* **It finishes the file whatever happens to the monitor**: on the monitor's request (SIGTERM,
  SIGHUP, Ctrl-C and ``--duration`` end the monitor that way), when the monitor process dies (even
  by SIGKILL: the socket closes) and on SIGTERM to the recorder itself. It ignores Ctrl-C and
  SIGHUP, which a terminal sends to the whole process group: the monitor decides when to stop.

Everything the recorder counts (datagrams, bytes, kernel drops, the decoder's counters, the
analysis shed) reaches the monitor about four times a second and is recorded like a live
source's counts.
"""

from __future__ import annotations

import base64
import errno
import json
import logging
import os
import pickle
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections import deque
from pathlib import Path

from livesweep.errors import ConfigError, LivesweepError, LogFormatError
from livesweep.telemetry.mavlink_in import KERNEL_DROPS_KNOWN, SO_RXQ_OVFL
from livesweep.telemetry.recorder import RAW_TOPIC

__all__ = ["LiveCapture", "CaptureSource", "CaptureRecorder", "RAW_TOPIC", "RCVBUF_BYTES", "EVENT_MESSAGES",
           "KILL_LOSS_S", "buffer_for", "frame_heads"]

log = logging.getLogger(__name__)

#: Kernel receive buffer asked for per UDP socket at start [bytes]: about 10 s at 2 000 small
#: datagrams/s (each costs about 0.8-1.3 kB of buffer, not its length). Once the link's rate is
#: known the buffer is sized to hold ``KILL_LOSS_S`` of it (see :func:`buffer_for`).
RCVBUF_BYTES = 16 << 20
#: What a kill of the recorder may lose of the stream that waits in the kernel's buffer [s]: the
#: buffer is sized to this much of the measured rate. Long enough to ride out the stalls of a busy
#: machine (a 2-core laptop with four monitors, five streams and a process on every core stalled
#: the recorder for more than 1 s: a 1 s buffer dropped up to 1 060 datagrams a run where this one
#: drops none), short enough that a kill (power loss) costs seconds, not minutes.
KILL_LOSS_S = 5.0
#: The smallest buffer [bytes]: a slow link keeps about a thousand datagrams of room.
RCVBUF_MIN_BYTES = 1 << 20
#: MAVLink messages that carry test-point evidence or what the vehicle says of itself: forwarded to
#: the analysis even when it is behind (never shed).
EVENT_MESSAGES = {0: "HEARTBEAT", 22: "PARAM_VALUE", 252: "NAMED_VALUE_INT", 253: "STATUSTEXT"}
_RAW_SCHEMA = {"type": "object", "description": "A MAVLink datagram exactly as received (base64)",
               "properties": {"src": {"type": "integer", "description": "index into the channel's sources"},
                              "b64": {"type": "string", "contentEncoding": "base64"}},
               "required": ["src", "b64"]}
_SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)
_STATUS_EVERY_S = 0.25        # counters to the monitor this often [s]
_DROPS_EVERY_S = 1.0          # the kernel's drop count read from /proc this often [s]
_DRAIN_S = 5.0                # at the end, read the sockets until empty for at most this long [s]
_BATCH_BYTES = 48 * 1024      # datagrams forwarded per packet to the monitor, at most
_PENDING_EVENTS = 100_000     # event datagrams waiting for the monitor, at most (then they are shed too)
_READY_S = 20.0               # the recorder process must be ready within this [s]


def frame_heads(data: bytes) -> list[tuple[int, int]] | None:
    """``(message id, system id)`` of the MAVLink frames in a datagram, from their headers alone;
    None when the bytes do not frame as MAVLink."""
    out, p, n = [], 0, len(data)
    while p < n:
        magic = data[p]
        if magic == 0xFD and p + 10 <= n:
            length = 12 + data[p + 1] + (13 if data[p + 2] & 1 else 0)
            out.append((data[p + 7] | (data[p + 8] << 8) | (data[p + 9] << 16), data[p + 5]))
        elif magic == 0xFE and p + 6 <= n:
            length = 8 + data[p + 1]
            out.append((data[p + 5], data[p + 3]))
        else:
            return None
        p += length
    return out


def buffer_for(rate_hz: float, mean_bytes: float) -> int:
    """The kernel buffer [bytes, as ``getsockopt(SO_RCVBUF)`` reports it] that holds ``KILL_LOSS_S``
    of a stream of ``rate_hz`` datagrams/s of ``mean_bytes`` each: Linux charges a datagram about
    ``max(832, length + 1000)`` bytes on loopback (measured), not its length."""
    charge = max(832.0, mean_bytes + 1000.0)
    return int(min(max(rate_hz * KILL_LOSS_S * charge, RCVBUF_MIN_BYTES), 2 * RCVBUF_BYTES))


def _set_rcvbuf(sock: socket.socket, effective_bytes: int) -> int:
    """Ask for a receive buffer of ``effective_bytes`` (Linux doubles what is asked); the one granted."""
    for opt in (_SO_RCVBUFFORCE, socket.SO_RCVBUF):
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, max(effective_bytes // 2, 1))
            break
        except OSError:
            continue
    return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)


def open_udp(host: str, port: int, rcvbuf_bytes: int = RCVBUF_BYTES) -> tuple[socket.socket, int]:
    """A bound, non-blocking UDP socket with the kernel's drop count on every datagram and a large
    receive buffer (forced past ``net.core.rmem_max`` where the process may); returns it and the
    buffer granted [bytes]."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_DGRAM)
    try:
        _set_rcvbuf(sock, 2 * rcvbuf_bytes)
        if KERNEL_DROPS_KNOWN:
            try:
                sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            except OSError:  # pragma: no cover - an old kernel: drops stay unknown
                pass
        sock.bind((host, port))
        sock.setblocking(False)
        return sock, sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    except OSError as e:
        sock.close()
        raise LivesweepError(f"MAVLink input udpin:{host}:{port} cannot be opened: {e.strerror or e}") from None


# ================================================================================================
# the monitor's side
# ================================================================================================


class CaptureSource:
    """The analysis' view of the recorder process: the frames it forwards (implements
    ``frames.Source``; the frames are recorded already, so the monitor does not record them again).

    ``counts`` are the recorder's: every datagram it read, the decoder's counters, kernel drops and
    ``analysis_shed`` (datagrams skipped for the analysis, recorded all the same).
    """

    live = True
    #: The frames come recorded: the monitor's ingest must not write them again.
    recorded = True

    def __init__(self, capture: "LiveCapture"):
        self._cap = capture
        self.description = ", ".join(capture.urls)
        self.url = self.description

    @property
    def counts(self) -> dict:
        return self._cap.counts

    def request_drain(self) -> None:
        """At stop: the recorder reads, decodes and forwards what it holds, then says so (:attr:`drained`)."""
        self._cap.request_drain()

    @property
    def drained(self) -> bool:
        return self._cap.drained

    @property
    def finished(self) -> bool:
        return self._cap.ended

    @property
    def shed(self) -> int:
        """Datagrams the recorder could not hand to the analysis (recorded all the same)."""
        return int(self._cap.counts.get("analysis_shed", 0))

    @property
    def last_rx(self) -> dict:
        """Receive time [ns] of the latest frame per system id, as the recorder saw them."""
        return self._cap.last_rx

    def want(self, topics, system: int | None = None) -> None:
        """Forward only datagrams with one of these ``/mavlink/<MSG>`` topics (and the first of every
        message type, and the test-point evidence), and once the analysis follows one vehicle
        (``system``), only that vehicle's data."""
        self._cap.want(topics, system)

    def poll(self, timeout_s: float = 0.05, max_frames: int = 10_000) -> list:
        return self._cap.poll(timeout_s, max_frames)

    def close(self) -> None:
        pass            # the recorder closes the capture (it must finish the file first)


class CaptureRecorder:
    """The recorder interface (:class:`~livesweep.telemetry.recorder.McapRecorder`'s) of the recorder process."""

    def __init__(self, capture: "LiveCapture"):
        self._cap = capture
        self.path = capture.record_path

    @property
    def bad_publish_time(self) -> int:
        """Frames recorded with their receive time for a vehicle stamp MCAP cannot hold."""
        return int(self._cap.counts.get("bad_publish_time", 0))

    @property
    def unrecordable(self) -> int:
        """Frames the recorder could not write (counted, said as a link alert)."""
        return int(self._cap.counts.get("unrecordable", 0))

    def record(self, frames) -> None:
        """Frames of the monitor's other sources (Zenoh, markers, its own events)."""
        if frames:
            self._cap.send(("frames", [(f.topic, f.receive_ns, f.vehicle_ns, f.data) for f in frames]))

    def record_result(self, name: str, payload: dict, log_time_ns: int, *, flush: bool = False) -> None:
        self._cap.send(("result", name, payload, int(log_time_ns), bool(flush)))

    def set_counters(self, counters: dict) -> None:
        self._cap.send(("counters", counters))

    def maybe_flush(self) -> None:
        pass            # the recorder flushes on its own clock

    @property
    def message_counts(self) -> dict:
        return dict(self._cap.summary.get("message_counts", {}))

    def close(self):
        return self._cap.close()


class LiveCapture:
    """Starts and talks to the recorder process (module docstring).

    Parameters
    ----------
    urls : list of str
        ``udpin:HOST:PORT`` inputs (port 0: any free port; :attr:`urls` then says which).
    record_path : str or Path, optional
        The MCAP file to write; None: the process reads and forwards, records nothing.
    overwrite : bool
        Replace an existing file (``--force``).
    settings, metadata : dict, optional
        As :class:`~livesweep.telemetry.recorder.McapRecorder`'s.
    signing_key : bytes, optional
        32-byte MAVLink 2 signing key (unsigned and forged frames are refused and counted).
    rcvbuf_bytes : int
        Kernel receive buffer asked for per socket [bytes].
    forward_buffer_bytes : int
        Buffer of the socket that hands datagrams to the analysis [bytes]: how far the analysis may
        fall behind before data is shed for it.

    Raises
    ------
    ConfigError, LivesweepError, LogFormatError
        A url that is not ``udpin``, a port that cannot be bound, a file that exists (without
        ``overwrite``) or is being written by another process: one line naming it.
    """

    def __init__(self, urls, *, record_path=None, overwrite: bool = False, settings: dict | None = None,
                 metadata: dict | None = None, signing_key: bytes | None = None,
                 rcvbuf_bytes: int = RCVBUF_BYTES, forward_buffer_bytes: int = 8 << 20):
        from livesweep.telemetry.clock import receive_offset_ns
        from livesweep.telemetry.mavlink_in import MavlinkDecoder, parse_source_url

        self.record_path = None if record_path is None else Path(record_path)
        if self.record_path is not None and self.record_path.exists() and not overwrite:
            raise LogFormatError(f"MCAP log {self.record_path} exists: it is not overwritten unless asked (--force)")
        self._socks, self.urls = [], []
        try:
            for url in urls:
                t = parse_source_url(url)
                if t["kind"] != "udpin":
                    raise ConfigError(f"MAVLink input {url!r}: the recorder process reads udpin links only")
                sock, _granted = open_udp(t["host"], t["port"], rcvbuf_bytes)
                self._socks.append(sock)
                host, port = sock.getsockname()[:2]
                self.urls.append(f"udpin:{host}:{port}")
            self._frames_rx, frames_tx = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            ctl_tx, ctl_rx = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
            for s, size in ((frames_tx, forward_buffer_bytes), (self._frames_rx, forward_buffer_bytes),
                            (ctl_tx, 8 << 20)):
                for opt in (socket.SO_SNDBUF, socket.SO_RCVBUF):
                    try:
                        s.setsockopt(socket.SOL_SOCKET, opt, size)
                    except OSError:  # pragma: no cover
                        pass
            self._frames_rx.setblocking(False)
            config = {"urls": self.urls, "fds": [s.fileno() for s in self._socks], "frames_fd": frames_tx.fileno(),
                      "ctl_fd": ctl_rx.fileno(), "record": None if record_path is None else str(record_path),
                      "overwrite": bool(overwrite), "settings": settings, "metadata": metadata,
                      "key": None if signing_key is None else signing_key.hex(), "clock_offset_ns": receive_offset_ns()}
            env = dict(os.environ)
            src = str(Path(__file__).resolve().parents[2])
            env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
            self._proc = subprocess.Popen([sys.executable, "-m", "livesweep.telemetry.capture"], stdin=subprocess.PIPE,
                                          pass_fds=[*config["fds"], config["frames_fd"], config["ctl_fd"]], env=env,
                                          start_new_session=False)
            self._proc.stdin.write(json.dumps(config).encode())
            self._proc.stdin.close()
            frames_tx.close()
            ctl_rx.close()
            self._ctl = ctl_tx
            self._wait_ready()
        except BaseException:
            self._abandon()
            raise
        for s in self._socks:            # the recorder has its own copies
            s.close()
        self._decoders = [MavlinkDecoder(signing_key, False, live=True) for _ in self.urls]
        self.counts: dict = {"received": {}, "by_system": {}, "datagrams": 0, "analysis_shed": 0}
        self.last_rx: dict = {}
        self.summary: dict = {}
        self.ended = False
        self.drained = False
        self._closed = False
        self._send_lock = threading.Lock()       # the ingest thread and the main thread both send
        self.source = CaptureSource(self)
        self.recorder = CaptureRecorder(self)

    # -- start and stop ---------------------------------------------------------------------------
    def _wait_ready(self) -> None:
        deadline = time.monotonic() + _READY_S
        while time.monotonic() < deadline:
            r, _, _ = select.select([self._frames_rx], [], [], 0.1)
            if r:
                raw = self._frames_rx.recv(1 << 20)
                if not raw:
                    raise LivesweepError(f"the recorder process ended at start (exit code {self._proc.wait()})")
                msg = pickle.loads(raw)
                if msg[0] == "ready":
                    return
                if msg[0] == "error":
                    raise LogFormatError(msg[1])
            if self._proc.poll() is not None:
                raise LivesweepError(f"the recorder process ended at start (exit code {self._proc.returncode})")
        raise LivesweepError(f"the recorder process did not start within {_READY_S:g} s")

    def _abandon(self) -> None:
        for s in getattr(self, "_socks", []):
            s.close()
        proc = getattr(self, "_proc", None)
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()

    def send(self, msg: tuple) -> None:
        """One message to the recorder process (blocks while it is busy; never drops)."""
        if self._closed:
            return
        data = pickle.dumps(msg, protocol=pickle.HIGHEST_PROTOCOL)
        try:
            with self._send_lock:
                self._ctl.sendall(struct.pack("<I", len(data)) + data)
        except OSError as e:
            raise LivesweepError(f"the recorder process is gone ({e.strerror or e}); "
                                 f"exit code {self._proc.poll()}") from None

    def request_drain(self) -> None:
        """Ask the recorder to read what the sockets hold now, decode it, forward what the analysis
        wants and say ``drained`` (then :attr:`drained` is True, its counts final up to there)."""
        self.drained = False
        self.send(("drain",))

    def want(self, topics, system: int | None = None) -> None:
        from livesweep.telemetry.mavlink_codec import message_class

        ids = set()
        for t in topics:
            if t.startswith("/mavlink/"):
                try:
                    ids.add(message_class(t.split("/", 2)[2]).id)
                except ConfigError:
                    continue
        self.send(("want", sorted(ids), system))

    def close(self):
        """Ask the recorder to read what the sockets still hold, decode everything, finish the file
        and end; returns the file's path (None without one). Idempotent."""
        if self._closed:
            return self.record_path
        self._closed = True
        try:
            data = pickle.dumps(("close",), protocol=pickle.HIGHEST_PROTOCOL)
            with self._send_lock:
                self._ctl.sendall(struct.pack("<I", len(data)) + data)
        except OSError:
            pass
        self._frames_rx.setblocking(True)
        self._frames_rx.settimeout(1.0)
        while True:          # the last status and the summary; frames after the stop are of no use now
            try:
                raw = self._frames_rx.recv(1 << 22)
            except socket.timeout:
                if self._proc.poll() is not None:
                    break
                continue
            except OSError:
                break
            if not raw:
                break
            msg = pickle.loads(raw)
            if msg[0] == "status":
                self._status(msg[1])
            elif msg[0] == "closed":
                self.summary = msg[1]
                self._status(msg[1]["status"])
            elif msg[0] == "error":
                self.summary = {"error": msg[1]}
        self._proc.wait()
        self._ctl.close()
        self._frames_rx.close()
        self.ended = True
        if self.summary.get("error"):
            raise LogFormatError(self.summary["error"])
        if self._proc.returncode != 0:
            raise LivesweepError(f"the recorder process failed (exit code {self._proc.returncode})")
        return self.record_path

    # -- frames -----------------------------------------------------------------------------------
    def _status(self, st: dict) -> None:
        self.counts = st["counts"]
        self.last_rx = st["last_rx"]

    def poll(self, timeout_s: float = 0.05, max_frames: int = 10_000) -> list:
        """Frames the recorder forwarded (decoded here), waiting up to ``timeout_s`` when there are none."""
        out: list = []
        if self._closed:
            return out
        sock = self._frames_rx
        waited = False
        while len(out) < max_frames:
            try:
                raw = sock.recv(1 << 22)
            except (BlockingIOError, InterruptedError):
                if out or waited or not timeout_s:
                    break
                select.select([sock], [], [], timeout_s)
                waited = True
                continue
            if not raw:
                self.ended = True
                break
            msg = pickle.loads(raw)
            if msg[0] == "data":
                for k, rx, data in msg[1]:
                    self._decoders[k].datagram(data, rx, out)
            elif msg[0] == "status":
                self._status(msg[1])
            elif msg[0] == "drained":
                self._status(msg[1])
                self.drained = True
                break
            elif msg[0] == "error":
                raise LogFormatError(msg[1])
        return out


# ================================================================================================
# the recorder process
# ================================================================================================


class _Recorder:
    """The recorder process's loop (module docstring)."""

    def __init__(self, cfg: dict):
        from livesweep.telemetry import clock
        from livesweep.telemetry.mavlink_in import MavlinkDecoder
        from livesweep.telemetry.recorder import McapRecorder

        clock.set_receive_offset_ns(cfg["clock_offset_ns"])
        self.receive_ns = clock.receive_ns
        self.urls = cfg["urls"]
        self.socks = [socket.socket(fileno=fd) for fd in cfg["fds"]]
        self.out = socket.socket(fileno=cfg["frames_fd"])
        self.out.setblocking(False)
        self.ctl = socket.socket(fileno=cfg["ctl_fd"])
        self.ctl.setblocking(False)
        self.ctl_buf = bytearray()
        key = bytes.fromhex(cfg["key"]) if cfg.get("key") else None
        self.decoders = [MavlinkDecoder(key, False, live=True) for _ in self.urls]
        self.rec = None
        if cfg.get("record"):
            self.rec = McapRecorder(cfg["record"], settings=cfg.get("settings"), metadata=cfg.get("metadata"),
                                    overwrite=cfg.get("overwrite", False))
            self.rec.writer.add_channel(RAW_TOPIC, "livesweep.datagram", _RAW_SCHEMA,
                                        {"sources": json.dumps(self.urls)})
        self.backlog: deque = deque()          # (src, receive ns, bytes) not decoded yet
        self.fwd: list = []                    # (src, receive ns, bytes) for the monitor
        self.fwd_bytes = 0
        self.events: deque = deque()           # event packets waiting for the monitor
        self.wanted: set | None = None         # msg ids the analysis wants (None: all)
        self.system: int | None = None         # the vehicle the analysis follows (None: any)
        self.seen_ids: set = set()
        self.datagrams = [0] * len(self.urls)
        self.bytes = [0] * len(self.urls)
        self.kernel_drops = [0] * len(self.urls)
        self.shed = 0
        self.last_rx: dict = {}
        self.closing = False
        self.monitor_gone = False
        self.ctl_eof = False
        self.counters: dict | None = None      # the monitor's counters, for the file's metadata
        self.last_status = self.last_drops = time.monotonic()
        self.rcvbuf_bytes = [s.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF) for s in self.socks]
        self._sized_at = (time.monotonic(), [0] * len(self.socks), [0] * len(self.socks))
        self.drain_asked = False
        self.undecoded_at_stop = 0
        self.frames: list = []                 # decoded frames waiting for JSON (reused list)

    # -- reading ----------------------------------------------------------------------------------
    def read(self, k: int, budget: int = 2000) -> int:
        """Take what socket ``k`` holds (at most ``budget`` datagrams): recorded raw at once."""
        sock = self.socks[k]
        rec = self.rec
        write = rec.writer.write_encoded if rec is not None else None
        n = 0
        drops = None
        b64 = base64.b64encode
        prefix = b'{"src":%d,"b64":"' % k
        while n < budget:
            try:
                data, anc, _flags, _addr = sock.recvmsg(65535, 64)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as e:
                if e.errno == errno.ECONNREFUSED:
                    continue
                raise LivesweepError(f"MAVLink input {self.urls[k]}: {e.strerror or e}") from None
            rx = self.receive_ns()
            for level, kind, payload in anc:
                if kind == SO_RXQ_OVFL and len(payload) >= 4:
                    drops = struct.unpack("I", payload[:4])[0]
            if write is not None:
                write(RAW_TOPIC, prefix + b64(data) + b'"}', rx)
            self.backlog.append((k, rx, data))
            self.bytes[k] += len(data)
            n += 1
            self.forward(k, rx, data)
        self.datagrams[k] += n
        if drops is not None:
            self.kernel_drops[k] = drops
        return n

    def forward(self, k: int, rx: int, data: bytes) -> None:
        """Hand a datagram to the analysis if it wants it; events are never shed."""
        heads = frame_heads(data)
        event = False
        if heads is None:
            want = True
        else:
            want = self.wanted is None
            system = self.system
            for i, sysid in heads:
                if i in EVENT_MESSAGES:
                    event = True
                if not want and ((i in self.wanted and (system is None or sysid == system))
                                 or i not in self.seen_ids):
                    want = True
                self.seen_ids.add(i)
        if not (want or event):
            return
        if event:
            self.flush_forward()
            self.send_out(("data", [(k, rx, data)]), event=True)
            return
        self.fwd.append((k, rx, data))
        self.fwd_bytes += len(data) + 32
        if self.fwd_bytes >= _BATCH_BYTES:
            self.flush_forward()

    def flush_forward(self) -> None:
        if self.fwd:
            batch, self.fwd, self.fwd_bytes = self.fwd, [], 0
            self.send_out(("data", batch))

    def send_out(self, msg: tuple, *, event: bool = False) -> bool:
        """One packet to the monitor without ever waiting: a data packet that does not fit is shed
        (counted); an event packet waits for room (bounded) after those already waiting."""
        if self.monitor_gone:
            return False
        if event:
            if len(self.events) >= _PENDING_EVENTS:
                self.shed += 1
                return False
            self.events.append(pickle.dumps(msg, protocol=pickle.HIGHEST_PROTOCOL))
            self.send_events()
            return True
        if self.events:                  # nothing overtakes the evidence still waiting
            self.send_events()
            if self.events:
                if msg[0] == "data":
                    self.shed += len(msg[1])
                return False
        data = pickle.dumps(msg, protocol=pickle.HIGHEST_PROTOCOL)
        try:
            self.out.send(data)
            return True
        except (BlockingIOError, InterruptedError):
            if msg[0] == "data":
                self.shed += len(msg[1])
            return False
        except OSError:
            self.monitor_gone = True
            return False

    def send_events(self) -> None:
        while self.events:
            try:
                self.out.send(self.events[0])
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self.monitor_gone = True
                self.events.clear()
                return
            self.events.popleft()

    # -- decoding -----------------------------------------------------------------------------------
    def decode(self, max_n: int) -> int:
        """Decode up to ``max_n`` datagrams of the backlog into the JSON channels."""
        n = 0
        frames = self.frames
        last_rx = self.last_rx
        while self.backlog and n < max_n:
            k, rx, data = self.backlog.popleft()
            self.decoders[k].datagram(data, rx, frames)
            n += 1
        if frames:
            for f in frames:
                last_rx[f.data.get("sysid")] = f.receive_ns
            if self.rec is not None:
                self.rec.record(frames)
            frames.clear()
        return n

    def readable(self) -> bool:
        """A socket has data waiting (checked between decoding slices)."""
        r, _, _ = select.select(self.socks, [], [], 0)
        return bool(r)

    # -- the monitor's messages ---------------------------------------------------------------------
    def control(self) -> None:
        while not self.ctl_eof:
            try:
                chunk = self.ctl.recv(1 << 20)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                chunk = b""
            if not chunk:                # the monitor closed its end: it is gone (or was closing anyway)
                self.monitor_gone = self.monitor_gone or not self.closing
                self.closing = True
                self.ctl_eof = True
                break
            self.ctl_buf += chunk
        buf = self.ctl_buf
        while len(buf) >= 4:
            (n,) = struct.unpack_from("<I", buf)
            if len(buf) < 4 + n:
                break
            msg = pickle.loads(bytes(buf[4:4 + n]))
            del buf[:4 + n]
            self.handle(msg)

    def handle(self, msg: tuple) -> None:
        kind = msg[0]
        if kind == "result":
            _, name, payload, log_ns, flush = msg
            if self.rec is not None:
                self.rec.record_result(name, payload, log_ns, flush=flush)
        elif kind == "frames":
            if self.rec is not None:
                from livesweep.telemetry.frames import Frame

                self.rec.record([Frame(t, rx, v, d) for t, rx, v, d in msg[1]])
        elif kind == "counters":
            self.counters = msg[1]
        elif kind == "want":
            self.wanted = set(msg[1]) | set(EVENT_MESSAGES)
            self.system = msg[2]
        elif kind == "close":
            self.closing = True
        elif kind == "drain":
            self.drain_asked = True

    # -- status -------------------------------------------------------------------------------------
    def refresh_drops(self) -> None:
        """The kernel's drop count from /proc too (the one stamped on datagrams arrives with the next)."""
        from livesweep.telemetry.mavlink_in import udp_kernel_drops

        for k, sock in enumerate(self.socks):
            drops = udp_kernel_drops(sock)
            if drops is not None:
                self.kernel_drops[k] = max(self.kernel_drops[k], drops)

    def status(self) -> dict:
        counts: dict = {}
        for k, dec in enumerate(self.decoders):
            c = dec.snapshot()
            c["kernel_drops"] = self.kernel_drops[k]
            for key, v in c.items():
                if isinstance(v, dict):
                    merged = counts.setdefault(key, {})
                    for kk, vv in v.items():
                        merged[kk] = merged.get(kk, 0) + vv
                else:
                    counts[key] = counts.get(key, 0) + v
        counts["datagrams"] = sum(self.datagrams)
        counts["bytes"] = sum(self.bytes)
        counts["analysis_shed"] = self.shed
        counts["decode_backlog"] = len(self.backlog)
        counts["undecoded_at_stop"] = self.undecoded_at_stop
        counts["rcvbuf_bytes"] = self.rcvbuf_bytes
        if self.rec is not None:
            counts["unrecordable"] = self.rec.unrecordable
            counts["bad_publish_time"] = self.rec.bad_publish_time
        return {"counts": counts, "last_rx": dict(self.last_rx)}

    def size_buffers(self, now: float) -> None:
        """Each socket's kernel buffer to ``KILL_LOSS_S`` of its measured rate (:func:`buffer_for`):
        what a kill loses of the stream waiting there stays within the promise; a stall longer than
        that costs kernel drops, counted."""
        t0, n0, b0 = self._sized_at
        dt = now - t0
        if dt < 1.0:
            return
        for k, sock in enumerate(self.socks):
            n = self.datagrams[k] - n0[k]
            if n <= 0:
                continue
            want = buffer_for(n / dt, (self.bytes[k] - b0[k]) / n)
            if abs(want - self.rcvbuf_bytes[k]) > 0.25 * self.rcvbuf_bytes[k]:
                self.rcvbuf_bytes[k] = _set_rcvbuf(sock, want)
        self._sized_at = (now, list(self.datagrams), list(self.bytes))

    def drain(self) -> None:
        """What the monitor asked at its stop: read the sockets until empty, decode, forward, say
        ``drained`` with the counts (bounded by ``_DRAIN_S``)."""
        self.read_and_decode()
        self.refresh_drops()
        self.send_out(("drained", self.status()), event=True)

    def read_and_decode(self) -> None:
        """Read the sockets until empty (at most ``_DRAIN_S``), hand the analysis its share, then
        decode the backlog (at most ``_DRAIN_S`` more)."""
        deadline = time.monotonic() + _DRAIN_S
        while time.monotonic() < deadline and sum(self.read(k) for k in range(len(self.socks))):
            pass
        self.flush_forward()
        deadline = time.monotonic() + _DRAIN_S
        while self.backlog and time.monotonic() < deadline:
            self.decode(2_000)

    def periodic(self, now: float) -> None:
        if now - self.last_status >= _STATUS_EVERY_S:
            self.last_status = now
            if now - self.last_drops >= _DROPS_EVERY_S:
                self.last_drops = now
                self.refresh_drops()
                self.size_buffers(now)
            self.flush_forward()
            self.send_out(("status", self.status()))
        if self.rec is not None:
            self.rec.maybe_flush()          # every flush_interval_s (1 s): the most a kill loses

    # -- the loop -----------------------------------------------------------------------------------
    def run(self) -> None:
        socks = self.socks
        waitables = [*socks, self.ctl]
        while not self.closing:
            timeout = 0.0 if self.backlog else 0.05
            r, _, _ = select.select(waitables, [], [], timeout)
            if self.ctl in r:            # the monitor's wishes first: what it wants applies to what is read now
                self.control()
                if self.drain_asked:
                    self.drain_asked = False
                    self.drain()
            got = 0
            for k, s in enumerate(socks):
                if s in r:
                    got += self.read(k)
            if got:
                self.flush_forward()
            if self.events:
                self.send_events()
            # decode between reads, a slice at a time, while no datagram waits
            while self.backlog and not self.closing:
                self.decode(256)
                if self.readable():
                    break
            self.periodic(time.monotonic())
        self.finish()

    def finish(self) -> None:
        """Read what the sockets still hold, decode everything, finish the file, say so."""
        self.read_and_decode()
        # beyond that the stop would wait on decoding: the rest is in the file as received
        # (/link/mavlink), not decoded to /mavlink/*, and counted
        self.undecoded_at_stop = len(self.backlog)
        self.backlog.clear()
        self.control()            # the monitor's last results and counters
        self.refresh_drops()
        st = self.status()
        summary = {"status": st, "message_counts": {}}
        if self.rec is not None and self.counters is not None:
            name = ", ".join(self.urls)              # this process's source, with its final counts
            for entry in self.counters.get("sources", []):
                if entry.get("name") == name:
                    entry.update(st["counts"])
            self.rec.set_counters(self.counters)
        if self.rec is not None:
            summary["message_counts"] = dict(self.rec.message_counts)
            self.rec.close()
        if not self.monitor_gone:
            self.out.setblocking(True)
            self.send_events()
            try:
                self.out.send(pickle.dumps(("closed", summary), protocol=pickle.HIGHEST_PROTOCOL))
            except OSError:
                pass


def _main() -> int:
    import gc

    # the decode backlog of a burst holds millions of objects: a full collection over it would stall
    # the socket loop; the loop makes no reference cycles worth collecting often
    gc.set_threshold(100_000, 50, 1000)
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # the terminal's Ctrl-C is the monitor's to handle
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    cfg = json.loads(sys.stdin.buffer.read())
    out = socket.socket(fileno=cfg["frames_fd"])
    try:
        rec = _Recorder(cfg)
    except (LivesweepError, OSError) as e:
        why = str(e) if isinstance(e, LivesweepError) else \
            f"{cfg.get('record') or 'the recorder'}: cannot be written: {e.strerror or e}"
        out.send(pickle.dumps(("error", why)))
        return 1
    signal.signal(signal.SIGTERM, lambda *a: setattr(rec, "closing", True))
    out.send(pickle.dumps(("ready",)))
    try:
        rec.run()
    except (LivesweepError, OSError) as e:    # a full disk, a socket error: one line to the monitor
        why = str(e) if isinstance(e, LivesweepError) else \
            f"{cfg.get('record') or 'the recorder'}: {e.strerror or e} (recording stopped)"
        if rec.rec is not None:
            try:                              # what is written stays readable (livesweep recover)
                rec.rec.close()
            except (LivesweepError, OSError):
                pass
        try:
            rec.out.setblocking(True)
            rec.out.send(pickle.dumps(("error", why)))
        except OSError:
            pass
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(_main())
