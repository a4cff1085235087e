"""State-space derivative identification from frequency responses (DERIVID; docs/method.md §8).

Model (docs/method.md §8.1)::

    M x' = F x + G u(t - tau)          y = H x + J u(t - tau)
    T(jw) = [H (jw M - F)^-1 G + J] diag(exp(-jw tau_j))

with M, F, G, H, J given entry by entry as strings of a case's ``[state_space]`` table (numbers,
parameter and constant names, ``+ - * /`` and parentheses; :mod:`livesweep.ident.expression`), one
delay parameter per input (optional). Units are the case file's: states and outputs in whatever
units the matrices imply (the XV-15 cases: v ft/s, p and r rad/s, phi rad; outputs deg/s, deg,
ft/s^2, ft/s), inputs in their signal units (deg), delays in seconds, omega in rad/s.

Cost (docs/method.md §8.2): the NAVFIT cost of every pair the model's outputs and inputs cover, over
that pair's own band at ``N_OMEGA`` = 20 log-spaced points (:mod:`livesweep.ident.cost` -- the one
criterion), summed; ``J_ave = J / n_pairs`` (guideline J_ave <= 100, <= 50 excellent).

Optimiser (docs/method.md §8.3): :func:`scipy.optimize.least_squares` (trust-region reflective) on the
stacked residuals of :func:`livesweep.ident.cost.residuals`, with the exact Jacobian (derivatives
of the matrices' entries times linear solves with ``jw M - F``), Jacobian-based parameter scaling
and delays bounded to ``>= 0``. Accuracy (CR bounds, insensitivities, correlation) comes from the
same Jacobian at the solution (:mod:`livesweep.ident.accuracy`); the structure-reduction loop of
method.md §8.5 is :func:`reduce_structure`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg
from scipy.optimize import least_squares

from livesweep.errors import ConfigError, check_band, quote
from livesweep.ident.accuracy import (MAX_CRAMER_RAO_PCT, MAX_INSENSITIVITY_PCT, accuracy_from_jacobian)
from livesweep.ident.cost import MIN_COHERENCE, N_OMEGA, W_G, W_P, fit_points, residuals, select_band
from livesweep.ident.expression import compile_entry
from livesweep.limits import MAX_MODEL_DIMENSION
from livesweep.numeric import finite_or_none as _num, frozen_array as _frozen

__all__ = ["StateSpaceModel", "FittedParameter", "StateSpaceFit", "select_pairs", "a_priori_eliminations",
           "fit_state_space", "refit_state_space", "evaluate_state_space", "REFIT_NFEV", "reduce_structure", "equation_error_start",
           "MAX_DELTA_COST"]

#: A deletion is kept when the average cost rises by no more than this (docs/method.md §8.5).
MAX_DELTA_COST = 2.0

_MATRICES = ("M", "F", "G", "H", "J")
_TABLE_KEYS = {"states", "inputs", "outputs", "M", "F", "G", "H", "J", "constants", "parameters", "delays", "output_delays",
               "input_skews", "bands", "units"}
_DB = 20.0 / math.log(10.0)
_DEG = 180.0 / math.pi


def _names(table, key, where, required=True):
    raw = table.get(key)
    if raw is None:
        if required:
            raise ConfigError(f"{where}{key}: missing (a list of signal names)")
        return ()
    if not isinstance(raw, (list, tuple)) or not raw or not all(isinstance(n, str) and n for n in raw):
        raise ConfigError(f"{where}{key} = {quote(raw)}: must be a non-empty list of names")
    if len(raw) > MAX_MODEL_DIMENSION:
        raise ConfigError(f"{where}{key}: {len(raw)} names; a model has at most {MAX_MODEL_DIMENSION}")
    dup = sorted({n for n in raw if list(raw).count(n) > 1})
    if dup:
        raise ConfigError(f"{where}{key} = {quote(raw)}: repeated name(s) {', '.join(dup)}")
    return tuple(raw)


def _shape_of(raw, name, rows, cols, row_what, col_what, where):
    if not isinstance(raw, (list, tuple)):
        raise ConfigError(f"{where}{name}: must be a list of rows (lists of strings), got {raw!r}")
    if len(raw) != rows:
        raise ConfigError(f"{where}{name} has {len(raw)} rows, expected {rows} (one per {row_what})")
    for i, row in enumerate(raw):
        if not isinstance(row, (list, tuple)):
            raise ConfigError(f"{where}{name}[{i}] = {row!r}: must be a list of entries")
        if len(row) != cols:
            raise ConfigError(f"{where}{name}[{i}] has {len(row)} entries, expected {cols} (one per {col_what})")


def _parse_delays(table, key, names_of, what, constants, parameters, w):
    """``delays`` / ``output_delays``: per input/output, a parameter or constant name or seconds."""
    raw_d = table.get(key, {}) or {}
    if not isinstance(raw_d, dict):
        raise ConfigError(f"{w}{key} = {raw_d!r}: must be a table of {what} = delay parameter")
    for name in raw_d:
        if name not in names_of:
            raise ConfigError(f"{w}{key}.{name}: not an {what} ({what}s: {', '.join(names_of)})")
    delays, dentries = {}, []
    for name in names_of:
        val = raw_d.get(name)
        if val is None:
            delays[name] = None
            dentries.append(compile_entry("0", constants, parameters, f"{w}{key}.{name}"))
            continue
        if isinstance(val, str) and val.strip() not in parameters and val.strip() not in constants:
            raise ConfigError(f"{w}{key}.{name} = {val!r}: unknown name (must be a parameter or constant "
                              "name, or a number of seconds)")
        if not isinstance(val, str) and (isinstance(val, bool) or not isinstance(val, (int, float)) or val < 0):
            raise ConfigError(f"{w}{key}.{name} = {val!r}: must be a parameter name or a delay >= 0 s")
        delays[name] = val.strip() if isinstance(val, str) else None
        dentries.append(compile_entry(val, constants, parameters, f"{w}{key}.{name}"))
    return delays, dentries


@dataclass(frozen=True)
class StateSpaceModel:
    """A parameterised state-space model ``M x' = F x + G u(t - tau)``, ``y = H x + J u(t - tau)``.

    Build it with :meth:`from_table`. Parameters are addressed by name; ``theta`` is always the
    full parameter vector in :attr:`parameters` order (fixed ones included).

    Attributes
    ----------
    states, inputs, outputs : tuple of str
    M, F, G, H, J : tuple of tuple of CompiledEntry
        Entries (shapes n x n, n x n, n x m, p x n, p x m).
    constants : dict of str -> float
    parameters : tuple of str
        Parameter names, in the order of ``theta``.
    initial : ndarray
        Initial (or, for fixed parameters, held) values.
    fixed : tuple of bool
    delays : dict of str -> str or None
        Delay parameter (or constant) name per input [s]; None for an undelayed input.
    delay_entries : tuple of CompiledEntry
        One per input (the number 0 when undelayed).
    output_delays : dict of str -> str or None
        Delay (sensor time skew) parameter or constant name per output [s]: ``y_o`` is measured
        ``tau_o`` late, ``exp(-s tau_o)`` on every pair of that output.
    output_delay_entries : tuple of CompiledEntry
        One per output (the number 0 when undelayed).
    input_skews : dict of str -> str or None
        Time skew of an input's *measurement* [s]: the logged input is ``tau_s`` late, so the
        model sees it advanced, ``exp(+s tau_s)`` on every pair of that input (what a control
        position sensor logged late looks like; the net input delay ``tau - tau_s`` may then
        be negative).
    input_skew_entries : tuple of CompiledEntry
        One per input (the number 0 when not skewed).
    state_units : dict of str -> str
        Units of the states as the case's ``units`` table gives them (``v = "ft/s"``); the report
        derives every derivative's units from them and the signals' units.
    bands : dict of (str, str) -> (float, float)
        Per-pair fitting bands [rad/s] from the case (``"p/da" = [lo, hi]``); others follow
        coherence.
    where : str
        How messages name the table (e.g. ``"cruise.toml [state_space]"``).
    unset : tuple of str
        Free parameters the case gave no initial value (held at 0 here);
        :func:`fit_state_space` starts them from :func:`equation_error_start` when it is given
        the frequency-response set.
    """

    states: tuple
    inputs: tuple
    outputs: tuple
    M: tuple
    F: tuple
    G: tuple
    H: tuple
    J: tuple
    constants: dict
    parameters: tuple
    initial: np.ndarray
    fixed: tuple
    delays: dict
    delay_entries: tuple
    bands: dict = field(default_factory=dict)
    where: str = ""
    unset: tuple = ()
    output_delays: dict = field(default_factory=dict)
    output_delay_entries: tuple = ()
    input_skews: dict = field(default_factory=dict)
    input_skew_entries: tuple = ()
    state_units: dict = field(default_factory=dict)
    _cache: dict = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "_cache", self._assemble())

    # --- construction ---------------------------------------------------------------------

    @classmethod
    def from_matrices(cls, *, states, inputs, outputs, F, G, H, M=None, J=None, parameters=None,
                      constants=None, delays=None, output_delays=None, where: str = "") -> "StateSpaceModel":
        """Build a model from matrices whose entries are numbers or expressions of parameters.

        The notebook form of :meth:`from_table` (the same checks and messages).

        Parameters
        ----------
        states, inputs, outputs : sequence of str
        F, G, H : array_like, shapes (n, n), (n, m), (p, n)
            Entries are numbers, or strings: a parameter or constant name or an arithmetic
            expression of them (``"Lp"``, ``"-g"``, ``"Yv*r2d"``).
        M, J : array_like, optional
            Shapes (n, n) and (p, m); default identity and zero.
        parameters : mapping, optional
            Name -> initial value (free), or ``{"value": v, "fixed": True}``.
        constants : mapping, optional
            Name -> number.
        delays, output_delays : mapping, optional
            Input (output) name -> parameter or constant name, or a number [s].
        where : str
            Prefix for messages.

        Returns
        -------
        StateSpaceModel

        Examples
        --------
        >>> from livesweep.ident.state_space import StateSpaceModel
        >>> m = StateSpaceModel.from_matrices(states=["p"], inputs=["da"], outputs=["p"],
        ...                                   F=[["Lp"]], G=[["Lda"]], H=[[1.0]],
        ...                                   parameters={"Lp": -2.0, "Lda": 5.0})
        >>> m.parameters
        ('Lp', 'Lda')
        """
        def rows(name, a):
            if a is None:
                return None
            arr = np.asarray(a, dtype=object)
            if arr.ndim != 2:
                raise ConfigError(f"{where + ': ' if where else ''}{name} must be a 2-D matrix, got shape {arr.shape}")
            return [[e if isinstance(e, str) else repr(float(e)) for e in row] for row in arr.tolist()]

        table = {"states": list(states), "inputs": list(inputs), "outputs": list(outputs),
                 "F": rows("F", F), "G": rows("G", G), "H": rows("H", H),
                 "parameters": {k: (dict(v) if isinstance(v, dict) else {"value": float(v)})
                                for k, v in (parameters or {}).items()}}
        for key, val in (("M", M), ("J", J)):
            if val is not None:
                table[key] = rows(key, val)
        for key, val in (("constants", constants), ("delays", delays), ("output_delays", output_delays)):
            if val:
                table[key] = dict(val)
        return cls.from_table(table, where=where)

    @classmethod
    def from_table(cls, table: dict, where: str = "") -> "StateSpaceModel":
        """Build and validate a model from a case's ``[state_space]`` table (docs/case-file.md).

        Parameters
        ----------
        table : dict
            Keys ``states``, ``inputs``, ``outputs`` (lists of names); ``F``, ``G``, ``H`` and
            optionally ``M`` (default identity) and ``J`` (default zero): lists of rows of entry
            strings; ``units`` (state -> units text, optional); ``constants`` (name -> number); ``parameters`` (name -> ``{value, fixed}``
            or a bare number; a free parameter may omit ``value``, see :attr:`unset`); ``delays`` (input -> parameter or constant name, or a number
            [s]); ``bands`` (``"output/input"`` -> ``[lo, hi]`` rad/s, optional).
        where : str
            Prefix for messages, e.g. the case file name.

        Raises
        ------
        ConfigError
            Unknown keys, wrong shapes, bad or unknown names, non-arithmetic entries, entries
            not finite at the initial values, unused free parameters, M singular at the
            initial values -- naming the key, entry and value.
        """
        w = f"{where}: " if where else ""
        if not isinstance(table, dict):
            raise ConfigError(f"{w}[state_space] must be a table, got {table!r}")
        unknown = sorted(set(table) - _TABLE_KEYS)
        if unknown:
            raise ConfigError(f"{w}unknown key(s) {', '.join(unknown)} in [state_space]; "
                              f"known: {', '.join(sorted(_TABLE_KEYS))}")
        states = _names(table, "states", w)
        inputs = _names(table, "inputs", w)
        outputs = _names(table, "outputs", w)
        n, m, p = len(states), len(inputs), len(outputs)

        constants = {}
        raw_c = table.get("constants", {}) or {}
        if not isinstance(raw_c, dict):
            raise ConfigError(f"{w}constants = {raw_c!r}: must be a table of name = number")
        for name, val in raw_c.items():
            if not name.isidentifier():
                raise ConfigError(f"{w}constants.{name}: not a valid name")
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
                raise ConfigError(f"{w}constants.{name} = {val!r}: must be a finite number")
            constants[name] = float(val)

        raw_p = table.get("parameters", {}) or {}
        if not isinstance(raw_p, dict):
            raise ConfigError(f"{w}parameters = {raw_p!r}: must be a table of name = {{value, fixed}}")
        names, init, fixed, unset = [], [], [], []
        for name, spec in raw_p.items():
            if not name.isidentifier():
                raise ConfigError(f"{w}parameters.{name}: not a valid name")
            if name in constants:
                raise ConfigError(f"{w}parameters.{name}: the name is also a constant")
            if isinstance(spec, dict):
                bad = sorted(set(spec) - {"value", "fixed"})
                if bad:
                    raise ConfigError(f"{w}parameters.{name}: unknown key(s) {', '.join(bad)} (use value, fixed)")
                val, fx = spec.get("value"), spec.get("fixed", False)
                if val is None:
                    if fx:
                        raise ConfigError(f"{w}parameters.{name}: fixed but has no value")
                    unset.append(name)
                    val = 0.0
            else:
                val, fx = spec, False
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
                raise ConfigError(f"{w}parameters.{name}.value = {val!r}: must be a finite number")
            if not isinstance(fx, bool):
                raise ConfigError(f"{w}parameters.{name}.fixed = {fx!r}: must be true or false")
            names.append(name)
            init.append(float(val))
            fixed.append(fx)

        defaults = {"M": [["1" if i == j else "0" for j in range(n)] for i in range(n)],
                    "J": [["0"] * m for _ in range(p)]}
        shapes = {"M": (n, n, "state", "state"), "F": (n, n, "state", "state"), "G": (n, m, "state", "input"),
                  "H": (p, n, "output", "state"), "J": (p, m, "output", "input")}
        mats = {}
        for key in _MATRICES:
            raw = table.get(key, defaults.get(key))
            if raw is None:
                raise ConfigError(f"{w}{key}: missing (a list of rows of entry strings)")
            rows, cols, rw, cw = shapes[key]
            _shape_of(raw, key, rows, cols, rw, cw, w)
            mats[key] = tuple(tuple(compile_entry(e, constants, names, f"{w}{key}[{i}][{j}]")
                                    for j, e in enumerate(row)) for i, row in enumerate(raw))

        delays, dentries = _parse_delays(table, "delays", inputs, "input", constants, names, w)
        odelays, odentries = _parse_delays(table, "output_delays", outputs, "output", constants, names, w)
        iskews, isentries = _parse_delays(table, "input_skews", inputs, "input", constants, names, w)

        bands = {}
        raw_b = table.get("bands", {}) or {}
        if not isinstance(raw_b, dict):
            raise ConfigError(f"{w}bands = {raw_b!r}: must be a table of \"output/input\" = [lo, hi]")
        for key, val in raw_b.items():
            parts = key.split("/")
            if len(parts) != 2 or parts[0] not in outputs or parts[1] not in inputs:
                raise ConfigError(f"{w}bands.{key!r}: must name a pair \"output/input\" of the model")
            bands[(parts[0], parts[1])] = check_band(val, f"{w}bands.{key}")

        used = set()
        for key in _MATRICES:
            for row in mats[key]:
                for e in row:
                    used.update(e.parameters)
        for e in (*dentries, *odentries, *isentries):
            used.update(e.parameters)
        for name, fx in zip(names, fixed):
            if not fx and name not in used:
                raise ConfigError(f"{w}parameters.{name}: free but used in no matrix entry or delay")

        raw_u = table.get("units") or {}
        if not isinstance(raw_u, dict):
            raise ConfigError(f"{w}units = {quote(raw_u)}: must be a table of state = \"units\"")
        for name, unit in raw_u.items():
            if name not in states:
                raise ConfigError(f"{w}units.{name}: not a state (states: {', '.join(states)})")
            if not isinstance(unit, str):
                raise ConfigError(f"{w}units.{name} = {quote(unit)}: must be a string such as \"rad/s\"")
        model = cls(states, inputs, outputs, mats["M"], mats["F"], mats["G"], mats["H"], mats["J"], constants,
                    tuple(names), _frozen(init), tuple(fixed), delays, tuple(dentries), bands, where, tuple(unset),
                    odelays, tuple(odentries), iskews, tuple(isentries), dict(raw_u))
        model._check_at(model.initial, "the initial values")
        return model

    def _check_at(self, theta, what: str):
        """ConfigError when an entry is not finite or M is singular at ``theta``."""
        for key in _MATRICES:
            for row in getattr(self, key):
                for e in row:
                    v = e.value(theta)
                    if not math.isfinite(v):
                        raise ConfigError(f"{e.where} = {e.text!r}: not finite at {what} ({v})")
        for e in (*self.delay_entries, *self.output_delay_entries, *self.input_skew_entries):
            v = e.value(theta)
            if not math.isfinite(v) or v < 0:
                raise ConfigError(f"{e.where} = {e.text!r}: delay must be finite and >= 0 s at {what}, got {v}")
        M = self.matrices(theta)[0]
        if np.linalg.matrix_rank(M) < M.shape[0]:
            w = f"{self.where}: " if self.where else ""
            raise ConfigError(f"{w}M is singular at {what} (rank {np.linalg.matrix_rank(M)} of {M.shape[0]}): "
                              f"M = {M.tolist()}")

    def _assemble(self) -> dict:
        """Affine parts as arrays; non-affine entries listed for evaluation by tree."""
        P = len(self.parameters)
        base, coef, nonlin = {}, {}, []
        for key in _MATRICES:
            rows = getattr(self, key)
            shape = (len(rows), len(rows[0]) if rows else 0)
            b = np.zeros(shape)
            c = np.zeros((P,) + shape)
            for i, row in enumerate(rows):
                for j, e in enumerate(row):
                    if e.affine is not None:
                        b[i, j] = e.affine[0]
                        for k, v in e.affine[1]:
                            c[k, i, j] += v
                    else:
                        nonlin.append((key, i, j, e))
            base[key], coef[key] = b, c
        tb = np.zeros(len(self.inputs))
        tc = np.zeros((P, len(self.inputs)))
        for j, e in enumerate(self.delay_entries):
            if e.affine is not None:
                tb[j] = e.affine[0]
                for k, v in e.affine[1]:
                    tc[k, j] += v
            else:
                nonlin.append(("tau", 0, j, e))
        base["tau"], coef["tau"] = tb[None, :], tc[:, None, :]
        for key, entries, n in (("tau_y", self.output_delay_entries, len(self.outputs)),
                                ("tau_s", self.input_skew_entries, len(self.inputs))):
            ob, oc = np.zeros(n), np.zeros((P, n))
            for j, e in enumerate(entries or ()):
                if e.affine is not None:
                    ob[j] = e.affine[0]
                    for k, v in e.affine[1]:
                        oc[k, j] += v
                else:
                    nonlin.append((key, 0, j, e))
            base[key], coef[key] = ob[None, :], oc[:, None, :]
        return {"base": base, "coef": coef, "nonlin": nonlin}

    # --- parameters -----------------------------------------------------------------------

    @property
    def free(self) -> np.ndarray:
        """Indices of the free parameters in ``theta``."""
        return np.flatnonzero(~np.asarray(self.fixed, bool))

    @property
    def free_names(self) -> tuple:
        return tuple(self.parameters[k] for k in self.free)

    def index(self, name: str) -> int:
        """Index of parameter ``name``; ConfigError listing the parameters when unknown."""
        try:
            return self.parameters.index(name)
        except ValueError:
            raise ConfigError(f"unknown parameter {name!r}; parameters: {', '.join(self.parameters)}") from None

    def theta(self, values: dict | None = None) -> np.ndarray:
        """Full parameter vector: the initial values, overridden by ``values`` (name -> value)."""
        th = np.array(self.initial, float)
        for name, v in (values or {}).items():
            th[self.index(name)] = float(v)
        return th

    def with_values(self, theta=None, fixed: dict | None = None) -> "StateSpaceModel":
        """The same structure with initial values ``theta`` and, optionally, some parameters fixed.

        Parameters
        ----------
        theta : array_like, optional
            Full parameter vector (becomes the new initial values); default the current ones.
        fixed : dict of str -> float, optional
            Parameters to fix, and the values to hold them at.
        """
        th = np.array(self.initial if theta is None else theta, float)
        fx = list(self.fixed)
        for name, v in (fixed or {}).items():
            k = self.index(name)
            th[k] = float(v)
            fx[k] = True
        return replace(self, initial=_frozen(th), fixed=tuple(fx), unset=())

    def delay_parameter_indices(self) -> tuple:
        """Indices of parameters that are (alone) an input's delay: bounded to >= 0 in fits."""
        out = []
        for e in (*self.delay_entries, *self.output_delay_entries, *self.input_skew_entries):
            if e.affine is not None and e.affine[0] == 0.0 and len(e.affine[1]) == 1 and e.affine[1][0][1] > 0:
                out.append(e.affine[1][0][0])
        return tuple(sorted(set(out)))

    # --- evaluation -----------------------------------------------------------------------

    def matrices(self, theta):
        """Numerical matrices at ``theta``.

        Parameters
        ----------
        theta : array_like
            Full parameter vector.

        Returns
        -------
        M, F, G, H, J : ndarray
        tau : ndarray, shape (n_inputs,)
            Input delays [s].
        """
        th = np.asarray(theta, float)
        c = self._cache
        out = {k: c["base"][k] + np.tensordot(th, c["coef"][k], axes=1) for k in (*_MATRICES, "tau")}
        for key, i, j, e in c["nonlin"]:
            if key not in ("tau_y", "tau_s"):
                out[key][i, j] = e.value(th)
        return out["M"], out["F"], out["G"], out["H"], out["J"], out["tau"][0]

    def _extra_delays(self, theta, which: str) -> np.ndarray:
        th = np.asarray(theta, float)
        c = self._cache
        out = c["base"][which] + np.tensordot(th, c["coef"][which], axes=1)
        for key, i, j, e in c["nonlin"]:
            if key == which:
                out[i, j] = e.value(th)
        return out[0]

    def output_delays_s(self, theta) -> np.ndarray:
        """Output (sensor skew) delays [s] at ``theta``, shape (n_outputs,)."""
        return self._extra_delays(theta, "tau_y")

    def input_skews_s(self, theta) -> np.ndarray:
        """Input measurement skews [s] at ``theta``, shape (n_inputs,): the net input delay of
        the model is ``tau - input_skews_s``."""
        return self._extra_delays(theta, "tau_s")

    def _derivatives(self, theta):
        """d(matrix)/d(theta_k) for every parameter k: dict of arrays (P, rows, cols)."""
        th = np.asarray(theta, float)
        c = self._cache
        d = {k: c["coef"][k] for k in (*_MATRICES, "tau", "tau_y", "tau_s")}
        if c["nonlin"]:
            d = {k: v.copy() for k, v in d.items()}
            for key, i, j, e in c["nonlin"]:
                d[key][:, i, j] = e.value_and_gradient(th)[1]
        return d

    def frequency_response(self, theta, omega) -> np.ndarray:
        """Model frequency response.

        Parameters
        ----------
        theta : array_like
            Full parameter vector.
        omega : array_like
            Frequencies [rad/s].

        Returns
        -------
        ndarray, complex, shape (n_outputs, n_inputs, n_freq)
            ``diag(exp(-jw tau_y)) [H (jw M - F)^-1 G + J] diag(exp(-jw (tau - tau_s)))`` in output
            units per input unit (``tau_s``: input skews)
            (computed with linear solves, no inverse).
        """
        return self._response(theta, np.atleast_1d(np.asarray(omega, float)), jacobian=False)[0]

    def _response(self, theta, omega, jacobian: bool):
        M, F, G, H, J, tau = self.matrices(theta)
        tau = tau - self.input_skews_s(theta)                 # net input delay
        tau_y = self.output_delays_s(theta)
        s = 1j * omega                                        # (f,)
        A = s[:, None, None] * M[None] - F[None]              # (f, n, n)
        X = np.linalg.solve(A, np.broadcast_to(G, (omega.size,) + G.shape))   # (f, n, m)
        T0 = H[None] @ X + J[None]                            # (f, p, m)
        E = np.exp(-s[:, None] * tau[None, :])                # (f, m)
        Ey = np.exp(-s[:, None] * tau_y[None, :])             # (f, p)
        E2 = E[:, None, :] * Ey[:, :, None]                   # (f, p, m)
        T = T0 * E2
        if not jacobian:
            return np.moveaxis(T, 0, -1), None
        d = self._derivatives(theta)
        Yl = np.swapaxes(np.linalg.solve(np.swapaxes(A, 1, 2), np.broadcast_to(H.T, (omega.size,) + H.T.shape)), 1, 2)
        # dA X = (s dM - dF) X ;  dT0 = dH X + Yl (dG - dA X) + dJ
        # this is the inner loop of every fit: each product is one BLAS call over all parameters and
        # frequencies (k x f small matmuls cost 4x more)
        k, n = d["F"].shape[:2]
        f, _, m = X.shape
        p = H.shape[0]
        Xt = np.moveaxis(X, 0, 1).reshape(n, f * m)                                   # (n, f m)
        dFX = (d["F"].reshape(k * n, n) @ Xt).reshape(k, n, f, m)
        dMX = (d["M"].reshape(k * n, n) @ Xt).reshape(k, n, f, m)
        dHX = (d["H"].reshape(k * p, n) @ Xt).reshape(k, p, f, m)
        inner = d["G"][:, :, None, :] + dFX - s[None, None, :, None] * dMX             # (k, n, f, m)
        inner = inner.transpose(2, 1, 0, 3).reshape(f, n, k * m)                        # (f, n, k m)
        YI = (Yl @ inner).reshape(f, p, k, m).transpose(2, 0, 1, 3)                      # (k, f, p, m)
        dT0 = np.swapaxes(dHX, 1, 2) + YI + d["J"][:, None]                              # (k, f, p, m)
        dtau = d["tau"][:, 0, :] - d["tau_s"][:, 0, :]                     # (k, m), net input delay
        dtau_y = d["tau_y"][:, 0, :]                                       # (k, p)
        dT = dT0 * E2[None] + T[None] * (-s[None, :, None, None] * (dtau[:, None, None, :] + dtau_y[:, None, :, None]))
        return np.moveaxis(T, 0, -1), np.moveaxis(dT, 1, -1)               # (p,m,f), (k,p,m,f)

    def eigenvalues(self, theta) -> np.ndarray:
        """Eigenvalues of ``M^-1 F`` [rad/s] (generalised problem ``F x = lambda M x``), sorted."""
        M, F = self.matrices(theta)[:2]
        return np.sort_complex(scipy.linalg.eigvals(F, M))


