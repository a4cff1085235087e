"""The residual loop (``livesweep.ident.residual``) on data with an effect nobody declared.

Data: XV-15 cruise sweeps of both axes flown in the simulator (calm air, half the default
turbulence) with one effect injected, and verification doublets / 3-2-1-1 flown with the same
effect. Model: the shipped cruise case's ``[state_space]`` table, which does not have the effect.
Truth: the injected effect's own parameters. The augmented models are also checked against
analytic factors written here, independently of the code.
"""

from __future__ import annotations

import copy
import math
import tomllib

import numpy as np
import pytest

from livesweep.config import load_case
from livesweep.ident.residual import (Candidate, augment_table, diagnose, effect_text, run_residual_loop,
                                      table_with_fit)
from livesweep.ident.state_space import StateSpaceModel, fit_state_space, select_pairs
from livesweep.ident.verify import verify
from livesweep.report.case_file import dumps_toml
from livesweep.sim.effects import make_effect
from livesweep.sim.models import xv15_cruise
from livesweep.sim.scenario import simulate, sweep_scenario, verification_scenario
from livesweep.spectral.analysis import analyze

from helpers import simulated_record

CASE = "config/xv15_cruise_lateral.toml"
BAND = (0.3, 20.0)
WINDOWS = (7.0, 12.0, 20.0, 40.0, 80.0)
OUTPUTS = ("p", "r", "ay", "beta")
TURBULENCE = 0.5
TRUTH = xv15_cruise()


def _table():
    return copy.deepcopy(load_case(CASE).tables["state_space"])


def _late(values, names, name, samples):
    """The logged input ``name`` recorded ``samples`` late (first value held)."""
    if name is not None:
        k = names.index(name)
        values[k] = np.concatenate([np.full(samples, values[k, 0]), values[k, :-samples]])
    return values


def _data(effects, seed, late=(None, 0)):
    sc = sweep_scenario("xv15-cruise", axes=("da", "dr"), repeats=2, omega_min_rad_s=BAND[0], omega_max_rad_s=BAND[1],
                        duration_s=100.0, amplitudes={"da": 3.0, "dr": 3.0}, off_axis_rms=0.2, seed=seed,
                        effects=tuple(effects), turbulence_scale=TURBULENCE)
    values, names = simulated_record(simulate(sc))
    values = _late(values, names, *late)
    values = values - values.mean(axis=1, keepdims=True)
    frs = analyze(values, names, 50.0, ["da", "dr"], list(OUTPUTS), BAND, windows_s=WINDOWS).best
    vs = verification_scenario("xv15-cruise", manoeuvres=(("da", "doublet", 2.0, 1.0), ("dr", "doublet", 3.0, 1.5),
                                                          ("da", "3211", 1.5, 0.7)),
                               effects=tuple(effects), seed=seed + 100, turbulence_scale=0.3)
    vv, vn = simulated_record(simulate(vs))
    vv = _late(vv, vn, *late)
    t = np.arange(vv.shape[1]) / 50.0
    u = np.vstack([vv[vn.index(n)] for n in ("da", "dr")])
    y = np.vstack([vv[vn.index(n)] for n in OUTPUTS])

    def check(model, theta):
        M, F, G, H, J, tau = model.matrices(theta)
        return verify(M, F, G, H, J, tau, t, u, y, output_names=list(OUTPUTS),
                      output_delays=model.output_delays_s(theta), input_skews=model.input_skews_s(theta))

    return frs, check


def _loop(effects, edit=None, seed=11, late=(None, 0)):
    frs, check = _data(effects, seed, late)
    table = _table()
    if edit:
        edit(table)
    model = StateSpaceModel.from_table(table)
    pairs, _ = select_pairs(frs, model)
    fit = fit_state_space(model, pairs)
    return run_residual_loop(table, fit, frs, verify=check)


def _fix_tau_a(t):
    t["parameters"]["tau_a"] = {"value": TRUTH.input_delays_s[0], "fixed": True}


def _drop_np(t):
    t["F"][2][1] = "0"
    del t["parameters"]["Np"]


