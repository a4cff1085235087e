"""What one pass over a log gathers: :class:`_Stats`.

One job: take a log's messages in file order (or a topic's columns at once) and keep, per topic,
its count and time span and its first message; per signal of the candidate maps, its samples
(:class:`_Signal`: receive time, stamp, system, value range); what the main system says of itself
(:class:`~livesweep.monitor.vehicle.VehicleInfo`); and the SystemID runs it announces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.monitor.systemid import SAME_START_S, SystemIdWatch, better_injection

#: Topics whose every message the vehicle checks and the SystemID watch read (in file order).
_VEHICLE_TOPICS = frozenset(("/mavlink/PARAM_VALUE", "/dataflash/PARM", "/dataflash/SIDS", "/mavlink/STATUSTEXT",
                             "/dataflash/MSG", "/mavlink/HEARTBEAT", "/dataflash/MODE"))


def _key(spec) -> str:
    return f"{spec.topic}|{spec.field}|{spec.where}|{spec.sysid}|{spec.compid}|{spec.stamp}|{spec.stamp_topic}"


class _Signal:
    """The samples one signal of the maps has in the log: receive time [ns], its stamp [s] (NaN
    without one), the system that sent it (-1: none said), and the range of its values."""

    __slots__ = ("extractor", "spec", "n", "lo", "hi", "_rx", "_stamp", "_sysid", "_blocks", "_arrays")

    def __init__(self, spec):
        from livesweep.telemetry.extract import compile_signal

        self.spec = spec
        self.extractor = compile_signal(spec)
        self.n = 0
        self.lo, self.hi = math.inf, -math.inf
        self._rx: list[int] = []
        self._stamp: list[float] = []
        self._sysid: list[int] = []
        self._blocks: list[tuple] = []
        self._arrays = None

    def add(self, rx_ns: int, value: float, stamp: float, sysid: int) -> None:
        self.n += 1
        if value < self.lo:
            self.lo = value
        if value > self.hi:
            self.hi = value
        self._rx.append(rx_ns)
        self._stamp.append(stamp)
        self._sysid.append(sysid)

    def add_block(self, rx_ns: np.ndarray, values: np.ndarray, stamps: np.ndarray) -> None:
        if not rx_ns.size:
            return
        self.n += int(rx_ns.size)
        self.lo = min(self.lo, float(values.min()))
        self.hi = max(self.hi, float(values.max()))
        self._blocks.append((rx_ns.astype(np.int64), stamps.astype(np.float64),
                             np.full(rx_ns.size, -1, dtype=np.int64)))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(receive ns, stamp s, sysid)`` of every sample, in the order taken."""
        if self._arrays is None:
            parts = [(np.asarray(self._rx, dtype=np.int64), np.asarray(self._stamp, dtype=np.float64),
                      np.asarray(self._sysid, dtype=np.int64))] + self._blocks
            self._arrays = tuple(np.concatenate([p[k] for p in parts]) for k in range(3))
        return self._arrays