# --- pairs ----------------------------------------------------------------------------------

def select_pairs(frs, model: StateSpaceModel, *, bands: dict | None = None, min_coherence: float = MIN_COHERENCE,
                 omega_range=None, min_decades: float = 0.3, n_omega: int = N_OMEGA):
    """The model's pairs from a frequency-response set, at their fitting points.

    Parameters
    ----------
    frs : FrequencyResponseSet
        Usually the MISO-conditioned set.
    model : StateSpaceModel
    bands : dict of (output, input) -> (lo, hi), optional
        Per-pair bands [rad/s]; overrides the model's ``bands``. Other pairs take the widest
        contiguous stretch with coherence >= ``min_coherence``.
    min_coherence : float
        Coherence defining a pair's band when none is given.
    omega_range : (float, float), optional
        Frequencies outside which no coherence-selected band may reach [rad/s] (e.g. to keep
        out closed-loop-dominated low frequencies); explicit ``bands`` are not clipped.
    min_decades : float
        Coherence-selected bands narrower than this (after clipping) are skipped as unusable.

    Returns
    -------
    pairs : list of PairData
    skipped : list of (output, input, reason)
        Pairs the model covers but the data cannot support (not in the set, or no band with
        usable coherence).
    """
    bands = {**model.bands, **(bands or {})}
    pairs, skipped = [], []
    for o in model.outputs:
        for i in model.inputs:
            if o not in frs.outputs or i not in frs.inputs:
                skipped.append((o, i, "not in the frequency-response set"))
                continue
            resp = frs.pair(o, i)
            band = bands.get((o, i))
            if band is None:
                band = select_band(resp, min_coherence)
                if band is None:
                    skipped.append((o, i, f"no band with coherence >= {min_coherence:g}"))
                    continue
                if omega_range is not None:
                    band = (max(band[0], float(omega_range[0])), min(band[1], float(omega_range[1])))
                if band[1] <= band[0] or math.log10(band[1] / band[0]) < min_decades:
                    skipped.append((o, i, f"coherent band ({band[0]:.3g}-{band[1]:.3g} rad/s) narrower than "
                                          f"{min_decades:g} decade"))
                    continue
            try:
                pd = fit_points(resp, band, n_omega, min_coherence)
            except ConfigError as exc:
                skipped.append((o, i, str(exc)))
                continue
            if _no_path(model, o, i, pd.omega):
                skipped.append((o, i, "the model has no path from this input to this output (response identically "
                                      "zero) though the data are coherent: a coupling the model lacks?"))
                continue
            pairs.append(pd)
    return pairs, skipped


