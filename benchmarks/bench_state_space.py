#!/usr/bin/env python3
"""XV-15 cruise state-space fit (8 pairs, 17 parameters, CR bounds) against a time-domain
output-error fit of the same model on the same data, both measured in this run on one core.

The frequency-domain fit works on 8 pairs x 20 frequencies (320 residuals); the output-error fit
simulates the model over the whole identification record (434 s at 50 Hz, 4 outputs: 86 800
residuals) for every cost and Jacobian evaluation (scipy least_squares, finite differences), with
state biases and output reference shifts estimated alongside, as a time-domain fit must
(the seed's key feature 6).

    python benchmarks/bench_state_space.py
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from livesweep.config import load_case  # noqa: E402
from livesweep.ident.state_space import StateSpaceModel, fit_state_space, select_pairs  # noqa: E402
from livesweep.ident.verify import simulate_response  # noqa: E402
from livesweep.pipeline.frequency_response import load_record, run_frequency_response_stage  # noqa: E402
from livesweep.sim.models import xv15_cruise  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    case = load_case(ROOT / "config" / "xv15_cruise_lateral.toml")
    frs = run_frequency_response_stage(case).analysis.best
    model = StateSpaceModel.from_table(case.tables["state_space"], where="bench")
    pairs, _ = select_pairs(frs, model)
    times = []
    for _ in range(3):
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

    def resid(z):
        th = theta0.copy()
        th[idx] = z[:len(idx)]
        M, F, G, H, J, tau = model.matrices(th)
        b = z[len(idx):len(idx) + n_x]
        yref = z[len(idx) + n_x:]
        ym = simulate_response(M, F, G, H, J, np.maximum(np.asarray(tau, float), 0.0), dt, u, bias=b)
        return ((ym + yref[:, None]) - y).ravel() / np.std(y, axis=1).repeat(y.shape[1])

    z0 = np.concatenate([theta0[idx], np.zeros(n_x + n_y)])
    t0 = time.perf_counter()
    oe = least_squares(resid, z0, x_scale="jac", max_nfev=60)
    t_oe = time.perf_counter() - t0
    err_oe = np.median([abs(oe.x[k] - truth[n]) / abs(truth[n]) for k, n in enumerate(free) if truth.get(n)])
    print(f"frequency-domain state-space fit: {t_fd:6.2f} s (8 pairs x 20 points, 17 parameters, CR bounds), "
          f"J_ave {fit.cost_average:.1f}, median parameter error {100 * err_fd:.1f} %")
    print(f"time-domain output-error fit:     {t_oe:6.2f} s ({y.size} residuals, {oe.nfev} evaluations + "
          f"finite-difference Jacobians, {len(z0)} unknowns incl. 8 biases/reference shifts), "
          f"median parameter error {100 * err_oe:.1f} %, status {oe.status}")
    print(f"ratio time-domain / frequency-domain: {t_oe / t_fd:.0f}x (target: state-space fit under 5 s)")


if __name__ == "__main__":
    main()
