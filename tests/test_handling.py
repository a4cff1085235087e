"""Bandwidth, phase delay, crossover and margins against analytic systems written out here (method.md §10)."""

import numpy as np
import pytest
from scipy.optimize import brentq

from livesweep.errors import ConfigError
from livesweep.ident.handling import bandwidth, crossover_and_margins, omega_180, phase_delay
from livesweep.spectral.response import FrequencyResponse

R2D = 180 / np.pi
W = np.geomspace(0.05, 200, 3000)


def integrator_delay(K, tau):
    return lambda w: K * np.exp(-1j * w * tau) / (1j * w)


def lag_loop(K, T, tau):
    """L = K e^(-tau s) / (s (T s + 1)) and its exact magnitude [-] and phase [deg]."""
    H = lambda w: K * np.exp(-1j * w * tau) / (1j * w * (1j * w * T + 1))
    mag = lambda w: K / (w * np.sqrt(1 + (w * T) ** 2))
    phase = lambda w: -90 - R2D * np.arctan(w * T) - R2D * w * tau
    return H, mag, phase


def test_integrator_plus_delay_attitude_response():
    tau = 0.1
    H = integrator_delay(2.0, tau)(W)
    w180 = np.pi / (2 * tau)                                    # -90 - 57.3 w tau = -180
    assert omega_180((W, H)) == pytest.approx(w180, rel=1e-4)
    bw = bandwidth((W, H), kind="rate")
    assert bw.omega_180 == pytest.approx(w180, rel=1e-4)
    assert bw.phase == pytest.approx(np.pi / (4 * tau), rel=1e-4)   # -135 deg
    assert bw.gain == pytest.approx(w180 / 10 ** (6 / 20), rel=1e-4)  # |H| = K/w: +6 dB at w180 / 1.995
    assert bw.bandwidth == pytest.approx(min(bw.gain, bw.phase))
    # phase lag beyond -180 at 2 w180 is 90 deg: tau_p = 90 / (57.3 * 2 w180) = tau / 2 (ADS-33/OFA formula)
    for method in ("two_point", "lsq", "auto"):
        assert phase_delay((W, H), method) == pytest.approx(tau / 2, rel=1e-4)


@pytest.mark.parametrize("K, T, tau", [(5.0, 0.2, 0.05), (2.0, 0.5, 0.02), (1.0, 0.05, 0.12)])
def test_bandwidth_and_phase_delay_of_a_lagged_integrator(K, T, tau):
    H, mag, phase = lag_loop(K, T, tau)
    w180 = brentq(lambda w: phase(w) + 180, 1e-3, 1e3)
    w135 = brentq(lambda w: phase(w) + 135, 1e-3, w180)
    level = 20 * np.log10(mag(w180)) + 6
    wgain = brentq(lambda w: 20 * np.log10(mag(w)) - level, 1e-3, w180)
    tau_p = -(phase(2 * w180) + 180) / (R2D * 2 * w180)

    resp = FrequencyResponse("phi", "dlat", W, H(W), np.full(W.size, 0.95), np.full(W.size, 0.05))
    bw = bandwidth(resp, kind="rate")
    assert bw.omega_180 == pytest.approx(w180, rel=1e-3)
    assert bw.phase == pytest.approx(w135, rel=1e-3)
    assert bw.gain == pytest.approx(wgain, rel=1e-3)
    assert bw.bandwidth == pytest.approx(min(wgain, w135), rel=1e-3)
    assert bandwidth(resp, kind="attitude").bandwidth == pytest.approx(w135, rel=1e-3)
    assert phase_delay(resp, "two_point") == pytest.approx(tau_p, rel=1e-3)
    # the same from the rate response p/dlat = s * phi/dlat
    rate = (W, 1j * W * H(W))
    assert bandwidth(rate, integrate=True) == pytest.approx(tuple(bw), rel=1e-9)
    assert phase_delay(rate, "two_point", integrate=True) == pytest.approx(tau_p, rel=1e-3)