def _no_path(model: StateSpaceModel, output: str, input: str, omega) -> bool:
    """Whether the model's response ``output/input`` is identically zero by its structure (zero at
    the initial values and at other generic ones): it has no magnitude in dB to fit."""
    i, j = model.outputs.index(output), model.inputs.index(input)
    th0 = np.asarray(model.initial, float)
    for th in (th0, 1.1 * th0 + 0.1):
        with np.errstate(all="ignore"):
            try:
                T = model.frequency_response(th, omega)[i, j]
            except np.linalg.LinAlgError:
                return False
        if not np.all(T == 0.0):
            return False
    return True


def a_priori_eliminations(model: StateSpaceModel, skipped_pairs) -> dict:
    """Control derivatives to remove before fitting because their pairs have no coherence.

    docs/method.md §8.2: pairs with near-zero coherence are dropped and "the matching derivatives can
    be removed a priori". A parameter is matched to the skipped pair ``y/u_j`` when it appears only
    in column ``j`` of ``G`` (and of ``J``) at a state ``x_s`` that output ``y`` measures directly
    (the ``H`` row of ``y`` is a constant multiple of ``x_s`` alone, e.g. ``p`` of roll rate), and
    every output measuring ``x_s`` directly lost its pair with ``u_j``.

    Parameters
    ----------
    model : StateSpaceModel
    skipped_pairs : iterable of (output, input, ...)

    Returns
    -------
    dict of str -> str
        Parameter -> reason, for :meth:`StateSpaceModel.with_values` (fix at 0).
    """
    skipped = {(t[0], t[1]) for t in skipped_pairs}
    theta = model.initial
    direct = {}                                            # state index -> outputs measuring it alone
    for r, o in enumerate(model.outputs):
        nz = [j for j, e in enumerate(model.H[r]) if not (e.is_constant and e.value(theta) == 0.0)]
        if len(nz) == 1 and model.H[r][nz[0]].is_constant:
            direct.setdefault(nz[0], []).append(o)
    where_used = {}
    for key in _MATRICES:
        for i, row in enumerate(getattr(model, key)):
            for j, e in enumerate(row):
                for name in e.parameters:
                    where_used.setdefault(name, set()).add((key, i, j))
    for j, e in enumerate(model.delay_entries):
        for name in e.parameters:
            where_used.setdefault(name, set()).add(("tau", 0, j))
    out = {}
    for name in model.free_names:
        uses = where_used.get(name, set())
        if not uses or any(k not in ("G", "J") for k, _, _ in uses):
            continue
        cols = {j for _, _, j in uses}
        g_states = {i for k, i, _ in uses if k == "G"}
        if len(cols) != 1 or len(g_states) != 1:
            continue
        j, s_ = cols.pop(), g_states.pop()
        outs = direct.get(s_, [])
        u = model.inputs[j]
        if outs and all((o, u) in skipped for o in outs):
            out[name] = (f"pair(s) {', '.join(f'{o}/{u}' for o in outs)} without usable coherence: "
                         f"{model.states[s_]} response to {u} not measurable")
    return out