# effect(s), case edit, (kind, where), truth of the new parameters
CASES = {
    "time_delay": ([("time_delay", dict(input="da", delay_s=0.06))], _fix_tau_a, ("time_delay", "da"),
                   {"tau_a": TRUTH.input_delays_s[0] + 0.06}),
    "actuator_lag": ([("actuator_lag", dict(input="dr", time_constant_s=0.125))], None, ("actuator_lag", "dr"),
                     {"w_act_dr": 8.0}),
    "actuator_second_order": ([("actuator_second_order", dict(input="da", omega_rad_s=10.0, zeta=0.5))], None,
                              ("actuator_second_order", "da"), {"wn_act_da": 10.0, "zeta_act_da": 0.5}),
    "notch": ([("notch_filter", dict(input="da", omega_rad_s=6.0, zeta=0.3, depth=0.7))], None,
              ("notch_filter", "da"), {"w_notch_da": 6.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.7}),
    "structural_mode": ([("structural_mode", dict(output="p", omega_rad_s=12.0, zeta_pole=0.1, zeta_zero=0.3))], None,
                        ("structural_mode", "p"), {"w_mode_p": 12.0, "zeta_mode_p": 0.1, "zeta_zero_mode_p": 0.3}),
    "sensor_skew": ([("sensor_skew", dict(output="p", delay_s=0.06))], None, ("sensor_skew", "p"), {"skew_p": 0.06}),
    "scale_factor": ([("scale_factor", dict(output="r", factor=1.2))], None, ("scale_factor", "r"), {"k_r": 1.2}),
    "missing_derivative": ([], _drop_np, ("missing_derivative", "F[r][p]"), {"F_r_p": TRUTH.derivatives["Np"]}),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_undeclared_effect_is_found_identified_and_halves_the_cost(name):
    effects, edit, (kind, where), truth = CASES[name]
    loop = _loop([make_effect(k, **p) for k, p in effects], edit)
    first = loop.steps[0]
    print(f"\n{name}: {loop.conclusion}; top {[c.to_dict() for c in first.candidates[:3]]}")
    for st in loop.steps:
        print("  ", st.to_dict()["effect"], st.cost_before, "->", st.cost_after)
    # the top diagnosis has the right kind and location, and is the one added
    assert (first.candidates[0].kind, first.candidates[0].where) == (kind, where)
    assert first.effect is not None and (first.effect["kind"], first.effect["where"]) == (kind, where)
    assert len(loop.added) == 1, loop.added
    # its parameters lie within 3 Cramer-Rao bounds of the injected values
    for p in first.effect["parameters"]:
        cr = p["cramer_rao_pct"] / 100 * abs(p["value"])
        assert abs(p["value"] - truth[p["name"]]) <= 3 * cr, (p, truth[p["name"]])
        assert p["cramer_rao_pct"] <= 20 and p["insensitivity_pct"] <= 10
    assert {p["name"] for p in first.effect["parameters"]} == set(truth)
    # the cost drops by at least half; the verification error does not get worse beyond noise
    assert loop.fit.cost_average <= 0.5 * first.cost_before
    assert first.verification_after["j_rms"] <= first.verification_before["j_rms"] * 1.05
    assert loop.steps[-1].effect is None and loop.conclusion.startswith("added")
    # a scale factor added is not also reported as one the data cannot show
    assert all((x["kind"], x["where"]) != (kind, where) for x in loop.limits)


@pytest.mark.slow
def test_an_input_logged_late_is_found_as_its_sensor_skew():
    """The rudder command logged 80 ms late: the outputs lead it by 80 - 33 ms (the true rudder
    delay), the free delay tau_r sits at its bound 0, and the loop adds a skew of the dr
    measurement (tau_r then held at 0: only the net delay is identifiable)."""
    loop = _loop([], late=("dr", 4))
    first = loop.steps[0]
    print(f"\n{loop.conclusion}; top {[c.to_dict() for c in first.candidates[:3]]}")
    assert (first.candidates[0].kind, first.candidates[0].where) == ("sensor_skew", "dr")
    assert first.effect is not None and (first.effect["kind"], first.effect["where"]) == ("sensor_skew", "dr")
    (skew,) = first.effect["parameters"]
    truth = 0.08 - TRUTH.input_delays_s[1]
    assert abs(skew["value"] - truth) <= 3 * skew["cramer_rao_pct"] / 100 * skew["value"], (skew, truth)
    assert loop.fit.parameter("tau_r").fixed and loop.fit.value("tau_r") == 0.0
    assert loop.fit.cost_average <= 0.5 * first.cost_before


@pytest.mark.slow
def test_two_effects_at_once_are_both_found():
    loop = _loop([make_effect("sensor_skew", output="p", delay_s=0.06),
                  make_effect("actuator_lag", input="dr", time_constant_s=0.125)])
    found = {(e["kind"], e["where"]) for e in loop.added}
    assert found == {("sensor_skew", "p"), ("actuator_lag", "dr")}
    values = {p["name"]: p for e in loop.added for p in e["parameters"]}
    # the final fit holds both; each within 3 CR of the truth
    for name, truth in (("skew_p", 0.06), ("w_act_dr", 8.0)):
        q = loop.fit.parameter(name)
        assert abs(q.value - truth) <= 3 * q.cramer_rao, (name, q)
        assert name in values
    assert loop.fit.cost_average <= 0.5 * loop.steps[0].cost_before


@pytest.mark.slow
@pytest.mark.parametrize("seed", [50, 51, 52])
def test_clean_data_adds_nothing(seed):
    """No effect injected: the loop must not add one (no false positive over several noise seeds)."""
    loop = _loop([], seed=seed)
    top = loop.steps[0].candidates[0]
    print(f"\nseed {seed}: {loop.conclusion}; top {top.to_dict()}")
    assert loop.added == ()
    assert loop.conclusion.startswith("nothing to add: residual within noise")
    # the criterion's own account: no candidate's screening drop reaches what its F-test needs
    from livesweep.ident.residual_space import whitened_ss
    from livesweep.ident.selection import significance

    first = loop.steps[0]
    ss0 = whitened_ss(first.residuals_before)
    n_pts = loop.criterion["effective_points"]
    n_model = int(sum(not f for f in loop.fit.model.fixed))
    assert not any(significance(ss0, ss0 - c.evidence, c.n_parameters, n_pts, n_model, len(first.candidates)).significant
                   for c in first.candidates)


# --- augmentation against analytic factors ------------------------------------------------------

W = np.geomspace(0.3, 20.0, 40)
S = 1j * W


def _truth_table():
    t = _table()
    th = {**TRUTH.derivatives, "tau_a": TRUTH.input_delays_s[0], "tau_r": TRUTH.input_delays_s[1]}
    t["parameters"] = {k: {"value": float(th[k])} for k in t["parameters"]}
    return t


def _response(table):
    m = StateSpaceModel.from_table(table)
    return m.frequency_response(m.initial, W)


def _bandpass(w0, z):
    return 2 * z * w0 * S / (S**2 + 2 * z * w0 * S + w0**2)


AUGMENTATIONS = [
    (Candidate("actuator_lag", "dr", {"time_constant_s": 0.125}, 0.0), ("in", 1, 8.0 / (S + 8.0))),
    (Candidate("actuator_second_order", "da", {"omega_rad_s": 10.0, "zeta": 0.5}, 0.0),
     ("in", 0, 100.0 / (S**2 + 10.0 * S + 100.0))),
    (Candidate("notch_filter", "da", {"omega_rad_s": 6.0, "zeta": 0.3, "depth": 0.7}, 0.0),
     ("in", 0, 1 - 0.7 * _bandpass(6.0, 0.3))),
    (Candidate("structural_mode", "ay", {"omega_rad_s": 12.0, "zeta_pole": 0.1, "zeta_zero": 0.3}, 0.0),
     ("out", 2, 1 + 2.0 * _bandpass(12.0, 0.1))),
    (Candidate("sensor_skew", "beta", {"delay_s": 0.05}, 0.0), ("out", 3, np.exp(-0.05 * S))),
    (Candidate("scale_factor", "ay", {"factor": 1.2}, 0.0), ("out", 2, 1.2 + 0 * S)),
    (Candidate("time_delay", "dr", {"delay_s": 0.04}, 0.0), ("in", 1, np.exp(-0.04 * S))),
    (Candidate("sensor_skew", "da", {"delay_s": 0.03}, 0.0), ("in", 0, np.exp(+0.03 * S))),
]


@pytest.mark.parametrize("cand, expect", AUGMENTATIONS, ids=[f"{c.kind}-{c.where}" for c, _ in AUGMENTATIONS])
def test_augmented_model_is_the_nominal_times_the_effect(cand, expect):
    """Every pair the effect touches is multiplied by its analytic factor (ay carries a feed-through
    J term, so input effects reach it through the added states too); the others are unchanged."""
    base = _truth_table()
    T0 = _response(base)
    aug, new = augment_table(base, cand)
    T1 = _response(aug)
    where, k, factor = expect
    expected = T0.copy()
    if where == "in":
        expected[:, k, :] *= factor
    else:
        expected[k, :, :] *= factor
    np.testing.assert_allclose(T1, expected, rtol=1e-9, atol=1e-12 * np.abs(T0).max())
    assert new and all(n in aug["parameters"] for n in new)
    # the written table round-trips through TOML and still builds the same model
    again = tomllib.loads(dumps_toml({"state_space": aug}))["state_space"]
    np.testing.assert_allclose(_response(again), T1, rtol=1e-12)


def test_missing_derivative_fills_the_absent_entry():
    base = _truth_table()
    ref = _response(base)
    _drop_np(base)
    aug, new = augment_table(base, Candidate("missing_derivative", "F[r][p]",
                                             {"name": "F_r_p", "value": TRUTH.derivatives["Np"]}, 0.0))
    assert new == ["F_r_p"] and aug["F"][2][1] == "F_r_p"
    np.testing.assert_allclose(_response(aug), ref, rtol=1e-9)


@pytest.mark.slow
def test_diagnosis_ranks_the_model_own_sensitivity_for_a_fixed_derivative():
    """A derivative wrongly fixed (Nr held at half its value) is explained by freeing it."""
    frs, _ = _data([], seed=11)
    table = _table()
    table["parameters"]["Nr"] = {"value": 0.5 * TRUTH.derivatives["Nr"], "fixed": True}
    model = StateSpaceModel.from_table(table)
    pairs, _ = select_pairs(frs, model, n_omega=100)
    fit = fit_state_space(model, pairs)
    top = diagnose(table_with_fit(table, fit), fit, pairs, frs)[0]
    assert (top.kind, top.where) == ("missing_derivative", "Nr")
    assert math.isclose(top.parameters["value"], TRUTH.derivatives["Nr"], rel_tol=0.25)


def test_a_candidate_that_diverges_in_verification_counts_as_worse():
    """An augmented model that blows up open loop must not pass the time-domain test as
    'unchanged' (its residual is all invalid, so a noise estimate alone would say nothing)."""
    from livesweep.ident.residual import _verification_change

    t = np.arange(3000) / 50.0
    u = np.sin(0.7 * t)[None, :]
    y = (0.5 * np.sin(0.7 * t - 0.3))[None, :]
    one = np.eye(1)
    stable = verify(one, -one, one, one, 0 * one, [0.0], t, u, y, output_names=["y"])
    diverging = verify(one, 400 * one, one, one, 0 * one, [0.0], t, u, y, output_names=["y"])
    assert not np.isfinite(diverging.j_rms)
    assert _verification_change(stable, diverging)["verdict"] == "worse"
    assert _verification_change(stable, stable)["verdict"] == "unchanged"
    # slower divergence: e^(2t) .. e^(5t) over the 60 s record. The prediction stays finite, but
    # the block means grow with it (their scatter as large as their mean) or overflow when
    # squared; the J_rms guideline the stable model meets is failed by far: worse, not unchanged
    for growth in (2.0, 3.0, 4.0, 5.0):
        slow = verify(one, growth * one, one, one, 0 * one, [0.0], t, u, y, output_names=["y"])
        assert np.isfinite(slow.j_rms) and slow.j_rms > slow.guidelines["j_rms_max"] >= stable.j_rms
        assert _verification_change(stable, slow)["verdict"] == "worse", growth


# --- acceptance as CIFER practice does it ------------------------------------------------------

@pytest.mark.slow
def test_a_sharp_mode_with_a_poorly_determined_damping_is_added_with_the_damping_fixed():
    """The structural mode the loop used to reject (dipole at 12 rad/s on p: pole damping 0.05,
    zero damping 0.15, +9.5 dB): its pole damping comes out at CR ~20.4 % > 20 %. The shape is
    plain, so the damping is fixed where the fit put it (structure reduction inside the effect)
    and the mode is added; the record says what was fixed and why. Seed 13 (the rule was written
    looking at seeds 11-12)."""
    from livesweep.ident.residual import CLEAR_EVIDENCE_FACTOR, effect_text

    zp, zz = 0.05, 0.15
    assert 20 * math.log10(zz / zp) == pytest.approx(9.5, abs=0.05)       # the issue's +9.5 dB peak
    loop = _loop([make_effect("structural_mode", output="p", omega_rad_s=12.0, zeta_pole=zp, zeta_zero=zz)], seed=13)
    first = loop.steps[0]
    assert first.effect is not None and (first.effect["kind"], first.effect["where"]) == ("structural_mode", "p")
    (rec,) = [t for t in first.tried if t["kind"] == "structural_mode"]
    (fixed,) = rec["fixed"]
    assert fixed["name"] == "zeta_mode_p" and fixed["cramer_rao_pct"] > 20
    assert "zeta_mode_p fixed at" in rec["reason"]
    assert rec["evidence_after"] >= CLEAR_EVIDENCE_FACTOR * rec["significance"]["needed"]
    # the fixed damping within 3 of the Cramer-Rao bounds it had when it was fixed
    assert abs(fixed["value"] - zp) <= 3 * fixed["cramer_rao_pct"] / 100 * fixed["value"]
    params = {p["name"]: p for p in first.effect["parameters"]}
    assert params["zeta_mode_p"]["fixed"] and not params["w_mode_p"]["fixed"]
    assert not params["zeta_zero_mode_p"]["fixed"]
    for name, truth in (("w_mode_p", 12.0), ("zeta_zero_mode_p", zz)):
        p = params[name]
        assert p["cramer_rao_pct"] <= 20 and p["insensitivity_pct"] <= 10
        assert abs(p["value"] - truth) <= 3 * p["cramer_rao_pct"] / 100 * abs(p["value"]), (p, truth)
    assert loop.fit.cost_average <= 0.5 * first.cost_before
    assert loop.added == ({k: v for k, v in first.effect.items() if k != "with"},)
    assert f"zeta_mode_p = {fixed['value']:.4g} (fixed: poorly determined)" in effect_text(first.effect)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [31, 32, 33])
