"""Which vehicle the analysis follows: chosen once for the whole stream.

A link can carry several systems: a second vehicle, a ground station, a companion computer, a
stranger on the same radio channel. Pairing one vehicle's inputs with another's outputs would give
a response of nothing, so the monitor analyses one system (and on each message type one component
of it) and records the rest.

The system is named (``livesweep monitor --sysid``, a map's ``[map].sysid``) or chosen: the first
vehicle, in the order of their first HEARTBEAT (then of their first mapped frame, for a stream
without HEARTBEATs), that has sent ``SETTLE_FRAMES`` frames of **every** mapped message type, at
``MIN_RATE_HZ`` or more on average since its first mapped frame. A vehicle earlier in that order
that has not qualified yet is waited for, for up to ``CHOOSE_WITHIN_FRAMES`` mapped frames. A
ground station (a HEARTBEAT of type GCS) is never chosen. A frame or a few from another system,
arriving first, decide nothing; until the choice the frames are held (in order, bounded), then the
chosen vehicle's are analysed from its first one, so the analysis sees exactly what it would have
seen with that vehicle alone on the link. Counting frames rather than seconds keeps the wait a
fraction of a second of data at any replay speed. When nobody qualifies within
``CHOOSE_WITHIN_FRAMES`` (a vehicle that never sends one of the mapped messages), the system with
the most mapped frames is followed, so the analysis is never starved.

Pure: no I/O; the times are the frames' receive times, so a replay chooses as the live run did.
"""

from __future__ import annotations

from collections import deque

from livesweep.telemetry.frames import Frame

__all__ = ["CHOOSE_WITHIN_FRAMES", "GCS_MAV_TYPE", "MAX_HELD_FRAMES", "MIN_RATE_HZ", "SETTLE_FRAMES",
           "VehicleChooser"]

#: A candidate sends this many frames of every mapped message before it is chosen ...
SETTLE_FRAMES = 10
#: ... at this mean rate or more [Hz of receive time] (a few frames of a stranger never qualify).
MIN_RATE_HZ = 5.0
#: With no choice after this many mapped frames (all systems), the first qualified or the busiest is followed.
CHOOSE_WITHIN_FRAMES = 2_000
#: Frames held while undecided, at most (the oldest beyond are left out of the analysis, counted).
MAX_HELD_FRAMES = 200_000
#: MAVLink MAV_TYPE of a ground control station.
GCS_MAV_TYPE = 6
_HEARTBEAT = "/mavlink/HEARTBEAT"


class VehicleChooser:
    """Holds frames until one system qualifies (see the module notes), then hands them back.

    Parameters
    ----------
    topics : iterable of str
        The mapped topics whose signals follow the vehicle lock (every one must be sent).
    """

    def __init__(self, topics):
        self.topics = frozenset(topics)
        self.held: deque[Frame] = deque()
        self.dropped = 0                                   # held frames left out (the hold was full)
        self._first: dict[int, float] = {}                 # sysid -> first mapped frame [s]
        self._counts: dict[int, dict[str, int]] = {}       # sysid -> topic -> mapped frames
        self._comps: dict[tuple[int, str], dict] = {}      # (sysid, topic) -> compid -> frames
        self._gcs: set[int] = set()
        self._heartbeat: dict[int, float] = {}             # sysid -> first HEARTBEAT [s]
        self._qualified: set[int] = set()
        self._mapped = 0                                   # mapped frames seen (all systems)
        self.reason = ""

    def push(self, frame: Frame) -> tuple[int | None, dict[str, int]] | None:
        """Hold ``frame``; return ``(sysid, {topic: compid})`` once a system is chosen (then take
        :attr:`held` and stop pushing), ``(None, {})`` when the mapped frames carry no system id,
        else None."""
        if len(self.held) >= MAX_HELD_FRAMES:
            self.held.popleft()
            self.dropped += 1
        self.held.append(frame)
        d = frame.data
        sysid = d.get("sysid")
        if sysid is None:
            if frame.topic in self.topics:        # a stream without system ids (Zenoh, a table): nothing to choose
                self.reason = "its frames carry no system id"
                return None, {}
            return None
        t = frame.receive_ns * 1e-9
        if frame.topic == _HEARTBEAT:
            if d.get("type") == GCS_MAV_TYPE:
                self._gcs.add(sysid)
            else:
                self._heartbeat.setdefault(sysid, t)
            return None
        if frame.topic not in self.topics:
            return None
        self._mapped += 1
        self._first.setdefault(sysid, t)
        counts = self._counts.setdefault(sysid, {})
        counts[frame.topic] = counts.get(frame.topic, 0) + 1
        comps = self._comps.setdefault((sysid, frame.topic), {})
        comps[d.get("compid")] = comps.get(d.get("compid"), 0) + 1
        if sysid not in self._qualified and self._qualifies(sysid, t):
            self._qualified.add(sysid)
        if self._qualified:
            first = min((s for s in self._first if s not in self._gcs), key=self._order, default=None)
            if first in self._qualified:
                self.reason = (f"the first vehicle to send {SETTLE_FRAMES} frames of every mapped message at "
                               f"{MIN_RATE_HZ:g} Hz or more")
                return self._chosen(first)
        if self._mapped >= CHOOSE_WITHIN_FRAMES:
            return self.decide_now()
        return None

    def _order(self, sysid: int) -> tuple:
        """Vehicles by their first HEARTBEAT, then (no HEARTBEAT) by their first mapped frame."""
        return (self._heartbeat.get(sysid, float("inf")), self._first[sysid], sysid)

    def _qualifies(self, sysid: int, t: float) -> bool:
        counts = self._counts[sysid]
        if sysid in self._gcs or len(counts) < len(self.topics):
            return False
        least = min(counts.values())
        return least >= SETTLE_FRAMES and least >= MIN_RATE_HZ * (t - self._first[sysid])

    def decide_now(self) -> tuple[int | None, dict[str, int]]:
        """The choice when waiting longer is no use (``CHOOSE_WITHIN_FRAMES`` passed, the stream ended):
        the system that sent the most mapped message types, then the most frames; ``(None, {})``
        when none sent any."""
        if self._qualified:
            first = min(self._qualified, key=self._order)
            self.reason = (f"the first vehicle to send {SETTLE_FRAMES} frames of every mapped message at "
                           f"{MIN_RATE_HZ:g} Hz or more (an earlier one did not within {CHOOSE_WITHIN_FRAMES} frames)")
            return self._chosen(first)
        busiest = max((s for s in self._counts if s not in self._gcs),
                      key=lambda s: (len(self._counts[s]), sum(self._counts[s].values())), default=None)
        if busiest is None:
            self.reason = "no system sent a mapped message"
            return None, {}
        self.reason = (f"no system sent {SETTLE_FRAMES} frames of every mapped message at {MIN_RATE_HZ:g} Hz: "
                       "the one that sent the most")
        return self._chosen(busiest)

    def _chosen(self, sysid: int) -> tuple[int, dict[str, int]]:
        """The system and, per topic, its component that sent that topic most."""
        comps = {topic: max(c.items(), key=lambda kv: kv[1])[0]
                 for (s, topic), c in self._comps.items() if s == sysid}
        return sysid, comps
