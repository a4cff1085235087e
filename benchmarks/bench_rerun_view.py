#!/usr/bin/env python3
"""``RerunView.log_estimate`` of a large estimate against the plain Rerun SDK route measured in the
same run (single core, in-memory recordings drained after every update).

The estimate: 4 inputs x 12 outputs (48 pairs) x 150 frequencies, coherence, |H| and phase with
noise, 8 updates at successive flight times. Timed per update on the calling thread's CPU clock
(``time.thread_time``: Rerun's own threads and other load on the machine are not counted) and on
the wall clock:

* **livesweep**: ``RerunView.log_estimate`` (every pair's three plots with their masked stretches
  and coherence points, the coherence waterfalls, fractions, status document);
* **baseline**: the same plots as a Rerun user would log them with the SDK's archetypes, one
  ``rr.log`` per plot: per pair ``rr.LineStrips2D`` for |H| and phase (one strip each),
  ``rr.LineStrips2D`` + ``rr.Points2D`` (coloured at gamma^2 = 0.6) for the coherence, an
  ``rr.Tensor`` of the pair's waterfall rows; ``rr.Scalars`` of the fractions and an
  ``rr.TextDocument`` status.

The first update of each (one-off set-up: grids, descriptors, entity paths) is shown apart; the
ratio is of the medians of the later ones. This replaces the test suite's former ``assert
median CPU < 0.1 s`` (tests/test_rerun_view.py), whose budget is printed as a line of its own.

    python benchmarks/bench_rerun_view.py [--updates 8]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import rerun as rr  # noqa: E402

from livesweep.monitor.rerun_view import RerunView  # noqa: E402

N_IN, N_OUT, N_F = 4, 12, 150
WATERFALL_ROWS = 30
BUDGET_CPU_S = 0.1          # the tests' former bound: median CPU of an update after the first


def estimates(n_updates: int):
    ins = [f"u{k}" for k in range(N_IN)]
    outs = [f"y{k}" for k in range(N_OUT)]
    omega = np.logspace(np.log10(0.3), np.log10(40.0), N_F)
    rng = np.random.default_rng(1)
    s = 1j * omega
    g = 10.0 / (s * (s / 5.0 + 1.0))
    rows = [{"output": o, "input": i, "band": (1.0, 10.0), "fraction": 0.5} for o in outs for i in ins]
    out = []
    for _ in range(n_updates):
        coh = np.clip(rng.normal(0.8, 0.1, (N_OUT, N_IN, N_F)), 0, 1)
        mag = 20 * np.log10(abs(g)) + rng.normal(0, 0.5, (N_OUT, N_IN, N_F))
        pha = np.degrees(np.unwrap(np.angle(g))) + rng.normal(0, 3, (N_OUT, N_IN, N_F))
        out.append((coh, mag, pha))
    return ins, outs, omega, rows, out


def timed(fn, *args):
    c0, w0 = time.thread_time(), time.perf_counter()
    fn(*args)
    return time.thread_time() - c0, time.perf_counter() - w0


class PlainRerun:
    """The same plots through the SDK's archetypes, one ``rr.log`` per plot."""

    def __init__(self, ins, outs):
        self.ins, self.outs = ins, outs
        self.rec = rr.RecordingStream("bench-plain")
        self.rec.set_log_time_enabled(False)
        self.rec.set_log_tick_enabled(False)
        self.memory = self.rec.memory_recording()
        self.waterfall = {}

    def log_estimate(self, t_s, omega, coh, mag, pha, rows):
        rec = self.rec
        rec.set_time("flight_time", duration=t_s)
        logw = np.log10(omega).astype(np.float32)
        green, grey = [0, 160, 0, 255], [150, 150, 150, 255]
        for io, o in enumerate(self.outs):
            for ii, i in enumerate(self.ins):
                base = f"pairs/{o}_{i}"
                c = coh[io, ii]
                xy = np.column_stack([logw, c]).astype(np.float32)
                rec.log(f"{base}/coherence", rr.LineStrips2D([xy], colors=[green]),
                        rr.Points2D(xy, colors=np.where((c >= 0.6)[:, None], green, grey).astype(np.uint8)))
                rec.log(f"{base}/magnitude", rr.LineStrips2D([np.column_stack([logw, mag[io, ii]]).astype(np.float32)]))
                rec.log(f"{base}/phase", rr.LineStrips2D([np.column_stack([logw, pha[io, ii]]).astype(np.float32)]))
                row = np.clip(np.rint(c * 100.0), 0, 100).astype(np.uint8)[None, :]
                old = self.waterfall.get((o, i))
                new = row if old is None else np.concatenate([old[-(WATERFALL_ROWS - 1):], row])
                self.waterfall[(o, i)] = new
                rec.log(f"{base}/waterfall", rr.Tensor(new, dim_names=["estimate", "frequency bin"]))
        rec.log("status/fractions", rr.Scalars(np.array([r["fraction"] for r in rows], float)))
        rec.log("status/adequacy", rr.TextDocument("\n".join(f"{r['output']}/{r['input']}: {r['fraction']:.0%}"
                                                             for r in rows), media_type=rr.MediaType.MARKDOWN))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--updates", type=int, default=8)
    args = ap.parse_args()
    ins, outs, omega, rows, data = estimates(max(2, args.updates))
    view = RerunView(ins, outs, waterfall_rows=WATERFALL_ROWS)     # no sink: in-memory recording
    plain = PlainRerun(ins, outs)
    ls, ref = [], []
    try:
        for n, (coh, mag, pha) in enumerate(data):                   # in turn: the same load on both
            ls.append(timed(view.log_estimate, 1.0 + n, omega, outs, ins, coh, mag, pha, rows, "continue", []))
            view.memory.drain_as_bytes()
            ref.append(timed(plain.log_estimate, 1.0 + n, omega, coh, mag, pha, rows))
            plain.memory.drain_as_bytes()
    finally:
        view.close()
    cpu_ls, wall_ls = statistics.median(c for c, _ in ls[1:]), statistics.median(w for _, w in ls[1:])
    cpu_ref, wall_ref = statistics.median(c for c, _ in ref[1:]), statistics.median(w for _, w in ref[1:])
    print(f"{N_IN} inputs x {N_OUT} outputs x {N_F} frequencies, {len(data)} updates; median of updates 2.. "
          "(thread CPU / wall)")
    print(f"RerunView.log_estimate (livesweep): first {1e3 * ls[0][1]:6.1f} ms wall; then "
          f"{1e3 * cpu_ls:6.1f} ms CPU / {1e3 * wall_ls:6.1f} ms wall")
    print(f"rr.log per plot (baseline):         first {1e3 * ref[0][1]:6.1f} ms wall; then "
          f"{1e3 * cpu_ref:6.1f} ms CPU / {1e3 * wall_ref:6.1f} ms wall")
    print(f"ratio livesweep / baseline: {cpu_ls / cpu_ref:.2f} (CPU), {wall_ls / wall_ref:.2f} (wall)")
    print(f"budget: {1e3 * cpu_ls:.1f} ms CPU per update, under {1e3 * BUDGET_CPU_S:.0f} ms: "
          f"{'OK' if cpu_ls < BUDGET_CPU_S else 'MISSED'}")


if __name__ == "__main__":
    main()
