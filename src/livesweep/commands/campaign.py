"""``livesweep campaign``: a flight-test campaign database (:mod:`livesweep.campaign`).

``campaign add DB FILES...`` adds logs (one line per file: added N test points / unchanged /
skipped: reason; exit status 0 even when files are skipped); ``campaign list DB`` prints the test
points as a table, filtered by axis, swept input, verdict or flight."""

from __future__ import annotations

import sys

__all__ = ["cmd_campaign", "add_campaign_arguments"]


def add_campaign_arguments(p) -> None:
    """The ``campaign`` verb's sub-verbs (``add``, ``list``) on its parser ``p``."""
    sub = p.add_subparsers(dest="campaign_verb", metavar="{add,list,identify,report}", required=True)
    a = sub.add_parser("add", help="add log files (.bin, .tlog, .mcap, .ulg) and their test points",
                       description="Add log files to the campaign DB (created when missing). A file whose content "
                                   "(SHA-256) is already in is unchanged; a damaged or unreadable one is skipped, "
                                   "nothing of it written. Example: livesweep campaign add flights.db logs/*.bin")
    a.add_argument("db", help="campaign database (SQLite file)")
    a.add_argument("files", nargs="+", help="log files")
    a.set_defaults(func=cmd_campaign)
    li = sub.add_parser("list", help="list the test points (a table), filtered",
                        description="List the campaign's test points. Example: livesweep campaign list flights.db "
                                    "--axis 7 --verdict GO")
    li.add_argument("db", help="campaign database (SQLite file)")
    li.add_argument("--axis", type=int, help="SystemID axis number")
    li.add_argument("--input", dest="swept_input", metavar="NAME", help="swept input")
    li.add_argument("--verdict", help="GO, NO-GO, ... or 'none' for test points found offline and not judged")
    li.add_argument("--flight", help="flight id, or the start of its SHA-256 (8 hex digits or more)")
    li.add_argument("--flights", action="store_true", help="list the flights instead of the test points")
    li.set_defaults(func=cmd_campaign)
    ident = sub.add_parser("identify", help="identify the test points of one input across flights, concatenated",
                           description="Concatenate the selected test points of one swept input (across flights) "
                                       "into one identification (the method's multi-run concatenation) and write "
                                       "the usual report. Example: livesweep campaign identify flights.db --map "
                                       "ardupilot-sysid-dataflash --input roll --out roll-report")
    ident.add_argument("db", help="campaign database (SQLite file)")
    ident.add_argument("--map", required=True, help="channel map: a preset name or a map file")
    ident.add_argument("--input", dest="swept_input", metavar="NAME", help="the swept input")
    ident.add_argument("--all", action="store_true",
                       help="every swept input with usable test points, one case each, on the batch engine "
                            "(OUT/cases, OUT/reports; --workers N or --dask ADDRESS)")
    ident.add_argument("--workers", type=int, help="with --all: local worker processes (default: the CPUs)")
    ident.add_argument("--dask", metavar="ADDRESS", help="with --all: a Dask scheduler (tcp://host:8786)")
    ident.add_argument("--out", required=True, help="folder for the case file and the report")
    ident.add_argument("--verdict", default="usable",
                       help="usable (GO or not judged; default), GO, NO-GO, none, or any")
    ident.add_argument("--axis", type=int, help="SystemID axis number")
    ident.add_argument("--flight", help="flight id, or the start of its SHA-256")
    ident.set_defaults(func=cmd_campaign)
    rep = sub.add_parser("report", help="one HTML page: test points, their responses overlaid, their parameters",
                         description="Write DIR/campaign.html: the flights and test points, each pair's recorded "
                                     "responses (/livesweep/model) overlaid on one Bode plot, and the identified "
                                     "parameters with their Cramer-Rao bounds against a condition. Example: "
                                     "livesweep campaign report flights.db --out campaign --input roll")
    rep.add_argument("db", help="campaign database (SQLite file)")
    rep.add_argument("--out", required=True, help="folder for campaign.html")
    rep.add_argument("--input", dest="swept_input", metavar="NAME", help="only the test points of this swept input")
    rep.add_argument("--condition", metavar="NAME",
                     help="plot the parameters against this test-point condition (default: test-point order)")
    rep.set_defaults(func=cmd_campaign)


