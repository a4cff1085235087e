"""Hampel wild-point detection and replacement, against spikes injected by the simulator."""

from __future__ import annotations

import numpy as np
import pytest

from livesweep.consistency.wildpoints import WildPointReport, replace_wild_points
from livesweep.errors import ConfigError
from livesweep.sim.effects import make_effect
from livesweep.sim.scenario import simulate, sweep_scenario

SEED = 1


def _run(spikes: bool, noise: bool = True, seed: int = SEED):
    effects = (make_effect("spikes", output="r", rate_hz=0.2, magnitude=5.0),) if spikes else ()
    sc = sweep_scenario(
        "xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=0.3, omega_max_rad_s=12.0,
        duration_s=60.0, amplitudes={"da": 3.0}, noise=noise, turbulence=True, seed=seed,
        effects=effects,
    )
    return simulate(sc)


@pytest.fixture(scope="module")
def spiked():
    return _run(spikes=True)


@pytest.fixture(scope="module")
def clean():
    return _run(spikes=False)


@pytest.fixture(scope="module")
def noise_free():
    return _run(spikes=False, noise=False)


def _noise_std(res, output):
    return next(s.noise_std for s in res.scenario.sensors if s.output == output)


def test_injected_spikes_all_found_no_false_positives(spiked):
    x = spiked.outputs["r"].values
    injected = np.array(sorted(spiked.injected["spikes"]["r"]))
    assert injected.size >= 5
    y, rep = replace_wild_points(x, name="r")
    assert isinstance(rep, WildPointReport)
    assert rep.name == "r" and rep.half_window == 7 and rep.n_sigma == 4.0
    assert rep.n_replaced == rep.indices.size
    assert np.all(np.diff(rep.indices) > 0) and rep.indices.dtype.kind == "i"
    found = set(rep.indices.tolist())
    assert set(injected.tolist()) <= found                       # recall 100 %
    false_pos = found - set(injected.tolist())
    assert len(false_pos) <= 0.01 * injected.size                # measured: 0 with seed 1
    assert y is not x and not np.shares_memory(y, x)
    np.testing.assert_array_equal(x[injected] != y[injected], True)


def test_clean_record_same_seed_has_no_false_positives(clean):
    for name in ("p", "r", "phi"):
        y, rep = replace_wild_points(clean.outputs[name].values, name=name)
        assert rep.n_replaced == 0, (name, rep.indices)
        np.testing.assert_array_equal(y, clean.outputs[name].values)


def test_replaced_values_within_three_noise_sigmas_of_truth(spiked, noise_free):
    sigma = _noise_std(spiked, "r")
    assert sigma == pytest.approx(0.05)
    injected = np.array(spiked.injected["spikes"]["r"])
    y, _ = replace_wild_points(spiked.outputs["r"].values, name="r")
    truth = noise_free.outputs["r"].values
    err = np.abs(y[injected] - truth[injected])
    assert np.max(err) < 3 * sigma
    # Untouched samples stay exactly as measured.
    keep = np.ones(y.size, bool)
    keep[injected] = False
    np.testing.assert_array_equal(y[keep], spiked.outputs["r"].values[keep])


def test_runs_of_three_adjacent_spikes_are_caught(clean, noise_free):
    x = clean.outputs["r"].values.copy()
    truth = noise_free.outputs["r"].values
    sigma = _noise_std(clean, "r")
    runs = [
        (1000, (5.0, 5.0, 5.0)),
        (2500, (-4.0, -6.0, -5.0)),
        (4000, (5.0, -5.0, 5.0)),
        (5500, (3.0, 3.0, 3.0)),
        (x.size - 3, (5.0, 5.0, 5.0)),   # at the very end of the record
        (0, (-5.0, -5.0, -5.0)),         # at the very start
    ]
    spikes = []
    for i0, mags in runs:
        for j, m in enumerate(mags):
            x[i0 + j] += m
            spikes.append(i0 + j)
    y, rep = replace_wild_points(x, name="r")
    np.testing.assert_array_equal(rep.indices, sorted(spikes))
    interior = [i for i in spikes if 3 <= i < x.size - 3]
    # A run of 3 is bridged over 4 samples: noise of the ends plus the signal's curvature.
    assert np.max(np.abs(y[interior] - truth[interior])) < 3 * sigma


