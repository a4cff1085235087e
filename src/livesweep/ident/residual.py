"""Close the loop: find the model's residual, trace it to the effect the model lacks, add it.

After a state-space fit, the frequency-domain residual of every pair (data minus model, dB and
deg at the fitting points) is compared with the random error of the data and matched against a
catalogue of effects a flight-test engineer meets:

=========================  ========  =========================================================
kind                       where     signature (factor on the affected pairs)
=========================  ========  =========================================================
``time_delay``             input     ``exp(-s tau)``: phase growing linearly with w, magnitude flat
``actuator_lag``           input     ``w_a/(s + w_a)``
``actuator_second_order``  input     ``w_n^2/(s^2 + 2 zeta w_n s + w_n^2)``
``notch_or_filter``        input     ``1 + g 2 zeta w s/(s^2 + 2 zeta w s + w^2)`` (g < 0: notch)
``structural_mode``        output    the same local signature, on one output's pairs
``sensor_skew``            output    ``exp(-s tau)`` on one output's pairs only
``scale_factor``           output    constant dB offset on one output's pairs
``missing_derivative``     entry     the model's own sensitivity to a fixed or absent parameter
=========================  ========  =========================================================

Evidence (:func:`diagnose`). Residuals are whitened by the data's random error
(``sigma_dB = 20/ln10 eps``, ``sigma_deg = 180/pi eps``, eps floored at 0.02). The model's free
parameters may re-adjust, so the residual and every signature are projected off the span of the
model's own (whitened) log-response Jacobian first. A candidate's evidence is the drop of the
whitened sum of squares its best parameters give in that projected space, a chi-square-like
number in noise units. Nonlinear shapes are profiled on a grid (corner frequency; frequency and
damping with a linear amplitude). On clean data it is far above the 1 per parameter of white
noise (neighbouring frequency points are correlated, and the grids look in many places), so the
thresholds :data:`MIN_EVIDENCE` are measured, per kind, on clean logs: below them the loop says
"nothing to add".

Augmentation (:func:`augment_table`) edits the case's ``[state_space]`` table: new states,
parameters, input or output delays, as a user would write them (the result is a readable case).
Re-identification (:func:`run_residual_loop`) fits the top candidates in full and keeps the best
one only if the cost drops beyond noise (evidence of the refit >= threshold and J_ave down by
:data:`MIN_RELATIVE_COST_DROP`), the verification error (when a callback is given) drops, and the
new parameters meet the accuracy guidelines (CR% <= 20, I% <= 10). The loop repeats until nothing
significant remains or ``max_steps``.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.ident.accuracy import MAX_CRAMER_RAO_PCT, MAX_INSENSITIVITY_PCT
from livesweep.ident.state_space import StateSpaceFit, StateSpaceModel, fit_state_space
from livesweep.numbers import finite_or_none

__all__ = ["KINDS", "MIN_EVIDENCE", "MIN_RELATIVE_COST_DROP", "FIXABLE_PREFIXES",
           "FREQUENCY_PREFIXES", "CLEAR_EVIDENCE_FACTOR", "PairResidual", "Candidate", "LoopStep",
           "ResidualLoop", "pair_residuals", "diagnose", "augment_table", "run_residual_loop", "table_with_fit",
           "effect_text"]

KINDS = ("time_delay", "actuator_lag", "actuator_second_order", "notch_or_filter", "structural_mode",
         "sensor_skew", "scale_factor", "missing_derivative")
#: Evidence a candidate needs, per kind: about twice the largest value seen on 28 clean simulated
#: cruise logs (seeds 30-43, each at full and at half turbulence; no effect injected; nominal
#: model = the truth's structure; 100 points per pair). Largest seen: skew 24, lag 51, second-order
#: 43, missing derivative 116, structural mode 119, notch 161, scale factor 178. The flexible
#: resonant shapes and the scale factor (nearly a rescaling of a state, which the derivatives
#: absorb) pick up the most noise.
MIN_EVIDENCE = {
    "time_delay": 50.0, "sensor_skew": 50.0, "actuator_lag": 150.0, "actuator_second_order": 150.0,
    "missing_derivative": 250.0, "structural_mode": 250.0, "notch_or_filter": 350.0, "scale_factor": 400.0,
}
MIN_RELATIVE_COST_DROP = 0.10
N_OMEGA_LOOP = 100
VERIFICATION_BLOCK_S = 2.0
EPS_FLOOR = 0.02
_DB = 20.0 / math.log(10.0)
_DEG = 180.0 / math.pi
_ZETA_GRID = (0.03, 0.06, 0.1, 0.2, 0.4)
_ZETA_ACT_GRID = (0.3, 0.5, 0.7, 1.0)


# ------------------------------------------------------------------------------------------------
# residuals
# ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PairResidual:
    """One pair's residual at its fitting points.

    Attributes
    ----------
    output, input : str
    omega : ndarray
        [rad/s]
    magnitude_db, phase_deg : ndarray
        Data minus model [dB], [deg] (phase wrapped to (-180, 180]).
    sigma_db, sigma_deg : ndarray
        1-sigma random error of the data there [dB], [deg].
    """

    output: str
    input: str
    omega: np.ndarray
    magnitude_db: np.ndarray
    phase_deg: np.ndarray
    sigma_db: np.ndarray
    sigma_deg: np.ndarray

    @property
    def rms_noise_units(self) -> float:
        """RMS of the whitened residual (about 1 when the residual is noise)."""
        z = np.concatenate([self.magnitude_db / self.sigma_db, self.phase_deg / self.sigma_deg])
        return float(np.sqrt(np.mean(z**2)))

    def to_dict(self) -> dict:
        return {"output": self.output, "input": self.input, "rms_noise_units": round(self.rms_noise_units, 3),
                "omega": self.omega.round(5).tolist(), "magnitude_db": self.magnitude_db.round(4).tolist(),
                "phase_deg": self.phase_deg.round(3).tolist(), "sigma_db": self.sigma_db.round(4).tolist(),
                "sigma_deg": self.sigma_deg.round(3).tolist()}


def _sigma(frs, pair):
    resp = frs.pair(pair.output, pair.input)
    ok = np.isfinite(resp.random_error)
    eps = np.interp(np.log10(pair.omega), np.log10(resp.omega[ok]), resp.random_error[ok])
    eps = np.maximum(eps, EPS_FLOOR)
    return _DB * eps, _DEG * eps


def pair_residuals(model: StateSpaceModel, theta, pairs, frs) -> list[PairResidual]:
    """Data minus model for every fitted pair, with the data's random error.

    Parameters
    ----------
    model : StateSpaceModel
    theta : array_like
        Full parameter vector.
    pairs : list of PairData
        The fitted pairs (:func:`livesweep.ident.state_space.select_pairs`).
    frs : FrequencyResponseSet
        The responses the pairs came from (for the random error).
    """
    out = []
    for p in pairs:
        T = model.frequency_response(theta, p.omega)[model.outputs.index(p.output), model.inputs.index(p.input)]
        mag = p.magnitude_db - _DB * np.log(np.abs(T))
        ph = np.angle(np.exp(1j * np.deg2rad(p.phase_deg)) / T, deg=True)
        sdb, sdeg = _sigma(frs, p)
        out.append(PairResidual(p.output, p.input, p.omega, mag, ph, sdb, sdeg))
    return out


# ------------------------------------------------------------------------------------------------
# screening
# ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Candidate:
    """A ranked explanation of the residual.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    where : str
        Input or output name, or for ``missing_derivative`` the parameter (existing fixed one, or
        the new entry as ``"F[r][p]"``).
    parameters : dict
        Screening estimates in the units of the augmented model (s, rad/s, -, gain).
    evidence : float
        Whitened sum-of-squares drop (noise units), after the model's own parameters re-adjust.
    """

    kind: str
    where: str
    parameters: dict
    evidence: float

    def to_dict(self) -> dict:
        return {"kind": self.kind, "where": self.where, "evidence": round(float(self.evidence), 2),
                "parameters": {k: (round(float(v), 6) if isinstance(v, float) else v) for k, v in self.parameters.items()}}


class _Space:
    """Stacked, whitened residual space of the fitted pairs with the model's Jacobian projected out."""

    def __init__(self, model, theta, pairs, frs, residuals=None):
        self.pairs = pairs
        self.res = residuals if residuals is not None else pair_residuals(model, theta, pairs, frs)
        self.sig = np.concatenate([np.concatenate([r.sigma_db, r.sigma_deg]) for r in self.res])
        self.r = np.concatenate([np.concatenate([r.magnitude_db, r.phase_deg]) for r in self.res]) / self.sig
        self.model, self.theta = model, theta
        self.full = self.log_jacobian_all(model, theta)
        # free parameters that may re-adjust; a delay held at its bound 0 cannot go negative, so
        # it does not absorb a phase lead (it stays out of the projection)
        at_bound = {k for k in model.delay_parameter_indices() if theta[k] <= 1e-9}
        free = [k for k in np.flatnonzero(~np.asarray(model.fixed)) if k not in at_bound]
        D = self.full[:, free]
        if D.shape[1]:
            D = D / np.maximum(np.linalg.norm(D, axis=0), 1e-300)
            U, s, _ = np.linalg.svd(D, full_matrices=False)
            self.Q = U[:, s > 1e-9 * s[0]]
        else:
            self.Q = D
        self.pr = self.project(self.r)
        self.base = float(self.pr @ self.pr)

    def project(self, v):
        v = np.asarray(v, float)
        return v - self.Q @ (self.Q.T @ v) if self.Q.shape[1] else v

    def log_jacobian_all(self, model, theta):
        """Whitened d(dB, deg)/d theta of the model, shape (n_points, n_parameters)."""
        parts = []
        for p in self.pairs:
            T, dT = model._response(theta, p.omega, jacobian=True)
            i, j = model.outputs.index(p.output), model.inputs.index(p.input)
            g = dT[:, i, j] / T[i, j][None, :]                       # (P, f)
            parts.append(np.concatenate([_DB * g.real, _DEG * g.imag], axis=1))
        return np.concatenate(parts, axis=1).T / self.sig[:, None]

    def log_jacobian(self, model, theta, k):
        """Column ``k`` of :meth:`log_jacobian_all` (cached for the space's own model)."""
        if model is self.model:
            return self.full[:, k]
        return self.log_jacobian_all(model, theta)[:, k]

    def signature(self, factor_fn, select):
        """Whitened (dB, deg) of ``ln factor(omega)`` on the selected pairs, zero elsewhere.

        ``factor_fn(omega) -> complex log-factor`` (array); ``select(pair) -> bool``.
        """
        parts = []
        for p in self.pairs:
            n = p.omega.size
            if select(p):
                L = factor_fn(p.omega)
                parts.append(np.concatenate([_DB * L.real, _DEG * L.imag]))
            else:
                parts.append(np.zeros(2 * n))
        return np.concatenate(parts) / self.sig

    def linear(self, v):
        """Best amplitude and evidence of a signature linear in one parameter."""
        pv = self.project(v)
        den = float(pv @ pv)
        if den <= 1e-12 * max(1.0, float(v @ v)):
            return 0.0, 0.0
        a = float(pv @ self.pr) / den
        return a, a * a * den

    def shape(self, s):
        """Evidence of a fixed signature (no free amplitude)."""
        ps = self.project(s)
        return float(2 * ps @ self.pr - ps @ ps)

    def linear_grid(self, V):
        """Best amplitude and evidence per column of V (vectorised :meth:`linear`)."""
        PV = V - self.Q @ (self.Q.T @ V) if self.Q.shape[1] else V
        den = np.sum(PV**2, axis=0)
        num = PV.T @ self.pr
        with np.errstate(divide="ignore", invalid="ignore"):
            a = np.where(den > 1e-12, num / den, 0.0)
        return a, a * num


