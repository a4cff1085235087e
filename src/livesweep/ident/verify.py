"""Time-domain verification of an identified state-space model (CIFER's VERIFY, docs/method.md §9).

The model (docs/method.md §8.1, one delay per input)::

    M x' = F x + G u(t - tau) + b          b: constant biases, one per state equation
    y    = H x + J u(t - tau) + y_ref      y_ref: reference shifts, one per output

is driven open loop with the *measured* inputs of manoeuvres dissimilar to the identification
sweeps (doublets, 3-2-1-1s, steps). No identified parameter is changed; only ``b`` and ``y_ref``
(and, optionally, the initial state) are fitted.

Method
------
The model is linear in ``b``, ``y_ref`` and the initial state ``x0``, so::

    y_model(t) = y_u(t) + sum_j S_j(t) b_j + y_ref [+ sum_i X_i(t) x0_i]

* ``y_u``: response to the measured, delayed inputs from ``x(0) = 0`` (trim);
* ``S_j``: response to a unit constant bias in state equation ``j`` (from ``x(0) = 0``);
* ``X_i``: free response from a unit initial state ``x0 = e_i`` (only with ``x0="least_squares"``).

One stacked linear least-squares problem over every valid sample of every output, each output
weighted by ``W = diag(weights)``, gives ``[b; y_ref (; x0)]``. Regressor columns are scaled to
unit weighted norm before ``numpy.linalg.lstsq`` (minimum-norm solution, relative ``rcond``
1e-10); the numerical rank is reported in the notes when it is deficient.

Simulation is exact for inputs that are piecewise linear between samples: ``M`` is removed by
linear solves (``A = M^-1 F``, ``B = M^-1 G``, never an explicit inverse) and the continuous
system is discretised with the matrix exponential and a first-order hold of the inputs (constant
biases are exact under any hold). Delays are fractional sample shifts by linear interpolation on
the data grid, the first sample held before the record starts (records start in trim). These
are the simulator's own conventions (``livesweep.sim.engine``): magnitude error at most about
``(w dt)^2 / 8`` for the shift and ``(w dt)^2 / 12`` for the hold.

Metrics (docs/method.md §9), over the valid samples, ``r = y_data - y_model``::

    J_rms = sqrt( sum_o w_o sum_t r_o(t)^2 / sum_o n_t,o )       (= sqrt(1/(n_t n_o) sum r' W r))
    TIC_o = rms(r_o) / ( rms(y_data,o - y_ref,o) + rms(y_model,o - y_ref,o) )

TIC is computed on the perturbations about the fitted reference shift (the model's ``y`` is a
perturbation from trim); for data already in perturbation form this is the textbook formula, and
it keeps a channel's trim value (e.g. a sensor offset) from flattering its TIC.

Guidelines used for ``passed`` (docs/method.md §9: "J_rms <~ 1.0-2.0", "TIC <= 0.25-0.3"): livesweep
takes the permissive end of the J_rms band, ``J_rms <= 2.0``, and the strict end of the TIC band,
``TIC <= 0.25`` for every output. Both limits are keyword arguments of :func:`verify`.

Identifiability of biases versus initial state: with ``A`` nonsingular a constant bias ``b``
produces exactly the free response from ``x0 = A^-1 M^-1 b`` plus the constant ``-H A^-1 M^-1 b``,
so biases plus reference shifts already act as an estimate of the initial state (when ``(H, A)``
is observable). ``x0="zero"`` (default) is therefore well posed; ``x0="least_squares"`` adds the
initial state explicitly, which only adds information along directions where ``A`` is singular
(pure integrators) and otherwise makes ``b``, ``y_ref`` and ``x0`` non-unique (the fit, the TIC and
J_rms stay unique; the minimum-norm split is reported and a note says so).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np

from livesweep.errors import ConfigError
from livesweep.lti import discretize_foh
from livesweep.numeric import finite_or_none as _num

__all__ = ["J_RMS_MAX", "TIC_MAX", "OutputFit", "Verification", "verify", "simulate_response"]

#: Guideline: J_rms at or below this passes (docs/method.md §9, upper end of "<~ 1.0-2.0").
J_RMS_MAX = 2.0
#: Guideline: every output's TIC at or below this passes (docs/method.md §9, lower end of "0.25-0.3").
TIC_MAX = 0.25

_RCOND = 1e-10
_COND_MAX = 1e12


@dataclass(frozen=True)
class OutputFit:
    """Verification result for one output channel.

    Attributes
    ----------
    name : str
        Output name.
    units : str
        Output units (e.g. ``"deg/s"``, ``"ft/s^2"``, ``"deg"``); ``""`` when not given.
    tic : float
        Theil inequality coefficient, in [0, 1] (0 = perfect); NaN with no valid sample.
    rms : float
        RMS of the residual ``y_data - y_model`` over the valid samples [output units].
    reference_shift : float
        Fitted ``y_ref`` of this output [output units].
    weight : float
        Weight ``w_o`` of this output in J_rms and in the fit [1/(output units)^2].
    n_samples : int
        Valid samples used.
    passed : bool
        ``tic <= tic_max``.
    """

    name: str
    units: str
    tic: float
    rms: float
    reference_shift: float
    weight: float
    n_samples: int
    passed: bool


@dataclass(frozen=True, eq=False)
class Verification:
    """A model driven open loop with measured inputs, compared with the measured outputs.

    Attributes
    ----------
    outputs : tuple of OutputFit
        Per output, in the order of the rows of ``H``.
    j_rms : float
        Weighted RMS cost (dimensionless with unit weights and signals in deg, deg/s, ft/s,
        ft/s^2); ``inf`` when the simulation overflowed.
    t_s : ndarray, shape (N,)
        Sample times [s].
    measured : ndarray, shape (n_out, N)
        Measured outputs as given (NaN where not valid) [output units].
    predicted : ndarray, shape (n_out, N)
        Model outputs including the fitted biases, reference shifts (and initial state).
    inputs : ndarray, shape (m, N)
        Measured inputs as given (before the delays) [input units].
    biases : ndarray, shape (n_states,)
        Fitted constant ``b`` in ``M x' = F x + G u + b`` [state-equation units, e.g. rad/s^2].
    reference_shifts : ndarray, shape (n_out,)
        Fitted ``y_ref`` [output units].
    initial_state : ndarray, shape (n_states,)
        Initial state used (zeros unless ``x0="least_squares"``) [state units].
    weights : ndarray, shape (n_out,)
        Output weights (diagonal of W).
    passed : bool
        ``j_rms <= j_rms_max`` and every output's ``tic <= tic_max``.
    guidelines : dict
        ``{"j_rms_max", "tic_max", "source"}``.
    rank : int
        Numerical rank of the least-squares problem; ``n_unknowns`` when all are determined.
    n_unknowns : int
        Number of fitted constants.
    notes : tuple of str
        Anything the caller should know (excluded samples, rank deficiency, instability).
    """

    outputs: tuple[OutputFit, ...]
    j_rms: float
    t_s: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    inputs: np.ndarray
    biases: np.ndarray
    reference_shifts: np.ndarray
    initial_state: np.ndarray
    weights: np.ndarray
    passed: bool
    guidelines: dict = field(default_factory=dict)
    rank: int = 0
    n_unknowns: int = 0
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("t_s", "measured", "predicted", "inputs", "biases", "reference_shifts",
                     "initial_state", "weights"):
            arr = np.array(getattr(self, name), dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "outputs", tuple(self.outputs))
        object.__setattr__(self, "notes", tuple(self.notes))
        object.__setattr__(self, "guidelines", dict(self.guidelines))

    @property
    def output_names(self) -> tuple[str, ...]:
        """Output names in row order."""
        return tuple(o.name for o in self.outputs)

    def output(self, name: str) -> OutputFit:
        """The :class:`OutputFit` of output ``name`` (ConfigError listing the outputs otherwise)."""
        for o in self.outputs:
            if o.name == name:
                return o
        raise ConfigError(f"no output {name!r} in this verification; outputs are {', '.join(self.output_names)}")

    def to_dict(self) -> dict:
        """The ``verification`` entry of ``report.json`` (docs/outputs.md, report.json), JSON-ready.

        Returns
        -------
        dict
            ``{outputs: [{name, units, tic, rms, reference_shift, weight, n_samples, passed}],
            j_rms, passed, guidelines, biases, initial_state, rank, n_unknowns, notes}``;
            non-finite numbers become ``None``.
        """
        return {
            "outputs": [{"name": o.name, "units": o.units, "tic": _num(o.tic), "rms": _num(o.rms),
                         "reference_shift": _num(o.reference_shift), "weight": _num(o.weight),
                         "n_samples": int(o.n_samples), "passed": bool(o.passed)} for o in self.outputs],
            "j_rms": _num(self.j_rms),
            "passed": bool(self.passed),
            "guidelines": dict(self.guidelines),
            "biases": [_num(b) for b in self.biases],
            "initial_state": [_num(x) for x in self.initial_state],
            "rank": int(self.rank),
            "n_unknowns": int(self.n_unknowns),
            "notes": list(self.notes),
        }


# --------------------------------------------------------------------------------------------
# simulation
# --------------------------------------------------------------------------------------------


def _matrix(a, shape, what) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim == 1 and shape[1] == 0 and arr.size == 0:
        arr = arr.reshape(shape)
    if arr.shape != shape:
        raise ConfigError(f"verify: {what} has shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"verify: {what} has non-finite entries")
    return arr


def _state_matrices(M, F, G):
    """``A = M^-1 F``, ``B = M^-1 G``, ``E = M^-1`` by one LU solve; ConfigError for singular M."""
    n = F.shape[0]
    if n == 0:
        raise ConfigError("verify: the model has no states")
    s = np.linalg.svd(M, compute_uv=False)
    if s[-1] <= 0 or s[0] / s[-1] > _COND_MAX:
        cond = np.inf if s[-1] <= 0 else s[0] / s[-1]
        raise ConfigError(f"verify: M is singular (condition number {cond:.3g}); "
                          "the state equation M x' = F x + G u cannot be solved for x'")
    sol = np.linalg.solve(M, np.hstack([F, G, np.eye(n)]))
    return sol[:, :n], sol[:, n:n + G.shape[1]], sol[:, n + G.shape[1]:]


def _discretize_foh(A, B, dt):
    """``x[k+1] = Phi x[k] + Gamma0 w[k] + Gamma1 w[k+1]`` for ``w`` linear between samples (exact)."""
    return discretize_foh(A, B, dt)


def _delayed(u: np.ndarray, tau_s: np.ndarray, dt: float) -> np.ndarray:
    """Rows of ``u`` (m, N) delayed by ``tau_s`` (fractional samples, linear interpolation, first value held)."""
    N = u.shape[1]
    k = np.arange(N, dtype=float)
    return np.vstack([np.interp(k - tau / dt, k, row) for row, tau in zip(u, tau_s)]) if u.shape[0] else u.copy()


def simulate_response(M, F, G, H, J, tau_s, dt: float, u, *, bias=None, x0=None) -> np.ndarray:
    """Open-loop response of ``M x' = F x + G u(t - tau) + bias``, ``y = H x + J u(t - tau)``.

    Exact for inputs linear between samples (first-order hold through the matrix exponential);
    delays are fractional sample shifts by linear interpolation (first sample held before the
    start).

    Parameters
    ----------
    M, F : ndarray, shape (n, n)
    G : ndarray, shape (n, m)
    H : ndarray, shape (p, n)
    J : ndarray, shape (p, m)
    tau_s : array_like, shape (m,)
        Input delays [s], >= 0.
    dt : float
        Sample interval [s].
    u : ndarray, shape (m, N)
        Inputs on the grid ``k dt`` [input units].
    bias : array_like, shape (n,), optional
        Constant bias in each state equation (zero by default).
    x0 : array_like, shape (n,), optional
        Initial state (zero by default).

    Returns
    -------
    ndarray, shape (p, N)
        Outputs [output units].
    """
    F = np.asarray(F, float)
    n = F.shape[0]
    u = np.atleast_2d(np.asarray(u, float))
    m, N = u.shape
    M, G, H, J = (_matrix(M, (n, n), "M"), _matrix(G, (n, m), "G"), _matrix(H, (np.shape(H)[0], n), "H"),
                  _matrix(J, (np.shape(H)[0], m), "J"))
    tau = _delays(tau_s, m)
    A, B, E = _state_matrices(M, F, G)
    Phi, G0, G1 = _discretize_foh(A, np.hstack([B, E]), float(dt))
    ud = _delayed(u, tau, float(dt))
    b = np.zeros(n) if bias is None else np.asarray(bias, float).reshape(n)
    w = np.vstack([ud, np.repeat(b[:, None], N, axis=1)])
    drive = (G0 @ w[:, :-1] + G1 @ w[:, 1:])
    X = np.empty((n, N))
    X[:, 0] = 0.0 if x0 is None else np.asarray(x0, float).reshape(n)
    _recurse(Phi, X, drive)
    return H @ X + J @ ud


def _recurse(Phi: np.ndarray, X: np.ndarray, drive: np.ndarray) -> None:
    """In place: ``X[..., k+1] = Phi X[..., k] + drive[..., k]`` (X is (n, N) or (n, K, N))."""
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(X.shape[-1] - 1):
            X[..., k + 1] = Phi @ X[..., k] + drive[..., k]


def _delays(tau_s, m: int) -> np.ndarray:
    tau = np.atleast_1d(np.asarray(tau_s, dtype=float)).ravel()
    if tau.size != m:
        raise ConfigError(f"verify: {tau.size} input delays given for {m} inputs")
    if not np.all(np.isfinite(tau)) or np.any(tau < 0):
        raise ConfigError(f"verify: input delays must be finite and >= 0 s, got {tau.tolist()}")
    return tau


# --------------------------------------------------------------------------------------------
# verification
# --------------------------------------------------------------------------------------------


def verify(M, F, G, H, J, tau, t_s, u, y, *, output_names, output_units=None, weights=None, valid=None,
           x0: str = "zero", j_rms_max: float = J_RMS_MAX, tic_max: float = TIC_MAX,
           output_delays=None, input_skews=None) -> Verification:
    """Verify a state-space model in the time domain (docs/method.md §9; see the module docstring).

    Parameters
    ----------
    M, F : array_like, shape (n, n)
        ``M x' = F x + G u(t - tau)``; M must be nonsingular (ConfigError otherwise).
    G : array_like, shape (n, m)
    H : array_like, shape (p, n)
    J : array_like, shape (p, m)
        ``y = H x + J u(t - tau)``, in the units of ``y``.
    tau : array_like, shape (m,)
        Delay of each input [s], >= 0.
    output_delays : array_like, shape (p,), optional
        Time skew of each output [s], >= 0: the model's output ``o`` is compared ``tau_o`` late
        (the sensor's sample is older than its stamp). Default none.
    input_skews : array_like, shape (m,), optional
        Time skew of each input's measurement [s], >= 0: the logged input is that late, so the
        model is driven by it advanced (net shift ``tau - skew``; the last sample is held past the
        end). Default none.
    t_s : array_like, shape (N,)
        Uniformly spaced sample times [s].
    u : array_like, shape (m, N)
        Measured inputs [input units]; must be finite (split the record at gaps).
    y : array_like, shape (p, N)
        Measured outputs [output units]; non-finite samples are excluded like invalid ones.
    output_names : sequence of str, length p
    output_units : sequence of str, optional
    weights : array_like, shape (p,), optional
        Diagonal of W (default ones: unit weights with signals in deg, deg/s, ft/s, ft/s^2).
    valid : array_like of bool, shape (N,) or (p, N), optional
        Samples to use in the fit and the metrics (all by default). The simulation always runs
        over the whole record.
    x0 : {"zero", "least_squares"}
        Initial state: zero (trim; default) or fitted with the biases (see module docstring).
    j_rms_max, tic_max : float
        Pass limits (defaults :data:`J_RMS_MAX` = 2.0, :data:`TIC_MAX` = 0.25).

    Returns
    -------
    Verification
    """
    t = np.asarray(t_s, dtype=float).ravel()
    N = t.size
    F = np.asarray(F, dtype=float)
    if F.ndim != 2 or F.shape[0] != F.shape[1]:
        raise ConfigError(f"verify: F must be square, got shape {F.shape}")
    n = F.shape[0]
    F = _matrix(F, (n, n), "F")
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[None, :]
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[None, :]
    m, p = u.shape[0], y.shape[0]
    M = _matrix(M, (n, n), "M")
    G = _matrix(G, (n, m), "G")
    H = _matrix(H, (p, n), "H")
    J = _matrix(J, (p, m), "J")
    tau = _delays(tau, m)
    if input_skews is not None:
        skews = _delays(input_skews, m)
        tau = tau - skews                               # may be negative: an advance
    if u.shape[1] != N or y.shape[1] != N:
        raise ConfigError(f"verify: t_s has {N} samples but u has {u.shape[1]} and y {y.shape[1]}")
    if N < 3:
        raise ConfigError(f"verify: need at least 3 samples, got {N}")
    dt = (t[-1] - t[0]) / (N - 1)
    if not np.isfinite(dt) or dt <= 0 or np.max(np.abs(np.diff(t) - dt)) > 1e-6 * dt + 1e-9:
        raise ConfigError("verify: t_s must be finite, increasing and uniformly spaced")
    bad_u = ~np.isfinite(u)
    if bad_u.any():
        i, k = np.argwhere(bad_u)[0]
        raise ConfigError(f"verify: input {i} is not finite at t = {t[k]:.3f} s "
                          f"({int(bad_u.sum())} samples); split the record at gaps")
    names = tuple(str(s) for s in output_names)
    if len(names) != p:
        raise ConfigError(f"verify: {len(names)} output names for {p} outputs")
    units = tuple(str(s) for s in output_units) if output_units is not None else ("",) * p
    if len(units) != p:
        raise ConfigError(f"verify: {len(units)} output units for {p} outputs")
    w = np.ones(p) if weights is None else np.asarray(weights, dtype=float).ravel()
    if w.size != p or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ConfigError(f"verify: weights must be {p} finite positive numbers, got {np.asarray(weights).tolist()}")
    if x0 not in ("zero", "least_squares"):
        raise ConfigError(f"verify: x0 must be 'zero' or 'least_squares', got {x0!r}")

    ok = np.isfinite(y)
    if valid is not None:
        v = np.asarray(valid, dtype=bool)
        if v.shape == (N,):
            v = np.broadcast_to(v, (p, N))
        if v.shape != (p, N):
            raise ConfigError(f"verify: valid has shape {v.shape}, expected ({N},) or ({p}, {N})")
        ok = ok & v
    notes = []
    excluded = int(p * N - ok.sum())
    if excluded:
        notes.append(f"{excluded} output samples excluded (invalid or non-finite) from the fit and the metrics")

    # --- responses: inputs, unit biases, unit initial states -----------------------------------
    A, B, E = _state_matrices(M, F, G)
    Phi, G0, G1 = _discretize_foh(A, np.hstack([B, E]), dt)
    ud = _delayed(u, tau, dt)
    n_x0 = n if x0 == "least_squares" else 0
    K = 1 + n + n_x0                                    # scenarios: inputs, biases, initial states
    X = np.zeros((n, K, N))
    drive = np.zeros((n, K, N - 1))
    drive[:, 0, :] = G0[:, :m] @ ud[:, :-1] + G1[:, :m] @ ud[:, 1:]
    drive[:, 1:1 + n, :] = (G0[:, m:] + G1[:, m:])[:, :, None]
    if n_x0:
        X[:, 1 + n:, 0] = np.eye(n)
    _recurse(Phi, X, drive)
    Y = np.einsum("pn,nkt->pkt", H, X)               # (p, K, N)
    y_u = Y[:, 0, :] + J @ ud
    if output_delays is not None:
        tau_y = np.atleast_1d(np.asarray(output_delays, dtype=float)).ravel()
        if tau_y.size != p or not np.all(np.isfinite(tau_y)) or np.any(tau_y < 0):
            raise ConfigError(f"verify: output delays must be {p} finite numbers >= 0 s, got {tau_y.tolist()}")
        for o in np.flatnonzero(tau_y > 0):
            Y[o] = _delayed(Y[o], np.full(K, tau_y[o]), dt)
            y_u[o] = _delayed(y_u[o][None, :], tau_y[o:o + 1], dt)[0]

    eig = np.linalg.eigvals(A)
    growth = float(np.max(eig.real))
    T = dt * (N - 1)
    if growth > 0:
        notes.append(f"model unstable: max Re(eigenvalue) = {growth:.4g} rad/s, growth factor "
                     f"{np.exp(min(growth * T, 700.0)):.3g} over the {T:.3g} s record; simulated open loop anyway")

    n_unk = n + p + n_x0
    # finite but so large that the least squares below would overflow squaring them is diverged too
    huge = math.sqrt(np.finfo(float).max / max(Y.size, 1))
    if not (np.all(np.isfinite(Y)) and np.all(np.isfinite(y_u))) or max(np.max(np.abs(Y), initial=0.0),
                                                                          np.max(np.abs(y_u), initial=0.0)) > huge:
        notes.append("simulation diverged (overflow): the model cannot predict this record open loop")
        return _diverged(names, units, w, t, y, u, n, p, tau, notes, j_rms_max, tic_max, n_unk)

    # --- stacked weighted least squares for [b; y_ref; x0] ------------------------------------
    sw = np.sqrt(w)
    rows, rhs = [], []
    for o in range(p):
        idx = np.flatnonzero(ok[o])
        reg = np.zeros((idx.size, n_unk))
        reg[:, :n] = Y[o, 1:1 + n, idx]
        reg[:, n + o] = 1.0
        if n_x0:
            reg[:, n + p:] = Y[o, 1 + n:, idx]
        rows.append(sw[o] * reg)
        rhs.append(sw[o] * (y[o, idx] - y_u[o, idx]))
    R = np.vstack(rows)
    r = np.concatenate(rhs)
    n_fit = r.size
    if n_fit < n_unk:
        raise ConfigError(f"verify: {n_fit} valid output samples cannot determine {n_unk} biases and shifts")
    scale = np.linalg.norm(R, axis=0)
    scale[scale == 0] = 1.0
    theta_s, _, rank, _ = np.linalg.lstsq(R / scale, r, rcond=_RCOND)
    theta = theta_s / scale
    if rank < n_unk:
        why = (" (biases, reference shifts and initial state trade off; the minimum-norm split is reported, "
               "the prediction is unique)" if n_x0 else " (the minimum-norm solution is reported)")
        notes.append(f"least squares rank {rank} of {n_unk} unknowns{why}")
    b, y_ref = theta[:n], theta[n:n + p]
    x_init = theta[n + p:] if n_x0 else np.zeros(n)
    pred = y_u + np.einsum("pkt,k->pt", Y[:, 1:1 + n, :], b) + y_ref[:, None]
    if n_x0:
        pred = pred + np.einsum("pkt,k->pt", Y[:, 1 + n:, :], x_init)

    # --- metrics ---------------------------------------------------------------------------------
    fits, num, den = [], 0.0, 0
    for o in range(p):
        sel = ok[o]
        k = int(sel.sum())
        if k == 0:
            fits.append(OutputFit(names[o], units[o], np.nan, np.nan, float(y_ref[o]), float(w[o]), 0, False))
            notes.append(f"output {names[o]!r} has no valid sample")
            continue
        res = y[o, sel] - pred[o, sel]
        with np.errstate(over="ignore", invalid="ignore"):     # a model that diverges: J_rms not finite
            rms = float(np.sqrt(np.mean(res ** 2)))
            d = (float(np.sqrt(np.mean((y[o, sel] - y_ref[o]) ** 2)))
                 + float(np.sqrt(np.mean((pred[o, sel] - y_ref[o]) ** 2))))
        tic = rms / d if d > 0 else (0.0 if rms == 0 else 1.0)
        fits.append(OutputFit(names[o], units[o], tic, rms, float(y_ref[o]), float(w[o]), k, bool(tic <= tic_max)))
        with np.errstate(over="ignore", invalid="ignore"):
            num += w[o] * float(np.sum(res ** 2))
        den += k
    j_rms = float(np.sqrt(num / den)) if den else float("nan")
    passed = bool(np.isfinite(j_rms) and j_rms <= j_rms_max and all(f.passed for f in fits))
    return Verification(
        outputs=tuple(fits), j_rms=j_rms, t_s=t, measured=np.where(ok, y, np.nan), predicted=pred, inputs=u,
        biases=b, reference_shifts=y_ref, initial_state=x_init, weights=w, passed=passed,
        guidelines=_guidelines(j_rms_max, tic_max), rank=int(rank), n_unknowns=n_unk, notes=tuple(notes),
    )


def _guidelines(j_rms_max: float, tic_max: float) -> dict:
    return {"j_rms_max": float(j_rms_max), "tic_max": float(tic_max),
            "source": "docs/method.md §9: J_rms <~ 1.0-2.0 and TIC <= 0.25-0.3 acceptable; passed = J_rms <= j_rms_max "
                      "and every output's TIC <= tic_max"}


def _diverged(names, units, w, t, y, u, n, p, tau, notes, j_rms_max, tic_max, n_unk) -> Verification:
    fits = tuple(OutputFit(nm, un, 1.0, float("inf"), 0.0, float(wo), 0, False) for nm, un, wo in zip(names, units, w))
    return Verification(
        outputs=fits, j_rms=float("inf"), t_s=t, measured=y, predicted=np.full_like(y, np.nan), inputs=u,
        biases=np.zeros(n), reference_shifts=np.zeros(p), initial_state=np.zeros(n), weights=w, passed=False,
        guidelines=_guidelines(j_rms_max, tic_max), rank=0, n_unknowns=n_unk, notes=tuple(notes),
    )
