"""Alerts an operator reads: each kind of trouble said once, then at most every so often.

The sliding-window checks run five times a second and would repeat the same line as often: a
flight of a few chirps produced hundreds of alerts, and the one that mattered drowned.
:class:`AlertGate` lets an alert through when its subject (kind and what it is about: a pair, a
signal, the link) has not been said within ``interval_s`` of data time; what it holds back is
counted and said with the next one of that subject ("(4 more in the last 10 s)"). Data time, not
the wall clock, so a replay says what the live run said.

What a chirp is expected to do is no alert at all, and never reaches the gate: inputs that move
together while one is swept are the controller's reaction (``ExcitationMonitor.update(sweeping=True)``).

Pure: no I/O.
"""

from __future__ import annotations

import re

from livesweep.spectral.excitation import Alert

__all__ = ["AlertGate", "ALERT_INTERVAL_S"]

#: The same subject is said at most this often [s of data time].
ALERT_INTERVAL_S = 10.0
_NUMBERS = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
_PAIR = re.compile(r"^\s*(\S+/\S+):")


def _subject(alert: Alert) -> tuple:
    """What an alert is about: its kind and the pair or signal it names, its words without numbers
    for the others (so '3 lost' and '5 lost' are one subject)."""
    m = _PAIR.match(alert.message)
    if m:
        return alert.kind, m.group(1)
    return alert.kind, _NUMBERS.sub("#", alert.message)


class AlertGate:
    """Rate limit and de-duplication of alerts by subject, on data time.

    Parameters
    ----------
    interval_s : float
        The same subject is let through at most this often [s of data time].
    """

    def __init__(self, interval_s: float = ALERT_INTERVAL_S):
        self.interval_s = float(interval_s)
        self._last: dict[tuple, float] = {}      # subject -> data time it was last said
        self._held: dict[tuple, int] = {}        # subject -> alerts held back since
        self.held_back = 0                       # all alerts held back so far

    def admit(self, t_s: float | None, alert: Alert) -> Alert | None:
        """The alert to say now (with how many were held back since the last of its subject), or
        None to hold it back. An alert without a data time (before any sample) always passes."""
        key = _subject(alert)
        if t_s is None:
            return alert
        last = self._last.get(key)
        if last is not None and t_s - last < self.interval_s and t_s >= last:
            self._held[key] = self._held.get(key, 0) + 1
            self.held_back += 1
            return None
        self._last[key] = t_s
        n = self._held.pop(key, 0)
        if not n:
            return alert
        return Alert(alert.kind, f"{alert.message} ({n} more in the last {t_s - last:.0f} s)", alert.value)