def _bandpass(omega, w, z):
    s = 1j * omega
    return 2 * z * w * s / (s**2 + 2 * z * w * s + w**2)


def _band_of(pairs):
    lo = min(p.omega[0] for p in pairs)
    hi = max(p.omega[-1] for p in pairs)
    return lo, hi


def _is_zero(entry) -> bool:
    try:
        return float(str(entry)) == 0.0
    except ValueError:
        return False


def _entry_params(entry, names) -> bool:
    import re
    return any(tok in names for tok in re.findall(r"[A-Za-z_][A-Za-z_0-9]*", str(entry)))


#: States the loop adds for effects (their equations are the effect's, not the vehicle's).
EFFECT_STATE_PREFIXES = ("act_", "actrate_", "notch_", "notchrate_", "mode_", "moderate_")


def _dynamic_rows(table, params) -> list[int]:
    """Vehicle state equations with at least one parameter (kinematic rows like phi' = p and the
    states of added effects are left alone)."""
    rows = []
    for i in range(len(table["states"])):
        if table["states"][i].startswith(EFFECT_STATE_PREFIXES):
            continue
        entries = list(table["F"][i]) + list(table["G"][i])
        if any(_entry_params(e, params) for e in entries):
            rows.append(i)
    return rows


def diagnose(table: dict, fit: StateSpaceFit, pairs, frs, *, kinds=KINDS, residuals=None) -> list[Candidate]:
    """Rank the catalogue's effects by how much of the residual each explains (module docstring).

    Parameters
    ----------
    table : dict
        The ``[state_space]`` table the fit's model was built from (:func:`table_with_fit`).
    fit : StateSpaceFit
    pairs : list of PairData
    frs : FrequencyResponseSet
    kinds : sequence of str
        Which kinds to consider.
    residuals : list of PairResidual, optional
        :func:`pair_residuals` of the fit when the caller has them already.

    Returns
    -------
    list of Candidate
        Best first; one per kind and location (its best grid point).
    """
    model, theta = fit.model, fit.theta
    sp = _Space(model, theta, pairs, frs, residuals)
    lo, hi = _band_of(pairs)
    out: list[Candidate] = []
    free_names = {n for n, f in zip(model.parameters, model.fixed) if not f}
    w_grid = np.geomspace(lo, hi, 48)

    for u in model.inputs:
        sel = (lambda p, u=u: p.input == u)
        a, ev = sp.linear(sp.signature(lambda w: -1j * w, sel))
        if "time_delay" in kinds and a > 0 and model.delays.get(u) not in free_names:
            out.append(Candidate("time_delay", u, {"tau_s": a}, ev))
        if "sensor_skew" in kinds and a < 0 and model.input_skews.get(u) not in free_names:
            # a phase lead on every pair of one input: its measurement is logged late
            out.append(Candidate("sensor_skew", u, {"tau_s": -a}, ev))
        if "actuator_lag" in kinds:
            grid = np.geomspace(lo / 2, 3 * hi, 60)
            evs = [sp.shape(sp.signature(lambda w, a=a: np.log(a / (1j * w + a)), sel)) for a in grid]
            k = int(np.argmax(evs))
            out.append(Candidate("actuator_lag", u, {"omega_rad_s": float(grid[k])}, evs[k]))
        if "actuator_second_order" in kinds:
            best = (-np.inf, None)
            for wn in np.geomspace(lo, 3 * hi, 40):
                for z in _ZETA_ACT_GRID:
                    ev = sp.shape(sp.signature(lambda w, wn=wn, z=z: np.log(wn**2 / ((1j * w) ** 2 + 2 * z * wn * 1j * w + wn**2)), sel))
                    if ev > best[0]:
                        best = (ev, {"omega_rad_s": float(wn), "zeta": z})
            out.append(Candidate("actuator_second_order", u, best[1], best[0]))
        if "notch_or_filter" in kinds:
            out.append(_resonance(sp, "notch_or_filter", u, sel, w_grid))

    for y in model.outputs:
        sel = (lambda p, y=y: p.output == y)
        if "sensor_skew" in kinds and model.output_delays.get(y) not in free_names:
            a, ev = sp.linear(sp.signature(lambda w: -1j * w, sel))
            if a > 0:
                out.append(Candidate("sensor_skew", y, {"tau_s": a}, ev))
        if "scale_factor" in kinds:
            a, ev = sp.linear(sp.signature(lambda w: np.ones_like(w, dtype=complex), sel))
            out.append(Candidate("scale_factor", y, {"factor": float(math.exp(a))}, ev))
        if "structural_mode" in kinds:
            out.append(_resonance(sp, "structural_mode", y, sel, w_grid))

    if "missing_derivative" in kinds:
        for name, k, target in _missing_derivative_slots(table, model):
            if k is not None:
                col = sp.log_jacobian(model, theta, k)
            else:
                aug, _ = _add_entry(table, target, name)
                m2 = StateSpaceModel.from_table(aug)
                th2 = np.array([theta[model.index(n)] if n in model.parameters else 0.0 for n in m2.parameters])
                col = sp.log_jacobian(m2, th2, m2.index(name))
            a, ev = sp.linear(col)
            cur = float(theta[k]) if k is not None else 0.0
            out.append(Candidate("missing_derivative", name if k is not None else target,
                                 {"name": name, "value": cur + a}, ev))
    out.sort(key=lambda c: -c.evidence)
    return out


