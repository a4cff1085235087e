"""State-space identification (DERIVID, method.md §8) against the XV-15 truth of the simulator.

The acceptance data are the shipped sample logs (replay_logs/, simulated from
livesweep.sim.models with the seed's Tables 2.1-2.4; Lr = Yda = 0 in cruise; Yr = Lr = Ydr = Ldr =
0 in hover), run through the frequency-response stage of the shipped case files. Tolerances are
Cramer-Rao bounds (raw normalisation, calibrated by the Monte-Carlo test at the end).
"""

import copy
import json

import numpy as np
import pytest
import control

from helpers import assert_roots_close
from livesweep.config import load_case
from livesweep.errors import ConfigError
from livesweep.ident.accuracy import MONTE_CARLO_SCATTER_OVER_CR, accuracy_from_jacobian
from livesweep.ident.state_space import (StateSpaceModel, _Problem, a_priori_eliminations, equation_error_start,
                                         fit_state_space, reduce_structure, select_pairs)
from livesweep.stages.frequency_response import run_frequency_response_stage
from livesweep.sim.models import xv15_cruise, xv15_hover
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.spectral.analysis import analyze

CRUISE = "config/xv15_cruise_lateral.toml"
HOVER = "config/xv15_hover_lateral.toml"


def _truth_values(truth):
    d = dict(truth.derivatives)
    d["tau_a"], d["tau_r"] = truth.input_delays_s
    return d


CRUISE_TRUTH = _truth_values(xv15_cruise())
HOVER_TRUTH = _truth_values(xv15_hover())


@pytest.fixture(scope="module")
def cruise():
    case = load_case(CRUISE)
    st = run_frequency_response_stage(case)
    return case, st.analysis.best


@pytest.fixture(scope="module")
def hover_stage():
    return run_frequency_response_stage(load_case(HOVER))


@pytest.fixture(scope="module")
def hover(hover_stage):
    return hover_stage.case, hover_stage.analysis.best


def _table(path):
    return copy.deepcopy(load_case(path).tables["state_space"])


def _report(fit, truth):
    lines = [f"J_ave = {fit.cost_average:.2f}; converged {fit.converged}; {fit.message}"]
    for q in fit.parameters:
        t = truth.get(q.name, np.nan)
        k = (q.value - t) / q.cramer_rao if not q.fixed else np.nan
        lines.append(f"  {q.name:6s} {q.value:+11.5g} truth {t:+11.5g}  CR {q.cramer_rao:9.3g}  CR% {q.cramer_rao_pct:7.2f}"
                     f"  I% {q.insensitivity_pct:7.2f}  (est-truth)/CR {k:+6.2f}{'  fixed' if q.fixed else ''}")
    return "\n".join(lines)


def _within_cr(fit, truth, k=3.0):
    bad = [(q.name, q.value, truth[q.name], q.cramer_rao) for q in fit.parameters
           if not q.fixed and not abs(q.value - truth[q.name]) <= k * q.cramer_rao]
    assert not bad, f"outside {k} CR: {bad}\n{_report(fit, truth)}"


# --- model construction and evaluation --------------------------------------------------------

def test_shipped_cases_build_models():
    m = StateSpaceModel.from_table(_table(CRUISE), CRUISE)
    assert m.states == ("v", "p", "r", "phi") and m.inputs == ("da", "dr") and m.outputs == ("p", "r", "ay", "beta")
    assert len(m.parameters) == 17 and not any(m.fixed)
    assert m.delays == {"da": "tau_a", "dr": "tau_r"}
    M, F, G, H, J, tau = m.matrices(m.initial)
    assert F[0, 2] == pytest.approx(15.0 - 286.93) and F[0, 3] == pytest.approx(32.174)
    assert H[3, 0] == pytest.approx(57.2958 / 286.93) and J[2, 1] == pytest.approx(-0.2)
    np.testing.assert_allclose(tau, [0.08, 0.03])
    assert [m.parameters[k] for k in m.delay_parameter_indices()] == ["tau_a", "tau_r"]
    h = StateSpaceModel.from_table(_table(HOVER), HOVER)
    assert h.outputs == ("p", "r", "ay", "v", "phi") and h.delays == {"da": None, "dr": None}
    assert h.matrices(h.initial)[5].tolist() == [0.0, 0.0]