# --- fit -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class FittedParameter:
    """One identified parameter.

    Attributes
    ----------
    name : str
    value : float
        Identified (or held) value, in the units the case's matrices give it.
    fixed : bool
    cramer_rao, insensitivity : float
        1-sigma bounds in the parameter's units (raw normalisation, see
        :mod:`livesweep.ident.accuracy`); NaN for fixed parameters, inf when not identifiable.
    cramer_rao_pct, insensitivity_pct : float
        Relative to ``|value|`` [%].
    """

    name: str
    value: float
    fixed: bool
    cramer_rao: float
    cramer_rao_pct: float
    insensitivity: float
    insensitivity_pct: float


@dataclass(frozen=True)
class StateSpaceFit:
    """Result of :func:`fit_state_space` (and of :func:`reduce_structure`).

    Attributes
    ----------
    model : StateSpaceModel
        The model as fitted (fixed flags as used; initial values = the start of this fit).
    theta : ndarray
        Full parameter vector at the solution.
    parameters : tuple of FittedParameter
        In model order.
    correlation : ndarray, shape (n_free, n_free)
        Correlation of the free parameters (order of :attr:`correlation_names`).
    correlation_names : tuple of str
    cost_pairs : tuple of (output, input, J)
        Cost of each fitted pair.
    cost_average : float
        ``J_ave`` (guideline <= 100; <= 50 excellent).
    eigenvalues : ndarray, complex
        Eigenvalues of the identified model [rad/s].
    converged : bool
        The optimiser met a convergence test (False: stopped at its evaluation limit or failed).
    message : str
    n_iterations : int
        Cost evaluations the optimiser used.
    removed : tuple of dict
        Structure-reduction log (empty for a plain fit): one dict per attempted deletion.
    skipped_pairs : tuple of (output, input, reason)
    bands : tuple of (output, input, lo, hi)
        The fitted pairs' bands [rad/s].
    """

    model: StateSpaceModel
    theta: np.ndarray
    parameters: tuple
    correlation: np.ndarray
    correlation_names: tuple
    cost_pairs: tuple
    cost_average: float
    eigenvalues: np.ndarray
    converged: bool
    message: str
    n_iterations: int
    removed: tuple = ()
    skipped_pairs: tuple = ()
    bands: tuple = ()

    def parameter(self, name: str) -> FittedParameter:
        """The parameter called ``name``."""
        return self.parameters[self.model.index(name)]

    def value(self, name: str) -> float:
        return self.parameter(name).value

    @property
    def removed_parameters(self) -> tuple:
        """Parameters the structure reduction eliminated (held at 0), in order."""
        return tuple(step["parameter"] for step in self.removed if step.get("accepted"))

    def frequency_response(self, omega) -> np.ndarray:
        """Identified model's response ``(n_outputs, n_inputs, n_freq)`` at ``omega`` [rad/s]."""
        return self.model.frequency_response(self.theta, omega)

    def matrices(self) -> dict:
        """``A = M^-1 F``, ``B = M^-1 G``, ``C = H``, ``D = J`` at the fitted values (new arrays),
        with ``states``, ``inputs``, ``outputs`` and the input delays ``tau_s`` [s]."""
        M, F, G, H, J, tau = self.model.matrices(self.theta)
        return {"A": np.linalg.solve(M, F), "B": np.linalg.solve(M, G), "C": np.array(H), "D": np.array(J),
                "tau_s": np.array(tau, float), "states": self.model.states, "inputs": self.model.inputs,
                "outputs": self.model.outputs}

    def to_ss(self, *, pade_order: int | None = None):
        """This model as ``control.StateSpace`` (needs python-control); delays left out unless
        ``pade_order`` is given. See :func:`livesweep.interop.state_space_to_ss`."""
        from livesweep.interop import state_space_to_ss

        return state_space_to_ss(self, pade_order=pade_order)

    def to_dict(self) -> dict:
        """The ``report.json`` ``state_space`` form (docs/outputs.md, report.json), JSON-ready (non-finite -> null)."""
        return {
            "parameters": [{"name": q.name, "value": _num(q.value), "fixed": bool(q.fixed),
                            "cramer_rao": _num(q.cramer_rao), "cramer_rao_pct": _num(q.cramer_rao_pct),
                            "insensitivity": _num(q.insensitivity), "insensitivity_pct": _num(q.insensitivity_pct)}
                           for q in self.parameters],
            "cost": {"average": _num(self.cost_average),
                     "pairs": [{"output": o, "input": i, "cost": _num(c)} for o, i, c in self.cost_pairs]},
            "eigenvalues": [[float(e.real), float(e.imag)] for e in self.eigenvalues],
            "removed_parameters": list(self.removed_parameters),
            "reduction_log": [dict(step) for step in self.removed],
            "correlation": {"names": list(self.correlation_names),
                            "matrix": [[_num(x) for x in row] for row in self.correlation]},
            "bands": [{"output": o, "input": i, "band_rad_s": [lo, hi]} for o, i, lo, hi in self.bands],
            "skipped_pairs": [{"output": o, "input": i, "reason": r} for o, i, r in self.skipped_pairs],
            "converged": bool(self.converged),
            "message": self.message,
            "n_iterations": int(self.n_iterations),
        }


