#!/usr/bin/env python3
"""Spectral analysis speed, as ratios against baselines measured in the same run (single core).

On the XV-15 cruise case (``config/xv15_cruise_lateral.toml``: 2 inputs x 4 outputs, windows
7/12/20/40/80 s, band 0.3-20 rad/s, 50 Hz, ~434 s):

1. log reading: ``load_record`` (MCAP -> signals -> 50 Hz record), timed on its own;
2. ``analyze``: every window, SISO and MISO, composite;
3. floor: the bare chirp-z transforms of the same tapered segments on the same grids
   (``segment_transforms`` per window with the plan and grid ``window_spectra`` uses; plans,
   tapers and grids are built outside the timing) -> ratio analyze / floor (target <= 3);
4. scipy: the same result as a straightforward scipy user would get it: per window,
   ``scipy.signal.csd`` for every needed pair (inputs x outputs, input x input, every
   auto-spectrum), nperseg = window samples, 80 % overlap; 2-input conditioning by
   ``np.linalg.solve`` at every FFT bin inside the band (one batched call per output); an
   inverse-variance composite of the per-window responses on a common log grid with ``np.interp``
   -> ratio analyze / scipy (target < 1);
5. the end-to-end frequency-response stage of ``livesweep identify``
   (``run_frequency_response_stage``), which includes log reading.

Times are the best of ``--repeats`` runs (default 5; 3 for the log reading and the stage).

    python benchmarks/bench_spectral.py [--repeats 5]
"""

from __future__ import annotations

import os

# single core: set before numpy is imported anywhere
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import signal as sps  # noqa: E402

from livesweep.config import load_case  # noqa: E402
from livesweep.pipeline.frequency_response import load_record, run_frequency_response_stage  # noqa: E402
from livesweep.spectral.analysis import analyze  # noqa: E402
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW  # noqa: E402
from livesweep.spectral.transform import segment_transforms, uniform_grid  # noqa: E402
from livesweep.spectral.windows import hann, plan_segments  # noqa: E402

CASE = Path(__file__).resolve().parents[1] / "config" / "xv15_cruise_lateral.toml"


