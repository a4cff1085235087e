"""The ``livesweep`` command line's parser: every verb, option, help text and example.

:func:`build_parser` is what :func:`livesweep.cli.main` parses with; each verb's ``func`` is its
command in :mod:`livesweep.commands`.
"""

from __future__ import annotations

import argparse

from livesweep import __version__
from livesweep.commands.campaign import add_campaign_arguments
from livesweep.commands.demo import cmd_demo
from livesweep.commands.identify import cmd_identify
from livesweep.commands.logs import cmd_convert, cmd_inspect, cmd_maps, cmd_new_case, cmd_recover
from livesweep.commands.monitor import cmd_monitor, cmd_replay
from livesweep.commands.sim import cmd_sim, cmd_stream
from livesweep.spectral import DEFAULT_WINDOW_S
from livesweep.stages import STAGES  # the stage names only: the stages load when a command runs

__all__ = ["build_parser", "EXAMPLES"]


def _mavlink_system(text: str) -> tuple:
    """``--sysid 1`` or ``1:1``: (system id, component id or None), each 0-255."""
    parts = text.split(":")
    try:
        ids = [int(p) for p in parts]
    except ValueError:
        ids = []
    if not 1 <= len(ids) <= 2 or not all(0 <= i <= 255 for i in ids):
        raise argparse.ArgumentTypeError(f"{text!r} is not SYS or SYS:COMP (MAVLink ids 0-255)")
    return ids[0], ids[1] if len(ids) == 2 else None


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    return v


