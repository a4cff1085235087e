#!/usr/bin/env python3
"""Verdict latency: a verdict change reaches the MCAP file and Rerun how soon after its packet, at 2 000 msg/s?

A `livesweep sim` process streams the XV-15 cruise sweeps (both axes, ``--repeat`` sweeps each) as
MAVLink 2 over UDP loopback at 8x real time (~2 000 msg/s). A thread of this process acts as the
operator: every ``--cycle`` wall seconds it sends a NAMED_VALUE_INT "LS_TP" marker (1: a test point
sweeping ``da`` starts; 0: it ends) on the same link, so the verdict changes dozens of times
(WAIT when a test point opens, GO or NO-GO when it is judged). The full monitor runs as the
``livesweep monitor`` command runs it: the recorder process (the UDP socket and the MCAP file,
verdicts flushed to the file as they are recorded) and, in this process, aligner -> estimator and
test-point judge (update every 0.2 s of wall time) -> Rerun (.rrd). ``--hog`` runs it all beside
processes that keep every core busy.

Measured in the same run, on the same process clock (``livesweep.telemetry.clock.receive_ns``):

* **monitor**: for every verdict change, the receipt of the oldest packet not yet processed when
  it was decided -> the change recorded to the MCAP file (flushed), published and logged to
  Rerun (``MonitorPipeline.totals.verdict_latency_s``); and, for the changes a marker caused,
  the marker's send -> the verdict's record stamp.
* **baseline**: a bare pymavlink receive loop on the same stream with the same markers (what any
  receiver must pay to see the packet at all): the marker's send -> its parse.

Printed: p50/p99/max of each, the monitor's p99 as a ratio to the update period (the issue's
budget is p99 <= 250 ms) and to the baseline's p99.

    python benchmarks/bench_verdict_latency.py [--speed 8] [--repeat 2] [--cycle 3] [--hog]
"""

from __future__ import annotations

import argparse
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from bench_ingest import start_sim  # the same sim stream as the ingest benchmark (benchmarks/ is on sys.path)
from livesweep.telemetry import mavlink_codec  # noqa: F401  (MAVLink 2 before pymavlink loads)

ROOT = Path(__file__).resolve().parents[1]
UPDATE_WALL_S = 0.2          # estimates (and test-point judgements) this often [s of wall time]