def test_a_notch_on_clean_hover_is_not_made_acceptable_by_fixing(seed):
    """Clean hover data where a notch on da picks up some evidence (1.5-3 times its threshold) with
    a poorly determined damping and depth: fixing is for effects that are clearly there, one
    parameter at most, so it is rejected as before, not added with two of its three parameters
    fixed. CLEAR_EVIDENCE_FACTOR was set looking at seed 31; 32 and 33 are held out."""
    frs, table, fit = _hover([], seed=seed)
    loop = run_residual_loop(table, fit, frs)
    notch = [t for t in loop.steps[0].tried if t["kind"] == "notch_filter"]
    assert all(not t["accepted"] and t["fixed"] == [] for t in notch)
    assert loop.added == ()


def _hover(effects, seed, edit=None, noise=1.0):
    """A hover test point (the pilot's loop closed in the simulator) with ``effects``, analysed; the
    shipped hover case's model (changed by ``edit(table)``, if given) fitted to it; ``noise``
    multiplies every sensor's noise."""
    from dataclasses import replace

    case = load_case("config/xv15_hover_lateral.toml")
    table = copy.deepcopy(case.tables["state_space"])
    if edit is not None:
        edit(table)
    sc = sweep_scenario("xv15-hover", axes=("da", "dr"), repeats=2, omega_min_rad_s=0.2, omega_max_rad_s=12.0,
                        duration_s=100.0, amplitudes={"da": 1.5, "dr": 3.0}, off_axis_rms=0.2, seed=seed,
                        effects=tuple(effects), turbulence_scale=0.5)
    sc = replace(sc, sensors=tuple(replace(x, noise_std=x.noise_std * noise) for x in sc.sensors))
    values, names = simulated_record(simulate(sc))
    values = values - values.mean(axis=1, keepdims=True)
    frs = analyze(values, names, 50.0, ["da", "dr"], list(table["outputs"]), (0.2, 12.0),
                  windows_s=(10.0, 20.0, 40.0, 80.0, 160.0)).best
    model = StateSpaceModel.from_table(table)
    pairs, _ = select_pairs(frs, model)
    return frs, table, fit_state_space(model, pairs)


