"""The closing verdict and its margin, against a system whose true coherence is known.

References the code did not make: Bendat & Piersol's random errors of the coherence and of the
response (written here from the number of averages), and the true coherence of a linear system
with additive white output noise, ``gamma^2 = |G|^2 S_u / (|G|^2 S_u + S_n)``, which crosses 0.6 at
a frequency computed here in closed form.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from livesweep.spectral.criteria import Criteria
from livesweep.spectral.injection import SweepInjection, ardupilot_chirp
from livesweep.spectral.verdict import coherence_sigma, judge_test_point

FS = 50.0
BAND = (1.0, 40.0)
#: G(s) = K / (s / WB + 1) with white input and output noise of equal variance: gamma^2 = |G|^2 /
#: (|G|^2 + 1) = 0.6 where |G|^2 = 1.5. MARGINAL_SIGMAS was measured on K 3, WB 4, 240 s (seeds
#: 0-7), then checked on K 2, WB 8, 120 s (seeds 100-107: a first value, 2, bracketed too widely
#: there and was set to the measured 1.5); the bracket is judged here on a third system and seeds.
K, WB, SECONDS = 2.5, 6.0, 180.0
W_CROSS = WB * math.sqrt(K ** 2 / 1.5 - 1.0)
TRUE_FRACTION = math.log(W_CROSS / BAND[0]) / math.log(BAND[1] / BAND[0])
EVERYTHING_SWEPT = SweepInjection(BAND[0], BAND[1], t_record_s=1.0)       # the excitation is not under test here


@pytest.mark.parametrize("g2", [0.3, 0.6, 0.9])
@pytest.mark.parametrize("n_d", [3, 5, 20])
def test_coherence_sigma_is_bendat_and_piersols(g2, n_d):
    """sigma(gamma^2) from the response's random error equals B&P's from the number of averages."""
    eps_r = math.sqrt(1 - g2) / (math.sqrt(g2) * math.sqrt(2 * n_d))
    want = g2 * math.sqrt(2) * (1 - g2) / (math.sqrt(g2) * math.sqrt(n_d))
    assert float(coherence_sigma(np.array([g2]), np.array([eps_r]))[0]) == pytest.approx(want, rel=1e-12)


def _record(seed: int, seconds: float = SECONDS) -> np.ndarray:
    """u white, y = G u + n with n white of u's variance, on a 50 Hz grid (bilinear G, prewarped at W_CROSS)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    u = rng.standard_normal(n)
    b, a = signal.bilinear([K], [1 / WB, 1.0], fs=FS)
    y = signal.lfilter(b, a, u) + rng.standard_normal(n)
    return np.vstack([u, y])


def test_the_adequate_fraction_brackets_the_true_one_and_a_threshold_inside_the_bracket_is_marginal():
    """The true coherence is adequate over 1 rad/s .. W_CROSS (10.7 rad/s: 64 % of the band's decades).
    Over eight independent records: the estimate is near it, its random-error bracket holds it as a
    one-sigma bracket should, a threshold at the true fraction then reads '(marginal)', and one 30
    points away never does."""
    held, marginal_at_truth, marginal_far = 0, 0, 0
    for seed in range(200, 208):
        values = _record(seed)
        j = judge_test_point(values, ["u", "y"], FS, "u", ["y"], BAND, injection=EVERYTHING_SWEPT, elapsed_s=1e3,
                             criteria=Criteria(required_fraction=TRUE_FRACTION))
        (p,) = j.pairs
        assert p.adequate_fraction == pytest.approx(TRUE_FRACTION, abs=0.06)
        lo, hi = p.adequate_range
        held += lo <= TRUE_FRACTION <= hi
        marginal_at_truth += j.marginal
        far = judge_test_point(values, ["u", "y"], FS, "u", ["y"], BAND, injection=EVERYTHING_SWEPT, elapsed_s=1e3,
                               criteria=Criteria(required_fraction=TRUE_FRACTION - 0.3))
        assert far.verdict == "GO" and not far.marginal and far.label == "GO"
        marginal_far += far.marginal
    # a one-sigma bracket holds the truth 68 % of the time: at least 4 of 8 at the binomial 5 % level
    # (measured here: 5 of 8, and 5 of 8 marginal)
    assert held >= 4 and marginal_at_truth >= 4 and marginal_far == 0, (held, marginal_at_truth)


def test_each_rule_says_its_distance_from_the_threshold():
    j = judge_test_point(_record(0), ["u", "y"], FS, "u", ["y"], BAND, injection=EVERYTHING_SWEPT, elapsed_s=1e3,
                         criteria=Criteria(required_fraction=0.3))
    (p,) = j.pairs
    pair_line = next(r for r in j.reasons if r.startswith("y/u:"))
    assert f"{100 * (p.adequate_fraction - 0.3):+.0f} points" in pair_line and "within the random error" in pair_line
    swept_line = next(r for r in j.reasons if r.startswith("u:"))
    assert "100 % of 1-40 rad/s swept (need 30 %: +70 points)" in swept_line


def test_a_running_verdict_judges_the_band_swept_so_far_and_says_how_much():
    """Half way up ArduCopter's chirp: judged over the start frequency to where the chirp is, 'so far'."""
    inj = ardupilot_chirp(0.5, 12.0, 40.0, t_fade_in_s=3.0, t_fade_out_s=2.0)
    elapsed = 1.0 + 4.0 + 18.0
    w_now = inj.swept_band(elapsed)[1]
    j = judge_test_point(_record(1, 60.0), ["u", "y"], FS, "u", ["y"], BAND, injection=inj, elapsed_s=elapsed,
                         final=False, criteria=Criteria(required_fraction=0.3))
    assert not j.final and j.band_rad_s == pytest.approx(inj.band_rad_s)
    assert j.swept_rad_s == pytest.approx((math.pi, w_now))
    assert j.label == f"{j.verdict} so far"
    assert j.progress() == f"0.5-{w_now / (2 * math.pi):.3g} Hz of 0.5-12 Hz swept"
    assert j.pairs[0].response.omega[-1] == pytest.approx(w_now)          # the band so far, nothing above it


def test_a_chirp_stopped_early_is_no_go_naming_the_band_it_never_reached():
    inj = ardupilot_chirp(0.5, 12.0, 40.0)
    elapsed = 1.0 + 4.0 + 9.0                                             # a quarter of the way up
    w_cut = inj.swept_band(elapsed)[1]
    j = judge_test_point(_record(2, 60.0), ["u", "y"], FS, "u", ["y"], BAND, injection=inj, elapsed_s=elapsed)
    assert j.verdict == "NO-GO" and not j.marginal
    gap = next(m for m in j.missing if m.startswith("u needs a sweep over"))
    assert gap.startswith(f"u needs a sweep over {w_cut:.3g}-75.4 rad/s: the injection")
