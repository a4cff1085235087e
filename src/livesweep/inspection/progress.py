"""How far ``livesweep inspect`` has read, written to stderr: :func:`stderr_progress`.

One job: turn the ``progress(done, total, unit)`` calls of :func:`~livesweep.inspection.inspect_log`
into a line on the terminal (rewritten in place) or a line every few seconds in a log.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

__all__ = ["stderr_progress"]


def stderr_progress(path, *, stream=None, after_s: float = 1.0):
    """A ``progress`` for :func:`inspect_log` that writes how far it has read to stderr.

    Nothing for the first ``after_s``; then, on a terminal, one line rewritten in place at most
    four times a second (cleared at the end); otherwise a line every 5 s at most.
    ``reading flight.bin: 40 % (3.2 of 8.0 MB)``.

    Parameters
    ----------
    path : str or Path
        The log (its name is shown).
    stream : file, optional
        Default ``sys.stderr``.
    after_s : float
        Quiet time [s] before the first report.
    """
    out = sys.stderr if stream is None else stream
    tty = bool(getattr(out, "isatty", lambda: False)())
    every = 0.25 if tty else 5.0
    t0 = time.monotonic()
    state = {"next": t0 + after_s, "shown": False}
    name = Path(path).name

    def report(done: int, total: int, unit: str) -> None:
        now = time.monotonic()
        end = total > 0 and done >= total
        if end:
            if tty and state["shown"]:
                out.write("\r\033[K")
                out.flush()
            return
        if now < state["next"]:
            return
        state["next"] = now + every
        if unit == "bytes":
            amount = f"{done / 1e6:.1f} of {total / 1e6:.1f} MB"
        else:
            amount = f"{done} of {total} {unit}"
        pct = f"{100 * done / total:.0f} % " if total > 0 else ""
        text = f"reading {name}: {pct}({amount})"
        out.write(("\r\033[K" + text) if tty else text + "\n")
        out.flush()
        state["shown"] = True

    return report
