"""``livesweep demo``: the simulated XV-15 flown live into the monitor over UDP loopback, recorded,
then identified from the recording: :func:`livesweep.monitor` and :func:`livesweep.identify`,
printed as ``monitor`` and ``identify`` print them."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

from livesweep import __version__
from livesweep.commands.common import command_name
from livesweep.commands.identify import present_identification, progress_printer
from livesweep.commands.monitor_summary import print_monitor_summary
from livesweep.errors import ConfigError, LivesweepError

__all__ = ["cmd_demo", "DEMO_CASE"]

#: The packaged channel map the demo's monitor and case use.
CHANNELS = Path(__file__).resolve().parents[1] / "data" / "xv15_channels.toml"

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

    import tomllib

    from livesweep.config import load_channel_map
    from livesweep.ident.envelope import ModelSettings
    from livesweep.tf_tables import specs_of_tables
    from livesweep.locks import folder_lock
    from livesweep.monitor.pipeline import MonitorSettings
    from livesweep.monitor.session import monitor
    from livesweep.report.writer import prepare_out_dir
    from livesweep.sim.samples import SAMPLE_LOGS
    from livesweep.stages.identify import identify

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
    signals, _ = load_channel_map(CHANNELS)
    signals_text = CHANNELS.read_text()
    case_text = DEMO_CASE.format(signals=signals_text[signals_text.index("[signals.da]"):signals_text.index("[spectral]")])
    tables = tomllib.loads(case_text)["transfer_functions"]     # each test point's model: the case's structure
    settings = MonitorSettings(signals=signals, inputs=("da",), outputs=("p", "r", "ay", "beta"), band_rad_s=(0.3, 20.0),
                               sample_rate_hz=50.0, window_s=240.0, required_pairs=(("p", "da"),),
                               models=ModelSettings(specs_of_tables(tables, "the demo case"), tables=tables))
    log = out_dir / "live.mcap"
    rrd = out_dir / "live.rrd"
    live = monitor("udpin:127.0.0.1:0", settings, record=log, overwrite=True,     # the demo rewrites its own folder
                   rerun={"recording_id": "demo", "save_path": None if args.view else rrd, "spawn": args.view},
                   metadata={"test_point": {"aircraft": "XV-15", "manoeuvre": "aileron sweeps x2 (simulated)",
                                            "source": "livesweep demo"}})
    with live:
        port = int(live.urls[0].rsplit(":", 1)[1])
        print(f"  simulator -> MAVLink 2 over udp 127.0.0.1:{port} at {args.speed:g}x real time -> monitor")
        sim = subprocess.Popen([sys.executable, "-m", "livesweep", "sim", "--axis", "da", "--repeat", "2",
                                "--omega-min", "0.3", "--omega-max", "20", "--duration", "100", "--amplitude", "3",
                                "--off-axis-rms", "0.2", "--seed", "11", "--speed", str(args.speed),
                                "--mavlink", f"udpout:127.0.0.1:{port}"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            while sim.poll() is None and live.running:
                time.sleep(0.1)
            if live.running:
                time.sleep(1.0)                  # drain what is still in flight
        finally:
            if sim.poll() is None:
                sim.kill()
        summary = live.stop()
    if sim.returncode not in (0, None):
        raise LivesweepError(f"the simulator failed: {sim.stderr.read().decode().strip()[-300:]}")
    print_monitor_summary(summary)
    print(f"  recording: {log} (Foxglove: open it and import the layout {live.layout.name})"
          + ("" if args.view else f"\n  rerun: {rrd} (open with: {command_name('rerun')} {rrd})"))
    print()
    case = out_dir / "demo_case.toml"
    case.write_text(case_text)
    report_dir = out_dir / "report"
    with folder_lock(prepare_out_dir(report_dir)):
        progress = progress_printer()
        ident = identify(case, progress=progress)
        present_identification(ident, report_dir, progress=progress)
    report = report_dir / "report.html"
    ls = command_name("livesweep")
    print(f"""
next:
  1. open the report in a browser: {report.resolve().as_uri()}
  2. look at the live session again: {command_name('rerun')} {rrd}
     (or run the monitor over the recording: {ls} replay {log})
  3. start your own case: {case} is the case file this demo identified; for your own log,
     {ls} inspect LOG   lists what it holds and the channel maps that fit it, and
     {ls} new-case LOG --map NAME --out case.toml   writes a case for it""")
    return 0
