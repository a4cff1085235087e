#!/usr/bin/env python3
"""Load: the highest MAVLink rate the live monitor records without losing a frame, and loss beyond it counted.

A sender process streams pre-packed MAVLink 2 frames over UDP loopback at a fixed rate for
``--seconds`` (60 by default). The frames come from as many simulated vehicles as the rate needs for
each to stream in real time (about 310 messages per second of flight: system ids 1..N, each flying
the XV-15 cruise sweeps), so the link carries the rate while the monitor analyses one vehicle at
the pace of a real flight and records them all. Each rate of the ladder is run against, in the
same run:

* baseline: what a competent engineer writes to record a link with pymavlink and mcap: one thread,
  ``recvmsg`` -> ``parse_buffer`` -> ``to_dict`` -> ``json.dumps`` -> ``mcap.Writer.add_message``,
  4 MB socket buffer, the kernel's drop count read from ``SO_RXQ_OVFL``;
* livesweep: the ``livesweep monitor`` command (recording, aligner, sliding-window estimator, Rerun
  ``.rrd``), stopped with SIGTERM; frames recorded and every counter read back from the MCAP.

For each: frames sent, recorded, dropped by the kernel, and whether recorded + dropped = sent (loss
counted, never silent). Prints the highest lossless rate of each and their ratio.

    python benchmarks/bench_load.py [--rates 10000,20000,30000,40000] [--seconds 60]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from livesweep.telemetry import mavlink_codec as codec  # MAVLink 2 before pymavlink loads

ROOT = Path(__file__).resolve().parents[1]

SENDER = r"""
import socket, struct, sys, time
path, port, rate, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
blob = open(path, "rb").read()
frames, p = [], 0
n_max = int(rate * seconds)
while p < len(blob) and len(frames) < n_max:
    (n,) = struct.unpack_from("<H", blob, p)
    frames.append(blob[p + 2:p + 2 + n])
    p += 2 + n
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4 << 20)
addr = ("127.0.0.1", port)
t0 = time.perf_counter()
for i, f in enumerate(frames):
    s.sendto(f, addr)
    if i % 200 == 199:
        d = t0 + (i + 1) / rate - time.perf_counter()
        if d > 0:
            time.sleep(d)
print(len(frames), time.perf_counter() - t0)
"""

BASELINE = r"""
import json, os, signal, socket, struct, sys, time
os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as mav2
from mcap.writer import Writer, CompressionType
out = sys.argv[1]
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
sock.setsockopt(socket.SOL_SOCKET, 40, 1)               # SO_RXQ_OVFL: the kernel's drop count
sock.bind(("127.0.0.1", 0))
sock.settimeout(0.2)
mav = mav2.MAVLink(None)
mav.robust_parsing = True
f = open(out, "wb")
w = Writer(f, compression=CompressionType.ZSTD)
w.start()
schema = w.register_schema("json", "jsonschema", b"{}")
chans = {}
stop = []
signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
print(sock.getsockname()[1], flush=True)
n = drops = 0
while not stop:
    try:
        data, anc, _f, _a = sock.recvmsg(65535, 64)
    except socket.timeout:
        continue
    except InterruptedError:
        continue
    for lvl, typ, d in anc:
        if typ == 40:
            drops = struct.unpack("I", d[:4])[0]
    t = time.time_ns()
    for m in mav.parse_buffer(data) or ():
        name = m.get_type()
        if name == "BAD_DATA":
            continue
        cid = chans.get(name)
        if cid is None:
            cid = chans[name] = w.register_channel("/mavlink/" + name, "json", schema)
        d = m.to_dict()
        d["sysid"], d["compid"] = m.get_srcSystem(), m.get_srcComponent()
        w.add_message(cid, t, json.dumps(d).encode(), t)
        n += 1