@pytest.mark.parametrize("path, truth", [(CRUISE, xv15_cruise()), (HOVER, xv15_hover())])
def test_frequency_response_equals_the_simulator_model(path, truth):
    """The case's matrices at the truth values reproduce livesweep.sim.models' exact responses."""
    m = StateSpaceModel.from_table(_table(path))
    th = m.theta({k: v for k, v in _truth_values(truth).items() if k in m.parameters})
    w = np.geomspace(0.05, 50, 77)
    T = m.frequency_response(th, w)
    ref = truth.frequency_response(w)[[truth.outputs.index(o) for o in m.outputs]]
    np.testing.assert_allclose(T, ref, rtol=2e-5)       # H uses 57.2958 for 180/pi
    assert_roots_close(m.eigenvalues(th), truth.eigenvalues(), rtol=2e-5)   # case U0 = 286.93 (sim 286.9277)


def test_implicit_M_and_nonlinear_entries_against_python_control():
    table = {
        "states": ["x1", "x2"], "inputs": ["u"], "outputs": ["y1", "y2"],
        "M": [["1", "-Zwd"], ["0", "m/2"]],
        "F": [["a", "1"], ["-k*a", "-c/m"]],
        "G": [["0"], ["b/(1 + a*a)"]],
        "H": [["1", "0"], ["k", "c"]],
        "J": [["0"], ["d"]],
        "constants": {"m": 2.0},
        "parameters": {"Zwd": {"value": 0.3}, "a": -0.5, "k": {"value": 4.0, "fixed": True}, "c": 0.8, "b": 1.5,
                       "d": 0.1, "tau": 0.05},
        "delays": {"u": "tau"},
    }
    m = StateSpaceModel.from_table(table)
    th = m.initial
    M, F, G, H, J, tau = m.matrices(th)
    np.testing.assert_allclose(M, [[1, -0.3], [0, 1.0]])
    np.testing.assert_allclose(G, [[0], [1.5 / 1.25]])
    Mi = np.linalg.inv(M)
    w = np.geomspace(0.1, 30, 40)
    ref = control.ss(Mi @ F, Mi @ G, H, J)(1j * w) * np.exp(-1j * w * 0.05)
    np.testing.assert_allclose(m.frequency_response(th, w), ref, rtol=1e-9)
    assert_roots_close(m.eigenvalues(th), np.linalg.eigvals(Mi @ F), rtol=1e-10)


@pytest.mark.slow
def test_exact_jacobian_against_central_differences(cruise):
    _, frs = cruise
    table = _table(CRUISE)
    table["M"][1][0] = "Mvp"                                     # a parameter inside M as well
    table["G"][1][0] = "Lda*(1 + Yda*Yda)"                       # and a non-affine entry
    table["parameters"]["Mvp"] = {"value": 0.01}
    m = StateSpaceModel.from_table(table)
    pairs, _ = select_pairs(frs, m)
    prob = _Problem(m, pairs)
    th = m.initial.copy()
    th[m.index("Yda")] = 0.3
    free = m.free
    r, D = prob.residuals_and_jacobian(th, free)
    assert np.dot(r, r) == pytest.approx(sum(c for *_, c in prob.pair_costs(th)))
    num = np.empty_like(D)
    for a, k in enumerate(free):
        h = 1e-6 * max(1.0, abs(th[k]))
        tp, tm = th.copy(), th.copy()
        tp[k] += h
        tm[k] -= h
        num[:, a] = (prob.residuals(tp) - prob.residuals(tm)) / (2 * h)
    np.testing.assert_allclose(D, num, rtol=1e-5, atol=1e-6 * np.abs(num).max())


def _with_extra_delay(key, target, name, value):
    """The cruise model and the same model with ``[state_space.<key>] <target> = <name>``."""
    base = StateSpaceModel.from_table(_table(CRUISE))
    table = _table(CRUISE)
    table[key] = {target: name}
    table["parameters"][name] = {"value": value}
    return base, StateSpaceModel.from_table(table)


