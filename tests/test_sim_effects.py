"""Each injectable effect against its analytic frequency response; the engine against python-control.

Method: a noise-free multisine (integer periods of 20 s) after 100 s of settling; complex amplitudes
by least squares (tests/helpers.py). The engine's discretisation errors are below (w dt)^2/8
(0.001 dB at 12.6 rad/s on the 400 Hz grid), so 0.005 dB and 0.05 deg are honest bounds.
"""

import numpy as np
import pytest
from scipy.linalg import solve_continuous_lyapunov

from helpers import Multisine, db, phasors
from livesweep.errors import ConfigError
from livesweep.sim.effects import EFFECT_KINDS, make_effect, parse_effect
from livesweep.sim.engine import augment
from livesweep.sim.models import get_model
from livesweep.sim.scenario import Scenario, Segment, default_sensors, simulate
from livesweep.sim.engine import Turbulence

control = pytest.importorskip("control")

PERIOD = 20.0
OMEGAS = 2 * np.pi / PERIOD * np.array([1, 2, 4, 8, 16, 32, 40])   # 0.31 .. 12.6 rad/s
SETTLE = 100.0
DB_TOL, DEG_TOL = 0.005, 0.05


class MultisineInput:
    def __init__(self, amplitude=0.5):
        self.sig = Multisine(OMEGAS, amplitude, PERIOD)
        self.total_duration_s = SETTLE + 2 * PERIOD

    def __call__(self, t):
        return self.sig(t)


def run(effects=(), axis="da", model="xv15-cruise", noise=False, turbulence=None, seed=1):
    m = get_model(model)
    sc = Scenario(model=m, segments=(Segment("multisine", "multisine", axis, MultisineInput()),),
                  effects=tuple(effects), sensors=default_sensors(m, noise=noise), turbulence=turbulence, seed=seed)
    return simulate(sc)


def measured_response(res, output, axis):
    y, u = res.outputs[output], res.inputs[axis]
    t0 = res.scenario.boot_time_s + SETTLE
    my, mu = y.t_s >= t0, u.t_s >= t0
    return phasors(y.t_s[my], y.values[my], OMEGAS) / phasors(u.t_s[mu], u.values[mu], OMEGAS)


@pytest.fixture(scope="module")
def nominal():
    return {axis: run(axis=axis) for axis in ("da", "dr")}


def assert_ratio(ratio, expected):
    np.testing.assert_allclose(db(ratio), db(expected), atol=DB_TOL)
    np.testing.assert_allclose(np.angle(ratio / expected, deg=True), 0.0, atol=DEG_TOL)


@pytest.mark.slow
def test_engine_matches_python_control_on_every_pair(nominal):
    """The whole simulator (augmentation, FOH discretisation, delays, sampling) against python-control."""
    m = get_model("xv15-cruise")
    sys = control.ss(m.F, m.G, m.H, m.J)
    ref = control.frequency_response(sys, OMEGAS).frdata  # (n_out, n_in, n_freq)
    for j, axis in enumerate(m.inputs):
        delay = np.exp(-1j * OMEGAS * m.input_delays_s[j])
        for i, out in enumerate(m.outputs):
            assert_ratio(measured_response(nominal[axis], out, axis), ref[i, j] * delay)


