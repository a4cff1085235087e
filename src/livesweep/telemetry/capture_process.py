"""The recorder process: its loop (:class:`_Recorder`) and its entry point (:func:`_main`).

One job: run the process :class:`~livesweep.telemetry.capture.LiveCapture` starts
(``python -m livesweep.telemetry.capture``). Its loop takes every datagram off its sockets and
records it raw at once; forwards to the monitor the datagrams the analysis wants (never blocking:
what does not fit is shed for the analysis and counted, except the test-point evidence of
:data:`EVENT_MESSAGES`, which waits); decodes the backlog into the ``/mavlink/<MSG>`` channels
between reads; records what the monitor sends back; reports its counters; and finishes the file
whatever happens to the monitor. The design is described in :mod:`livesweep.telemetry.capture`.
"""

from __future__ import annotations

import base64
import errno
import json
import pickle
import select
import signal
import socket
import struct
import sys
import time
from collections import deque

from livesweep.errors import LivesweepError
from livesweep.telemetry.capture_udp import _set_rcvbuf, buffer_for
from livesweep.telemetry.recorder import RAW_TOPIC
from livesweep.telemetry.udp_drops import SO_RXQ_OVFL

__all__ = ["EVENT_MESSAGES", "frame_heads"]

#: MAVLink messages that carry test-point evidence or what the vehicle says of itself: forwarded to
#: the analysis even when it is behind (never shed).
EVENT_MESSAGES = {0: "HEARTBEAT", 22: "PARAM_VALUE", 252: "NAMED_VALUE_INT", 253: "STATUSTEXT"}
_RAW_SCHEMA = {"type": "object", "description": "A MAVLink datagram exactly as received (base64)",
               "properties": {"src": {"type": "integer", "description": "index into the channel's sources"},
                              "b64": {"type": "string", "contentEncoding": "base64"}},
               "required": ["src", "b64"]}
_STATUS_EVERY_S = 0.25        # counters to the monitor this often [s]
_DROPS_EVERY_S = 1.0          # the kernel's drop count read from /proc this often [s]
_DRAIN_S = 5.0                # at the end, read the sockets until empty for at most this long [s]
_BATCH_BYTES = 48 * 1024      # datagrams forwarded per packet to the monitor, at most
_PENDING_EVENTS = 100_000     # event datagrams waiting for the monitor, at most (then they are shed too)


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


class _Recorder:
    """The recorder process's loop (the module docstrings of this module and of
    :mod:`livesweep.telemetry.capture`)."""

    def __init__(self, cfg: dict):
        from livesweep.telemetry import clock
        from livesweep.telemetry.mavlink_decode import MavlinkDecoder
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
        from livesweep.telemetry.udp_drops import udp_kernel_drops

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