def _assert_jacobian_column_is_central_difference(m, frs, name):
    prob = _Problem(m, select_pairs(frs, m)[0])
    k = m.index(name)
    _, D = prob.residuals_and_jacobian(m.initial, m.free)
    tp, tm = m.initial.copy(), m.initial.copy()
    tp[k] += 1e-6
    tm[k] -= 1e-6
    num = (prob.residuals(tp) - prob.residuals(tm)) / 2e-6
    np.testing.assert_allclose(D[:, list(m.free).index(k)], num, rtol=1e-5, atol=1e-6 * np.abs(num).max())


@pytest.mark.slow
def test_output_delay_is_a_pure_skew_on_that_outputs_pairs_with_an_exact_jacobian(cruise):
    """A sensor time skew (``output_delays``): exp(-jw tau_p) on every p pair, nothing else."""
    _, frs = cruise
    base, m = _with_extra_delay("output_delays", "p", "tau_p", 0.05)
    w = np.geomspace(0.3, 20, 50)
    expected = base.frequency_response(base.initial, w)
    expected[0] *= np.exp(-1j * w * 0.05)
    np.testing.assert_allclose(m.frequency_response(m.initial, w), expected, rtol=1e-12, atol=0)
    assert m.output_delays_s(m.initial).tolist() == [0.05, 0.0, 0.0, 0.0]
    assert m.index("tau_p") in m.delay_parameter_indices()
    _assert_jacobian_column_is_central_difference(m, frs, "tau_p")


@pytest.mark.slow
def test_input_skew_advances_that_inputs_pairs_with_an_exact_jacobian(cruise):
    """An input measured late (``input_skews``): exp(+jw tau_s) on every dr pair, so the net input
    delay tau_r - tau_s may be negative."""
    _, frs = cruise
    base, m = _with_extra_delay("input_skews", "dr", "skew_dr", 0.08)
    w = np.geomspace(0.3, 20, 50)
    expected = base.frequency_response(base.initial, w)
    expected[:, 1] *= np.exp(+1j * w * 0.08)
    np.testing.assert_allclose(m.frequency_response(m.initial, w), expected, rtol=1e-12, atol=0)
    assert m.input_skews_s(m.initial).tolist() == [0.0, 0.08]
    _assert_jacobian_column_is_central_difference(m, frs, "skew_dr")


# --- bad input ---------------------------------------------------------------------------------

def _assert_raises_config_error(mutate, match):
    table = _table(CRUISE)
    mutate(table)
    with pytest.raises(ConfigError, match=match):
        StateSpaceModel.from_table(table, "cruise.toml [state_space]")


def test_unknown_name_in_an_entry():
    def f(t):
        t["F"][0][2] = "Yr - U1"
    _assert_raises_config_error(f, r"F\[0\]\[2\] = 'Yr - U1': unknown name 'U1'")


def test_non_arithmetic_entries():
    def f(t):
        t["G"][1][0] = "Lda**2"
    _assert_raises_config_error(f, r"G\[1\]\[0\] = 'Lda\*\*2': unexpected")

    def g(t):
        t["H"][2][0] = "abs(Yv)"
    _assert_raises_config_error(g, r"H\[2\]\[0\] = 'abs\(Yv\)': unexpected '\('")

    def e(t):
        t["J"][0][1] = ""
    _assert_raises_config_error(e, r"J\[0\]\[1\] = '': empty expression")


@pytest.mark.parametrize("key, mutate, match", [
    ("F rows", lambda t: t["F"].pop(), r"F has 3 rows, expected 4 \(one per state\)"),
    ("G cols", lambda t: t["G"][2].append("0"), r"G\[2\] has 3 entries, expected 2 \(one per input\)"),
    ("H rows", lambda t: t["H"].append(["0", "0", "0", "0"]), r"H has 5 rows, expected 4 \(one per output\)"),
    ("J cols", lambda t: t["J"][1].pop(), r"J\[1\] has 1 entries, expected 2"),
    ("M", lambda t: t.__setitem__("M", "identity"), r"M: must be a list of rows"),
])
def test_wrong_shapes(key, mutate, match):
    _assert_raises_config_error(mutate, match)


