"""Model and data export: state-space matrices and transfer-function polynomials in report.json,
frequency responses as CSV and MATLAB .mat, read back with the standard readers and compared
with the frequency-response set the report saved and with python-control."""

import csv
import json

import numpy as np
import pytest
import scipy.io

import livesweep


@pytest.fixture(scope="module")
def written(cruise_identification, tmp_path_factory):
    out = tmp_path_factory.mktemp("export")
    livesweep.write_report(cruise_identification, out, plots=False)
    return cruise_identification, out, json.loads((out / "report.json").read_text())


def test_state_space_matrices_reproduce_the_models_response(written):
    ident, out, report = written
    m = report["state_space"]["matrices"]
    A, B, C, D = (np.array(m[k], float) for k in "ABCD")
    assert m["states"] == list(ident.state_space.fit.model.states) and m["output_units"][0] == "deg/s"
    w = np.geomspace(0.3, 20.0, 30)
    tau = np.array(m["input_delays_s"])
    # C (jwI - A)^-1 B + D with the input delays is the fitted model's response
    T = np.array([(C @ np.linalg.solve(1j * x * np.eye(len(A)) - A, B) + D) * np.exp(-1j * x * tau)[None, :] for x in w])
    np.testing.assert_allclose(np.moveaxis(T, 0, -1), ident.state_space.fit.frequency_response(w), rtol=1e-8, atol=1e-12)
    eig = np.linalg.eigvals(A)
    want = np.array([complex(*e) for e in report["state_space"]["eigenvalues"]])
    for e in want:                                                          # nearest neighbour
        assert np.min(np.abs(eig - e)) < 1e-8 * max(1.0, abs(e))


def test_transfer_function_polynomials_match_python_control(written):
    control = pytest.importorskip("control")
    ident, out, report = written
    tf = report["transfer_functions"][0]
    fit = ident.transfer_functions.fits[0]
    w = np.geomspace(0.5, 15.0, 25)
    T = control.tf(tf["polynomials"]["numerator"], tf["polynomials"]["denominator"])
    got = control.frequency_response(T, w).complex.ravel() * np.exp(-1j * w * tf["polynomials"]["delay_s"])
    np.testing.assert_allclose(got, fit.response(w), rtol=1e-9)


def test_csv_and_mat_hold_the_saved_frequency_responses(written):
    ident, out, report = written
    frs = ident.responses
    assert report["exports"] == {"csv": "frequency_responses.csv", "mat": "frequency_responses.mat"}
    with open(out / "frequency_responses.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(frs.outputs) * len(frs.inputs) * frs.omega.size
    k = frs.outputs.index("p")
    j = frs.inputs.index("da")
    got = [r for r in rows if (r["output"], r["input"]) == ("p", "da")]
    H = np.array([complex(float(r["real"]), float(r["imag"])) for r in got])
    np.testing.assert_allclose(H, frs.H[k, j], rtol=1e-12)
    np.testing.assert_allclose([float(r["coherence"]) for r in got], frs.coherence[k, j], rtol=1e-12)
    assert got[0]["output_units"] == "deg/s" and got[0]["input_units"] == "deg"
    mat = scipy.io.loadmat(out / "frequency_responses.mat")
    np.testing.assert_allclose(mat["omega_rad_s"].ravel(), frs.omega, rtol=1e-12)
    np.testing.assert_allclose(mat["H"], frs.H, rtol=1e-12)
    assert [str(x[0]) if np.ndim(x) else str(x) for x in mat["outputs"].ravel()] == list(frs.outputs)
    np.testing.assert_allclose(mat["A"], report["state_space"]["matrices"]["A"], rtol=1e-12)
