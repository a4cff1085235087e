#!/usr/bin/env python3
"""Simulator and log-writer speed, as ratios against baselines measured in the same run.

1. Simulation: livesweep's engine against ``scipy.signal.lsim`` (first-order hold) on the same
   augmented XV-15 cruise system, grid and input (no pilot loop, so both do the same work).
2. Pilot loop: the hover simulation (sequential pilot feedback) against the same engine open loop.
3. Log writing: ``write_sim_log`` (MAVLink record canonicalisation + MCAP) against a bare
   ``json.dumps`` + ``mcap.writer.Writer`` loop over the same records.

    python benchmarks/bench_sim.py [--seconds 200]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer
from scipy import signal as sps

from livesweep.sim.engine import augment, step
from livesweep.sim.models import get_model
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.telemetry.sim_telemetry import mavlink_timeline, write_sim_log


def best_of(fn, n=3):
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=200.0, help="simulated flight time for the engine runs")
    args = ap.parse_args()

    m = get_model("xv15-cruise")
    sysa = augment(m, [])
    fs = 400.0
    t = np.arange(0, args.seconds, 1 / fs)
    u = np.column_stack([np.sin(0.3 * t + 0.01 * t**2), 0.2 * np.sin(1.7 * t)])
    eta = np.zeros((t.size, sysa.Bw.shape[1]))
    sysz = sysa.__class__(**{**vars(sysa), "delays_s": np.zeros_like(sysa.delays_s)})
    t_ours, (_, y_ours) = best_of(lambda: step(sysz, 1 / fs, u, eta))
    lti = sps.StateSpace(sysa.A, sysa.B, sysa.C, sysa.D)
    t_lsim, (_, y_lsim, _) = best_of(lambda: sps.lsim(lti, u, t, interp=True))
    err = np.max(np.abs(y_ours - y_lsim)) / np.max(np.abs(y_lsim))
    print(f"engine  {t.size} steps: livesweep {t_ours * 1e3:7.1f} ms, scipy lsim {t_lsim * 1e3:7.1f} ms, "
          f"ratio {t_ours / t_lsim:5.2f} (max relative difference {err:.1e})")

    sc_open = sweep_scenario("xv15-cruise", axes=("da",), repeats=1, duration_s=100.0, noise=False, seed=1)
    sc_pilot = sweep_scenario("xv15-hover", axes=("da",), repeats=1, omega_min_rad_s=0.2, omega_max_rad_s=12.0,
                              duration_s=100.0, noise=False, seed=1)
    t_open, _ = best_of(lambda: simulate(sc_open))
    t_pilot, _ = best_of(lambda: simulate(sc_pilot))
    print(f"pilot   hover with pilot loop {t_pilot * 1e3:7.1f} ms, cruise open loop {t_open * 1e3:7.1f} ms, "
          f"ratio {t_pilot / t_open:5.2f}")

    res = simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=1, duration_s=100.0, seed=1))
    records, _ = mavlink_timeline(res)
    with tempfile.TemporaryDirectory() as tmp:
        def ours():
            return write_sim_log(res, Path(tmp) / "a.mcap")

        def bare():
            with open(Path(tmp) / "b.mcap", "wb") as f:
                w = Writer(f, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
                w.start()
                ids = {}
                for r in records:
                    if r.msgname not in ids:
                        sid = w.register_schema(r.msgname, "jsonschema", b"{}")
                        ids[r.msgname] = w.register_channel(f"/mavlink/{r.msgname}", "json", sid)
                    w.add_message(ids[r.msgname], r.log_time_ns, json.dumps(r.record).encode(), r.vehicle_time_ns)
                w.finish()

        t_w, _ = best_of(ours)
        t_b, _ = best_of(bare)
    n = len(records)
    print(f"log     {n} messages: write_sim_log {t_w * 1e3:7.1f} ms ({t_w / n * 1e6:5.1f} us/msg), "
          f"bare json+mcap {t_b * 1e3:7.1f} ms ({t_b / n * 1e6:5.1f} us/msg), ratio {t_w / t_b:5.2f}")


if __name__ == "__main__":
    main()
