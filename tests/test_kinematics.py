"""Euler kinematics and the angle-versus-integrated-rate consistency check.

Truth comes from analytic attitude histories and from the simulator's exactly injected sensor
effects (sensor_skew on p: p_meas(t) = p(t - delay_s); scale_factor on phi; sensor_bias on p).
In the XV-15 lateral model phi' = p exactly, so phi vs the integral of p is the roll check.
"""

from __future__ import annotations

import numpy as np
import pytest

from livesweep.consistency.kinematics import KinematicCheck, check_angle_against_rate, euler_angle_rates
from livesweep.errors import ConfigError
from livesweep.sim.effects import make_effect
from livesweep.sim.scenario import simulate, sweep_scenario

FS = 50.0  # phi's rate; p (100 Hz) is taken every 2nd sample


# --- Euler angle rates ----------------------------------------------------------------------

def _attitude(t):
    phi = 0.6 * np.sin(0.9 * t) + 0.2 * np.cos(2.3 * t)
    theta = 0.4 * np.sin(0.5 * t + 0.3) + 0.1 * np.sin(3.1 * t)
    psi = 0.7 * t + 0.5 * np.sin(0.4 * t)
    return phi, theta, psi


def _attitude_dot(t):
    phi_d = 0.6 * 0.9 * np.cos(0.9 * t) - 0.2 * 2.3 * np.sin(2.3 * t)
    theta_d = 0.4 * 0.5 * np.cos(0.5 * t + 0.3) + 0.1 * 3.1 * np.cos(3.1 * t)
    psi_d = 0.7 + 0.5 * 0.4 * np.cos(0.4 * t)
    return phi_d, theta_d, psi_d


def test_euler_angle_rates_match_finite_difference_of_analytic_attitude():
    t = np.linspace(0.0, 20.0, 2001)
    phi, theta, _ = _attitude(t)
    phi_d, theta_d, psi_d = _attitude_dot(t)
    # Inverse 3-2-1 kinematics, written here independently: body rates from Euler rates.
    p = phi_d - psi_d * np.sin(theta)
    q = theta_d * np.cos(phi) + psi_d * np.cos(theta) * np.sin(phi)
    r = -theta_d * np.sin(phi) + psi_d * np.cos(theta) * np.cos(phi)
    h = 1e-5
    fd = [(a - b) / (2 * h) for a, b in zip(_attitude(t + h), _attitude(t - h))]
    got = euler_angle_rates(p, q, r, phi, theta)
    for g, ref in zip(got, fd):
        assert g.shape == t.shape
        np.testing.assert_allclose(g, ref, rtol=0, atol=1e-6)


def test_euler_angle_rates_level_is_identity_and_broadcasts():
    pd, td, sd = euler_angle_rates(np.array([0.1, 0.2]), 0.3, -0.4, 0.0, 0.0)
    np.testing.assert_allclose(pd, [0.1, 0.2])
    np.testing.assert_allclose(td, [0.3, 0.3])
    np.testing.assert_allclose(sd, [-0.4, -0.4])


def test_euler_angle_rates_rejects_pitch_at_or_beyond_90_deg():
    with pytest.raises(ConfigError, match="theta"):
        euler_angle_rates(0.0, 0.0, 0.0, 0.0, np.array([0.1, 10.0]))  # degrees passed by mistake
    with pytest.raises(ConfigError, match="theta"):
        euler_angle_rates(0.0, 0.0, 0.0, 0.0, np.pi / 2)
    with pytest.raises(ConfigError, match="shapes"):
        euler_angle_rates(np.zeros(3), np.zeros(4), 0.0, 0.0, 0.0)


# --- angle vs integrated rate ---------------------------------------------------------------

def _roll_record(effects=(), seed=1):
    sc = sweep_scenario(
        "xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=0.3, omega_max_rad_s=12.0,
        duration_s=60.0, amplitudes={"da": 3.0}, noise=True, turbulence=True, seed=seed,
        effects=tuple(effects),
    )
    res = simulate(sc)
    p, phi = res.outputs["p"], res.outputs["phi"]
    np.testing.assert_allclose(p.t_s[::2], phi.t_s)
    return phi.values.copy(), p.values[::2].copy()


SKEW_P_S = 0.04       # p sampled 0.04 s before its stamp: p_meas(t) = p(t - 0.04)
SCALE_PHI = 1.08
BIAS_P = 0.3          # deg/s


def _effects():
    return (
        make_effect("sensor_skew", output="p", delay_s=SKEW_P_S),
        make_effect("scale_factor", output="phi", factor=SCALE_PHI),
        make_effect("sensor_bias", output="p", bias=BIAS_P),
    )


@pytest.fixture(scope="module")
def corrupted():
    return _roll_record(_effects())


@pytest.fixture(scope="module")
def clean():
    return _roll_record()


def test_check_recovers_injected_scale_skew_and_bias(corrupted):
    phi, p = corrupted
    c = check_angle_against_rate(phi, p, FS, angle_name="phi", rate_name="p")
    assert isinstance(c, KinematicCheck)
    assert c.name == "phi vs integral of p" and c.measured == "phi" and c.reconstructed_from == "integral of p"
    assert abs(c.scale_factor_error - (SCALE_PHI - 1.0)) < 0.01
    # phi(t) = 1.08 R(t) and recon(t) = R(t - 0.04)  =>  phi(t) = 1.08 recon(t + 0.04): dt = -0.04.
    assert abs(c.skew_s - (-SKEW_P_S)) < 0.005
    assert abs(c.rate_bias - BIAS_P) < 0.05
    assert c.passed is False
    assert c.band_rad_s == (0.3, 10.0)
    assert 0 < c.rms_residual < 0.2  # deg: sensor noise (0.05) plus integrated rate noise


