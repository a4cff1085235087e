"""The one stream every source produces (docs/method.md §1): frames with receive and vehicle times.

Live MAVLink, live Zenoh, the simulator and MCAP replay all yield :class:`Frame` objects, so
replaying a log is just another source and reproduces the live estimates exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

__all__ = ["Frame", "Source"]


@dataclass(frozen=True, slots=True)
class Frame:
    """One received message.

    Attributes
    ----------
    topic : str
        Its MCAP topic: ``/mavlink/<MSGNAME>`` or ``/zenoh/<key expression>`` (docs/outputs.md, MCAP recordings).
    receive_ns : int
        Receive time [ns since the UNIX epoch] (the MCAP ``log_time``).
    vehicle_ns : int or None
        The vehicle time stamp the message carries [ns, the vehicle's clock as sent: not
        unwrapped], or None (the MCAP ``publish_time`` falls back to ``receive_ns``).
    data : dict
        The JSON record, exactly what is recorded.
    """

    topic: str
    receive_ns: int
    vehicle_ns: int | None
    data: dict


class Source(Protocol):
    """What the monitor pipeline needs from a source."""

    def poll(self, timeout_s: float = 0.05, max_frames: int = 10_000) -> list[Frame]:
        """Frames received since the last call (waits up to ``timeout_s`` when there are none)."""

    @property
    def counts(self) -> dict:
        """Counters: received, rejected, malformed, per message type or key, ... (never silent)."""

    @property
    def finished(self) -> bool:
        """True when the source can produce nothing more (end of a log); live sources never finish."""

    def close(self) -> None:
        """Release sockets, sessions and files."""