def _resonance(sp, kind, where, sel, w_grid):
    V, params = [], []
    for w0 in w_grid:
        for z in _ZETA_GRID:
            V.append(sp.signature(lambda w, w0=w0, z=z: _bandpass(w, w0, z), sel))
            params.append((float(w0), z))
    a, ev = sp.linear_grid(np.column_stack(V))
    ev = np.where(a > -0.95, ev, -np.inf)            # 1 + g B must keep its sign
    k = int(np.argmax(ev))
    return Candidate(kind, where, {"omega_rad_s": params[k][0], "zeta": params[k][1], "gain": float(a[k])}, float(ev[k]))


def _missing_derivative_slots(table, model):
    """(parameter name, index or None, entry "F[i][j]") of fixed parameters and of absent entries
    in the dynamic rows of F and G."""
    params = set(table.get("parameters", {}))
    slots = []
    for n, f in zip(model.parameters, model.fixed):
        if f and not n.startswith(("tau", "skew")):
            slots.append((n, model.index(n), n))
    states, inputs = table["states"], table["inputs"]
    for i in _dynamic_rows(table, params):
        for key, cols in (("F", states), ("G", inputs)):
            for j, e in enumerate(table[key][i]):
                if _is_zero(e) and not (key == "F" and states[j].startswith(EFFECT_STATE_PREFIXES)):
                    name = _fresh(f"{key}_{states[i]}_{cols[j]}", params)
                    slots.append((name, None, f"{key}[{states[i]}][{cols[j]}]"))
    return slots


def _fresh(name, taken) -> str:
    base, k = name, 2
    while name in taken:
        name = f"{base}_{k}"
        k += 1
    return name


# ------------------------------------------------------------------------------------------------
# augmentation
# ------------------------------------------------------------------------------------------------

