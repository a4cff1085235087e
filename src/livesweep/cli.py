"""The ``livesweep`` command.

Verbs so far: ``sim`` (simulate a test point to MCAP and/or live MAVLink), ``identify`` (frequency
responses from a case file) and ``demo`` (the one command a newcomer runs first). Bad input prints one line ``livesweep: error: ...`` and exits 2.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from pathlib import Path

from livesweep import __version__
from livesweep.errors import ConfigError, LivesweepError

EXIT_USAGE = 2


def _check_out_path(path: str) -> Path:
    """Fail before any work when the output cannot be written."""
    p = Path(path)
    if p.exists() and p.is_dir():
        raise ConfigError(f"--out {path!r} is a directory; give a file name ending in .mcap")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ConfigError(f"--out {path!r}: directory {str(parent)!r} does not exist")
    if not os.access(parent, os.W_OK):
        raise ConfigError(f"--out {path!r}: directory {str(parent)!r} is not writable")
    return p


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    return v


def _build_scenario(args):
    from livesweep.sim.effects import parse_effect
    from livesweep.sim.scenario import sweep_scenario, verification_scenario

    effects = tuple(parse_effect(s) for s in args.effect)
    if args.manoeuvre == "sweep":
        return sweep_scenario(
            args.model, axes=tuple(args.axis), repeats=args.repeat,
            omega_min_rad_s=args.omega_min, omega_max_rad_s=args.omega_max, duration_s=args.duration,
            amplitudes={a: args.amplitude for a in args.axis}, off_axis_rms=args.off_axis_rms,
            effects=effects, noise=not args.no_noise, turbulence=not args.no_turbulence, seed=args.seed,
        )
    if not (math.isfinite(args.amplitude) and args.amplitude > 0):
        raise ConfigError(f"--amplitude must be > 0, got {args.amplitude!r}")
    return verification_scenario(
        args.model, manoeuvres=tuple((a, args.manoeuvre, args.amplitude, args.pulse) for a in args.axis),
        effects=effects, noise=not args.no_noise, turbulence=not args.no_turbulence, seed=args.seed,
    )


def _print_log_summary(path: Path, out=sys.stdout) -> None:
    from livesweep.telemetry.mcap_log import read_summary

    s = read_summary(path)
    size = path.stat().st_size
    print(f"wrote {path} ({size / 1e6:.2f} MB, {s.duration_s:.1f} s of flight)", file=out)
    print(f"  {'channel':34s} {'messages':>9s} {'rate Hz':>8s}", file=out)
    for topic, n in sorted(s.message_counts.items()):
        rate = n / s.duration_s if s.duration_s > 0 else float("nan")
        print(f"  {topic:34s} {n:9d} {rate:8.1f}", file=out)
    tp = s.metadata.get("test_point", {})
    if tp:
        print(f"  test point: {tp.get('aircraft', '')} {tp.get('model', '')}: {tp.get('manoeuvre', '')}", file=out)


def cmd_sim(args) -> int:
    """Simulate a test point; write MCAP and/or stream MAVLink 2."""
    from livesweep.sim.scenario import simulate

    if not args.out and not args.mavlink:
        raise ConfigError("give --out FILE.mcap and/or --mavlink URL (e.g. udpout:127.0.0.1:14550)")
    if not (math.isfinite(args.speed) and args.speed > 0):
        raise ConfigError(f"--speed must be > 0 (1 = real time), got {args.speed!r}")
    out = _check_out_path(args.out) if args.out else None
    sender = None
    if args.mavlink:
        from livesweep.telemetry.mavlink_out import MavlinkSender

        sender = MavlinkSender(args.mavlink)
    result = simulate(_build_scenario(args))
    if out is not None:
        from livesweep.telemetry.sim_telemetry import write_sim_log

        info = write_sim_log(result, out)
        _print_log_summary(out)
        clipped = {k: v for k, v in info["stats"]["pwm_clipped"].items() if v}
        if clipped:
            print(f"  warning: servo PWM clipped to 1000..2000 us: {clipped}", file=sys.stderr)
    if sender is not None:
        from livesweep.telemetry.mavlink_out import stream_records
        from livesweep.telemetry.sim_telemetry import mavlink_timeline

        records, _ = mavlink_timeline(result)
        records.sort(key=lambda r: (r.vehicle_time_ns, r.msgname))
        timed = ((r.vehicle_time_ns * 1e-9, r.msgname, r.record) for r in records if r.msgname != "HEARTBEAT")
        try:
            stats = stream_records(sender, timed, speed=args.speed)
        finally:
            sender.close()
        total = sum(stats.get("counts", {}).values()) if isinstance(stats, dict) else 0
        print(f"sent {total} MAVLink 2 messages to {args.mavlink} at {args.speed:g}x real time", file=sys.stdout)
    return 0


DEMO_CASE = """# Written by `livesweep demo`: the frequency-response case for the demo log (DESIGN.md §4.2).
[case]
name = "xv15-cruise-aileron-demo"
aircraft = "XV-15"
condition = "cruise, 170 kn TAS (simulated)"

