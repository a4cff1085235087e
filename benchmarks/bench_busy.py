#!/usr/bin/env python3
"""A busy machine: the live recording keeps every frame and the test points keep their times.

The field laptop also runs a ground station and video. Measured in one run, each part against its
baseline in the same run:

1. **Lossless rate**, without and with a process keeping every core busy (:class:`helpers.CpuHog`):
   pre-packed MAVLink 2 frames over UDP loopback at a ladder of rates for ``--seconds`` each
   (bench_load's streams: as many simulated XV-15 vehicles as the rate needs), into
   * the baseline: a bare pymavlink parse of the same frames (``recvmsg`` -> ``parse_buffer``, 4 MB
     socket buffer): what any receiver must pay to see the frames at all;
   * ``livesweep monitor --record --rerun-save``: the recorder process (the datagrams to the MCAP
     as received, then decoded to the JSON channels) and the analysis and Rerun view.
   A rate is lossless when every frame sent is in the recording (its JSON channels; the raw
   datagram channel too) and the sender kept the rate. Printed: the highest rate of each that was
   lossless there and at every lower rate of the ladder, and their ratio.
2. **A real SystemID chirp at about 2 000 msg/s for 60 s, with every core busy**: the shared
   ArduCopter SITL log (``sid_axis7_rate_roll.bin``) streamed as ArduCopter's telemetry at its
   own 400 Hz (``livesweep stream``, speed ``--sid-speed``) into ``livesweep monitor --map
   ardupilot-copter-pid``: frames sent against recorded and dropped by the kernel, the test point
   against the autopilot's own "SystemID Starting"/"Finished" (DataFlash MSG ``TimeUS``, read with
   pymavlink), its verdict, and whether every message of the recording decodes as a JSON viewer
   (Foxglove) reads it: a JSON object on a channel with a JSON Schema, holding the schema's
   required keys.
3. **Verdict latency** (bench_verdict_latency's markers at about 2 000 msg/s): p99 from the packet
   behind a verdict change to the change in the MCAP file and in Rerun, as a ratio to the update
   period, without and with the hog.

    python benchmarks/bench_busy.py [--seconds 20] [--rates 40000,60000,80000,100000]
                                    [--hog-rates 2000,5000,10000,20000] [--sid-speed 1.15] [--skip-latency]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import bench_load
import bench_verdict_latency
from livesweep.telemetry import mavlink_codec  # noqa: F401  (MAVLink 2 before pymavlink loads)

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from helpers import CpuHog  # noqa: E402

DATA = ROOT.parent / "shared" / "data"
SID7 = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"

BARE = r"""
import os, socket, struct, signal, sys
os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as mav2
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
sock.setsockopt(socket.SOL_SOCKET, 40, 1)               # SO_RXQ_OVFL: the kernel's drop count
sock.bind(("127.0.0.1", 0))
sock.settimeout(0.2)
mav = mav2.MAVLink(None)
mav.robust_parsing = True
stop = []
signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
print(sock.getsockname()[1], flush=True)
n = drops = 0
while not stop:
    try:
        data, anc, _f, _a = sock.recvmsg(65535, 64)
    except (socket.timeout, InterruptedError):
        continue
    for lvl, typ, d in anc:
        if typ == 40:
            drops = struct.unpack("I", d[:4])[0]
    for m in mav.parse_buffer(data) or ():
        n += m.get_type() != "BAD_DATA"
