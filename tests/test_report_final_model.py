"""The report signs the model the user takes away: when the residual loop adds an effect (a notch
filter at 6 rad/s in the aileron path that the case does not declare), the summary, the derivative
and mode tables, the handling-qualities table and every Bode overlay of report.html show the final
model, with the model before the loop beside it; report.json's top-level ``model`` and
``identify()``'s ``model`` are the same model.

Independent references: the injected notch (the simulator's truth), the augmented case file the
loop writes, and scipy's state-space frequency response of the exported matrices."""

from __future__ import annotations

import base64
import html as html_lib
import json
import re
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

import livesweep
from livesweep.config import load_case
from livesweep.report.console import summary_lines
from livesweep.report.writer import write_report
from livesweep.sim.effects import make_effect
from livesweep.sim.scenario import simulate, sweep_scenario, verification_scenario
from livesweep.telemetry.sim_telemetry import write_sim_log

ROOT = Path(__file__).resolve().parents[1]
NOTCH = {"omega_rad_s": 6.0, "zeta": 0.3, "depth": 0.7}


@pytest.fixture(scope="module")
def notch_report(tmp_path_factory):
    d = tmp_path_factory.mktemp("notch")
    eff = (make_effect("notch_filter", input="da", **NOTCH),)
    for ax, amp, seed in (("da", 3.0, 3), ("dr", 5.0, 4)):
        sc = sweep_scenario("xv15-cruise", axes=(ax,), amplitudes={ax: amp}, off_axis_rms=0.2, seed=seed, effects=eff)
        write_sim_log(simulate(sc), d / f"xv15_cruise_sweeps_{ax}.mcap")
    vs = verification_scenario("xv15-cruise", manoeuvres=(("da", "doublet", 3.0, 1.0), ("dr", "doublet", 3.0, 1.5)),
                               effects=eff, seed=5, turbulence_scale=0.0)
    write_sim_log(simulate(vs), d / "xv15_cruise_verify.mcap")
    case = d / "case.toml"
    case.write_text((ROOT / "config" / "xv15_cruise_lateral.toml").read_text().replace("../replay_logs/", ""))
    ident = livesweep.identify(case)
    out = d / "out"
    write_report(ident, out)
    return ident, out, json.loads((out / "report.json").read_text()), (out / "report.html").read_text()


def _cells(page: str, first: str) -> list[str]:
    """The cells (text) of the table row whose first cell is ``first``."""
    for row in re.findall(r"<tr[^>]*>(.*?)</tr>", page, re.S):
        cells = [html_lib.unescape(re.sub(r"<[^>]+>", "", c)).strip() for c in re.findall(r"<td[^>]*>(.*?)</td>", row, re.S)]
        if cells and cells[0] == first:
            return cells
    raise AssertionError(f"no table row {first!r}")


@pytest.mark.slow
def test_the_loop_adds_the_notch_and_report_json_signs_the_final_model(notch_report):
    ident, out, rep, _ = notch_report
    model, pre = rep["model"], rep["state_space"]
    assert model["source"] == "residual-loop" and "notch_filter at da" in model["label"]
    values = {p["name"]: p for p in model["parameters"]}
    w = values["w_notch_da"]
    assert abs(w["value"] - NOTCH["omega_rad_s"]) <= 3 * w["cramer_rao_pct"] / 100 * w["value"]
    # the final model is the augmented case's, value for value
    table = load_case(out / rep["residual_loop"]["augmented_case"]).tables["state_space"]
    written = {k: v["value"] for k, v in table["parameters"].items()}
    assert set(written) == set(values)
    for name, p in values.items():
        assert p["value"] == pytest.approx(written[name], rel=1e-9, abs=1e-12), name
    # one J_ave story: both on the stage's points, the loop's result far below the stage's
    assert model["before_loop"]["cost_average"] == pre["cost"]["average"]
    assert model["points_per_pair"] == 20 and rep["residual_loop"]["points_per_pair"] > 20
    assert model["cost"]["average"] < 0.5 * pre["cost"]["average"]
    # identify()'s model is report.json's model
    assert ident.model.cost_average == pytest.approx(model["cost"]["average"], rel=1e-9)
    assert {p.name for p in ident.model.parameters} == set(values)
    assert ident.model_before_loop.cost_average == pytest.approx(pre["cost"]["average"], rel=1e-9)


