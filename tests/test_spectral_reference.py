"""Responses through a common reference (method.md §4.6) against the exact model.

A closed-loop test point (XV-15 hover, pilot loop, full turbulence) biases the direct MISO estimate
where the disturbance fed back into the commands dominates; the estimate formed through the logged
sweep injection is unbiased. Truth: the simulator's own model, T(jw) = H (jwI - F)^-1 G + J.
"""

from __future__ import annotations

import numpy as np
import pytest

from livesweep.errors import ConfigError
from livesweep.sim.models import xv15_hover
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.spectral.analysis import analyze

from helpers import simulated_record

BAND = (0.2, 12.0)
WINDOWS = (10.0, 20.0, 40.0, 80.0, 160.0)


def _record(result):
    values, names = simulated_record(result, references=True)
    return values - values.mean(axis=1, keepdims=True), names


@pytest.fixture(scope="module")
def closed_loop():
    sc = sweep_scenario("xv15-hover", axes=("da", "dr"), repeats=2, omega_min_rad_s=BAND[0], omega_max_rad_s=BAND[1],
                        duration_s=100.0, amplitudes={"da": 1.5, "dr": 3.0}, off_axis_rms=0.2, seed=5)
    values, names = _record(simulate(sc))
    an = analyze(values, names, 50.0, ["da", "dr"], ["p", "phi", "r"], BAND, windows_s=WINDOWS,
                 references=["da_ref", "dr_ref"])
    truth = xv15_hover().frequency_response(an.best.omega)
    out_index = {n: i for i, n in enumerate(xv15_hover().outputs)}
    return an, truth, out_index


def _errors(frs, truth, out_index, output, input_):
    pr = frs.pair(output, input_)
    T = truth[out_index[output], {"da": 0, "dr": 1}[input_]]
    ratio = pr.H / T
    return pr, 20 * np.log10(np.abs(ratio)), np.degrees(np.angle(ratio))


@pytest.mark.parametrize("output", ["p", "phi"])
def test_referenced_roll_response_is_unbiased_where_the_direct_miso_estimate_is_not(closed_loop, output):
    an, truth, idx = closed_loop
    low = an.best.omega < 0.8
    ref, dm_ref, dp_ref = _errors(an.referenced, truth, idx, output, "da")
    _, dm_dir, dp_dir = _errors(an.miso, truth, idx, output, "da")
    # the direct estimate is biased at low frequency (the loop's inverse shows through)
    assert np.median(np.abs(dm_dir[low])) > 2.0
    # the referenced one agrees with the exact model within its own 2-sigma random error
    ok = ref.coherence >= 0.3
    eps_db = 20 * np.log10(1 + 2 * ref.random_error[ok])
    eps_deg = np.degrees(2 * ref.random_error[ok])
    inside = (np.abs(dm_ref[ok]) <= eps_db) & (np.abs(dp_ref[ok]) <= eps_deg)
    assert ok.mean() > 0.8 and inside.mean() >= 0.85, (ok.mean(), inside.mean())
    assert np.median(np.abs(dm_ref[low & ok])) < 0.25 * np.median(np.abs(dm_dir[low & ok]))


def test_referenced_yaw_response_to_rudder_matches_the_model(closed_loop):
    an, truth, idx = closed_loop
    ref, dm, dp = _errors(an.referenced, truth, idx, "r", "dr")
    ok = ref.coherence >= 0.6
    assert ok.mean() > 0.8
    assert np.median(np.abs(dm[ok])) < 0.5 and np.median(np.abs(dp[ok])) < 3.0


def test_referenced_coherence_is_the_product_of_its_legs(closed_loop):
    """The derived pair's coherence never exceeds either leg: a closed loop cannot make data look
    better than the injection explains."""
    an, _, _ = closed_loop
    ref = an.referenced.pair("p", "da")
    direct = an.miso.pair("p", "da")
    low = an.best.omega < 0.5
    assert np.all(ref.coherence <= 1.0) and np.median(ref.coherence[low]) < np.median(direct.coherence[low])
    assert an.best is an.referenced


def test_one_reference_per_input_is_required():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((4, 5000))
    with pytest.raises(ConfigError, match="one reference per input"):
        analyze(x, ["u1", "u2", "y", "r1"], 50.0, ["u1", "u2"], ["y"], (0.5, 10.0), references=["r1"])


