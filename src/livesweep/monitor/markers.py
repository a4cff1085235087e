"""The operator's test-point markers, typed in the monitor's terminal (a :class:`~livesweep.telemetry.frames.Source`).

A flight-test engineer who calls the test points on the radio marks them by typing, one line each:

    s roll      (or "start roll"): a test point starts, sweeping input "roll" (the input may be left out)
    e           (or "end"): it ends

Each line becomes a frame on ``/marker/terminal`` (:data:`livesweep.monitor.testpoints.MARKER_TOPIC`)
with ``{"action": "start"|"end", "input": name or None, "note": the line}``, stamped with the
receive clock. The frames are recorded like any other, so a replay sees the same markers at the
same places. Anything else typed is counted (``ignored_lines``) and answered with one line saying
what the marker syntax is.
"""

from __future__ import annotations

import collections
import sys
import threading

from livesweep.monitor.testpoints import MARKER_TOPIC
from livesweep.telemetry.clock import receive_ns
from livesweep.telemetry.frames import Frame

__all__ = ["MarkerSource", "parse_marker", "HELP"]

HELP = "test-point markers: type 's INPUT' + Enter when a sweep starts, 'e' + Enter when it ends"
_START, _END = ("s", "start"), ("e", "end")


def parse_marker(line: str) -> dict | None:
    """The marker a typed line means, or None when it is not one."""
    words = line.strip().split()
    if not words:
        return None
    word = words[0].lower()
    if word in _START and len(words) <= 2:
        return {"action": "start", "input": words[1] if len(words) == 2 else None, "note": line.strip()}
    if word in _END and len(words) == 1:
        return {"action": "end", "input": None, "note": line.strip()}
    return None


class MarkerSource:
    """Lines of a text stream (the terminal) as marker frames.

    Parameters
    ----------
    stream : text file, optional
        Default ``sys.stdin``. Read on a daemon thread, so a terminal nobody types in never blocks
        the monitor.
    err : text file, optional
        Where a line that is not a marker is answered (default ``sys.stderr``).
    """

    live = True

    def __init__(self, stream=None, err=None):
        self._stream = sys.stdin if stream is None else stream
        self._err = sys.stderr if err is None else err
        self._q: collections.deque[Frame] = collections.deque(maxlen=10_000)
        self._counts = {"markers": 0, "ignored_lines": 0}
        self._closed = False
        self.description = "terminal markers"
        self._thread = threading.Thread(target=self._read, name="livesweep-markers", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            for line in self._stream:
                if self._closed:
                    return
                marker = parse_marker(line)
                if marker is None:
                    if line.strip():
                        self._counts["ignored_lines"] += 1
                        print(f"monitor: not a marker ({line.strip()[:40]!r}); {HELP}", file=self._err, flush=True)
                    continue
                self._counts["markers"] += 1
                self._q.append(Frame(MARKER_TOPIC, receive_ns(), None, marker))
        except (OSError, ValueError):       # the terminal went away: no more markers
            return

    @property
    def counts(self) -> dict:
        return dict(self._counts)

    @property
    def finished(self) -> bool:
        return False

    def poll(self, timeout_s: float = 0.05, max_frames: int = 10_000) -> list[Frame]:
        """The markers typed since the last call; never waits (it always runs next to a link)."""
        out = []
        while self._q and len(out) < max_frames:
            out.append(self._q.popleft())
        return out

    def close(self) -> None:
        self._closed = True