@pytest.mark.slow
def test_exported_final_matrices_reproduce_the_model_drawn(notch_report):
    """scipy's response of report.json's A, B, C, D (input delays applied) is identify()'s final model."""
    ident, _, rep, _ = notch_report
    m = rep["model"]["matrices"]
    A, B, C, D = (np.array(m[k], float) for k in "ABCD")
    omega = np.geomspace(0.3, 20.0, 25)
    T = ident.model.frequency_response(omega)
    tau_in = np.array(m["input_delays_s"]) - np.array(m["input_skews_s"])
    for j in range(B.shape[1]):
        num, den = signal.ss2tf(A, B, C, D, input=j)
        for i in range(C.shape[0]):
            _, H = signal.freqs(num[i], den, worN=omega)
            expected = H * np.exp(-1j * omega * (tau_in[j] + m["output_delays_s"][i]))
            np.testing.assert_allclose(T[i, j], expected, rtol=1e-6, atol=1e-9)
    assert "notch_da" in " ".join(m["states"])


@pytest.mark.slow
def test_report_html_summary_tables_and_overlays_carry_the_final_model(notch_report):
    _, out, rep, page = notch_report
    model, pre = rep["model"], rep["state_space"]
    # the summary row signs the final model, the pre-loop figure beside it
    row = " ".join(_cells(page, "state-space"))
    assert f"J_ave {model['cost']['average']:.1f}" in row and "notch_filter at da" in row
    assert f"before the residual loop: J_ave {pre['cost']['average']:.1f}" in row
    # the derivative table: the final value, and the value before the loop beside it
    before = {p["name"]: p for p in pre["parameters"]}
    for p in model["parameters"]:
        cells = _cells(page, p["name"])
        assert float(cells[1]) == pytest.approx(p["value"], rel=1e-4, abs=1e-9), p["name"]
        if p["name"] in before:
            assert float(cells[6]) == pytest.approx(before[p["name"]]["value"], rel=1e-4, abs=1e-9), p["name"]
        else:
            assert cells[7] == "added by the loop"
    # the mode table names the final model's modes; the notch's own states are not a flight mode
    names = [m["name"] for m in model["modes"]]
    assert "Dutch roll" in names
    for m in model["modes"]:
        assert html_lib.escape(m["name"]) in page
    # every Bode overlay of a modelled pair: the final model solid with its J, the pre-loop dashed beside it
    final_j = {(c["output"], c["input"]): c["cost"] for c in model["cost"]["pairs"]}
    pre_j = {(c["output"], c["input"]): c["cost"] for c in pre["cost"]["pairs"]}
    for r in rep["frequency_responses"]:
        key = (r["output"], r["input"])
        if key not in final_j:
            continue
        svg = (out / r["plot"]).read_text()
        solid = re.search(r'<g ([^>]*)data-label="final model \(J (\d+)\)"', svg)
        dashed = re.search(r'<g ([^>]*)data-label="before the residual loop \(J (\d+)\)"', svg)
        assert solid and dashed, key
        assert int(solid.group(2)) == round(final_j[key]) and int(dashed.group(2)) == round(pre_j[key])
        assert "stroke-dasharray" not in solid.group(1) and "stroke-dasharray" in dashed.group(1)
        if key == ("p", "da"):          # the grey fit band of the transfer function has its legend entry
            assert ">fit band of TF p_da</text>" in svg
        # and the page embeds exactly that plot
        assert base64.b64encode(svg.encode()).decode()[:200] in page


