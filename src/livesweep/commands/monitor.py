"""``livesweep monitor`` (:func:`livesweep.monitor` on live links) and ``livesweep replay``
(:func:`livesweep.replay` over a recording): the options turned into the library's arguments,
and the summary printed."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from livesweep.commands.common import check_out_path
from livesweep.commands.monitor_summary import print_monitor_summary
from livesweep.errors import ConfigError

__all__ = ["cmd_monitor", "cmd_replay", "monitor_settings", "setting_options", "rerun_options", "OPTION_NAMES"]

#: How messages name the monitor settings the command line sets: by the options that set them.
OPTION_NAMES = {"window_s": "--window", "update_period_s": "--update-period", "required_pairs": "--require",
                "saturation_limits": "--saturation"}


def setting_options(args) -> dict:
    """What --window, --update-period, --sysid, --require and --saturation set, as keywords of
    :func:`livesweep.monitor.session.with_options` (None: the map's or the recording's own)."""
    return {"window_s": args.window, "update_period_s": args.update_period, "system": getattr(args, "sysid", None),
            "required_pairs": args.require, "saturation_limits": args.saturation, "names": OPTION_NAMES}


def monitor_settings(args):
    """Channel map, spectral and test-point settings from --map (a preset or a map file) or --case
    (default: the packaged XV-15 map) with the command line's options."""
    from livesweep.monitor.session import map_settings

    return map_settings(args.case, getattr(args, "map", None), **setting_options(args))


def rerun_options(args) -> dict | None:
    """The Rerun view --rerun-save, --rerun-spawn, --rerun-serve and --rerun-bind ask for, as the
    view's keywords (None: no view)."""
    if not (args.rerun_save or args.rerun_spawn or args.rerun_serve):
        return None
    return {"save_path": args.rerun_save, "spawn": args.rerun_spawn, "serve": args.rerun_serve,
            "bind_host": args.rerun_bind}


def _read_signing_key(path: str | None) -> bytes | None:
    """The 32-byte MAVLink signing key in ``path`` (one line naming the file when it cannot be used)."""
    if not path:
        return None
    try:
        with open(path, "rb") as f:
            key = f.read(33)               # a key is 32 bytes: more says it is the wrong file
    except OSError as e:
        raise ConfigError(f"--signing-key-file {path!r}: cannot be read ({e.strerror or e})") from None
    if len(key) != 32:
        raise ConfigError(f"--signing-key-file {path!r}: holds {'more than 32' if len(key) > 32 else len(key)} bytes; "
                          "a MAVLink 2 signing key is 32 bytes "
                          "(e.g. the SHA-256 of a passphrase)")
    return key


def _stop_on_signals(live) -> None:
    """SIGTERM (systemd, docker stop, timeout), SIGHUP (a closed terminal) and SIGINT (Ctrl-C) finish
    the recording like the end of --duration. Further signals do not interrupt the finishing (that
    could leave the file without its summary); SIGKILL still ends the process at once, losing at
    most the last second."""
    import signal

    def handler(signum, frame):
        name = signal.Signals(signum).name
        if live.stop_requested:
            print(f"monitor: {name}: still finishing the recording (a few seconds at most)", file=sys.stderr,
                  flush=True)
            return
        print(f"monitor: {name}: finishing the recording", file=sys.stderr, flush=True)
        live.request_stop()

    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        signal.signal(sig, handler)


def cmd_monitor(args) -> int:
    """Live monitor: MAVLink and/or Zenoh in, estimates to Rerun/Zenoh, everything to MCAP."""
    from livesweep.monitor.session import monitor
    from livesweep.telemetry.mavlink_in import parse_source_url

    if not args.mavlink and not args.zenoh:
        raise ConfigError("give --mavlink URL (e.g. udpin:127.0.0.1:14550) and/or --zenoh KEYEXPR")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ConfigError(f"--duration must be > 0 seconds, got {args.duration!r}")
    settings = monitor_settings(args)
    if args.record:
        check_out_path(args.record)
        if Path(args.record).exists() and not args.force:
            raise ConfigError(f"--record {args.record!r} exists: a recording is never overwritten; choose another "
                              "name or pass --force")
    key = _read_signing_key(args.signing_key_file)
    for url in args.mavlink or []:
        parse_source_url(url)                  # a bad url named as --mavlink gives it, before anything opens
    live = monitor([*(args.mavlink or []), *([f"zenoh:{args.zenoh}"] if args.zenoh else [])], settings,
                   record=args.record, overwrite=args.force, rerun=rerun_options(args), signing_key=key,
                   zenoh_config=args.zenoh_config, zenoh_listen=args.zenoh_listen,
                   publish=bool(args.zenoh and args.zenoh_publish), duration_s=args.duration,
                   status=sys.stderr if args.status or (args.status is None and sys.stderr.isatty()) else None,
                   markers=bool(args.markers or (args.markers is None and sys.stdin.isatty())),
                   metadata={"test_point": {"source": "livesweep monitor"}})
    with live:                                  # stopped and its recording finished whatever happens here
        _stop_on_signals(live)
        where = [f"mavlink {getattr(s, 'description', s.url)}" for s in live.sources if hasattr(s, "url")]
        where += [f"zenoh {args.zenoh}"] if args.zenoh else []
        print(f"monitor: listening on {', '.join(where)}; Ctrl-C to stop", flush=True)
        if any(type(src).__name__ == "MarkerSource" for src in live.sources):
            from livesweep.monitor.markers import HELP

            print(f"monitor: {HELP}", flush=True)
        summary = live.wait()
    print_monitor_summary(summary)
    if args.record:
        print(f"wrote {args.record} (Foxglove: open it and import the layout {live.layout})")
    return 0


def _recorded_settings(log: str):
    """The monitor settings a recording was made with, or None (:func:`livesweep.monitor.session.recorded_settings`)."""
    from livesweep.monitor.session import recorded_settings

    return recorded_settings(log)


def cmd_replay(args) -> int:
    """Run the monitor over a recorded MCAP log (:func:`livesweep.replay`), with the settings it was
    recorded with unless --case or --map says otherwise; the command line's options apply to
    either."""
    from livesweep.monitor.session import recorded_settings, replay, with_options

    if not Path(args.log).is_file():
        raise ConfigError(f"log {args.log!r} does not exist")
    settings = None
    if not args.case and not getattr(args, "map", None):
        settings = recorded_settings(args.log)
        if settings is not None:
            print(f"replay: the settings recorded in {args.log} (give --case or --map to use others)")
            settings = with_options(settings, f"{args.log}: livesweep_settings.json", **setting_options(args))
    if settings is None:
        settings = monitor_settings(args)
    result = replay(args.log, settings=settings, rerun=rerun_options(args), speed=args.speed or 0.0)
    print_monitor_summary(result.summary)
    return 0
