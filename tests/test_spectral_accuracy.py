"""Composite frequency responses against the exact model response (python-control), issue #3."""

import numpy as np
import pytest

from livesweep.sim.inputs import FrequencySweep, PilotNoise
from livesweep.sim.models import get_model
from livesweep.sim.scenario import Scenario, Segment, default_sensors, default_turbulence, simulate, sweep_scenario
from livesweep.spectral.analysis import analyze

control = pytest.importorskip("control")

FS = 50.0


def record(res, outputs):
    """Inputs and outputs on the 50 Hz input grid (100 Hz sensors decimated, 50 Hz ones as they are)."""
    names = list(res.inputs) + list(outputs)
    rows = [res.inputs[n].values for n in res.inputs]
    for o in outputs:
        s = res.outputs[o]
        step = int(round(s.rate_hz / FS))
        rows.append(s.values[::step])
    return np.vstack(rows), names


def exact(model, omega):
    """T(jw) from python-control (independent of livesweep), with the input delays."""
    T = control.frequency_response(control.ss(model.F, model.G, model.H, model.J), omega).frdata
    return T * np.exp(-1j * np.outer(model.input_delays_s, omega))[None, :, :]


def sweeps(seed, noise, repeats=2, duration_s=120.0):
    """Aileron sweeps 0.2-25 rad/s: as in flight test, the analysed band (0.3-20) lies inside the sweep."""
    return simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=repeats, amplitudes={"da": 3.0},
                                   omega_min_rad_s=0.2, omega_max_rad_s=25.0, duration_s=duration_s,
                                   noise=noise, turbulence=noise, seed=seed))


def test_noise_free_composite_matches_the_model_within_02_db_and_1_deg():
    res = sweeps(2, noise=False, repeats=3, duration_s=150.0)
    m = res.scenario.model
    x, names = record(res, ["p", "r", "ay", "beta"])
    an = analyze(x, names, FS, ["da"], ["p", "r", "ay", "beta"], (0.3, 20.0))
    T = exact(m, an.siso.omega)
    checked = 0
    for a, out in enumerate(an.siso.outputs):
        good = an.siso.coherence[a, 0] > 0.99
        ratio = an.siso.H[a, 0, good] / T[m.outputs.index(out), 0, good]
        assert np.max(np.abs(20 * np.log10(np.abs(ratio)))) < 0.2, out
        assert np.max(np.abs(np.angle(ratio, deg=True))) < 1.0, out
        checked += good.sum()
    assert np.mean(an.siso.coherence[0, 0] > 0.99) > 0.9   # p/da is coherent almost everywhere
    assert checked > 300


@pytest.mark.slow
def test_noisy_composite_is_within_two_random_errors_of_the_truth_at_90_percent_of_points():
    """Every magnitude point and every phase point (a Bode plot's worth each) of the adequate band
    (gamma^2 >= 0.6), pooled over four turbulence/noise realisations: neighbouring points of the
    dense log grid share errors (at 0.35 rad/s about 12 points sit in one resolution cell), so one
    realisation alone swings by several percent. Measured per seed: 87-94 %; pooled: 91 %."""
    inside, total = 0, 0
    for seed in (5, 6, 7, 8):
        res = sweeps(seed, noise=True)
        m = res.scenario.model
        x, names = record(res, ["p", "r", "ay", "beta"])
        an = analyze(x, names, FS, ["da"], ["p", "r", "ay", "beta"], (0.3, 20.0))
        T = exact(m, an.siso.omega)
        for a, out in enumerate(an.siso.outputs):
            adequate = an.siso.coherence[a, 0] >= 0.6
            ratio = an.siso.H[a, 0, adequate] / T[m.outputs.index(out), 0, adequate]
            eps = an.siso.random_error[a, 0, adequate]
            inside += np.sum(np.abs(np.log(np.abs(ratio))) <= 2 * eps) + np.sum(np.abs(np.angle(ratio)) <= 2 * eps)
            total += 2 * ratio.size
    assert total > 3000
    assert inside / total >= 0.90


def correlated_inputs_scenario(seed=3, noise=False):
    """Aileron sweep with a rudder that follows it (pilot coordinating turns) plus its own noise:
    input cross-coherence about 0.5 over the band."""
    m = get_model("xv15-cruise")
    sweep = FrequencySweep(0.3, 20.0, 100.0, 3.0, trim_s=3.0)

    class Follow:
        total_duration_s = sweep.total_duration_s

        def __init__(self, k):
            self.noise = PilotNoise(2.6, bandwidth_rad_s=25.0, seed=seed + k)

        def __call__(self, t):
            return 1.2 * sweep(t) + self.noise(t)

    segs = tuple(Segment(f"da sweep {k}", "sweep", "da", sweep, (("dr", Follow(k)),)) for k in range(2))
    sc = Scenario(model=m, segments=segs, sensors=default_sensors(m, noise=noise),
                  turbulence=default_turbulence(m) if noise else None, seed=seed)
    return simulate(sc)


def test_correlated_inputs_bias_siso_but_not_miso():
    res = correlated_inputs_scenario()
    m = res.scenario.model
    x, names = record(res, ["p", "r", "beta"])
    an = analyze(x, names, FS, ["da", "dr"], ["p", "r", "beta"], (0.5, 15.0))
    assert an.miso is not None
    T = exact(m, an.siso.omega)
    # input cross-coherence about 0.5 (median over the band)
    from livesweep.spectral.composite import interpolate_window
    from livesweep.spectral.miso import input_coherence_max
    G, usable = interpolate_window(an.windows[1], an.siso.omega, [0, 1])
    c12 = input_coherence_max(G, [0, 1])[usable]
    assert 0.3 < np.median(c12) < 0.7
    # SISO: visibly biased on every on-axis and coupled pair (each output also answers the other input)
    for out, inp in (("p", "da"), ("r", "dr"), ("beta", "dr")):
        a, b = an.siso.outputs.index(out), an.siso.inputs.index(inp)
        err = np.abs(20 * np.log10(np.abs(an.siso.H[a, b] / T[m.outputs.index(out), b])))
        assert np.median(err) > 1.0, (out, inp)
    # MISO-conditioned: every pair within 2 random-error bounds of the truth at >= 90 % of the
    # magnitude and phase points where its partial coherence is >= 0.9
    inside = total = 0
    for a, out in enumerate(an.miso.outputs):
        for b, inp in enumerate(an.miso.inputs):
            good = an.miso.coherence[a, b] >= 0.9
            ratio = an.miso.H[a, b, good] / T[m.outputs.index(out), b, good]
            eps = an.miso.random_error[a, b, good]
            inside += np.sum(np.abs(np.log(np.abs(ratio))) <= 2 * eps) + np.sum(np.abs(np.angle(ratio)) <= 2 * eps)
            total += 2 * ratio.size
    assert total > 600 and inside / total >= 0.90
    # on-axis pairs: the conditioned median error is a fraction of the SISO one
    for out, inp in (("p", "da"), ("r", "dr")):
        a, b = an.miso.outputs.index(out), an.miso.inputs.index(inp)
        t = T[m.outputs.index(out), b]
        good = an.miso.coherence[a, b] >= 0.9
        miso_err = np.median(np.abs(20 * np.log10(np.abs(an.miso.H[a, b, good] / t[good]))))
        siso_err = np.median(np.abs(20 * np.log10(np.abs(an.siso.H[a, b] / t))))
        assert miso_err < 0.3 and miso_err < siso_err / 5, (out, inp, miso_err, siso_err)
    assert an.miso.multiple_coherence.shape == (3, an.miso.omega.size)