w.finish()
f.close()
print(n, drops, flush=True)
"""


def base_flight() -> tuple[list[tuple[str, dict]], int, float]:
    """The XV-15 cruise sweep as (message, record) in time order, its span [µs] and messages per second."""
    from livesweep.sim.scenario import simulate, sweep_scenario
    from livesweep.telemetry.sim_telemetry import mavlink_timeline

    res = simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=1, duration_s=100.0, amplitudes={"da": 3.0},
                                  off_axis_rms=0.2, seed=3))
    recs, _ = mavlink_timeline(res)
    recs.sort(key=lambda r: (r.vehicle_time_ns, r.msgname))
    base = [(r.msgname, r.record) for r in recs if r.msgname != "HEARTBEAT"]
    span_us = (recs[-1].vehicle_time_ns - recs[0].vehicle_time_ns) // 1000 + 1_000_000
    return base, span_us, len(base) / (span_us * 1e-6)


def pack_stream(path: Path, rate: float, seconds: float, flight) -> int:
    """Pre-pack ``rate * seconds`` MAVLink 2 frames of enough vehicles for each to stream in real time."""
    from pymavlink.dialects.v20 import ardupilotmega as mav2

    base, span_us, per_s = flight
    n_vehicles = min(255, max(1, math.ceil(rate / per_s)))
    vehicles = [mav2.MAVLink(None, srcSystem=v + 1, srcComponent=1) for v in range(n_vehicles)]
    n_frames = int(rate * seconds)
    written = k = 0
    with open(path, "wb") as f:
        while written < n_frames:
            lap, i = divmod(k, len(base))
            name, rec = base[i]
            spec = codec._spec(name)
            tf = codec.vehicle_time_field(name)
            for mav in vehicles:
                kw = {fl.name: rec[fl.name] for fl in spec.fields}
                for fl in spec.fields:
                    if fl.kind == "char" and isinstance(kw[fl.name], str):
                        kw[fl.name] = kw[fl.name].encode()
                if tf is not None:       # each lap continues the vehicle's clock
                    wrap = 2**32 if codec.stamp_wrap_units(name, tf[0]) else 2**64
                    kw[tf[0]] = (kw[tf[0]] + lap * span_us * 1000 // tf[1]) % wrap
                buf = bytes(getattr(mav, name.lower() + "_encode")(**kw).pack(mav))
                mav.seq = (mav.seq + 1) % 256
                f.write(struct.pack("<H", len(buf)) + buf)
                written += 1
            k += 1
    return n_vehicles


def send(path: Path, port: int, rate: float, seconds: float) -> tuple[int, float]:
    r = subprocess.run([sys.executable, "-c", SENDER, str(path), str(port), str(rate), str(seconds)],
                       capture_output=True, text=True, check=True)
    n, wall = r.stdout.split()
    return int(n), float(wall)


def run_baseline(stream: Path, rate: float, seconds: float, tmp: Path) -> dict:
    out = tmp / "baseline.mcap"
    rx = subprocess.Popen([sys.executable, "-c", BASELINE, str(out)], stdout=subprocess.PIPE, text=True)
    port = int(rx.stdout.readline())
    sent, wall = send(stream, port, rate, seconds)
    time.sleep(1.0)
    rx.send_signal(signal.SIGTERM)
    recorded, drops = map(int, rx.stdout.read().split())
    rx.wait(30)
    return {"sent": sent, "recorded": recorded, "kernel_drops": drops, "send_wall_s": wall}


def run_monitor(stream: Path, rate: float, seconds: float, tmp: Path) -> dict:
    from livesweep.telemetry.mcap_log import read_summary
    from livesweep.telemetry.recorder import COUNTERS_METADATA

    out, rrd = tmp / "monitor.mcap", tmp / "monitor.rrd"
    for p in (out, rrd):
        p.unlink(missing_ok=True)
    mon = subprocess.Popen([sys.executable, "-m", "livesweep", "monitor", "--mavlink", "udpin:127.0.0.1:0",
                            "--record", str(out), "--rerun-save", str(rrd), "--window", "60"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = mon.stdout.readline()
    port = int(line.split("udpin:127.0.0.1:")[1].split(";")[0].split(",")[0])
    sent, wall = send(stream, port, rate, seconds)
    time.sleep(1.0)
    t_stop = time.monotonic()
    mon.send_signal(signal.SIGTERM)
    mon.communicate(timeout=300)
    stop_s = time.monotonic() - t_stop
    s = read_summary(out)
    src = json.loads(s.metadata[COUNTERS_METADATA]["sources"])[0]
    pipe = json.loads(s.metadata[COUNTERS_METADATA]["pipeline"])
    recorded = sum(v for k, v in s.message_counts.items() if k.startswith("/mavlink/"))
    return {"sent": sent, "recorded": recorded, "kernel_drops": src["kernel_drops"], "send_wall_s": wall,
            "analysis_shed": pipe["analysis_shed"], "stop_s": stop_s, "complete": s.complete}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rates", default="10000,20000,25000,30000,40000", help="msg/s ladder, comma-separated")
    ap.add_argument("--seconds", type=float, default=60.0, help="seconds at each rate")
    args = ap.parse_args()
    rates = [float(r) for r in args.rates.split(",")]
    flight = base_flight()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        stream = tmp / "stream.bin"
        print(f"{args.seconds:g} s at each rate; each vehicle streams {flight[2]:.0f} msg/s (real time)")
        best = {"baseline": 0.0, "livesweep": 0.0}
        print(f"{'rate msg/s':>10s} {'vehicles':>8s} {'who':>9s} {'sent':>9s} {'recorded':>9s} {'kernel drops':>12s} "
              f"{'counted':>8s} {'analysis shed':>13s} {'stop s':>6s}")
        for rate in rates:
            n_vehicles = pack_stream(stream, rate, args.seconds, flight)
            for who, fn in (("baseline", run_baseline), ("livesweep", run_monitor)):
                r = fn(stream, rate, args.seconds, tmp)
                counted = r["recorded"] + r["kernel_drops"] == r["sent"]
                lossless = r["recorded"] == r["sent"]
                achieved = r["sent"] / r["send_wall_s"]
                if lossless and achieved >= 0.97 * rate:
                    best[who] = max(best[who], rate)
                print(f"{rate:10.0f} {n_vehicles:8d} {who:>9s} {r['sent']:9d} {r['recorded']:9d} {r['kernel_drops']:12d} "
                      f"{'yes' if counted else 'NO':>8s} {r.get('analysis_shed', 0):13d} "
                      f"{r.get('stop_s', float('nan')):6.1f}" + ("" if r.get("complete", True) else "  UNFINISHED FILE")
                      + ("" if achieved >= 0.97 * rate else f"  (sender reached only {achieved:.0f} msg/s)"))
        ratio = best["livesweep"] / best["baseline"] if best["baseline"] else float("nan")
        print(f"highest lossless rate over {args.seconds:g} s: livesweep monitor {best['livesweep']:.0f} msg/s "
              f"(recording + analysis + Rerun), baseline recorder {best['baseline']:.0f} msg/s (recording only): "
              f"ratio {ratio:.2f}")


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()
