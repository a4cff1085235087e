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

Modules: this module holds the monitor's side (:class:`LiveCapture`, which starts the recorder
process and talks to it, and its :class:`CaptureSource` and :class:`CaptureRecorder` views) and is
the recorder process's entry point. The recorder process's loop is
:mod:`~livesweep.telemetry.capture_process`; its sockets and their buffer sizes
:mod:`~livesweep.telemetry.capture_udp`.
"""

from __future__ import annotations

import json
import logging
import os
import pickle
import select
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

from livesweep.errors import ConfigError, LivesweepError, LogFormatError
from livesweep.telemetry.capture_process import (_BATCH_BYTES, _DRAIN_S, _DROPS_EVERY_S, _PENDING_EVENTS, _RAW_SCHEMA,
                                                 _STATUS_EVERY_S, EVENT_MESSAGES, _main, _Recorder, frame_heads)
from livesweep.telemetry.capture_udp import (_SO_RCVBUFFORCE, KILL_LOSS_S, RCVBUF_BYTES, RCVBUF_MIN_BYTES, _set_rcvbuf,
                                             buffer_for, open_udp)
from livesweep.telemetry.recorder import RAW_TOPIC
from livesweep.telemetry.udp_drops import KERNEL_DROPS_KNOWN, SO_RXQ_OVFL

__all__ = ["LiveCapture", "CaptureSource", "CaptureRecorder", "RAW_TOPIC", "RCVBUF_BYTES", "EVENT_MESSAGES",
           "KILL_LOSS_S", "buffer_for", "frame_heads"]

log = logging.getLogger(__name__)

_READY_S = 20.0               # the recorder process must be ready within this [s]

#: Names defined in the modules above that are also importable from here.
_MOVED = (
    KILL_LOSS_S, RCVBUF_MIN_BYTES, _SO_RCVBUFFORCE, _set_rcvbuf,
    _RAW_SCHEMA, _STATUS_EVERY_S, _DROPS_EVERY_S, _DRAIN_S, _BATCH_BYTES, _PENDING_EVENTS, _Recorder,
    KERNEL_DROPS_KNOWN, SO_RXQ_OVFL,
)


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


if __name__ == "__main__":
    sys.exit(_main())
