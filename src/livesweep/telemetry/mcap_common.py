"""What the MCAP log modules share: the file magic, the nanosecond-time check, and how a CRC mismatch is worded.

Part of :mod:`livesweep.telemetry.mcap_log` (the facade: import from there).
"""

from __future__ import annotations

import numbers
from typing import Any

from mcap.records import Chunk
from mcap.stream_reader import CRCValidationError

from livesweep.errors import LogFormatError


_MAGIC = b"\x89MCAP0\r\n"

_UINT64_MAX = 2**64 - 1


def _check_time_ns(value: Any, what: str, where: str) -> int:
    """Return ``value`` as an int if it is an integer number of nanoseconds in [0, 2**64)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise LogFormatError(
            f"{where}: {what} must be an integer number of nanoseconds >= 0, "
            f"got {value!r} ({type(value).__name__})"
        )
    v = int(value)
    if v < 0 or v > _UINT64_MAX:
        raise LogFormatError(
            f"{where}: {what} must be an integer number of nanoseconds in [0, 2**64), got {v}"
        )
    return v


def _crc_text(path, what: str, expected: int, actual: int) -> str:
    return (f"{path}: {what} fails its CRC check (stored {expected:#010x}, computed {actual:#010x}): the log "
            "is damaged (these bytes changed after they were written)")


def _crc_error_text(path, e: CRCValidationError, where: str = "") -> str:
    """_crc_text for mcap's CRCValidationError (a chunk or the data section)."""
    rec = e.record
    where = f" {where}" if where else ""
    if isinstance(rec, Chunk):
        what = f"the chunk{where} (log times {rec.message_start_time} to {rec.message_end_time} ns)"
    else:
        what = f"the data section{where}"
    return _crc_text(path, what, e.expected, e.actual)
