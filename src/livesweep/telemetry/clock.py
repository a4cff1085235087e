"""Time at the edge: a receive clock that never steps, and vehicle stamps that are checked before use.

A live link carries whatever the vehicle (or an attacker, or a rebooting autopilot) writes into its
time fields: ``time_usec`` may be microseconds since boot or since the UNIX epoch (MAVLink allows
both), a uint32 field wraps every 71.6 min, a reboot starts the clock again, and a single corrupt or
forged frame can carry any 64-bit value. Nothing downstream may trust such a stamp blindly: one
frame 116 days ahead would make the aligner fill 116 days of grid.

* :class:`ReceiveClock`: receive times in UNIX nanoseconds that advance with the monotonic clock,
  so an NTP step of the wall clock during a flight does not move frames backwards or forwards.
* :class:`StampClock`: continuous seconds from one stream's raw stamps. A stamp is *plausible* when
  its step from the stream's last accepted stamp is no more than ``max_reorder_s`` backwards and no
  more than ``slack_s + max_rate * (receive step)`` forwards (``max_rate`` allows replays and
  simulators running faster than real time). A plausible step forward of more than ten typical
  steps is held for one stamp: the next tells a gap (both released) from an outlier (dropped).
  An implausible stamp is held; if the next stamps
  fit the old clock it was an outlier and is dropped and counted; if ``confirm`` consecutive
  stamps agree with each other instead, the clock re-anchors (a reboot, an epoch switch) and
  releases them, continuing ``reset_gap_s`` after the last accepted time, so no window spans the
  discontinuity and the continuous clock never jumps by the size of the step. A uint32 wrap is
  recognised only for fields declared ``wrap_units`` wide, and only from the top of the range to
  its bottom.

* :class:`StampCheck`: whether a stamp is one a vehicle's clock can have, for the recording (which
  keeps every frame and only decides whether its stamp becomes the MCAP publish time). One check
  per (system, component, message type): a field's meaning differs between messages (GPS_RAW_INT's
  ``time_usec`` may be UNIX time where HIGHRES_IMU's is boot time, SERVO_OUTPUT_RAW's is a uint32
  that wraps). A stamp is plausible when it is a UNIX (or GPS) time up to a day after the receive
  clock, or when it steps back (a reboot, a wrap, a restarted simulator, reordering: the clock
  may restart, so the stamp starts a new epoch of the stream), or when it steps forward from one
  of the stream's recent epochs by no more than ``slack_s + max_rate * (receive step)``. Zero is
  "no time yet" (GPS before a fix) and anchors nothing. What is left is a stamp ahead of every
  clock the stream has shown: a value no clock of this vehicle has reached (a corrupt or forged
  frame), unless ``confirm`` such stamps in a row agree (then they are a new epoch).

Everything depends on the frames alone (stamp and receive time), never on the wall clock, so a
replay of a recording makes the same decisions as the live run.
"""

from __future__ import annotations

import math
import time

__all__ = ["ReceiveClock", "StampCheck", "StampClock", "UINT64_NS_MAX", "receive_ns", "receive_offset_ns", "set_receive_offset_ns"]

#: The largest time an MCAP record can carry [ns].
UINT64_NS_MAX = 2**64 - 1


class ReceiveClock:
    """UNIX-epoch nanoseconds that advance with :func:`time.monotonic_ns`.

    The epoch offset is read once, when the clock is made; after that a step of the system's wall
    clock (NTP, a user setting the date) does not move receive times.
    """

    def __init__(self) -> None:
        self._offset = time.time_ns() - time.monotonic_ns()

    def now_ns(self) -> int:
        """Receive time now [ns since the UNIX epoch, monotonic]."""
        return time.monotonic_ns() + self._offset


_RECEIVE_CLOCK = ReceiveClock()


def receive_ns() -> int:
    """Now on the process's one receive clock [ns since the UNIX epoch, monotonic]: the sources stamp
    frames with it and the monitor stamps its results with it, so both share one time base."""
    return _RECEIVE_CLOCK.now_ns()