class _Problem:
    """Stacked residuals and their exact Jacobian for a model and its pairs."""

    def __init__(self, model: StateSpaceModel, pairs):
        self.model = model
        self.pairs = list(pairs)
        for pr in self.pairs:
            if pr.output not in model.outputs or pr.input not in model.inputs:
                raise ConfigError(f"pair {pr.output}/{pr.input} is not an output/input pair of the model "
                                  f"(outputs {', '.join(model.outputs)}; inputs {', '.join(model.inputs)})")
        self.omega = np.concatenate([pr.omega for pr in self.pairs])
        self.sl, k = [], 0
        for pr in self.pairs:
            self.sl.append(slice(k, k + pr.n_omega))
            k += pr.n_omega
        self.oi = [(model.outputs.index(pr.output), model.inputs.index(pr.input)) for pr in self.pairs]
        self.scale = [np.sqrt(20.0 / pr.n_omega * pr.weight) for pr in self.pairs]
        self.n_residuals = 2 * self.omega.size

    def residuals(self, theta):
        with np.errstate(all="ignore"):
            T = self.model.frequency_response(theta, self.omega)
        return np.concatenate([residuals(pr, T[o, i, sl]) for pr, (o, i), sl in zip(self.pairs, self.oi, self.sl)])

    def residuals_and_jacobian(self, theta, free):
        """Residuals (``sum r^2 = J``) and ``D = dr/dtheta[free]``, shape (n_residuals, n_free)."""
        with np.errstate(all="ignore"):
            T, dT = self.model._response(theta, self.omega, jacobian=True)
            r, D = [], []
            for pr, (o, i), sl, sc in zip(self.pairs, self.oi, self.sl, self.scale):
                t = T[o, i, sl]
                r.append(residuals(pr, t))
                rel = dT[free][:, o, i, sl] / t[None, :]                      # (k, f)
                dmag = -sc[None, :] * math.sqrt(W_G) * _DB * rel.real
                dph = -sc[None, :] * math.sqrt(W_P) * _DEG * rel.imag
                D.append(np.concatenate([dmag, dph], axis=1).T)
        return np.concatenate(r), np.concatenate(D, axis=0)

    def pair_costs(self, theta):
        """[(output, input, J)] at ``theta``."""
        r = self.residuals(theta)
        out, k = [], 0
        for pr in self.pairs:
            n = 2 * pr.n_omega
            out.append((pr.output, pr.input, float(np.dot(r[k:k + n], r[k:k + n]))))
            k += n
        return out