def test_check_passes_clean_record(clean):
    phi, p = clean
    c = check_angle_against_rate(phi, p, FS)
    assert abs(c.scale_factor_error) < 0.01
    assert abs(c.skew_s) < 0.005
    assert abs(c.rate_bias) < 0.05
    assert c.passed is True


@pytest.mark.parametrize("which", ["corrupted", "clean"])
def test_check_with_two_second_gap_in_valid_mask(which, request):
    phi, p = request.getfixturevalue(which)
    n = phi.size
    valid = np.ones(n, bool)
    gap = slice(n // 2 - 50, n // 2 + 50)  # 2 s at 50 Hz
    valid[gap] = False
    phi = phi.copy()
    p = p.copy()
    phi[gap] = 1e6   # garbage that must not enter the fit
    p[gap] = np.nan
    c = check_angle_against_rate(phi, p, FS, valid=valid)
    if which == "corrupted":
        assert abs(c.scale_factor_error - (SCALE_PHI - 1.0)) < 0.01
        assert abs(c.skew_s + SKEW_P_S) < 0.005
        assert abs(c.rate_bias - BIAS_P) < 0.05
        assert not c.passed
    else:
        assert abs(c.scale_factor_error) < 0.01
        assert abs(c.skew_s) < 0.005
        assert abs(c.rate_bias) < 0.05
        assert c.passed


def test_check_analytic_signal_in_radians_sign_conventions():
    """Exact synthetic case: angle lags by 13 ms, reads 3 % low, rate biased by -0.002 rad/s."""
    fs = 100.0
    t = np.arange(0, 40.0, 1 / fs)
    w = np.array([0.5, 1.1, 2.3, 4.0, 7.0])
    amp = np.array([0.2, 0.1, 0.05, 0.03, 0.01])
    ph = np.array([0.0, 1.0, 2.0, 0.5, 1.5])

    def ang(tt):
        return np.sum(amp[:, None] * np.sin(w[:, None] * tt + ph[:, None]), axis=0)

    def ang_dot(tt):
        return np.sum(amp[:, None] * w[:, None] * np.cos(w[:, None] * tt + ph[:, None]), axis=0)

    angle = 0.97 * ang(t - 0.013) + 0.05
    rate = ang_dot(t) - 0.002
    c = check_angle_against_rate(angle, rate, fs, band_rad_s=(0.3, 10.0), tolerance_scale=0.05,
                                 tolerance_skew_s=0.02)
    # Noise-free: only integration and filtering error remain (measured ~1e-8, 4e-7 s, 1e-9).
    assert abs(c.scale_factor_error + 0.03) < 1e-4
    assert abs(c.skew_s - 0.013) < 2e-5
    assert abs(c.rate_bias + 0.002) < 1e-5
    assert c.passed  # |lambda| = 0.03 < 0.05 and 13 ms < 20 ms
    tight = check_angle_against_rate(angle, rate, fs, tolerance_skew_s=0.01)
    assert not tight.passed


def test_check_input_errors_name_signal_and_value():
    x = np.zeros(1000)
    with pytest.raises(ConfigError, match=r"phi has 1000 samples but p has 999"):
        check_angle_against_rate(x, x[:-1], 50.0, angle_name="phi", rate_name="p")
    with pytest.raises(ConfigError, match=r"band_rad_s.*\(10.0, 0.3\)"):
        check_angle_against_rate(x, x, 50.0, band_rad_s=(10.0, 0.3))
    with pytest.raises(ConfigError, match=r"sample_rate_hz.*-5"):
        check_angle_against_rate(x, x, -5.0)
    with pytest.raises(ConfigError, match="no valid stretch"):
        check_angle_against_rate(x[:100], x[:100], 50.0, angle_name="theta", rate_name="q")
    with pytest.raises(ConfigError, match="no content in the band"):
        check_angle_against_rate(x, x, 50.0)


@pytest.mark.parametrize("band", [(0.3, 10.0), (1.0, 20.0), (0.5, 5.0)])
def test_zero_phase_bandpass_is_scipy_forward_backward_butterworth_away_from_the_ends(band):
    """The check's band-pass is applied as |H|^2 of scipy's butter(2, band, "bandpass") in the
    frequency domain: away from the ends it must equal sosfiltfilt of the same design."""
    import math

    import scipy.signal as sg

    from livesweep.consistency.kinematics import zero_phase_bandpass

    fs = 50.0
    rng = np.random.default_rng(11)
    x = np.cumsum(rng.standard_normal(20_000)) * 0.1 + np.sin(np.arange(20_000) / fs * 2.0)
    x = sg.detrend(x)
    ref = sg.sosfiltfilt(sg.butter(2, list(band), btype="bandpass", output="sos", fs=2 * math.pi * fs), x)
    got = zero_phase_bandpass(x, band, fs)
    edge = int(4 * 2 * math.pi / band[0] * fs)          # four periods of the low band edge
    assert np.max(np.abs(got - ref)[edge:-edge]) < 1e-5 * np.ptp(ref)