def test_singular_M():
    def f(t):
        t["M"][3][3] = "0"
    _assert_raises_config_error(f, r"cruise.toml \[state_space\]: M is singular at the initial values")

    def g(t):                                            # singular only at the given parameter value
        t["M"][1][1] = "Mpp"
        t["parameters"]["Mpp"] = {"value": 0.0}
    _assert_raises_config_error(g, "M is singular")


def test_other_bad_tables():
    _assert_raises_config_error(lambda t: t.__setitem__("Q", []), r"unknown key\(s\) Q in \[state_space\]")
    _assert_raises_config_error(lambda t: t["parameters"].__setitem__("Yv", {"value": -0.3, "free": True}),
         r"parameters.Yv: unknown key\(s\) free")
    _assert_raises_config_error(lambda t: t["parameters"].__setitem__("Yv", {"value": "big"}), r"parameters.Yv.value = 'big'")
    _assert_raises_config_error(lambda t: t["parameters"].__setitem__("Zz", {"value": 1.0}), "parameters.Zz: free but used in no matrix")
    _assert_raises_config_error(lambda t: t["delays"].__setitem__("de", "tau_e"), r"delays.de: not an input")
    _assert_raises_config_error(lambda t: t["delays"].__setitem__("da", "tau_x"), r"delays.da = 'tau_x': unknown name")
    _assert_raises_config_error(lambda t: t["constants"].__setitem__("U0", "fast"), r"constants.U0 = 'fast': must be a finite number")
    _assert_raises_config_error(lambda t: t.__setitem__("states", ["v", "p", "p", "phi"]), r"states = .*repeated name\(s\) p")
    _assert_raises_config_error(lambda t: t["parameters"].__setitem__("g", {"value": 1.0}), "parameters.g: the name is also a constant")

    def nonfinite(t):
        t["G"][0][0] = "Yda / Yv"
        t["parameters"]["Yv"] = {"value": 0.0}
    _assert_raises_config_error(nonfinite, r"G\[0\]\[0\] = 'Yda / Yv': not finite at the initial values")

    def bands(t):
        t["bands"] = {"p/da": [2.0, 1.0]}
    _assert_raises_config_error(bands, r"bands.p/da = \[2.0, 1.0\]")


# --- the XV-15 cruise acceptance ---------------------------------------------------------------

@pytest.fixture(scope="module")
def cruise_fit(cruise):
    case, frs = cruise
    model = StateSpaceModel.from_table(case.tables["state_space"], str(case.path))
    pairs, skipped = select_pairs(frs, model)
    fit = fit_state_space(model, pairs, skipped_pairs=skipped)
    return model, pairs, fit


@pytest.mark.slow
def test_cruise_recovers_tables_2_1_and_2_2(cruise_fit):
    """The fit's speed (under 5 s) is benchmarks/bench_state_space.py's: no timing here."""
    model, pairs, fit = cruise_fit
    print("\n" + _report(fit, CRUISE_TRUTH))
    assert len(pairs) == 8 and not fit.skipped_pairs
    assert fit.converged, fit.message
    assert fit.cost_average <= 50
    assert all(c <= 100 for *_, c in fit.cost_pairs)
    _within_cr(fit, CRUISE_TRUTH, 3.0)
    for name in ("Lp", "Lda", "Nr", "Ndr", "Lv", "Nv"):
        assert fit.parameter(name).cramer_rao_pct < 20, name
    for q in fit.parameters:                                     # CR >= I always (method.md §8.4)
        assert q.cramer_rao >= q.insensitivity * (1 - 1e-9)
    # the identified modes are the truth's (Dutch roll, roll, spiral)
    assert_roots_close(fit.eigenvalues, xv15_cruise().eigenvalues(), atol=0.08)


