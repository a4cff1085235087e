"""The ``livesweep`` command.

Verbs: ``sim`` (simulate a test point to MCAP and/or live MAVLink), ``monitor`` (live sweep
monitor), ``replay`` (the monitor over a recording), ``identify`` (frequency responses from a case
file) and ``demo`` (the one command a newcomer runs first). Bad input prints one line ``livesweep: error: ...`` and exits 2.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from livesweep import __version__
from livesweep.errors import ConfigError, LivesweepError
from livesweep.stages import STAGES  # the stage names only: the stages load when a command runs
from livesweep.spectral import DEFAULT_WINDOW_S

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


DEMO_CASE = """# Written by `livesweep demo`: the frequency-response case for the demo log (every key: docs/case-file.md).
[case]
name = "xv15-cruise-aileron-demo"
aircraft = "XV-15"
condition = "cruise, 170 kn TAS (simulated)"

[[identify]]
log = "live.mcap"
label = "aileron sweeps x2, recorded live"

{signals}
[spectral]
inputs = ["da"]
outputs = ["p", "r", "ay", "beta"]
band_rad_s = [0.3, 20.0]
sample_rate_hz = 50.0

[transfer_functions.p_da]          # roll-rate structure of Tischler & Remple's Eq. 2.7 (docs/method.md §11.1)
output = "p"
input = "da"
numerator = "s [zeta_phi, w_phi]"
denominator = "(1/Ts) (1/Tr) [zeta_dr, w_dr]"
delay = true
"""


def cmd_demo(args) -> int:
    """Fly the XV-15 cruise aileron sweeps live: simulator -> MAVLink 2 over UDP loopback -> monitor
    (MCAP recording, Rerun, verdict) -> frequency responses from the recording."""
    import subprocess
    import time

    from livesweep.config import load_channel_map
    from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
    from livesweep.monitor.rerun_view import RerunView
    from livesweep.sim.samples import SAMPLE_LOGS
    from livesweep.telemetry.capture import LiveCapture

    out_dir = Path(args.out) if args.out else Path.cwd() / "livesweep-demo"
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"--out {str(out_dir)!r} exists and is not a directory")
    out_dir.mkdir(parents=True, exist_ok=True)
    if not os.access(out_dir, os.W_OK):
        raise ConfigError(f"--out {str(out_dir)!r} is not writable")
    if not (math.isfinite(args.speed) and args.speed > 0):
        raise ConfigError(f"--speed must be > 0, got {args.speed!r}")
    name = "xv15_cruise_sweeps_da.mcap"
    print(f"livesweep {__version__} demo: {SAMPLE_LOGS[name][0]}")
    print(f"  writing to {out_dir}")
    channels = Path(__file__).resolve().parent / "data" / "xv15_channels.toml"
    signals, _ = load_channel_map(channels)
    settings = MonitorSettings(signals=signals, inputs=("da",), outputs=("p", "r", "ay", "beta"), band_rad_s=(0.3, 20.0),
                               sample_rate_hz=50.0, window_s=240.0, required_pairs=(("p", "da"),))
    log = out_dir / "live.mcap"
    rrd = out_dir / "live.rrd"
    # the link and the recording in a process of their own, as the monitor runs them
    capture = LiveCapture(["udpin:127.0.0.1:0"], record_path=log, settings=settings.to_dict(), overwrite=True,
                          metadata={"test_point": {"aircraft": "XV-15", "manoeuvre": "aileron sweeps x2 (simulated)",
                                                   "source": "livesweep demo"}})       # the demo rewrites its own folder
    port = int(capture.urls[0].rsplit(":", 1)[1])
    source, recorder = capture.source, capture.recorder
    from livesweep.monitor.foxglove import write_layout

    try:
        layout = write_layout(log, settings.signals, settings.inputs, settings.outputs)
        view = RerunView(list(settings.inputs), list(settings.outputs), recording_id="demo",
                         save_path=None if args.view else rrd, spawn=args.view)
    except BaseException:
        capture.close()
        raise
    print(f"  simulator -> MAVLink 2 over udp 127.0.0.1:{port} at {args.speed:g}x real time -> monitor")
    sim = subprocess.Popen([sys.executable, "-m", "livesweep", "sim", "--axis", "da", "--repeat", "2",
                            "--omega-min", "0.3", "--omega-max", "20", "--duration", "100", "--amplitude", "3",
                            "--off-axis-rms", "0.2", "--seed", "11", "--speed", str(args.speed),
                            "--mavlink", f"udpout:127.0.0.1:{port}"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    finished = []

    def stop() -> bool:
        if sim.poll() is None:
            return False
        finished.append(time.monotonic())
        return time.monotonic() - finished[0] > 1.0          # drain what is still in flight

    pipe = MonitorPipeline(settings, [source], recorder=recorder, view=view, keep_estimates=False)
    try:
        summary = pipe.run(stop=stop)
    finally:
        capture.close()
        if sim.poll() is None:
            sim.kill()
    if sim.returncode not in (0, None):
        raise LivesweepError(f"the simulator failed: {sim.stderr.read().decode().strip()[-300:]}")
    _print_monitor_summary(summary)
    print(f"  recording: {log} (Foxglove: open it and import the layout {layout.name})"
          + ("" if args.view else f"\n  rerun: {rrd} (open with: {_command('rerun')} {rrd})"))
    print()
    signals_text = channels.read_text()
    case = out_dir / "demo_case.toml"
    case.write_text(DEMO_CASE.format(signals=signals_text[signals_text.index("[signals.da]"):signals_text.index("[spectral]")]))
    code = cmd_identify(argparse.Namespace(case=str(case), out=str(out_dir / "report"), stage="residual-loop"))
    report = out_dir / "report" / "report.html"
    ls = _command("livesweep")
    print(f"""