def table_with_fit(table: dict, fit: StateSpaceFit) -> dict:
    """A copy of ``table`` whose parameter values (and fixed flags) are the fit's."""
    t = copy.deepcopy(table)
    t["parameters"] = {n: {"value": float(v), **({"fixed": True} if f else {})}
                       for n, v, f in zip(fit.model.parameters, fit.theta, fit.model.fixed)}
    return t


def _add_state(t, names):
    """Append states (identity rows/columns of M, zero rows/columns elsewhere); return indices."""
    idx = []
    for name in names:
        n = len(t["states"])
        t["states"].append(_fresh(name, set(t["states"])))
        t["M"] = [row + ["0"] for row in t.get("M") or [["1" if a == b else "0" for b in range(n)] for a in range(n)]]
        t["M"].append(["0"] * n + ["1"])
        t["F"] = [row + ["0"] for row in t["F"]]
        t["F"].append(["0"] * (n + 1))
        t["G"].append(["0"] * len(t["inputs"]))
        t["H"] = [row + ["0"] for row in t["H"]]
        idx.append(n)
    return idx


def _param(t, name, value, taken=None):
    name = _fresh(name, set(t["parameters"]) | set(t.get("constants", {})) | set(taken or ()))
    t["parameters"][name] = {"value": float(value)}
    return name


def _mul(a, b) -> str:
    if _is_zero(a) or _is_zero(b):
        return "0"
    return f"({a})*({b})"


def _add_entry(table, target, name, value=0.0):
    """Put a new parameter into an absent entry ``"F[row][col]"`` / ``"G[row][col]"``."""
    t = copy.deepcopy(table)
    key, rest = target[0], target[2:-1]
    row, col = rest.split("][")
    i = t["states"].index(row)
    j = (t["states"] if key == "F" else t["inputs"]).index(col)
    t.setdefault("parameters", {})[name] = {"value": float(value)}
    t[key][i][j] = name
    return t, [name]


def augment_table(table: dict, candidate: Candidate) -> tuple[dict, list[str]]:
    """The ``[state_space]`` table with ``candidate``'s effect added.

    Returns
    -------
    table : dict
        A new table (the input is not modified).
    new_parameters : list of str
        Names of the parameters the effect added (or freed).
    """
    t = copy.deepcopy(table)
    t.setdefault("parameters", {})
    t.setdefault("J", [["0"] * len(t["inputs"]) for _ in t["outputs"]])
    t["J"] = [list(r) for r in t["J"]]
    for key in ("F", "G", "H"):
        t[key] = [list(r) for r in t[key]]
    if t.get("M"):
        t["M"] = [list(r) for r in t["M"]]
    t["states"] = list(t["states"])
    k, where, par = candidate.kind, candidate.where, candidate.parameters
    n0 = len(t["states"])
    if k == "time_delay":
        cur = (t.get("delays") or {}).get(where)
        start = par["tau_s"]
        if isinstance(cur, str) and cur in t["parameters"]:
            start += float(t["parameters"][cur].get("value", 0.0))
            t["parameters"][cur] = {"value": start}
            return t, [cur]
        if isinstance(cur, str) and cur in (t.get("constants") or {}):
            start += float(t["constants"][cur])
        elif isinstance(cur, (int, float)):
            start += float(cur)
        name = _param(t, f"tau_{where}", start)
        t.setdefault("delays", {})[where] = name
        return t, [name]
    if k == "sensor_skew" and where in t["inputs"]:
        name = _param(t, f"skew_{where}", par["tau_s"])
        t.setdefault("input_skews", {})[where] = name
        delay = (t.get("delays") or {}).get(where)
        if isinstance(delay, str) and delay in t["parameters"] and not t["parameters"][delay].get("fixed"):
            # only the net delay tau - skew is identifiable: a delay the fit held at 0 stays there
            if abs(float(t["parameters"][delay].get("value", 0.0))) <= 1e-6:
                t["parameters"][delay] = {"value": 0.0, "fixed": True}
        return t, [name]
    if k == "sensor_skew":
        cur = (t.get("output_delays") or {}).get(where)
        if isinstance(cur, str) and cur in t["parameters"]:
            t["parameters"][cur] = {"value": float(t["parameters"][cur].get("value", 0.0)) + par["tau_s"]}
            return t, [cur]
        name = _param(t, f"skew_{where}", par["tau_s"])
        t.setdefault("output_delays", {})[where] = name
        return t, [name]
    if k == "scale_factor":
        o = t["outputs"].index(where)
        name = _param(t, f"k_{where}", par["factor"])
        t["H"][o] = [_mul(name, e) for e in t["H"][o]]
        t["J"][o] = [_mul(name, e) for e in t["J"][o]]
        return t, [name]
    if k == "missing_derivative":
        name = par["name"]
        if name in t["parameters"]:
            t["parameters"][name] = {"value": float(par["value"])}
            return t, [name]
        return _add_entry(t, where, name, par["value"])
    if k in ("actuator_lag", "actuator_second_order", "notch_or_filter"):
        j = t["inputs"].index(where)
        if k == "actuator_lag":
            w = _param(t, f"w_act_{where}", par["omega_rad_s"])
            (a,) = _add_state(t, [f"act_{where}"])
            _route_input(t, j, a, n0)
            t["F"][a][a] = f"-{w}"
            t["G"][a][j] = w
            return t, [w]
        if k == "actuator_second_order":
            wn = _param(t, f"wn_act_{where}", par["omega_rad_s"])
            z = _param(t, f"zeta_act_{where}", par["zeta"])
            a, ad = _add_state(t, [f"act_{where}", f"actrate_{where}"])
            _route_input(t, j, a, n0)
            t["F"][a][ad] = "1"
            t["F"][ad][a] = f"-{wn}*{wn}"
            t["F"][ad][ad] = f"-2*{z}*{wn}"
            t["G"][ad][j] = f"{wn}*{wn}"
            return t, [wn, z]
        w = _param(t, f"w_notch_{where}", par["omega_rad_s"])
        z = _param(t, f"zeta_notch_{where}", par["zeta"])
        g = _param(t, f"g_notch_{where}", par["gain"])
        x, v = _add_state(t, [f"notch_{where}", f"notchrate_{where}"])
        gain = f"2*{g}*{z}*{w}"
        for i in range(n0):
            t["F"][i][v] = _mul(t["G"][i][j], gain)
        for o in range(len(t["outputs"])):
            t["H"][o][v] = _mul(t["J"][o][j], gain)
        t["F"][x][v] = "1"
        t["F"][v][x] = f"-{w}*{w}"
        t["F"][v][v] = f"-2*{z}*{w}"
        t["G"][v][j] = "1"
        return t, [w, z, g]
    if k == "structural_mode":
        o = t["outputs"].index(where)
        w = _param(t, f"w_mode_{where}", par["omega_rad_s"])
        z = _param(t, f"zeta_mode_{where}", par["zeta"])
        g = _param(t, f"g_mode_{where}", par["gain"])
        h_row, j_row = list(t["H"][o]), list(t["J"][o])
        x, v = _add_state(t, [f"mode_{where}", f"moderate_{where}"])
        for c, e in enumerate(h_row):
            t["F"][v][c] = e
        t["F"][x][v] = "1"
        t["F"][v][x] = f"-{w}*{w}"
        t["F"][v][v] = f"-2*{z}*{w}"
        t["G"][v] = j_row
        t["H"][o][v] = f"2*{g}*{z}*{w}"
        return t, [w, z, g]
    raise ConfigError(f"unknown effect kind {k!r}; known: {', '.join(KINDS)}")