def _result(model, problem, theta, converged, message, nfev, removed=(), skipped=()):
    free = model.free
    with np.errstate(all="ignore"):
        r, D = problem.residuals_and_jacobian(theta, free)
        D = np.where(np.isfinite(D), D, 0.0)
        acc = accuracy_from_jacobian(D, theta[free])
        pc = problem.pair_costs(theta)
    params = []
    fpos = {k: a for a, k in enumerate(free)}
    for k, name in enumerate(model.parameters):
        if k in fpos:
            a = fpos[k]
            params.append(FittedParameter(name, float(theta[k]), False, float(acc.cramer_rao[a]),
                                          float(acc.cramer_rao_pct[a]), float(acc.insensitivity[a]),
                                          float(acc.insensitivity_pct[a])))
        else:
            params.append(FittedParameter(name, float(theta[k]), True, math.nan, math.nan, math.nan, math.nan))
    J_ave = float(np.mean([c for _, _, c in pc])) if pc else math.nan
    try:
        eig = model.eigenvalues(theta)
    except (np.linalg.LinAlgError, ValueError):
        eig = np.array([], complex)
    return StateSpaceFit(model, _frozen(theta), tuple(params), acc.correlation, model.free_names, tuple(pc), J_ave,
                         _frozen(eig, complex), bool(converged), message, int(nfev), tuple(removed), tuple(skipped),
                         tuple((pr.output, pr.input, float(pr.band_rad_s[0]), float(pr.band_rad_s[1]))
                               for pr in problem.pairs))


