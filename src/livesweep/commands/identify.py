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

    if getattr(args, "map", None):
        return _identify_flight(args)
    if getattr(args, "swept_input", None):
        from livesweep.errors import ConfigError

        raise ConfigError("--input selects a swept input of a flight log: give it with --map")
    with folder_lock(prepare_out_dir(args.out)):
        case = load_case(args.case)
        progress = progress_printer()
        ident = identify(case, until=args.stage, progress=progress)
        present_identification(ident, args.out, plots=getattr(args, "plots", True), progress=progress)
    return 0


def _identify_flight(args) -> int:
    """``identify FLIGHT.mcap --map NAME``: each swept input's test points as one case, a report each."""
    from pathlib import Path

    from livesweep.campaign.concat import identify_test_points
    from livesweep.campaign.flight import plan_flight
    from livesweep.locks import folder_lock
    from livesweep.report.writer import prepare_out_dir

    plans = plan_flight(args.case, map=args.map, swept_input=args.swept_input)
    stem = Path(args.case).stem
    for plan in plans:
        out = Path(args.out) / plan.swept_input
        with folder_lock(prepare_out_dir(out)):
            progress = progress_printer()
            progress(f"{stem}: {len(plan.points)} test point(s) of {plan.swept_input}: "
                     + ", ".join(f"{p.label} ({p.start_s:.1f}-{p.end_s:.1f} s)" for p in plan.points))
            ident = identify_test_points(plan.points, map=args.map, inputs=[plan.swept_input],
                                         transfer_functions=plan.transfer_functions or None, out_dir=out,
                                         name=f"{stem}-{plan.swept_input}")
            present_identification(ident, out, plots=getattr(args, "plots", True), progress=progress)
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