@pytest.mark.slow
def test_a_pilot_s_attitude_feedback_is_not_taken_for_a_moment_due_to_attitude():
    """Hover in turbulence, nothing injected (seed 805). Without references the pilot's feedback of
    phi through da biases the estimate in the shape of a roll moment due to bank angle: offered
    F[p][phi], the loop added it and J_ave fell from 8.5 to 4.3 (at turbulence 0.25 or none,
    nothing was added on the same seed). Forces and moments do not depend on the attitude, so the
    catalogue offers no entry in a kinematic state's column (phi' = p holds no parameter): the
    hover model then has no absent entry to offer, a removed Lv is offered back, and the loop adds
    nothing here."""
    from livesweep.effects.derivative import derivative_slots

    frs, table, fit = _hover([], seed=805)
    assert derivative_slots(table, fit.model) == []
    dropped = copy.deepcopy(table)
    dropped["F"][dropped["states"].index("p")][dropped["states"].index("v")] = "0"
    del dropped["parameters"]["Lv"]
    assert [w for _, _, w in derivative_slots(dropped, StateSpaceModel.from_table(dropped))] == ["F[p][v]"]
    loop = run_residual_loop(table, fit, frs)
    assert loop.added == (), loop.conclusion


@pytest.mark.slow
def test_an_effect_that_bends_the_derivatives_beyond_the_cost_guideline_is_still_found():
    """Hover, a 5 rad/s second-order actuator on da (zeta 0.6): the derivatives bend so far to make
    up for it that the fit fails the method's J_ave <= 100 guideline (about 320), the linear screen
    about that fit finds no candidate significant, and the refit from the bent derivatives does not
    converge. The loop refits the best-ranked candidates anyway, a second time from the case's own
    starting values, and finds the actuator. Its damping is within 3 Cramer-Rao bounds of the
    injection; its frequency within 5 % (the bound, 1.5 %, does not cover the bias the closed pilot
    loop leaves in hover: a fit with the injection's values fixed ends at J_ave 66, not the clean
    6-12)."""
    from livesweep.ident.accuracy import MAX_COST_AVERAGE

    frs, table, fit = _hover([make_effect("actuator_second_order", input="da", omega_rad_s=5.0, zeta=0.6)], seed=204)
    loop = run_residual_loop(table, fit, frs)
    assert loop.steps[0].cost_before > MAX_COST_AVERAGE
    assert [(e["kind"], e["where"]) for e in loop.added] == [("actuator_second_order", "da")]
    p = {x["name"]: x for x in loop.added[0]["parameters"]}
    assert p["wn_act_da"]["value"] == pytest.approx(5.0, rel=0.05)
    z = p["zeta_act_da"]
    assert abs(z["value"] - 0.6) <= 3 * z["cramer_rao_pct"] / 100 * z["value"], z
    assert loop.fit.cost_average <= 0.5 * loop.steps[0].cost_before


@pytest.mark.slow
@pytest.mark.parametrize("seed, delay_s", [(34, 0.1), (22, 0.05)])
def test_a_delay_in_hover_is_added_as_a_delay_and_nothing_patches_it(seed, delay_s):
    """Hover, a pure delay on da: the one-parameter delay is what is added (not the two-parameter
    actuator that scores nearly the same), within 3 Cramer-Rao bounds of the injection, the cost
    at least halved, and no second effect is added to patch it."""
    frs, table, fit = _hover([make_effect("time_delay", input="da", delay_s=delay_s)], seed=seed)
    loop = run_residual_loop(table, fit, frs)
    assert [(e["kind"], e["where"]) for e in loop.added] == [("time_delay", "da")]
    (tau,) = loop.added[0]["parameters"]
    assert abs(tau["value"] - delay_s) <= 3 * tau["cramer_rao_pct"] / 100 * tau["value"], tau
    assert loop.fit.cost_average <= 0.5 * loop.steps[0].cost_before


def test_a_near_tie_goes_to_the_simpler_effect_and_both_are_reported():
    """The choice among accepted candidates (the hover miss: a second-order actuator lowering the
    whitened residual by 93 more than a delay, 53 383 vs 53 290): with the residual's level per
    independent point s2 = SS / dof, the extra parameter must lower the sum of squares by
    NOISE_INFLATION x F_crit(1, dof) x s2 (a one-parameter F-test, scipy's F quantile here) to be
    worth it. 93 is below that: the delay is added and the actuator named beside it; a winner by
    far more is taken even with more parameters."""
    from scipy import stats

    from livesweep.ident.residual import _choose, _Judge
    from livesweep.ident.selection import FALSE_ALARM, NOISE_INFLATION

    n_points, n_model, ss0 = 600.0, 20, 60000.0
    judge = _Judge([], None, None, n_points, FALSE_ALARM)

    def rec(kind, evidence, n_par):
        return ({"kind": kind, "where": "da", "evidence_after": evidence, "cost_after": 6.0, "reason": "accepted",
                 "ss_before": ss0, "parameters": [{"name": f"x{k}"} for k in range(n_par)]}, object())

    dof = n_points - n_model - 1 - 1
    need = NOISE_INFLATION * stats.f.isf(FALSE_ALARM, 1, dof) * (ss0 - 53290.0) / dof
    assert 93.0 < need < 500.0                                # the two cases below straddle it
    delay, second = rec("time_delay", 53290.0, 1), rec("actuator_second_order", 53383.0, 2)
    chosen = _choose([second, delay], judge, n_model)
    assert chosen is delay
    assert "preferred to actuator_second_order" in chosen[0]["reason"]
    clear = rec("actuator_second_order", 53290.0 + 1.5 * need, 2)
    delay2 = rec("time_delay", 53290.0, 1)
    assert _choose([delay2, clear], judge, n_model) is clear
    assert _choose([], judge, n_model) is None


