"""What ``livesweep inspect`` reports: :class:`LogInspection` and the records it holds.

One job: the frozen records :func:`~livesweep.inspection.inspect_log` returns: each topic
(:class:`TopicInfo`), how each preset fits (:class:`MapFit`), each SystemID run
(:class:`SystemIdRun`) and the whole (:class:`LogInspection`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["TopicInfo", "MapFit", "SystemIdRun", "LogInspection"]


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a log.

    Attributes
    ----------
    topic : str
    messages : int
    rate_hz : float
        Messages per second over the topic's own span (0 for a single message).
    start_s, end_s : float
        First and last receive time [s] relative to the log's first message.
    fields : tuple of (str, str)
        Numeric fields (dotted paths for nested values, ``controls.0``) and their units ("" when
        the log declares none). For a topic livesweep does not decode (``decoded`` False): every
        field its schema declares and the schema's type (``stamp.sec``, ``"int32"``).
    encoding : str
        The message encoding (``json``; ``cdr``, ``protobuf`` ... in an MCAP file).
    decoded : bool
        livesweep reads the messages' values (False: counted, not decoded; no map can use them).
    fields_note : str
        Why the fields cannot be listed ("" when they are, or when the topic simply has none).
    """

    topic: str
    messages: int
    rate_hz: float
    start_s: float
    end_s: float
    fields: tuple = ()
    encoding: str = "json"
    decoded: bool = True
    fields_note: str = ""


@dataclass(frozen=True)
class MapFit:
    """How a preset fits the log.

    Attributes
    ----------
    name : str
    pairs, total : int
        (output, input) pairs whose signals the log holds and vary, of all the map's pairs.
    why : str
        Why it does not fit ("" when it does): another vehicle, signals too slow for the band
        (each slow message with its rate [Hz] and the rate needed [Hz]).
    live : bool
        A preset for the log's telemetry as ``livesweep stream`` sends it (a DataFlash log).
    """

    name: str
    pairs: int
    total: int
    why: str = ""
    live: bool = False

    @property
    def fits(self) -> bool:
        return not self.why


@dataclass(frozen=True)
class SystemIdRun:
    """One ArduPilot SystemID run the log announces.

    Attributes
    ----------
    start_s, end_s : float
        Relative to the log's first message [s]; ``end_s`` NaN when the log does not say.
    axis : int or None
    what : str
        Axis, band and magnitude in words.
    data : bool
        The signals a fitting preset needs for this run (its swept input and required outputs)
        cover it at the rate its band needs; False for a run the log only announces (a log
        filtered around one run keeps the others' texts).
    """

    start_s: float
    end_s: float
    axis: int | None
    what: str
    data: bool = True


@dataclass(frozen=True)
class LogInspection:
    """What :func:`inspect_log` found.

    Attributes
    ----------
    path : Path
        The log asked about.
    format : str
        ``mcap``, ``tlog``, ``dataflash``, ``ulog``, ...
    duration_s : float
    topics : tuple of TopicInfo
    maps : tuple of (str, int, int)
        Presets that fit: ``(name, pairs with data, pairs)``, best first.
    test_points : tuple of (float, float, str)
        ``(start_s, end_s, what)`` of the SystemID runs with data (``SystemIdRun.data``), relative
        to the first message [s].
    notes : tuple of str
    fits : tuple of MapFit
        Every preset that holds signals of the log, fitting or not (with why).
    live_maps : tuple of str
        For a DataFlash log: the presets for its telemetry as ``livesweep stream --rate-hz``
        :data:`STREAM_RATE_HZ` sends it, best first.
    systemid : tuple of SystemIdRun
        Every SystemID run the log announces, with or without data.
    """

    path: Path
    format: str
    duration_s: float
    topics: tuple
    maps: tuple = ()
    test_points: tuple = ()
    notes: tuple = field(default_factory=tuple)
    fits: tuple = ()
    live_maps: tuple = ()
    systemid: tuple = ()