def _route_input(t, j, a, n0):
    """Input ``j`` now reaches the rest of the model through state ``a`` (an actuator)."""
    for i in range(n0):
        t["F"][i][a] = t["G"][i][j]
        t["G"][i][j] = "0"
    for o in range(len(t["outputs"])):
        t["H"][o][a] = t["J"][o][j]
        t["J"][o][j] = "0"


# ------------------------------------------------------------------------------------------------
# the loop
# ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class LoopStep:
    """One step of the residual loop (DESIGN.md §4.3 ``residual_loop.steps``).

    Attributes
    ----------
    candidates : tuple of Candidate
        The ranking before this step (best first).
    tried : tuple of dict
        Each re-identified candidate: kind, where, cost_after, evidence_after, verification_after,
        parameters (name, value, CR%, I%), accepted, reason.
    effect : dict or None
        The accepted effect (kind, where, parameters), None when nothing was accepted.
    cost_before, cost_after : float
        J_ave before and after (after = before when nothing was accepted).
    verification_before, verification_after : dict or None
        ``{"j_rms", "tic": {output: value}}`` from the verification callback.
    residuals_before, residuals_after : tuple of PairResidual
    """

    candidates: tuple
    tried: tuple
    effect: dict | None
    cost_before: float
    cost_after: float
    verification_before: dict | None
    verification_after: dict | None
    residuals_before: tuple
    residuals_after: tuple

    def to_dict(self) -> dict:
        return {"effect": self.effect, "cost_before": round(self.cost_before, 4), "cost_after": round(self.cost_after, 4),
                "verification_before": self.verification_before, "verification_after": self.verification_after,
                "candidates": [c.to_dict() for c in self.candidates[:8]], "tried": list(self.tried)}


@dataclass(frozen=True)
class ResidualLoop:
    """Result of :func:`run_residual_loop`.

    Attributes
    ----------
    steps : tuple of LoopStep
        Accepted steps, then the final step that found nothing (or nothing acceptable).
    table : dict
        The final ``[state_space]`` table (with every accepted effect, values = final fit).
    fit : StateSpaceFit
        The final fit.
    unexplained : tuple of dict
        Pairs whose residual stays above noise (rms in noise units > 2) and candidates that had
        evidence but were rejected.
    conclusion : str
        One line: what was added, or "nothing to add: residual within noise".
    n_fits : int
        Re-identifications run.
    """

    steps: tuple
    table: dict
    fit: StateSpaceFit
    unexplained: tuple
    conclusion: str
    n_fits: int

    @property
    def added(self) -> tuple:
        """Every effect added, in order (the partners of a pair added together as their own entries)."""
        out = []
        for s in self.steps:
            if s.effect is not None:
                out.append({k: v for k, v in s.effect.items() if k != "with"})
                out += list(s.effect.get("with", ()))
        return tuple(out)

    def to_dict(self) -> dict:
        return {"steps": [s.to_dict() for s in self.steps], "unexplained": list(self.unexplained),
                "conclusion": self.conclusion, "re_identifications": self.n_fits}


def _param_report(fit, names):
    out = []
    for n in names:
        q = fit.parameter(n)
        out.append({"name": n, "value": float(q.value), "cramer_rao_pct": _finite(q.cramer_rao_pct),
                    "insensitivity_pct": _finite(q.insensitivity_pct), "fixed": bool(q.fixed)})
    return out


def _finite(x):
    return finite_or_none(x, 3)


def _whitened_ss(residuals) -> float:
    """Sum of squares of the whitened residual of every pair (noise units)."""
    return float(sum(np.sum((r.magnitude_db / r.sigma_db) ** 2) + np.sum((r.phase_deg / r.sigma_deg) ** 2)
                     for r in residuals))