next:
  1. open the report in a browser: {report.resolve().as_uri()}
  2. look at the live session again: {_command('rerun')} {rrd}
     (or run the monitor over the recording: {ls} replay {log})
  3. start your own case: {case} is the case file this demo identified; for your own log,
     {ls} inspect LOG   lists what it holds and the channel maps that fit it, and
     {ls} new-case LOG --map NAME --out case.toml   writes a case for it""")
    return code


def _command(name: str) -> str:
    """How to run the console script ``name`` (``rerun``, ``livesweep``) from this environment: the
    bare name when it is on PATH, else the one installed next to this Python (a virtual
    environment that is not activated), else ``python -m``."""
    import shutil

    if shutil.which(name):
        return name
    beside = Path(sys.executable).parent / name
    return str(beside) if beside.exists() else f"{sys.executable} -m {name}"


def cmd_inspect(args) -> int:
    """``livesweep inspect LOG``: topics, fields, rates, span, test points, fitting channel maps."""
    from livesweep.inspection import format_inspection, inspect_log, stderr_progress

    print(format_inspection(inspect_log(args.log, columns=args.columns, progress=stderr_progress(args.log))))
    return 0


def cmd_new_case(args) -> int:
    """``livesweep new-case LOG --map NAME``: an annotated case file."""
    from livesweep.new_case import write_new_case

    r = write_new_case(args.log, args.map, args.out, force=args.force)
    if r["converted"]:
        print(f"new-case: converted {args.log} to {r['log']}")
    print(f"new-case: wrote {r['case']} (log {r['log']}, map {args.map}); next: edit [case] and [spectral], then\n"
          f"  livesweep identify {r['case']} --out report")
    return 0


#: Exit status of ``livesweep recover`` when messages (or other records) were lost or are kept
#: unverified: the finished copy is still written.
EXIT_DATA_LOST = 1


def cmd_recover(args) -> int:
    """``livesweep recover LOG``: a finished copy of an unfinished or damaged recording, saying what
    was lost or kept unverified; exit status 0 only when nothing was."""
    from livesweep.telemetry.mcap_recover import RECOVER_METADATA_NAME, recover

    most = 10                                # offsets, ranges and lines printed before "... and N more"

    def listed(items, fmt=str) -> str:
        return ", ".join(fmt(x) for x in items[:most]) + (f" and {len(items) - most} more" if len(items) > most else "")

    def count(n: int, what: str) -> str:
        return f"{n} {what}" + ("" if n == 1 else "s")

    src = Path(args.log)
    out = Path(args.out) if args.out else src.with_name(src.stem + ".recovered.mcap")
    from livesweep.locks import check_file_free

    check_file_free(out, overwrite=args.force)
    r = recover(src, out, overwrite=args.force)
    state = ("was finished" if r.complete_source
             else "was unfinished (no readable footer: its writer stopped before closing it, or its end is damaged)")
    of = f" of the {r.messages_expected} it holds" if r.messages_expected is not None else ""
    print(f"recover: {src} {state}; {count(r.messages_written, 'message')}{of} written to {out}, a finished "
          "file any MCAP reader opens")
    if r.messages_lost is None:
        print("recover: LOST: an unknown number of messages (no readable statistics record or message index "
              "counts them)")
    elif r.messages_lost:
        print(f"recover: LOST: {count(r.messages_lost, 'message')}" + (f" of {r.messages_expected}" if of else ""))
    if r.damaged_chunks:
        print(f"recover:   skipped {count(len(r.damaged_chunks), 'chunk')} that did not decompress, at bytes "
              f"{listed(r.damaged_chunks)}")
    if r.skipped_bytes:
        total = sum(b - a for a, b in r.skipped_bytes)
        print(f"recover:   {total} bytes not read: {listed(r.skipped_bytes, lambda ab: f'{ab[0]}-{ab[1]}')}")
    if r.messages_unverified:
        where = (f"{count(len(r.unverified_chunks), 'chunk')} failing the CRC check (at bytes "
                 f"{listed(r.unverified_chunks)})" if r.unverified_chunks
                 else "outside chunks in a data section that fails its CRC check")
        print(f"recover: UNVERIFIED: {count(r.messages_unverified, 'message')} kept from {where}: their contents "
              f"may differ from what was recorded; {out} records this in its {RECOVER_METADATA_NAME!r} metadata")
    for line in r.unreadable[:most]:
        print(f"recover:   {line}")
    if len(r.unreadable) > most:
        print(f"recover:   ... and {len(r.unreadable) - most} more")
    for line in r.notes[:most]:
        print(f"recover: note: {line}")
    if len(r.notes) > most:
        print(f"recover: note: ... and {len(r.notes) - most} more")
    if not r.clean:
        return EXIT_DATA_LOST
    print("recover: nothing that was in the file was lost, and every message is verified")
    return 0


def cmd_identify(args) -> int:
    """Identify from a case file: frequency responses, then (as the case defines them) transfer
    functions, state-space derivatives and time-domain verification."""
    from livesweep.config import load_case
    from livesweep.locks import folder_lock
    from livesweep.report.writer import prepare_out_dir

    with folder_lock(prepare_out_dir(args.out)):
        return _identify(args, load_case(args.case))


def _identify(args, case) -> int:
    """Run :func:`livesweep.identify` on the case (the output folder is prepared and locked), write
    its report and print its summary."""
    import time

    from livesweep.stages.identify import identify
    from livesweep.report.writer import write_report

    t0 = time.monotonic()

    def progress(msg):
        print(f"[{time.monotonic() - t0:6.1f} s] {msg}", flush=True)

    ident = identify(case, until=args.stage, progress=progress)
    progress("writing the report" + ("" if getattr(args, "plots", True) else " (no plots)"))
    path = write_report(ident, args.out, plots=getattr(args, "plots", True))
    from livesweep.report.console import summary_lines

    print("\n".join(summary_lines(ident)))
    print(f"wrote {path} and {path.parent / 'report.html'}")
    return 0


#: The monitor settings the command line sets, by the options that set them (for messages).
_MONITOR_OPTIONS = {"window_s": "--window", "update_period_s": "--update-period"}


def _monitor_settings(args):
    """Channel map, spectral and test-point settings from --map (a preset or a map file) or --case
    (default: the packaged XV-15 map) plus CLI overrides."""
    from livesweep.config import read_channel_map
    from livesweep.maps import load_map
    from livesweep.monitor.pipeline import MonitorSettings

    map_arg = getattr(args, "map", None)
    if map_arg and args.case:
        raise ConfigError(f"give --case or --map, not both (--case {args.case!r}, --map {map_arg!r})")
    if map_arg:
        chosen = load_map(map_arg)
    else:
        chosen = read_channel_map(args.case or Path(__file__).resolve().parent / "data" / "xv15_channels.toml",
                                  one_clock=False)
    signals, spectral, path = chosen.signals, chosen.spectral, chosen.path
    if spectral is None:
        raise ConfigError(f"{path}: the monitor needs a [spectral] table (inputs, outputs, band_rad_s, sample_rate_hz)")
    return MonitorSettings(
        signals=signals, inputs=tuple(spectral.inputs), outputs=tuple(spectral.outputs),
        band_rad_s=tuple(spectral.band_rad_s), sample_rate_hz=spectral.sample_rate_hz,
        window_s=DEFAULT_WINDOW_S if args.window is None else args.window,
        update_period_s=0.2 if args.update_period is None else args.update_period,
        required_pairs=_required_pairs(args.require, spectral),
        saturation_limits=_saturation_limits(args.saturation, spectral),
        references=tuple(spectral.references) if spectral.references else None,
        test_points=chosen.test_points, map_name=chosen.name, vehicle=dict(chosen.vehicle) or None,
        system=getattr(args, "sysid", None) or chosen.system,
    ).check_limits(str(path), names={**_MONITOR_OPTIONS, "outputs": f"{path}: spectral.outputs"})


def _saturation_limits(items, spectral):
    if not items:
        return None
    limits = {}
    for item in items:
        name, sep, rng = item.partition("=")
        lo, sep2, hi = rng.partition(":")
        try:
            lo_f, hi_f = float(lo), float(hi)
        except ValueError:
            lo_f = hi_f = math.nan
        if not sep or not sep2 or name not in spectral.inputs or not (lo_f < hi_f):
            raise ConfigError(f"--saturation {item!r}: give INPUT=LOW:HIGH in input units with an input of "
                              f"{list(spectral.inputs)}, e.g. da=-20:20")
        limits[name] = (lo_f, hi_f)
    return limits


def _pair(item: str, inputs, outputs) -> tuple[str, str]:
    """``OUT/IN`` of ``--require``; one line naming the item when it is not a pair of the map."""
    out, sep, inp = item.partition("/")
    if not sep or out not in outputs or inp not in inputs:
        raise ConfigError(f"--require {item!r}: give OUTPUT/INPUT with an output of {list(outputs)} "
                          f"and an input of {list(inputs)}")
    return out, inp


def _required_pairs(items, spectral):
    if not items:
        return None
    return tuple(_pair(item, spectral.inputs, spectral.outputs) for item in items)


def _view(args, settings, name):
    if not (args.rerun_save or args.rerun_spawn or args.rerun_serve):
        return None
    from livesweep.monitor.rerun_view import RerunView

    return RerunView(list(settings.inputs), list(settings.outputs), recording_id=name,
                     save_path=args.rerun_save, spawn=args.rerun_spawn, serve=args.rerun_serve,
                     bind_host=args.rerun_bind)


#: How the monitor's summary names the aligner's counts of what it repaired or left out: (one, many).
_ALIGNER_WORDS = {
    "missing_field": ("frame lacking a mapped field", "frames lacking a mapped field"),
    "not_a_number": ("value that was not a number", "values that were not numbers"),
    "late_dropped": ("late sample dropped", "late samples dropped"),
    "reordered": ("sample put back in time order", "samples put back in time order"),
    "wraps": ("clock wrap unwrapped", "clock wraps unwrapped"),
    "resets": ("clock reset", "clock resets"),
    "clock_rejected": ("sample with an implausible stamp dropped", "samples with an implausible stamp dropped"),
    "other_system": ("frame of another system left out", "frames of another system left out"),
    "samples_skipped": ("grid sample skipped at a clock jump", "grid samples skipped at a clock jump"),
    "samples_invalid": ("grid sample left invalid in a gap (not interpolated)",
                        "grid samples left invalid in gaps (not interpolated)"),
}


def _counts_text(counts: dict, words: dict | None = None) -> str:
    """Counts for people: ``{"truncated_tail": 1, "bad_crc": 0}`` -> ``"1 truncated tail"``: zeros left
    out; a key's words from ``words`` (a string, or ``(one, many)``), else the key with spaces;
    "none" when nothing is left."""
    parts = []
    for k, v in counts.items():
        if v:
            w = (words or {}).get(k, str(k).replace("_", " "))
            parts.append(f"{v} {w if isinstance(w, str) else w[v != 1]}")
    return ", ".join(parts) or "none"


def _loss_text(src: dict) -> str:
    """What a source lost, each kind by its own name: the kernel's drops (counted by the kernel),
    MAVLink sequence gaps (an estimate), datagrams recorded but not decoded at the stop."""
    parts = []
    if src.get("kernel_drops"):
        parts.append(f"{src['kernel_drops']} dropped by the kernel (socket buffer full; counted by the kernel)")
    gaps = sum((src.get("seq_gaps") or {}).values())
    if gaps:
        parts.append(f"{gaps} missing by MAVLink's 8-bit sequence (an estimate: frames refused here and losses "
                     "before this link count too; runs of 256 are not seen)")
    if src.get("undecoded_at_stop"):
        parts.append(f"{src['undecoded_at_stop']} recorded as received but not decoded at the stop "
                     "(/link/mavlink holds them)")
    return "loss: " + "; ".join(parts) if parts else ""


def _print_monitor_summary(summary: dict, out=sys.stdout) -> None:
    from livesweep.monitor.pipeline import LINK_ANOMALIES

    anomaly_words = {key: words for where, key, words in LINK_ANOMALIES if where == "source"}
    anomaly_keys = set(anomaly_words)
    print(f"monitor: {summary['frames']} frames, {summary['estimates']} estimates over {summary['data_s'] or 0:.1f} s "
          f"of data in {summary['wall_s']:.1f} s", file=out)
    al = summary["aligner"]
    issues = {k: v for k, v in al.items() if k in ("missing_field", "not_a_number", "late_dropped", "reordered",
                                                   "wraps", "resets", "clock_rejected", "other_system",
                                                   "samples_skipped", "samples_invalid") and v}
    if issues:
        print(f"  repairs and gaps: {_counts_text(issues, _ALIGNER_WORDS)}", file=out)
    counters = summary.get("counters") or {}
    for src in counters.get("sources", []):
        received = src.get("received") or src.get("replayed") or {}
        systems = src.get("by_system") or {}
        bad = {k: v for k, v in src.items() if k in anomaly_keys and k != "kernel_drops" and v}
        by_sys = sorted(systems.items(), key=lambda kv: -kv[1])
        sys_text = ", ".join(f"{k}: {v}" for k, v in by_sys[:5]) + (f", ... ({len(by_sys)} systems)" if len(by_sys) > 5
                                                                     else "")
        rejected = f"; rejected or repaired: {_counts_text(bad, anomaly_words)}" if bad else "; nothing rejected"
        print(f"  {src['name']}: {sum(received.values())} frames" + (f" from systems {{{sys_text}}}"
              if systems else "") + rejected, file=out)
        loss = _loss_text(src)
        if loss:
            print(f"    {loss}", file=out)
    pipe = counters.get("pipeline") or {}
    if pipe.get("not_taken_at_stop"):
        print(f"  not recorded: {pipe['not_taken_at_stop']} frames a source still held when the stop's drain "
              "time was up", file=out)
    if pipe.get("analysis_shed"):
        print(f"  analysis skipped {pipe['analysis_shed']} frames to keep up (all recorded)", file=out)
    from livesweep.monitor.text import test_point_line

    tps = summary.get("test_points") or []
    print(f"  test points: {len(tps)}" + ("" if tps else " (no sweep, SystemID run or marker seen)"), file=out)
    for k, tp in enumerate(tps, 1):
        print(f"    {test_point_line(k, tp)}", file=out)
    if summary["verdict"]:
        print(f"  verdict: {summary['verdict']}", file=out)
    for line in summary.get("map_problems") or ():
        print(f"  map: {line}", file=out)
    if summary.get("recorded"):
        from livesweep.telemetry.recorder import RAW_TOPIC, RESULT_PREFIX

        rec = summary["recorded"]
        raw = rec.get(RAW_TOPIC, 0)
        results = sum(n for t, n in rec.items() if t.startswith(RESULT_PREFIX + "/"))
        print(f"  recorded {sum(rec.values())} messages: {sum(rec.values()) - raw - results} received"
              + (f", {raw} datagrams as received" if raw else "") + f", {results} live results", file=out)


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


def _stop_on_signals(pipe) -> None:
    """SIGTERM (systemd, docker stop, timeout), SIGHUP (a closed terminal) and SIGINT (Ctrl-C) finish
    the recording like the end of --duration. Further signals do not interrupt the finishing (that
    could leave the file without its summary); SIGKILL still ends the process at once, losing at
    most the last second."""
    import signal

    def handler(signum, frame):
        name = signal.Signals(signum).name
        if pipe.stop_requested:
            print(f"monitor: {name}: still finishing the recording (a few seconds at most)", file=sys.stderr,
                  flush=True)
            return
        print(f"monitor: {name}: finishing the recording", file=sys.stderr, flush=True)
        pipe.request_stop()

    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        signal.signal(sig, handler)


def cmd_monitor(args) -> int:
    """Live monitor: MAVLink and/or Zenoh in, estimates to Rerun/Zenoh, everything to MCAP."""
    from livesweep.monitor.pipeline import MonitorPipeline

    if not args.mavlink and not args.zenoh:
        raise ConfigError("give --mavlink URL (e.g. udpin:127.0.0.1:14550) and/or --zenoh KEYEXPR")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ConfigError(f"--duration must be > 0 seconds, got {args.duration!r}")
    settings = _monitor_settings(args)
    if args.record:
        _check_out_path(args.record)
        if Path(args.record).exists() and not args.force:
            raise ConfigError(f"--record {args.record!r} exists: a recording is never overwritten; choose another "
                              "name or pass --force")
    key = _read_signing_key(args.signing_key_file)
    from livesweep.telemetry.capture import LiveCapture
    from livesweep.telemetry.mavlink_in import MavlinkSource, parse_source_url

    udp = [u for u in args.mavlink or [] if parse_source_url(u)["kind"] == "udpin"]
    sources, publisher, view, capture = [], None, None, None
    try:                 # everything that can fail first: the recording (which --force truncates) last
        for url in args.mavlink or []:
            if url not in udp:
                sources.append(MavlinkSource(url, signing_key=key))
        if args.zenoh:
            from livesweep.telemetry.zenoh_io import ZenohPublisher, ZenohSource, zenoh_config

            cfg = zenoh_config(config_path=args.zenoh_config) if args.zenoh_config else None
            sources.append(ZenohSource(args.zenoh, config=cfg, listen_port=args.zenoh_listen))
            if args.zenoh_publish:
                publisher = ZenohPublisher(config=cfg, connect_port=args.zenoh_listen)
        view = _view(args, settings, "live")
        # the UDP links and the recording in a process of their own: a busy analysis cannot starve them
        capture = LiveCapture(udp, record_path=args.record, overwrite=args.force, settings=settings.to_dict(),
                              metadata={"test_point": {"source": "livesweep monitor"}}, signing_key=key) \
            if udp or args.record else None
        if capture is not None and udp:
            sources.insert(0, capture.source)
        recorder = capture.recorder if args.record else None
        if recorder is not None:
            from livesweep.monitor.foxglove import write_layout

            layout = write_layout(args.record, settings.signals, settings.inputs, settings.outputs)
    except BaseException:
        for part in (*sources, publisher, view, capture):
            if part is not None:
                part.close()
        raise
    if args.markers or (args.markers is None and sys.stdin.isatty()):
        from livesweep.monitor.markers import MarkerSource

        sources.append(MarkerSource())
    status = None
    if args.status or (args.status is None and sys.stderr.isatty()):
        from livesweep.monitor.status_line import StatusLine

        status = StatusLine(sys.stderr)
    pipe = MonitorPipeline(settings, sources, recorder=recorder, view=view, publisher=publisher, keep_estimates=False,
                           status_line=status)
    _stop_on_signals(pipe)
    where = [f"mavlink {getattr(s, 'description', s.url)}" for s in sources if hasattr(s, "url")]
    where += [f"zenoh {args.zenoh}"] if args.zenoh else []
    print(f"monitor: listening on {', '.join(where)}; Ctrl-C to stop", flush=True)
    if any(type(src).__name__ == "MarkerSource" for src in sources):
        from livesweep.monitor.markers import HELP

        print(f"monitor: {HELP}", flush=True)
    try:
        summary = pipe.run(duration_s=args.duration)
    finally:
        if capture is not None:
            capture.close()
    if status is not None:
        status.close()
    _print_monitor_summary(summary)
    if args.record:
        print(f"wrote {args.record} (Foxglove: open it and import the layout {layout})")
    return 0


def _recorded_settings(log: str):
    """The monitor settings a recording was made with, or None (:func:`livesweep.monitor.session.recorded_settings`)."""
    from livesweep.monitor.session import recorded_settings

    return recorded_settings(log)


def cmd_replay(args) -> int:
    """Run the monitor pipeline over a recorded MCAP log (:func:`livesweep.monitor.session.replay`),
    with the settings it was recorded with unless --case or --map says otherwise."""
    from dataclasses import replace

    from livesweep.monitor.session import recorded_settings, replay

    if not Path(args.log).is_file():
        raise ConfigError(f"log {args.log!r} does not exist")
    settings = None
    if not args.case and not getattr(args, "map", None):
        settings = recorded_settings(args.log)
        if settings is not None:
            print(f"replay: the settings recorded in {args.log} (give --case or --map to use others)")
            overrides = {k: v for k, v in (("window_s", args.window), ("update_period_s", args.update_period),
                                           ("system", args.sysid)) if v is not None}
            if args.require:
                overrides["required_pairs"] = tuple(_pair(item, settings.inputs, settings.outputs)
                                                    for item in args.require)
            settings = replace(settings, **overrides).check_limits(
                f"{args.log}: livesweep_settings.json", names={k: v for k, v in _MONITOR_OPTIONS.items() if k in overrides})
    if settings is None:
        settings = _monitor_settings(args)
    result = replay(args.log, settings=settings, rerun=_view(args, settings, "replay"), speed=args.speed or 0.0)
    _print_monitor_summary(result.summary)
    return 0


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

    i = sub.add_parser("identify", help="identify from a case file (docs/case-file.md) and write report.json, report.html, plots")
    i.add_argument("case", help="case file (TOML)")
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
                 "livesweep identify my_case.toml --out out/quick --stage frequency-response --no-plots"],
    "maps": ["livesweep maps"],
    "convert": ["livesweep convert 00000012.BIN --out flight.mcap",
                "livesweep convert sweep.npy --columns config/xplane_c172_columns.toml --out sweep.mcap"],
    "inspect": ["livesweep inspect flight.tlog", "livesweep inspect sweep.npy --columns columns.toml"],
    "new-case": ["livesweep new-case 00000012.BIN --map ardupilot-sysid-dataflash --out roll.toml"],
    "recover": ["livesweep recover flight.mcap", "livesweep recover flight.mcap --out fixed.mcap --force"],
    "stream": ["livesweep stream flight.tlog --mavlink udpout:127.0.0.1:14550"],
    "batch": ["livesweep batch cases/ --out out/batch --workers 4", "livesweep batch cases/*.toml --out out/batch --no-plots"],
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


def cmd_maps(args) -> int:
    """List the channel-map presets: name, description, inputs and outputs, what each needs."""
    from livesweep.maps import list_maps

    for m in list_maps():
        print(m.name)
        print(f"    {m.description}")
        print(f"    inputs: {', '.join(m.inputs)}; outputs: {', '.join(m.outputs)}")
        print(f"    needs: {m.needs}")
    print("use one with: livesweep monitor --map NAME ... / livesweep replay LOG --map NAME")
    return 0


def cmd_convert(args) -> int:
    """Convert a log to MCAP and print what was read, skipped and repaired."""
    from livesweep.convert import convert

    options = {"column_map": args.columns} if args.columns else {}
    if args.partial:
        options["partial"] = True
    res = convert(args.src, args.out, force=args.force, **options)
    print(f"{res.source.name} ({res.format}{', ' + res.format_version if res.format_version else ''}) -> {res.output}")
    print(f"  messages read {res.messages_read}, written {res.messages_written} on {len(res.topics)} channels")
    print(f"  skipped: {_counts_text(res.skipped)}; repaired: {_counts_text(res.repaired)}")
    for w in res.warnings:
        print(f"  warning: {w}")
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


def _default_axis(model: str) -> str:
    """The first input of ``model`` (``da`` for the XV-15; an unknown model is reported later)."""
    from livesweep.sim.models import MODELS

    return MODELS[model]().inputs[0] if model in MODELS else "da"


#: Commands whose linear algebra is many small problems (fits, SVDs of a few hundred points):
#: a BLAS thread pool costs more than it gains there, so they run single-threaded unless the user
#: set the variables (measured: the residual stage 60 % and a whole identify about 30 % faster).
_SMALL_BLAS_VERBS = ("identify", "batch", "demo")
_BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


class _Signalled(SystemExit):
    """Raised in the main thread by SIGTERM or SIGHUP (:func:`_unwind_on_signals`); exit status
    ``128 + signal number``, as the signal itself would have given."""

    def __init__(self, signum: int):
        import signal

        super().__init__(128 + signum)
        self.name = signal.Signals(signum).name


def _unwind_on_signals() -> dict:
    """Make SIGTERM (``kill``, ``timeout``, systemd, ``docker stop``) and SIGHUP (a closed terminal)
    raise :class:`_Signalled` instead of ending the process where it stands, so ``with`` blocks and
    ``finally`` clauses run: an atomic writer deletes its ``.partial`` file, locks are released.

    A signal ignored when the process started (``nohup``) stays ignored. A second signal ends the
    process at once (the default action), should the unwinding itself hang. Commands that finish
    their work on a signal (``monitor``) install their own handlers, which replace these. Nothing
    is installed outside the main thread (Python runs signal handlers only there).

    Returns
    -------
    dict
        Signal -> the handler replaced, for :func:`main` to put back when the command returns.
    """
    import signal
    import threading

    def handler(signum, frame):
        signal.signal(signum, signal.SIG_DFL)
        raise _Signalled(signum)

    replaced = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(sig) == signal.SIG_DFL:
                replaced[sig] = signal.signal(sig, handler)
    return replaced


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    verb = next((a for a in argv if not a.startswith("-")), None)
    if verb in _SMALL_BLAS_VERBS and "numpy" not in sys.modules:   # before anything loads numpy (the parser does)
        for var in _BLAS_THREAD_VARS:
            os.environ.setdefault(var, "1")
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "axis", None) is None and args.verb == "sim":
        args.axis = [_default_axis(args.model)]
    replaced = _unwind_on_signals()
    try:
        return args.func(args)
    except LivesweepError as exc:
        print(f"livesweep: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("livesweep: interrupted", file=sys.stderr)
        return 130
    except _Signalled as exc:
        print(f"livesweep: {exc.name}: stopped", file=sys.stderr)
        return exc.code
    finally:
        import signal

        for sig, previous in replaced.items():
            signal.signal(sig, previous)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
