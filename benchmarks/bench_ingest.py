#!/usr/bin/env python3
"""Live ingest: MAVLink 2 over UDP loopback at ~2000 messages/s for ~60 s into the full monitor.

A `livesweep sim` process streams the XV-15 cruise sweeps (both axes, two sweeps each) at 8x real
time (~2000 msg/s); estimates every 0.2 s of wall time (1.6 s of flight). Measured in the same run:

* baseline: a bare pymavlink receive loop (parse only) on the same stream -> CPU per message;
* monitor: MAVLink source -> MCAP recorder -> aligner -> online estimator (5 updates/s) -> Rerun
  (.rrd, every estimate logged) -> CPU per message, CPU share, received = sent = recorded, and
  the latency from a packet's arrival to the Rerun log of the estimate that includes it.

    python benchmarks/bench_ingest.py [--speed 8]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from livesweep.telemetry import mavlink_codec  # noqa: F401  (MAVLink 2 before pymavlink loads)

ROOT = Path(__file__).resolve().parents[1]


def start_sim(port: int, speed: float, repeat: int = 2) -> subprocess.Popen:
    """`livesweep sim` streaming the XV-15 cruise sweeps (both axes, ``repeat`` each) to ``port``."""
    return subprocess.Popen([sys.executable, "-m", "livesweep", "sim", "--axis", "da", "--axis", "dr", "--repeat",
                             str(repeat), "--amplitude", "3", "--off-axis-rms", "0.2", "--seed", "3", "--speed", str(speed),
                             "--mavlink", f"udpout:127.0.0.1:{port}"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def sent_count(sim: subprocess.Popen) -> int:
    out = sim.stdout.read().decode()
    return int(out.split("sent ")[1].split()[0])


def baseline(speed: float) -> dict:
    from pymavlink import mavutil

    rx = mavutil.mavlink_connection("udpin:127.0.0.1:0")
    import socket

    rx.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    port = rx.port.getsockname()[1]
    sim = start_sim(port, speed)
    n, cpu0, t0, quiet = 0, time.process_time(), time.monotonic(), None
    while True:
        m = rx.recv_msg()
        if m is not None:
            n += m.get_type() != "BAD_DATA"
            quiet = None
            continue
        if sim.poll() is not None:
            quiet = quiet or time.monotonic()
            if time.monotonic() - quiet > 1.0:
                break
        time.sleep(0.0005)
    cpu = time.process_time() - cpu0
    return {"received": n, "sent": sent_count(sim), "cpu_s": cpu, "wall_s": time.monotonic() - t0}


def monitor(speed: float, out: Path) -> dict:
    from livesweep.config import load_channel_map
    from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
    from livesweep.monitor.rerun_view import RerunView
    from livesweep.telemetry.mavlink_in import MavlinkSource
    from livesweep.telemetry.mcap_log import read_summary
    from livesweep.telemetry.recorder import McapRecorder

    signals, _ = load_channel_map(ROOT / "config" / "xv15_channels.toml")
    period = 0.2 * speed            # 5 estimates per second of wall time, every one logged to Rerun
    st = MonitorSettings(signals=signals, inputs=("da", "dr"), outputs=("p", "r", "ay", "beta"), band_rad_s=(0.5, 20.0),
                         window_s=120.0, update_period_s=period, view_period_s=period, results_every=1)
    src = MavlinkSource("udpin:127.0.0.1:0")
    sim = start_sim(src.local_address[1], speed)
    rec = McapRecorder(out / "ingest.mcap", settings=st.to_dict())
    view = RerunView(list(st.inputs), list(st.outputs), recording_id="bench", save_path=out / "ingest.rrd")
    pipe = MonitorPipeline(st, [src], recorder=rec, view=view, keep_estimates=False)
    done = []

    def stop():
        if sim.poll() is None:
            return False
        done.append(time.monotonic())
        return time.monotonic() - done[0] > 1.0

    cpu0 = time.process_time()
    summary = pipe.run(stop=stop)
    cpu = time.process_time() - cpu0
    s = read_summary(out / "ingest.mcap")
    recorded = sum(v for k, v in s.message_counts.items() if k.startswith("/mavlink/"))
    lat = np.asarray(list(pipe.totals.latency_s)[1:])   # the first waits for the first full segment
    return {"received": summary["frames"], "sent": sent_count(sim), "recorded": recorded, "cpu_s": cpu,
            "wall_s": summary["wall_s"], "estimates": summary["estimates"], "lat_p50": np.percentile(lat, 50),
            "lat_p99": np.percentile(lat, 99), "lat_max": lat.max(), "data_s": summary["data_s"],
            "first_s": pipe.totals.latency_s[0]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--speed", type=float, default=8.0, help="x real time: 8 gives about 2000 msg/s")
    args = ap.parse_args()
    b = baseline(args.speed)
    with tempfile.TemporaryDirectory() as tmp:
        m = monitor(args.speed, Path(tmp))
    rate = m["received"] / m["wall_s"]
    print(f"stream: {m['sent']} MAVLink 2 messages over {m['wall_s']:.1f} s ({rate:.0f} msg/s, {m['data_s']:.0f} s of flight)")
    print(f"baseline pymavlink parse only : received {b['received']}/{b['sent']}, "
          f"CPU {1e6 * b['cpu_s'] / max(b['received'], 1):6.1f} us/msg ({100 * b['cpu_s'] / b['wall_s']:.0f} % of a core)")
    print(f"monitor (record, align, estimate, rerun): received {m['received']}/{m['sent']}, recorded {m['recorded']}, "
          f"CPU {1e6 * m['cpu_s'] / max(m['received'], 1):6.1f} us/msg ({100 * m['cpu_s'] / m['wall_s']:.0f} % of a core)")
    print(f"  ratio monitor / bare parse CPU per message: {(m['cpu_s'] / m['received']) / (b['cpu_s'] / b['received']):.2f}")
    print(f"  {m['estimates']} estimates (5 per wall second, every one logged to Rerun); latency packet -> Rerun log "
          f"of the estimate that includes it: p50 {1e3 * m['lat_p50']:.0f} ms, p99 {1e3 * m['lat_p99']:.0f} ms, "
          f"max {1e3 * m['lat_max']:.0f} ms (target p99 <= 200 ms update period + 50 ms); the first estimate waits "
          f"{m['first_s']:.1f} s for the first full segment")


if __name__ == "__main__":
    main()