@pytest.mark.slow
def test_cruise_structure_reduction_removes_a_true_zero_and_keeps_the_real_ones(cruise_fit):
    model, pairs, fit = cruise_fit
    red = reduce_structure(model, pairs, fit)
    print("\n" + "\n".join(str(s) for s in red.removed))
    print(_report(red, CRUISE_TRUTH))
    removed = set(red.removed_parameters)
    assert removed & {"Lr", "Yda"}, red.removed
    # only truly-zero or (seed CR% 31 %) weakly determined Yp may go
    assert removed <= {"Lr", "Yda", "Yp"}, red.removed
    for name in ("Lp", "Lda", "Nr", "Ndr", "Lv", "Nv", "Yv", "Np", "Nda", "Ldr", "Ydr", "Yr", "tau_a", "tau_r"):
        assert not red.parameter(name).fixed, name
    for step in red.removed:
        assert step["accepted"] == (step["delta_cost"] <= 2.0)
        assert step["reason"] in ("insensitivity", "cramer_rao")
    assert red.converged and red.cost_average <= 50
    _within_cr(red, CRUISE_TRUTH, 3.0)
    for q in red.parameters:
        if q.fixed:
            assert q.value == 0.0 and q.name in removed
        else:
            assert q.insensitivity_pct <= 10.0 and q.name not in removed
    d = red.to_dict()
    json.dumps(d, allow_nan=False)
    assert d["removed_parameters"] == list(red.removed_parameters)
    assert {p["name"] for p in d["parameters"]} == set(model.parameters)
    assert len(d["cost"]["pairs"]) == 8 and d["cost"]["average"] == pytest.approx(red.cost_average)
    assert all(len(e) == 2 for e in d["eigenvalues"]) and d["converged"] is True
    assert {"cramer_rao_pct", "insensitivity_pct", "fixed", "value"} <= set(d["parameters"][0])


@pytest.mark.slow
def test_a_fit_that_does_not_converge_says_so(cruise_fit):
    model, pairs, _ = cruise_fit
    fit = fit_state_space(model, pairs, max_nfev=2)
    assert fit.converged is False
    assert "did not converge" in fit.message and "2 cost evaluations" in fit.message
    assert fit.to_dict()["converged"] is False


@pytest.mark.slow
def test_lm_and_multistart_agree(cruise_fit):
    model, pairs, fit = cruise_fit
    lm = fit_state_space(model, pairs, method="lm")
    assert lm.converged and lm.cost_average == pytest.approx(fit.cost_average, rel=1e-5)
    far = model.theta({"Lp": -2.0, "Nr": -0.2, "Yr": 40.0})
    ms = fit_state_space(model, pairs, theta0=far, extra_starts=[model.initial])
    assert "best of 2 starts" in ms.message and ms.cost_average == pytest.approx(fit.cost_average, rel=1e-5)
    with pytest.raises(ConfigError, match="method 'bfgs'"):
        fit_state_space(model, pairs, method="bfgs")


@pytest.mark.slow
def test_equation_error_start_when_the_case_gives_no_values(cruise, cruise_fit):
    _, frs = cruise
    _, _, fit = cruise_fit
    table = _table(CRUISE)
    table["parameters"] = {name: {} for name in table["parameters"]}
    model = StateSpaceModel.from_table(table)
    assert set(model.unset) == set(model.parameters)
    start = equation_error_start(model, frs)
    for name in ("Lp", "Lda", "Nr", "Ndr", "Lv", "Nv", "Yv"):      # a rough but right-signed start
        assert np.sign(start[model.index(name)]) == np.sign(CRUISE_TRUTH[name])
    ee = fit_state_space(model, frs)
    assert ee.converged and ee.cost_average == pytest.approx(fit.cost_average, rel=1e-6)


# --- hover ---------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def hover_fit(hover):
    case, frs = hover
    model = StateSpaceModel.from_table(case.tables["state_space"], str(case.path))
    pairs, skipped = select_pairs(frs, model)
    prior = a_priori_eliminations(model, skipped)
    model = model.with_values(fixed={name: 0.0 for name in prior})
    return model, pairs, skipped, prior, fit_state_space(model, pairs, skipped_pairs=skipped)


