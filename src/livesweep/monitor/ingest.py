"""The monitor's edge: one thread reads every source and records every frame, analysis never holds it up.

:class:`Ingest` polls the sources, writes each frame to the MCAP recorder as soon as it is read and
offers the frames the analysis needs to a :class:`FrameQueue`. The analysis (aligner, estimator,
view) runs on the caller's thread and takes frames from the queue at its own pace:

* from a **live** source (``source.live`` is True: a MAVLink link, a Zenoh session) the queue never
  makes the ingest wait: frames that do not fit are dropped *for the analysis only* and counted
  (``analysis_shed``); they are in the recording all the same;
* from a **file** (a replay, a tlog, anything without ``live``) the ingest waits for room, so the
  analysis sees every frame and a replay reproduces the live estimates.

On stop, the frames still waiting in a live source (its socket buffer, its parser) are read and
recorded before the thread ends (for at most ``drain_timeout_s``), so nothing that reached the
machine is lost to the stop. An exception in the thread (a full disk) ends it and is re-raised by
:meth:`Ingest.check` on the analysis thread.
"""

from __future__ import annotations

import threading
import time
from collections import deque

__all__ = ["FrameQueue", "Ingest"]


class FrameQueue:
    """A bounded hand-over of frame lists from the ingest thread to the analysis.

    Parameters
    ----------
    limit : int
        Frames held at most.
    shed : bool
        True: :meth:`put` drops what does not fit (counted in :attr:`shed`); False: it waits for room.
    """

    def __init__(self, limit: int, *, shed: bool):
        self.limit = int(limit)
        self.shedding = bool(shed)
        self.shed = 0
        self._items: deque[list] = deque()
        self._n = 0
        self._closed = False
        self._cv = threading.Condition()

    def put(self, frames: list, keep=None) -> None:
        """Queue ``frames`` (a list; dropped and counted beyond the limit when shedding, except those
        whose topic ``keep(topic)`` says must reach the analysis: test-point evidence)."""
        if not frames:
            return
        with self._cv:
            if self.shedding:
                room = self.limit - self._n
                if room < len(frames):
                    # in order: every frame ``keep`` names, and the others while room is left for them
                    must = [keep is not None and keep(f.topic) for f in frames]
                    room = max(room - sum(must), 0)
                    out = []
                    for f, m in zip(frames, must):
                        if m or room > 0:
                            out.append(f)
                            room -= not m
                    self.shed += len(frames) - len(out)
                    frames = out
                    if not frames:
                        return
            else:
                while self._n + len(frames) > self.limit and self._n and not self._closed:
                    self._cv.wait(0.1)
                if self._closed:
                    return
            self._items.append(frames)
            self._n += len(frames)
            self._cv.notify_all()

    def get(self, timeout_s: float, max_frames: int = 5_000) -> list:
        """Queued frames, oldest first: whole batches up to about ``max_frames`` (possibly none
        after ``timeout_s`` [s]), so one turn of the analysis loop stays short."""
        with self._cv:
            if not self._items and not self._closed and timeout_s > 0:
                self._cv.wait(timeout_s)
            out: list = []
            while self._items and (not out or len(out) + len(self._items[0]) <= max_frames):
                out.extend(self._items.popleft())
            self._n -= len(out)
            self._cv.notify_all()
            return out

    def close(self) -> None:
        """No more frames will come; a waiting :meth:`put` gives up."""
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    @property
    def ended(self) -> bool:
        """Closed and empty: the analysis has everything it will get."""
        with self._cv:
            return self._closed and not self._items

    def __len__(self) -> int:
        return self._n


#: At the stop, a source without a drain request is read until it has been quiet this long [s].
_DRAIN_QUIET_S = 0.5