print(n, drops, flush=True)
"""


def run_bare(stream: Path, rate: float, seconds: float) -> dict:
    rx = subprocess.Popen([sys.executable, "-c", BARE], stdout=subprocess.PIPE, text=True)
    port = int(rx.stdout.readline())
    sent, wall = bench_load.send(stream, port, rate, seconds)
    time.sleep(1.0)
    rx.send_signal(signal.SIGTERM)
    got, drops = map(int, rx.stdout.read().split())
    rx.wait(30)
    return {"sent": sent, "recorded": got, "kernel_drops": drops, "send_wall_s": wall}


def run_monitor(stream: Path, rate: float, seconds: float, tmp: Path) -> dict:
    r = bench_load.run_monitor(stream, rate, seconds, tmp)
    from livesweep.telemetry.mcap_log import read_summary
    from livesweep.telemetry.recorder import RAW_TOPIC

    r["raw"] = read_summary(tmp / "monitor.mcap").message_counts.get(RAW_TOPIC, 0)
    return r


def ladder(rates, seconds: float, flight, tmp: Path, label: str) -> dict:
    best = {"bare pymavlink parse": 0.0, "livesweep monitor": 0.0}
    failed: set[str] = set()
    stream = tmp / "stream.bin"
    print(f"\n{label}: {seconds:g} s at each rate")
    print(f"{'rate msg/s':>10s} {'who':>22s} {'sent':>9s} {'recorded':>9s} {'kernel drops':>12s} {'shed':>6s} "
          f"{'stop s':>6s}")
    for rate in rates:
        bench_load.pack_stream(stream, rate, seconds, flight)
        for who, fn in (("bare pymavlink parse", lambda: run_bare(stream, rate, seconds)),
                        ("livesweep monitor", lambda: run_monitor(stream, rate, seconds, tmp))):
            r = fn()
            ok = r["recorded"] == r["sent"] and r.get("raw", r["sent"]) == r["sent"]
            kept = r["sent"] / r["send_wall_s"] >= 0.97 * rate
            if ok and kept and who not in failed:          # lossless here and at every lower rate
                best[who] = max(best[who], rate)
            elif not (ok and kept):
                failed.add(who)
            print(f"{rate:10.0f} {who:>22s} {r['sent']:9d} {r['recorded']:9d} {r['kernel_drops']:12d} "
                  f"{r.get('analysis_shed', 0):6d} {r.get('stop_s', float('nan')):6.1f}"
                  + ("" if kept else f"  (sender reached only {r['sent'] / r['send_wall_s']:.0f} msg/s)"))
    ratio = best["livesweep monitor"] / best["bare pymavlink parse"] if best["bare pymavlink parse"] else float("nan")
    print(f"highest lossless rate {label}: livesweep monitor {best['livesweep monitor']:.0f} msg/s, bare pymavlink "
          f"parse {best['bare pymavlink parse']:.0f} msg/s: ratio {ratio:.2f}")
    return best


def _reference(log: Path) -> dict:
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(log), zero_time_base=True)
    out = {}
    while (m := r.recv_match(type="MSG")) is not None:
        if m.Message == "SystemID Starting: axis=7":
            out["start"] = m.TimeUS * 1e-6
        elif m.Message == "SystemID Finished" and "start" in out and "end" not in out:
            out["end"] = m.TimeUS * 1e-6
    return out


def foxglove_decodable(path: Path) -> tuple[int, list[str]]:
    """Every message a JSON object on a channel with a JSON Schema, holding the schema's required
    keys (what a JSON viewer needs to decode it): (messages checked, problems)."""
    from mcap.reader import make_reader

    problems, n = [], 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        required = {}
        for schema, channel, msg in reader.iter_messages():
            n += 1
            if channel.id not in required:
                if channel.message_encoding != "json" or schema is None or schema.encoding != "jsonschema":
                    problems.append(f"{channel.topic}: encoding {channel.message_encoding}/"
                                    f"{getattr(schema, 'encoding', None)}")
                    required[channel.id] = ()
                    continue
                required[channel.id] = tuple(json.loads(schema.data).get("required", ()))
            try:
                obj = json.loads(msg.data)
            except ValueError:
                problems.append(f"{channel.topic}: a message is not JSON")
                continue
            if not isinstance(obj, dict) or any(k not in obj for k in required[channel.id]):
                problems.append(f"{channel.topic}: a message lacks a required key")
    return n, problems[:10]


def sid_busy(speed: float, tmp: Path) -> None:
    """The SystemID roll chirp at ~2 000 msg/s, every core busy."""
    from livesweep.telemetry.mcap_log import read_messages, read_summary
    from livesweep.telemetry.recorder import COUNTERS_METADATA, RAW_TOPIC

    if not SID7.is_file():
        print(f"\n(part 2 skipped: {SID7} not found)")
        return
    out = tmp / "sid.mcap"
    ref = _reference(SID7)
    with CpuHog() as hog:
        mon = subprocess.Popen([sys.executable, "-m", "livesweep", "monitor", "--mavlink", "udpin:127.0.0.1:0",
                                "--map", "ardupilot-copter-pid", "--record", str(out), "--rerun-save",
                                str(tmp / "sid.rrd"), "--no-status", "--no-markers"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        port = int(mon.stdout.readline().split("udpin:127.0.0.1:")[1].split(";")[0])
        st = subprocess.run([sys.executable, "-m", "livesweep", "stream", str(SID7), "--mavlink",
                             f"udpout:127.0.0.1:{port}", "--start-s", "30", "--end-s", "98", "--speed", str(speed)],
                            capture_output=True, text=True, check=True)
        time.sleep(3.0)
        mon.send_signal(signal.SIGINT)
        mon.communicate(timeout=300)
        n_hog = hog.n
    m = re.search(r"sent (\d+) messages in ([\d.]+) s", st.stdout)
    sent, wall = int(m.group(1)), float(m.group(2))
    s = read_summary(out)
    recorded = sum(v for k, v in s.message_counts.items() if k.startswith("/mavlink/"))
    src = json.loads(s.metadata[COUNTERS_METADATA]["sources"])[0]
    (tp,) = [m.data for m in read_messages(out, topics="/livesweep/test_point")]
    n_msgs, problems = foxglove_decodable(out)
    print(f"\nSystemID roll chirp streamed at {speed:g}x (ArduCopter's 400 Hz telemetry) beside {n_hog} busy "
          f"process(es): {sent} frames sent in {wall:.1f} s ({sent / wall:.0f} msg/s)")
    print(f"  recorded {recorded} (raw datagrams {s.message_counts.get(RAW_TOPIC, 0)}), kernel drops "
          f"{src['kernel_drops']}, analysis shed {src.get('analysis_shed', 0)}: "
          f"{'0 frames lost' if recorded == sent else f'{sent - recorded} LOST'}")
    print(f"  test point {tp['start_s']:.3f}-{tp['end_s']:.3f} s against the autopilot's {ref['start']:.3f}-"
          f"{ref['end']:.3f} s (differences {tp['start_s'] - ref['start']:+.3f}, {tp['end_s'] - ref['end']:+.3f} s): "
          f"{tp['label']} over {tp['judged_band_rad_s'][0]:.3g}-{tp['judged_band_rad_s'][1]:.3g} rad/s")
    print(f"  Foxglove: {n_msgs} messages on JSON channels with JSON Schemas"
          + (": every one decodes" if not problems else f"; problems: {problems}"))


def latency(cycle: float) -> None:
    period = bench_verdict_latency.UPDATE_WALL_S
    print(f"\nverdict latency at about 2 000 msg/s (update period {1e3 * period:.0f} ms of wall time):")
    for label, hog in (("idle machine", False), ("every core busy", True)):
        if hog:
            with CpuHog():
                b, m = bench_verdict_latency.measure(8.0, 2, cycle)
        else:
            b, m = bench_verdict_latency.measure(8.0, 2, cycle)
        p99 = float(np.percentile(m["own"], 99))
        print(f"  {label:16s}: monitor {bench_verdict_latency.stats(m['own'])}; p99 / update period "
              f"{p99 / period:.2f}; baseline bare pymavlink p99 {1e3 * float(np.percentile(b['lat'], 99)):.1f} ms")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=20.0, help="seconds at each rate of the ladders")
    ap.add_argument("--rates", default="40000,60000,80000,100000", help="ladder without the hog, msg/s")
    ap.add_argument("--hog-rates", default="2000,5000,10000,20000", help="ladder with the hog, msg/s")
    ap.add_argument("--sid-speed", type=float, default=1.15, help="x real time of the SystemID stream (~2000 msg/s)")
    ap.add_argument("--cycle", type=float, default=3.0, help="marker cycle of the latency part [s]")
    ap.add_argument("--skip-latency", action="store_true")
    args = ap.parse_args()
    flight = bench_load.base_flight()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        idle = ladder([float(r) for r in args.rates.split(",")], args.seconds, flight, tmp, "idle machine")
        with CpuHog() as hog:
            busy = ladder([float(r) for r in args.hog_rates.split(",")], args.seconds, flight, tmp,
                          f"beside {hog.n} busy process(es)")
        sid_busy(args.sid_speed, tmp)
    if not args.skip_latency:
        latency(args.cycle)
    r_idle = idle["livesweep monitor"] / idle["bare pymavlink parse"] if idle["bare pymavlink parse"] else float("nan")
    print(f"\nlossless: idle {idle['livesweep monitor']:.0f} msg/s ({r_idle:.2f} of a bare pymavlink parse, "
          f"{idle['bare pymavlink parse']:.0f}); busy {busy['livesweep monitor']:.0f} msg/s (bare parse "
          f"{busy['bare pymavlink parse']:.0f})")


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()
