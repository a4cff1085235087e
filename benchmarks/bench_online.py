#!/usr/bin/env python3
"""Live spectral monitoring cost against a competent incremental estimator measured in the same run
(single core).

Setting: 4 inputs x 12 outputs at 200 Hz, band 1-40 rad/s, 60 s sliding window, segments of
3 periods of the band's low end (18.85 s, the estimator's default), 80 % overlap, 5 updates per
second (blocks of 40 samples). Synthetic data: four independent band-limited inputs, outputs are
filtered mixtures of them plus noise.

A *refresh* is what a live display does per block: consume the block, then have the responses it
shows -- H, gamma^2 and eps_r of all 48 input/output pairs and the largest input cross-coherence.

1. livesweep: ``OnlineSpectralEstimator.update(block)``, then ``result()`` with ``.ordinary`` and
   ``.input_coherence``.
2. baseline, :class:`RunningRfft`: what a competent numpy/scipy user writes -- running sums of rfft
   bins. Every segment is transformed once when it completes (``scipy.signal.detrend``, the Hann
   taper, one ``numpy.fft.rfft`` call over all 16 signals (faster here than ``scipy.fft.rfft``),
   zero-padded to twice the segment or a little more for
   the same grid as livesweep's: ``scipy.fft.next_fast_len(2 n)`` points, kept at the bins of the
   band); the products the display needs
   (input x output, input x input, every autospectrum) are added to running sums, and subtracted
   when the segment leaves the window. Each refresh computes H, gamma^2, eps_r (bias-corrected
   coherence, Welch's equivalent averages) and the input coherence from the running sums. It is
   asserted to give livesweep's numbers (to 1e-9; eps_r to 1e-7).
3. per refresh over ``--updates`` refreshes after the window has filled (both estimators fed the
   same blocks, interleaved, so that both see the same machine load): median, p99 and max; also
   the median over the refreshes where a segment entered or left the window (the only ones where
   the responses change). Ratio livesweep / baseline (target <= 1, p99 too).
4. replay: 600 s fed as fast as possible in 40-sample blocks, update only and with a refresh at
   every block, and in 1 s blocks with refreshes -> multiple of real time (target >= 100x), for
   both.

    python benchmarks/bench_online.py [--updates 1000] [--replay-s 600]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from collections import deque  # noqa: E402

import numpy as np  # noqa: E402
import scipy.fft  # noqa: E402
from scipy import signal as sps  # noqa: E402

from livesweep.spectral.online import OnlineSpectralEstimator  # noqa: E402

FS = 200.0
BAND = (1.0, 40.0)
WINDOW_S = 60.0
OVERLAP = 0.8
BLOCK = 40
N_IN, N_OUT = 4, 12
RTOL = 1e-9
EPS_RTOL = 1e-7


def make_data(seconds: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    sos_in = sps.butter(2, 45.0 / (2 * np.pi), fs=FS, output="sos")
    u = sps.sosfilt(sos_in, rng.standard_normal((N_IN, n)), axis=1)
    y = np.empty((N_OUT, n))
    for k in range(N_OUT):
        wn = (2.0 + 2.5 * k) / (2 * np.pi)
        b, a = sps.butter(2, min(wn, 0.4 * FS), fs=FS)
        mix = rng.standard_normal(N_IN)
        y[k] = sps.lfilter(b, a, mix @ u) + 0.1 * rng.standard_normal(n)
    names = [f"u{i}" for i in range(N_IN)] + [f"y{k}" for k in range(N_OUT)]
    return names, np.vstack([u, y])


class RunningRfft:
    """Sliding-window H, gamma^2, eps_r and input coherence from running sums of rfft bins.

    Segments of ``n`` samples every ``hop`` samples from the first sample; those that end within
    the last ``window_s`` are averaged. Rows 0..n_in-1 of the blocks are the inputs.
    """

    def __init__(self, n_sig, n_in, fs, band, window_s, n, hop, pad=2):
        self.n_in, self.n, self.hop, self.W = n_in, n, hop, round(window_s * fs)
        self.taper = sps.get_window("hann", n)                     # periodic Hann
        self.nfft = scipy.fft.next_fast_len(pad * n, real=True)   # >= 2n, a fast length (same bins as livesweep)
        step = 2 * np.pi * fs / self.nfft
        self.k = slice(math.floor(band[0] / step + 1e-9), math.ceil(band[1] / step - 1e-9) + 1)
        self.omega = step * np.arange(self.k.start, self.k.stop)
        nf = self.omega.size
        self.buf = np.empty((n_sig, 4 * n))
        self.len = 0                 # samples in buf
        self.buf_start = 0           # stream index of buf[:, 0]
        self.next_start = 0          # stream index of the next segment
        self.consumed = 0
        self.segs = deque()          # (start, X (n_sig, nf))
        self.s_xy = np.zeros((n_in, n_sig - n_in, nf), complex)   # sum conj(X_in) X_out
        self.s_uu = np.zeros((n_in, n_in, nf), complex)            # sum conj(X_in) X_in
        self.s_auto = np.zeros((n_sig, nf))                         # sum |X|^2
        self.n_eff = {}

    def _accumulate(self, X, sign):
        xi = X[:self.n_in].conj()
        self.s_xy += sign * (xi[:, None, :] * X[None, self.n_in:, :])
        self.s_uu += sign * (xi[:, None, :] * X[None, :self.n_in, :])
        self.s_auto += sign * (X.real ** 2 + X.imag ** 2)

    def update(self, block):
        m = block.shape[1]
        if self.len + m > self.buf.shape[1]:                      # keep the tail from the next segment on
            drop = self.next_start - self.buf_start
            self.buf[:, :self.len - drop] = self.buf[:, drop:self.len]
            self.len -= drop
            self.buf_start = self.next_start
            if self.len + m > self.buf.shape[1]:
                grown = np.empty((self.buf.shape[0], 2 * (self.len + m)))
                grown[:, :self.len] = self.buf[:, :self.len]
                self.buf = grown
        self.buf[:, self.len:self.len + m] = block
        self.len += m
        self.consumed += m
        while self.next_start + self.n <= self.consumed:           # a segment completed
            a = self.next_start - self.buf_start
            seg = sps.detrend(self.buf[:, a:a + self.n], axis=-1, type="constant") * self.taper
            X = np.fft.rfft(seg, n=self.nfft, axis=-1)[:, self.k]
            self._accumulate(X, 1)
            self.segs.append((self.next_start, X))
            self.next_start += self.hop
        while self.segs and self.segs[0][0] + self.n <= self.consumed - self.W:
            self._accumulate(self.segs.popleft()[1], -1)

    def refresh(self):
        """H (n_out, n_in, f), gamma^2, eps_r and the largest input-input coherence (f,)."""
        K = len(self.segs)
        n_eff = self.n_eff.get(K)
        if n_eff is None:                       # Welch's equivalent averages for K overlapped segments
            w, w2 = self.taper, self.taper @ self.taper
            lags = np.arange(1, K) * self.hop
            lags = lags[lags < self.n]
            rho = np.array([(w[:-s] @ w[s:] / w2) ** 2 for s in lags])
            n_eff = self.n_eff[K] = K / (1 + 2 * np.sum((1 - np.arange(1, lags.size + 1) / K) * rho))
        sxx = self.s_auto[:self.n_in]
        syy = self.s_auto[self.n_in:]
        gxy = self.s_xy.transpose(1, 0, 2)                         # (n_out, n_in, f)
        H = gxy / sxx
        coh = np.clip((gxy.real ** 2 + gxy.imag ** 2) / (sxx * syy[:, None, :]), 0, 1)
        # eps_r with the few-averages bias of gamma^2 removed: g + (1 - g)^2 / n = coh
        disc = 1 - 4 * (1 - coh) / n_eff
        g = np.clip(1 - np.where(disc >= 0, 0.5 * n_eff * (1 - np.sqrt(np.clip(disc, 0, None))), 1), 0, 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            eps = np.where(g > 0, np.maximum(np.sqrt((1 - g) / (2 * n_eff * g)), 1e-6), np.inf)
        iu = np.triu_indices(self.n_in, 1)
        cu = self.s_uu[iu]
        incoh = np.max((cu.real ** 2 + cu.imag ** 2) / (sxx[iu[0]] * sxx[iu[1]]), axis=0)
        return H, coh, eps, incoh


def livesweep_estimator():
    return OnlineSpectralEstimator(NAMES, NAMES[:N_IN], NAMES[N_IN:], FS, BAND, window_s=WINDOW_S, overlap=OVERLAP)


def livesweep_refresh(est, blk):
    est.update(blk)
    r = est.result()
    if r is not None:
        r.ordinary
        r.input_coherence
    return r


def baseline_estimator(probe):
    return RunningRfft(len(NAMES), N_IN, FS, BAND, WINDOW_S, probe.n, probe.hop)


def baseline_refresh(est, blk):
    est.update(blk)
    return est.refresh() if est.segs else None


def check_same(r, b):
    """livesweep's result and the baseline's refresh are the same numbers."""
    H, coh, eps, incoh = b
    o = r.ordinary
    # eps_r is ill-conditioned where the bias-corrected coherence nears 0 (1 - 0.5 n (1 - sqrt(.))
    # cancels): rounding of gamma^2 there moves it by up to ~1e-9 relative, hence its own tolerance
    for name, a, ref, tol in (("H", o.H, H, RTOL), ("gamma^2", o.coherence, coh, RTOL),
                              ("eps_r", o.random_error, eps, EPS_RTOL),
                              ("input coherence", r.input_coherence, incoh, RTOL)):
        assert np.array_equal(np.isfinite(a), np.isfinite(ref)), name
        k = np.isfinite(ref)
        err = np.max(np.abs(a[k] - ref[k]) / np.abs(ref[k]))
        assert err < tol, (name, err)


def replay(make, refresh, x, block, with_responses):
    est = make()
    t0 = time.perf_counter()
    for k in range(0, x.shape[1], block):
        blk = x[:, k:k + block]
        if with_responses:
            refresh(est, blk)
        else:
            est.update(blk)
    return time.perf_counter() - t0


NAMES: list = []


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--updates", type=int, default=1000)
    ap.add_argument("--replay-s", type=float, default=600.0)
    args = ap.parse_args()

    warm_s = WINDOW_S + 25.0
    need_s = max(args.replay_s, warm_s + args.updates * BLOCK / FS + 1.0)
    names, x = make_data(need_s)
    NAMES[:] = names
    ls = livesweep_estimator()
    bl = baseline_estimator(ls)
    assert np.allclose(bl.omega, ls.omega, rtol=1e-12, atol=0), "the two estimators must use the same bins"
    print("settings")
    print(f"  signals            {N_IN} inputs x {N_OUT} outputs at {FS:g} Hz")
    print(f"  band               {BAND[0]:g}-{BAND[1]:g} rad/s, {ls.omega.size} bins of a {ls.n_fft}-point rfft "
          f"(spacing {ls.omega[1] - ls.omega[0]:.4f} rad/s)")
    print(f"  window             {WINDOW_S:g} s sliding; segments {ls.segment_s:.2f} s ({ls.n} samples, "
          f"resolves from {3 * 2 * np.pi / ls.segment_s:.2f} rad/s), hop {ls.hop} samples, overlap {OVERLAP:g}")
    print(f"  refreshes          blocks of {BLOCK} samples ({FS / BLOCK:g} per second)")

    start = int(warm_s * FS)
    livesweep_refresh(ls, x[:, :start])
    baseline_refresh(bl, x[:, :start])
    t_ls, t_bl, changed = [], [], []
    for j in range(args.updates):
        blk = x[:, start + j * BLOCK:start + (j + 1) * BLOCK]
        before = ls.n_segment_transforms, len(ls._segs)
        if j % 2:                                  # alternate who goes first (caches, block data)
            t0 = time.perf_counter()
            r = livesweep_refresh(ls, blk)
            t1 = time.perf_counter()
            b = baseline_refresh(bl, blk)
            t2 = time.perf_counter()
            t_ls.append(t1 - t0)
            t_bl.append(t2 - t1)
        else:
            t0 = time.perf_counter()
            b = baseline_refresh(bl, blk)
            t1 = time.perf_counter()
            r = livesweep_refresh(ls, blk)
            t2 = time.perf_counter()
            t_bl.append(t1 - t0)
            t_ls.append(t2 - t1)
        changed.append(0 if before == (ls.n_segment_transforms, len(ls._segs)) else
                       1 if before[0] != ls.n_segment_transforms else 2)     # 1: a segment entered, 2: one left
        if j % 50 == 0 or changed[-1]:
            check_same(r, b)
    t_ls, t_bl, changed = np.array(t_ls), np.array(t_bl), np.array(changed)
    entered, left = changed == 1, changed == 2
    r = ls.result()

    def ms(v):
        return f"{1e3 * v:6.3f} ms"

    def row(label, t):
        return (f"  {label:<24} median {ms(np.median(t))}  p99 {ms(np.percentile(t, 99))}  max {ms(t.max())}  "
                f"| median when a segment entered {ms(np.median(t[entered]))}, left {ms(np.median(t[left]))}")

    print(f"\nper refresh ({args.updates} refreshes after the window filled; {r.n_segments} segments in the window, "
          f"n_eff {r.n_eff:.1f}; a segment enters every {ls.hop / BLOCK:.1f} refreshes: {entered.sum()} entered, "
          f"{left.sum()} left)")
    print(row("livesweep", t_ls))
    print(row("baseline (running rfft)", t_bl))
    ratios = {"median": np.median(t_ls) / np.median(t_bl), "p99": np.percentile(t_ls, 99) / np.percentile(t_bl, 99)}
    more = {"entered": np.median(t_ls[entered]) / np.median(t_bl[entered]),
            "left": np.median(t_ls[left]) / np.median(t_bl[left])}
    print("  ratio livesweep / baseline: " + "   ".join(f"{k} {v:5.2f}" for k, v in ratios.items())
          + f"   (target <= 1: {'OK' if max(ratios.values()) <= 1 else 'MISSED'});   medians when a segment "
          + ", ".join(f"{k} {v:5.2f}" for k, v in more.items()))
    print(f"  same numbers: H, gamma^2, input coherence agree to < {RTOL:g}, eps_r to < {EPS_RTOL:g} (checked on "
          f"{int((changed > 0).sum() + args.updates // 50)} refreshes)")

    xr = x[:, :int(args.replay_s * FS)]
    print(f"\nreplay of {args.replay_s:g} s (target >= 100x real time)")
    for label, block, resp in (("40-sample blocks, update only", BLOCK, False),
                               ("40-sample blocks, refresh each", BLOCK, True),
                               ("1 s blocks, refresh each", int(FS), True)):
        t1 = replay(livesweep_estimator, livesweep_refresh, xr, block, resp)
        t2 = replay(lambda: baseline_estimator(ls), baseline_refresh, xr, block, resp)
        print(f"  {label:<32} livesweep {t1:6.3f} s ({args.replay_s / t1:6.0f}x)   baseline {t2:6.3f} s "
              f"({args.replay_s / t2:6.0f}x)   ratio {t1 / t2:5.2f}")


if __name__ == "__main__":
    main()