def best_of(fn, n):
    times, out = [], None
    for _ in range(n):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def scipy_composite(x, names, fs, inputs, outputs, band, windows_s, overlap, n_freq):
    """The scipy.signal route to the same SISO + MISO composite responses.

    Returns (omega, H_siso (n_out, n_in, n_f), H_miso (n_out, n_in, n_f)).
    """
    sig = {n: x[k] for k, n in enumerate(names)}
    omega = np.geomspace(band[0], band[1], n_freq)
    q = len(inputs)
    shape = (len(outputs), q, n_freq)
    num_s, den_s = np.zeros(shape, complex), np.zeros(shape)
    num_m, den_m = np.zeros(shape, complex), np.zeros(shape)
    for w_s in windows_s:
        n = int(round(w_s * fs))
        hop = max(1, int(round((1 - overlap) * n)))
        kw = dict(fs=fs, window="hann", nperseg=n, noverlap=n - hop, detrend="constant")
        n_avg = (x.shape[1] - n) // hop + 1
        f, _ = sps.welch(sig[inputs[0]], **kw)
        w = 2 * np.pi * f
        k = (w >= band[0]) & (w <= band[1])
        w = w[k]
        auto = {a: sps.welch(sig[a], **kw)[1][k] for a in [*inputs, *outputs]}
        cross = {(a, b): sps.csd(sig[a], sig[b], **kw)[1][k]
                 for ia, a in enumerate(inputs) for b in [*inputs[ia + 1:], *outputs]}
        Gxx = np.empty((w.size, q, q), complex)
        for i, a in enumerate(inputs):
            Gxx[:, i, i] = auto[a]
            for j in range(i + 1, q):
                Gxx[:, i, j] = cross[(a, inputs[j])]
                Gxx[:, j, i] = np.conj(cross[(a, inputs[j])])
        usable = (omega >= max(w[0], MIN_PERIODS_PER_WINDOW * 2 * np.pi / w_s)) & (omega <= w[-1])
        for o, out in enumerate(outputs):
            g = np.stack([cross[(a, out)] for a in inputs], axis=1)            # (n_f, q)
            # SISO: H1 and ordinary coherence per pair
            for i, a in enumerate(inputs):
                H = g[:, i] / auto[a]
                coh = np.clip(np.abs(g[:, i]) ** 2 / (auto[a] * auto[out]), 1e-12, 1 - 1e-12)
                eps2 = (1 - coh) / (coh * 2 * n_avg)
                Hi = np.interp(omega, w, H.real) + 1j * np.interp(omega, w, H.imag)
                Wi = np.where(usable, 1.0 / np.interp(omega, w, eps2), 0.0)
                num_s[o, i] += Wi * Hi
                den_s[o, i] += Wi
            # MISO: H = Gxx^-1 g per frequency, multiple coherence 1 - Gnn / Gyy
            H = np.linalg.solve(Gxx, g[..., None])[..., 0]                     # (n_f, q)
            explained = np.real(np.einsum("fi,fi->f", np.conj(g), H))
            mc = np.clip(explained / auto[out], 1e-12, 1 - 1e-12)
            eps2 = (1 - mc) / (mc * 2 * max(n_avg - q + 1, 1))
            Wi = np.where(usable, 1.0 / np.interp(omega, w, eps2), 0.0)
            for i in range(q):
                Hi = np.interp(omega, w, H[:, i].real) + 1j * np.interp(omega, w, H[:, i].imag)
                num_m[o, i] += Wi * Hi
                den_m[o, i] += Wi
    with np.errstate(divide="ignore", invalid="ignore"):
        return omega, num_s / den_s, num_m / den_m


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5, help="repetitions of the fast timings (best is kept)")
    args = ap.parse_args()
    reps, reps_slow = args.repeats, max(1, min(3, args.repeats))

    case = load_case(CASE)
    sp = case.spectral
    names = list(dict.fromkeys([*sp.inputs, *sp.outputs]))
    fs = sp.sample_rate_hz
    t_read, record = best_of(lambda: load_record(case, case.identify, names, fs), reps_slow)
    rows = [record.names.index(n) for n in names]
    x = np.ascontiguousarray(record.values[rows])
    valid = np.all(record.valid[rows], axis=0)
    dur = record.n_samples / fs

    def run_analyze():
        return analyze(x, names, fs, sp.inputs, sp.outputs, sp.band_rad_s, valid=valid,
                       windows_s=sp.windows_s, overlap=sp.overlap, n_freq=sp.n_freq)

    t_an, res = best_of(run_analyze, reps)

    # the floor: the same CZTs window_spectra computes, nothing else
    jobs = []
    for w_s in sp.windows_s:
        n = int(round(w_s * fs))
        plan = plan_segments(x.shape[1], n, sp.overlap, valid)
        jobs.append((plan.starts, n, hann(n), uniform_grid(sp.band_rad_s[0], sp.band_rad_s[1], w_s, 2.0)))
    for (starts, n, _, om), ws in zip(jobs, res.windows):
        assert np.array_equal(om, ws.omega) and starts.size == ws.n_segments

    def floor():
        return [segment_transforms(x, starts, n, taper, om, fs) for starts, n, taper, om in jobs]

    t_floor, _ = best_of(floor, reps)

    t_sp, (om_sp, H_sp, Hm_sp) = best_of(
        lambda: scipy_composite(x, names, fs, list(sp.inputs), list(sp.outputs), sp.band_rad_s, sp.windows_s,
                                sp.overlap, sp.n_freq), reps)

    t_stage, _ = best_of(lambda: run_frequency_response_stage(load_case(CASE)), reps_slow)

    # sanity: the scipy route computes the same responses (differences: FFT bins vs CZT grid,
    # composite of H vs composite of spectra). NaN where no FFT bin brackets a point (band edges).
    assert np.allclose(om_sp, res.siso.omega)
    with np.errstate(divide="ignore", invalid="ignore"):
        sel_s = (res.siso.coherence >= 0.6) & np.isfinite(H_sp)
        sel_m = (res.miso.coherence >= 0.6) & np.isfinite(Hm_sp)
        d_siso = np.abs(20 * np.log10(np.abs(H_sp[sel_s] / res.siso.H[sel_s])))
        d_miso = np.abs(20 * np.log10(np.abs(Hm_sp[sel_m] / res.miso.H[sel_m])))
        p_miso = np.abs(np.angle(Hm_sp[sel_m] / res.miso.H[sel_m], deg=True))

    n_seg = sum(ws.n_segments for ws in res.windows)
    n_czt = sum(ws.n_segments * ws.omega.size for ws in res.windows)
    print(f"XV-15 cruise lateral: {len(sp.inputs)} inputs x {len(sp.outputs)} outputs, {record.n_samples} samples "
          f"({dur:.1f} s at {fs:g} Hz, {len(record.joins) + 1} records), windows {list(sp.windows_s)} s, "
          f"band {list(sp.band_rad_s)} rad/s")
    print(f"single core: OMP/OPENBLAS/MKL_NUM_THREADS=1 (machine has {os.cpu_count()} CPUs); numpy {np.__version__}; "
          f"best of {reps} ({reps_slow} for log reading and stage)")
    print(f"{n_seg} segments, {len(names)} signals, {n_czt} segment-frequency points per signal")
    print()
    print(f"{'step':<44}{'time [ms]':>11}{'ratio':>9}  target")
    print(f"{'log reading (load_record)':<44}{t_read * 1e3:11.1f}")
    print(f"{'analyze (5 windows, SISO+MISO, composite)':<44}{t_an * 1e3:11.1f}")
    print(f"{'floor: bare segment_transforms (CZT)':<44}{t_floor * 1e3:11.1f}{t_an / t_floor:9.2f}  "
          f"analyze/floor <= 3   {'OK' if t_an / t_floor <= 3 else 'MISSED'}")
    print(f"{'scipy.signal csd + solve + composite':<44}{t_sp * 1e3:11.1f}{t_an / t_sp:9.2f}  "
          f"analyze/scipy < 1    {'OK' if t_an / t_sp < 1 else 'MISSED'}")
    print(f"{'identify, frequency-response stage':<44}{t_stage * 1e3:11.1f}{t_stage / t_read:9.2f}  "
          f"(stage / log reading)")
    print(f"{'  of which not log reading nor analyze':<44}{(t_stage - t_read - t_an) * 1e3:11.1f}"
          f"{'':9}  (wild points, trim, kinematic checks, adequacy)")
    print()
    print(f"scipy route vs analyze where gamma^2 >= 0.6 ({sel_s.sum()} SISO, {sel_m.sum()} MISO points): SISO |dB| median {np.median(d_siso):.3f} "
          f"(95 % {np.percentile(d_siso, 95):.3f}); MISO |dB| median {np.median(d_miso):.3f} "
          f"(95 % {np.percentile(d_miso, 95):.3f}), phase median {np.median(p_miso):.2f} deg")


if __name__ == "__main__":
    main()
