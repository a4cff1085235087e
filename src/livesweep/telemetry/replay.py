"""MCAP replay as a frame source: the same pipeline as live, from a log (docs/method.md §1)."""

from __future__ import annotations

import math
import time

from livesweep.errors import ConfigError
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mcap_log import SkippedMessages, iter_file_order
from livesweep.telemetry.recorder import RAW_TOPIC, RESULT_PREFIX

__all__ = ["McapReplaySource"]


class McapReplaySource:
    """Frames of a recorded log in the order they were received.

    Parameters
    ----------
    path : str or Path
    speed : float
        0 or inf: as fast as possible; N: N times real time (paced by the receive times).
    include_results : bool
        Replay livesweep's own ``/livesweep/...`` results too (default no: they are recomputed).

    The raw datagrams a live recording keeps (``RAW_TOPIC``) are not replayed: the decoded
    ``/mavlink/<MSG>`` channels carry the same frames, as the live analysis took them.

    A message that is not a JSON object (damaged, nested too deeply, an array) or a chunk that
    fails its CRC is skipped and counted (``counts["skipped_messages"]``, and by reason in
    ``counts["skipped"]``), never fatal: the rest of the log replays.
    """

    #: A file: the monitor reads it at its own pace and never sheds analysis load.
    live = False

    def __init__(self, path, *, speed: float = 0.0, include_results: bool = False,
                 clock=time.monotonic, sleep=time.sleep):
        if not (speed == 0 or speed > 0) or (isinstance(speed, float) and math.isnan(speed)):
            raise ConfigError(f"replay speed must be > 0 (or 0 for as fast as possible), got {speed!r}")
        self.path = path
        self.speed = float(speed)
        self._skipped = SkippedMessages()
        self._it = iter_file_order(path, skipped=self._skipped)
        self._include_results = include_results
        self._clock, self._sleep = clock, sleep
        self._t0_log: int | None = None
        self._t0_wall = 0.0
        self._pending = None
        self._finished = False
        self._counts = {"replayed": {}, "skipped_results": 0, "skipped_raw": 0}

    @property
    def counts(self) -> dict:
        return {**self._counts, "skipped_messages": self._skipped.total, "skipped": dict(self._skipped.counts)}

    @property
    def finished(self) -> bool:
        return self._finished

    def poll(self, timeout_s: float = 0.05, max_frames: int = 10_000) -> list[Frame]:
        out: list[Frame] = []
        paced = self.speed > 0 and math.isfinite(self.speed)
        while len(out) < max_frames:
            m = self._pending if self._pending is not None else next(self._it, None)
            self._pending = None
            if m is None:
                self._finished = True
                break
            if m.topic.startswith(RESULT_PREFIX + "/") and not self._include_results:
                self._counts["skipped_results"] += 1
                continue
            if m.topic == RAW_TOPIC:
                self._counts["skipped_raw"] += 1
                continue
            if paced:
                if self._t0_log is None:
                    self._t0_log, self._t0_wall = m.log_time_ns, self._clock()
                due = self._t0_wall + (m.log_time_ns - self._t0_log) * 1e-9 / self.speed
                wait = due - self._clock()
                if wait > 0:
                    if out or wait > timeout_s:
                        self._pending = m
                        if not out:
                            self._sleep(timeout_s)
                        break
                    self._sleep(wait)
            vehicle = m.publish_time_ns if m.publish_time_ns != m.log_time_ns else None
            out.append(Frame(m.topic, m.log_time_ns, vehicle, m.data))
            c = self._counts["replayed"]
            c[m.topic] = c.get(m.topic, 0) + 1
        return out

    def close(self) -> None:
        self._finished = True
