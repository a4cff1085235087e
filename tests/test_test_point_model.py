"""The model of a test point (livesweep.ident.test_point_model) on responses of known systems.

References the code did not make: analytic responses of first- and second-order systems with a
delay, their analytic crossover and phase margin (brentq on the closed form), and the scatter of
a figure over parameters drawn from the fit's own covariance (the propagated bound must equal it
to first order).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from livesweep.ident.envelope import EnvelopeLimits, Prediction
from livesweep.ident.test_point_model import _response, model_pair
from livesweep.spectral.criteria import Criteria
from livesweep.spectral.response import FrequencyResponse
from livesweep.stages.parametric import TransferFunctionSpec, handling_qualities
from livesweep.ident.transfer_function import TransferFunctionModel
from livesweep.telemetry.recorder import RESULT_SCHEMAS

W = np.geomspace(2.0, 90.0, 160)


def _resp(H, seed=None, output="p", input="roll", mag_noise=0.0, phase_noise_deg=0.0):
    H = np.asarray(H, complex)
    if seed is not None:
        rng = np.random.default_rng(seed)
        H = H * 10 ** (rng.normal(0, mag_noise, H.size) / 20) * np.exp(1j * np.radians(rng.normal(0, phase_noise_deg, H.size)))
    return FrequencyResponse(output, input, W, H, np.full(W.size, 0.97), np.full(W.size, 0.03))


def first_order(K=40.0, a=20.0, tau=0.015, w=W):
    s = 1j * w
    return K / (s + a) * np.exp(-tau * s)


def second_order(wn=30.0, zeta=0.35, tau=0.01, w=W):
    s = 1j * w
    return wn ** 2 / (s * s + 2 * zeta * wn * s + wn ** 2) * np.exp(-tau * s)


def _param(pm, name):
    return next(p for p in pm.parameters if p.name == name)


def test_a_first_order_rate_response_gets_the_first_order_model_and_its_values():
    pm = model_pair(_resp(first_order(), seed=1, mag_noise=0.2, phase_noise_deg=1.0), output_units="deg/s")
    assert pm.structure == "first order" and pm.fit.cost <= 50
    for name, true in (("gain", 40.0), ("1/T", 20.0), ("tau", 0.015)):
        p = _param(pm, name)
        assert p.cramer_rao is not None and p.cramer_rao > 0
        assert abs(p.value - true) <= 3 * p.cramer_rao, (name, p.value, p.cramer_rao)
        assert abs(p.value / true - 1) < 0.05
    assert not pm.flags


def test_a_resonant_response_gets_the_second_order_model():
    pm = model_pair(_resp(second_order(), seed=2, mag_noise=0.2, phase_noise_deg=1.0), output_units="deg/s")
    assert pm.structure == "second order"
    assert abs(_param(pm, "zeta").value - 0.35) < 0.02
    assert abs(_param(pm, "wn").value - 30.0) < 0.5
    assert abs(_param(pm, "tau").value - 0.01) < 0.001


def test_an_output_without_rate_or_attitude_units_needs_a_table():
    from livesweep.errors import ConfigError

    with pytest.raises(ConfigError, match="p/roll: no structure"):
        model_pair(_resp(first_order()), output_units="m/s^2")


def test_a_figure_bound_equals_the_scatter_of_the_figure_over_the_parameters_covariance():
    pm = model_pair(_resp(second_order(), seed=3, mag_noise=0.5, phase_noise_deg=3.0), output_units="deg/s")
    fit = pm.fit
    bw = next(f for f in pm.figures if f.name == "bandwidth")
    assert bw.value is not None and bw.cramer_rao is not None
    rng = np.random.default_rng(0)
    keys = list(fit.parameters)
    theta = np.array([fit.parameters[k] for k in keys])
    draws = rng.multivariate_normal(theta, np.asarray(fit.covariance), size=400)
    values = []
    for d in draws:
        hq = handling_qualities(W, _response(fit, dict(zip(keys, d)), W), output_units="deg/s")
        if hq and hq["bandwidth_rad_s"] is not None:
            values.append(hq["bandwidth_rad_s"])
    assert len(values) > 380
    # first order: equal; the standard error of a standard deviation from 400 draws is 3.5 %
    assert np.std(values) == pytest.approx(bw.cramer_rao, rel=0.15)


def test_the_phase_margin_of_a_broken_loop_pair_and_its_limit():
    K, a, tau = 400.0, 10.0, 0.02                       # L = K / (s (s + a)) e^(-tau s)
    s = 1j * W
    L = K / (s * (s + a)) * np.exp(-tau * s)
    wc = brentq(lambda w: K / (w * math.hypot(w, a)) - 1.0, 1.0, 100.0)
    pm_true = 180.0 - 90.0 - math.degrees(math.atan2(wc, a)) - math.degrees(tau * wc)
    spec = TransferFunctionSpec(TransferFunctionModel("loop", numerator="", denominator="s (1/T)", delay=True,
                                                      output="p", input="err"))
    resp = FrequencyResponse("p", "err", W, L, np.full(W.size, 0.97), np.full(W.size, 0.03))
    limits = EnvelopeLimits(min_phase_margin_deg=round(pm_true) + 5.0, broken_loop=("p/err",))
    pm = model_pair(resp, output_units="deg/s", spec=spec, limits=limits)
    fig = {f.name: f for f in pm.figures}
    assert fig["crossover"].value == pytest.approx(wc, rel=0.01)
    assert fig["phase margin"].value == pytest.approx(pm_true, abs=0.5)
    [check] = [c for c in pm.limits if c.name == "phase margin"]
    assert not check.ok
    assert check.text.startswith(f"p/err: phase margin {fig['phase margin'].value:.3g}")
    assert check.text.endswith(f"limit {round(pm_true) + 5.0:g} deg: do not proceed")
    ok = model_pair(resp, output_units="deg/s", spec=spec,
                    limits=EnvelopeLimits(min_phase_margin_deg=round(pm_true) - 5.0, broken_loop=("p/err",)))
    assert all(c.ok for c in ok.limits)


def test_damping_delay_and_bandwidth_limits_name_the_value_and_the_limit():
    resp = _resp(second_order(zeta=0.35, tau=0.01), seed=4, mag_noise=0.2, phase_noise_deg=1.0)
    limits = EnvelopeLimits(min_damping=0.5, max_delay_s=0.005, bandwidth_rad_s=(1.0, 200.0))
    pm = model_pair(resp, output_units="deg/s", limits=limits)
    by = {c.name.split()[0]: c for c in pm.limits}
    assert not by["damping"].ok and "limit 0.5: do not proceed" in by["damping"].text
    assert not by["delay"].ok and "limit 0.005 s: do not proceed" in by["delay"].text
    assert by["bandwidth"].ok and "do not proceed" not in by["bandwidth"].text


def test_a_true_prediction_passes_and_one_with_its_delay_doubled_does_not():
    resp = _resp(second_order(zeta=0.6, wn=40.0, tau=0.012), seed=5, mag_noise=0.3, phase_noise_deg=2.0)
    true = Prediction(name="design", output="p", input="roll", gain=1600.0, denominator="[0.6, 40]", delay_s=0.012)
    wrong = Prediction(name="design", output="p", input="roll", gain=1600.0, denominator="[0.6, 40]", delay_s=0.024)
    good = model_pair(resp, output_units="deg/s", prediction=true)
    bad = model_pair(resp, output_units="deg/s", prediction=wrong)
    [g] = [c for c in good.limits if c.name == "prediction"]
    [b] = [c for c in bad.limits if c.name == "prediction"]
    assert g.ok and g.value < 100
    assert not b.ok and b.value > 100 and "the aircraft is not what was predicted" in b.text
    assert "predicted_magnitude_db" in bad.curve


def _validate(schema: dict, value, where="$"):
    """The parts of JSON Schema the recorder's schemas use: type, properties, required, items, enum."""
    types = schema.get("type")
    if types is not None:
        types = [types] if isinstance(types, str) else types
        ok = {"object": isinstance(value, dict), "array": isinstance(value, list), "string": isinstance(value, str),
              "boolean": isinstance(value, bool), "null": value is None,
              "integer": isinstance(value, int) and not isinstance(value, bool),
              "number": isinstance(value, (int, float)) and not isinstance(value, bool)}
        assert any(ok[t] for t in types), f"{where}: {value!r} is not {types}"
    if "enum" in schema:
        assert value in schema["enum"], f"{where}: {value!r} not in {schema['enum']}"
    if isinstance(value, dict):
        for k in schema.get("required", ()):
            assert k in value, f"{where}: missing {k}"
        for k, v in value.items():
            if k in schema.get("properties", {}):
                _validate(schema["properties"][k], v, f"{where}.{k}")
            elif isinstance(schema.get("additionalProperties"), dict):
                _validate(schema["additionalProperties"], v, f"{where}.{k}")
    if isinstance(value, list) and "items" in schema:
        for i, v in enumerate(value):
            _validate(schema["items"], v, f"{where}[{i}]")


