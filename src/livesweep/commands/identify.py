"""``livesweep identify``: :func:`livesweep.identify` on a case file, its report written and its
summary printed (``livesweep demo`` ends the same way)."""

from __future__ import annotations

import time
from pathlib import Path

__all__ = ["cmd_identify", "progress_printer", "present_identification"]


def cmd_identify(args) -> int:
    """Identify from a case file: frequency responses, then (as the case defines them) transfer
    functions, state-space derivatives and time-domain verification."""
    from livesweep.config import load_case
    from livesweep.locks import folder_lock
    from livesweep.report.writer import prepare_out_dir
    from livesweep.stages.identify import identify

    with folder_lock(prepare_out_dir(args.out)):
        case = load_case(args.case)
        progress = progress_printer()
        ident = identify(case, until=args.stage, progress=progress)
        present_identification(ident, args.out, plots=getattr(args, "plots", True), progress=progress)
    return 0


def progress_printer():
    """A ``progress`` callback for :func:`livesweep.identify` that prints each line with the time
    since it was made: ``[   2.1 s] xv15-cruise: frequency responses from 2 record(s)``."""
    t0 = time.monotonic()

    def progress(msg: str) -> None:
        print(f"[{time.monotonic() - t0:6.1f} s] {msg}", flush=True)

    return progress


def present_identification(ident, out, *, plots: bool = True, progress=None) -> Path:
    """Write the report of an :class:`~livesweep.stages.identify.Identification` to the folder
    ``out`` (prepared and locked by the caller) and print its summary and where it went.

    Returns
    -------
    Path
        The ``report.json`` written.
    """
    from livesweep.report.console import summary_lines
    from livesweep.report.writer import write_report

    if progress is not None:
        progress("writing the report" + ("" if plots else " (no plots)"))
    path = write_report(ident, out, plots=plots)
    print("\n".join(summary_lines(ident)))
    print(f"wrote {path} and {path.parent / 'report.html'}")
    return path
