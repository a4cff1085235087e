"""The kernel's count of UDP datagrams dropped for a full socket receive buffer (Linux).

One job: say how many datagrams a socket lost before they were read. Linux stamps that count on
every datagram when the socket has ``SO_RXQ_OVFL`` set, and lists it in ``/proc/net/udp``
(:func:`udp_kernel_drops`), which also shows drops at the end of a burst.
"""

from __future__ import annotations

import os
import socket
import sys

__all__ = ["SO_RXQ_OVFL", "KERNEL_DROPS_KNOWN", "udp_kernel_drops"]

#: Linux: the socket option that reports the kernel's drop count with every datagram.
SO_RXQ_OVFL = 40
#: Whether the kernel says how many datagrams it dropped (Linux).
KERNEL_DROPS_KNOWN = sys.platform.startswith("linux")


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

