"""The report's handling-qualities numbers: only for attitude responses (a rate output integrated,
an attitude output as it is), with the control sense read from the response, not guessed."""

import numpy as np
import pytest

from livesweep.stages.parametric import handling_qualities

W = np.geomspace(0.3, 40.0, 300)
S = 1j * W
TAU = 0.05


def _roll_rate():        # p/da = 4 / (s + 2) e^(-tau s), deg/s per deg
    return 4.0 / (S + 2.0) * np.exp(-S * TAU)


def _pitch_rate():       # q/de = 6 (s + 1.2) / (s^2 + 2 0.5 4 s + 16) e^(-tau s): positive, phase below -90 deg up high
    return 6.0 * (S + 1.2) / (S**2 + 4.0 * S + 16.0) * np.exp(-S * TAU)


def test_an_attitude_output_is_not_integrated_again():
    rate = handling_qualities(W, _roll_rate(), output_units="deg/s")
    att = handling_qualities(W, _roll_rate() / S, output_units="deg")
    assert rate["response"] == "attitude (rate / s)" and att["response"] == "attitude"
    for key in ("omega_180_rad_s", "bandwidth_rad_s", "phase_delay_s"):
        assert att[key] == pytest.approx(rate[key], rel=1e-9), key


def test_a_positive_pitch_response_is_not_flipped_and_a_reversed_one_is():
    pos = handling_qualities(W, _pitch_rate(), output_units="deg/s")
    neg = handling_qualities(W, -_pitch_rate(), output_units="deg/s")
    assert pos["sign_flipped"] is False and neg["sign_flipped"] is True
    # the attitude response q/(s de) crosses -180 deg where the model's phase says (analytic, on a fine grid)
    w = np.geomspace(0.3, 40.0, 200001)
    ph = np.unwrap(np.angle(6.0 * (1j * w + 1.2) / ((1j * w) ** 2 + 4.0 * 1j * w + 16.0) * np.exp(-1j * w * TAU)
                            / (1j * w)))
    w180 = w[np.argmax(np.rad2deg(ph) <= -180.0)]
    assert pos["omega_180_rad_s"] == pytest.approx(w180, rel=2e-3)
    assert neg["omega_180_rad_s"] == pytest.approx(pos["omega_180_rad_s"], rel=1e-9)


def test_outputs_that_are_not_attitudes_get_no_handling_qualities():
    assert handling_qualities(W, _roll_rate(), output_units="ft/s^2") is None
    assert handling_qualities(W, _roll_rate(), output_units="deg") is not None