def _fmt(x, nd: int = 3) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.{nd}f}"
    return str(x)


def _table(header, rows) -> str:
    rows = [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(h), *(len(r[k]) for r in rows)) if rows else len(h) for k, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in rows]
    return "\n".join(line.rstrip() for line in lines)


def cmd_campaign(args) -> int:
    from pathlib import Path

    import livesweep.campaign as campaign
    from livesweep.errors import ConfigError

    if args.campaign_verb in ("list", "identify", "report") and not Path(args.db).is_file():
        raise ConfigError(f"{args.db}: no such campaign database")
    with campaign.open(args.db) as c:
        if args.campaign_verb == "add":
            def progress(path, outcome, detail):
                if outcome == "added":
                    print(f"{path}: added {detail} test point{'' if detail == 1 else 's'}")
                elif outcome == "unchanged":
                    print(f"{path}: unchanged (already in)")
                else:
                    print(f"{path}: skipped: {detail}")
                sys.stdout.flush()

            r = c.add(args.files, progress=progress)
            n = c.counts()
            print(f"campaign {args.db}: {len(r.added)} added, {len(r.unchanged)} unchanged, {len(r.skipped)} "
                  f"skipped; {n['flights']} flights, {n['test_points']} test points")
            return 0
        if args.campaign_verb == "identify":
            from livesweep.campaign.identify import identify_all, identify_selection

            verdict = None if args.verdict == "any" else args.verdict
            if args.all:
                rows = identify_all(c, args.out, map=args.map, verdict=verdict, workers=args.workers,
                                    dask_address=args.dask)
                for row in rows:
                    print(f"{row.get('case', '?')}: {row.get('status', '?')}"
                          + (f" ({row['error']})" if row.get("error") else ""))
                print(f"wrote {Path(args.out) / 'reports'}")
                return 0 if all(row.get("status") != "failed" for row in rows) else 1
            if not args.swept_input:
                raise ConfigError("campaign identify: give --input NAME, or --all")
            flight = None if args.flight is None else (int(args.flight) if args.flight.isdigit() and
                                                       len(args.flight) < 8 else args.flight)
            done = identify_selection(c, args.out, map=args.map, swept_input=args.swept_input, verdict=verdict,
                                      axis=args.axis, flight=flight)
            print(f"campaign {args.db}: {len(done.test_points)} test point(s) of {args.swept_input} concatenated: "
                  + ", ".join(f"flight {r.flight_id} TP{r.number} ({r.start_s:.1f}-{r.end_s:.1f} s)"
                              for r in done.test_points))
            print(f"wrote {done.report}")
            return 0
        if args.campaign_verb == "report":
            from livesweep.campaign.report import write_campaign_report

            print(f"wrote {write_campaign_report(c, args.out, swept_input=args.swept_input, condition=args.condition)}")
            return 0
        if args.flights:
            print(_table(["id", "sha256", "format", "vehicle", "date", "test points", "path"],
                         [(f.id, f.sha256[:12], f.format, f.vehicle, f.date, f.test_points, f.path)
                          for f in c.flights()]))
            return 0
        tps = c.test_points(axis=args.axis, swept_input=args.swept_input, verdict=args.verdict, flight=args.flight)
        print(_table(["id", "flight", "#", "start_s", "end_s", "axis", "input", "source", "verdict", "label"],
                     [(t.id, t.flight_id, t.number, t.start_s, t.end_s, t.axis, t.swept_input, t.source, t.verdict,
                       t.label) for t in tps]))
        print(f"{len(tps)} test point{'' if len(tps) == 1 else 's'}")
        return 0