def run_residual_loop(table: dict, fit: StateSpaceFit, frs, *, verify=None, max_steps: int = 3,
                      n_refit: int = 3, min_evidence: dict | None = None, n_omega: int = N_OMEGA_LOOP,
                      kinds=KINDS, progress=None) -> ResidualLoop:
    """Diagnose, augment, re-identify, repeat (see the module docstring).

    Parameters
    ----------
    table : dict
        ``[state_space]`` table of the fitted model.
    fit : StateSpaceFit
        The identified model (after structure reduction, if any).
    frs : FrequencyResponseSet
        The responses it was fitted to. The loop re-selects the same pairs at ``n_omega`` points
        (default 60, not the criterion's 20: a mode with zeta = 0.05 is 10 % of its frequency wide,
        20 points over two decades are 26 % apart) and refits the model there once as its baseline.
    verify : callable, optional
        ``verify(model, theta) -> Verification`` (or a list, one per record) on dissimilar
        manoeuvres (:func:`livesweep.ident.verify.verify`).
        A change is refused when it makes the verification error worse beyond noise (the mean
        change of the squared error, against its scatter over 2 s blocks); without a callback only
        the frequency-domain tests decide.
    max_steps : int
        Effects added at most.
    n_refit : int
        Candidates re-identified in full per step (best evidence first).
    min_evidence : dict, optional
        Noise threshold on the evidence per kind (default :data:`MIN_EVIDENCE`).
    n_omega : int
        Fitting points per pair inside the loop.
    kinds : sequence of str
        Catalogue entries to consider (default all of :data:`KINDS`).
    progress : callable, optional
        ``progress(str)`` for long steps.
    """
    from livesweep.ident.state_space import select_pairs

    min_evidence = {**MIN_EVIDENCE, **(min_evidence or {})}
    pairs, _ = select_pairs(frs, fit.model, n_omega=n_omega)
    if not pairs:
        raise ConfigError("residual loop: no pair of the model has usable coherence")
    fit = fit_state_space(fit.model.with_values(fit.theta), pairs)
    table = table_with_fit(table, fit)
    steps, unexplained, n_fits = [], [], 1
    ver = verify(fit.model, fit.theta) if verify else None
    before = tuple(pair_residuals(fit.model, fit.theta, pairs, frs))
    for _ in range(max_steps + 1):
        ss_before = _whitened_ss(before)
        cands = diagnose(table, fit, pairs, frs, kinds=kinds, residuals=before)
        strong = [c for c in cands if c.evidence >= min_evidence[c.kind]]
        tried, best, accepted = [], None, []
        if len(steps) < max_steps:
            seen = set()
            for c in strong:
                if len(tried) >= n_refit:
                    break
                if (c.kind, c.where) in seen:
                    continue
                seen.add((c.kind, c.where))
                if progress:
                    progress(f"residual loop: re-identifying with {c.kind} at {c.where} (evidence {c.evidence:.0f})")
                rec, new = _try(table, c, fit, pairs, frs, verify, ss_before, ver, min_evidence)
                n_fits += 1
                tried.append(rec)
                if rec["accepted"]:
                    accepted.append((rec, new))
            best = _choose(accepted, min_evidence)
            leader = max(tried, key=lambda t: t.get("evidence_after", -np.inf), default=None)
            if leader is not None and not leader["accepted"] and len(steps) + 2 <= max_steps:
                # the best explanation fails alone: two effects may overlap (a mode and an actuator
                # lag); try the strongest candidates in pairs at different places, each pair judged
                # as one effect, and keep a pair only if it explains more than the best single one
                # by more than the noise threshold of its second effect
                duo = _pair_search(strong, table, fit, pairs, frs, verify, ss_before, ver, min_evidence, progress)
                n_fits += len(duo)
                tried += [rec for rec, _ in duo]
                ok = [d for d in duo if d[0]["accepted"]]
                pick = _choose(ok, min_evidence)
                if pick is not None and (best is None or pick[0]["evidence_after"] >= best[0]["evidence_after"]
                                         + min(min_evidence[w["kind"]] for w in pick[0]["with"])):
                    best = pick
            # An accepted candidate that explains less than half of what the best-explaining one
            # does (even if that one failed a guideline) is a partial explanation, not the effect.
            top = max((t.get("evidence_after", -np.inf) for t in tried), default=-np.inf)
            if best is not None and best[0]["evidence_after"] < 0.5 * top:
                best[0]["accepted"] = False
                best[0]["reason"] = (f"explains {best[0]['evidence_after']:.0f}, less than half of the best candidate's "
                                     f"{top:.0f}: a partial explanation")
                best = None
        if best is None:
            steps.append(LoopStep(tuple(cands), tuple(tried), None, fit.cost_average, fit.cost_average,
                                  _ver_summary(ver), _ver_summary(ver), before, before))
            unexplained += [{"kind": t["kind"], "where": t["where"], "reason": t["reason"]} for t in tried]
            break
        rec, (table, fit, ver_after, after) = best
        effect = {"kind": rec["kind"], "where": rec["where"], "parameters": rec["parameters"]}
        if rec.get("ambiguous_with"):
            effect["ambiguous_with"] = rec["ambiguous_with"]
        if rec.get("with"):
            effect["with"] = rec["with"]
        steps.append(LoopStep(tuple(cands), tuple(tried), effect, rec["cost_before"], rec["cost_after"],
                              _ver_summary(ver), _ver_summary(ver_after), before, after))
        ver, before = ver_after, after
    for r in before:                                  # the final fit's residual
        if r.rms_noise_units > 2.0:
            unexplained.append({"pair": f"{r.output}/{r.input}", "rms_noise_units": round(r.rms_noise_units, 2)})
    added = [e for s in steps if s.effect is not None for e in (s.effect, *s.effect.get("with", ()))]
    if added:
        conclusion = "added " + "; ".join(
            f"{e['kind']} at {e['where']}" + "".join(f" (hard to tell from {a['kind']} at {a['where']} in this band)"
                                                      for a in e.get("ambiguous_with", ()))
            for e in added)
    elif steps and any(c.evidence >= min_evidence[c.kind] for c in steps[-1].candidates):
        conclusion = "residual above noise, but no candidate effect passed the acceptance tests"
    else:
        conclusion = "nothing to add: residual within noise"
    return ResidualLoop(tuple(steps), table, fit, tuple(unexplained), conclusion, n_fits)


def effect_text(effect: dict) -> str:
    """One line for an added effect: ``"structural_mode at p: w_mode_p = 12.01 (CR 0.9 %), zeta_mode_p
    = 0.05158 (fixed: poorly determined), ..."``, and the effects it could not be told from."""
    def par(p):
        if p.get("fixed"):
            return f"{p['name']} = {p['value']:.4g} (fixed: poorly determined)"
        return f"{p['name']} = {p['value']:.4g} (CR {p['cramer_rao_pct']} %)"
    text = f"{effect['kind']} at {effect['where']}: " + ", ".join(par(p) for p in effect["parameters"])
    for w in effect.get("with", ()):
        text += f"; together with {w['kind']} at {w['where']}: " + ", ".join(par(p) for p in w["parameters"])
    for a in effect.get("ambiguous_with", ()):
        text += f"; hard to tell from {a['kind']} at {a['where']} in this band"
    return text


#: Candidates (best evidence first, distinct kind and place) combined in pairs when the best one
#: fails alone.
N_PAIR = 4


def _pair_search(strong, table, fit, pairs, frs, verify, ss_before, ver, min_evidence, progress):
    """Re-identify the pairs of the :data:`N_PAIR` strongest distinct candidates at different places."""
    top, seen = [], set()
    for c in strong:
        if (c.kind, c.where) not in seen and len(top) < N_PAIR:
            seen.add((c.kind, c.where))
            top.append(c)
    out = []
    for i, a in enumerate(top):
        for b in top[i + 1:]:
            if a.where == b.where:
                continue
            if progress:
                progress(f"residual loop: re-identifying with {a.kind} at {a.where} and {b.kind} at {b.where}")
            rec, new = _try(table, [a, b], fit, pairs, frs, verify, ss_before, ver, min_evidence)
            out.append((rec, new))
    return out


