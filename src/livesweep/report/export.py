"""Model and data export for control design elsewhere: frequency responses as CSV and MATLAB
``.mat``, state-space matrices and transfer-function polynomials as plain lists for ``report.json``.

Files (in the report folder):

- ``frequency_responses.csv``: one row per pair and frequency, columns ``output, input,
  omega_rad_s, magnitude_db, phase_deg, real, imag, coherence, random_error, output_units,
  input_units`` (empty where the estimate is not finite).
- ``frequency_responses.mat`` (MATLAB 5, ``scipy.io.savemat``): ``omega_rad_s`` (1 x n_freq),
  ``H`` (complex, n_out x n_in x n_freq), ``coherence``, ``random_error`` (same shape),
  ``outputs``, ``inputs``, ``output_units``, ``input_units`` (cell arrays of strings),
  ``conditioned`` (1 when MISO-conditioned) and, with a state-space model, ``A``, ``B``, ``C``,
  ``D``, ``states`` and ``input_delays_s``. Non-finite estimates are NaN.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

__all__ = ["RESPONSES_CSV", "RESPONSES_MAT", "write_responses_csv", "write_responses_mat", "state_space_export",
           "polynomials"]

RESPONSES_CSV = "frequency_responses.csv"
RESPONSES_MAT = "frequency_responses.mat"


def _cell(x: float) -> str:
    return repr(float(x)) if math.isfinite(x) else ""


def write_responses_csv(frs, path, units: dict) -> Path:
    """Write every pair of a FrequencyResponseSet as rows of ``path`` (see the module docstring).

    Parameters
    ----------
    frs : FrequencyResponseSet
    path : str or Path
    units : dict of str -> str
        Signal name -> units, for the ``output_units`` / ``input_units`` columns.
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["output", "input", "omega_rad_s", "magnitude_db", "phase_deg", "real", "imag", "coherence",
                "random_error", "output_units", "input_units"])
    for pair in frs.pairs():
        ou, iu = units.get(pair.output, ""), units.get(pair.input, "")
        cols = [np.asarray(c, float).tolist() for c in (pair.omega, pair.magnitude_db, pair.phase_deg, pair.H.real,
                                                         pair.H.imag, pair.coherence, pair.random_error)]
        for row in zip(*cols):      # magnitude and phase computed once per pair, not once per row
            w.writerow([pair.output, pair.input, *map(_cell, row), ou, iu])
    path = Path(path)
    path.write_text(buf.getvalue())
    return path


def state_space_export(fit, units: dict) -> dict:
    """``A = M^-1 F``, ``B = M^-1 G``, ``C = H``, ``D = J`` of a StateSpaceFit with names, units and
    delays, JSON-ready (non-finite entries None).

    Returns
    -------
    dict
        ``states``, ``inputs``, ``outputs``, ``input_units``, ``output_units``, ``A``, ``B``, ``C``,
        ``D`` (lists of rows), ``input_delays_s``, ``output_delays_s``, ``input_skews_s`` and a
        ``note`` on the units (the case's model units: outputs and inputs as logged, states as the
        model's equations define them).
    """
    m = fit.matrices()
    model = fit.model

    def rows(a):
        return [[float(x) if math.isfinite(x) else None for x in row] for row in np.atleast_2d(a)]

    return {"states": list(m["states"]), "inputs": list(m["inputs"]), "outputs": list(m["outputs"]),
            "input_units": [units.get(n, "") for n in m["inputs"]],
            "output_units": [units.get(n, "") for n in m["outputs"]],
            "A": rows(m["A"]), "B": rows(m["B"]), "C": rows(m["C"]), "D": rows(m["D"]),
            "input_delays_s": [float(t) for t in m["tau_s"]],
            "output_delays_s": [float(t) for t in model.output_delays_s(fit.theta)],
            "input_skews_s": [float(t) for t in model.input_skews_s(fit.theta)],
            "note": "x' = A x + B u(t - tau), y = C x + D u(t - tau); outputs and inputs in the units listed, "
                    "states in the units the model's equations give them"}


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def gain_units(fit, units: dict) -> str:
    """Units of the gain K of a FittedTransferFunction's factored form.

    Each factor (s + a) or s carries 1/s, so K is in output units per input unit times
    s^-(n_poles - n_zeros): ``(deg/s)/deg·s⁻¹`` for a first-order p/da.
    """
    def wrap(u):
        u = (u or "-").strip().replace("^2", "²").replace("^3", "³")
        return f"({u})" if "/" in u or " " in u else u

    base = f"{wrap(units.get(fit.output, ''))}/{wrap(units.get(fit.input, ''))}"
    r = len(fit.poles) - len(fit.zeros)
    return base if r == 0 else f"{base}·s{str(-r).translate(_SUPERSCRIPT)}"


def polynomials(fit) -> dict:
    """Numerator and denominator coefficients (highest power first) of a FittedTransferFunction,
    ``T(s) = num(s) / den(s) * exp(-delay_s s)``."""
    num = float(fit.gain) * np.poly(np.asarray(fit.zeros, complex)) if len(fit.zeros) else np.array([float(fit.gain)])
    den = np.poly(np.asarray(fit.poles, complex)) if len(fit.poles) else np.array([1.0])
    return {"numerator": [float(x) for x in np.real(num)], "denominator": [float(x) for x in np.real(den)],
            "delay_s": float(fit.delay_s)}


def write_responses_mat(frs, path, units: dict, fit=None) -> Path:
    """Write a FrequencyResponseSet (and, when given, the state-space model) as a MATLAB file."""
    from scipy.io import savemat

    data = {"omega_rad_s": np.asarray(frs.omega, float)[None, :], "H": np.asarray(frs.H, complex),
            "coherence": np.asarray(frs.coherence, float), "random_error": np.asarray(frs.random_error, float),
            "outputs": np.array(list(frs.outputs), dtype=object), "inputs": np.array(list(frs.inputs), dtype=object),
            "output_units": np.array([units.get(n, "") for n in frs.outputs], dtype=object),
            "input_units": np.array([units.get(n, "") for n in frs.inputs], dtype=object),
            "conditioned": int(bool(frs.conditioned))}
    if fit is not None:
        m = fit.matrices()
        data.update({"A": m["A"], "B": m["B"], "C": m["C"], "D": m["D"], "input_delays_s": m["tau_s"][None, :],
                     "states": np.array(list(m["states"]), dtype=object)})
    path = Path(path)
    savemat(path, data, do_compression=True)
    return path