[[identify]]
log = "xv15_cruise_sweeps_da.mcap"
label = "aileron sweeps x2"

{signals}
[spectral]
inputs = ["da"]
outputs = ["p", "r", "ay", "beta"]
band_rad_s = [0.3, 20.0]
sample_rate_hz = 50.0
"""


def cmd_demo(args) -> int:
    """Simulate the XV-15 cruise aileron sweeps, write them as MCAP, and identify their frequency responses."""
    from livesweep.sim.samples import SAMPLE_LOGS, sample_scenario
    from livesweep.sim.scenario import simulate
    from livesweep.telemetry.sim_telemetry import write_sim_log

    out_dir = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="livesweep-demo-"))
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"--out {str(out_dir)!r} exists and is not a directory")
    out_dir.mkdir(parents=True, exist_ok=True)
    if not os.access(out_dir, os.W_OK):
        raise ConfigError(f"--out {str(out_dir)!r} is not writable")
    name = "xv15_cruise_sweeps_da.mcap"
    print(f"livesweep {__version__} demo: {SAMPLE_LOGS[name][0]}")
    result = simulate(sample_scenario(name))
    path = out_dir / name
    write_sim_log(result, path, notes="livesweep demo")
    _print_log_summary(path)
    print("  manoeuvres (vehicle time since boot):")
    for s in result.segments:
        if s.kind != "trim":
            print(f"    {s.label:16s} {s.start_s:8.1f} .. {s.end_s:8.1f} s")
    print()
    channels = (Path(__file__).resolve().parent / "data" / "xv15_channels.toml").read_text()
    signals = channels[channels.index("[signals.da]"):channels.index("[spectral]")]
    case = out_dir / "demo_case.toml"
    case.write_text(DEMO_CASE.format(signals=signals))
    return cmd_identify(argparse.Namespace(case=str(case), out=str(out_dir / "report"), stage="frequency-response"))


def cmd_identify(args) -> int:
    """Identify from a case file: for now the frequency-response stage."""
    from livesweep.config import load_case
    from livesweep.pipeline.frequency_response import run_frequency_response_stage
    from livesweep.report.writer import prepare_out_dir, write_frequency_report

    prepare_out_dir(args.out)
    case = load_case(args.case)
    stage = run_frequency_response_stage(case)
    path = write_frequency_report(stage, args.out)
    best = stage.analysis.best
    dq = stage.data_quality
    print(f"{case.name}: {len(best.outputs)} outputs x {len(best.inputs)} inputs, "
          f"{'MISO-conditioned' if best.conditioned else 'SISO'} composite of windows {best.settings['windows_s']} s "
          f"over {dq['duration_s']:.0f} s at {dq['sample_rate_hz']:g} Hz")
    print(f"  {'pair':12s} {'adequate':>9s}  widest band gamma^2>=0.6, eps<=0.2 [rad/s]")
    for a in stage.adequacy:
        band = "-" if a.widest_band_rad_s is None else "%.2f .. %.2f" % a.widest_band_rad_s
        print(f"  {a.output + '/' + a.input:12s} {100 * a.fraction:8.0f}%  {band}")
    for c in dq["kinematic_checks"]:
        if "error" in c:
            print(f"  kinematic check {c['measured']} vs {c['reconstructed_from']}: not run ({c['error']})")
        else:
            print(f"  kinematic check {c['name']}: scale {c['scale_factor_error']:+.3f}, skew {1000 * c['skew_s']:+.0f} ms, "
                  f"rate bias {c['rate_bias']:+.3f} {c['rate_bias_units']}: {'pass' if c['passed'] else 'FAIL'}")
    repaired = {n: r for n, r in dq["repairs"].items() if any(r.values())}
    wild = {n: w["replaced"] for n, w in dq["wild_points"].items() if w["replaced"]}
    if repaired or wild:
        print(f"  repairs: {repaired or 'none'}; wild points replaced: {wild or 'none'}")
    for note in dq["notes"]:
        print(f"  note: {note}")
    print(f"wrote {path} and {path.parent / 'report.html'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="livesweep", description="Frequency-sweep monitoring and system identification.")
    p.add_argument("--version", action="version", version=f"livesweep {__version__}")
    sub = p.add_subparsers(dest="verb", required=True)

    s = sub.add_parser("sim", help="simulate a test point (sweeps or verification manoeuvres) to MCAP or live MAVLink")
    s.add_argument("--model", default="xv15-cruise", help="vehicle model: xv15-cruise or xv15-hover")
    s.add_argument("--manoeuvre", default="sweep", choices=["sweep", "doublet", "3211", "step"])
    s.add_argument("--axis", action="append", help="input to excite (da, dr); repeat for several; default da")
    s.add_argument("--repeat", type=int, default=2, help="sweeps per axis")
    s.add_argument("--omega-min", type=_positive_float, default=0.3, help="sweep start frequency [rad/s]")
    s.add_argument("--omega-max", type=_positive_float, default=20.0, help="sweep end frequency [rad/s]")
    s.add_argument("--duration", type=_positive_float, default=100.0, help="sweep length without trims [s]")
    s.add_argument("--amplitude", type=_positive_float, default=2.0, help="sweep or pulse amplitude [deg]")
    s.add_argument("--pulse", type=_positive_float, default=1.0, help="doublet/3211 unit pulse or step hold [s]")
    s.add_argument("--off-axis-rms", type=_positive_float, default=0.0, help="uncorrelated pilot noise on other inputs [deg rms]")
    s.add_argument("--effect", action="append", default=[], metavar="KIND:key=value,...",
                   help="inject an effect, e.g. sensor_skew:output=p,delay_s=0.05 (repeatable)")
    s.add_argument("--no-noise", action="store_true", help="no sensor noise")
    s.add_argument("--no-turbulence", action="store_true", help="calm air")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--out", help="MCAP file to write")
    s.add_argument("--mavlink", help="stream MAVLink 2 to a pymavlink URL, e.g. udpout:127.0.0.1:14550")
    s.add_argument("--speed", type=_positive_float, default=1.0, help="stream pace: 1 = real time, 10 = ten times faster")
    s.set_defaults(func=cmd_sim)

    i = sub.add_parser("identify", help="identify from a case file (DESIGN.md §4.2) and write report.json, report.html, plots")
    i.add_argument("case", help="case file (TOML)")
    i.add_argument("--out", required=True, help="folder for the report")
    i.add_argument("--stage", default="frequency-response", choices=["frequency-response"],
                   help="last stage to run (more stages come with the parametric issues)")
    i.set_defaults(func=cmd_identify)

    d = sub.add_parser("demo", help="simulate the XV-15 cruise sweeps to MCAP and identify their frequency responses")
    d.add_argument("--out", help="folder for the log (default: a new temporary folder)")
    d.set_defaults(func=cmd_demo)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "axis", None) is None and args.verb == "sim":
        args.axis = ["da"]
    try:
        return args.func(args)
    except LivesweepError as exc:
        print(f"livesweep: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("livesweep: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