def _choose(accepted, min_evidence):
    """The effect to add among the accepted ``(record, result)``: the lowest cost, unless a simpler
    one (fewer new parameters, fixed ones included) explains nearly as much, i.e. the whitened
    residual of the better one is lower by less than the noise threshold of its kind (what an
    effect of that kind picks up from noise alone on clean data): then the simpler one, as
    CIFER practice prefers the simplest structure the data support (a delay before a second-order
    actuator, a first-order before a second-order one). Candidates within that margin of the
    chosen one are listed in its record's ``ambiguous_with``: hard to tell apart in this band."""
    if not accepted:
        return None
    def size(a):
        return len(a[0]["parameters"]) + sum(len(w["parameters"]) for w in a[0].get("with", ()))
    best = min(accepted, key=lambda a: a[0]["cost_after"])
    margin = min_evidence[best[0]["kind"]]
    near = [a for a in accepted if a[0]["evidence_after"] >= best[0]["evidence_after"] - margin]
    chosen = min(near, key=lambda a: (size(a), -a[0]["evidence_after"]))
    rec = chosen[0]
    rec["ambiguous_with"] = [
        {"kind": a[0]["kind"], "where": a[0]["where"], "evidence_after": a[0]["evidence_after"],
         "cost_after": a[0]["cost_after"], "parameters": a[0]["parameters"]}
        for a in near if a is not chosen
        and a[0]["evidence_after"] >= rec["evidence_after"] - min_evidence[a[0]["kind"]]]
    if chosen is not best:
        rec["reason"] += (f"; preferred to {best[0]['kind']} at {best[0]['where']} (whitened residual lower by only "
                          f"{best[0]['evidence_after'] - rec['evidence_after']:.0f} < {margin:g}, with "
                          f"{size(best) - size(chosen)} more parameter(s))")
    return chosen


def _as_list(v):
    return list(v) if isinstance(v, (list, tuple)) else [v]


def _ver_summary(v):
    """``{"j_rms", "tic": {output: value}, "passed"}`` (records pooled: J_rms over all samples, the
    worst TIC per output), or None."""
    if v is None:
        return None
    vs = _as_list(v)
    n = [float(np.sum(np.isfinite(x.measured - x.predicted))) for x in vs]
    j = math.sqrt(sum(x.j_rms ** 2 * k for x, k in zip(vs, n)) / max(sum(n), 1.0))
    tic = {}
    for x in vs:
        for o in x.outputs:
            tic[o.name] = max(tic.get(o.name, 0.0), float(o.tic))
    return {"j_rms": _finite(j), "tic": {k: _finite(t) for k, t in tic.items()}, "passed": all(x.passed for x in vs)}


def _verification_change(before, after):
    """Paired comparison of two models on the same verification records.

    ``d(t) = sum_o (r_after,o(t)^2 - r_before,o(t)^2)``; its mean against the scatter of its means
    over :data:`VERIFICATION_BLOCK_S` blocks (turbulence makes neighbouring samples correlated).
    Verdict ``improved`` / ``worse`` beyond 2 sigma, else ``unchanged``.
    """
    if before is None or after is None:
        return None
    ds, means = [], []
    for b, a in zip(_as_list(before), _as_list(after)):
        ra, rb = a.measured - a.predicted, b.measured - b.predicted
        ok = np.all(np.isfinite(ra) & np.isfinite(rb), axis=0)
        d = np.sum(ra[:, ok] ** 2 - rb[:, ok] ** 2, axis=0)
        dt = float(np.median(np.diff(b.t_s))) if b.t_s.size > 1 else 1.0
        n_block = max(1, int(round(VERIFICATION_BLOCK_S / dt)))
        n_b = d.size // n_block
        means.extend(d[:n_b * n_block].reshape(n_b, n_block).mean(axis=1).tolist())
        ds.append(d)
    d = np.concatenate(ds) if ds else np.zeros(0)
    noise = float(np.std(means, ddof=1) / math.sqrt(len(means))) if len(means) >= 3 else float("inf")
    mean = float(d.mean()) if d.size else 0.0
    sb, sa = _ver_summary(before), _ver_summary(after)
    if sa["j_rms"] is None or not np.isfinite(mean):
        # the new model diverges open loop (or predicts nothing): worse, whatever the noise
        return {"j_rms_before": sb["j_rms"], "j_rms_after": sa["j_rms"], "mean_change": None, "noise": None,
                "verdict": "worse" if sb["j_rms"] is not None else "unchanged"}
    verdict = "improved" if mean < -2 * noise else ("worse" if mean > 2 * noise else "unchanged")
    return {"j_rms_before": sb["j_rms"], "j_rms_after": sa["j_rms"], "mean_change": mean, "noise": noise,
            "verdict": verdict}


def _guideline_failures(params) -> list[str]:
    """The accuracy guidelines (CR% <= 20, I% <= 10) each free new parameter fails, as reasons."""
    out = []
    for p in params:
        if p.get("fixed"):
            continue
        if p["cramer_rao_pct"] is None or p["cramer_rao_pct"] > MAX_CRAMER_RAO_PCT:
            out.append(f"{p['name']} CR% {p['cramer_rao_pct']} > {MAX_CRAMER_RAO_PCT:g}")
        if p["insensitivity_pct"] is None or p["insensitivity_pct"] > MAX_INSENSITIVITY_PCT:
            out.append(f"{p['name']} I% {p['insensitivity_pct']} > {MAX_INSENSITIVITY_PCT:g}")
    return out


#: An effect whose parameter is fixed must be clearly there: its whitened residual drop at least
#: this many times its kind's noise threshold (20 times the largest drop seen on clean cruise logs;
#: a sharp mode with a poorly determined damping drops it 60 times the threshold, a notch fitted
#: to clean hover noise 1.7 times). At most one parameter is fixed per effect.
CLEAR_EVIDENCE_FACTOR = 10.0
#: Parameters of an effect that may be fixed at their fitted value when poorly determined: the
#: shape parameters (a damping, a notch's depth or a mode's gain), never the frequency or the delay
#: that places the effect (a frequency that is not determined means the effect is not there).
FIXABLE_PREFIXES = ("zeta_", "g_")
#: Parameters that place an effect in frequency [rad/s]: fixing another of its parameters needs
#: this one inside the fitted band (a "notch" at 25 rad/s fitted to 0.3-20 rad/s data is a lag in
#: disguise, not a notch whose depth the data could not pin down).
FREQUENCY_PREFIXES = ("w_", "wn_")