# kind, parameters, (output, axis) observed, analytic factor written here, independently of the code
INPUT_AND_OUTPUT_EFFECTS = [
    ("time_delay", dict(input="da", delay_s=0.06), ("p", "da"), lambda s: np.exp(-0.06 * s)),
    ("actuator_lag", dict(input="da", time_constant_s=0.1), ("p", "da"), lambda s: 1 / (0.1 * s + 1)),
    ("actuator_second_order", dict(input="dr", omega_rad_s=15.0, zeta=0.6), ("r", "dr"),
     lambda s: 225.0 / (s**2 + 18.0 * s + 225.0)),
    ("structural_mode", dict(output="p", omega_rad_s=OMEGAS[5], zeta_pole=0.05, zeta_zero=0.15), ("p", "da"),
     lambda s: 1 + 2.0 * 2 * 0.05 * OMEGAS[5] * s / (s**2 + 2 * 0.05 * OMEGAS[5] * s + OMEGAS[5] ** 2)),
    # a dipole with its zero below the pole: (w/wz)^2 (s^2 + 2 zz wz s + wz^2)/(s^2 + 2 zp w s + w^2)
    ("structural_mode", dict(output="r", omega_rad_s=OMEGAS[5], zeta_pole=0.04, zeta_zero=0.1,
                             omega_zero_rad_s=0.9 * OMEGAS[5]), ("r", "dr"),
     lambda s: (1 / 0.81) * (s**2 + 2 * 0.1 * 0.9 * OMEGAS[5] * s + (0.9 * OMEGAS[5]) ** 2)
     / (s**2 + 2 * 0.04 * OMEGAS[5] * s + OMEGAS[5] ** 2)),
    ("notch_filter", dict(input="da", omega_rad_s=OMEGAS[5], zeta=0.3, depth=0.8), ("p", "da"),
     lambda s: (s**2 + 2 * 0.3 * 0.2 * OMEGAS[5] * s + OMEGAS[5] ** 2) / (s**2 + 2 * 0.3 * OMEGAS[5] * s + OMEGAS[5] ** 2)),
    ("sensor_skew", dict(output="p", delay_s=0.05), ("p", "da"), lambda s: np.exp(-0.05 * s)),
    ("sensor_skew", dict(output="ay", delay_s=-0.03), ("ay", "dr"), lambda s: np.exp(0.03 * s)),
    ("scale_factor", dict(output="r", factor=1.15), ("r", "dr"), lambda s: 1.15 + 0 * s),
]


@pytest.mark.parametrize("kind, params, pair, analytic", INPUT_AND_OUTPUT_EFFECTS,
                         ids=[f"{k}-{p.get('input', p.get('output'))}" for k, p, _, _ in INPUT_AND_OUTPUT_EFFECTS])
def test_effect_is_its_analytic_frequency_response(nominal, kind, params, pair, analytic):
    output, axis = pair
    effect = make_effect(kind, **params)
    res = run([effect], axis=axis)
    ratio = measured_response(res, output, axis) / measured_response(nominal[axis], output, axis)
    expected = analytic(1j * OMEGAS)
    assert_ratio(ratio, expected)
    np.testing.assert_allclose(effect.frequency_response(OMEGAS), expected, rtol=1e-12)
    # other pairs are untouched by an output effect on another output
    if effect.acts_on == "output":
        other = "phi" if output != "phi" else "p"
        r2 = measured_response(res, other, axis) / measured_response(nominal[axis], other, axis)
        assert_ratio(r2, np.ones_like(expected))


def test_structural_mode_peaks_at_the_ratio_of_its_dampings():
    """A dipole with zero and pole at one frequency peaks at zeta_zero / zeta_pole there."""
    e = make_effect("structural_mode", output="p", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.125)
    w = np.linspace(5, 20, 3001)
    mag = np.abs(e.frequency_response(w))
    assert mag.max() == pytest.approx(2.5, rel=1e-6)
    assert w[mag.argmax()] == pytest.approx(12.0, abs=0.01)
    assert abs(e.frequency_response([0.01])[0]) == pytest.approx(1.0, abs=1e-3)


def test_bias_spikes_and_dropouts_do_exactly_what_they_say(nominal):
    effects = [make_effect("sensor_bias", output="p", bias=0.7),
               make_effect("spikes", output="r", rate_hz=0.5, magnitude=20.0),
               make_effect("dropouts", output="ay", count=3, duration_s=0.5)]
    res = run(effects)
    nom = nominal["da"].outputs
    np.testing.assert_allclose(res.outputs["p"].values - nom["p"].values, 0.7, atol=1e-9)
    d = res.outputs["r"].values - nom["r"].values
    idx = np.flatnonzero(np.abs(d) > 1e-9)
    assert idx.tolist() == sorted(res.injected["spikes"]["r"])
    np.testing.assert_allclose(np.abs(d[idx]), 20.0, atol=1e-9)
    assert 40 <= idx.size <= 100   # Poisson(0.5/s x 140 s = 70): far outside 99.9 % otherwise
    t = res.outputs["ay"].t_s
    expected_gap = np.zeros(t.size, bool)
    for a, b in res.injected["dropouts"]["ay"]:
        expected_gap |= (t >= a) & (t < b)
    assert len(res.injected["dropouts"]["ay"]) == 3
    np.testing.assert_array_equal(~res.outputs["ay"].valid, expected_gap)
    assert expected_gap.sum() >= 50
    np.testing.assert_array_equal(res.outputs["ay"].values[~expected_gap], nom["ay"].values[~expected_gap])