def test_invalid_samples_are_never_modified_or_used(spiked):
    x = spiked.outputs["r"].values.copy()
    injected = np.array(sorted(spiked.injected["spikes"]["r"]))
    valid = np.ones(x.size, bool)
    hole = slice(injected[0] - 20, injected[0] + 20)  # a gap containing a spike
    valid[hole] = False
    x[injected[0] - 5] = np.nan                     # and a NaN inside it
    x[injected[0] - 3] = 1e9                        # and a huge value inside it
    nan_elsewhere = injected[-1] - 30
    x[nan_elsewhere] = np.nan                       # a NaN flagged valid is treated as invalid
    y, rep = replace_wild_points(x, valid=valid, name="r")
    np.testing.assert_array_equal(y[~valid], x[~valid])
    assert np.isnan(y[nan_elsewhere])
    assert not np.any(~valid[rep.indices])
    assert nan_elsewhere not in rep.indices
    expected = [i for i in injected if valid[i]]
    assert set(expected) <= set(rep.indices.tolist())
    assert rep.n_replaced == len(expected)


def test_smooth_clean_signal_no_false_positives_isolated_spike_caught():
    t = np.arange(0, 60.0, 0.01)
    # Flat trim (MAD = 0 there), then a sweep: noise-free and smooth.
    w = 0.3 + (12.0 - 0.3) * np.clip(t - 5.0, 0, None) / 55.0
    x = np.where(t < 5.0, 0.0, 2.0 * np.sin(np.cumsum(w) * 0.01))
    y, rep = replace_wild_points(x, name="smooth")
    assert rep.n_replaced == 0
    np.testing.assert_array_equal(y, x)
    xs = x.copy()
    # The floor of the local scale is the per-sample change (here 0.059): a spike of 0.5 in the
    # flat stretch (MAD = 0) is 8 floors. While sweeping, the local MAD sets the threshold.
    xs[200] += 0.5     # in the flat stretch
    xs[3000] -= 5.0    # sweeping at 5.6 rad/s
    xs[5800] += 5.0    # sweeping at 11.7 rad/s
    y, rep = replace_wild_points(xs, name="smooth")
    np.testing.assert_array_equal(rep.indices, [200, 3000, 5800])
    np.testing.assert_allclose(y[[200, 3000, 5800]], x[[200, 3000, 5800]], atol=0.02)


def test_twenty_thousand_samples_in_one_call():
    """A record of 20 000 samples goes through in one call and its spikes are found (the speed is
    benchmarks/bench_wildpoints.py's, against scipy's running median: no timing here)."""
    rng = np.random.default_rng(0)
    x = np.sin(np.arange(20000) * 0.01) + 0.05 * rng.standard_normal(20000)
    spikes = [1234, 9876, 15000]
    x[spikes] += 2.0
    y, rep = replace_wild_points(x)
    np.testing.assert_array_equal(rep.indices, spikes)              # no false alarm in 20 000 noisy samples
    assert np.all(np.abs(y[spikes] - np.sin(np.array(spikes) * 0.01)) < 0.3)


def test_short_and_degenerate_inputs():
    y, rep = replace_wild_points(np.array([1.0, 2.0]), name="x")
    assert rep.n_replaced == 0 and y.tolist() == [1.0, 2.0]
    y, rep = replace_wild_points(np.array([0.0, 0.0, 0.0, 9.0, 0.0, 0.0, 0.0]), half_window=7)
    assert rep.indices.tolist() == [3] and y[3] == 0.0
    y, rep = replace_wild_points(np.ones(50))
    assert rep.n_replaced == 0


def test_bad_settings_raise_config_error_naming_signal_and_value():
    x = np.zeros(100)
    with pytest.raises(ConfigError, match=r"'r'.*half_window.*|half_window.*'r'.*0"):
        replace_wild_points(x, half_window=0, name="r")
    with pytest.raises(ConfigError, match=r"n_sigma.*'r'.*-1"):
        replace_wild_points(x, n_sigma=-1, name="r")
    with pytest.raises(ConfigError, match=r"valid mask.*'r'.*\(99,\)"):
        replace_wild_points(x, valid=np.ones(99, bool), name="r")
    with pytest.raises(ConfigError, match=r"one-dimensional.*\(10, 10\)"):
        replace_wild_points(x.reshape(10, 10), name="r")