def _worst(params):
    """The fixable free parameter that misses the guidelines by most (relative to its limit), or
    None (also when a parameter that places the effect misses them: then nothing is fixed)."""
    def excess(p):
        cr, ins = p["cramer_rao_pct"], p["insensitivity_pct"]
        return max(math.inf if cr is None else cr / MAX_CRAMER_RAO_PCT,
                   math.inf if ins is None else ins / MAX_INSENSITIVITY_PCT)
    bad = [p for p in params if not p.get("fixed") and excess(p) > 1.0]
    if not bad or not all(p["name"].startswith(FIXABLE_PREFIXES) for p in bad):
        return None
    return max(bad, key=excess)


def _try(table, cand, fit, pairs, frs, verify, ss_before, ver_before, min_evidence):
    """Re-identify with ``cand`` (a Candidate, or several added together) added and judge it;
    returns (record, (table, fit, verification, residuals)) with the record's ``accepted`` and
    ``reason``. Several candidates are judged as one effect whose noise threshold is the sum of
    theirs; the record's ``with`` lists the others (kind, where, their parameters).

    When the effect's shape is supported (the fit converges, the whitened residual and J_ave fall
    beyond noise, verification is not worse) but one of its parameters misses the accuracy
    guidelines (a sharp mode's damping, a notch's depth), the structure-reduction step of the
    method is taken inside the effect: that parameter (one, a shape parameter: a damping or a
    gain) is fixed at its fitted value and the rest refitted, when the effect is clearly there
    (:data:`CLEAR_EVIDENCE_FACTOR`) and another of its parameters stays free. The record
    says which were fixed (``fixed``: name, value and why) and the effect is accepted with them.
    """
    cands = list(cand) if isinstance(cand, (list, tuple)) else [cand]
    cand = cands[0]
    threshold = sum(min_evidence[c.kind] for c in cands)
    rec = {"kind": cand.kind, "where": cand.where, "evidence": round(float(sum(c.evidence for c in cands)), 2),
           "cost_before": float(fit.cost_average), "fixed": []}
    try:
        aug, new, own = table, [], []
        for c in cands:
            aug, names = augment_table(aug, c)
            new += names
            own.append(names)
        model = StateSpaceModel.from_table(aug)
        new_fit = fit_state_space(model, pairs, max_nfev=100)
    except (ConfigError, np.linalg.LinAlgError, ValueError) as exc:
        rec.update(accepted=False, reason=f"could not re-identify: {exc}", cost_after=float("nan"), parameters=[])
        return rec, None
    while True:
        res_after = tuple(pair_residuals(new_fit.model, new_fit.theta, pairs, frs))
        ss_after = _whitened_ss(res_after)
        params = _param_report(new_fit, new)
        ver_after = verify(new_fit.model, new_fit.theta) if verify else None
        change = _verification_change(ver_before, ver_after)
        shape = []                                    # the effect's shape, whatever its parameters' accuracy
        if not new_fit.converged:
            shape.append("fit did not converge")
        if ss_before - ss_after < threshold:
            shape.append(f"whitened residual fell by {ss_before - ss_after:.1f} < {threshold:g} (noise)")
        if new_fit.cost_average > (1 - MIN_RELATIVE_COST_DROP) * fit.cost_average:
            shape.append(f"J_ave {fit.cost_average:.2f} -> {new_fit.cost_average:.2f} "
                         f"(< {100 * MIN_RELATIVE_COST_DROP:.0f} % drop)")
        if change is not None and change["verdict"] == "worse":
            if change["mean_change"] is None:
                shape.append(f"verification: the model diverges open loop (J_rms {change['j_rms_before']} -> not finite)")
            else:
                shape.append(f"verification J_rms {change['j_rms_before']:.4g} -> {change['j_rms_after']:.4g}: worse "
                             f"beyond noise (mean squared-error change {change['mean_change']:.3g} > 2 x "
                             f"{change['noise']:.3g})")
        accuracy = _guideline_failures(params)
        worst = _worst(params)
        n_free = sum(not p.get("fixed") for p in params)
        lo, hi = _band_of(pairs)
        outside = any(p["name"].startswith(FREQUENCY_PREFIXES) and not lo <= p["value"] <= hi for p in params)
        if (shape or not accuracy or worst is None or n_free <= 1 or rec["fixed"] or outside
                or ss_before - ss_after < CLEAR_EVIDENCE_FACTOR * threshold):
            break
        # the shape is there; one parameter is poorly determined: fix it where it is, refit the rest
        try:
            refit = fit_state_space(new_fit.model.with_values(new_fit.theta, fixed={worst["name"]: worst["value"]}),
                                    pairs, max_nfev=100)
        except (ConfigError, np.linalg.LinAlgError, ValueError):
            break
        why = (f"CR% {worst['cramer_rao_pct']}, I% {worst['insensitivity_pct']}: poorly determined, "
               f"fixed at its fitted value")
        rec["fixed"].append({"name": worst["name"], "value": float(worst["value"]),
                             "cramer_rao_pct": worst["cramer_rao_pct"], "insensitivity_pct": worst["insensitivity_pct"],
                             "reason": why})
        new_fit = refit
    by_name = {p["name"]: p for p in params}
    rec.update(cost_after=float(new_fit.cost_average), evidence_after=round(ss_before - ss_after, 2),
               parameters=[by_name[n] for n in own[0]], verification_after=_ver_summary(ver_after),
               verification_change=change)
    if len(cands) > 1:
        rec["with"] = [{"kind": c.kind, "where": c.where, "parameters": [by_name[n] for n in names]}
                       for c, names in zip(cands[1:], own[1:])]
    reasons = shape + accuracy
    rec["accepted"] = not reasons
    rec["reason"] = "; ".join(reasons) if reasons else (
        "accepted" + "".join(f"; {f['name']} fixed at {f['value']:.4g} ({f['reason'].split(':')[0]})"
                             for f in rec["fixed"]))
    return rec, (table_with_fit(aug, new_fit), new_fit, ver_after, res_after)
