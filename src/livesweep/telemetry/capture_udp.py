"""The recorder process's UDP sockets and the size of their kernel buffers.

One job: open a bound, non-blocking UDP socket that reports the kernel's drop count with every
datagram (:func:`open_udp`), and size its receive buffer to hold ``KILL_LOSS_S`` of the measured
stream (:func:`buffer_for`), so a kill of the recorder loses at most that much of what waits in the
kernel. Part of :mod:`livesweep.telemetry.capture`.
"""

from __future__ import annotations

import socket

from livesweep.errors import LivesweepError
from livesweep.telemetry.udp_drops import KERNEL_DROPS_KNOWN, SO_RXQ_OVFL

__all__ = ["RCVBUF_BYTES", "KILL_LOSS_S", "RCVBUF_MIN_BYTES", "buffer_for", "open_udp"]

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
_SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)


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

