"""A one-line terminal status for operators without Rerun.

:func:`format_status` turns one update into one line (pure); :class:`StatusLine` writes such a
line to a stream at most once a second, overwriting itself with ``"\\r"`` on a terminal and as
plain lines otherwise (a log file or a pipe gets one line per second, no control characters).

The update is a dict; every key is optional (a missing or None value is shown as ``-``):

``frames_per_s`` : float
    Frames received per second over the last interval [1/s].
``frames_lost`` : int
    Frames lost so far (sequence gaps, kernel drops, shed frames) [count].
``test_point`` : str or None
    Label of the open test point (``"TP3 da"``); None when no test point is open.
``test_point_elapsed_s`` : float or None
    Time since that test point opened [s].
``test_point_loss`` : float or None
    Fraction of its frames that test point has lost so far (0..1; its last judgement's
    :class:`~livesweep.spectral.verdict.DataLoss`); shown from 0.1 % on.
``verdict`` : str
    ``"WAIT"``, ``"GO"`` or ``"NO-GO"``, or the last test point's label (``"NO-GO (link)"``).
``sweep`` : dict of str -> float or None
    Current sweep frequency per swept input [rad/s] (None: not sweeping).
``alerts`` : int
    Alerts raised so far [count].

Example lines::

    54 fr/s | lost 0 | TP2 da 01:42 | NO-GO | da 3.2 rad/s | 3 alerts
    41 fr/s | lost 14652 | TP3 da 01:10 27 % lost | NO-GO (link) | da 9.5 rad/s | 5 alerts
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import TextIO

from livesweep.monitor.text import omega_text

__all__ = ["format_status", "StatusLine", "STATUS_KEYS"]

#: The keys :func:`format_status` reads.
STATUS_KEYS = ("frames_per_s", "frames_lost", "test_point", "test_point_elapsed_s", "test_point_loss", "verdict",
               "sweep", "alerts")


def _num(x) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _clock(seconds: float) -> str:
    s = int(max(0.0, seconds))
    h, rem = divmod(s, 3600)
    return f"{h:d}:{rem // 60:02d}:{rem % 60:02d}" if h else f"{rem // 60:02d}:{rem % 60:02d}"


def format_status(info: dict, width: int | None = None) -> str:
    """One status line from one update (see the module docstring for the keys).

    Parameters
    ----------
    info : dict
        The update.
    width : int, optional
        Terminal width [characters]; a longer line is cut and ends in ``"…"``.

    Returns
    -------
    str
        ``"<fps> fr/s | lost <n> | <test point> <mm:ss> [<p> % lost] | <verdict> | <input> <omega> rad/s ... |
        <n> alerts"``, no line break.
    """
    fps = _num(info.get("frames_per_s"))
    lost = _num(info.get("frames_lost"))
    parts = [f"{fps:.0f} fr/s" if fps is not None else "- fr/s",
             f"lost {lost:.0f}" if lost is not None else "lost -"]
    tp = info.get("test_point")
    if tp:
        el = _num(info.get("test_point_elapsed_s"))
        text = f"{tp} {_clock(el)}" if el is not None else str(tp)
        loss = _num(info.get("test_point_loss"))
        if loss is not None and loss >= 0.0005:          # what rounds to 0.0 % is not said
            text += f" {100 * loss:.0f} % lost" if loss >= 0.01 else f" {100 * loss:.1f} % lost"
        parts.append(text)
    else:
        parts.append("no test point")
    parts.append(str(info.get("verdict") or "-"))
    sweep = info.get("sweep") or {}
    if sweep:
        parts.append(", ".join(f"{name} {omega_text(w)} rad/s" if _num(w) is not None else f"{name} quiet"
                               for name, w in sweep.items()))
    n_alerts = _num(info.get("alerts"))
    if n_alerts is not None:
        parts.append(f"{n_alerts:.0f} alert" + ("" if n_alerts == 1 else "s"))
    line = " | ".join(parts).replace("\r", " ").replace("\n", " ")
    if width is not None and width > 0 and len(line) > width:
        line = line[:max(0, width - 1)] + "…"
    return line


class StatusLine:
    """Writes :func:`format_status` lines to a stream, at most one per ``min_interval_s``.

    Parameters
    ----------
    stream : text stream
        Where to write (default ``sys.stderr``).
    min_interval_s : float
        Least time between two lines [s] (default 1).
    tty : bool, optional
        Overwrite the line with ``"\\r"`` (True) or write plain lines (False); default: whether
        ``stream`` is a terminal.
    width : int, optional
        Line width on a terminal [characters]; default: the terminal's width at each write.
    clock : callable
        Monotonic seconds (for tests).
    """

    def __init__(self, stream: TextIO | None = None, *, min_interval_s: float = 1.0, tty: bool | None = None,
                 width: int | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.min_interval_s = float(min_interval_s)
        if tty is None:
            try:
                tty = bool(self.stream.isatty())
            except (AttributeError, ValueError, OSError):
                tty = False
        self.tty = tty
        self.width = width
        self._clock = clock
        self._last: float | None = None
        self._shown = 0          # characters of the line now on the terminal
        self._pending: dict | None = None

    def _width(self) -> int | None:
        if not self.tty:
            return None
        if self.width is not None:
            return self.width
        import shutil
        return max(20, shutil.get_terminal_size((100, 24)).columns - 1)

    def update(self, info: dict, *, force: bool = False) -> bool:
        """Show ``info`` if a second (``min_interval_s``) has passed since the last line; True if written.

        An update that comes too soon is kept and shown by :meth:`close` if nothing follows it.
        """
        now = self._clock()
        if not force and self._last is not None and now - self._last < self.min_interval_s:
            self._pending = info
            return False
        self._pending = None
        self._last = now
        self._write(format_status(info, self._width()))
        return True

    def _write(self, line: str) -> None:
        try:
            if self.tty:
                pad = " " * max(0, self._shown - len(line))      # clear what the longer last line left
                self.stream.write("\r" + line + pad)
                self._shown = len(line)
            else:
                self.stream.write(line + "\n")
            self.stream.flush()
        except (OSError, ValueError):
            pass    # a closed or broken stream must not stop the monitor

    def close(self) -> None:
        """Show a pending update and end the line on a terminal (so the next output starts clean)."""
        if self._pending is not None:
            self.update(self._pending, force=True)
        if self.tty and self._shown:
            try:
                self.stream.write("\n")
                self.stream.flush()
            except (OSError, ValueError):
                pass
            self._shown = 0