def test_sensor_noise_has_the_configured_standard_deviation(nominal):
    res = run(noise=True)
    for s in res.scenario.sensors:
        e = res.outputs[s.output].values - nominal["da"].outputs[s.output].values
        # relative standard error of a sample std over n >= 7000 samples is < 1 %
        assert np.std(e) == pytest.approx(s.noise_std, rel=0.04)
        assert abs(np.mean(e)) < 4 * s.noise_std / np.sqrt(e.size)


@pytest.mark.slow
def test_turbulence_output_variance_matches_the_lyapunov_solution():
    m = get_model("xv15-cruise")
    turb = Turbulence(sigmas=(3.0, 0.02), correlation_time_s=4.0)

    class Quiet:
        total_duration_s = 1500.0

        def __call__(self, t):
            return np.zeros_like(t)

    res = simulate(Scenario(model=m, segments=(Segment("calm", "trim", None, Quiet()),),
                            sensors=default_sensors(m, noise=False), turbulence=turb, seed=5))
    sysa = augment(m, [], turb)
    P = solve_continuous_lyapunov(sysa.A, -sysa.Bw @ sysa.Bw.T)
    for out in ("p", "beta"):
        i = m.outputs.index(out)
        y = res.outputs[out].values[res.outputs[out].t_s > res.scenario.boot_time_s + 100]
        # ~1400 s / (2 x 4 s correlation) = 175 independent looks: sample variance within +/-30 %
        assert np.var(y) == pytest.approx(sysa.C[i] @ P @ sysa.C[i], rel=0.3)


def test_effects_are_parsed_by_name_and_bad_ones_are_named():
    assert parse_effect("sensor_skew:output=p,delay_s=0.05") == make_effect("sensor_skew", output="p", delay_s=0.05)
    assert set(EFFECT_KINDS) >= {"time_delay", "actuator_lag", "actuator_second_order", "structural_mode",
                                  "sensor_skew", "scale_factor", "sensor_bias", "spikes", "dropouts"}
    with pytest.raises(ConfigError, match="unknown effect 'wobble'"):
        parse_effect("wobble:output=p")
    with pytest.raises(ConfigError, match="actuator_lag: time_constant_s must be > 0"):
        parse_effect("actuator_lag:input=da,time_constant_s=-1")
    with pytest.raises(ConfigError, match="missing parameter"):
        parse_effect("time_delay:input=da")
    with pytest.raises(ConfigError, match="unknown input 'de'"):
        run([make_effect("time_delay", input="de", delay_s=0.1)])
    with pytest.raises(ConfigError, match="unknown output 'q'"):
        run([make_effect("scale_factor", output="q", factor=1.1)])


def test_engine_equals_scipy_lsim_with_first_order_hold():
    """Same augmented system, grid and input (delays zeroed, lsim has none): identical to rounding."""
    from dataclasses import replace

    from scipy import signal as sps

    from livesweep.sim.engine import step

    m = get_model("xv15-cruise")
    sysa = replace(augment(m, [make_effect("actuator_lag", input="da", time_constant_s=0.05),
                               make_effect("structural_mode", output="p", omega_rad_s=11.0, zeta_pole=0.05,
                                           zeta_zero=0.1, omega_zero_rad_s=10.0)]),
                   delays_s=np.zeros(2))
    t = np.arange(0, 30, 1 / 400)
    u = np.column_stack([np.sin(0.5 * t + 0.05 * t**2), 0.3 * np.cos(2.1 * t)])
    _, y = step(sysa, 1 / 400, u, np.zeros((t.size, sysa.Bw.shape[1])))
    _, y_ref, _ = sps.lsim(sps.StateSpace(sysa.A, sysa.B, sysa.C, sysa.D), u, t, interp=True)
    np.testing.assert_allclose(y, y_ref, rtol=0, atol=1e-9 * np.max(np.abs(y_ref)))