def receive_offset_ns() -> int:
    """The receive clock's offset from the monotonic clock [ns]: a helper process given it
    (:func:`set_receive_offset_ns`) stamps on exactly this process's receive clock."""
    return _RECEIVE_CLOCK._offset


def set_receive_offset_ns(offset_ns: int) -> None:
    """Stamp on another process's receive clock (its :func:`receive_offset_ns`): the monotonic clock
    is the machine's, so the two processes' receive times then compare to the nanosecond."""
    _RECEIVE_CLOCK._offset = int(offset_ns)


class StampClock:
    """Continuous time [s] of one stream of raw stamps, with implausible stamps rejected.

    Parameters
    ----------
    scale_s : float
        Seconds per stamp unit (1e-6 for ``time_usec``, 1e-3 for ``time_boot_ms``).
    wrap_units : int, optional
        The field's range when it is an unsigned integer that wraps (2**32 for a uint32
        ``time_usec``); None: the field does not wrap.
    max_reorder_s : float
        Backward steps up to this are reordering: the sample keeps its own time, the anchor stays.
    slack_s : float
        Forward step allowed whatever the receive step [s] (link latency jitter, a paused stream).
    max_rate : float
        Vehicle seconds allowed per receive second beyond ``slack_s`` (a 100x replay is plausible).
    confirm : int
        Consecutive, mutually consistent implausible stamps needed to re-anchor the clock.
    reset_gap_s : float
        After a re-anchoring the clock continues this long after the last accepted time [s].
    establish : bool
        True: the first anchor, too, needs ``confirm`` consistent stamps (they are held until then
        and released together), so a bad first stamp can never become the reference of the
        continuous clock. False: the first stamp anchors at once (enough when only the
        accept/reject decision is used).
    hold_jumps : bool
        True: a plausible forward step of more than ten typical steps (at least 50 ms) is held
        until the next stamp: if that one goes on from it, the stream had a gap and both are
        released; if not, it was an outlier (dropped, counted) and the clock has not moved. So a
        single stamp a few seconds ahead can neither shift the clock nor drag the aligner's grid.
    reanchor : callable, optional
        ``reanchor(first_new_stamp_s, proposed_offset_s) -> offset_s`` decides the offset of a
        re-anchoring: the aligner gives every clock of one vehicle that restarts at one reboot the
        same offset, so signals from different messages stay aligned to the sample.

    Attributes
    ----------
    wraps, resets, rejected : int
        Wraps unwrapped, re-anchorings (reboots, epoch switches) and stamps dropped.
    """

    def __init__(self, scale_s: float, *, wrap_units: int | None = None, max_reorder_s: float = 1.0,
                 slack_s: float = 5.0, max_rate: float = 100.0, confirm: int = 5, reset_gap_s: float = 1.0,
                 establish: bool = False, hold_jumps: bool = True, reanchor=None):
        self.scale_s = float(scale_s)
        self.wrap_units = wrap_units
        self.max_reorder_s = float(max_reorder_s)
        self.slack_s = float(slack_s)
        self.max_rate = float(max_rate)
        self.confirm = max(int(confirm), 1)
        self.reset_gap_s = float(reset_gap_s)
        self.establish = bool(establish)
        self.hold_jumps = bool(hold_jumps)
        self.reanchor = reanchor
        self.offset_s = 0.0
        self._last_raw: float | None = None
        self._last_s = 0.0
        self._last_rx = 0.0
        self.last_t = -math.inf
        self._pending: list[tuple] = []       # held samples: (raw, stamp [s], receive [s], payload)
        self._jump: tuple | None = None       # a plausible forward jump held for one stamp
        self._step: float | None = None       # typical forward step [s] (moving average)
        self.wraps = self.resets = self.rejected = 0

    @property
    def warmup(self) -> int:
        """Stamps held now while the first anchor is being established."""
        return len(self._pending) if self._last_raw is None else 0

    def _plausible(self, ds: float, dr: float) -> bool:
        return -self.max_reorder_s <= ds <= self.slack_s + self.max_rate * max(dr, 0.0)

    def feed(self, raw: float, receive_s: float, payload=None) -> list[tuple[float, object]]:
        """Take stamp ``raw`` received at ``receive_s`` [s]; returns the samples released now.

        Returns
        -------
        list of (float, object)
            ``(t, payload)`` with ``t`` on the continuous clock [s]: the sample itself when its
            stamp fits the stream's clock; nothing while it is held (it jumped forward, or does
            not fit, and the stamps after it will tell); a held jump and this sample when this one
            continues from the jump (the stream had a gap); or every held sample and this one when
            enough consecutive stamps confirm a new clock (a reboot, an epoch switch, the first
            anchor). Held samples that turn out to be outliers are dropped and counted in
            :attr:`rejected`; so is a stamp that is not a finite number.
        """
        try:
            s = float(raw) * self.scale_s
        except (OverflowError, TypeError, ValueError):
            s = math.nan
        if not math.isfinite(s) or not math.isfinite(receive_s):
            self.rejected += 1
            return []
        if self._last_raw is None:
            if not self.establish:
                return [self._accept(raw, s, receive_s, payload)]
            return self._candidate(raw, s, receive_s, payload)
        out = []
        if self._jump is not None:                       # the stamp before jumped forward: this one tells
            jr, js, jrx, jp = self._jump
            self._jump = None
            if -self.max_reorder_s <= s - js <= self._jump_s() and self._plausible(s - js, receive_s - jrx):
                out.append(self._accept(jr, js, jrx, jp))  # it goes on from the jump: the stream had a gap
            else:
                self.rejected += 1                         # the jump was an outlier
        ds = s - self._last_s
        wrap_s = 0.0
        w = self.wrap_units
        if w is not None and ds < 0:
            zone = (self.slack_s + self.max_rate * max(receive_s - self._last_rx, 0.0)) / self.scale_s
            if self._last_raw >= w - zone and raw < zone:
                wrap_s = w * self.scale_s
        if not self._plausible(ds + wrap_s, receive_s - self._last_rx):
            return out + self._candidate(raw, s, receive_s, payload)
        self._drop_pending()
        if wrap_s:
            self.offset_s += wrap_s
            self.wraps += 1
        elif ds < 0:
            return out + [(s + self.offset_s, payload)]     # reordered: the anchor stays where it is
        elif self.hold_jumps and ds > self._jump_s():
            self._jump = (raw, s, receive_s, payload)        # plausible, but one stamp does not move the clock
            return out
        return out + [self._accept(raw, s, receive_s, payload)]

    @property
    def jump_held(self) -> bool:
        """True when the last stamp fed jumped forward and is held until the next one tells."""
        return self._jump is not None

    def _jump_s(self) -> float:
        """A forward step longer than this is held [s]: ten typical steps, at least 50 ms."""
        return math.inf if self._step is None else max(10.0 * self._step, 0.05)

    def _candidate(self, raw: float, s: float, receive_s: float, payload) -> list[tuple[float, object]]:
        """A stamp that does not fit the anchor (or there is none yet): held until ``confirm``
        consecutive ones agree, then the clock (re-)anchors and releases them."""
        pend = self._pending
        if pend and not self._plausible(s - pend[-1][1], receive_s - pend[-1][2]):
            self._drop_pending()
            pend = self._pending
        pend.append((raw, s, receive_s, payload))
        if len(pend) < self.confirm:
            return []
        # confirmed: the stream is on a (new) clock. The first anchor keeps the stamps' own time; a
        # re-anchoring (reboot, epoch switch) continues reset_gap_s after the last accepted time,
        # so no window spans the discontinuity and the clock never jumps by the size of the step.
        if self._last_raw is not None:
            offset = self.last_t + self.reset_gap_s - pend[0][1]
            self.offset_s = offset if self.reanchor is None else self.reanchor(pend[0][1], offset)
            self.resets += 1
            self._step = None
        held, self._pending = pend, []
        return [self._accept(r, x, rx, p) for r, x, rx, p in held]

    def _drop_pending(self) -> None:
        """The held stamps were outliers (or a false start): count and forget them."""
        self.rejected += len(self._pending)
        self._pending = []

    def _accept(self, raw: float, s: float, receive_s: float, payload) -> tuple[float, object]:
        if self._last_raw is not None and s > self._last_s:
            step = s - self._last_s
            self._step = step if self._step is None else 0.9 * self._step + 0.1 * step
        self._last_raw, self._last_s, self._last_rx = raw, s, receive_s
        t = s + self.offset_s
        self.last_t = max(self.last_t, t)
        return t, payload


