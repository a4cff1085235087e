"""The simulator's XV-15 models against the seed's tables (reference/method.md §11) and python-control."""

import numpy as np
import pytest

control = pytest.importorskip("control")

from helpers import assert_roots_close
from livesweep.errors import ConfigError
from livesweep.sim.models import get_model, xv15_cruise, xv15_hover

U0 = 170 * 1.6878099  # ft/s
G = 32.174

# Table 2.1 / 2.2 (cruise) and 2.3 / 2.4 (hover), as printed in method.md §11 (English units, per deg).
CRUISE = dict(Yv=-0.2797, Yp=-1.984, Yr=16.44, Lv=-8.119e-3, Lp=-0.6780, Lr=0.0, Nv=7.240e-3, Np=-0.2308,
              Nr=-0.9759, Yda=0.0, Ydr=-0.2173, Lda=-0.07775, Ldr=-7.024e-3, Nda=-0.02166, Ndr=0.02213)
HOVER = dict(Yv=-0.09755, Yp=-1.489, Yr=0.0, Lv=-4.374e-3, Lp=-0.2365, Lr=0.0, Nv=7.152e-4, Np=0.03862,
             Nr=-0.1416, Yda=-0.04523, Ydr=0.0, Lda=-0.05777, Ldr=0.0, Nda=5.910e-3, Ndr=0.01187)


def table_F(d, u0):
    return np.array([[d["Yv"], d["Yp"], d["Yr"] - u0, G], [d["Lv"], d["Lp"], d["Lr"], 0],
                     [d["Nv"], d["Np"], d["Nr"], 0], [0, 1, 0, 0]])


def table_G(d):
    return np.array([[d["Yda"], d["Ydr"]], [d["Lda"], d["Ldr"]], [d["Nda"], d["Ndr"]], [0, 0]])


def test_cruise_matrices_are_the_seed_tables():
    m = xv15_cruise()
    np.testing.assert_allclose(m.F, table_F(CRUISE, U0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.G, table_G(CRUISE), rtol=0, atol=1e-12)
    assert m.input_delays_s == (0.08920, 0.03276)


def test_hover_matrices_are_the_seed_tables():
    m = xv15_hover()
    np.testing.assert_allclose(m.F, table_F(HOVER, 0.0), atol=1e-12)
    np.testing.assert_allclose(m.G, table_G(HOVER), atol=1e-12)
    assert m.input_delays_s == (0.0, 0.0)


def test_cruise_eigenvalues_match_python_control_and_the_seed_modes():
    m = xv15_cruise()
    poles = control.ss(table_F(CRUISE, U0), table_G(CRUISE), np.eye(4), 0).poles()
    assert_roots_close(m.eigenvalues(), poles, atol=1e-9)
    # The seed's transfer function (Eq. 2.9), identified separately, has spiral 0.0912, roll 1.00 and
    # Dutch roll [0.237, 1.67]; the state-space tables imply the same modes within the scatter of two
    # independent fits (the seed: "nearly matches").
    real = sorted(-p.real for p in poles if abs(p.imag) < 1e-9)
    spiral, roll = real
    dr = [p for p in poles if p.imag > 1e-9][0]
    assert 0 < spiral < 0.2                      # stable, slow spiral
    assert roll == pytest.approx(1.00, rel=0.10)  # roll subsidence 1/T_R
    assert abs(dr) == pytest.approx(1.67, rel=0.20)  # Dutch roll natural frequency
    assert 0.1 < -dr.real / abs(dr) < 0.4           # lightly damped


def test_cruise_p_da_response_is_what_the_tables_imply():
    m = xv15_cruise()
    w = np.logspace(-1.5, 1.5, 60)
    H = np.zeros((5, 4))
    H[0, 1] = 180 / np.pi
    ref = control.ss(table_F(CRUISE, U0), table_G(CRUISE), H, 0)
    resp = control.frequency_response(ref, w)
    p_da = resp.frdata[0, 0] * np.exp(-1j * w * 0.08920)
    np.testing.assert_allclose(m.frequency_response(w)[0, 0], p_da, rtol=1e-9)
    # High-frequency gain = L_da in deg/s^2 per deg (Eq. 2.12: -0.07775 rad/s^2 = -4.455 deg/s^2).
    hf = m.frequency_response([1000.0])[0, 0, 0] * 1j * 1000.0 * np.exp(1j * 1000.0 * 0.0892)
    assert hf.real == pytest.approx(-4.455, rel=2e-3)


def test_cruise_p_da_nearly_matches_the_seed_transfer_function():
    """Eq. 2.9 against the SS tables: within 2 dB over 0.1-10 rad/s (measured 1.7 dB, at the Dutch
    roll) and within 12 deg of phase once the delays (TF 0.0533 s, SS 0.0892 s: each fit absorbs
    different high-order dynamics) are aligned (measured 10.8 deg, at 0.1 rad/s where the two
    spiral roots differ)."""
    w = np.array([0.1, 0.3, 1.0, 1.67, 1.93, 3.0, 10.0])
    s = 1j * w
    tf = (-4.60 * s * (s**2 + 2 * 0.278 * 1.93 * s + 1.93**2)
          / ((s + 0.0912) * (s + 1.0) * (s**2 + 2 * 0.237 * 1.67 * s + 1.67**2)))
    # method.md §11.1 fixture for the TF itself (dB, wrapped deg), checks our transcription of Eq. 2.9.
    fixture_db = [13.10, 15.08, 13.71, 11.15, 7.76, 2.61, -6.85]
    fixture_deg = [-143.6, 179.3, 134.8, 91.4, 82.7, 90.5, 64.0]
    np.testing.assert_allclose(20 * np.log10(abs(tf * np.exp(-0.0533 * s))), fixture_db, atol=0.01)
    np.testing.assert_allclose(np.angle(tf * np.exp(-0.0533 * s), deg=True), fixture_deg, atol=0.1)
    ss = xv15_cruise().frequency_response(w)[0, 0] * np.exp(1j * w * 0.0892)
    assert np.max(np.abs(20 * np.log10(abs(ss) / abs(tf)))) < 2.0
    assert np.max(np.abs(np.angle(ss / tf, deg=True))) < 12.0


def test_hover_has_the_unstable_lateral_oscillation_and_ay_is_specific_force():
    m = xv15_hover()
    unstable = [p for p in m.eigenvalues() if p.real > 0]
    assert len(unstable) == 2 and abs(unstable[0].imag) > 0.1
    # ay = v' - g phi (U0 = 0): the ay row equals the v row of [F G] minus the gravity term.
    i = m.outputs.index("ay")
    np.testing.assert_allclose(m.H[i], m.F[0] - np.array([0, 0, 0, G]), atol=1e-12)
    np.testing.assert_allclose(m.J[i], m.G[0], atol=1e-12)


def test_unknown_model_is_a_clear_error():
    with pytest.raises(ConfigError, match="unknown model 'xv16'.*xv15-cruise"):
        get_model("xv16")
