"""From frames to uniform sample blocks on one clock: the monitor's aligner (DESIGN.md §1).

* **One clock.** Every signal is timed by its stamp field (vehicle time) when the channel map
  names one, else by the receive time; a map that mixes the two is refused (the clocks are not
  comparable).
* **Wrap and reboot.** Raw stamps go through :class:`StampUnwrapper`: a backward step of more
  than half the 32-bit range is a wrap (``time_usec`` of SERVO_OUTPUT_RAW wraps every 71.6 min)
  and adds one period; any other backward step of more than ``max_reorder_s`` is a reset (reboot):
  the clock is re-anchored ``reset_gap_s`` after the last sample, so no window spans the reset.
  Both are counted.
* **Multi-rate alignment.** Each signal keeps its recent samples; grid samples ``t0 + k/fs`` are
  emitted once every signal has reached them, by linear interpolation between the bracketing
  samples. Where the bracketing samples are further apart than ``max(max_interp_gap_s, 1.5 x the
  signal's median spacing)`` the grid sample is marked invalid (a gap: excluded, never
  interpolated across). A signal that stops while others go on for ``gap_timeout_s`` is marked
  invalid from its last sample on, so one dead channel does not stall the others.

Everything is driven by the frames' contents alone (never by wall-clock time), so replaying a
recording through the same aligner reproduces the live blocks exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.config import SignalSpec
from livesweep.errors import ConfigError
from livesweep.telemetry.frames import Frame

__all__ = ["StampUnwrapper", "AlignedBlock", "GridAligner"]

WRAP_UNITS = 2**32
_EPS_S = 1e-7   # stamps within 0.1 us of a grid time are on it (grid times carry float round-off)


class StampUnwrapper:
    """Continuous seconds from raw stamps that may wrap at 2^32 units or reset on a reboot.

    Parameters
    ----------
    scale_s : float
        Seconds per stamp unit (1e-6 for ``time_usec``).
    max_reorder_s : float
        Backward steps up to this are reordering (returned as they are), not resets.
    reset_gap_s : float
        After a reset the clock continues this long after the last sample.
    """

    def __init__(self, scale_s: float, max_reorder_s: float = 1.0, reset_gap_s: float = 1.0):
        self.scale_s = float(scale_s)
        self.max_reorder_s = max_reorder_s
        self.reset_gap_s = reset_gap_s
        self.offset_s = 0.0
        self.last_raw: float | None = None
        self.last_t = -math.inf
        self.wraps = 0
        self.resets = 0

    def __call__(self, raw: float) -> float:
        """Seconds on the continuous clock for stamp ``raw``."""
        if self.last_raw is not None and raw < self.last_raw:
            back = self.last_raw - raw
            if back > WRAP_UNITS / 2 and self.last_raw < WRAP_UNITS * 1.01:
                self.offset_s += WRAP_UNITS * self.scale_s
                self.wraps += 1
            elif back * self.scale_s > self.max_reorder_s:
                self.offset_s = self.last_t + self.reset_gap_s - raw * self.scale_s
                self.resets += 1
            else:
                return raw * self.scale_s + self.offset_s   # reordered sample: leave the anchor alone
        t = raw * self.scale_s + self.offset_s
        self.last_raw = raw
        self.last_t = max(self.last_t, t)
        return t


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
    """

    t0_s: float
    values: np.ndarray
    valid: np.ndarray


