"""``livesweep sim`` (a simulated test point to MCAP and/or live MAVLink) and ``livesweep stream``
(a recorded log sent over MAVLink, paced by its own time)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from livesweep.commands.common import check_out_path
from livesweep.errors import ConfigError

__all__ = ["cmd_sim", "cmd_stream", "default_axis"]


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


def _print_log_summary(path: Path, out=None) -> None:
    from livesweep.telemetry.mcap_log import read_summary

    out = sys.stdout if out is None else out
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
    out = check_out_path(args.out) if args.out else None
    if out is not None:
        from livesweep.locks import check_file_free

        check_file_free(out, overwrite=args.force)
    sender = None
    if args.mavlink:
        from livesweep.telemetry.mavlink_out import MavlinkSender

        sender = MavlinkSender(args.mavlink)
    result = simulate(_build_scenario(args))
    if out is not None:
        from livesweep.telemetry.sim_telemetry import write_sim_log

        info = write_sim_log(result, out, overwrite=args.force)
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


def cmd_stream(args) -> int:
    """Send a recorded log over MAVLink, paced by its own time, and print what was sent."""
    from livesweep.telemetry.stream_log import stream_log

    s = stream_log(args.log, args.mavlink, speed=args.speed, start_s=args.start_s, end_s=args.end_s,
                   rate_hz=args.rate_hz, sysid=args.sysid, on_start=lambda line: print(f"stream: {line}", flush=True))
    kind = {"tlog": "MAVLink tlog, frames as recorded", "dataflash": "ArduPilot DataFlash, as ArduCopter's telemetry"}
    clock = "UNIX time" if s.format == "tlog" else "TimeUS"
    print(f"  {kind[s.format]}: {s.log_duration_s:.3f} s of the log, {s.start_s:.3f} .. {s.end_s:.3f} s after its first "
          f"time stamp ({clock} {s.log_first_s:.6f} s)")
    print(f"  sent {s.n_sent} messages in {s.wall_duration_s:.3f} s: {s.achieved_speed:.2f}x real time, "
          f"{s.message_rate_hz:.0f} msg/s" + (f" (at most {s.rate_hz:g} Hz per message)" if s.rate_hz else ""))
    print(f"  {'message':24s} {'sent':>8s} {'Hz':>8s}  (its rate over its own span of log time)")
    for name, n in sorted(s.sent.items()):
        print(f"  {name:24s} {n:8d} {s.rates_hz.get(name, float('nan')):8.2f}")
    if s.send_errors:
        print(f"  warning: {s.send_errors} messages could not be sent", file=sys.stderr)
    if s.undecodable:
        print(f"  note: {s.undecodable} recorded frames do not decode (bad CRC or payload); sent as recorded")
    if s.stepped_back:
        print(f"  note: {s.stepped_back} records stepped back in time; sent in log order at the time of the one before")
    return 0


def default_axis(model: str) -> str:
    """The first input of ``model`` (``da`` for the XV-15; an unknown model is reported later)."""
    from livesweep.sim.models import MODELS

    return MODELS[model]().inputs[0] if model in MODELS else "da"