@pytest.mark.slow
def test_hover_sample_logs_recover_tables_2_3_and_2_4(hover, hover_fit):
    """Shipped hover logs: flown with a stabilising pilot loop, so the case forms the responses
    through the logged sweep injections (method.md §4.6). The rudder pairs other than r/dr (and
    ay/dr) carry no usable coherence, so Ldr and Ydr (truly zero) are fixed a priori; every other
    parameter of Tables 2.3-2.4 comes out within 3 CR bounds."""
    case, frs = hover
    assert frs.settings["references"] == ["da_ref", "dr_ref"]
    model, pairs, skipped, prior, fit = hover_fit
    print("\n" + _report(fit, HOVER_TRUTH))
    assert {("p", "dr"), ("v", "dr"), ("phi", "dr")} <= {(o, i) for o, i, _ in skipped}
    assert set(prior) == {"Ydr", "Ldr"}                       # both truly zero in the hover truth
    assert fit.converged and fit.cost_average <= 50
    # each pair is fitted over its own coherent band: p/da to the sweep's top, although v has no
    # coherence at some frequencies above 3 rad/s (before stop 28 v's holes cut every pair at 6.6)
    band = {(p.output, p.input): p.omega.max() for p in pairs}
    assert band[("p", "da")] >= 11.5 and band[("v", "da")] < 6.0
    _within_cr(fit, HOVER_TRUTH, 3.0)
    for name in ("Lp", "Lda", "Nr", "Ndr", "Lv"):
        assert fit.parameter(name).cramer_rao_pct < 20, name
    # Nv (0.0007 in the table) sits at the guideline's edge on these logs: CR 19.5 % on the band
    # v's holes cut short, 20.6 % on the whole coherent band
    assert fit.parameter("Nv").cramer_rao_pct < 25
    # the identified modes are the truth's (unstable lateral oscillation, roll, yaw)
    assert_roots_close(fit.eigenvalues, xv15_hover().eigenvalues(), atol=0.08)


@pytest.mark.slow
def test_hover_structure_reduction_removes_the_true_zeros_and_keeps_the_real_ones(hover_fit):
    model, pairs, _, prior, fit = hover_fit
    red = reduce_structure(model, pairs, fit)
    print("\n" + "\n".join(str(s) for s in red.removed))
    print(_report(red, HOVER_TRUTH))
    # the table's remaining zeros go; of its non-zero derivatives only the two small yaw ones at the
    # guideline's edge may (Nv 0.0007: CR 20.6 %, I 10.8 % in the full fit; Np 0.039 after it)
    assert {"Yr", "Lr"} <= set(red.removed_parameters) <= {"Yr", "Lr", "Nv", "Np"}
    for name in ("Yv", "Yp", "Lv", "Lp", "Nr", "Yda", "Lda", "Nda", "Ndr"):
        assert not red.parameter(name).fixed, name
    assert red.converged and red.cost_average <= 50
    _within_cr(red, HOVER_TRUTH, 3.0)


@pytest.mark.slow
def test_hover_direct_miso_estimate_is_closed_loop_biased(hover, hover_stage):
    """Why the case uses references: on the same logs, the direct MISO responses make the true
    model misfit the low-frequency data, while the referenced responses fit it everywhere."""
    case, frs = hover
    st = hover_stage
    model = StateSpaceModel.from_table(case.tables["state_space"], str(case.path))
    th = model.theta({k: v for k, v in HOVER_TRUTH.items() if k in model.parameters})

    def truth_cost_below(frs_, hi):
        pairs, _ = select_pairs(frs_, model, omega_range=(0.0, hi))
        return np.mean([c for *_, c in _Problem(model, pairs).pair_costs(th)])

    j_direct, j_ref = truth_cost_below(st.analysis.miso, 1.0), truth_cost_below(st.analysis.referenced, 1.0)
    print(f"\n  truth model J_ave below 1 rad/s: direct MISO {j_direct:.1f}, referenced {j_ref:.1f}")
    # measured 10.7 vs 46.9 (the guideline is J_ave <= 50: the direct estimate sits at its edge)
    assert j_ref < 20 and j_direct > 3 * j_ref


