#!/usr/bin/env python3
"""XV-15 cruise state-space fit (8 pairs, 17 parameters, CR bounds) against two baselines measured
in this run on one core: the same frequency-domain fit written directly with scipy (like for like,
the headline ratio), and a time-domain output-error fit (a different method, for context).

The frequency-domain fit (livesweep, ``fit_state_space``) minimises the NAVFIT cost of 8 pairs x 20
frequencies (160 points, 320 residuals: magnitude and phase).

1. Like for like (:func:`frequency_domain_baseline`): the *same* cost -- the same 8 x 20 fitting
   points (320 residuals), the same coherence weights ``W_gamma``, ``W_g`` and ``W_p``, the same
   wrapped phase error -- on the *same* model structure (``M, F, G, H, J`` and the input delays
   from the case's ``[state_space]`` table, all 17 parameters free, delays bounded to >= 0),
   written as a competent numpy/scipy user would: the model response at every distinct fitting
   frequency with one batched ``numpy.linalg.solve``, the residuals in numpy, minimised by
   ``scipy.optimize.least_squares`` (trust-region reflective, ``x_scale="jac"``, the same
   tolerances and evaluation limit as livesweep, its default 2-point finite-difference Jacobian),
   then the Cramer-Rao bounds from the returned Jacobian (``sqrt(diag((2 D^T D)^-1))``). It is
   asserted to reach livesweep's cost (to 1e-6 relative) and parameters (to 1e-3 of their CR
   bounds). Ratio livesweep / this baseline: the headline.
2. A different method (context, not like for like): a time-domain **output-error** fit, which
   measures what identifying the same model from the time histories costs. It simulates the model
   over the whole identification record (434 s at 50 Hz, 4 outputs: **about 86 800 residuals**
   against livesweep's 320) for every cost and Jacobian evaluation (scipy ``least_squares``, finite
   differences), with state biases and output reference shifts estimated alongside, as a
   time-domain fit must (the seed's key feature 6). Its ratio compares two methods, not two
   implementations of one.

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
from livesweep.ident.cost import W_G, W_P  # noqa: E402
from livesweep.ident.state_space import StateSpaceModel, fit_state_space, select_pairs  # noqa: E402
from livesweep.ident.verify import simulate_response  # noqa: E402
from livesweep.stages.frequency_response import load_record, run_frequency_response_stage  # noqa: E402
from livesweep.sim.models import xv15_cruise  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SIM_RTOL = 1e-7            # simulations agree to this fraction of each output's range (rounding over 21 700 steps)
FIT_RTOL = 1e-3            # output-error fits on either simulation agree to this (relative)
FIT_BUDGET_S = 5.0         # the frequency-domain fit (8 pairs, 17 parameters, CR bounds) stays under this
FD_COST_RTOL = 1e-6        # the scipy frequency-domain fit reaches livesweep's cost to this (relative)
FD_PARAM_CR = 1e-3         # ... and its parameters to this fraction of their Cramer-Rao bounds


def frequency_domain_baseline(model, pairs, max_nfev=200, tol=1e-10):
    """The NAVFIT cost of ``pairs`` (docs/method.md §7.1) minimised over the model's free parameters
    with ``scipy.optimize.least_squares`` directly (finite-difference Jacobian), then the Cramer-Rao
    bounds from its Jacobian. Returns (least_squares result, free indices, theta, CR bounds)."""
    if any(model.output_delays.values()) or any(model.input_skews.values()):
        raise SystemExit("the baseline models input delays only")
    theta0 = np.array(model.initial, float)
    free = model.free
    lower = np.full(free.size, -np.inf)
    for k in model.delay_parameter_indices():
        lower[np.flatnonzero(free == k)] = 0.0
    # every pair's 20 points, stacked: frequency, (output, input), data, weights
    w = np.concatenate([p.omega for p in pairs])
    o = np.concatenate([np.full(p.n_omega, model.outputs.index(p.output)) for p in pairs])
    i = np.concatenate([np.full(p.n_omega, model.inputs.index(p.input)) for p in pairs])
    mag_data = np.concatenate([p.magnitude_db for p in pairs])
    ph_data = np.exp(1j * np.deg2rad(np.concatenate([p.phase_deg for p in pairs])))
    sc = np.concatenate([np.sqrt(20.0 / p.n_omega * p.weight) for p in pairs])
    wu, back = np.unique(w, return_inverse=True)                 # pairs with the same band share points
    s = 1j * wu[:, None, None]

    def resid(x):
        th = theta0.copy()
        th[free] = x
        M, F, G, H, J, tau = model.matrices(th)
        X = np.linalg.solve(s * M - F, np.broadcast_to(G, (wu.size,) + G.shape))   # (f, n, m)
        T = (H @ X + J)[back, o, i] * np.exp(-1j * w * tau[i])
        with np.errstate(divide="ignore"):
            mag = 20.0 * np.log10(np.abs(T))
        dph = np.angle(ph_data / T, deg=True)                      # wrapped to (-180, 180]
        return np.concatenate([sc * np.sqrt(W_G) * (mag_data - mag), sc * np.sqrt(W_P) * dph])

    res = least_squares(resid, np.clip(theta0[free], lower, np.inf), bounds=(lower, np.inf), method="trf",
                        x_scale="jac", ftol=tol, xtol=tol, gtol=tol, max_nfev=max_nfev)
    th = theta0.copy()
    th[free] = res.x
    cr = np.sqrt(np.diag(np.linalg.inv(2.0 * res.jac.T @ res.jac)))
    return res, free, th, cr


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
    times, times_sp = [], []
    for _ in range(args.repeats):                  # in turn, so that both see the same machine load
        t0 = time.perf_counter()
        fit = fit_state_space(model, pairs)
        times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        sp, sp_free, sp_theta, sp_cr = frequency_domain_baseline(model, pairs)
        times_sp.append(time.perf_counter() - t0)
    t_fd, t_sp = min(times), min(times_sp)
    truth = {**xv15_cruise().derivatives, "tau_a": 0.0892, "tau_r": 0.03276}
    free = list(model.free_names)
    err_fd = np.median([abs(fit.value(n) - truth[n]) / abs(truth[n]) for n in free if truth.get(n)])
    # the same fit: the same cost (J = sum r^2 = 2 * least_squares' cost) and the same parameters
    j_sp = 2.0 * sp.cost / len(pairs)
    assert abs(j_sp - fit.cost_average) <= FD_COST_RTOL * fit.cost_average, (j_sp, fit.cost_average)
    cr_ls = np.array([fit.parameter(n).cramer_rao for n in free])
    d_cr = np.max(np.abs(sp_theta[sp_free] - fit.theta[sp_free]) / cr_ls)
    assert d_cr < FD_PARAM_CR, d_cr
    d_crb = np.max(np.abs(sp_cr / cr_ls - 1.0))

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

    n_pts = sum(p.n_omega for p in pairs)
    print(f"single core; frequency-domain fits best of {args.repeats} (run in turn), output-error fits run once")
    print(f"frequency-domain state-space fit (livesweep): {t_fd:7.3f} s  ({len(pairs)} pairs x 20 points = {n_pts} "
          f"points, {2 * n_pts} residuals, {len(free)} parameters, exact Jacobian, CR bounds), J_ave "
          f"{fit.cost_average:.1f}, median parameter error {100 * err_fd:.1f} %")
    print("\nlike for like -- the same frequency-domain cost (same points, same weights) on the same model structure:")
    print(f"  scipy least_squares on it directly:         {t_sp:7.3f} s  ({2 * n_pts} residuals, {sp.nfev} evaluations "
          f"+ {sp.njev} finite-difference Jacobians, CR bounds from its Jacobian); J_ave {j_sp:.1f}, parameters "
          f"within {d_cr:.1e} CR of livesweep's, CR bounds within {d_crb:.1e} relative")
    print(f"  ratio livesweep / scipy frequency-domain fit: {t_fd / t_sp:.2f} "
          f"(target <= 1: {'OK' if t_fd <= t_sp else 'MISSED'})")
    print("\na different method, for context -- time-domain output error (simulates the whole record per evaluation;"
          f" {y.size} residuals, not {2 * n_pts}):")
    print(f"  time-domain output-error fit, modal lfilter:  {t_oe:7.3f} s  ({y.size} residuals, {oe.nfev} evaluations "
          f"+ finite-difference Jacobians, {len(z0)} unknowns incl. 8 biases/reference shifts), median parameter "
          f"error {100 * err_oe:.1f} %, status {oe.status}")
    if t_loop is not None:
        print(f"    the same fit on the per-sample loop:        {t_loop:7.3f} s  (same cost to 1e-8, same unknowns to "
              f"{FIT_RTOL:g}; loop / lfilter {t_loop / t_oe:.1f}x)")
    print(f"  ratio livesweep / output-error fit (two methods, not two implementations): {t_fd / t_oe:.4f}")
    # the budget tests/test_state_space.py asserted until its timing moved here
    print(f"budget: the state-space fit in {t_fd:.3f} s, under {FIT_BUDGET_S:g} s: "
          f"{'OK' if t_fd < FIT_BUDGET_S else 'MISSED'}")


if __name__ == "__main__":
    main()
