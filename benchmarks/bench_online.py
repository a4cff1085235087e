#!/usr/bin/env python3
"""Live spectral monitoring cost against a competent, memoised running-sum estimator measured in the
same run (single core), like for like.

Setting: 4 inputs x 12 outputs at 200 Hz, band 1-40 rad/s, 60 s sliding window, segments of
3 periods of the band's low end (18.85 s, the estimator's default), 80 % overlap, 5 updates per
second (blocks of 40 samples). Synthetic data: four independent band-limited inputs, outputs are
filtered mixtures of them plus noise.

A *refresh* is what a live display does per block: consume the block, then have the responses it
shows for all 48 input/output pairs and the largest input cross-coherence, either

* **ordinary**: H, gamma^2 and eps_r (SISO, H1), or
* **MISO**: the conditioned H, partial coherence, multiple coherence, eps_r (``n_eff - q + 1``
  averages) and the ill-conditioned flags -- what the monitor shows with several inputs.

1. livesweep: ``OnlineSpectralEstimator.update(block)``, then ``result()`` with ``.ordinary`` (or
   ``.conditioned``) and ``.input_coherence``.
2. baseline, :class:`RunningRfft`: what a competent numpy/scipy user writes -- running sums of rfft
   bins, with the responses memoised. Every segment is transformed once when it completes (mean
   removed, the Hann taper, one ``numpy.fft.rfft`` call over all 16 signals (faster here than
   ``scipy.fft.rfft``), zero-padded to ``scipy.fft.next_fast_len(2 n)`` points -- the same grid as
   livesweep's -- kept at the bins of the band); the products the responses need (every input
   row of the spectral matrix, every autospectrum) are added in place to running sums, and
   subtracted when the segment leaves the window. A refresh computes the responses from the
   running sums only when a segment entered or left since the last one, and otherwise returns its
   memo. The MISO responses are vectorised over outputs and frequencies with the block inverse:
   one ``numpy.linalg.inv`` of the 4x4 input coherence matrix per frequency, shared by the 12
   outputs (Schur complement), instead of inverting each 5x5 (inputs, output) block. It has no
   drift guard and no gap, quiet-signal or singular-matrix handling (livesweep pays for those).
   It is asserted to give livesweep's numbers (H to 1e-9 relative, coherences to 1e-9, eps_r to
   1e-7 relative -- the conditioned one where the partial coherence exceeds 1e-6; ill flags equal).
3. per refresh over ``--updates`` blocks after the window has filled, four estimators fed the same
   blocks (livesweep and baseline, ordinary and MISO; the order rotates from block to block so that
   all see the same machine load), split by what the block did:

   * *cached vs cached* -- no segment entered or left (most blocks): livesweep's refresh against
     the baseline's update plus its memo;
   * *changed vs changed* -- a segment entered (a transform, running sums, responses recomputed)
     or left (running sums, responses recomputed): livesweep's update and responses against the
     baseline's update and responses.

   Median of each and the ratio livesweep / baseline (target <= 1); for *changed* the sum of the
   two medians (entered + left: what each hop of the window costs); p99 over all blocks. The
   summary gives the ratios of wall time and, beside them, of this process's CPU time
   (``time.process_time``), which other processes on a shared machine disturb less.
4. replay: 600 s fed as fast as possible in 40-sample blocks, update only and with a refresh at
   every block (ordinary and MISO), and in 1 s blocks with refreshes -> multiple of real time
   (target >= 100x), for both.

    python benchmarks/bench_online.py [--updates 2000] [--replay-s 600]
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
MAX_INPUT_COHERENCE = 0.5
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


def random_error(coh, n_eff):
    """eps_r with the few-averages bias of gamma^2 removed (Bendat & Piersol), cancellation-free:
    with u = 1 - coh and d = sqrt(1 - 4 u / n), eps_r^2 = u / (n (1 + d - 2 u)); floor 1e-6, inf
    where the bias-corrected coherence is 0."""
    u = 1.0 - coh
    den = n_eff * (1.0 + np.sqrt(np.clip(1.0 - 4.0 * u / n_eff, 0.0, None)) - 2.0 * u)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, np.maximum(np.sqrt(u / den), 1e-6), np.inf)


class RunningRfft:
    """Sliding-window responses from running sums of rfft bins, memoised until the window changes.

    Segments of ``n`` samples every ``hop`` samples from the first sample; those that end within
    the last ``window_s`` are averaged. Rows 0..n_in-1 of the blocks are the inputs.
    """

    def __init__(self, n_sig, n_in, fs, band, window_s, n, hop, pad=2, max_input_coherence=MAX_INPUT_COHERENCE):
        self.n_in, self.n, self.hop, self.W = n_in, n, hop, round(window_s * fs)
        self.max_input_coherence = max_input_coherence
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
        self.s_rows = np.zeros((n_in, n_sig, nf), complex)        # sum conj(X_in) X_j, every signal j
        self.s_auto = np.zeros((n_sig, nf))                         # sum |X|^2
        self.version = 0             # bumped whenever a segment enters or leaves
        self.memo = {}               # response kind -> (version, responses)
        self.n_eff = {}

    def _accumulate(self, X, sign):
        c = X[:self.n_in].conj()[:, None, :] * X[None, :, :]
        a = X.real ** 2 + X.imag ** 2
        if sign > 0:
            self.s_rows += c
            self.s_auto += a
        else:
            self.s_rows -= c
            self.s_auto -= a

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
            seg = self.buf[:, a:a + self.n]
            seg = (seg - seg.mean(axis=-1, keepdims=True)) * self.taper
            X = np.fft.rfft(seg, n=self.nfft, axis=-1)[:, self.k]
            self._accumulate(X, 1)
            self.segs.append((self.next_start, X))
            self.next_start += self.hop
            self.version += 1
        while self.segs and self.segs[0][0] + self.n <= self.consumed - self.W:
            self._accumulate(self.segs.popleft()[1], -1)
            self.version += 1

    def _memoised(self, kind, compute):
        hit = self.memo.get(kind)
        if hit is not None and hit[0] == self.version:
            return hit[1]
        value = compute()
        self.memo[kind] = (self.version, value)
        return value

    def _neff(self):
        K = len(self.segs)
        n_eff = self.n_eff.get(K)
        if n_eff is None:                       # Welch's equivalent averages for K overlapped segments
            w, w2 = self.taper, self.taper @ self.taper
            lags = np.arange(1, K) * self.hop
            lags = lags[lags < self.n]
            rho = np.array([(w[:-s] @ w[s:] / w2) ** 2 for s in lags])
            n_eff = self.n_eff[K] = K / (1 + 2 * np.sum((1 - np.arange(1, lags.size + 1) / K) * rho))
        return n_eff

    def input_coherence(self):
        """Largest input-input ordinary coherence per frequency."""
        def compute():
            q, sxx = self.n_in, self.s_auto[:self.n_in]
            a, b = np.triu_indices(q, 1)
            cu = self.s_rows[a, b]
            return np.max((cu.real ** 2 + cu.imag ** 2) / (sxx[a] * sxx[b]), axis=0)
        return self._memoised("input coherence", compute)

    def refresh(self):
        """Ordinary responses: H, gamma^2, eps_r (n_out, n_in, f), and the input coherence (f,)."""
        def compute():
            q, n_eff = self.n_in, self._neff()
            sxx, syy = self.s_auto[:q], self.s_auto[q:]
            gxy = self.s_rows[:, q:].transpose(1, 0, 2)             # (n_out, n_in, f)
            H = gxy * (1.0 / sxx)
            coh = np.clip((gxy.real ** 2 + gxy.imag ** 2) / (sxx * syy[:, None, :]), 0, 1)
            return H, coh, random_error(coh, n_eff)
        return self._memoised("ordinary", compute) + (self.input_coherence(),)

    def refresh_conditioned(self):
        """MISO responses: H, partial coherence, eps_r (n_out, n_in, f), multiple coherence
        (n_out, f), ill-conditioned flags (f,), and the input coherence (f,)."""
        def compute():
            q, n_eff = self.n_in, self._neff()
            n_out, nf = self.s_auto.shape[0] - q, self.omega.size
            if len(self.segs) < q + 1:                              # rank < q + 1: nothing to condition yet
                return (np.full((n_out, q, nf), np.nan + 0j), np.zeros((n_out, q, nf)),
                        np.full((n_out, q, nf), np.inf), np.zeros((n_out, nf)), np.ones(nf, bool))
            d = np.sqrt(self.s_auto[:q]).T                          # (f, q)
            dy = np.sqrt(self.s_auto[q:]).T                         # (f, n_out)
            Cxx = np.moveaxis(self.s_rows[:, :q], -1, 0) / (d[:, :, None] * d[:, None, :])   # (f, q, q)
            P = np.linalg.inv(Cxx)
            R = np.moveaxis(self.s_rows[:, q:], -1, 0) / (d[:, :, None] * dy[:, None, :])    # (f, q, n_out)
            b = P @ R                                               # Cxx^-1 r for every output
            mc = np.einsum("fio,fio->fo", R.conj(), b).real         # multiple coherence r^H Cxx^-1 r
            b2 = b.real ** 2 + b.imag ** 2
            # partial coherence |C_iy|^2 / (C_ii C_yy) of the (inputs, output) block's inverse C:
            # C_yy = 1 / (1 - mc), C_iy = -b_i C_yy, C_ii = P_ii + b2_i C_yy
            pc = b2 / ((1.0 - mc)[:, None, :] * np.diagonal(P, axis1=1, axis2=2).real[:, :, None] + b2)
            H = (b * (dy[:, None, :] / d[:, :, None])).transpose(2, 1, 0)
            pc = np.clip(pc, 0, 1).transpose(2, 1, 0)
            ill = self.input_coherence() > self.max_input_coherence
            return H, pc, random_error(pc, n_eff - q + 1), np.clip(mc, 0, 1).T, ill
        return self._memoised("conditioned", compute) + (self.input_coherence(),)


def livesweep_estimator():
    return OnlineSpectralEstimator(NAMES, NAMES[:N_IN], NAMES[N_IN:], FS, BAND, window_s=WINDOW_S, overlap=OVERLAP,
                                   max_input_coherence=MAX_INPUT_COHERENCE)


def livesweep_refresh(est, blk):
    est.update(blk)
    r = est.result()
    if r is not None:
        r.ordinary
        r.input_coherence
    return r


def livesweep_refresh_miso(est, blk):
    est.update(blk)
    r = est.result()
    if r is not None:
        r.conditioned
        r.input_coherence
    return r


def baseline_estimator(probe):
    return RunningRfft(len(NAMES), N_IN, FS, BAND, WINDOW_S, probe.n, probe.hop)


def baseline_refresh(est, blk):
    est.update(blk)
    return est.refresh() if est.segs else None


def baseline_refresh_miso(est, blk):
    est.update(blk)
    return est.refresh_conditioned() if est.segs else None


def _close(name, a, ref, tol, relative=True):
    assert np.array_equal(np.isfinite(a), np.isfinite(ref)), name
    k = np.isfinite(ref)
    err = np.abs(a[k] - ref[k])
    if relative:
        err = err / np.abs(ref[k])
    assert err.max() < tol, (name, err.max())


def check_same(r, b):
    """livesweep's ordinary responses and the baseline's refresh are the same numbers."""
    H, coh, eps, incoh = b
    o = r.ordinary
    # eps_r is ill-conditioned where the bias-corrected coherence nears 0: rounding of gamma^2 there
    # moves it by up to ~1e-9 relative, hence its own tolerance
    _close("H", o.H, H, RTOL)
    _close("gamma^2", o.coherence, coh, RTOL, relative=False)
    _close("eps_r", o.random_error, eps, EPS_RTOL)
    _close("input coherence", r.input_coherence, incoh, RTOL, relative=False)


def check_same_miso(r, b):
    """livesweep's conditioned responses and the baseline's MISO refresh are the same numbers."""
    H, pc, eps, mc, ill, incoh = b
    c = r.conditioned
    _close("conditioned H", c.H, H, RTOL)
    _close("partial coherence", c.coherence, pc, RTOL, relative=False)
    _close("multiple coherence", c.multiple_coherence, mc, RTOL, relative=False)
    k = pc > 1e-6                          # eps_r of a near-zero partial coherence: relative rounding of pc
    _close("conditioned eps_r", c.random_error[k], eps[k], EPS_RTOL)
    assert np.array_equal(c.ill_conditioned, ill), "ill-conditioned flags"
    _close("input coherence", r.input_coherence, incoh, RTOL, relative=False)


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
    ap.add_argument("--updates", type=int, default=2000)
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

    # (label, livesweep estimator, its refresh, baseline estimator, its refresh, check)
    kinds = [("ordinary", ls, livesweep_refresh, bl, baseline_refresh, check_same),
             ("MISO", livesweep_estimator(), livesweep_refresh_miso, baseline_estimator(ls), baseline_refresh_miso,
              check_same_miso)]
    start = int(warm_s * FS)
    for _, e1, f1, e2, f2, _ in kinds:
        f1(e1, x[:, :start])
        f2(e2, x[:, :start])
    runners = [(k, side, est, fn) for k, (_, e1, f1, e2, f2, _) in enumerate(kinds)
               for side, est, fn in ((0, e1, f1), (1, e2, f2))]
    times = np.zeros((len(kinds), 2, args.updates))          # wall
    cpu = np.zeros((len(kinds), 2, args.updates))            # this process's CPU time
    changed = np.zeros(args.updates, int)
    n_checked = 0
    for j in range(args.updates):
        blk = x[:, start + j * BLOCK:start + (j + 1) * BLOCK]
        before = ls.n_segment_transforms, len(ls._segs)
        out = {}
        for i in range(len(runners)):               # rotate who goes first (caches, block data)
            k, side, est, fn = runners[(i + j) % len(runners)]
            c0, t0 = time.process_time(), time.perf_counter()
            out[k, side] = fn(est, blk)
            times[k, side, j] = time.perf_counter() - t0
            cpu[k, side, j] = time.process_time() - c0
        changed[j] = (0 if before == (ls.n_segment_transforms, len(ls._segs)) else
                      1 if before[0] != ls.n_segment_transforms else 2)     # 1: a segment entered, 2: one left
        if j % 50 == 0 or changed[j]:
            for k, (*_, check) in enumerate(kinds):
                check(out[k, 0], out[k, 1])
            n_checked += 1
    r = ls.result()
    sel = {"cached": changed == 0, "entered": changed == 1, "left": changed == 2}

    def ms(v):
        return f"{1e3 * v:6.3f} ms"

    print(f"\nper refresh ({args.updates} refreshes after the window filled; {r.n_segments} segments in the window, "
          f"n_eff {r.n_eff:.1f}; a segment enters every {ls.hop / BLOCK:.1f} refreshes: {sel['entered'].sum()} "
          f"entered, {sel['left'].sum()} left, {sel['cached'].sum()} nothing changed)")
    print(f"  {'':<30}{'nothing changed':>17}{'segment entered':>17}{'segment left':>17}{'p99 (all)':>13}")
    summary = []
    for k, (label, *_) in enumerate(kinds):
        med = {s: np.median(times[k][:, m], axis=-1) for s, m in sel.items()}
        p99 = np.percentile(times[k], 99, axis=-1)
        for side, who in ((0, "livesweep"), (1, "baseline (memoised sums)")):
            print(f"  {label + ' ' + who:<30}{ms(med['cached'][side]):>17}{ms(med['entered'][side]):>17}"
                  f"{ms(med['left'][side]):>17}{ms(p99[side]):>13}")
        rat = {s: v[0] / v[1] for s, v in med.items()}
        # a segment change: one segment enters and one leaves per hop, so the pair of medians
        cyc = med["entered"] + med["left"]
        rat["changed"] = cyc[0] / cyc[1]
        print(f"  {label + ' ratio livesweep/baseline':<30}{rat['cached']:>17.2f}{rat['entered']:>17.2f}"
              f"{rat['left']:>17.2f}{p99[0] / p99[1]:>13.2f}")
        mc = {s: np.median(cpu[k][:, m], axis=-1) for s, m in sel.items()}
        cyc = mc["entered"] + mc["left"]
        rat_cpu = {"cached": mc["cached"][0] / mc["cached"][1], "changed": cyc[0] / cyc[1]}
        summary.append((label, rat, rat_cpu))
    print("\n  like for like, ratio livesweep / baseline (target <= 1): cached = median over the blocks where nothing "
          "changed;\n  changed = (median when a segment entered + median when one left), the cost of the two changes "
          "every hop brings;\n  wall time, and in brackets this process's CPU time (steadier when other processes "
          "share the cores)")
    for label, rat, rc in summary:
        print(f"    {label:<9} cached vs cached {rat['cached']:5.2f} ({rc['cached']:5.2f}) "
              f"{'OK' if rat['cached'] <= 1 else 'MISSED'}   changed vs changed {rat['changed']:5.2f} "
              f"({rc['changed']:5.2f}) {'OK' if rat['changed'] <= 1 else 'MISSED'}")
    print(f"  same numbers: H to < {RTOL:g} relative, (partial, multiple, input) coherences to < {RTOL:g}, eps_r to "
          f"< {EPS_RTOL:g} relative, equal ill flags (checked on {n_checked} refreshes)")

    xr = x[:, :int(args.replay_s * FS)]
    print(f"\nreplay of {args.replay_s:g} s (target >= 100x real time)")
    for label, block, resp, f1, f2 in (("40-sample blocks, update only", BLOCK, False, None, None),
                                       ("40-sample blocks, refresh each", BLOCK, True, livesweep_refresh,
                                        baseline_refresh),
                                       ("40-sample blocks, MISO each", BLOCK, True, livesweep_refresh_miso,
                                        baseline_refresh_miso),
                                       ("1 s blocks, refresh each", int(FS), True, livesweep_refresh,
                                        baseline_refresh)):
        t1 = replay(livesweep_estimator, f1, xr, block, resp)
        t2 = replay(lambda: baseline_estimator(ls), f2, xr, block, resp)
        print(f"  {label:<32} livesweep {t1:6.3f} s ({args.replay_s / t1:6.0f}x)   baseline {t2:6.3f} s "
              f"({args.replay_s / t2:6.0f}x)   ratio {t1 / t2:5.2f}")


if __name__ == "__main__":
    main()