def test_nonlinear_phase_uses_the_least_squares_slope():
    # integrator + delay + a lightly damped mode between w180 and 2 w180 bends the phase there
    wn, zeta, tau = 20.0, 0.05, 0.05
    H = lambda w: np.exp(-1j * w * tau) / (1j * w) * wn**2 / ((1j * w) ** 2 + 2 * zeta * wn * 1j * w + wn**2)
    phase = lambda w: np.rad2deg(np.unwrap(np.angle(H(w))))
    wf = np.geomspace(0.05, 200, 200000)
    ph = phase(wf)
    w180 = wf[np.argmax(ph <= -180)]
    assert omega_180((W, H(W))) == pytest.approx(w180, rel=1e-3)
    band = (wf >= w180) & (wf <= 2 * w180)
    slope = np.polyfit(wf[band], ph[band], 1)[0]                 # deg per rad/s, uniform in omega here
    lsq = phase_delay((W, H(W)), "lsq")
    two = phase_delay((W, H(W)), "two_point")
    assert phase_delay((W, H(W)), "auto") == lsq and abs(lsq - two) > 0.2 * two
    # the implementation samples the data's (log-spaced) points: agreement with the uniform fit is approximate
    assert lsq == pytest.approx(-slope / (2 * R2D), rel=0.1)


@pytest.mark.parametrize("K, T, tau", [(5.0, 0.2, 0.05), (1.5, 1.0, 0.1), (40.0, 0.2, 0.05)])
def test_crossover_and_margins_of_lagged_integrator_loop(K, T, tau):
    H, mag, phase = lag_loop(K, T, tau)
    x = max(np.roots([T**2, 1.0, -K**2]).real)                  # |L| = 1: T^2 w^4 + w^2 - K^2 = 0
    wc = np.sqrt(x)
    pm = 180 + phase(wc)
    w180 = brentq(lambda w: phase(w) + 180, 1e-3, 1e3)
    gm = -20 * np.log10(mag(w180))
    m = crossover_and_margins((W, H(W)))
    assert m.crossover == pytest.approx(wc, rel=1e-3)
    assert m.phase_margin_deg == pytest.approx(pm, abs=0.05)
    assert m.omega_180 == pytest.approx(w180, rel=1e-3)
    assert m.gain_margin_db == pytest.approx(gm, abs=0.01)
    if K == 40.0:
        assert m.phase_margin_deg < 0 and m.gain_margin_db < 0      # an unstable loop reads as such


def test_missing_crossings_are_none():
    lag = lambda w: 0.5 / (1j * w + 1)                         # phase never below -90, |L| < 1
    H = lag(W)
    assert omega_180((W, H)) is None
    assert bandwidth((W, H)) == (None, None, None, None)
    assert phase_delay((W, H)) is None
    assert crossover_and_margins((W, H)) == (None, None, None, None)
    # w180 inside the data but 2 w180 above it
    tau = 0.1
    w_short = np.geomspace(1.0, 1.5 * np.pi / (2 * tau), 500)
    Hs = integrator_delay(1.0, tau)(w_short)
    assert omega_180((w_short, Hs)) == pytest.approx(np.pi / (2 * tau), rel=1e-4)
    assert phase_delay((w_short, Hs)) is None


def test_coherence_mask_and_bad_arguments():
    H = integrator_delay(2.0, 0.1)(W)
    coh = np.where((W > 10) & (W < 12), 0.2, 0.95)               # a dip below w180 = 15.7 rad/s
    resp = FrequencyResponse("phi", "dlat", W, H, coh, np.full(W.size, 0.05))
    assert omega_180(resp, min_coherence=0.6) == pytest.approx(np.pi / 0.2, rel=1e-3)
    with pytest.raises(ConfigError, match="'pitch'"):
        bandwidth(resp, kind="pitch")
    with pytest.raises(ConfigError, match="'slope'"):
        phase_delay(resp, "slope")
    with pytest.raises(ConfigError, match="coherence"):
        omega_180((W, H), min_coherence=0.5)