class _Channel:
    __slots__ = ("t", "v", "dt")

    def __init__(self):
        self.t: list[float] = []
        self.v: list[float] = []
        self.dt: float | None = None


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
        How long the other signals may run ahead of a silent one before it is marked missing.
    """

    def __init__(self, signals: dict[str, SignalSpec], names, sample_rate_hz: float, *,
                 max_interp_gap_s: float = 0.1, gap_timeout_s: float = 0.5, reset_gap_s: float = 1.0):
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
        self.fs = float(sample_rate_hz)
        self.max_interp_gap_s = max_interp_gap_s
        self.gap_timeout_s = gap_timeout_s
        self.by_topic: dict[str, list[str]] = {}
        for n, s in self.specs.items():
            self.by_topic.setdefault(s.topic, []).append(n)
        self.unwrappers: dict[tuple[str, str], StampUnwrapper] = {}
        self.reset_gap_s = reset_gap_s
        self.ch = {n: _Channel() for n in self.names}
        self.t0: float | None = None
        self.next_k = 0
        self.counts = {"frames_used": 0, "samples": 0, "missing_field": 0, "not_a_number": 0, "late_dropped": 0,
                       "reordered": 0, "wraps": 0, "resets": 0, "samples_emitted": 0, "samples_invalid": 0}

    # -- input ------------------------------------------------------------------------------
    def _time(self, topic: str, spec: SignalSpec, frame: Frame) -> float | None:
        if spec.stamp is None:
            return frame.receive_ns * 1e-9
        raw = frame.data.get(spec.stamp)
        if not isinstance(raw, (int, float)) or isinstance(raw, bool):
            self.counts["missing_field"] += 1
            return None
        key = (topic, spec.stamp)
        u = self.unwrappers.get(key)
        if u is None:
            u = self.unwrappers[key] = StampUnwrapper(spec.stamp_scale, reset_gap_s=self.reset_gap_s)
        w, r = u.wraps, u.resets
        t = u(raw)
        self.counts["wraps"] += u.wraps - w
        self.counts["resets"] += u.resets - r
        return t

    def push(self, frame: Frame) -> None:
        """Take the samples a frame carries (frames of other topics are ignored)."""
        names = self.by_topic.get(frame.topic)
        if not names:
            return
        self.counts["frames_used"] += 1
        times: dict[str | None, float | None] = {}
        for n in names:
            spec = self.specs[n]
            if spec.stamp not in times:
                times[spec.stamp] = self._time(frame.topic, spec, frame)
            t = times[spec.stamp]
            if t is None:
                continue
            raw = frame.data.get(spec.field)
            if raw is None and spec.field not in frame.data:
                self.counts["missing_field"] += 1
                continue
            if not isinstance(raw, (int, float)) or isinstance(raw, bool) or not math.isfinite(raw):
                self.counts["not_a_number"] += 1
                continue
            self._add(n, t, spec.scale * raw + spec.offset)

    def _add(self, name: str, t: float, v: float) -> None:
        c = self.ch[name]
        emitted_until = -math.inf if self.t0 is None else self.t0 + (self.next_k - 1) / self.fs
        if t <= emitted_until:
            self.counts["late_dropped"] += 1
            return
        if c.t and t <= c.t[-1]:
            if t == c.t[-1]:
                return
            i = int(np.searchsorted(c.t, t))
            c.t.insert(i, t)
            c.v.insert(i, v)
            self.counts["reordered"] += 1
        else:
            c.t.append(t)
            c.v.append(v)
        self.counts["samples"] += 1

    # -- output -----------------------------------------------------------------------------
    def pop_ready(self) -> AlignedBlock | None:
        """Every grid sample all signals have reached since the last call, or None."""
        chans = [self.ch[n] for n in self.names]
        if any(not c.t for c in chans):
            return None
        if self.t0 is None:
            self.t0 = max(c.t[0] for c in chans)
        lasts = np.array([c.t[-1] for c in chans])
        # a signal silent for gap_timeout_s while others advance no longer holds the grid back
        spread = float(lasts.max() - lasts.min())
        limit = float(lasts.min()) if spread <= self.gap_timeout_s else float(lasts.max()) - self.gap_timeout_s
        k_end = int(math.floor((limit - self.t0 + _EPS_S) * self.fs)) + 1
        if k_end <= self.next_k:
            return None
        tk = self.t0 + np.arange(self.next_k, k_end) / self.fs
        values = np.empty((len(chans), tk.size))
        valid = np.ones(tk.size, bool)
        for i, c in enumerate(chans):
            t = np.asarray(c.t)
            v = np.asarray(c.v)
            if c.dt is None and t.size >= 3:
                c.dt = float(np.median(np.diff(t)))
            bridge = max(self.max_interp_gap_s, 1.5 * (c.dt or 0.0))
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
            keep_from = max(0, int(np.searchsorted(t, tk[-1] + _EPS_S, side="right")) - 1)
            if keep_from > 0:
                del c.t[:keep_from]
                del c.v[:keep_from]
        block = AlignedBlock(float(tk[0]), values, valid)
        self.next_k = k_end
        self.counts["samples_emitted"] += tk.size
        self.counts["samples_invalid"] += int(np.sum(~valid))
        return block
