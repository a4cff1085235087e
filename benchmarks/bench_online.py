#!/usr/bin/env python3
"""Live spectral monitoring cost, as ratios against a scipy baseline measured in the same run (single core).

Setting: 4 inputs x 12 outputs at 200 Hz, band 1-40 rad/s, 60 s sliding window, segments of
3 periods of the band's low end (18.85 s, the estimator's default), 80 % overlap, 5 updates per
second (blocks of 40 samples). Synthetic data: four independent band-limited inputs, outputs are
filtered mixtures of them plus noise.

1. Per-update cost of ``OnlineSpectralEstimator.update`` alone, and of ``update`` + ``result()`` +
   the ordinary responses (H, gamma^2, eps_r for all 48 pairs), over ``--updates`` updates after
   the window has filled: median and p99.
2. Baseline: recomputing from scratch at every update what the display needs with scipy -- for the
   data span of the segments in the window, ``scipy.signal.csd`` for every input x output and
   input x input pair and ``scipy.signal.welch`` for every autospectrum (same segment length,
   overlap, Hann taper, constant detrend), then coherence from them. Ratio baseline / livesweep
   (target >= 20x).
3. Replay: 600 s of data fed as fast as possible in 40-sample blocks, update only and with the
   responses computed at every block, and in 1 s blocks with responses -> multiple of real time
   (target >= 100x).

Most of a segment-completing update (the p99) is scipy's ``CZT`` plan construction inside
``segment_transforms`` (~2.6 ms of ~5.5 ms here), rebuilt at every call.

    python benchmarks/bench_online.py [--updates 300] [--replay-s 600]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy import signal as sps  # noqa: E402

from livesweep.spectral.online import OnlineSpectralEstimator  # noqa: E402

FS = 200.0
BAND = (1.0, 40.0)
WINDOW_S = 60.0
OVERLAP = 0.8
BLOCK = 40
N_IN, N_OUT = 4, 12


def make_data(seconds: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    sos_in = sps.butter(2, 45.0 / (2 * np.pi), fs=FS, output="sos")
    u = sps.sosfilt(sos_in, rng.standard_normal((N_IN, n)), axis=1)
    y = np.empty((N_OUT, n))
    for k in range(N_OUT):
        wn = (2.0 + 2.5 * k) / (2 * np.pi)
        b, a = sps.butter(2, min(wn, 0.4 * FS) , fs=FS)
        mix = rng.standard_normal(N_IN)
        y[k] = sps.lfilter(b, a, mix @ u) + 0.1 * rng.standard_normal(n)
    names = [f"u{i}" for i in range(N_IN)] + [f"y{k}" for k in range(N_OUT)]
    return names, np.vstack([u, y])


def scipy_from_scratch(x, names, n, hop):
    """csd / welch for the pairs the display needs, then coherence; in the band only at the end."""
    kw = dict(fs=FS, window="hann", nperseg=n, noverlap=n - hop, detrend="constant")
    inputs = names[:N_IN]
    outputs = names[N_IN:]
    sig = {nm: x[k] for k, nm in enumerate(names)}
    auto = {nm: sps.welch(sig[nm], **kw)[1] for nm in names}
    f, _ = sps.welch(sig[names[0]], **kw)
    k = (2 * np.pi * f >= BAND[0]) & (2 * np.pi * f <= BAND[1])
    coh = {}
    for i in inputs:
        for o in outputs:
            g = sps.csd(sig[i], sig[o], **kw)[1]
            coh[(o, i)] = np.abs(g[k]) ** 2 / (auto[i][k] * auto[o][k])
    for a in range(N_IN):
        for b in range(a + 1, N_IN):
            g = sps.csd(sig[inputs[a]], sig[inputs[b]], **kw)[1]
            coh[(inputs[a], inputs[b])] = np.abs(g[k]) ** 2 / (auto[inputs[a]][k] * auto[inputs[b]][k])
    return coh


def timed_updates(names, x, start, n_updates, with_responses):
    est = OnlineSpectralEstimator(names, names[:N_IN], names[N_IN:], FS, BAND, window_s=WINDOW_S, overlap=OVERLAP)
    est.update(x[:, :start])                       # fill the window
    if with_responses:
        est.result().ordinary
    times = []
    for j in range(n_updates):
        blk = x[:, start + j * BLOCK:start + (j + 1) * BLOCK]
        t0 = time.perf_counter()
        est.update(blk)
        if with_responses:
            r = est.result()
            r.ordinary
            r.input_coherence
        times.append(time.perf_counter() - t0)
    return est, np.array(times)


def replay(names, x, with_responses, block=BLOCK):
    est = OnlineSpectralEstimator(names, names[:N_IN], names[N_IN:], FS, BAND, window_s=WINDOW_S, overlap=OVERLAP)
    t0 = time.perf_counter()
    for k in range(0, x.shape[1], block):
        est.update(x[:, k:k + block])
        if with_responses:
            r = est.result()
            if r is not None:
                r.ordinary
                r.input_coherence
    return time.perf_counter() - t0, est


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--updates", type=int, default=300)
    ap.add_argument("--replay-s", type=float, default=600.0)
    ap.add_argument("--scipy-repeats", type=int, default=5)
    args = ap.parse_args()

    warm_s = WINDOW_S + 25.0
    need_s = max(args.replay_s, warm_s + args.updates * BLOCK / FS + 1.0)
    names, x = make_data(need_s)
    probe = OnlineSpectralEstimator(names, names[:N_IN], names[N_IN:], FS, BAND, window_s=WINDOW_S, overlap=OVERLAP)
    n, hop = probe.n, probe.hop
    print("settings")
    print(f"  signals            {N_IN} inputs x {N_OUT} outputs at {FS:g} Hz")
    print(f"  band               {BAND[0]:g}-{BAND[1]:g} rad/s, {probe.omega.size} chirp-z points "
          f"(spacing {probe.omega[1] - probe.omega[0]:.4f} rad/s)")
    print(f"  window             {WINDOW_S:g} s sliding; segments {probe.segment_s:.2f} s ({n} samples, "
          f"resolves from {3 * 2 * np.pi / probe.segment_s:.2f} rad/s), hop {hop} samples, overlap {OVERLAP:g}")
    print(f"  updates            blocks of {BLOCK} samples ({FS / BLOCK:g} updates/s)")

    start = int(warm_s * FS)
    est, t_upd = timed_updates(names, x, start, args.updates, with_responses=False)
    _, t_full = timed_updates(names, x, start, args.updates, with_responses=True)
    r = est.result()
    K = r.n_segments
    span = (K - 1) * hop + n
    s0 = int(r.segment_starts[0])
    seg_x = x[:, s0:s0 + span]
    scipy_from_scratch(seg_x, names, n, hop)        # warm-up
    ts = []
    for _ in range(args.scipy_repeats):
        t0 = time.perf_counter()
        scipy_from_scratch(seg_x, names, n, hop)
        ts.append(time.perf_counter() - t0)
    t_scipy = float(np.median(ts))

    def ms(v):
        return f"{1e3 * v:8.3f} ms"

    print(f"\nper update ({args.updates} updates after the window filled; {K} segments in the window, "
          f"n_eff {r.n_eff:.1f}; a new segment every {hop / BLOCK:.1f} updates)")
    print(f"  update only            median {ms(np.median(t_upd))}   p99 {ms(np.percentile(t_upd, 99))}   "
          f"max {ms(t_upd.max())}")
    print(f"  update + responses     median {ms(np.median(t_full))}   p99 {ms(np.percentile(t_full, 99))}   "
          f"max {ms(t_full.max())}")
    print(f"  scipy from scratch     {ms(t_scipy)}   (csd x {N_IN * N_OUT + N_IN * (N_IN - 1) // 2}, welch x "
          f"{N_IN + N_OUT}, coherence; {span / FS:.1f} s of data, {K} segments)")
    print(f"  ratio scipy / livesweep (update + responses): median {t_scipy / np.median(t_full):7.1f}x   "
          f"p99 {t_scipy / np.percentile(t_full, 99):7.1f}x   (target >= 20x)")
    print(f"  ratio scipy / livesweep (update only):        median {t_scipy / np.median(t_upd):7.1f}x   "
          f"p99 {t_scipy / np.percentile(t_upd, 99):7.1f}x")

    xr = x[:, :int(args.replay_s * FS)]
    t_rep, e1 = replay(names, xr, with_responses=False)
    t_rep2, _ = replay(names, xr, with_responses=True)
    print(f"\nreplay of {args.replay_s:g} s in {BLOCK}-sample blocks ({e1.n_segment_transforms} segments, "
          f"{e1.n_transform_calls} chirp-z calls, {e1.n_resyncs} resyncs)")
    print(f"  update only            {t_rep:7.3f} s  -> {args.replay_s / t_rep:8.0f}x real time   (target >= 100x)")
    print(f"  update + responses     {t_rep2:7.3f} s  -> {args.replay_s / t_rep2:8.0f}x real time   (responses at every block)")
    t_rep3, _ = replay(names, xr, with_responses=True, block=int(FS))
    print(f"  1 s blocks + responses {t_rep3:7.3f} s  -> {args.replay_s / t_rep3:8.0f}x real time   (one display refresh per data second)")


if __name__ == "__main__":
    main()