class Operator(threading.Thread):
    """Sends LS_TP markers (1 = start sweeping da, 0 = end) every ``cycle_s / 2`` until stopped."""

    def __init__(self, port: int, cycle_s: float):
        super().__init__(daemon=True)
        from livesweep.telemetry.mavlink_out import MavlinkSender

        self.tx = MavlinkSender(f"udpout:127.0.0.1:{port}", source_system=255, source_component=190)  # a ground station
        self.cycle_s = cycle_s
        self.sent: list[tuple[int, int]] = []          # (value, receive_ns() at send)
        self.halt = threading.Event()

    def run(self) -> None:
        from livesweep.telemetry.clock import receive_ns

        value = 1
        self.halt.wait(self.cycle_s)                    # the first data first
        while not self.halt.is_set():
            t = receive_ns()
            self.tx.send_record("NAMED_VALUE_INT", {"time_boot_ms": (t // 1_000_000) % 2**32, "name": "LS_TP", "value": value})
            self.sent.append((value, t))
            value = 1 - value
            self.halt.wait(self.cycle_s / 2)
        self.tx.close()


def stats(x) -> str:
    x = np.asarray(x) * 1e3
    return f"p50 {np.percentile(x, 50):6.1f} ms, p99 {np.percentile(x, 99):6.1f} ms, max {x.max():6.1f} ms (n = {x.size})"


def baseline(speed: float, repeat: int, cycle_s: float) -> dict:
    """A bare pymavlink loop: marker send -> parse."""
    from pymavlink import mavutil

    from livesweep.telemetry.clock import receive_ns

    rx = mavutil.mavlink_connection("udpin:127.0.0.1:0")
    rx.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    port = rx.port.getsockname()[1]
    sim = start_sim(port, speed, repeat)
    op = Operator(port, cycle_s)
    op.start()
    seen, n, quiet = [], 0, None
    while True:
        m = rx.recv_msg()
        if m is not None:
            n += 1
            if m.get_type() == "NAMED_VALUE_INT":
                seen.append(receive_ns())
            quiet = None
            continue
        if sim.poll() is not None:
            op.halt.set()
            quiet = quiet or time.monotonic()
            if time.monotonic() - quiet > 1.0:
                break
        time.sleep(0.0005)
    op.join()
    sent = [t for _, t in op.sent]
    k = min(len(sent), len(seen))
    return {"lat": (np.asarray(seen[:k]) - np.asarray(sent[:k])) * 1e-9, "markers": len(sent), "received": n}


def monitor(speed: float, repeat: int, cycle_s: float, out: Path) -> dict:
    from livesweep.config import TestPointSettings, load_channel_map
    from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
    from livesweep.monitor.rerun_view import RerunView
    from livesweep.telemetry.capture import LiveCapture
    from livesweep.telemetry.mcap_log import read_messages

    signals, _ = load_channel_map(ROOT / "config" / "xv15_channels.toml")
    period = UPDATE_WALL_S * speed                      # data seconds per wall update
    st = MonitorSettings(signals=signals, inputs=("da", "dr"), outputs=("p", "r", "ay", "beta"), band_rad_s=(0.5, 20.0),
                         window_s=120.0, update_period_s=period, view_period_s=period,
                         test_points=TestPointSettings(sources=("marker",), min_duration_s=1.0))
    cap = LiveCapture(["udpin:127.0.0.1:0"], record_path=out / "verdict.mcap", settings=st.to_dict())
    port = int(cap.urls[0].rsplit(":", 1)[1])
    sim = start_sim(port, speed, repeat)
    op = Operator(port, cycle_s)
    view = RerunView(list(st.inputs), list(st.outputs), recording_id="bench", save_path=out / "verdict.rrd")
    pipe = MonitorPipeline(st, [cap.source], recorder=cap.recorder, view=view, keep_estimates=False)
    done = []

    def stop():
        if sim.poll() is None:
            return False
        op.halt.set()
        done.append(time.monotonic())
        return time.monotonic() - done[0] > 1.0

    op.start()
    try:
        summary = pipe.run(stop=stop)
    finally:
        cap.close()
    op.join()
    verdicts = [(m.log_time_ns, m.data) for m in read_messages(out / "verdict.mcap", topics="/livesweep/verdict")]
    # a marker-caused change: the first verdict recorded after a start marker was sent, before the next marker
    sends = [t for _, t in op.sent]
    caused = []
    for i, (v, t) in enumerate(op.sent):
        nxt = sends[i + 1] if i + 1 < len(sends) else np.inf
        after = [lt for lt, d in verdicts if t <= lt < nxt and d["verdict"] == "WAIT"]
        if v == 1 and after:
            caused.append((after[0] - t) * 1e-9)
    return {"own": np.asarray(summary["verdict_latency_s"]), "marker": np.asarray(caused), "markers": len(sends),
            "changes": len(verdicts), "received": summary["frames"], "wall_s": summary["wall_s"],
            "verdicts": sorted({d["verdict"] for _, d in verdicts})}


def measure(speed: float, repeat: int, cycle_s: float) -> tuple[dict, dict]:
    """The baseline and the monitor on the same stream, one after the other."""
    b = baseline(speed, repeat, cycle_s)
    with tempfile.TemporaryDirectory() as tmp:
        m = monitor(speed, repeat, cycle_s, Path(tmp))
    return b, m


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--speed", type=float, default=8.0, help="x real time: 8 gives about 2000 msg/s")
    ap.add_argument("--repeat", type=int, default=2, help="sweeps per axis (2: about 60 s of wall time at 8x)")
    ap.add_argument("--cycle", type=float, default=3.0, help="wall seconds from one marker start to the next")
    ap.add_argument("--hog", action="store_true", help="beside a process keeping every core busy")
    args = ap.parse_args()
    if args.hog:
        sys.path.insert(0, str(ROOT / "tests"))
        from helpers import CpuHog

        with CpuHog():
            b, m = measure(args.speed, args.repeat, args.cycle)
    else:
        b, m = measure(args.speed, args.repeat, args.cycle)
    print(f"stream: {m['received']} MAVLink 2 messages in {m['wall_s']:.1f} s ({m['received'] / m['wall_s']:.0f} msg/s), "
          f"{m['markers']} operator markers, {m['changes']} verdict changes ({', '.join(m['verdicts'])})")
    print(f"baseline bare pymavlink, marker send -> parse          : {stats(b['lat'])}")
    print(f"monitor, oldest packet behind a change -> MCAP + Rerun : {stats(m['own'])}")
    if m["marker"].size:
        print(f"monitor, marker send -> WAIT verdict recorded          : {stats(m['marker'])}")
    p99 = float(np.percentile(m["own"], 99))
    print(f"  ratio p99 / update period ({1e3 * UPDATE_WALL_S:.0f} ms): {p99 / UPDATE_WALL_S:.2f}; "
          f"ratio p99 / baseline p99: {p99 / float(np.percentile(b['lat'], 99)):.1f}; budget p99 <= 250 ms: "
          f"{'met' if p99 <= 0.25 else 'NOT met'}")


if __name__ == "__main__":
    main()
