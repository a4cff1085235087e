#!/usr/bin/env python3
"""XV-15 cruise state-space fit (8 pairs, 17 parameters, CR bounds) against a time-domain
output-error fit of the same model on the same data, both measured in this run on one core.

The frequency-domain fit (livesweep, ``fit_state_space``) works on 8 pairs x 20 frequencies (320
residuals). The output-error fit simulates the model over the whole identification record (434 s
at 50 Hz, 4 outputs: 86 800 residuals) for every cost and Jacobian evaluation (scipy
``least_squares``, finite differences), with state biases and output reference shifts estimated
alongside, as a time-domain fit must (the seed's key feature 6).

The output-error simulation is the competent one (:func:`simulate_modal`): the model discretised
once per evaluation (first-order hold, one matrix exponential), the discrete state matrix
diagonalised, and every mode run through ``scipy.signal.lfilter`` (a first-order recursion in C)
instead of a per-sample Python loop. It is checked against ``livesweep.ident.verify.simulate_response``
(same outputs to 1e-7 of their range), and the output-error fit it drives is checked against the
same fit driven by ``simulate_response`` (same cost to 1e-8, same unknowns to 1e-3), which is
also timed (``--skip-loop`` leaves that out).

    python benchmarks/bench_state_space.py [--repeats 3] [--skip-loop]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.linalg import expm  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402
from scipy.signal import lfilter  # noqa: E402

from livesweep.config import load_case  # noqa: E402
from livesweep.ident.state_space import StateSpaceModel, fit_state_space, select_pairs  # noqa: E402
from livesweep.ident.verify import simulate_response  # noqa: E402
from livesweep.stages.frequency_response import load_record, run_frequency_response_stage  # noqa: E402
from livesweep.sim.models import xv15_cruise  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SIM_RTOL = 1e-7            # simulations agree to this fraction of each output's range (rounding over 21 700 steps)
FIT_RTOL = 1e-3            # output-error fits on either simulation agree to this (relative)
FIT_BUDGET_S = 5.0         # the frequency-domain fit (8 pairs, 17 parameters, CR bounds) stays under this


def simulate_modal(M, F, G, H, J, tau_s, dt, u, bias):
    """Outputs of ``M x' = F x + G u(t - tau) + bias``, ``y = H x + J u(t - tau)`` from x(0) = 0.

    First-order hold (inputs linear between samples) through one matrix exponential, fractional
    input delays by linear interpolation (first sample held), then the recursion
    ``x[k+1] = Phi x[k] + d[k]`` in the eigenbasis of ``Phi``: one ``lfilter`` per mode.
    """
    n = F.shape[0]
    Minv = np.linalg.inv(M)
    B = np.hstack([Minv @ G, Minv])                     # inputs and the state biases
    q = B.shape[1]
    Z = np.zeros((n + 2 * q, n + 2 * q))
    Z[:n, :n] = Minv @ F * dt
    Z[:n, n:n + q] = B * dt
    Z[n:n + q, n + q:] = np.eye(q)
    E = expm(Z)
    Phi, Ga, Gb = E[:n, :n], E[:n, n:n + q], E[:n, n + q:]
    N = u.shape[1]
    k = np.arange(N, dtype=float)
    ud = np.vstack([np.interp(k - t / dt, k, row) for row, t in zip(u, tau_s)])
    w = np.vstack([ud, np.repeat(np.asarray(bias, float)[:, None], N, axis=1)])
    lam, V = np.linalg.eig(Phi)
    d = np.linalg.solve(V, (Ga - Gb) @ w[:, :-1] + Gb @ w[:, 1:])      # modal drive (n, N-1)
    z = np.zeros((n, N), complex)
    for i in range(n):
        z[i, 1:] = lfilter([1.0], [1.0, -lam[i]], d[i])
    return H @ (V @ z).real + J @ ud


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="repetitions of the frequency-domain fit (best kept)")
    ap.add_argument("--skip-loop", action="store_true", help="do not run the output-error fit on the per-sample loop")
    args = ap.parse_args()

    case = load_case(ROOT / "config" / "xv15_cruise_lateral.toml")
    frs = run_frequency_response_stage(case).analysis.best
    model = StateSpaceModel.from_table(case.tables["state_space"], where="bench")
    pairs, _ = select_pairs(frs, model)
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        fit = fit_state_space(model, pairs)
        times.append(time.perf_counter() - t0)
    t_fd = min(times)
    truth = {**xv15_cruise().derivatives, "tau_a": 0.0892, "tau_r": 0.03276}
    free = list(model.free_names)
    err_fd = np.median([abs(fit.value(n) - truth[n]) / abs(truth[n]) for n in free if truth.get(n)])

    rec = load_record(case, case.identify, ["da", "dr", "p", "r", "ay", "beta"], 50.0)
    u = np.vstack([rec.signal("da"), rec.signal("dr")])
    y = np.vstack([rec.signal(n) for n in ("p", "r", "ay", "beta")])
    dt = 1 / rec.sample_rate_hz
    theta0 = model.theta()
    idx = [list(model.parameters).index(n) for n in free]
    n_x, n_y = 4, 4
    y_scale = np.std(y, axis=1)

    def residuals(simulate):
        def resid(z):
            th = theta0.copy()
            th[idx] = z[:len(idx)]
            M, F, G, H, J, tau = model.matrices(th)
            b = z[len(idx):len(idx) + n_x]
            yref = z[len(idx) + n_x:]
            ym = simulate(np.asarray(M, float), np.asarray(F, float), np.asarray(G, float), np.asarray(H, float),
                          np.asarray(J, float), np.maximum(np.asarray(tau, float), 0.0), dt, u, b)
            return (((ym + yref[:, None]) - y) / y_scale[:, None]).ravel()
        return resid

    def loop(M, F, G, H, J, tau, dt_, u_, b):
        return simulate_response(M, F, G, H, J, tau, dt_, u_, bias=b)

    resid_modal, resid_loop = residuals(simulate_modal), residuals(loop)
    z0 = np.concatenate([theta0[idx], np.zeros(n_x + n_y)])
    # the same outputs: at the start and at a perturbed point, to SIM_RTOL of each output's range
    for z in (z0, z0 * (1 + 0.05 * np.sin(np.arange(z0.size))) + 0.01):
        d = (resid_modal(z) - resid_loop(z)).reshape(n_y, -1) * y_scale[:, None]
        rel = np.max(np.abs(d), axis=1) / np.ptp(y, axis=1)
        assert np.all(rel < SIM_RTOL), rel

    t0 = time.perf_counter()
    oe = least_squares(resid_modal, z0, x_scale="jac", max_nfev=60)
    t_oe = time.perf_counter() - t0
    err_oe = np.median([abs(oe.x[k] - truth[n]) / abs(truth[n]) for k, n in enumerate(free) if truth.get(n)])
    t_loop = None
    if not args.skip_loop:
        t0 = time.perf_counter()
        oe_loop = least_squares(resid_loop, z0, x_scale="jac", max_nfev=60)
        t_loop = time.perf_counter() - t0
        # the same fit: the same cost, and the same unknowns to FIT_RTOL (finite-difference
        # Jacobians turn the 1e-9 differences of the two simulations into ~1e-5 steps)
        assert abs(oe.cost - oe_loop.cost) <= 1e-8 * oe_loop.cost, (oe.cost, oe_loop.cost)
        assert np.allclose(oe.x, oe_loop.x, rtol=FIT_RTOL, atol=FIT_RTOL * np.max(np.abs(oe_loop.x))), \
            np.max(np.abs(oe.x - oe_loop.x))

    print(f"single core; frequency-domain fit best of {args.repeats}, output-error fits run once")
    print(f"frequency-domain state-space fit (livesweep): {t_fd:7.3f} s  (8 pairs x 20 points, 17 parameters, CR "
          f"bounds), J_ave {fit.cost_average:.1f}, median parameter error {100 * err_fd:.1f} %")
    print(f"time-domain output-error fit, modal lfilter:  {t_oe:7.3f} s  ({y.size} residuals, {oe.nfev} evaluations "
          f"+ finite-difference Jacobians, {len(z0)} unknowns incl. 8 biases/reference shifts), median parameter "
          f"error {100 * err_oe:.1f} %, status {oe.status}")
    if t_loop is not None:
        print(f"  the same fit on the per-sample loop:        {t_loop:7.3f} s  (same cost to 1e-8, same unknowns to "
              f"{FIT_RTOL:g}; loop / lfilter {t_loop / t_oe:.1f}x)")
    print(f"ratio livesweep / baseline (frequency-domain fit / output-error fit): {t_fd / t_oe:.4f} "
          f"(target <= 1: {'OK' if t_fd <= t_oe else 'MISSED'})")
    # the budget tests/test_state_space.py asserted until its timing moved here
    print(f"budget: the state-space fit in {t_fd:.3f} s, under {FIT_BUDGET_S:g} s: "
          f"{'OK' if t_fd < FIT_BUDGET_S else 'MISSED'}")


if __name__ == "__main__":
    main()