def test_rivals_are_those_the_data_prefer_no_more_than_an_effect_to_nothing():
    """Which re-identified candidates are reported as hard to tell from the chosen one: a
    difference of whitened sums of squares below what a one-parameter effect needs at the loop's
    screening level (alpha / m for m candidates screened; scipy's F quantile here), among
    candidates whose shape held, accepted or not (a lag whose corner lies above the band fails
    only the accuracy guidelines: in the band it is a delay)."""
    from scipy import stats

    from livesweep.ident.residual import _Judge, _rivals
    from livesweep.ident.selection import FALSE_ALARM, NOISE_INFLATION

    n_points, n_model, ss0, m = 600.0, 20, 60000.0, 30
    judge = _Judge([], None, None, n_points, FALSE_ALARM, n_tests=m)
    ss_chosen = 60000.0 - 53290.0
    dof = n_points - n_model - 1 - 1

    def need(n_tests):
        return NOISE_INFLATION * stats.f.isf(FALSE_ALARM / n_tests, 1, dof) * ss_chosen / dof

    assert need(1) < need(m)

    def rec(kind, where, drop_less, *, held=True, accepted=True):
        return {"kind": kind, "where": where, "evidence_after": 53290.0 - drop_less, "cost_after": 6.0,
                "ss_before": ss0, "parameters": [{"name": "x"}], "shape_held": held, "accepted": accepted}

    chosen = rec("time_delay", "da", 0.0)
    between = 0.5 * (need(1) + need(m))           # told apart at one test, not at the screening level
    second = rec("actuator_second_order", "da", -0.5 * need(1))
    second["parameters"] = [{"name": "wn"}, {"name": "zeta"}]
    far = rec("time_delay", "dr", 1.2 * need(m))   # the same kind elsewhere, clearly worse
    tried = [chosen,
             rec("actuator_lag", "da", -0.2 * need(1), accepted=False),      # fits better, fails accuracy
             rec("sensor_skew", "da", between),
             rec("notch_filter", "da", 0.1 * need(1), held=False, accepted=False),   # its fit diverged
             second,                                                         # richer: one test
             far,
             rec("sensor_skew", "r", 0.0)]                  # another kind at another place: not a rival
    got = [(r["kind"], r["accepted"]) for r in _rivals(chosen, tried, judge, n_model)]
    assert got == [("actuator_lag", False), ("sensor_skew", True), ("actuator_second_order", True)]
    far["evidence_after"] = 53290.0                                          # now as good: a rival
    assert ("time_delay", "dr") in [(r["kind"], r["where"]) for r in _rivals(chosen, tried, judge, n_model)]
    far["evidence_after"] = 53290.0 - 1.2 * need(m)
    second["accepted"] = False                                               # richer and undetermined: not listed
    assert "actuator_second_order" not in [r["kind"] for r in _rivals(chosen, tried, judge, n_model)]
    second["accepted"] = True
    second["evidence_after"] = 53290.0 + between                             # richer, better by more than one test
    assert [r["kind"] for r in _rivals(chosen, tried, judge, n_model)] == ["actuator_lag", "sensor_skew"]
    judge.n_tests = 1
    assert [r["kind"] for r in _rivals(chosen, tried, judge, n_model)] == ["actuator_lag"]
    assert _rivals({**chosen, "with": [{}]}, tried, judge, n_model) == []    # a pair: none


def test_a_richer_rival_is_named_when_its_extra_parameters_are_not_significant():
    """A notch (3 parameters) that explains a little more than the lag chosen (1 parameter): the
    lag is taken because the notch's 2 extra parameters are not significant (the choice's F-test
    with 2 parameters, scipy's F quantile here), and for that same reason the notch is named
    beside it. (Held-out-12's 20 rad/s quadrotor notch was added as a lag with no rival named: the
    rival rule held the notch to a one-parameter test.) Better by more than 2 parameters need, it
    is no rival but the better model."""
    from scipy import stats

    from livesweep.ident.residual import _choose, _Judge, _rivals
    from livesweep.ident.selection import FALSE_ALARM, NOISE_INFLATION

    n_points, n_model, ss0 = 600.0, 20, 60000.0
    judge = _Judge([], None, None, n_points, FALSE_ALARM, n_tests=30)
    ss_lag = 6000.0

    def rec(kind, ss, n_par):
        return {"kind": kind, "where": "pitch_cmd", "evidence_after": ss0 - ss, "cost_after": 4.0, "ss_before": ss0,
                "parameters": [{"name": f"x{k}"} for k in range(n_par)], "shape_held": True, "accepted": True,
                "reason": "accepted"}

    def need(k_extra):                      # the drop 2 extra parameters need over the lag's model
        dof = n_points - (n_model + 1) - k_extra
        return lambda ss_rich: NOISE_INFLATION * stats.f.isf(FALSE_ALARM, k_extra, dof) * k_extra * ss_rich / dof

    # a drop between what one and what two extra parameters need: the old rule's gap
    lo, hi = need(1)(ss_lag), need(2)(ss_lag)
    assert lo < hi
    drop = 0.5 * (lo + hi)
    lag, notch = rec("actuator_lag", ss_lag, 1), rec("notch_filter", ss_lag - drop, 3)
    assert need(2)(ss_lag - drop) > drop
    chosen = _choose([(notch, None), (lag, None)], judge, n_model)
    assert chosen[0] is lag
    assert [r["kind"] for r in _rivals(lag, [lag, notch], judge, n_model)] == ["notch_filter"]
    notch["evidence_after"] = ss0 - (ss_lag - 1.5 * need(2)(ss_lag))       # clearly better: chosen, no tie
    assert _choose([(notch, None), (lag, None)], judge, n_model)[0] is notch
    assert _rivals(lag, [lag, notch], judge, n_model) == []


@pytest.mark.slow
def test_a_sharp_mode_and_an_actuator_lag_together_are_found_as_a_pair():
    """The issue's second miss: the p mode (zeta 0.05, +9.5 dB at 12 rad/s) with a 0.1 s lag on da.
    Alone the mode cannot explain the lag's phase and fails; a second-order actuator alone is a
    partial answer. Tried together, the mode and the first-order lag are added in one step, each
    parameter within 3 Cramer-Rao bounds of its injection (the fixed damping: of its bound when
    fixed), the cost at least halved. Seed 13 (the pair search was written looking at 11-12)."""
    from livesweep.ident.residual import effect_text

    loop = _loop([make_effect("structural_mode", output="p", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15),
                  make_effect("actuator_lag", input="da", time_constant_s=0.1)], seed=13)
    print("\n" + loop.conclusion + "\n" + "\n".join(effect_text(s.effect) for s in loop.steps if s.effect))
    assert {(e["kind"], e["where"]) for e in loop.added} == {("structural_mode", "p"), ("actuator_lag", "da")}
    assert len(loop.added) == 2
    truth = {"w_mode_p": 12.0, "zeta_zero_mode_p": 0.15, "zeta_mode_p": 0.05, "w_act_da": 10.0}
    fixed = {f["name"]: f for s in loop.steps for t in s.tried if t.get("accepted") for f in t["fixed"]}
    for e in loop.added:
        for p in e["parameters"]:
            cr = (fixed[p["name"]] if p["fixed"] else p)["cramer_rao_pct"] / 100 * abs(p["value"])
            assert abs(p["value"] - truth[p["name"]]) <= 3 * cr, (p, truth[p["name"]])
    assert loop.fit.cost_average <= 0.5 * loop.steps[0].cost_before


def test_f_quantile_matches_scipy_stats():
    """The F-test's critical value comes from the incomplete beta function (scipy.stats is slow to
    import): it must be scipy.stats.f.isf over the levels and degrees of freedom the loop uses."""
    from scipy import stats

    from livesweep.ident.selection import f_isf

    for k in (1, 2, 3, 6):
        for dof in (2, 10, 80, 600, 5000):
            for level in (0.2, 0.01, 1e-4, 1e-8):
                assert math.isclose(f_isf(level, k, dof), stats.f.isf(level, k, dof), rel_tol=1e-6)