def fit_state_space(model: StateSpaceModel, pairs, *, theta0=None, max_nfev: int | None = 200,
                    method: str = "trf", x_scale="jac", ftol: float = 1e-10, xtol: float = 1e-10,
                    gtol: float = 1e-10, extra_starts=(), skipped_pairs=()) -> StateSpaceFit:
    """Fit the free parameters of ``model`` to the pairs' frequency responses.

    Parameters
    ----------
    model : StateSpaceModel
    pairs : list of PairData or FrequencyResponseSet
        The pairs to fit (from :func:`select_pairs` / :func:`livesweep.ident.cost.fit_points`). A
        FrequencyResponseSet is turned into pairs with :func:`select_pairs` (pairs without usable
        coherence are skipped and reported in the result).
    theta0 : array_like or dict, optional
        Start: full parameter vector, or name -> value overrides; default the model's initial
        values (with :func:`equation_error_start` values for :attr:`StateSpaceModel.unset`
        parameters when ``pairs`` is a FrequencyResponseSet). Fixed parameters keep the model's
        values.
    max_nfev : int, optional
        Limit on cost evaluations; a fit stopped by it has ``converged = False``.
    method : {"trf", "lm"}
        :func:`scipy.optimize.least_squares` method; "lm" takes no bounds, so delay parameters
        are then unbounded.
    x_scale : "jac" or array_like
        Parameter scaling for :func:`scipy.optimize.least_squares` (free parameters).
    ftol, xtol, gtol : float
        Convergence tolerances (see :func:`scipy.optimize.least_squares`).
    extra_starts : sequence of array_like or dict
        Further starting points (multi-start, docs/method.md §8.3: e.g. transfer-function results,
        a priori values, :func:`equation_error_start`); the solution with the lowest cost wins.
    skipped_pairs : sequence of (output, input, reason)
        Carried into the result (what :func:`select_pairs` skipped).

    Returns
    -------
    StateSpaceFit
        ``converged`` is False, with the reason in ``message``, when the optimiser stopped at
        ``max_nfev`` or failed; ``n_iterations`` counts cost evaluations over all starts.
    """
    start = None
    if not isinstance(pairs, (list, tuple)):
        if theta0 is None and model.unset:
            start = equation_error_start(model, pairs)
        pairs, skipped = select_pairs(pairs, model)
        skipped_pairs = tuple(skipped_pairs) + tuple(skipped)
    if method not in ("trf", "lm"):
        raise ConfigError(f"state-space fit method {method!r}: use 'trf' or 'lm'")
    if not pairs:
        raise ConfigError("no pairs to fit: the model's outputs and inputs cover no usable frequency response")
    problem = _Problem(model, pairs)
    if theta0 is None:
        theta = np.array(model.initial if start is None else start, float)
    elif isinstance(theta0, dict):
        theta = model.theta(theta0)
    else:
        theta = np.array(theta0, float)
        if theta.shape != (len(model.parameters),):
            raise ConfigError(f"theta0 has {theta.size} values, the model has {len(model.parameters)} parameters")
    fixed = np.asarray(model.fixed, bool)
    theta[fixed] = np.asarray(model.initial)[fixed]
    free = model.free
    if free.size == 0:
        return _result(model, problem, theta, True, "no free parameters: cost evaluated", 1, (), skipped_pairs)
    lower = np.full(free.size, -np.inf)
    for k in model.delay_parameter_indices():
        if k in free:
            lower[np.flatnonzero(free == k)[0]] = 0.0
    if method == "lm":
        lower[:] = -np.inf
    cache = {}

    def full(x, base):
        th = base.copy()
        th[free] = x
        return th

    def both(x, base):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            try:
                r, D = problem.residuals_and_jacobian(full(x, base), free)
            except np.linalg.LinAlgError:                  # j w M - F singular at a fitting frequency
                r, D = np.full(problem.n_residuals, 1e6), np.zeros((problem.n_residuals, free.size))
            if not np.all(np.isfinite(r)):
                r = np.where(np.isfinite(r), r, 1e6)
                D = np.where(np.isfinite(D), D, 0.0)
            cache[key] = (r, D)
        return cache[key]

    starts = [theta]
    for st in extra_starts:
        st = model.theta(st) if isinstance(st, dict) else np.array(st, float)
        if st.shape != theta.shape:
            raise ConfigError(f"extra start has {st.size} values, the model has {theta.size} parameters")
        st[fixed] = theta[fixed]
        starts.append(st)
    best, nfev, failures = None, 0, []
    for base in starts:
        x0 = np.clip(base[free], lower, np.inf)
        try:
            res = least_squares(lambda x: both(x, base)[0], x0, jac=lambda x: both(x, base)[1],
                                bounds=(lower, np.inf), method=method, x_scale=x_scale, ftol=ftol, xtol=xtol,
                                gtol=gtol, max_nfev=max_nfev)
        except (np.linalg.LinAlgError, ValueError) as exc:
            failures.append(str(exc))
            continue
        cache.clear()
        nfev += res.nfev
        if best is None or res.cost < best[0].cost:
            best = (res, base)
    if best is None:
        return _result(model, problem, theta, False, f"optimiser failed: {'; '.join(failures)}", 0, (), skipped_pairs)
    res, base = best
    th = full(res.x, base)
    converged = bool(res.status > 0)
    msg = res.message if converged else f"did not converge: {res.message} (after {res.nfev} cost evaluations)"
    if len(starts) > 1:
        msg += f" (best of {len(starts)} starts)"
    return _result(model, problem, th, converged, msg, nfev, (), skipped_pairs)


#: Cost evaluations of a refit (the residual loop's, the coupling search's) before it is
#: continued once (:func:`refit_state_space`).
REFIT_NFEV = 100


def evaluate_state_space(fit: StateSpaceFit, pairs) -> StateSpaceFit:
    """The fit ``fit`` judged on other frequency points, its parameters unchanged.

    J, the Cramer-Rao bounds and the insensitivities of :func:`fit_state_space` are computed at
    ``fit.theta`` on ``pairs``, so models fitted on different points (the residual loop's denser
    grid) are compared on one set (the state-space stage's :data:`~livesweep.ident.cost.N_OMEGA`
    points per pair). Convergence, message, structure-reduction log and skipped pairs are
    ``fit``'s.

    Parameters
    ----------
    fit : StateSpaceFit
    pairs : list of PairData
        From :func:`select_pairs` on ``fit.model``.

    Returns
    -------
    StateSpaceFit
        Same model and ``theta``; cost, bounds and bands of ``pairs``.
    """
    problem = _Problem(fit.model, pairs)
    return _result(fit.model, problem, np.array(fit.theta, float), fit.converged, fit.message, fit.n_iterations,
                   fit.removed, fit.skipped_pairs)


def refit_state_space(model: StateSpaceModel, pairs) -> StateSpaceFit:
    """A refit of a model changed from a converged one: :func:`fit_state_space` with
    :data:`REFIT_NFEV` cost evaluations; one that budget stopped is continued once from where it
    stopped with twice as many. A slow but steady descent (a delay on a pilot-loop axis, its cost
    equal to 4e-8 after 100 evaluations) is not a failure to converge; a fit still not settled
    after that is reported as one (``converged`` False)."""
    fit = fit_state_space(model, pairs, max_nfev=REFIT_NFEV)
    if not fit.converged:
        more = fit_state_space(fit.model.with_values(fit.theta), pairs, max_nfev=2 * REFIT_NFEV)
        if more.converged or more.cost_average <= fit.cost_average:
            fit = more
    return fit


# --- structure reduction -------------------------------------------------------------------