def _simulated_frs(model_name, amplitudes, band, windows, seed, turbulence=True):
    """A sample-log-like test point flown in the simulator and analysed (MISO-conditioned)."""
    sc = sweep_scenario(model_name, axes=("da", "dr"), repeats=2, omega_min_rad_s=band[0], omega_max_rad_s=band[1],
                        duration_s=100.0, amplitudes=amplitudes, off_axis_rms=0.2, seed=seed, turbulence=turbulence)
    res = simulate(sc)
    names, rows = [], []
    for name, sig in list(res.inputs.items()) + list(res.outputs.items()):
        names.append(name)
        rows.append(sig.values[::int(round(sig.rate_hz / 50.0))])
    n = min(r.size for r in rows)
    values = np.array([r[:n] for r in rows])
    values -= values.mean(axis=1, keepdims=True)
    return analyze(values, names, 50.0, ["da", "dr"], list(res.outputs), band, windows_s=windows).best


@pytest.mark.slow
def test_hover_open_loop_equivalent_data_recover_tables_2_3_and_2_4(hover):
    """Same test point without turbulence: the pilot loop then sees no disturbance, the responses
    are the open-loop ones, and the fit recovers the hover truth; the reduction removes exactly
    its zeros."""
    case, _ = hover
    frs = _simulated_frs("xv15-hover", {"da": 1.5, "dr": 3.0}, (0.2, 12.0), (10.0, 20.0, 40.0, 80.0, 160.0), seed=21,
                         turbulence=False)
    model = StateSpaceModel.from_table(case.tables["state_space"], str(case.path))
    pairs, skipped = select_pairs(frs, model)
    fit = fit_state_space(model, pairs, skipped_pairs=skipped)
    print("\n" + _report(fit, HOVER_TRUTH))
    assert fit.converged and fit.cost_average <= 50
    _within_cr(fit, HOVER_TRUTH, 3.0)
    for name in ("Yv", "Lv", "Lp", "Yda", "Lda", "Nda", "Ndr"):
        assert fit.parameter(name).cramer_rao_pct < 20, name
    red = reduce_structure(model, pairs, fit)
    print("\n".join(str(s) for s in red.removed))
    print(_report(red, HOVER_TRUTH))
    zeros = {"Yr", "Lr", "Ydr", "Ldr"}
    removed = red.removed_parameters
    # the four truly-zero parameters are the most insensitive and go first ...
    assert set(removed[:4]) == zeros
    # ... then at most the two the seed also found weakest (Np 29.9 %, Nv 7.7 % CR): here Nv goes
    # at I% = 11.0 with dJ_ave = 1.9 (< 2), then Np -- the guideline loop is that blunt
    assert set(removed) <= zeros | {"Nv", "Np"}
    for name in ("Yv", "Yp", "Lv", "Lp", "Nr", "Yda", "Lda", "Nda", "Ndr"):
        assert not red.parameter(name).fixed, name
    assert red.cost_average <= 50


# --- accuracy ------------------------------------------------------------------------------------

def test_accuracy_formulas_on_a_linear_problem():
    rng = np.random.default_rng(0)
    D = rng.standard_normal((50, 3)) * [1.0, 10.0, 0.1]
    D[:, 2] += 0.05 * D[:, 0]
    theta = np.array([2.0, -0.5, 0.01])
    acc = accuracy_from_jacobian(D, theta)
    H = 2 * D.T @ D
    C = np.linalg.inv(H)
    np.testing.assert_allclose(acc.cramer_rao, np.sqrt(np.diag(C)), rtol=1e-10)
    np.testing.assert_allclose(acc.insensitivity, 1 / np.sqrt(np.diag(H)), rtol=1e-12)
    np.testing.assert_allclose(acc.cramer_rao_pct, 100 * np.sqrt(np.diag(C)) / np.abs(theta), rtol=1e-10)
    np.testing.assert_allclose(acc.correlation, C / np.sqrt(np.outer(np.diag(C), np.diag(C))), atol=1e-12)
    assert np.all(acc.cramer_rao >= acc.insensitivity)
    # a parameter with no effect, and two that trade off exactly
    D2 = np.column_stack([D[:, 0], D[:, 0], np.zeros(50), D[:, 1]])
    acc2 = accuracy_from_jacobian(D2, np.array([1.0, 1.0, 1.0, 1.0]))
    assert np.isinf(acc2.cramer_rao[:3]).all() and np.isinf(acc2.insensitivity[2])
    K = 2 * np.column_stack([D[:, 0], D[:, 1]]).T @ np.column_stack([D[:, 0], D[:, 1]])   # theta0 + theta1, theta3
    assert acc2.cramer_rao[3] == pytest.approx(np.sqrt(np.linalg.inv(K)[1, 1]), rel=1e-8)


