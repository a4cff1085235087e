"""The residual loop on real (simulator-flown) data: X-Plane Cessna 172 elevator sweeps (shared data,
README section ``xplane_c172_pitch_sweeps``; no stated licence: read in place, never copied; every
test skips when the file is absent). Loading as in ``tests/test_xplane_real_data.py``.

Model: short period plus pitch attitude in yoke units (states alpha [deg], q [deg/s], theta [deg];
input de = yoke -1..1; outputs q, theta, alpha, all coherent, gamma^2 >= 0.89 over 1-30 rad/s)::

    alpha' = Za alpha + q + Zde de
    q'     = Ma alpha + Mq q + Mde de
    theta' = q

Fitting band 1-30 rad/s: below ~1 rad/s the phugoid (not in the model) shapes q/de and theta/de.
Identification on 5-190 s (sweeps 1 and 2), time-domain verification on the held-out third sweep
(190-285 s). The sweeps are repeats, not dissimilar manoeuvres, but it is the only held-out data.
J_rms ~4.9 fails the 2.0 guideline whatever the loop does: theta drifts with the phugoid
(TIC theta 0.22; q 0.09, alpha 0.03), so verification here only ranks changes.

Measured findings:

* The record has no input delay; the outputs *lead* the logged yoke: the residual phase grows
  with w (+10 deg on q, +15 deg on theta at 30 rad/s) and the free delay sits at its bound 0.
  Advancing the yoke by 60 ms (3 samples) gives a fitted delay of 51.5 ms: the lead is ~8.5 ms
  (100 ms -> 91.4 ms). The yoke is also sample-and-held in the log (71 % repeated values).
* (A) nominal, delay free: the free delay sits at its bound 0, so it cannot absorb the lead; the
  loop finds the same yoke skew as in (B) and, like there, does not add it (I% and verification).
* (B) delay removed: no time-delay candidate at all (the best delay is negative); the top is a
  skew of the yoke's measurement, 8.3 ms (J_ave 9.07 -> 2.21), rejected by I% (12.7 > 10) and by
  verification on the held-out sweep (worse beyond noise).
* (B') yoke advanced 60 ms, delay removed: the loop adds time_delay at de, tau = the free fit's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from livesweep.consistency.resample import resample_uniform
from livesweep.ident.residual import run_residual_loop
from livesweep.ident.state_space import StateSpaceModel, fit_state_space, select_pairs
from livesweep.ident.verify import verify
from livesweep.spectral.analysis import analyze

_REL = Path("shared") / "data" / "xplane_c172_pitch_sweeps" / "sweep_data_2017_10_18_14_07.npy"
_CANDIDATES = (Path(__file__).resolve().parents[2] / _REL, Path("/work") / _REL)
DATA = next((p for p in _CANDIDATES if p.is_file()), None)

FS = 50.0
DEG_PER_RAD = float(np.rad2deg(1.0))
IDENT_S = (5.0, 190.0)          # sweeps 1 and 2
VERIFY_S = (190.0, 285.0)       # sweep 3, held out
BAND = (1.0, 30.0)
OUTPUTS = ("q", "theta", "alpha")
SHIFT = 3                       # samples the yoke is advanced by in (B'): 60 ms


def _table(delay: bool) -> dict:
    rows = {"alpha": ["1", "0", "0"], "q": ["0", "1", "0"], "theta": ["0", "0", "1"]}
    t = {"states": ["alpha", "q", "theta"], "inputs": ["de"], "outputs": list(OUTPUTS),
         "F": [["Za", "1", "0"], ["Ma", "Mq", "0"], ["0", "1", "0"]],
         "G": [["Zde"], ["Mde"], ["0"]],
         "H": [rows[o] for o in OUTPUTS], "J": [["0"] for _ in OUTPUTS],
         # starts: q/de ~ Mde/s at 30 rad/s (|H| 5.5 deg/s) -> Mde ~ 165; peak near 5 rad/s -> Ma ~ -25
         "parameters": {"Za": {"value": -2.0}, "Ma": {"value": -25.0}, "Mq": {"value": -3.0},
                        "Zde": {"value": 0.0}, "Mde": {"value": 150.0}}}
    if delay:
        t["parameters"]["tau_de"] = {"value": 0.02}
        t["delays"] = {"de": "tau_de"}
    return t


@pytest.fixture(scope="module")
def record():
    if DATA is None:
        pytest.skip("X-Plane C172 sweep data not found (shared/data/xplane_c172_pitch_sweeps)")
    d = np.load(DATA)
    assert d.ndim == 2 and d.shape[1] == 8
    t = d[:, 0]
    r = resample_uniform({"de": (t, d[:, 1]), "q": (t, DEG_PER_RAD * d[:, 4]), "theta": (t, d[:, 2]),
                          "alpha": (t, d[:, 5])}, FS, label="xplane c172")
    assert r.all_valid().all()
    return list(r.names), np.array(r.values), r.t_s - r.t_s[0]


def _segment(record, span, shift):
    """Signals over ``span`` [s] with their means removed; the yoke advanced by ``shift`` samples
    (y(t) then responds to de'(t - shift/FS): a known extra transport delay)."""
    names, values, t = record
    i0, i1 = int(span[0] * FS), int(span[1] * FS)
    v = values[:, i0:i1].copy()
    k = names.index("de")
    v[k] = values[k, i0 + shift:i1 + shift]
    return v - v.mean(axis=1, keepdims=True), t[i0:i1]


def _case(record, shift, delay):
    names = record[0]
    v, _ = _segment(record, IDENT_S, shift)
    frs = analyze(v, names, FS, ["de"], list(OUTPUTS), BAND).best
    vv, vt = _segment(record, VERIFY_S, shift)
    u, y = vv[[names.index("de")]], vv[[names.index(o) for o in OUTPUTS]]

    def check(model, theta):
        M, F, G, H, J, tau = model.matrices(theta)
        return verify(M, F, G, H, J, tau, vt, u, y, output_names=list(OUTPUTS),
                      output_delays=model.output_delays_s(theta))

    table = _table(delay)
    model = StateSpaceModel.from_table(table)
    pairs, skipped = select_pairs(frs, model)
    assert not skipped and len(pairs) == 3
    fit = fit_state_space(model, pairs)
    return table, fit, frs, check


def _report(label, fit, loop=None):
    print(f"\n{label}: J_ave {fit.cost_average:.2f}  " + "  ".join(
        f"{n}={fit.parameter(n).value:.4g} ({fit.parameter(n).cramer_rao_pct:.3g} %)" for n in fit.model.parameters))
    if loop is not None:
        s0, s1 = loop.steps[0], loop.steps[-1]
        print(f"  loop: {loop.conclusion}; J_ave {s0.cost_before:.3f} -> {loop.fit.cost_average:.3f}; "
              f"verification J_rms {s0.verification_before['j_rms']} -> {s1.verification_after['j_rms']}")
        print("  top candidates: " + ", ".join(f"{c.kind}@{c.where} {c.evidence:.0f}" for c in s0.candidates[:4]))
        for tr in s0.tried:
            print(f"  tried {tr['kind']}@{tr['where']}: J_ave {tr['cost_after']:.3f}; {tr['reason'][:140]}")


@pytest.fixture(scope="module")
def nominal(record):
    table, fit, frs, check = _case(record, 0, True)
    return table, fit, frs, check, run_residual_loop(table, fit, frs, verify=check)


@pytest.mark.slow
def test_nominal_short_period_fit_on_real_data(nominal):
    _, fit, _, _, loop = nominal
    _report("nominal (delay free)", fit, loop)
    # measured: J_ave 9.88; Za -2.98 (3.9 %), Ma -16.7 (3.9 %), Mq -3.47 (6.3 %), Zde 3.26 (10.9 %),
    # Mde 165 (1.8 %); short period -3.23 +- 4.07j (5.2 rad/s, zeta 0.62)
    assert fit.converged and fit.cost_average < 20.0
    for n in ("Za", "Ma", "Mq", "Zde", "Mde"):
        assert fit.parameter(n).cramer_rao_pct <= 20.0, n
    wn = np.abs(fit.eigenvalues[np.abs(fit.eigenvalues) > 1e-6])
    assert np.all((wn > 4.0) & (wn < 6.5))
    # no positive delay in this record: tau at its bound (measured 5e-23 s)
    assert fit.value("tau_de") < 1e-3


@pytest.mark.slow
def test_A_loop_with_free_delay_adds_nothing_and_never_worsens(nominal):
    _, fit, _, _, loop = nominal
    s0 = loop.steps[0]
    # measured: J_ave 9.067 -> 9.067 (refit at 100 points), verification J_rms 4.877 -> 4.877; the
    # only candidate above threshold (sensor skew on q, evidence 185) refits to 0 s and is rejected.
    # Nothing was added in any of the bands 1-30, 1-20, 1.5-30, 0.8-25, 1-15 rad/s.
    assert loop.fit.cost_average <= s0.cost_before * (1 + 1e-9)
    assert loop.steps[-1].verification_after["j_rms"] <= s0.verification_before["j_rms"] + 1e-9
    for e in loop.added:
        for p in e["parameters"]:
            assert p["cramer_rao_pct"] is not None and p["cramer_rao_pct"] <= 20.0, p
    assert loop.added == ()


@pytest.fixture(scope="module")
def no_delay(record):
    table, fit, frs, check = _case(record, 0, False)
    return table, fit, frs, check, run_residual_loop(table, fit, frs, verify=check)


@pytest.mark.slow
def test_B_loop_without_delay_finds_no_delay_on_the_real_record(nominal, no_delay):
    _, fit, _, _, loop = no_delay
    _report("no delay", fit, loop)
    # same fit as the nominal one (its delay was at 0): J_ave 9.88
    assert fit.cost_average == pytest.approx(nominal[1].cost_average, rel=1e-6)
    s0 = loop.steps[0]
    # the outputs lead the yoke: the screened delay is negative, so no time_delay candidate at all
    assert not any(c.kind == "time_delay" for c in s0.candidates)
    # ... the lead is diagnosed as the yoke's measurement logged late: measured top = sensor_skew@de
    # (evidence 4264, ahead of a broad filter on de, 1619); refitted skew 8.3 ms (CR 15.8 %), which
    # is the lead the shifted-yoke runs below measure independently (60 ms shift -> 51.5 ms delay);
    # J_ave 9.07 -> 2.21. Not added: I% 12.7 > 10 and verification on the held-out sweep (dominated
    # by the unmodelled phugoid) J_rms 4.877 -> 4.946, worse beyond noise.
    top = s0.candidates[0]
    assert (top.kind, top.where) == ("sensor_skew", "de")
    tried = next(t for t in s0.tried if (t["kind"], t["where"]) == ("sensor_skew", "de"))
    (skew,) = tried["parameters"]
    assert 0.004 < skew["value"] < 0.013
    assert tried["cost_after"] < 0.5 * s0.cost_before
    assert not any(e["kind"] in ("time_delay", "actuator_lag") for e in loop.added)
    assert loop.fit.cost_average <= s0.cost_before * (1 + 1e-9)


@pytest.fixture(scope="module")
def shifted(record):
    free = _case(record, SHIFT, True)
    table, fit, frs, check = _case(record, SHIFT, False)
    return free[1], fit, run_residual_loop(table, fit, frs, verify=check)


def test_B_prime_loop_finds_the_delay_when_the_yoke_lags_by_60_ms(shifted):
    free_fit, fit, loop = shifted
    _report("yoke advanced 60 ms, delay free", free_fit)
    _report("yoke advanced 60 ms, no delay", fit, loop)
    tau_free = free_fit.value("tau_de")
    # measured: free delay 51.5 ms (CR 2.4 %): 60 ms minus the record's own ~8.5 ms lead
    # (100 ms shift -> 91.4 ms); J_ave 2.60
    assert 0.060 - 0.013 < tau_free < 0.060 - 0.004
    s0 = loop.steps[0]
    # measured: top candidate time_delay@de 47.8 ms (evidence 1.3e5), then actuator_second_order
    # and actuator_lag; accepted time_delay, tau 51.4 ms (CR 2.6 %)
    assert s0.candidates[0].kind in ("time_delay", "actuator_lag")
    assert s0.candidates[0].where == "de"
    assert loop.added and loop.added[0]["kind"] == "time_delay" and loop.added[0]["where"] == "de"
    (p,) = loop.added[0]["parameters"]
    assert p["value"] == pytest.approx(tau_free, abs=0.002)
    assert p["cramer_rao_pct"] <= 20.0
    # measured: J_ave 222.3 -> 2.53 (factor 88; the free-delay model's is 2.53 at these points);
    # verification J_rms 5.669 -> 4.936
    assert loop.fit.cost_average < s0.cost_before / 20.0
    assert loop.fit.cost_average < 2.0 * free_fit.cost_average
    assert loop.steps[0].verification_after["j_rms"] < 0.95 * s0.verification_before["j_rms"]