class _Stats:
    """Per-topic and per-signal statistics gathered in one pass over a log."""

    def __init__(self, maps):
        from livesweep.monitor.vehicle import VehicleInfo

        self.topics: dict[str, list] = {}            # topic -> [n, earliest ns, latest ns, first data]
        self.meta: dict[str, tuple] = {}             # topic -> (encoding, decoded, schema fields, why not, units)
        self._vehicles: dict = {}                    # sysid -> VehicleInfo: the log's main system is judged
        self._frames_by_system: dict = {}            # sysid -> frames (the main system sends the most)
        self._new_vehicle = VehicleInfo
        self.runs: list[dict] = []                   # SystemID runs: start ns, end ns, axis, injection
        self._watches: dict = {}                     # sysid -> SystemIdWatch
        self.t_end: int | None = None
        self.signals: dict[str, _Signal] = {}
        self.by_topic: dict[str, list[_Signal]] = {}
        self._stamp_sources: dict[str, set] = {}    # topic -> its fields other signals borrow their stamp from
        self._last_stamp: dict[tuple, tuple] = {}    # (sysid, topic, field) -> (receive ns, value)
        for _name, m, _ in maps:
            for spec in m.signals.values():
                key = _key(spec)
                if key not in self.signals:
                    self.signals[key] = sig = _Signal(spec)
                    self.by_topic.setdefault(spec.topic, []).append(sig)
                    if spec.stamp and spec.stamp_topic:
                        self._stamp_sources.setdefault(spec.stamp_topic, set()).add(spec.stamp)
        #: topic -> [(selection or None, a spec giving the stamp, the signals)]
        self._groups: dict[str, list] = {}
        for topic, sigs in self.by_topic.items():
            groups: dict[tuple, tuple] = {}
            for sig in sigs:
                sp, ex = sig.spec, sig.extractor
                g = (ex.conditions, sp.stamp, sp.stamp_scale, sp.stamp_topic)
                if g not in groups:
                    groups[g] = (ex if ex.conditions else None, sp, [])
                groups[g][2].append(sig)
            self._groups[topic] = list(groups.values())

    def wants_records(self, topic: str, columns: bool = False) -> bool:
        """Whether every message of ``topic`` must be taken as a record (:meth:`take`, in file
        order): the vehicle's and the SystemID watch's, the stamps signals borrow, and (unless the
        reader gives ``columns``, :meth:`take_columns`) the signals'."""
        return (topic in _VEHICLE_TOPICS or topic in self._stamp_sources
                or (not columns and topic in self.by_topic))

    def _span(self, topic: str, first_ns: int, last_ns: int, n: int, data) -> None:
        st = self.topics.get(topic)
        if st is None:
            self.topics[topic] = [n, first_ns, last_ns, data]
        else:
            st[0] += n
            if last_ns > st[2]:
                st[2] = last_ns
            if first_ns < st[1]:
                st[1] = first_ns
        if self.t_end is None or last_ns > self.t_end:
            self.t_end = last_ns

    def _count(self, topic: str, t_ns: int, data) -> None:
        """``topic``'s count and time span (``data``: its first message's, to list its fields)."""
        st = self.topics.get(topic)
        if st is None:
            self.topics[topic] = [1, t_ns, t_ns, data]
        else:                                    # the span: file order need not be time order
            st[0] += 1
            if t_ns > st[2]:
                st[2] = t_ns
            elif t_ns < st[1]:
                st[1] = t_ns
        if self.t_end is None or t_ns > self.t_end:
            self.t_end = t_ns

    def tick(self, topic: str, t_ns: int, sysid=None, data=None, system: bool = True) -> None:
        """One message of ``topic`` counted, not read (``data``: the first one's, to list its
        fields); ``system``: counted for system ``sysid`` (False: a message that is no record)."""
        self._count(topic, t_ns, data)
        if system:
            self._frames_by_system[sysid] = self._frames_by_system.get(sysid, 0) + 1

    def take(self, topic: str, t_ns: int, data) -> None:
        """One message of ``topic`` read: counted, its signals' samples, the vehicle and SystemID."""
        self._count(topic, t_ns, data)
        if not isinstance(data, dict):
            return
        sysid = data.get("sysid")
        self._frames_by_system[sysid] = self._frames_by_system.get(sysid, 0) + 1
        borrowed = self._stamp_sources.get(topic)
        if borrowed:
            for f in borrowed:
                v = data.get(f)
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    self._last_stamp[(sysid, topic, f)] = (t_ns, v)
        groups = self._groups.get(topic)
        if groups:
            sys_code = sysid if isinstance(sysid, int) and not isinstance(sysid, bool) else -1
            for selector, spec, sigs in groups:          # signals that take the same messages and stamp
                if selector is not None and not selector.selects(data):
                    continue
                stamp = self._stamp_of(spec, data, sysid, t_ns)
                for s in sigs:
                    v, problem = s.extractor.value(data)
                    if problem is None:
                        s.add(t_ns, v, stamp, sys_code)
        if topic in _VEHICLE_TOPICS:
            self._systemid(topic, t_ns, data)

    def _stamp_of(self, spec, data: dict, sysid, t_ns: int) -> float:
        """The sample's stamp [s] (its own field, or the latest of ``stamp_topic`` received at most
        ``BORROW_WITHIN_S`` before), NaN without one."""
        if not spec.stamp:
            return math.nan
        if spec.stamp_topic:
            from livesweep.telemetry.align import BORROW_WITHIN_S

            got = self._last_stamp.get((sysid, spec.stamp_topic, spec.stamp))
            if got is None or t_ns - got[0] > BORROW_WITHIN_S * 1e9:
                return math.nan
            raw = got[1]
        else:
            raw = data.get(spec.stamp)
            if not isinstance(raw, (int, float)) or isinstance(raw, bool):
                return math.nan
        return float(raw) * spec.stamp_scale

    def take_columns(self, topic: str, times_ns: np.ndarray, first, column) -> None:
        """Every message of ``topic`` at once: ``times_ns`` (file order), the first message's data,
        and ``column(field)``, the float64 values of one field (None when the topic lacks it)."""
        if not times_ns.size:
            return
        self._span(topic, int(times_ns.min()), int(times_ns.max()), int(times_ns.size), first)
        sysid = first.get("sysid") if isinstance(first, dict) else None
        self._frames_by_system[sysid] = self._frames_by_system.get(sysid, 0) + int(times_ns.size)
        for s in self.by_topic.get(topic, ()):
            ex = s.extractor
            cols = {}
            for f in ex.read_fields:
                c = column(f)
                if c is not None:
                    cols[f] = c
            if any(op not in cols for op in ex.expression.operands) or any(k not in cols for k, _ in ex.conditions):
                continue                                  # a field the topic lacks: no samples
            values = ex.values(cols)
            ok = np.isfinite(values)
            mask = ex.select_columns(cols)
            if mask is not None:
                ok &= mask
            spec = s.spec
            if spec.stamp and not spec.stamp_topic and spec.stamp in cols:
                stamps = cols[spec.stamp][ok] * spec.stamp_scale
            else:
                stamps = np.full(int(ok.sum()), np.nan)
            s.add_block(times_ns[ok], values[ok], stamps)

    def _main(self):
        """The system id that sent the most messages (a tlog may hold a ground station's too)."""
        return max(self._frames_by_system, key=self._frames_by_system.get) if self._frames_by_system else None

    @property
    def vehicle(self):
        """What the main system said of itself."""
        return self._vehicles.get(self._main()) or self._new_vehicle()

    def _systemid(self, topic: str, t_ns: int, d: dict) -> None:
        sysid = d.get("sysid")
        v = self._vehicles.get(sysid)
        if v is None:
            v = self._vehicles[sysid] = self._new_vehicle()
            self._watches[sysid] = SystemIdWatch()
        v.take(_Frame(topic, d))
        ev = self._watches[sysid].feed(topic, d, v)
        if ev is None or (sysid is not None and sysid != self._main()):
            return                               # SystemID runs of the main system only
        last = self.runs[-1] if self.runs and self.runs[-1]["end"] is None else None
        if ev.action == "end":
            if last is not None:
                last["end"] = t_ns
        elif last is not None and abs(t_ns - last["start"]) < SAME_START_S * 1e9:    # the same start, said again
            last["axis"] = ev.axis if last["axis"] is None else last["axis"]
            last["injection"] = better_injection(last["injection"], ev.injection)
        else:
            self.runs.append({"start": t_ns, "end": None, "axis": ev.axis, "injection": ev.injection})

    def signal(self, spec) -> _Signal:
        return self.signals[_key(spec)]

    def samples(self, sig: _Signal) -> tuple[np.ndarray, np.ndarray]:
        """``(receive ns, stamp s)`` of a signal's samples from the main system (every sample when
        the signal names its own system, or the main system sent none)."""
        rx, stamp, sysid = sig.arrays()
        main = self._main()
        if sig.spec.sysid is None and isinstance(main, int) and not isinstance(main, bool):
            mine = sysid == main
            if mine.any() and not mine.all():
                return rx[mine], stamp[mine]
        return rx, stamp


@dataclass(frozen=True)
class _Frame:
    topic: str
    data: dict