def reduce_structure(model: StateSpaceModel, pairs, fit: StateSpaceFit | None = None, *,
                     max_insensitivity_pct: float = MAX_INSENSITIVITY_PCT,
                     max_cramer_rao_pct: float = MAX_CRAMER_RAO_PCT, max_delta_cost: float = MAX_DELTA_COST,
                     keep=(), max_steps: int = 50, **fit_kw) -> StateSpaceFit:
    """Model-structure reduction (docs/method.md §8.5).

    Repeatedly: if some free parameter has I% > ``max_insensitivity_pct``, try deleting the most
    insensitive one; otherwise, if some has CR% > ``max_cramer_rao_pct``, try deleting the one with
    the largest CR%. A deletion fixes the parameter at 0 and reconverges from the current values;
    it is kept when ``J_ave`` rises by at most ``max_delta_cost``, else the parameter is restored
    and not tried again. Stops when every remaining candidate meets the guidelines.

    Parameters
    ----------
    model : StateSpaceModel
    pairs : list of PairData or FrequencyResponseSet
        As for :func:`fit_state_space`.
    fit : StateSpaceFit, optional
        A converged fit of ``model`` (fitted here when omitted).
    keep : sequence of str
        Parameters never to delete.
    max_steps : int
        At most this many deletion attempts.
    **fit_kw
        Passed to :func:`fit_state_space`.

    Returns
    -------
    StateSpaceFit
        The final fit; ``removed`` logs every attempt (parameter, reason, the I% or CR% that
        triggered it, J_ave before and after, delta, accepted).
    """
    if not isinstance(pairs, (list, tuple)):
        pairs, skipped = select_pairs(pairs, model)
        fit_kw.setdefault("skipped_pairs", tuple(skipped))
    if fit is None:
        fit = fit_state_space(model, list(pairs), **fit_kw)
    fit_kw.pop("skipped_pairs", None)
    current = fit
    log = list(fit.removed)
    tried = set(keep)
    for _ in range(max_steps):
        cands = [q for q in current.parameters if not q.fixed and q.name not in tried]
        ins = [q for q in cands if not q.insensitivity_pct <= max_insensitivity_pct]
        if ins:
            q = max(ins, key=lambda q: (q.insensitivity_pct if math.isfinite(q.insensitivity_pct) else math.inf))
            reason, crit = "insensitivity", q.insensitivity_pct
        else:
            crs = [q for q in cands if not q.cramer_rao_pct <= max_cramer_rao_pct]
            if not crs:
                break
            q = max(crs, key=lambda q: (q.cramer_rao_pct if math.isfinite(q.cramer_rao_pct) else math.inf))
            reason, crit = "cramer_rao", q.cramer_rao_pct
        tried.add(q.name)
        trial_model = current.model.with_values(current.theta, fixed={q.name: 0.0})
        trial = fit_state_space(trial_model, list(pairs), skipped_pairs=current.skipped_pairs, **fit_kw)
        delta = trial.cost_average - current.cost_average
        accepted = bool(trial.converged and delta <= max_delta_cost)
        log.append({"step": len(log) + 1, "parameter": q.name, "value_before": _num(q.value), "reason": reason,
                    "criterion_pct": _num(crit), "cost_before": _num(current.cost_average),
                    "cost_after": _num(trial.cost_average), "delta_cost": _num(delta), "accepted": accepted})
        if accepted:
            current = trial
    return replace(current, removed=tuple(log))


# --- initial values ------------------------------------------------------------------------

def equation_error_start(model: StateSpaceModel, frs, *, band_rad_s=None, min_coherence: float = MIN_COHERENCE):
    """Quick initial values by frequency-domain equation error (docs/method.md §8.3's third source).

    Works when every state can be read from the responses: each state is either a constant,
    parameter-free multiple of one output (``H`` row with a single constant non-zero entry and a
    zero ``J`` row), or follows from a parameter-free state equation (``x_i = x_j / (jw)``-type
    kinematics). The state equations, affine in the parameters, then give one complex linear
    least-squares problem per row, weighted by coherence, solved for the free parameters of
    ``M``, ``F`` and ``G`` at every grid frequency where the pair has usable coherence (inputs
    delayed by the initial delays). Parameters appearing only in ``H``/``J``/delays keep their
    initial values.

    Parameters
    ----------
    model : StateSpaceModel
    frs : FrequencyResponseSet
    band_rad_s : (float, float), optional
        Frequencies to use [rad/s]; default the whole set.
    min_coherence : float

    Returns
    -------
    ndarray
        Full parameter vector (a start for :func:`fit_state_space`).

    Raises
    ------
    ConfigError
        When some state cannot be reconstructed from the outputs or an equation row is not affine.
    """
    n, m = len(model.states), len(model.inputs)
    theta = np.array(model.initial, float)
    omega = np.asarray(frs.omega, float)
    keep = np.ones(omega.size, bool) if band_rad_s is None else (omega >= band_rad_s[0]) & (omega <= band_rad_s[1])
    w = omega[keep]
    s = 1j * w
    Ms, Fs, Gs, Hs, Js, tau = model.matrices(theta)
    # state responses X[i] (f, m) and their coherence weights
    X = [None] * n
    C = [None] * n
    for r, o in enumerate(model.outputs):
        if o not in frs.outputs:
            continue
        hrow, jrow = model.H[r], model.J[r]
        nz = [j for j, e in enumerate(hrow) if not (e.is_constant and e.value(theta) == 0.0)]
        if len(nz) != 1 or not hrow[nz[0]].is_constant or any(not (e.is_constant and e.value(theta) == 0.0) for e in jrow):
            continue
        i = nz[0]
        if X[i] is not None:
            continue
        a = frs.outputs.index(o)
        if not all(u in frs.inputs for u in model.inputs):
            break
        b = [frs.inputs.index(u) for u in model.inputs]
        X[i] = frs.H[a][b][:, keep].T / hrow[i].value(theta)
        C[i] = frs.coherence[a][b][:, keep].T
    for _ in range(n):                                   # kinematic rows: x_i from the others
        for i in range(n):
            if X[i] is not None:
                continue
            row = [model.M[i][j] for j in range(n)] + [model.F[i][j] for j in range(n)] + list(model.G[i])
            if any(not e.is_constant for e in row):
                continue
            others = [j for j in range(n) if j != i and (Fs[i, j] != 0 or Ms[i, j] != 0)]
            if any(X[j] is None for j in others):
                continue
            den = s * Ms[i, i] - Fs[i, i]
            num = sum((Fs[i, j] - s * Ms[i, j])[:, None] * X[j] for j in others) + Gs[i][None, :]
            X[i] = num / den[:, None]
            C[i] = np.min([C[j] for j in others], axis=0) if others else np.ones((w.size, m))
    missing = [model.states[i] for i in range(n) if X[i] is None]
    if missing:
        raise ConfigError(f"equation-error start: state(s) {', '.join(missing)} cannot be read from the outputs")
    Xa = np.stack(X, axis=0)                              # (n, f, m)
    Wc = np.min(np.stack(C, axis=0), axis=0)              # (f, m)
    good = np.all(np.isfinite(Xa), axis=0) & np.isfinite(Wc)
    Xa = np.where(good[None], Xa, 0.0)
    Wc = np.where(good, Wc, 0.0)
    U = np.exp(-s[:, None] * tau[None, :])                # (f, m) delayed unit inputs
    free = model.free
    fpos = {k: a for a, k in enumerate(free)}
    for i in range(n):
        entries = ([("M", j, model.M[i][j]) for j in range(n)] + [("F", j, model.F[i][j]) for j in range(n)]
                   + [("G", j, model.G[i][j]) for j in range(m)])
        if all(e.is_constant for _, _, e in entries):
            continue
        if any(e.affine is None for _, _, e in entries):
            raise ConfigError(f"equation-error start: state equation {i} ({model.states[i]}) is not affine in the "
                              "parameters")
        # sum_j (s M_ij - F_ij) X_j - G_i U = 0, each entry = c0 + sum c_k theta_k
        A = np.zeros((w.size, m, free.size), complex)
        bvec = np.zeros((w.size, m), complex)
        for kind, j, e in entries:
            if kind == "M":
                base = s[:, None] * Xa[j]
            elif kind == "F":
                base = -Xa[j]
            else:
                base = np.zeros((w.size, m), complex)
                base[:, j] = -U[:, j]
            c0, terms = e.affine
            bvec -= c0 * base
            for k, c in terms:
                if k in fpos:
                    A[:, :, fpos[k]] += c * base
                else:
                    bvec -= c * theta[k] * base
        wt = np.sqrt(np.where(Wc >= min_coherence, Wc, 0.0))
        A = (A * wt[..., None]).reshape(-1, free.size)
        bvec = (bvec * wt).reshape(-1)
        cols = np.flatnonzero(np.any(A != 0, axis=0))
        if cols.size == 0:
            continue
        Ar = np.concatenate([A[:, cols].real, A[:, cols].imag])
        br = np.concatenate([bvec.real, bvec.imag])
        sol, *_ = np.linalg.lstsq(Ar, br, rcond=None)
        theta[free[cols]] = sol
    return theta