def test_live_window_through_the_references_is_unbiased_too():
    """The live sliding-window estimator with the same references: over a 300 s window of the
    closed-loop test point its referenced p/da is unbiased below 0.8 rad/s where its conditioned
    (direct) estimate is not, and it is what ``best`` returns."""
    from livesweep.spectral.online import OnlineSpectralEstimator

    sc = sweep_scenario("xv15-hover", axes=("da", "dr"), repeats=2, omega_min_rad_s=BAND[0], omega_max_rad_s=BAND[1],
                        duration_s=100.0, amplitudes={"da": 1.5, "dr": 3.0}, off_axis_rms=0.2, seed=5)
    values, names = _record(simulate(sc))
    est = OnlineSpectralEstimator(names, ["da", "dr"], ["p", "phi"], 50.0, (0.4, 12.0), window_s=values.shape[1] / 50.0,
                                  segment_s=40.0, references=["da_ref", "dr_ref"])
    for i in range(0, values.shape[1], 500):
        est.update(values[:, i:i + 500])
    r = est.result()
    assert r.best is r.referenced
    truth = xv15_hover().frequency_response(r.omega)[0, 0]          # p/da
    low = (r.omega < 0.8) & r.usable
    err_ref = np.abs(20 * np.log10(np.abs(r.referenced.pair("p", "da").H[low] / truth[low])))
    err_dir = np.abs(20 * np.log10(np.abs(r.conditioned.pair("p", "da").H[low] / truth[low])))
    print(f"\nlive p/da below 0.8 rad/s: referenced median {np.median(err_ref):.2f} dB, direct {np.median(err_dir):.2f} dB")
    assert np.median(err_dir) > 2.0 and np.median(err_ref) < 0.3 * np.median(err_dir)
    with pytest.raises(ConfigError, match="one reference per input"):
        OnlineSpectralEstimator(names, ["da", "dr"], ["p"], 50.0, (0.4, 12.0), references=["da_ref"])


def test_an_output_no_window_resolves_loses_that_frequency_alone():
    """T_yu = T_yr T_ur^-1 row by row: an output whose T_yr is undefined at a frequency (an
    accelerometer with no coherence there: no window gives it weight) has no response there, and
    every other output keeps its own, equal to numpy's solve of its row. (Before, one such output
    took the frequency from every pair: the quadrotor's p/roll lost 20.5 and 31.9 rad/s where ax
    and ay had no coherence, and a 30 rad/s mode on p fell in the hole.)"""
    from livesweep.spectral.reference import combine_legs

    rng = np.random.default_rng(7)
    n_in, n_out, n = 2, 3, 6
    Tur = rng.normal(size=(n_in, n_in, n)) + 1j * rng.normal(size=(n_in, n_in, n)) + 3 * np.eye(2)[:, :, None]
    Tyr = rng.normal(size=(n_out, n_in, n)) + 1j * rng.normal(size=(n_out, n_in, n))
    Tyr[2, :, 3] = np.nan                            # output 2 unresolved at frequency 3
    pc_u, eps_u = np.full((n_in, n_in, n), 0.9), np.full((n_in, n_in, n), 0.05)
    pc_y, eps_y = np.full((n_out, n_in, n), 0.8), np.full((n_out, n_in, n), 0.1)
    rr = combine_legs(Tur, pc_u, eps_u, Tyr, pc_y, eps_y, np.full((n_out, n), 0.95), np.zeros(n, bool))
    for f in range(n):
        expect = np.linalg.solve(Tur[:, :, f].T, Tyr[:, :, f].T).T      # T_yr T_ur^-1
        rows = [0, 1] if f == 3 else [0, 1, 2]
        np.testing.assert_allclose(rr.H[rows, :, f], expect[rows], rtol=1e-10)
    assert np.all(np.isnan(rr.H[2, :, 3])) and np.all(rr.coherence[2, :, 3] == 0)
    assert np.all(np.isinf(rr.random_error[2, :, 3])) and rr.multiple_coherence[2, 3] == 0
    assert np.all(rr.coherence[:2, :, 3] > 0) and not rr.ill_conditioned[3]
