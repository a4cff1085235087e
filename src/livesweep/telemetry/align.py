"""From frames to uniform sample blocks on one clock: the monitor's aligner (docs/method.md §1).

* **One clock.** Every signal is timed by its stamp field (vehicle time) when the channel map
  names one, else by the receive time; a map that mixes the two is refused (the clocks are not
  comparable). A message without a time field (MAVLink PID_TUNING) may borrow one from another
  topic of the same vehicle (``stamp_topic``): it takes the stamp of the latest such frame received
  before it, at most ``BORROW_WITHIN_S`` of receive time earlier, so it stays on the vehicle clock
  at any replay speed.
* **Stamps are checked before use.** Each (topic, stamp field) has its own
  :class:`~livesweep.telemetry.clock.StampClock`: a stamp that does not follow the stream's
  recent clock (a corrupt or forged frame, a value from another epoch, one stamp a few seconds
  ahead) is dropped and counted (``clock_rejected``); the clock re-anchors (a reboot, a switch to
  UNIX time) only after several consecutive stamps agree, and then continues ``reset_gap_s``
  after the last sample, so no window spans the discontinuity (``resets``). All clocks of one
  vehicle that re-anchor at one reboot take the same offset, so signals from different messages
  stay aligned to the sample. uint32 MAVLink time fields are unwrapped (``wraps``); other fields
  never are. Each stream's first few stamps establish its clock (they are held, then released
  together), so a bad first stamp never becomes its reference.
* **One vehicle, chosen once.** MAVLink frames carry ``sysid`` and ``compid``: the aligner
  analyses one system, named (``system``) or chosen by
  :class:`~livesweep.telemetry.vehicle_choice.VehicleChooser` (the first to send 10 frames of every
  mapped message; frames are held until then, so a stranger's frames arriving first
  decide nothing), and on each topic one component of it; frames of other systems and components
  are counted (``other_system``, ``other_component``) and left out (the recording keeps them
  all), so one vehicle's inputs are never paired with another's outputs. A signal that names its own ``sysid``/``compid`` takes the frames of that vehicle
  instead (its stamps then have a clock of their own; ``other_system`` still counts the frames the
  lock leaves out for the other signals); a topic whose signals all do so does not move the lock.
* **One extraction.** What a frame gives each signal (its selection by ``sysid``, ``compid`` and
  ``where``, the field or expression, ``scale`` and ``offset``) is decided by the signal's
  :class:`~livesweep.telemetry.extract.SignalExtractor`, the same object the offline reader uses.
  :attr:`GridAligner.signal_counts` counts, per signal, the samples taken and the frames that gave
  none (``missing_field``, ``not_a_number``, ``filtered`` by the selection, ``other_vehicle``),
  for :func:`~livesweep.telemetry.extract.diagnose`.
* **Multi-rate alignment.** Each signal keeps its recent samples; grid samples ``t0 + k/fs`` are
  emitted once every signal has reached them, by linear interpolation between the bracketing
  samples. Where the bracketing samples are further apart than ``max(max_interp_gap_s, 1.5 x the
  signal's spacing)`` (the median of its first four) the grid sample is marked invalid (a gap:
  excluded, never interpolated across). A signal that stops while others go on for
  ``gap_timeout_s`` is marked invalid from its last sample on, so one dead channel does not stall
  the others. The grid starts once every signal has four samples.
* **The frames alone decide.** How far the grid may go (the *frontier*) moves with every frame
  pushed, and a sample that arrives for a time the frontier has passed is dropped and counted
  (``late_dropped``), so what :meth:`GridAligner.pop_ready` emits depends on the frames and their
  order only, never on when it is called or on wall-clock time: replaying a recording through the
  same aligner reproduces the live blocks exactly.
* **Bounded memory whatever the stamps say.** A block holds at most ``max_fill_s`` of grid (call
  :meth:`GridAligner.pop_ready` until it returns None); of a stretch where no signal has a sample
  (a jump of the clock) only the last ``max_fill_s`` is emitted, all of it invalid so the
  estimator's window is flushed, and the rest is skipped (``samples_skipped``); samples waiting for
  a signal that never arrived are kept for ``max_fill_s`` at most.
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from livesweep.config import SignalSpec
from livesweep.errors import ConfigError
from livesweep.telemetry.clock import StampClock
from livesweep.telemetry.extract import SIGNAL_COUNT_KEYS, as_number, compile_signal, lookup  # as_number: re-exported
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.vehicle_choice import VehicleChooser

__all__ = ["AlignedBlock", "GridAligner", "as_number"]

_EPS_S = 1e-7   # stamps within 0.1 us of a grid time are on it (grid times carry float round-off)
_FIRST_SAMPLES = 4   # a signal's spacing is the median of its first few (the grid starts once all have one)
_SAME_REBOOT_S = 10.0   # re-anchorings of one vehicle this close (offset and new stamps) are one reboot
#: A borrowed stamp (``stamp_topic``) is taken from a frame received at most this long before [s].
BORROW_WITHIN_S = 0.5


def _wrap_units(topic: str, field: str) -> int | None:
    """2**32 for a uint32 MAVLink time field (it wraps), else None (DataFlash, Zenoh, uint64 fields)."""
    if not topic.startswith("/mavlink/"):
        return None
    from livesweep.telemetry.mavlink_codec import stamp_wrap_units

    return stamp_wrap_units(topic.split("/", 2)[2], field)


@dataclass(frozen=True)
class AlignedBlock:
    """Uniform samples ready for the estimator.

    Attributes
    ----------
    t0_s : float
        Time of the first sample [s, the signals' clock].
    values : ndarray, shape (n_signals, n)
    valid : ndarray of bool, shape (n,)
        False where any signal is in a gap.
    t_s : ndarray, shape (n,), optional
        The sample times [s]: ``t0 + k / fs`` from the grid's own origin, so a sample has the same
        time to the last bit whatever block it comes in (a live link's few samples per block or a
        replay's thousands). None: ``t0_s + arange(n) / fs``.
    """

    t0_s: float
    values: np.ndarray
    valid: np.ndarray
    t_s: np.ndarray | None = None


class _Channel:
    __slots__ = ("t", "v", "dt", "first")

    def __init__(self):
        self.t: list[float] = []
        self.v: list[float] = []
        self.dt: float | None = None          # median spacing of the first samples [s]
        self.first: list[float] = []          # the first few sample times, for dt


class GridAligner:
    """Aligns the channel map's signals onto one uniform grid as frames arrive.

    Parameters
    ----------
    signals : dict of str -> SignalSpec
        Where each signal lives (the case's ``[signals]``).
    names : sequence of str
        Signals to align, in block row order.
    sample_rate_hz : float
        Grid rate.
    max_interp_gap_s : float
        Longest source-sample spacing bridged by interpolation.
    gap_timeout_s : float
        How long the other signals may run ahead of a silent one before it is marked missing [s].
        Also the largest lag between topics that costs nothing (a message that arrives later
        than this behind the others is late): 2 s, so a slow gateway or a second link does not
        make a signal look dead.
    reset_gap_s : float
        Gap left in the continuous clock when a stream's clock re-anchors [s].
    max_fill_s : float
        The longest stretch of grid emitted at once after a jump, and the longest a signal's
        samples wait for the others [s]: bounds memory whatever the stamps say. The monitor sets
        it to its sliding window, so everything older has left the window anyway.
    system : (int, int or None), optional
        The MAVLink system (and component; None: each topic's own) to analyse. None: chosen from
        the frames (:mod:`livesweep.telemetry.vehicle_choice`).

    Attributes
    ----------
    system : int or None
        The system analysed, once named or chosen.
    choice : str
        Why that system ("named", or the chooser's reason); empty before the choice.
    """

    def __init__(self, signals: dict[str, SignalSpec], names, sample_rate_hz: float, *,
                 max_interp_gap_s: float = 0.1, gap_timeout_s: float = 2.0, reset_gap_s: float = 1.0,
                 max_fill_s: float = 600.0, system: tuple | None = None):
        self.names = tuple(names)
        missing = [n for n in self.names if n not in signals]
        if missing:
            raise ConfigError(f"signals {missing} are not in the channel map ({', '.join(signals)})")
        self.specs = {n: signals[n] for n in self.names}
        stamped = {n for n, s in self.specs.items() if s.stamp}
        if stamped and len(stamped) != len(self.names):
            raise ConfigError(
                f"signals {sorted(stamped)} are timed by vehicle stamps but {sorted(set(self.names) - stamped)} by "
                "receive time: give every signal a stamp field, or none, so they share one clock")
        self.clock = "vehicle" if stamped else "receive"
        if not (sample_rate_hz > 0 and math.isfinite(sample_rate_hz)):
            raise ConfigError(f"sample_rate_hz must be > 0, got {sample_rate_hz!r}")
        if not (max_fill_s > 0 and math.isfinite(max_fill_s)):
            raise ConfigError(f"max_fill_s must be > 0, got {max_fill_s!r}")
        self.fs = float(sample_rate_hz)
        self.max_interp_gap_s = max_interp_gap_s
        self.gap_timeout_s = gap_timeout_s
        self.max_fill = max(int(math.ceil(max_fill_s * self.fs)), 1)
        self.max_fill_s = float(max_fill_s)
        self.by_topic: dict[str, list[str]] = {}
        for n, s in self.specs.items():
            self.by_topic.setdefault(s.topic, []).append(n)
        self.extractors = {n: compile_signal(s) for n, s in self.specs.items()}
        self._locked_topics = {t for t, ns in self.by_topic.items()
                               if any(self.extractors[n].follows_vehicle_lock for n in ns)}
        self._plain_groups: dict[str, dict[tuple, list[str]]] = {}   # topics without any selection: fixed groups
        for t, ns in self.by_topic.items():
            if all(self.extractors[n].follows_vehicle_lock and not self.extractors[n].conditions for n in ns):
                g: dict[tuple, list[str]] = {}
                for n in ns:
                    g.setdefault((self.specs[n].stamp, self.specs[n].stamp_topic, None), []).append(n)
                self._plain_groups[t] = g
        #: stamp topic -> the stamp fields borrowed from it (signals with ``stamp_topic``)
        self.stamp_topics: dict[str, tuple[str, ...]] = {}
        for spec in self.specs.values():
            if spec.stamp_topic:
                fields = self.stamp_topics.setdefault(spec.stamp_topic, ())
                if spec.stamp not in fields:
                    self.stamp_topics[spec.stamp_topic] = (*fields, spec.stamp)
        self._borrowed: dict[tuple, tuple[Any, int]] = {}   # (stamp topic, field, sysid) -> (raw stamp, receive ns)
        #: Per signal: samples taken, and frames of its topic that gave it none (missing_field,
        #: not_a_number, filtered by its sysid/compid/where, other_vehicle: left out by the lock).
        self.signal_counts = {n: dict.fromkeys(SIGNAL_COUNT_KEYS, 0) for n in self.names}
        self.clocks: dict[tuple[str, str], StampClock] = {}
        self.system = None                           # the system id analysed (named or chosen)
        self.components: dict[str, int] = {}          # topic -> the component id followed
        self.choice = ""
        self._chooser: VehicleChooser | None = None
        if system is not None:
            self.system, self.choice = int(system[0]), "named"
            if system[1] is not None:
                self.components = dict.fromkeys(self._locked_topics, int(system[1]))
        elif self._locked_topics:
            self._chooser = VehicleChooser(self._locked_topics)
        self._reanchors: dict = {}                    # vehicle -> (offset [s], first new stamp [s]) of its last reboot
        self.reset_gap_s = reset_gap_s
        self.ch = {n: _Channel() for n in self.names}
        self.t0: float | None = None
        self.next_k = 0                  # next grid sample to emit
        self.k_frontier = 0              # grid samples every signal has reached (emitted up to here)
        self._frontier_t = -math.inf     # time of the last grid sample before the frontier [s]
        self.counts = {"frames_used": 0, "samples": 0, "missing_field": 0, "not_a_number": 0, "late_dropped": 0,
                       "reordered": 0, "wraps": 0, "resets": 0, "clock_rejected": 0,
                       "other_system": 0, "other_component": 0, "samples_emitted": 0, "samples_invalid": 0, "samples_skipped": 0,
                       "samples_expired": 0, "held_dropped": 0}

    # -- input ------------------------------------------------------------------------------
    def _clock(self, frame: Frame, stamp: str, scale: float, key: tuple | None = None,
               stamp_topic: str | None = None) -> StampClock:
        """The stamp clock of (topic, stamp field), or of ``key`` (a signal with its own sysid/compid);
        a borrowed stamp wraps as the field of ``stamp_topic`` does."""
        key = key or ((frame.topic, stamp) if stamp_topic is None else (frame.topic, stamp, stamp_topic))
        c = self.clocks.get(key)
        if c is None:
            vehicle = frame.data.get("sysid", frame.topic)
            c = self.clocks[key] = StampClock(scale, wrap_units=_wrap_units(stamp_topic or frame.topic, stamp),
                                              reset_gap_s=self.reset_gap_s, establish=True,
                                              reanchor=functools.partial(self._reanchor, vehicle))
        return c

    def _reanchor(self, vehicle, first_s: float, offset_s: float) -> float:
        """One offset for every clock of ``vehicle`` that re-anchors at one reboot (their proposals
        differ by a sample period or so; a later reboot proposes an offset further on)."""
        prev = self._reanchors.get(vehicle)
        if prev is not None and abs(prev[0] - offset_s) <= _SAME_REBOOT_S and abs(prev[1] - first_s) <= _SAME_REBOOT_S:
            return prev[0]
        self._reanchors[vehicle] = (offset_s, first_s)
        return offset_s

    def _same_vehicle(self, frame: Frame) -> bool:
        """The first system seen on any mapped topic is analysed, with the first component seen on
        each topic; frames of other systems and components are counted and left out."""
        sysid = frame.data.get("sysid")
        if sysid is None:
            return True
        if self.system is None:
            self.system = sysid
        if sysid != self.system:
            self.counts["other_system"] += 1
            return False
        compid = self.components.setdefault(frame.topic, frame.data.get("compid"))
        if frame.data.get("compid") != compid:
            self.counts["other_component"] += 1
            return False
        return True

    def _values(self, names, frame: Frame) -> list[tuple[str, float]]:
        """(name, value in signal units) of the signals ``frame`` carries; the rest counted."""
        out = []
        for n in names:
            v, problem = self.extractors[n].value(frame.data)
            if problem is not None:
                self.counts[problem] += 1
                self.signal_counts[n][problem] += 1
                continue
            out.append((n, v))
        return out

    def _taking(self, names, frame: Frame) -> dict[tuple, list[str]]:
        """The signals of ``names`` that take ``frame`` (vehicle lock, sysid/compid/where), grouped by
        (stamp field, clock key); the others counted."""
        locked_ok = frame.topic not in self._locked_topics or self._same_vehicle(frame)
        plain = self._plain_groups.get(frame.topic)
        if plain is not None and locked_ok:
            return plain
        groups: dict[tuple, list[str]] = {}
        for n in names:
            ex = self.extractors[n]
            if ex.follows_vehicle_lock and not locked_ok:
                self.signal_counts[n]["other_vehicle"] += 1
                continue
            if ex.conditions:
                sel = ex.selects(frame.data)
                if sel is None:
                    self.counts["missing_field"] += 1
                    self.signal_counts[n]["missing_field"] += 1
                    continue
                if not sel:
                    self.signal_counts[n]["filtered"] += 1
                    continue
            spec = self.specs[n]
            own = None if ex.follows_vehicle_lock else (spec.sysid, spec.compid)
            groups.setdefault((spec.stamp, spec.stamp_topic, own), []).append(n)
        return groups

    def _note_stamps(self, frame: Frame) -> None:
        """Keep the stamps a frame of a stamp topic lends (per system)."""
        sysid = frame.data.get("sysid")
        for field in self.stamp_topics[frame.topic]:
            raw = lookup(frame.data, field)
            if not isinstance(raw, bool) and isinstance(raw, (int, float)):
                self._borrowed[(frame.topic, field, sysid)] = (raw, frame.receive_ns)

    def _borrow(self, frame: Frame, stamp_topic: str, field: str):
        """The stamp a frame without one takes: the latest of ``stamp_topic`` from its system, if recent."""
        got = self._borrowed.get((stamp_topic, field, frame.data.get("sysid")))
        if got is None or frame.receive_ns - got[1] > BORROW_WITHIN_S * 1e9 or frame.receive_ns < got[1]:
            return None
        return got[0]

    def push(self, frame: Frame) -> None:
        """Take the samples a frame carries (frames of other topics are ignored); while no vehicle
        is chosen, frames are held and taken, in order, once one is."""
        if not isinstance(frame.data, dict):
            return
        chooser = self._chooser
        if chooser is None:
            self._push(frame)
            return
        got = chooser.push(frame)
        if got is not None:
            self._take_choice(got)

    def settle_choice(self) -> None:
        """Choose now if no vehicle is chosen yet (the stream ended, or the monitor must say what it
        has found): :meth:`VehicleChooser.decide_now`, and the held frames are taken."""
        if self._chooser is not None:
            self._take_choice(self._chooser.decide_now())

    def _take_choice(self, got: tuple) -> None:
        chooser = self._chooser
        self._chooser = None
        self.system, comps = got
        self.components.update(comps)
        self.choice = chooser.reason
        self.counts["held_dropped"] += chooser.dropped
        held, chooser.held = chooser.held, None
        for f in held:
            self._push(f)

    def _push(self, frame: Frame) -> None:
        if frame.topic in self.stamp_topics:
            self._note_stamps(frame)
        names = self.by_topic.get(frame.topic)
        if not names:
            return
        by_stamp = self._taking(names, frame)
        if not by_stamp:
            return
        self.counts["frames_used"] += 1
        for (stamp, stamp_topic, own), group in by_stamp.items():
            values = self._values(group, frame)
            if stamp is None:
                released = [(frame.receive_ns * 1e-9, values)]
            else:
                # a dotted path too, as offline; borrowed from another topic's latest frame when so mapped
                raw = lookup(frame.data, stamp) if stamp_topic is None else self._borrow(frame, stamp_topic, stamp)
                if isinstance(raw, bool) or not isinstance(raw, (int, float)):
                    self.counts["missing_field"] += 1
                    for n, _ in values:
                        self.signal_counts[n]["missing_field"] += 1
                    continue
                clock_key = None if own is None else (frame.topic, stamp, *(() if stamp_topic is None else (stamp_topic,)),
                                                      *own)
                clock = self._clock(frame, stamp, self.specs[group[0]].stamp_scale, clock_key, stamp_topic)
                before = (clock.wraps, clock.resets, clock.rejected)
                released = clock.feed(raw, frame.receive_ns * 1e-9, values)
                for key, b, a in zip(("wraps", "resets", "clock_rejected"), before,
                                     (clock.wraps, clock.resets, clock.rejected)):
                    self.counts[key] += a - b
            for n, _ in values:
                self.signal_counts[n]["samples"] += 1
            for t, vals in released:
                for n, v in vals:
                    self._add(n, t, v)
        self._advance()

    def _add(self, name: str, t: float, v: float) -> None:
        c = self.ch[name]
        if t <= self._frontier_t:
            self.counts["late_dropped"] += 1
            return
        if c.t and t <= c.t[-1]:
            if t == c.t[-1]:
                return
            i = bisect.bisect_left(c.t, t)
            c.t.insert(i, t)
            c.v.insert(i, v)
            self.counts["reordered"] += 1
        else:
            c.t.append(t)
            c.v.append(v)
        if c.dt is None:
            c.first.append(t)
            if len(c.first) >= _FIRST_SAMPLES:
                c.dt = float(np.median(np.diff(sorted(c.first))))
                c.first = []
        self.counts["samples"] += 1

    def _advance(self) -> None:
        """Move the grid frontier as far as every signal has reached (the frames pushed so far decide
        it alone, not when :meth:`pop_ready` is called, so a replay emits what the live run did)."""
        chans = [self.ch[n] for n in self.names]
        if self.t0 is None:
            if any(c.dt is None for c in chans):
                self._expire(chans)
                return
            self.t0 = max(c.t[0] for c in chans)
        lasts = [c.t[-1] for c in chans]
        lo, hi = min(lasts), max(lasts)
        # a signal silent for gap_timeout_s while others advance no longer holds the grid back
        limit = lo if hi - lo <= self.gap_timeout_s else hi - self.gap_timeout_s
        k = int(math.floor((limit - self.t0 + _EPS_S) * self.fs)) + 1
        if k > self.k_frontier:
            self.k_frontier = k
            self._frontier_t = self.t0 + (k - 1) / self.fs

    # -- output -----------------------------------------------------------------------------
    def _expire(self, chans) -> None:
        """While some signal has not started, keep only the last ``max_fill_s`` of the others."""
        for c in chans:
            if c.t and c.t[-1] - c.t[0] > self.max_fill_s:
                k = bisect.bisect_left(c.t, c.t[-1] - self.max_fill_s)
                del c.t[:k]
                del c.v[:k]
                self.counts["samples_expired"] += k

    def _skip_empty(self, chans) -> None:
        """Skip grid that no signal has a sample near: of a jump, only the last ``max_fill_s`` is emitted.

        Only samples up to the frontier count (they alone are fixed by the frames pushed so far)."""
        t_next = self.t0 + self.next_k / self.fs
        ahead = [c.t[j] for c in chans if (j := bisect.bisect_left(c.t, t_next - _EPS_S)) < len(c.t)]
        first = min(min(ahead, default=math.inf), self._frontier_t)
        if first - t_next > self.max_fill_s:
            k = int(math.floor((first - self.max_fill_s - self.t0) * self.fs))
            if k > self.next_k:
                self.counts["samples_skipped"] += k - self.next_k
                self.next_k = k

    @property
    def frontier_s(self) -> float | None:
        """Data time every signal has reached [s] (the last grid time the aligner may emit); None
        before the grid has started."""
        return None if self.t0 is None or self.k_frontier == 0 else self._frontier_t

    def pop_ready(self) -> AlignedBlock | None:
        """The grid samples all signals have reached since the last call (at most ``max_fill_s`` of
        them: call until None), or None."""
        if self.t0 is None or self.k_frontier <= self.next_k:
            return None
        chans = [self.ch[n] for n in self.names]
        self._skip_empty(chans)
        k_end = min(self.k_frontier, self.next_k + self.max_fill)   # at most max_fill per call: call again
        if k_end <= self.next_k:
            return None
        tk = self.t0 + np.arange(self.next_k, k_end) / self.fs
        values = np.empty((len(chans), tk.size))
        valid = np.ones(tk.size, bool)
        for i, c in enumerate(chans):
            t = np.asarray(c.t)
            v = np.asarray(c.v)
            bridge = max(self.max_interp_gap_s, 1.5 * c.dt)
            j = np.searchsorted(t, tk + _EPS_S, side="right")   # t[j-1] <= tk (+eps) < t[j]
            lo = np.clip(j - 1, 0, t.size - 1)
            hi = np.clip(j, 0, t.size - 1)
            exact = (j > 0) & (np.abs(t[lo] - tk) <= _EPS_S)
            inside = (j > 0) & (j < t.size)
            span = t[hi] - t[lo]
            ok = exact | (inside & (span <= bridge))
            with np.errstate(invalid="ignore", divide="ignore"):
                f = np.where(exact | (span <= 0), 0.0, (tk - t[lo]) / np.where(span > 0, span, 1.0))
            values[i] = np.where(ok, v[lo] + f * (v[hi] - v[lo]), np.nan)
            valid &= ok
            # keep one sample before the next grid time for the next bracket
            keep_from = max(0, bisect.bisect_right(c.t, tk[-1] + _EPS_S) - 1)
            if keep_from > 0:
                del c.t[:keep_from]
                del c.v[:keep_from]
        block = AlignedBlock(float(tk[0]), values, valid, tk)
        self.next_k = k_end
        self.counts["samples_emitted"] += tk.size
        self.counts["samples_invalid"] += int(np.sum(~valid))
        return block
