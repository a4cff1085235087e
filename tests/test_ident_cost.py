"""The identification criterion against method.md §7.1 written out here."""

import numpy as np
import pytest

from livesweep.errors import ConfigError
from livesweep.ident.cost import coherence_weight, fit_points, pair_cost, residuals, select_band
from livesweep.spectral.response import FrequencyResponse


def test_coherence_weight_values_of_the_method():
    # method.md §7.1 [CALC]: gamma^2 = 1 -> 0.998; 0.8 -> 0.757; 0.6 -> 0.508; 0.4 -> 0.271
    np.testing.assert_allclose(coherence_weight([1.0, 0.8, 0.6, 0.4]), [0.998, 0.757, 0.508, 0.271], atol=1e-3)


def test_cost_is_the_formula_and_a_delay_costs_what_its_phase_says():
    w = np.geomspace(0.1, 100, 200)
    s = 1j * w
    H = 5.0 / (s + 2.0)
    resp = FrequencyResponse("y", "x", w, H, np.full(200, 0.9), np.full(200, 0.05))
    pair = fit_points(resp, band_rad_s=(0.5, 20.0))
    assert pair.n_omega == 20 and pair.omega[0] == pytest.approx(0.5) and pair.omega[-1] == pytest.approx(20.0)
    assert pair_cost(pair, 5.0 / (1j * pair.omega + 2.0)) == pytest.approx(0.0, abs=1e-4)   # interpolation only
    Td = 10 ** (pair.magnitude_db / 20) * np.exp(1j * np.deg2rad(pair.phase_deg))
    assert pair_cost(pair, Td) == pytest.approx(0.0, abs=1e-20)
    tau = 0.01
    T = Td * np.exp(-1j * pair.omega * tau)
    expected = 20 / 20 * np.sum(coherence_weight(0.9) * 0.01745 * np.rad2deg(pair.omega * tau) ** 2)
    assert pair_cost(pair, T) == pytest.approx(expected, rel=1e-6)
    T2 = 2.0 * Td                                                 # +6.02 dB everywhere
    assert pair_cost(pair, T2) == pytest.approx(20 * coherence_weight(0.9) * (20 * np.log10(2)) ** 2 / 1, rel=1e-9)
    assert residuals(pair, T).size == 40


def test_band_selection_and_no_usable_coherence():
    w = np.geomspace(0.1, 100, 100)
    coh = np.where((w > 1) & (w < 10), 0.9, 0.3)
    coh[(w > 30) & (w < 40)] = 0.95
    resp = FrequencyResponse("y", "x", w, 1 / (1j * w + 1), coh, np.full(100, 0.1))
    lo, hi = select_band(resp)
    assert lo > 1 and lo < 1.2 and hi < 10 and hi > 8
    bad = FrequencyResponse("y", "x", w, 1 / (1j * w + 1), np.full(100, 0.2), np.full(100, 0.1))
    with pytest.raises(ConfigError, match="pair y/x has no band with coherence >= 0.6"):
        fit_points(bad)
