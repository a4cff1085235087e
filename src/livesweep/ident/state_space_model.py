"""The parameterised state-space model of DERIVID (docs/method.md §8.1).

::

    M x' = F x + G u(t - tau)          y = H x + J u(t - tau)
    T(jw) = [H (jw M - F)^-1 G + J] diag(exp(-jw tau_j))

:class:`StateSpaceModel` holds the entries of M, F, G, H, J as compiled expressions of named
parameters and constants (:mod:`livesweep.ident.expression`; the case's ``[state_space]`` table is
parsed by :mod:`livesweep.ident.state_space_table`), evaluates the matrices at a parameter vector
``theta``, and gives the frequency response with its exact derivatives in the parameters (the
Jacobian every fit uses). Units are the case file's: states and outputs in whatever units the
matrices imply, inputs in their signal units, delays in seconds, omega in rad/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg

from livesweep.errors import ConfigError
from livesweep.ident.state_space_table import _MATRICES, parse_table
from livesweep.numeric import frozen_array as _frozen

__all__ = ["StateSpaceModel"]


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
        :func:`~livesweep.ident.state_space.fit_state_space` starts them from
        :func:`~livesweep.ident.state_space.equation_error_start` when it is given
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
        model = cls(**parse_table(table, where))
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