def test_the_record_follows_the_channel_schema():
    from livesweep.ident.test_point_model import TestPointModel

    pm = model_pair(_resp(second_order(), seed=6), output_units="deg/s",
                    limits=EnvelopeLimits(min_damping=0.5),
                    prediction=Prediction(name="x", output="p", input="roll", gain=900.0, denominator="[0.35, 30]"))
    record = {**TestPointModel((pm,), (), Criteria()).to_dict(),
              "test_point": {"number": 1, "start_s": 1.0, "end_s": 41.0, "swept_input": "roll", "axis": 7,
                             "source": "autopilot", "verdict": "GO", "label": "GO"},
              "trend": [], "trend_notes": []}
    _validate(RESULT_SCHEMAS["model"], record)
    assert record["breaches"] and not record["limits_ok"]


def test_a_state_space_prediction_is_the_analytic_response_and_is_held_against_the_data():
    wn, zeta, tau = 40.0, 0.6, 0.012
    A = [[0.0, 1.0], [-wn * wn, -2 * zeta * wn]]
    ss = {"a": A, "b": [[0.0], [wn * wn]], "c": [[1.0, 0.0], [0.0, 1.0]], "d": [[0.0], [0.0]]}
    pred = Prediction(name="ss", output="p", input="roll", state_space=ss, row=0, column=0, delay_s=tau)
    assert np.allclose(pred.response(W), second_order(wn=wn, zeta=zeta, tau=tau), rtol=1e-9, atol=1e-12)
    rate = Prediction(name="ss", output="p", input="roll", state_space=ss, row=1, column=0)   # x2 = x1': s H
    assert np.allclose(rate.response(W), 1j * W * second_order(wn=wn, zeta=zeta, tau=0.0), rtol=1e-9)
    resp = _resp(second_order(zeta=zeta, wn=wn, tau=tau), seed=7, mag_noise=0.3, phase_noise_deg=2.0)
    good = model_pair(resp, output_units="deg/s", prediction=pred)
    bad = model_pair(resp, output_units="deg/s", prediction=Prediction(
        name="ss", output="p", input="roll", state_space=ss, row=0, column=0, delay_s=2 * tau))
    assert [c.ok for c in good.limits if c.name == "prediction"] == [True]
    assert [c.ok for c in bad.limits if c.name == "prediction"] == [False]