def _add_monitor_options(m) -> None:
    m.add_argument("--case", help="case file or channel map ([signals] and [spectral]); default: the XV-15 map")
    m.add_argument("--map", metavar="NAME|FILE.toml",
                   help="a channel-map preset (`livesweep maps` lists them) or map file, in place of --case")
    m.add_argument("--window", type=_positive_float, help=f"sliding window [s] (default {DEFAULT_WINDOW_S:g})")
    m.add_argument("--update-period", type=_positive_float, help="estimate every this many seconds of data (default 0.2)")
    m.add_argument("--rerun-save", metavar="FILE.rrd", help="write the Rerun recording to a file (headless)")
    m.add_argument("--rerun-spawn", action="store_true", help="open the Rerun desktop viewer")
    m.add_argument("--rerun-serve", action="store_true", help="serve the Rerun web viewer")
    m.add_argument("--rerun-bind", default="127.0.0.1", help="address the Rerun web viewer binds (default 127.0.0.1)")
    m.add_argument("--sysid", type=_mavlink_system, metavar="SYS[:COMP]",
                   help="the MAVLink system (and component) to analyse; default: the map's [map].sysid, else the "
                        "first vehicle that sends 10 frames of every mapped message (others are recorded, not analysed)")
    m.add_argument("--saturation", action="append", metavar="IN=LO:HI",
                   help="actuator limits for the saturation alert, e.g. da=-20:20 (repeatable)")
    m.add_argument("--require", action="append", metavar="OUT/IN",
                   help="pair this test point must excite for a GO, e.g. p/da (repeatable; default: on-axis pairs)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="livesweep", description="Frequency-sweep monitoring and system identification.")
    p.add_argument("--version", action="version", version=f"livesweep {__version__}")
    sub = p.add_subparsers(dest="verb", required=True)

    s = sub.add_parser("sim", help="simulate a test point (sweeps or verification manoeuvres) to MCAP or live MAVLink")
    s.add_argument("--model", default="xv15-cruise", help="vehicle model: xv15-cruise, xv15-hover or quad-attitude")
    s.add_argument("--manoeuvre", default="sweep", choices=["sweep", "doublet", "3211", "step"],
                   help="frequency sweeps, or a verification manoeuvre: doublet, 3-2-1-1 or step")
    s.add_argument("--axis", action="append", help="input to excite (XV-15: da, dr; quad-attitude: roll_cmd, pitch_cmd); repeat for several; default the first")
    s.add_argument("--repeat", type=int, default=2, help="sweeps per axis")
    s.add_argument("--omega-min", type=_positive_float, default=0.3, help="sweep start frequency [rad/s]")
    s.add_argument("--omega-max", type=_positive_float, default=20.0, help="sweep end frequency [rad/s]")
    s.add_argument("--duration", type=_positive_float, default=100.0, help="sweep length without trims [s]")
    s.add_argument("--amplitude", type=_positive_float, default=2.0, help="sweep or pulse amplitude [input units: deg for the XV-15, -1..1 for quad-attitude]")
    s.add_argument("--pulse", type=_positive_float, default=1.0, help="doublet/3211 unit pulse or step hold [s]")
    s.add_argument("--off-axis-rms", type=_positive_float, default=0.0, help="uncorrelated pilot noise on other inputs [input units rms]")
    s.add_argument("--effect", action="append", default=[], metavar="KIND:key=value,...",
                   help="inject an effect, e.g. sensor_skew:output=p,delay_s=0.05 (repeatable)")
    s.add_argument("--no-noise", action="store_true", help="no sensor noise")
    s.add_argument("--no-turbulence", action="store_true", help="calm air")
    s.add_argument("--seed", type=int, default=0, help="random seed of noise and turbulence (same seed, same log)")
    s.add_argument("--out", help="MCAP file to write")
    s.add_argument("--force", action="store_true", help="replace an existing --out (never a file being recorded)")
    s.add_argument("--mavlink", help="stream MAVLink 2 to a pymavlink URL, e.g. udpout:127.0.0.1:14550")
    s.add_argument("--speed", type=_positive_float, default=1.0, help="stream pace: 1 = real time, 10 = ten times faster")
    s.set_defaults(func=cmd_sim)

    m = sub.add_parser("monitor", help="live sweep monitor: MAVLink/Zenoh in, coherence and adequacy in Rerun, MCAP recording")
    m.add_argument("--mavlink", action="append", metavar="URL", help="pymavlink connection, e.g. udpin:127.0.0.1:14550")
    m.add_argument("--signing-key-file", help="32-byte MAVLink 2 signing key: unsigned and forged packets are rejected")
    m.add_argument("--zenoh", metavar="KEYEXPR", help="subscribe to a Zenoh key expression (JSON payloads)")
    m.add_argument("--zenoh-config", help="Zenoh JSON5 config for real deployments (routers, TLS)")
    m.add_argument("--zenoh-listen", type=int, help="Zenoh TCP port on 127.0.0.1 (default: no listener)")
    m.add_argument("--zenoh-publish", action="store_true", help="publish live results under livesweep/...")
    m.add_argument("--record", metavar="FILE.mcap", help="record every message and the live results")
    m.add_argument("--force", action="store_true", help="overwrite an existing --record file")
    m.add_argument("--status", action=argparse.BooleanOptionalAction, default=None,
                   help="a one-line status on stderr once a second (frames/s, losses, test point, verdict, sweep); "
                        "default: when stderr is a terminal")
    m.add_argument("--markers", action=argparse.BooleanOptionalAction, default=None,
                   help="read test-point markers typed in the terminal ('s roll', 'e'); default: when it is one")
    m.add_argument("--duration", type=_positive_float, help="stop after this many seconds (default: Ctrl-C)")
    _add_monitor_options(m)
    m.set_defaults(func=cmd_monitor)

    r = sub.add_parser("replay", help="run the monitor pipeline over an MCAP recording")
    r.add_argument("log", help="MCAP log")
    r.add_argument("--speed", type=_positive_float, default=0.0, help="N x real time (default: as fast as possible)")
    _add_monitor_options(r)
    r.set_defaults(func=cmd_replay)

    i = sub.add_parser("identify", help="identify from a case file (docs/case-file.md), or from a flight's recorded "
                                        "test points with --map, and write report.json, report.html, plots")
    i.add_argument("case", help="case file (TOML), or a flight log (MCAP) with --map")
    i.add_argument("--map", help="with a flight log instead of a case: its channel map (a preset name or a file); "
                                 "each swept input's GO (or not judged) test points are identified together, one "
                                 "report per input in OUT/<input>")
    i.add_argument("--input", dest="swept_input", metavar="NAME", help="with --map: only this swept input")
    i.add_argument("--out", required=True, help="folder for the report")
    i.add_argument("--stage", default="residual-loop", choices=list(STAGES),
                   help="last stage to run (default: every stage the case defines)")
    i.add_argument("--no-plots", dest="plots", action="store_false",
                   help="skip the SVG plots (plots/*.svg, and so report.html has none; report.json is the same; "
                        "about half the time)")
    i.set_defaults(func=cmd_identify)

    mp = sub.add_parser("maps", help="list the channel-map presets for real vehicles (for monitor, replay and "
                                     "new-case --map NAME)",
                        description="List the channel-map presets shipped with livesweep (ArduPilot and PX4 "
                                    "vehicles): for each, its name, what it maps, its inputs and outputs, and what "
                                    "the log or link must carry (messages, rates, parameters). Give a preset's name "
                                    "to monitor, replay or new-case with --map NAME; `livesweep inspect LOG` says "
                                    "which presets fit a log.")
    mp.set_defaults(func=cmd_maps)

    c = sub.add_parser("convert", help="convert a MAVLink .tlog, DataFlash .bin, PX4 .px4log or .ulg, NumPy .npy, "
                                       "MATLAB .mat, Parquet or delimited text log to MCAP",
                       description="Convert a log to livesweep's MCAP (the only output format). Inputs, recognised "
                                   "by content, not by name: MAVLink .tlog; ArduPilot DataFlash .bin and PX4 sdlog2 "
                                   ".px4log; PX4 ULog .ulg (extra livesweep[ulog]); tables: NumPy .npy, MATLAB v5 "
                                   ".mat, Apache Parquet and delimited text (comma, tab, ';', '|' or whitespace), with a "
                                   "column map (--columns) naming the columns, their units and the time column "
                                   "(without one, the table's own column names are used). An MCAP file is not "
                                   "converted (`livesweep recover` finishes an unfinished one).")
    c.add_argument("src", help="the log (its format is recognised by content, not by name)")
    c.add_argument("--out", required=True, help="MCAP file to write")
    c.add_argument("--columns", help="column map (TOML) for .npy, .mat, Parquet and text tables")
    c.add_argument("--force", action="store_true", help="replace an existing --out (never the source log itself)")
    c.add_argument("--partial", action="store_true",
                   help="convert a damaged DataFlash or ULog log even when less than half of it is readable")
    c.set_defaults(func=cmd_convert)

    ins = sub.add_parser("inspect", help="what a log holds: topics, fields with units, rates, time span, test points, "
                                         "and the channel maps that fit it",
                         description="Describe any log livesweep reads (MCAP, .tlog, DataFlash .bin, .px4log, ULog; "
                                     "tables with --columns). Example: livesweep inspect flight.tlog")
    ins.add_argument("log", help="the log")
    ins.add_argument("--columns", help="column map (TOML) for .npy, .mat, Parquet and text tables")
    ins.set_defaults(func=cmd_inspect)

    nc = sub.add_parser("new-case", help="write an annotated case file for a log and a channel map",
                        description="Write a case file (TOML) for LOG with the channel map MAP: the log (converted to "
                                    "MCAP next to the case when needed), the map's [signals] and [spectral], and "
                                    "commented templates of the later stages. Example: livesweep new-case "
                                    "sid_roll.bin --map ardupilot-sysid-dataflash --out roll.toml")
    nc.add_argument("log", help="the log (any format livesweep reads)")
    nc.add_argument("--map", required=True, metavar="NAME|FILE.toml",
                    help="a channel-map preset (`livesweep maps`, or `livesweep inspect LOG` suggests one) or map file")
    nc.add_argument("--out", default="case.toml", help="case file to write (default: case.toml)")
    nc.add_argument("--force", action="store_true", help="replace an existing --out")
    nc.set_defaults(func=cmd_new_case)

    rc = sub.add_parser("recover", help="a finished copy of a killed or damaged recording, saying what was lost",
                        description="Copy every readable record of an unfinished or damaged MCAP recording (a killed "
                                    "process, flipped bits) into a finished file: damaged chunks are stepped over, "
                                    "what was lost or kept unverified is counted and printed, and the exit status is "
                                    "1 when anything was. Example: livesweep recover live.mcap")
    rc.add_argument("log", help="the unfinished or damaged MCAP file")
    rc.add_argument("--out", help="finished copy to write (default: LOG with .recovered.mcap)")
    rc.add_argument("--force", action="store_true", help="replace an existing --out")
    rc.set_defaults(func=cmd_recover)

    st = sub.add_parser("stream", help="send a recorded .tlog or DataFlash .bin over MAVLink as the vehicle sent it, "
                                       "paced by the log's own time")
    st.add_argument("log", help="MAVLink .tlog or ArduPilot DataFlash .bin (recognised by content)")
    st.add_argument("--mavlink", required=True, metavar="URL", help="where to send, e.g. udpout:127.0.0.1:14550")
    st.add_argument("--speed", type=_positive_float, default=1.0,
                    help="x real time (default 1; 0 = as fast as possible)")
    st.add_argument("--start-s", type=_positive_float, default=0.0,
                    help="send from this many seconds after the log's first time stamp (default 0)")
    st.add_argument("--end-s", type=_positive_float, help="send up to this many seconds after it (default: the end)")
    st.add_argument("--rate-hz", type=_positive_float,
                    help="DataFlash: at most this many of each message per second of log time, as a telemetry "
                         "stream rate (SRx_EXTRA1 = 50) would be (default: the log's own rate)")
    st.add_argument("--sysid", type=int, help="DataFlash: the MAVLink system id to send as (default 1)")
    st.set_defaults(func=cmd_stream)

    from livesweep.batch import add_batch_arguments

    b = sub.add_parser("batch", help="run many identifications in parallel (local cores or a Dask cluster), resumable")
    add_batch_arguments(b)

    cp = sub.add_parser("campaign", help="a flight-test campaign database: add logs, list their test points",
                        description="A campaign: every flight (log file, identified by the SHA-256 of its content) "
                                    "and test point in one SQLite file. `campaign add DB FILES...` adds logs; "
                                    "`campaign list DB` lists test points (--axis, --input, --verdict, --flight); "
                                    "`campaign identify DB --map M --input IN --out DIR` identifies the selected test "
                                    "points of one input across flights, concatenated; `campaign report DB --out DIR` "
                                    "writes one HTML page of the test points, their responses overlaid and their "
                                    "parameters against a condition (--input, --condition).")
    add_campaign_arguments(cp)

    d = sub.add_parser("demo", help="fly simulated XV-15 sweeps live into the monitor, record them, identify frequency responses")
    d.add_argument("--out", help="folder for the recording, the .rrd and the report (default: ./livesweep-demo)")
    d.add_argument("--speed", type=_positive_float, default=10.0, help="simulator pace, x real time (default 10)")
    d.add_argument("--view", action="store_true", help="open the Rerun viewer instead of writing live.rrd")
    d.set_defaults(func=cmd_demo)
    for verb, sp in sub.choices.items():
        sp.formatter_class = _HelpFormatter
        sp.epilog = "examples:\n" + "\n".join(f"  {line}" for line in EXAMPLES[verb])
    return p


#: What ``livesweep VERB --help`` shows under "examples" (each line runs as written, given the files).
EXAMPLES = {
    "sim": ["livesweep sim --axis da --repeat 2 --out sweeps.mcap",
            "livesweep sim --manoeuvre doublet --axis dr --amplitude 3 --effect time_delay:input=dr,delay_s=0.05 "
            "--out verify.mcap",
            "livesweep sim --mavlink udpout:127.0.0.1:14550 --speed 10"],
    "monitor": ["livesweep monitor --mavlink udpin:0.0.0.0:14550 --map ardupilot-copter-quad-x --record flight.mcap "
                "--rerun-spawn",
                "livesweep monitor --zenoh 'drone/**' --case my_case.toml --record flight.mcap --rerun-save flight.rrd"],
    "replay": ["livesweep replay flight.mcap", "livesweep replay flight.mcap --map ardupilot-copter-pid --speed 4"],
    "identify": ["livesweep identify config/xv15_cruise_lateral.toml --out out/cruise",
                 "livesweep identify my_case.toml --out out/quick --stage frequency-response --no-plots",
                 "livesweep identify flight.mcap --map ardupilot-sysid-dataflash --out out/flight"],
    "maps": ["livesweep maps"],
    "convert": ["livesweep convert 00000012.BIN --out flight.mcap",
                "livesweep convert sweep.npy --columns config/xplane_c172_columns.toml --out sweep.mcap"],
    "inspect": ["livesweep inspect flight.tlog", "livesweep inspect sweep.npy --columns columns.toml"],
    "new-case": ["livesweep new-case 00000012.BIN --map ardupilot-sysid-dataflash --out roll.toml"],
    "recover": ["livesweep recover flight.mcap", "livesweep recover flight.mcap --out fixed.mcap --force"],
    "stream": ["livesweep stream flight.tlog --mavlink udpout:127.0.0.1:14550"],
    "batch": ["livesweep batch cases/ --out out/batch --workers 4", "livesweep batch cases/*.toml --out out/batch --no-plots"],
    "campaign": ["livesweep campaign add flights.db logs/*.bin logs/*.tlog",
                 "livesweep campaign list flights.db --axis 7 --verdict GO",
                 "livesweep campaign identify flights.db --map ardupilot-sysid-dataflash --input roll --out roll"],
    "demo": ["livesweep demo", "livesweep demo --out /tmp/demo --speed 20 --view"],
}


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the examples' line breaks and shows each option's default unless its help says it."""

    def _get_help_string(self, action):
        text = action.help or ""
        d = action.default
        if (not action.option_strings or "default" in text.lower() or d is None or isinstance(d, (bool, list))
                or d is argparse.SUPPRESS):
            return text
        return text + " (default: %(default)s)"