#: UNIX time of 2000-01-01 [ns]: a stamp from there to a day after the receive clock is a calendar time.
_CALENDAR_FROM_NS = 946_684_800 * 10**9
_DAY_NS = 86_400 * 10**9


class StampCheck:
    """Whether each stamp of one (system, component, message type) stream is one a vehicle's clock
    can have (module notes).

    Parameters
    ----------
    slack_s : float
        Forward step allowed whatever the receive step [s].
    max_rate : float
        Vehicle seconds allowed per receive second beyond ``slack_s`` (fast replays).
    max_reorder_s : float
        A step back up to this continues the same epoch [s].
    epochs : int
        Recent epochs kept (the stream's clock before and after restarts).
    confirm : int
        Consecutive, mutually plausible stamps ahead of every epoch that start a new one.
    wrap_ns : int, optional
        The field's range [ns] when it is an unsigned integer that wraps (a uint32 ``time_usec``:
        2**32 us): a step from the top of the range to its bottom continues the epoch.
    """

    def __init__(self, *, slack_s: float = 5.0, max_rate: float = 100.0, max_reorder_s: float = 1.0,
                 epochs: int = 4, confirm: int = 3, wrap_ns: int | None = None):
        self.wrap_ns = wrap_ns
        self.slack_ns = slack_s * 1e9
        self.max_rate = float(max_rate)
        self.reorder_ns = max_reorder_s * 1e9
        self.n_epochs = int(epochs)
        self.confirm = int(confirm)
        self._epochs: list[list] = []          # [last stamp ns (unwrapped), last receive ns, wraps ns], most recent first
        self._ahead: list[tuple[int, int]] = []

    def _fits(self, epoch, stamp_ns: int, rx_ns: int) -> bool:
        step = stamp_ns - epoch[0]
        return -self.reorder_ns <= step <= self.slack_ns + self.max_rate * max(rx_ns - epoch[1], 0)

    def check(self, stamp_ns: int, rx_ns: int) -> bool:
        """True when ``stamp_ns`` [ns] received at ``rx_ns`` [ns, UNIX] is plausible."""
        if stamp_ns == 0:
            return True
        if _CALENDAR_FROM_NS <= stamp_ns <= rx_ns + _DAY_NS:
            return True
        epochs = self._epochs
        for i, e in enumerate(epochs):            # e: [last stamp, last receive, offset of the wraps]
            t = stamp_ns + e[2]
            if self._fits(e, t, rx_ns) or (self.wrap_ns and self._fits(e, t + self.wrap_ns, rx_ns)
                                           and e[0] - e[2] > self.wrap_ns // 2):
                if not self._fits(e, t, rx_ns):   # from the top of the range to its bottom
                    e[2] += self.wrap_ns
                    t += self.wrap_ns
                e[0], e[1] = max(e[0], t), rx_ns
                if i:
                    epochs.insert(0, epochs.pop(i))
                self._ahead.clear()
                return True
        if not epochs or stamp_ns < max(e[0] - e[2] for e in epochs):   # the first, or a step back: a new epoch
            epochs.insert(0, [stamp_ns, rx_ns, 0])
            del epochs[self.n_epochs:]
            self._ahead.clear()
            return True
        ahead = self._ahead
        if ahead and not self._fits([ahead[-1][0], ahead[-1][1], 0], stamp_ns, rx_ns):
            ahead.clear()
        ahead.append((stamp_ns, rx_ns))
        if len(ahead) >= self.confirm:          # they agree: the stream's clock moved on
            epochs.insert(0, [stamp_ns, rx_ns, 0])
            del epochs[self.n_epochs:]
            ahead.clear()
        return False