@pytest.mark.parametrize("table, message", [
    ('state_space = { a = [[0.0, 1.0]], b = [[1.0]], c = [[1.0]], d = [[0.0]] }',
     "predictions.x.state_space: a is 1 x 2, must be 1 x 1"),
    ('gain = 2.0\ndenominator = "[zeta, 3.0]"', "predictions.x.denominator: a prediction gives every value"),
    ('denominator = "[0.5, 3.0]"', "predictions.x.gain: must be a finite, non-zero number"),
    ('gain = 1.0\nstate_space = { a = [[-1.0]], b = [[1.0]], c = [[1.0]], d = [[0.0]] }',
     "give either state_space or gain"),
])
def test_a_bad_prediction_is_refused_naming_its_key(tmp_path, table, message):
    from livesweep.config import read_channel_map
    from livesweep.errors import ConfigError

    m = tmp_path / "m.toml"
    m.write_text('[signals.p]\ntopic = "/a"\nfield = "p"\n\n[signals.roll]\ntopic = "/a"\nfield = "r"\n\n'
                 f'[predictions.x]\noutput = "p"\ninput = "roll"\n{table}\n')
    with pytest.raises(ConfigError) as e:
        read_channel_map(m)
    assert str(m) in str(e.value) and message in str(e.value)
    assert "\n" not in str(e.value)


def test_a_quadratic_more_damped_than_two_is_flagged_as_two_real_roots():
    # two real poles (2 and 12 rad/s) with a first-order fit far from excellent: the second-order
    # model fits them as one quadratic of damping (2 + 12) / (2 sqrt(24)) = 1.43 < 2, so no flag;
    # poles at 1 and 40 rad/s give 41 / (2 sqrt(40)) = 3.2 > 2: flagged
    s = 1j * W
    for (a, b), flagged in (((2.0, 12.0), False), ((1.0, 40.0), True)):
        H = a * b / ((s + a) * (s + b)) * np.exp(-0.01 * s)
        pm = model_pair(_resp(H), output_units="deg/s")
        assert pm.structure == "second order"          # first order is far from excellent on two poles
        zeta = _param(pm, "zeta").value
        assert zeta == pytest.approx((a + b) / (2 * np.sqrt(a * b)), rel=1e-3)
        assert any("degenerate quadratic" in f for f in pm.flags) == flagged, (a, b, pm.flags)