class Ingest(threading.Thread):
    """Reads the sources, records every frame, hands the wanted ones to a :class:`FrameQueue`.

    Parameters
    ----------
    sources : list of frames.Source
    queue : FrameQueue
    recorder : McapRecorder, optional
    wanted_topics : set of str, optional
        Topics the analysis uses; other frames are recorded but not queued, bar the first of each
        topic (None: all).
    also_wanted : callable, optional
        ``also_wanted(topic) -> bool`` for further topics the analysis uses (test-point evidence).
    drain_timeout_s : float
        On stop, read live sources until they are empty, for at most this long [s].
    """

    def __init__(self, sources, queue: FrameQueue, *, recorder=None, wanted_topics=None, also_wanted=None,
                 drain_timeout_s: float = 5.0):
        super().__init__(name="livesweep-ingest", daemon=True)
        self.sources = list(sources)
        self.queue = queue
        self.recorder = recorder
        self.wanted = None if wanted_topics is None else frozenset(wanted_topics)
        self.also_wanted = also_wanted
        self._verdicts: dict[str, bool] = {}     # topic -> wanted (decided once per topic)
        self.drain_timeout_s = float(drain_timeout_s)
        self.received = 0          # frames read from the sources (all recorded, when recording)
        self.received_recorded = 0  # of which from sources that recorded them (a recorder process: it
                                    # forwards only what the analysis takes, and counts all it read)
        #: receive time [ns] of the latest frame from each system (``sysid``; None: frames without one)
        self.last_rx: dict = {}
        self._topics: set[str] = set()  # topics read so far (the first frame of each goes to the analysis)
        self.drained = 0           # of which read while draining at stop
        self.not_taken_at_stop = 0  # frames a source still held when the drain's time was up (not recorded)
        self.error: BaseException | None = None
        self._stop_event = threading.Event()
        self._drain = False

    def stop(self, *, drain: bool) -> None:
        """Ask the thread to end; ``drain``: first read and record what live sources still hold."""
        self._drain = drain
        self._stop_event.set()

    @property
    def finished(self) -> bool:
        """Every source is at its end."""
        return all(s.finished for s in self.sources)

    def check(self) -> None:
        """Re-raise an exception the thread ended with (on the caller's thread)."""
        if self.error is not None:
            err, self.error = self.error, None
            raise err

    def _take(self, frames: list, recorded: bool = False) -> None:
        """Record ``frames`` (unless their source recorded them already: the recorder process's) and
        queue the ones the analysis needs."""
        if self.recorder is not None and not recorded:
            self.recorder.record(frames)
        self.received += len(frames)
        if recorded:
            self.received_recorded += len(frames)
        last = self.last_rx
        for f in frames:
            d = f.data
            last[d.get("sysid") if isinstance(d, dict) else None] = f.receive_ns
        seen = self._topics
        first = None
        for f in frames:
            if f.topic not in seen:
                seen.add(f.topic)
                first = (first or set()) | {id(f)}
        if self.wanted is not None:
            # and the first frame of every other topic: the analysis names what the link carries
            # when a map finds nothing, from the frames it took (so a replay names the same)
            frames = [f for f in frames if self._wants(f.topic) or (first is not None and id(f) in first)]
        self.queue.put(frames, keep=self.also_wanted)

    def _wants(self, topic: str) -> bool:
        w = self._verdicts.get(topic)
        if w is None:
            w = self._verdicts[topic] = topic in self.wanted or (self.also_wanted is not None
                                                                   and self.also_wanted(topic))
        return w

    def run(self) -> None:
        timeout = 0.02 if len(self.sources) > 1 else 0.05
        try:
            while not self._stop_event.is_set():
                for src in self.sources:
                    frames = src.poll(timeout_s=timeout)
                    if frames:
                        self._take(frames, getattr(src, "recorded", False))
                if self.recorder is not None:
                    self.recorder.maybe_flush()
                if self.finished:
                    break
            if self._drain:
                self._drain_live()
        except BaseException as e:  # noqa: BLE001 - handed to the analysis thread, re-raised there
            self.error = e
        finally:
            self.queue.close()

    def _drain_live(self) -> None:
        """What live sources hold at the stop, read and recorded (bounded by ``drain_timeout_s``). A
        recorder process is asked to drain first and says when it has (its counts are final up to
        there); what is still waiting at the deadline is counted (``not_taken_at_stop``)."""
        deadline = time.monotonic() + self.drain_timeout_s
        for src in self.sources:
            if not getattr(src, "live", False):
                continue
            ask = getattr(src, "request_drain", None)
            if ask is not None:
                ask()
            quiet_since = time.monotonic()
            while time.monotonic() < deadline:
                frames = src.poll(timeout_s=0.05)
                if frames:
                    self.drained += len(frames)
                    self._take(frames, getattr(src, "recorded", False))
                    quiet_since = time.monotonic()
                elif ask is not None and src.drained:
                    break
                elif ask is None and time.monotonic() - quiet_since >= _DRAIN_QUIET_S:
                    break                    # what the link still had in flight has arrived
            waiting = getattr(src, "waiting", None)
            if waiting is not None:
                self.not_taken_at_stop += int(waiting)