@pytest.mark.slow
def test_cramer_rao_monte_carlo(cruise):
    """Calibrate the raw CR normalisation: independent noisy realisations of the cruise test point
    (turbulence, sensor noise, off-axis pilot noise; new seeds), identified with the cruise model
    (Lr, Yda fixed at their true 0); scatter of the estimates vs the mean CR bound.

    Measured with 80 realisations (seeds 200-279) while writing this test: median std/CR 0.68
    (range 0.34 tau_a ... 1.50 Ldr), rms error/CR median 0.98 -- the yaw-axis Nv, Nr, Ndr carry a
    systematic bias of ~2.5 CR (3-7 %) that the spectral chain introduces with turbulence.
    """
    case, _ = cruise
    model = StateSpaceModel.from_table(case.tables["state_space"]).with_values(fixed={"Lr": 0.0, "Yda": 0.0})
    est, crs = [], []
    for seed in range(300, 310):
        frs = _simulated_frs("xv15-cruise", {"da": 3.0, "dr": 5.0}, (0.3, 20.0), (7.0, 12.0, 20.0, 40.0, 80.0), seed)
        pairs, _ = select_pairs(frs, model)
        fit = fit_state_space(model, pairs)
        assert fit.converged
        est.append([q.value for q in fit.parameters])
        crs.append([q.cramer_rao for q in fit.parameters])
    est, crs = np.array(est), np.array(crs)
    free = model.free
    truth = np.array([CRUISE_TRUTH[n] for n in model.parameters])
    ratio = est[:, free].std(axis=0, ddof=1) / crs[:, free].mean(axis=0)
    rms = np.sqrt(np.mean((est[:, free] - truth[free]) ** 2, axis=0)) / crs[:, free].mean(axis=0)
    for n, a, b in zip(model.free_names, ratio, rms):
        print(f"  {n:6s} std/CR {a:5.2f}  rms(err)/CR {b:5.2f}")
    factor = float(np.median(ratio))
    print(f"  median std/CR = {factor:.2f} (documented {MONTE_CARLO_SCATTER_OVER_CR}); median rms/CR = "
          f"{np.median(rms):.2f}")
    # 10 realisations: each std/CR is within about +-50 % (chi, 9 dof, 99 %); the median is steadier
    assert abs(factor - MONTE_CARLO_SCATTER_OVER_CR) <= 0.3
    assert np.all(ratio < 3.0)
    assert np.median(rms) < 1.6


@pytest.mark.slow
def test_hover_residual_loop_adds_nothing_outside_the_true_structure(hover, hover_fit):
    """The shipped hover logs hold no undeclared effect: after the reduction, the residual loop
    adds nothing but, at most, a derivative of Tables 2.3-2.4 the reduction took out (Np), with the
    table's sign (no verification records in the hover case)."""
    from livesweep.ident.residual import run_residual_loop

    case, frs = hover
    model, pairs, _, _, fit = hover_fit
    red = reduce_structure(model, pairs, fit)
    loop = run_residual_loop(case.tables["state_space"], red, frs)
    print("\n", loop.conclusion, [c.to_dict() for c in loop.steps[0].candidates[:3]])
    for e in loop.added:
        assert e["kind"] == "missing_derivative" and e["where"] in red.removed_parameters, e
        (p,) = e["parameters"]
        assert HOVER_TRUTH[p["name"]] != 0.0 and np.sign(p["value"]) == np.sign(HOVER_TRUTH[p["name"]]), p