def test_a_pair_is_kept_only_when_each_partner_is_needed():
    """A pair (``_partners_needed``) counts as two effects only if each partner lowers the whitened
    sum of squares significantly on top of the other alone: an F-test at false_alarm with the
    partner's parameters counted (scipy's F quantile here). The hover case that made it (a 6 rad/s
    second-order actuator on dr, 2 parameters, alone at S = 1037; with a notch on da, 3 more, at
    S = 770): the notch's 267 are below the ~450 its 3 parameters need, so the pair is refused and
    the actuator alone stands."""
    from scipy import stats

    from livesweep.ident.residual import _Judge, _partners_needed
    from livesweep.ident.selection import FALSE_ALARM, NOISE_INFLATION

    n_points, n_model, ss0 = 185.0, 14, 66582.0
    judge = _Judge([], None, None, n_points, FALSE_ALARM, n_tests=40)

    def pair(ss_pair):
        return {"kind": "notch_filter", "where": "da", "ss_before": ss0, "evidence_after": ss0 - ss_pair,
                "parameters": [{"name": n} for n in ("w", "zeta", "depth")], "accepted": True, "reason": "accepted",
                "with": [{"kind": "actuator_second_order", "where": "dr", "parameters": [{"name": "wn"}, {"name": "z"}]}]}

    notch_alone = {"evidence_after": ss0 - 5000.0}
    actuator_alone = {"evidence_after": ss0 - 1037.0}
    dof = n_points - (n_model + 2) - 3
    need = NOISE_INFLATION * stats.f.isf(FALSE_ALARM, 3, dof) * 3 * 770.0 / dof
    assert 267.0 < need < 1037.0 - 500.0
    rec = pair(770.0)
    _partners_needed(rec, [notch_alone, actuator_alone], judge, n_model)
    assert not rec["accepted"] and "notch_filter at da adds 267" in rec["reason"]
    rec = pair(1037.0 - 1.2 * need)                       # now the notch earns its parameters
    _partners_needed(rec, [notch_alone, actuator_alone], judge, n_model)
    assert rec["accepted"], rec["reason"]
    rec = pair(770.0)
    _partners_needed(rec, [notch_alone, {}], judge, n_model)   # the actuator alone could not be refitted:
    assert rec["accepted"], rec["reason"]                          # nothing to be nested in


def test_verification_worse_needs_the_loops_false_alarm_level():
    """'Worse in verification' refuses a correct effect by chance as often as the one-sided normal
    quantile at false_alarm allows (2.33 sigma at 1 %, scipy's quantile here), not 2 sigma (2.3 %)."""
    from scipy import stats

    from livesweep.ident.residual import FALSE_ALARM, _verification_change

    t = np.arange(3000) / 50.0
    u = np.sin(0.7 * t)[None, :]
    rng = np.random.default_rng(5)
    y = (0.5 * np.sin(0.7 * t - 0.3) + 0.05 * rng.standard_normal(t.size))[None, :]
    one = np.eye(1)
    a = verify(one, -one, one, one, 0 * one, [0.0], t, u, y, output_names=["y"])
    b = verify(one, -1.1 * one, one, one, 0 * one, [0.0], t, u, y, output_names=["y"])
    ch = _verification_change(a, b)
    assert math.isclose(ch["z"], stats.norm.isf(FALSE_ALARM), abs_tol=1e-3)
    sigmas = ch["mean_change"] / ch["noise"]
    expect = "worse" if sigmas > ch["z"] else "improved" if sigmas < -ch["z"] else "unchanged"
    assert ch["verdict"] == expect
    loose = _verification_change(a, b, alpha=0.5)                      # z = 0: any change decides
    assert loose["verdict"] == ("worse" if sigmas > 0 else "improved")



@pytest.mark.slow
def test_a_derivative_held_far_from_its_value_is_screened_along_the_exact_response():
    """Lda held fixed at a quarter of the simulator's value: the fit bends the other derivatives to
    J_ave above 200, and ln|p/da| is far from linear in Lda over that distance (linearised, the
    step reaches 0.63 of the simulator's Lda and a scale factor on p ranks first). The exact line
    search along Lda ranks freeing it first, at the simulator's value within 25 %."""
    frs, _ = _data([], seed=13)
    table = _table()
    truth = TRUTH.derivatives["Lda"]
    table["parameters"]["Lda"] = {"value": 0.25 * truth, "fixed": True}
    model = StateSpaceModel.from_table(table)
    pairs, _ = select_pairs(frs, model, n_omega=100)
    fit = fit_state_space(model, pairs)
    top = diagnose(table_with_fit(table, fit), fit, pairs, frs)[0]
    assert (top.kind, top.where) == ("missing_derivative", "Lda"), top
    assert top.parameters["value"] == pytest.approx(truth, rel=0.25)


@pytest.mark.slow
def test_a_pair_the_model_has_no_path_for_is_skipped_with_its_reason_and_the_loop_runs():
    """The rudder column removed from the cruise model (Ydr, Ldr, Ndr): every output's response to
    dr is zero by the model's structure, though the simulated data are coherent there. Those pairs
    cannot be fitted in dB; they are skipped with the reason (before, the residual loop stopped on
    a LinAlgError from the infinite residual)."""
    frs, _ = _data([], seed=13)
    table = _table()
    for row in range(3):
        table["G"][row][1] = "0"
    table["J"][2][1] = "0"
    for name in ("Ydr", "Ldr", "Ndr"):
        del table["parameters"][name]
    model = StateSpaceModel.from_table(table)
    pairs, skipped = select_pairs(frs, model)
    coherent = {o for o in OUTPUTS if np.nanmax(frs.pair(o, "dr").coherence) > 0.8}
    assert coherent                                   # the data do show the rudder
    assert {(o, i) for o, i, why in skipped if "no path" in why} == {(o, "dr") for o in coherent}
    assert all(p.input == "da" for p in pairs)
    loop = run_residual_loop(table, fit_state_space(model, pairs), frs)
    assert loop.steps


def _drop_nda(t):
    t["G"][t["states"].index("r")][t["inputs"].index("da")] = "0"
    del t["parameters"]["Nda"]


