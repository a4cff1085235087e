"""Sweep and multistep inputs against their formulas (method.md §2.3)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scipy.signal import welch

from livesweep.errors import ConfigError
from livesweep.sim.inputs import Doublet, FrequencySweep, Multistep, PilotNoise, Step


def method_sweep(t, wmin, wmax, T, A):
    """method.md §2.3, transcribed: theta = wmin t + C2 (wmax - wmin) [(T/C1)(exp(C1 t/T) - 1) - t]."""
    C1, C2 = 4.0, 0.0187
    theta = wmin * t + C2 * (wmax - wmin) * ((T / C1) * (math.exp(C1 * t / T) - 1) - t)
    omega = wmin + C2 * (math.exp(C1 * t / T) - 1) * (wmax - wmin)
    return A * math.sin(theta), omega


@settings(max_examples=60, deadline=None)
@given(wmin=st.floats(0.1, 2.0), ratio=st.floats(2.0, 100.0), extra=st.floats(1.0, 3.0),
       A=st.floats(0.1, 10.0), frac=st.floats(0.0, 1.0))
def test_sweep_follows_the_formula_between_fades(wmin, ratio, extra, A, frac):
    T = extra * 2 * 2 * math.pi / wmin
    sw = FrequencySweep(wmin, wmin * ratio, T, A, trim_s=3.0)
    t = sw.fade_in + frac * (T - sw.fade_in - sw.fade_out)
    value, omega = method_sweep(t, wmin, wmin * ratio, T, A)
    assert sw(np.array([3.0 + t]))[0] == pytest.approx(value, abs=1e-9 * A)
    assert float(sw.omega(t)) == pytest.approx(omega, rel=1e-12)


def test_sweep_instantaneous_frequency_is_the_phase_derivative():
    sw = FrequencySweep(0.3, 20.0, 100.0, 1.0)
    t = np.linspace(0, 100, 200001)
    dtheta = np.gradient(sw.phase(t), t)
    np.testing.assert_allclose(dtheta[1:-1], sw.omega(t)[1:-1], rtol=1e-6)
    # K(T) = 0.0187 (e^4 - 1) = 1.0023 and K = 0.5 at t = 0.83 T (method.md §2.3 check).
    assert float(sw.schedule(100.0)) == pytest.approx(1.0023, abs=1e-4)
    t_half = 100.0 * math.log(1 + 0.5 / 0.0187) / 4.0
    assert t_half / 100.0 == pytest.approx(0.83, abs=0.005)


def test_sweep_trims_and_fades():
    sw = FrequencySweep(0.5, 10.0, 60.0, 2.0, trim_s=3.0, fade_in_s=4.0, fade_out_s=2.0)
    t = np.linspace(0, sw.total_duration_s, 20001)
    x = sw(t)
    assert sw.total_duration_s == 66.0
    assert np.all(x[(t < 3.0) | (t > 63.0)] == 0)
    assert np.max(np.abs(x)) <= 2.0 + 1e-12
    # raised cosine: 0.5 at the middle of the fade-in
    assert float(sw.envelope(2.0)) == pytest.approx(0.5)
    assert float(sw.envelope(1.0)) == pytest.approx(0.5 * (1 - math.cos(math.pi / 4)))
    assert float(sw.envelope(59.0)) == pytest.approx(0.5)
    assert float(sw.envelope(30.0)) == 1.0


@pytest.mark.parametrize("kwargs, message", [
    (dict(omega_min_rad_s=2.0, omega_max_rad_s=1.0, duration_s=60, amplitude=1), "must be below omega_max"),
    (dict(omega_min_rad_s=0.3, omega_max_rad_s=10, duration_s=20, amplitude=1), "too short for omega_min_rad_s = 0.3"),
    (dict(omega_min_rad_s=0.3, omega_max_rad_s=10, duration_s=60, amplitude=0), "amplitude must be"),
    (dict(omega_min_rad_s=0.3, omega_max_rad_s=10, duration_s=60, amplitude=-2), "amplitude must be"),
    (dict(omega_min_rad_s=float("nan"), omega_max_rad_s=10, duration_s=60, amplitude=1), "omega_min_rad_s must be"),
])
def test_invalid_sweeps_name_the_value(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        FrequencySweep(**kwargs)


def test_doublet_and_3211_shapes():
    d = Doublet(2.0, 1.5, trim_s=2.0, settle_s=5.0)
    t = np.arange(0, d.total_duration_s, 0.001)
    x = d(t)
    assert np.sum(x == 2.0) == pytest.approx(1500, abs=1)
    assert np.sum(x == -2.0) == pytest.approx(1500, abs=1)
    assert np.trapezoid(x, t) == pytest.approx(0.0, abs=0.01)
    m = Multistep(1.0, 0.5, (3, 2, 1, 1), trim_s=1.0, settle_s=2.0)
    np.testing.assert_allclose(m.edges(), [1.0, 2.5, 3.5, 4.0, 4.5])
    assert m(np.array([1.2, 2.7, 3.7, 4.2, 4.7])).tolist() == [1.0, -1.0, 1.0, -1.0, 0.0]
    s = Step(3.0, 4.0, trim_s=1.0)
    assert s(np.array([0.5, 1.0, 4.99, 5.0])).tolist() == [0.0, 3.0, 3.0, 0.0]


def test_pilot_noise_is_band_limited_with_the_rms_asked_for():
    t = np.arange(0, 400, 0.01)
    x = PilotNoise(0.3, bandwidth_rad_s=1.0, seed=4)(t)
    assert np.sqrt(np.mean(x**2)) == pytest.approx(0.3, rel=1e-9)
    f, spec = welch(x, fs=100.0, window="hann", nperseg=8192)
    w = 2 * np.pi * f
    # a 2nd-order Butterworth applied forward and back: -80 dB/decade above the corner
    assert spec[w > 10].mean() < 1e-5 * spec[w < 0.5].mean()
    np.testing.assert_array_equal(x, PilotNoise(0.3, 1.0, seed=4)(t))
