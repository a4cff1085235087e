"""Which urls a live MAVLink input accepts: :func:`parse_source_url`.

One job: validate a live input url (``udpin``, ``tcp``, ``tcpin``, serial) and say what to open,
refusing file paths (read with :class:`~livesweep.telemetry.mavlink_tlog.TlogSource`) and
``udpout`` (a monitor receives).
"""

from __future__ import annotations

import os
import re
from typing import Any

from livesweep.errors import ConfigError
from livesweep.telemetry.mavlink_out import parse_url

__all__ = ["parse_source_url"]

_SHORT_URL_RE = re.compile(r"^(udpin|udp|tcpin):(?::)?(\d{1,5})$")
_NET_PREFIX_RE = re.compile(r"^(udpout|udpin|udp|tcp|tcpin):")
_FILE_SUFFIXES = (".tlog", ".bin", ".log", ".mavlink", ".raw", ".px4log", ".ulg", ".mcap", ".elf")


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