@pytest.mark.slow
def test_a_control_derivative_the_fit_made_up_for_is_found_by_refitting_every_missing_one():
    """Hover, the model without Nda (yaw due to aileron). The fit bends the other derivatives to
    make up for it (J_ave about 70: inside the method's <= 100 guideline, but the whitened residual's
    mean square is far above NOISE_INFLATION), and about that fit the screen ranks G[r][da] nowhere
    near significant (ln|r/da| is far from linear in Nda there). The loop, seeing the lack of fit,
    refits every missing derivative from the case's starting values and adds Nda: within 3
    Cramer-Rao bounds of the simulator's, the cost at least halved, nothing else added.
    Seed 81 was not looked at while the lack-of-fit rule was set (hover seeds 408, 508 and 608
    of benchmarks/residual_confusion.py were)."""
    from livesweep.ident.selection import NOISE_INFLATION
    from livesweep.sim.models import xv15_hover

    frs, table, fit = _hover([], seed=81, edit=_drop_nda)
    loop = run_residual_loop(table, fit, frs)
    first = loop.steps[0]
    res = first.residuals_before
    assert sum(np.sum((r.magnitude_db / r.sigma_db) ** 2 + (r.phase_deg / r.sigma_deg) ** 2) for r in res) \
        > NOISE_INFLATION * sum(2 * r.omega.size for r in res)
    screened = next(c for c in first.candidates if (c.kind, c.where) == ("missing_derivative", "G[r][da]"))
    assert first.candidates.index(screened) >= 3          # the screen alone would not have refitted it
    assert [(e["kind"], e["where"]) for e in loop.added] == [("missing_derivative", "G[r][da]")]
    (p,) = loop.added[0]["parameters"]
    truth = xv15_hover().derivatives["Nda"]
    assert abs(p["value"] - truth) <= 3 * p["cramer_rao_pct"] / 100 * abs(p["value"]), (p, truth)
    assert loop.fit.cost_average <= 0.5 * first.cost_before


@pytest.mark.slow
def test_a_control_path_effect_the_screen_misplaces_is_found_by_refitting_every_one():
    """Hover, a 7 rad/s second-order actuator on dr (zeta 0.5). The fit bends the yaw derivatives
    to make up for it, and about that fit the screen sees a 0.2 rad/s resonance and a 10 s lag, not
    the actuator. The loop, seeing the lack of fit, refits every control-path effect once and adds
    the actuator: both parameters within 3 Cramer-Rao bounds of the injection, the cost at least
    halved, nothing else added. (The rule was set on development hover seed 73 and held-out-8 seed
    903 of benchmarks/residual_confusion.py; this seed was not looked at.)"""
    frs, table, fit = _hover([make_effect("actuator_second_order", input="dr", omega_rad_s=7.0, zeta=0.5)], seed=85)
    loop = run_residual_loop(table, fit, frs)
    first = loop.steps[0]
    screened = next(c for c in first.candidates if (c.kind, c.where) == ("actuator_second_order", "dr"))
    assert first.candidates.index(screened) >= 3          # the screen alone would not have refitted it
    assert [(e["kind"], e["where"]) for e in loop.added] == [("actuator_second_order", "dr")], loop.conclusion
    p = {x["name"]: x for x in loop.added[0]["parameters"]}
    for name, truth in (("wn_act_dr", 7.0), ("zeta_act_dr", 0.5)):
        assert abs(p[name]["value"] - truth) <= 3 * p[name]["cramer_rao_pct"] / 100 * p[name]["value"], p[name]
    assert loop.fit.cost_average <= 0.5 * first.cost_before


SKEW_SEED = 62     # one where the bound lands between the guideline and a third (61: 18.6 %, 64: evidence < 2x needed)


@pytest.mark.slow
def test_an_effect_s_only_parameter_three_bounds_from_zero_is_kept_and_said_to_be_poorly_determined():
    """Hover, a 30 ms skew on phi (missed on held-out-8 seed 906 of
    benchmarks/residual_confusion.py): clearly there by its F-test, its only parameter at a
    Cramer-Rao bound above the 20 % guideline but below a third of its value (three bounds from
    zero). The loop adds it with the value fixed and says so, and the value is within 3 of those
    bounds of the injection."""
    from livesweep.ident.accuracy import MAX_CRAMER_RAO_PCT
    from livesweep.ident.residual import ONLY_PARAMETER_CR_PCT

    frs, table, fit = _hover([make_effect("sensor_skew", output="phi", delay_s=0.03)], seed=SKEW_SEED)
    loop = run_residual_loop(table, fit, frs)
    assert [(e["kind"], e["where"]) for e in loop.added] == [("sensor_skew", "phi")], loop.conclusion
    (skew,) = loop.added[0]["parameters"]
    assert skew["fixed"]
    (why,) = next(t for t in loop.steps[0].tried if t["accepted"])["fixed"]
    assert MAX_CRAMER_RAO_PCT < why["cramer_rao_pct"] <= ONLY_PARAMETER_CR_PCT
    assert abs(skew["value"] - 0.03) <= 3 * why["cramer_rao_pct"] / 100 * skew["value"]
    assert "poorly determined" in effect_text(loop.added[0])


@pytest.mark.slow
def test_an_effect_added_first_is_taken_out_when_a_later_one_explains_it():
    """Hover, a second-order actuator on dr (8 rad/s, zeta 0.5) with a 50 ms skew on p. The first
    step adds a delay on dr (simpler than the actuator and not significantly worse alone), the
    second the skew, the third the actuator. With the actuator in, the delay no longer lowers the
    whitened residual significantly (the F-test of a pair's partners), so the backward step takes
    it out: the model ends with the skew and the actuator, each parameter within 3 Cramer-Rao
    bounds of the injection, and the report says what was taken out. (Seen on held-out-10 seed
    1110 of benchmarks/residual_confusion.py, where the delay stayed in; seeds 91-94 here all
    add the delay first.)"""
    effects = [make_effect("actuator_second_order", input="dr", omega_rad_s=8.0, zeta=0.5),
               make_effect("sensor_skew", output="p", delay_s=0.05)]
    frs, table, fit = _hover(effects, seed=91)
    loop = run_residual_loop(table, fit, frs)
    order = [(s.effect["kind"], s.effect["where"]) for s in loop.steps if s.effect]
    assert order[0] == ("time_delay", "dr") and "removed" in loop.steps[0].effect
    assert sorted((e["kind"], e["where"]) for e in loop.added) == [("actuator_second_order", "dr"), ("sensor_skew", "p")]
    p = {x["name"]: x for e in loop.added for x in e["parameters"]}
    for name, truth in (("wn_act_dr", 8.0), ("zeta_act_dr", 0.5), ("skew_p", 0.05)):
        assert abs(p[name]["value"] - truth) <= 3 * p[name]["cramer_rao_pct"] / 100 * p[name]["value"], p[name]
    assert "tau_dr" not in loop.table["parameters"]
    assert "took out time_delay at dr" in loop.conclusion
    assert loop.fit.cost_average <= 0.5 * loop.steps[0].cost_before


