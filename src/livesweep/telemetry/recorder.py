"""Live MCAP recording: every received message as it came, plus livesweep's results (DESIGN.md §4.1).

The file is written directly (not atomically: a recording must survive the process being
killed) and the open chunk is closed and handed to the OS every ``flush_interval_s`` of wall
time, so a kill loses at most that much (default 1 s) plus what the OS had not written.
Ctrl-C or ``--duration`` ends with :meth:`McapRecorder.close`, which finishes the file (summary,
index) so any MCAP reader opens it.
"""

from __future__ import annotations

import json
import time

from livesweep import __version__
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mcap_log import McapLogWriter

__all__ = ["McapRecorder", "RESULT_PREFIX"]

RESULT_PREFIX = "/livesweep"
_GENERIC = {"type": "object", "description": "JSON object as received"}


def _schema_for(topic: str) -> tuple[str, dict]:
    if topic.startswith("/mavlink/"):
        from livesweep.telemetry import mavlink_codec

        name = topic.split("/", 2)[2]
        try:
            return f"mavlink.{name}", mavlink_codec.json_schema(name)
        except Exception:  # noqa: BLE001 - an unknown message still gets recorded
            return f"mavlink.{name}", _GENERIC
    return topic.strip("/").replace("/", "."), _GENERIC


class McapRecorder:
    """Records frames and results to ``path``.

    Parameters
    ----------
    path : str or Path
    flush_interval_s : float
        Wall-clock period of chunk flushes [s]: the most a kill can lose.
    settings : dict, optional
        Stored as the ``livesweep_settings.json`` attachment (the channel map and spectral
        settings the live results came from).
    metadata : dict of str -> dict, optional
        MCAP metadata records (test point: aircraft, condition, manoeuvre, notes).
    """

    def __init__(self, path, *, flush_interval_s: float = 1.0, settings: dict | None = None,
                 metadata: dict | None = None, clock=time.monotonic):
        self.writer = McapLogWriter(path, library=f"livesweep {__version__} recorder", atomic=False,
                                    chunk_size=256 * 1024, flush_every=0)
        self.flush_interval_s = flush_interval_s
        self._clock = clock
        self._last_flush = clock()
        self.path = self.writer.path
        for name, values in (metadata or {}).items():
            self.writer.add_metadata(name, values)
        if settings is not None:
            self.writer.add_attachment("livesweep_settings.json", json.dumps(settings, indent=1).encode(),
                                       "application/json")
        self._known: set[str] = set()

    def _channel(self, topic: str, schema: tuple[str, dict] | None = None) -> None:
        if topic not in self._known:
            name, sch = schema or _schema_for(topic)
            self.writer.add_channel(topic, name, sch)
            self._known.add(topic)

    def record(self, frames: list[Frame]) -> None:
        """Write received frames (log_time = receive time, publish_time = vehicle time or receive time)."""
        for f in frames:
            self._channel(f.topic)
            self.writer.write(f.topic, f.data, log_time_ns=f.receive_ns,
                              publish_time_ns=f.vehicle_ns if f.vehicle_ns is not None and f.vehicle_ns >= 0 else None)
        self.maybe_flush()

    def record_result(self, name: str, payload: dict, log_time_ns: int) -> None:
        """Write a live result on ``/livesweep/<name>``."""
        topic = f"{RESULT_PREFIX}/{name}"
        self._channel(topic, (f"livesweep.{name}", {"type": "object", "description": f"livesweep live {name}"}))
        self.writer.write(topic, payload, log_time_ns=log_time_ns)

    def maybe_flush(self) -> None:
        now = self._clock()
        if now - self._last_flush >= self.flush_interval_s:
            self.writer.flush()
            self._last_flush = now

    @property
    def message_counts(self) -> dict:
        return self.writer.message_counts

    def close(self):
        """Finish the file (idempotent)."""
        if not self.writer.closed:
            return self.writer.close()
        return self.writer.path