@pytest.mark.slow
def test_handling_qualities_and_console_speak_of_the_final_model(notch_report):
    ident, _, rep, page = notch_report
    (tf,) = [t for t in rep["transfer_functions"] if t["name"] == "p_da"]
    hq = tf["handling_qualities"]
    assert hq["model"] is not None and hq["model_before_loop"] is not None
    assert "ω" in page and "final model [rad/s]" in html_lib.unescape(page)
    assert tf["gain_units"] == "(deg/s)/deg·s⁻¹"
    lines = "\n".join(summary_lines(ident))
    assert f"final model (state space + notch_filter at da): J_ave {rep['model']['cost']['average']:.1f}" in lines
    assert f"({rep['state_space']['cost']['average']:.1f} before the residual loop" in lines


# Seed Eq. 2.9 (cruise p/da transfer function): its modes (reference/method.md §11.1).
SEED_CRUISE = {"spiral": -0.0912, "roll subsidence": -1.00,
               "Dutch roll": complex(-0.237 * 1.67, 1.67 * np.sqrt(1 - 0.237**2))}


def _hover_roots():
    """The seed's hover modes (Table 2.3): r decoupled (a yaw root at N_r) and the roots of the
    hover cubic of v, p, phi: s^3 - (Yv + Lp) s^2 + (Yv Lp - Yp Lv) s - g Lv."""
    from livesweep.sim.models import xv15_hover

    d = dict(xv15_hover().derivatives)
    cubic = np.roots([1.0, -(d["Yv"] + d["Lp"]), d["Yv"] * d["Lp"] - d["Yp"] * d["Lv"], -32.174 * d["Lv"]])
    return {"yaw subsidence": d["Nr"], "lateral phugoid": next(z for z in cubic if z.imag > 0),
            "roll subsidence": next(z.real for z in cubic if abs(z.imag) < 1e-9)}


@pytest.mark.slow
@pytest.mark.parametrize("case, truth, tol", [("xv15_cruise_lateral", SEED_CRUISE, 0.35),
                                              ("xv15_hover_lateral", None, 0.15)])
def test_shipped_cases_name_their_modes_at_the_seed_eigenvalues(case, truth, tol, tmp_path):
    """Cruise: Dutch roll, roll subsidence and spiral at the seed's eigenvalues; hover (no airspeed,
    so no Dutch roll and no spiral): roll subsidence, the lateral phugoid and yaw subsidence at
    the seed's hover derivatives' roots. Every name lands on the nearest identified eigenvalue."""
    truth = truth or _hover_roots()
    ident = livesweep.identify(ROOT / "config" / f"{case}.toml", until="state-space")
    write_report(ident, tmp_path, plots=False)
    rep = json.loads((tmp_path / "report.json").read_text())
    page = (tmp_path / "report.html").read_text()
    rows = rep["model"]["modes"]
    assert rep["model"]["source"] == "state-space" and rows == rep["state_space"]["modes"]
    for name, lam in truth.items():
        nearest = min(rows, key=lambda m: abs(complex(*m["eigenvalue"]) - lam))
        assert nearest["name"] == name, (name, lam, nearest)
        assert abs(complex(*nearest["eigenvalue"]) - lam) < tol, (name, lam, nearest["eigenvalue"])
        assert f"<td>{name}</td>" in page


def test_bounds_the_data_do_not_determine_read_not_determined():
    """A candidate whose Cramér-Rao bound is 3e18 % (the residual loop's refused candidates, the
    accuracy guidelines' reasons, the report's tables) reads "not determined", never a number."""
    from livesweep.ident.accuracy import guideline_failures
    from livesweep.ident.residual import effect_text
    from livesweep.report.summary import cr_text

    huge = {"name": "w_act_da", "value": 12.0, "cramer_rao_pct": 3.18e18, "insensitivity_pct": 4.0e17, "fixed": False}
    text = effect_text({"kind": "actuator_lag", "where": "da", "parameters": [huge]})
    assert "not determined" in text and "e+1" not in text
    (reason,) = guideline_failures([huge])
    assert "not determined" in reason and "e+1" not in reason
    assert cr_text(3.18e18) == cr_text(None) == cr_text(float("inf")) == "not determined"
    assert cr_text(12.34) == "12.3" and cr_text(999.0) == "999.0"