@pytest.mark.slow
def test_an_effect_the_backward_step_cannot_retest_is_kept_and_said():
    """The backward step re-fits the model without each earlier effect; when that model cannot
    be built (here the later effect's record names a parameter the current table lacks) the
    earlier effect stays in and the failure is returned with its kind, place and error, for the
    record and the conclusion, not skipped silently."""
    from livesweep.ident.residual import _backward, _Judge
    from livesweep.ident.residual_space import pair_residuals, whitened_ss
    from livesweep.ident.selection import effective_points

    frs, _ = _data([make_effect("sensor_skew", output="p", delay_s=0.05)], seed=12)
    t0 = _table()
    skew = Candidate("sensor_skew", "p", {"delay_s": 0.05}, 1.0, 1)
    t1, names1 = augment_table(t0, skew)
    model = StateSpaceModel.from_table(t1)
    pairs, _ = select_pairs(frs, model)
    fit = fit_state_space(model, pairs)
    table = table_with_fit(t1, fit)
    judge = _Judge(pairs, frs, None, effective_points(pairs, frs.settings), 0.01)
    ss = whitened_ss(tuple(pair_residuals(fit.model, fit.theta, pairs, frs)))
    history = [{"table": t0, "cands": [skew], "names": names1, "effect": {"kind": "sensor_skew", "where": "p"}},
               {"table": t1, "cands": [], "names": ["no_such_parameter"], "effect": {"kind": "x", "where": "y"}}]
    removal, untested = _backward(history, table, fit, ss, judge, None)
    assert removal is None
    assert [(u["kind"], u["where"]) for u in untested] == [("sensor_skew", "p")]
    assert "no_such_parameter" in untested[0]["error"]


@pytest.mark.slow
def test_one_place_s_rival_kinds_do_not_take_every_refit_from_the_next_place():
    """Hover with twice the sensor noise, a 0.1 s lag on da and a 50 ms skew on r. Once the lag
    is in, the screen ranks a delay, a second-order actuator and a lag on dr (one feature, one
    place) above the skew on r; the three refits per step went to them and a delay on dr was added
    for the skew (held-out-12 seed 1309 of benchmarks/residual_confusion.py). The best candidate
    at each of the first places is refitted too: the model ends with the lag and the skew, each
    parameter within 3 Cramer-Rao bounds of its injection, the cost at least halved. (Seeds 96,
    97 and 99 rank the skew fourth; 95 and 98 first.)"""
    frs, table, fit = _hover([make_effect("actuator_lag", input="da", time_constant_s=0.1),
                              make_effect("sensor_skew", output="r", delay_s=0.05)], seed=96, noise=2.0)
    loop = run_residual_loop(table, fit, frs)
    second = loop.steps[1]
    ranked = [(c.kind, c.where) for c in second.candidates]
    assert ranked.index(("sensor_skew", "r")) >= 3, ranked[:5]
    assert sorted((e["kind"], e["where"]) for e in loop.added) == [("actuator_lag", "da"), ("sensor_skew", "r")]
    p = {x["name"]: x for e in loop.added for x in e["parameters"]}
    fixed = {f["name"]: f for s in loop.steps for t in s.tried if t.get("accepted") for f in t["fixed"]}
    for name, truth in (("w_act_da", 10.0), ("skew_r", 0.05)):
        cr = (fixed[name] if p[name]["fixed"] else p[name])["cramer_rao_pct"]     # a fixed one: its bound when fixed
        assert abs(p[name]["value"] - truth) <= 3 * cr / 100 * p[name]["value"], (p[name], cr)
    assert loop.fit.cost_average <= 0.5 * loop.steps[0].cost_before


@pytest.mark.slow
def test_a_refit_stopped_by_its_budget_is_continued_not_called_unconverged(monkeypatch):
    """A refit inside the loop (and the coupling search) that runs out of cost evaluations while still descending is
    continued once from where it stopped (held-out-12 seed 1310 of
    benchmarks/residual_confusion.py: the best candidate, a delay on hover dr, was refused as "fit
    did not converge" at a cost equal to 4e-8 of the converged one). With the budget cut to 3
    evaluations here, the first fit stops unconverged; the continued one converges to the fit
    run without a budget (scipy's least_squares to its own tolerances)."""
    import livesweep.ident.state_space as S

    frs, _ = _data([make_effect("time_delay", input="dr", delay_s=0.08)], seed=14)
    t0 = _table()
    model = StateSpaceModel.from_table(t0)
    pairs, _ = select_pairs(frs, model)
    fit = fit_state_space(model, pairs)
    t1, _ = augment_table(table_with_fit(t0, fit), Candidate("time_delay", "dr", {"delay_s": 0.01}, 1.0, 1))
    m = StateSpaceModel.from_table(t1)
    free = fit_state_space(m, pairs, max_nfev=None)
    monkeypatch.setattr(S, "REFIT_NFEV", 3)
    assert not fit_state_space(m, pairs, max_nfev=3).converged
    got = S.refit_state_space(m, pairs)
    assert got.converged
    assert got.cost_average == pytest.approx(free.cost_average, rel=1e-8)
    k = m.index("tau_r")
    assert got.theta[k] == pytest.approx(free.theta[k], rel=1e-5)


@pytest.mark.slow
def test_an_earlier_effect_is_replaced_by_its_simpler_rival_once_a_later_one_is_in():
    """Hover, a 60 ms delay on da with a 10 rad/s mode on p (pole damping 0.06, zero 0.2). At the
    first step a second-order actuator on da explains far more than the delay: its low-damped
    resonance stands in for part of the mode. The mode comes at the second step; with it in, the
    actuator's extra parameter is no longer significant over the delay (the simplest-first test
    of the first step, made again), so the delay takes its place. Every parameter ends within 3
    Cramer-Rao bounds of the injection, the table holds tau_da and no actuator, the report says
    what was replaced. (Held-out-13 seed 1409 of benchmarks/residual_confusion.py kept the
    actuator; seeds 100-104 here all add it first.)"""
    effects = [make_effect("time_delay", input="da", delay_s=0.06),
               make_effect("structural_mode", output="p", omega_rad_s=10.0, zeta_pole=0.06, zeta_zero=0.2)]
    frs, table, fit = _hover(effects, seed=101)
    loop = run_residual_loop(table, fit, frs)
    first, second = (s.effect for s in loop.steps[:2])
    assert (first["kind"], first["where"]) == ("actuator_second_order", "da")
    assert first["removed"]["replaced_by"] == "time_delay at da"
    assert (second["replaces"]["by"]["kind"], second["replaces"]["kind"]) == ("time_delay", "actuator_second_order")
    assert sorted((e["kind"], e["where"]) for e in loop.added) == [("structural_mode", "p"), ("time_delay", "da")]
    truth = {"tau_da": 0.06, "w_mode_p": 10.0, "zeta_mode_p": 0.06, "zeta_zero_mode_p": 0.2}
    fixed = {f["name"]: f for s in loop.steps for t in s.tried if t.get("accepted") for f in t["fixed"]}
    for e in loop.added:
        for p in e["parameters"]:
            cr = (fixed[p["name"]] if p["fixed"] else p)["cramer_rao_pct"]
            assert abs(p["value"] - truth[p["name"]]) <= 3 * cr / 100 * abs(p["value"]), (p, truth[p["name"]])
    assert "tau_da" in loop.table["parameters"] and "wn_act_da" not in loop.table["parameters"]
    assert "actuator_second_order at da added before replaced by time_delay at da" in loop.conclusion
    assert "replaced actuator_second_order at da, added before, by time_delay at da" in effect_text(second)
    assert "(replaced by time_delay at da at step 2:" in effect_text(first)
    assert loop.fit.cost_average <= 0.5 * loop.steps[0].cost_before
