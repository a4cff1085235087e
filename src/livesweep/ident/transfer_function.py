"""Transfer-function models in the factored shorthand of Tischler & Remple's Eq. 2.8, fitted with NAVFIT's cost.

Shorthand (docs/method.md §7.3): ``(1/T)`` means ``(s + 1/T)``, ``[zeta, w]`` means
``(s^2 + 2 zeta w s + w^2)``, ``s`` / ``s^n`` a free differentiator (a root at the origin), the gain K
multiplies the factored form and a delay appears as ``e^(-tau s)``::

    T(s) = K * prod(numerator factors) / prod(denominator factors) * e^(-tau s)

Because every factor is monic, K is the high-frequency gain times s^(relative degree), e.g.
Tischler & Remple's Eq. 2.9 ``p/da = -4.60 s [0.278, 1.93] e^(-0.0533 s) / ((0.0912)(1.00)[0.237, 1.67])``
has ``|p/da| * w -> 4.60`` at high frequency.

Parameters: first-order factors by their inverse time constant ``1/T`` [rad/s] (key ``"1/T"``),
quadratics by damping ``zeta`` [-] and natural frequency ``w`` [rad/s] (keys as written), so the
roots stay real-valued parameters; a negative ``1/T`` or ``zeta`` is an unstable root and is allowed
(``w`` is kept > 0: ``(-zeta, -w)`` is the same quadratic). ``"gain"`` is K (output units per input
unit, times s^(relative degree)) and ``"tau"`` the delay [s], bounded ``0 <= tau <= tau_max_s``.

Fitting (:func:`fit_transfer_function`) minimises the sum of squares of
:func:`livesweep.ident.cost.residuals`, i.e. the cost J of docs/method.md §7.1 summed over the pairs, with
``scipy.optimize.least_squares`` (trust-region reflective, ``x_scale='jac'``, analytic Jacobian of
the model's log-response mapped through the cost's own residual function). Several pairs may be
fitted together with one shared denominator (Tischler & Remple's Eq. 2.7: common lateral-directional
denominator, distinct numerators with their own gain, zeros and delay).

Accuracy (docs/method.md §8.4): the Gauss-Newton Hessian of J is ``H = 2 D^T D`` with ``D = dr/dtheta``
at the solution; ``CR_i = sqrt((H^-1)_ii)`` (absolute, in the parameter's units) and
``CR_i% = 100 CR_i/|theta_i|``; insensitivity ``I_i = 1/sqrt(H_ii)``. **Normalisation.** This is the
CIFER form; it equals the least-squares standard deviation of the estimate only when the residual
variance is 1/2, i.e. when the fit leaves ``J ~ n_omega`` (about 20 per pair). The statistical
(1-sigma) scatter for white fitting-point noise is ``sqrt(2 * residual_variance) * CR_i`` with
``residual_variance = J_total / (N_residuals - n_parameters)`` (reported): with clean data
(J << 20) the CIFER bound is conservative by ``sqrt(1/(2 residual_variance))``.
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
from scipy.optimize import least_squares

from livesweep.errors import ConfigError, quote
from livesweep.ident.cost import PairData, fit_points, residuals
from livesweep.limits import MAX_TF_ORDER
from livesweep.numeric import frozen_array
from livesweep.spectral.response import FrequencyResponse

__all__ = ["Factor", "Structure", "parse_structure", "TransferFunctionModel", "FittedTransferFunction",
           "fit_transfer_function", "RESERVED_NAMES", "STRUCTURE_PREFIXES"]

RESERVED_NAMES = frozenset({"gain", "tau"})
#: The prefix :func:`parse_structure` gives the generated parameter names of a plain-order
#: numerator and denominator (so a numerator ``"2"`` and a denominator ``"2"`` do not share names).
STRUCTURE_PREFIXES = {"numerator": "n", "denominator": "d"}

_NAME = r"[A-Za-z_][A-Za-z0-9_]*"
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_ARG = rf"(?:{_NAME}|{_NUM})"
_RE_S = re.compile(r"s(?:\^(\d+))?")
_RE_FIRST = re.compile(rf"\(\s*1\s*/\s*({_ARG})\s*\)")
_RE_SECOND = re.compile(rf"\[\s*({_ARG})\s*,\s*({_ARG})\s*\]")
_RE_TOKEN = re.compile(r"\[[^\[\]]*\]|\([^()]*\)|[^\s\[\]()]+|\S+")
_RE_NAME = re.compile(_NAME)
_EPS_CAL = 1e-6          # step [neper / rad] used to read the cost's residual map (exact: the map is linear)
_BIG = 1e6               # residual substituted where the model response is not finite


# ----------------------------------------------------------------------------- structures


@dataclass(frozen=True)
class Factor:
    """One factor of the shorthand.

    Attributes
    ----------
    kind : str
        ``"s"`` (root(s) at the origin), ``"first"`` ``(s + 1/T)`` or ``"second"``
        ``(s^2 + 2 zeta w s + w^2)``.
    names : tuple
        Parameter names as written (``None`` where a value is fixed): ``(T,)`` for a first-order
        factor, ``(zeta, w)`` for a quadratic, ``()`` for ``s``.
    fixed : tuple
        Fixed values (``None`` where free): ``(1/T [rad/s],)`` or ``(zeta [-], w [rad/s])``.
    power : int
        Power of ``s`` (kind ``"s"`` only).
    """

    kind: str
    names: tuple = ()
    fixed: tuple = ()
    power: int = 1

    @property
    def n_roots(self) -> int:
        return self.power if self.kind == "s" else (1 if self.kind == "first" else 2)

    @property
    def keys(self) -> tuple:
        """Parameter keys (``"1/T"`` for first-order factors, the names for quadratics; None if fixed)."""
        if self.kind == "first":
            return (None if self.names[0] is None else f"1/{self.names[0]}",)
        return tuple(self.names)

    @property
    def is_free(self) -> bool:
        return any(k is not None for k in self.keys)

    def text(self) -> str:
        if self.kind == "s":
            return "s" if self.power == 1 else f"s^{self.power}"
        if self.kind == "first":
            return f"(1/{self.names[0] if self.names[0] is not None else _g(1.0 / self.fixed[0])})"
        a = [n if n is not None else _g(v) for n, v in zip(self.names, self.fixed)]
        return f"[{a[0]}, {a[1]}]"


def _g(v: float) -> str:
    return f"{v:.6g}"


@dataclass(frozen=True)
class Structure:
    """A product of shorthand factors (numerator or denominator of a transfer function).

    Attributes
    ----------
    factors : tuple of Factor
        In the written order.
    text : str
        The text it was parsed from (not compared).
    """

    factors: tuple = ()
    text: str = field(default="", compare=False)

    @property
    def order(self) -> int:
        """Degree of the polynomial in s."""
        return sum(f.n_roots for f in self.factors)

    @property
    def parameter_keys(self) -> tuple:
        """Keys of the free parameters, in the written order."""
        return tuple(k for f in self.factors for k in f.keys if k is not None)

    def __str__(self) -> str:
        return " ".join(f.text() for f in self.factors) or "1"


def _arg(tok: str, text: str, what: str):
    """(name, None) for a parameter name, (None, value) for a number."""
    if _RE_NAME.fullmatch(tok):
        if tok in RESERVED_NAMES:
            raise ConfigError(f"transfer-function structure {quote(text)}: parameter name {quote(tok)} is reserved "
                              f"({', '.join(sorted(RESERVED_NAMES))} name the gain and the delay)")
        return tok, None
    v = float(tok)
    if not math.isfinite(v):
        raise ConfigError(f"transfer-function structure {quote(text)}: {what} {quote(tok)} is not finite")
    return None, v


def parse_structure(text, *, prefix: str = "") -> Structure:
    """Parse the factored shorthand of Tischler & Remple's Eq. 2.8.

    Parameters
    ----------
    text : str or int
        Factors separated by spaces: ``s``, ``s^n`` (roots at the origin), ``(1/T)`` for
        ``(s + 1/T)`` and ``[zeta, w]`` for ``(s^2 + 2 zeta w s + w^2)``. ``T``, ``zeta`` and ``w``
        are parameter names (identifiers) or numbers, which fix that value (``(1/0.05)`` is
        ``(s + 20)``; ``(1/-5)`` an unstable ``(s - 0.2)``). A plain order ``"n"`` (or int) is a
        generic n-th order polynomial in factored form: ``n // 2`` quadratics
        ``[zeta_<prefix>i, w_<prefix>i]`` and, for odd n, one ``(1/T_<prefix>1)`` first.
        ``""`` or ``"0"`` is the constant 1.
    prefix : str
        Inserted in the generated names of a plain order (the model uses ``"n"``/``"d"`` so a
        numerator ``"2"`` and a denominator ``"2"`` do not share names).

    Returns
    -------
    Structure

    Raises
    ------
    ConfigError
        Naming the token that is not a factor, a repeated or reserved parameter name, a zero
        time constant, a non-positive fixed natural frequency or an order (degree in s) above
        :data:`livesweep.limits.MAX_TF_ORDER`.
    """
    if isinstance(text, bool) or not isinstance(text, (str, int)):
        raise ConfigError(f"transfer-function structure must be text or an order, got {quote(text)}")
    src = str(text)
    t = src.strip()
    factors: list[Factor] = []

    def too_high(order) -> ConfigError:
        return ConfigError(f"transfer-function structure {quote(src)}: order {order} is above the limit of "
                           f"{MAX_TF_ORDER}")

    if re.fullmatch(r"\d+", t or "0"):
        if len(t) > 6:                                  # no int() of thousands of digits
            raise too_high(quote(t))
        n = int(t or "0")
        if n > MAX_TF_ORDER:
            raise too_high(n)
        if n % 2:
            factors.append(Factor("first", (f"T_{prefix}1",), (None,)))
        for i in range(n // 2):
            factors.append(Factor("second", (f"zeta_{prefix}{i + 1}", f"w_{prefix}{i + 1}"), (None, None)))
        return Structure(tuple(factors), src)
    order = 0
    for match in _RE_TOKEN.finditer(t):
        tok = match.group()
        if m := _RE_S.fullmatch(tok):
            if len(m.group(1) or "") > 6:
                raise too_high(f"{m.group(1)[:7]}... or more")
            p = int(m.group(1) or 1)
            if p < 1:
                raise ConfigError(f"transfer-function structure {quote(src)}: bad factor {quote(tok)} "
                                  "(power of s must be >= 1)")
            factors.append(Factor("s", (), (), p))
        elif m := _RE_FIRST.fullmatch(tok):
            name, val = _arg(m.group(1), src, "time constant")
            if name is None:
                if val == 0:
                    raise ConfigError(f"transfer-function structure {quote(src)}: factor {quote(tok)} has a zero "
                                      "time constant")
                factors.append(Factor("first", (None,), (1.0 / val,)))
            else:
                factors.append(Factor("first", (name,), (None,)))
        elif m := _RE_SECOND.fullmatch(tok):
            zn, zv = _arg(m.group(1), src, "damping")
            wn, wv = _arg(m.group(2), src, "natural frequency")
            if wn is None and not wv > 0:
                raise ConfigError(f"transfer-function structure {quote(src)}: factor {quote(tok)} needs a natural "
                                  "frequency > 0")
            factors.append(Factor("second", (zn, wn), (zv, wv)))
        else:
            raise ConfigError(f"transfer-function structure {quote(src)}: bad factor {quote(tok)} (expected s, s^n, "
                              "(1/T), [zeta, w] with names or numbers, or a plain order such as 2)")
        order += factors[-1].n_roots
        if order > MAX_TF_ORDER:          # stop at the limit, not after a crafted text's millions of factors
            raise too_high(order if match.end() == len(t) else f"{order} or more")
    seen: set = set()
    for f in factors:
        for n in f.names:
            if n is None:
                continue
            if n in seen:
                raise ConfigError(f"transfer-function structure {quote(src)}: parameter name {quote(n)} is used twice")
            seen.add(n)
    return Structure(tuple(factors), src)


@dataclass(frozen=True)
class TransferFunctionModel:
    """A transfer-function structure to fit to one pair.

    Attributes
    ----------
    name : str
    numerator, denominator : Structure or str
        Text (or an order) is parsed with :func:`parse_structure` (plain-order names get the
        prefixes ``n``/``d``).
    delay : bool
        Fit a delay ``e^(-tau s)``, ``tau >= 0`` [s].
    output, input : str, optional
        When given, the pair fitted with this model must have these names.
    """

    name: str
    numerator: Structure | str = ""
    denominator: Structure | str = ""
    delay: bool = True
    output: str | None = None
    input: str | None = None

    def __post_init__(self):
        for key, prefix in STRUCTURE_PREFIXES.items():
            if not isinstance(getattr(self, key), Structure):
                object.__setattr__(self, key, parse_structure(getattr(self, key), prefix=prefix))
        common = set(self.numerator.parameter_keys) & set(self.denominator.parameter_keys)
        if common:
            raise ConfigError(f"transfer function {self.name!r}: parameter {sorted(common)[0]!r} appears in both "
                              "numerator and denominator (use distinct names)")


# ----------------------------------------------------------------------------- results


def _jsonf(v):
    v = float(v)
    return v if math.isfinite(v) else None


def _frozen(a):
    return frozen_array(a, dtype=None)


@dataclass(frozen=True)
class FittedTransferFunction:
    """A fitted transfer function ``T(s) = gain * prod(s - z) / prod(s - p) * e^(-delay_s s)``.

    Attributes
    ----------
    name, output, input : str
    gain : float
        K of the factored form (output units per input unit times s^-(n_poles - n_zeros)).
    zeros, poles : ndarray, complex
        Roots [rad/s], numerator/denominator factors in the written order.
    delay_s : float
        tau [s] (0 when the model has no delay).
    cost : float
        J of this pair (docs/method.md §7.1).
    parameters : dict
        Key -> value: ``"gain"``, ``"tau"`` [s] (with a delay), ``"1/T"`` [rad/s], ``zeta`` [-],
        ``w`` [rad/s]; fixed values are not parameters.
    cramer_rao : dict
        Key -> CR_i = sqrt((H^-1)_ii), H = 2 D^T D (absolute, parameter units; see module docs for
        the normalisation); ``inf`` when the parameter is not identifiable.
    cramer_rao_pct : dict
        Key -> 100 CR_i / |theta_i|.
    factors : list of dict
        Readable factors: ``{"where", "kind": "s", "power"}``, ``{"where", "kind": "first", "name",
        "inverse_time_constant" [rad/s], "time_constant_s", "fixed"}``, ``{"where", "kind": "second",
        "names", "zeta", "omega" [rad/s], "fixed"}``.
    converged : bool
    message : str
    numerator, denominator : str
        The structures (shorthand).
    insensitivity_pct : dict
        Key -> 100 I_i/|theta_i|, I_i = 1/sqrt(H_ii).
    residual_variance : float
        J_total / (N_residuals - n_parameters) of the (joint) fit; ``sqrt(2 residual_variance) *
        CR_i`` is the statistical 1-sigma scatter for white fitting-point noise.
    fit_group : tuple of str
        Names of the transfer functions fitted together (shared denominator), this one included.
    band_rad_s : tuple
        The pair's fitting band [rad/s].
    """

    name: str
    output: str
    input: str
    gain: float
    zeros: np.ndarray
    poles: np.ndarray
    delay_s: float
    cost: float
    parameters: dict
    cramer_rao: dict
    cramer_rao_pct: dict
    factors: list
    converged: bool
    message: str
    numerator: str = ""
    denominator: str = ""
    insensitivity_pct: dict = field(default_factory=dict)
    residual_variance: float = float("nan")
    fit_group: tuple = ()
    band_rad_s: tuple = ()

    def response(self, omega) -> np.ndarray:
        """Model response T(j omega) at ``omega`` [rad/s] (complex, output units per input unit)."""
        s = 1j * np.asarray(omega, float)
        T = np.full(s.shape, complex(self.gain))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for z in self.zeros:
                T = T * (s - z)
            for p in self.poles:
                T = T / (s - p)
            return T * np.exp(-s * self.delay_s)

    def to_tf(self, *, pade_order: int | None = None):
        """This fit as ``control.TransferFunction`` (needs python-control); the delay is left out
        unless ``pade_order`` is given. See :func:`livesweep.interop.transfer_function_to_tf`."""
        from livesweep.interop import transfer_function_to_tf

        return transfer_function_to_tf(self, pade_order=pade_order)

    def to_dict(self) -> dict:
        """The ``report.json`` entry (docs/outputs.md, report.json): roots as ``[re, im]`` pairs [rad/s]."""
        return {
            "name": self.name, "output": self.output, "input": self.input,
            "gain": _jsonf(self.gain),
            "zeros": [[_jsonf(z.real), _jsonf(z.imag)] for z in self.zeros],
            "poles": [[_jsonf(p.real), _jsonf(p.imag)] for p in self.poles],
            "delay_s": _jsonf(self.delay_s),
            "cost": _jsonf(self.cost),
            "numerator": self.numerator, "denominator": self.denominator,
            "parameters": {k: _jsonf(v) for k, v in self.parameters.items()},
            "cramer_rao": {k: _jsonf(v) for k, v in self.cramer_rao.items()},
            "cramer_rao_pct": {k: _jsonf(v) for k, v in self.cramer_rao_pct.items()},
            "insensitivity_pct": {k: _jsonf(v) for k, v in self.insensitivity_pct.items()},
            "residual_variance": _jsonf(self.residual_variance),
            "factors": [{k: (_jsonf(v) if isinstance(v, float) else v) for k, v in f.items()} for f in self.factors],
            "converged": bool(self.converged), "message": self.message,
            "fit_group": list(self.fit_group),
            "band_rad_s": [_jsonf(b) for b in self.band_rad_s],
        }


# ----------------------------------------------------------------------------- the problem


def _quad_roots(zeta: float, w: float) -> np.ndarray:
    d = np.sqrt(complex(zeta * zeta - 1.0))
    return np.array([-zeta * w + w * d, -zeta * w - w * d])


class _Problem:
    """Parameter layout and residuals of a (joint) fit.

    x = [shared denominator parameters] + per pair [gain, numerator parameters, tau (if delay)].
    A compiled factor is ``(kind, power, idx, fixed)``: ``idx`` holds an x index or -1 per value.
    """

    def __init__(self, pairs: list[PairData], models: list[TransferFunctionModel], tau_max: float):
        self.pairs, self.models = pairs, models
        self.keys: list[tuple] = []        # (pair index or None for shared, key)
        lo: list[float] = []
        hi: list[float] = []
        w_floor = 1e-6 * min(float(p.omega[0]) for p in pairs)

        def compile_structure(st: Structure, scope):
            out = []
            for f in st.factors:
                idx = []
                for j, key in enumerate(f.keys):
                    if key is None:
                        idx.append(-1)
                        continue
                    idx.append(len(self.keys))
                    self.keys.append((scope, key))
                    is_w = f.kind == "second" and j == 1
                    lo.append(w_floor if is_w else -np.inf)
                    hi.append(np.inf)
                out.append((f.kind, f.power, tuple(idx), f.fixed))
            return out

        self.den = compile_structure(models[0].denominator, None)
        self.n_den = len(self.keys)
        self.gain_idx, self.num, self.tau_idx, self.slices = [], [], [], []
        for p, m in enumerate(models):
            start = len(self.keys)
            self.gain_idx.append(len(self.keys))
            self.keys.append((p, "gain"))
            lo.append(-np.inf)
            hi.append(np.inf)
            self.num.append(compile_structure(m.numerator, p))
            if m.delay:
                self.tau_idx.append(len(self.keys))
                self.keys.append((p, "tau"))
                lo.append(0.0)
                hi.append(tau_max)
            else:
                self.tau_idx.append(-1)
            self.slices.append(slice(start, len(self.keys)))
        self.lower, self.upper = np.array(lo), np.array(hi)
        self.n = len(self.keys)
        self.n_resid = sum(2 * p.n_omega for p in pairs)

    # -- model

    @staticmethod
    def _factor(kind, power, idx, fixed, x, s, want_grad):
        vals = [x[i] if i >= 0 else fixed[j] for j, i in enumerate(idx)]
        if kind == "s":
            return s ** power, []
        if kind == "first":
            f = s + vals[0]
            return f, ([(idx[0], 1.0 / f)] if want_grad and idx[0] >= 0 else [])
        z, w = vals
        f = s * s + 2.0 * z * w * s + w * w
        g = []
        if want_grad:
            if idx[0] >= 0:
                g.append((idx[0], 2.0 * w * s / f))
            if idx[1] >= 0:
                g.append((idx[1], (2.0 * z * s + 2.0 * w) / f))
        return f, g

    def response(self, x, p, omega=None, want_grad=False):
        """T(j omega) of pair p and, optionally, d ln T / dx (complex, shape (n_omega, n))."""
        s = 1j * (self.pairs[p].omega if omega is None else np.asarray(omega, float))
        G = np.zeros((s.size, self.n), complex) if want_grad else None
        K = x[self.gain_idx[p]]
        T = np.full(s.shape, complex(K))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for sign, facs in ((1, self.num[p]), (-1, self.den)):
                for kind, power, idx, fixed in facs:
                    f, grads = self._factor(kind, power, idx, fixed, x, s, want_grad)
                    T = T * f if sign > 0 else T / f
                    for i, g in grads:
                        G[:, i] += sign * g
            if self.tau_idx[p] >= 0:
                T = T * np.exp(-s * x[self.tau_idx[p]])
                if want_grad:
                    G[:, self.tau_idx[p]] = -s
            if want_grad:
                G[:, self.gain_idx[p]] = 1.0 / K
        return T, G

    def _pair_resid(self, T, pair):
        if not np.all(np.isfinite(T)) or np.any(T == 0):
            return None
        return residuals(pair, T)

    def resid(self, x):
        out = []
        for p, pair in enumerate(self.pairs):
            T, _ = self.response(x, p)
            r = self._pair_resid(T, pair)
            out.append(np.full(2 * pair.n_omega, _BIG) if r is None else r)
        return np.concatenate(out)

    def jac(self, x):
        """dr/dx: the model's d ln T mapped through the cost's residual function, whose magnitude block
        depends on Re ln T and phase block on Im ln T point by point (read off with a tiny step, exact
        because the map is linear in ln T)."""
        rows = []
        for p, pair in enumerate(self.pairs):
            T, G = self.response(x, p, want_grad=True)
            n = pair.n_omega
            r0 = self._pair_resid(T, pair)
            if r0 is None:
                rows.append(np.zeros((2 * n, self.n)))
                continue
            a = (residuals(pair, T * np.exp(_EPS_CAL)) - r0) / _EPS_CAL
            b = (residuals(pair, T * np.exp(1j * _EPS_CAL)) - r0) / _EPS_CAL
            k = np.concatenate([np.arange(n), np.arange(n)])
            Jp = a[:, None] * G.real[k] + b[:, None] * G.imag[k]
            rows.append(np.where(np.isfinite(Jp), Jp, 0.0))
        return np.vstack(rows)

    def cost(self, x) -> float:
        r = self.resid(x)
        return float(np.dot(r, r))

    def pair_costs(self, x) -> list[float]:
        out = []
        for p, pair in enumerate(self.pairs):
            T, _ = self.response(x, p)
            r = self._pair_resid(T, pair)
            out.append(float("inf") if r is None else float(np.dot(r, r)))
        return out

    # -- assembling a start from factor values

    def pack(self, den_vals, num_vals, gains, taus) -> np.ndarray:
        """x from per-factor value tuples (den shared, num per pair), gains and delays per pair."""
        x = np.zeros(self.n)
        for facs, vals in [(self.den, den_vals)] + [(self.num[p], num_vals[p]) for p in range(len(self.pairs))]:
            for (kind, power, idx, fixed), v in zip(facs, vals):
                for i, val in zip(idx, v):
                    if i >= 0:
                        x[i] = val
        for p in range(len(self.pairs)):
            x[self.gain_idx[p]] = gains[p]
            if self.tau_idx[p] >= 0:
                x[self.tau_idx[p]] = taus[p]
        return np.clip(x, self.lower, self.upper)


# ----------------------------------------------------------------------------- starting values


def _data(pair: PairData) -> np.ndarray:
    return 10.0 ** (pair.magnitude_db / 20.0) * np.exp(1j * np.deg2rad(pair.phase_deg))


def _fixed_product(facs, s):
    """Product of the s powers and the fully fixed factors at s."""
    out = np.ones(s.shape, complex)
    for kind, power, idx, fixed in facs:
        if kind == "s":
            out = out * s ** power
        elif all(i < 0 for i in idx):
            if kind == "first":
                out = out * (s + fixed[0])
            else:
                out = out * (s * s + 2 * fixed[0] * fixed[1] * s + fixed[1] ** 2)
    return out


def _free_factors(facs):
    return [(k, idx) for k, (kind, power, idx, fixed) in enumerate(facs)
            if kind != "s" and any(j >= 0 for j in idx)]


def _n_free_roots(facs) -> int:
    return sum(1 if facs[k][0] == "first" else 2 for k, _ in _free_factors(facs))


def _match_roots(roots, facs) -> list[tuple]:
    """Per-factor values for ``facs`` (compiled) from polynomial roots [rad/s]; non-free factors keep
    their fixed values. Surplus complex pairs become two real roots of the same modulus, surplus real
    roots are paired into quadratics (zeta may exceed 1)."""
    free = _free_factors(facs)
    n1 = sum(1 for k, _ in free if facs[k][0] == "first")
    n2 = len(free) - n1
    roots = np.asarray(roots, complex)
    roots = roots[np.isfinite(roots)]
    is_real = np.abs(roots.imag) <= 1e-8 * (np.abs(roots) + 1e-12)
    reals = sorted((float(r) for r in roots[is_real].real), key=abs)
    quads = [(-r.real / abs(r), abs(r)) for r in sorted(roots[~is_real & (roots.imag > 0)], key=abs)]
    while len(quads) > n2 and len(reals) < n1:
        z, w = max(quads, key=lambda q: q[0])
        quads.remove((z, w))
        reals += [-w if z >= 0 else w] * 2
    reals.sort(key=abs)
    while len(reals) > n1 and len(reals) >= 2 and len(quads) < n2:
        r1, r2 = reals.pop(0), reals.pop(0)
        w = math.sqrt(max(abs(r1 * r2), 1e-12))
        quads.append((-(r1 + r2) / (2 * w), w))
    quads.sort(key=lambda q: q[1])
    # pad (deficient polynomial degree) with values spread high
    while len(reals) < n1:
        reals.append(-(abs(reals[-1]) * 3 if reals else 1.0))
    while len(quads) < n2:
        quads.append((0.7, quads[-1][1] * 3 if quads else 1.0))
    vals = [tuple(f[3]) if f[0] != "s" else () for f in facs]
    it1, it2 = iter(reals), iter(quads)
    for k, _ in free:
        kind, power, idx, fixed = facs[k]
        if kind == "first":
            v = (-next(it1),)
        else:
            v = next(it2)
        vals[k] = tuple(fixed[j] if idx[j] < 0 else v[j] for j in range(len(idx)))
    return vals


def _factor_values_poly(facs, vals, s):
    """Value of the free factors' product at s, given per-factor values."""
    out = np.ones(s.shape, complex)
    for k, _ in _free_factors(facs):
        v = vals[k]
        if facs[k][0] == "first":
            out = out * (s + v[0])
        else:
            out = out * (s * s + 2 * v[0] * v[1] * s + v[1] ** 2)
    return out


def _sk_fit(prob: _Problem, tau: float, n_iter: int = 8):
    """Sanathanan-Koerner fit of data = B_p(s)/A(s) (A shared, monic; fixed factors, s powers and the
    delay guess divided out). Returns the den roots and the numerator roots per pair [rad/s]."""
    na = _n_free_roots(prob.den)
    omegas = [p.omega for p in prob.pairs]
    w0 = math.sqrt(min(o[0] for o in omegas) * max(o[-1] for o in omegas))
    Y, S, W, nb = [], [], [], []
    for p, pair in enumerate(prob.pairs):
        s = 1j * pair.omega
        tau_p = tau if prob.tau_idx[p] >= 0 else 0.0
        with np.errstate(all="ignore"):
            y = _data(pair) * np.exp(s * tau_p) * _fixed_product(prob.den, s) / _fixed_product(prob.num[p], s)
        Y.append(y)
        S.append(s / w0)
        W.append(np.sqrt(pair.weight))
        nb.append(_n_free_roots(prob.num[p]))
    n_unk = na + sum(b + 1 for b in nb)
    a = np.zeros(na)
    A_prev = [np.ones(len(y), complex) for y in Y]
    b_all = None
    for _ in range(n_iter):
        rows, rhs = [], []
        col = na
        for p, (y, sp, wp) in enumerate(zip(Y, S, W)):
            wt = wp / np.maximum(np.abs(y * A_prev[p]), 1e-300)
            M = np.zeros((len(y), n_unk), complex)
            for i in range(na):
                M[:, i] = y * sp ** i
            for j in range(nb[p] + 1):
                M[:, col + j] = -sp ** j
            col += nb[p] + 1
            r = -y * sp ** na
            rows.append(wt[:, None] * M)
            rhs.append(wt * r)
        M = np.vstack(rows)
        r = np.concatenate(rhs)
        Mr = np.vstack([M.real, M.imag])
        rr = np.concatenate([r.real, r.imag])
        if not (np.all(np.isfinite(Mr)) and np.all(np.isfinite(rr))):
            return None
        sol, *_ = np.linalg.lstsq(Mr, rr, rcond=None)
        a, b_all = sol[:na], sol[na:]
        A_prev = [np.polyval(np.concatenate([[1.0], a[::-1]]), sp) for sp in S]
    den_roots = np.roots(np.concatenate([[1.0], a[::-1]])) * w0 if na else np.array([])
    num_roots, col = [], 0
    for p in range(len(prob.pairs)):
        b = b_all[col:col + nb[p] + 1]
        col += nb[p] + 1
        num_roots.append(np.roots(b[::-1]) * w0 if nb[p] and np.any(b[1:] != 0) else np.array([]))
    return den_roots, num_roots


def _num_given_den(prob: _Problem, p: int, den_vals, tau: float):
    """Numerator roots of pair p by weighted linear least squares with the denominator and delay fixed."""
    pair = prob.pairs[p]
    s = 1j * pair.omega
    nb = _n_free_roots(prob.num[p])
    if nb == 0:
        return np.array([])
    w0 = math.sqrt(pair.omega[0] * pair.omega[-1])
    tau_p = tau if prob.tau_idx[p] >= 0 else 0.0
    with np.errstate(all="ignore"):
        den = _fixed_product(prob.den, s) * _factor_values_poly(prob.den, den_vals, s)
        y = _data(pair) * den * np.exp(s * tau_p) / _fixed_product(prob.num[p], s)
    wt = np.sqrt(pair.weight) / np.maximum(np.abs(y), 1e-300)
    sp = s / w0
    M = np.column_stack([sp ** j for j in range(nb + 1)]) * wt[:, None]
    rhs = y * wt
    Mr, rr = np.vstack([M.real, M.imag]), np.concatenate([rhs.real, rhs.imag])
    if not (np.all(np.isfinite(Mr)) and np.all(np.isfinite(rr))):
        return np.array([])
    b, *_ = np.linalg.lstsq(Mr, rr, rcond=None)
    return np.roots(b[::-1]) * w0 if np.any(b[1:] != 0) else np.array([])


def _gain_from_data(prob: _Problem, x: np.ndarray, p: int) -> float:
    """Gain magnitude from the weighted mean dB offset, sign from the weighted circular-mean phase offset
    (a negative gain is a 180 deg offset)."""
    pair = prob.pairs[p]
    x1 = x.copy()
    x1[prob.gain_idx[p]] = 1.0
    T1, _ = prob.response(x1, p)
    with np.errstate(all="ignore"):
        dmag = pair.magnitude_db - 20.0 * np.log10(np.abs(T1))
        dph = np.deg2rad(pair.phase_deg) - np.angle(T1)
    ok = np.isfinite(dmag) & np.isfinite(dph)
    if not np.any(ok):
        return 1.0
    w = pair.weight[ok]
    mag = 10.0 ** (np.sum(w * dmag[ok]) / np.sum(w) / 20.0)
    sign = 1.0 if np.real(np.sum(w * np.exp(1j * dph[ok]))) >= 0 else -1.0
    return sign * (mag if np.isfinite(mag) and mag > 0 else 1.0)


def _complete(prob: _Problem, den_vals, tau: float) -> np.ndarray:
    num_vals = [_match_roots(_num_given_den(prob, p, den_vals, tau), prob.num[p]) for p in range(len(prob.pairs))]
    taus = [tau] * len(prob.pairs)
    x = prob.pack(den_vals, num_vals, [1.0] * len(prob.pairs), taus)
    for p in range(len(prob.pairs)):
        x[prob.gain_idx[p]] = _gain_from_data(prob, x, p)
    return x


def _grid_den_candidates(prob: _Problem):
    """Denominator values from break frequencies log-spread over the band (shifted x1/3, x1, x3),
    every arrangement of first-order/quadratic kinds over the ascending slots (at most 6), damping 0.3/0.7."""
    free = _free_factors(prob.den)
    lo = min(p.omega[0] for p in prob.pairs)
    hi = max(p.omega[-1] for p in prob.pairs)
    if not free:
        return [[tuple(f[3]) if f[0] != "s" else () for f in prob.den]]
    kinds = [prob.den[k][0] for k, _ in free]
    arrangements = sorted(set(itertools.permutations(kinds)))[:6]
    m = len(free)
    out = []
    for shift in (1.0, 1.0 / 3.0, 3.0):
        slots = lo * (hi / lo) ** ((np.arange(m) + 0.5) / m) * shift
        for arr in arrangements:
            for zeta in (0.3, 0.7):
                firsts = [w for w, k in zip(slots, arr) if k == "first"]
                seconds = [w for w, k in zip(slots, arr) if k == "second"]
                roots = [-w for w in firsts] + [r for w in seconds for r in _quad_roots(zeta, w)]
                out.append(_match_roots(np.array(roots), prob.den))
    return out


def _auto_starts(prob: _Problem, tau_max: float) -> list[np.ndarray]:
    top = max(p.omega[-1] for p in prob.pairs)
    has_delay = any(i >= 0 for i in prob.tau_idx)
    taus = sorted({min(t, tau_max) for t in ((0.0, 0.5 / top, 1.0 / top) if has_delay else (0.0,))})
    starts = []
    for tau in taus:
        sk = _sk_fit(prob, tau)
        if sk is None:
            continue
        den_roots, num_roots = sk
        den_vals = _match_roots(den_roots, prob.den)
        starts.append(_complete(prob, den_vals, tau))
    for den_vals in _grid_den_candidates(prob):
        for tau in taus:
            starts.append(_complete(prob, den_vals, tau))
    return starts


# ----------------------------------------------------------------------------- fitting


def _canonical(prob: _Problem, x: np.ndarray) -> np.ndarray:
    """Same-kind, fully free factors of a structure in ascending |root| frequency, in the written order."""
    x = x.copy()
    for facs in [prob.den] + prob.num:
        for kind in ("first", "second"):
            grp = [idx for (k, power, idx, fixed) in facs if k == kind and all(i >= 0 for i in idx)]
            if len(grp) < 2:
                continue
            vals = [x[list(idx)].copy() for idx in grp]
            vals.sort(key=(lambda v: abs(v[0])) if kind == "first" else (lambda v: v[1]))
            for idx, v in zip(grp, vals):
                x[list(idx)] = v
    return x


def _covariance(J: np.ndarray):
    """H^-1 with H = 2 J^T J; parameters in an (almost) null direction get inf."""
    H = 2.0 * J.T @ J
    n = H.shape[0]
    d = np.sqrt(np.clip(np.diag(H), 1e-300, None))
    Hs = H / np.outer(d, d)                                # scale-free for the rank decision
    ev, V = np.linalg.eigh(Hs)
    tol = max(ev.max(), 1e-300) * 1e-12
    good = ev > tol
    Cs = (V[:, good] / ev[good]) @ V[:, good].T
    C = Cs / np.outer(d, d)
    bad = np.zeros(n, bool)
    if not np.all(good):
        bad = np.any(np.abs(V[:, ~good]) > 1e-3, axis=1)
    var = np.diag(C).copy()
    var[bad] = np.inf
    return np.sqrt(np.clip(var, 0.0, None)), np.diag(H)


def _parse_user_start(prob: _Problem, names: list[str], spec: Mapping, base: np.ndarray) -> np.ndarray:
    """x from a user start: ``key`` sets that parameter wherever it exists, ``"<tf name>.<key>"`` only in
    that transfer function; the rest comes from ``base``; each gain not given is read from the data."""
    x = base.copy()
    gain_given = set()
    for k_full, v in spec.items():
        tf, _, key = str(k_full).rpartition(".")
        try:
            val = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"start value {k_full!r} must be a number, got {v!r}") from None
        hit = False
        for i, (scope, key_i) in enumerate(prob.keys):
            if key_i != key or (tf and not (tf in names and (scope is None or names[scope] == tf))):
                continue
            x[i] = val
            hit = True
            if key == "gain":
                gain_given.add(scope)
        if not hit:
            raise ConfigError(f"start value {k_full!r} names no parameter of the fit "
                              f"(parameters: {sorted({k for _, k in prob.keys})})")
    x = np.clip(x, prob.lower, prob.upper)
    for p in range(len(prob.pairs)):
        if p not in gain_given:
            x[prob.gain_idx[p]] = _gain_from_data(prob, x, p)
    return x


def fit_transfer_function(pairs, models, *, starts: Sequence[Mapping] | None = None, auto_starts: bool = True,
                          n_refine: int = 8, n_polish: int = 2, tau_max_s: float = np.inf,
                          sort_factors: bool = True, max_nfev: int = 2000) -> list[FittedTransferFunction]:
    """Fit gain, zeros, poles and delay to one pair, or to several pairs with a shared denominator.

    Parameters
    ----------
    pairs : PairData, FrequencyResponse or list of them
        The data (a FrequencyResponse is reduced with :func:`livesweep.ident.cost.fit_points` defaults).
    models : TransferFunctionModel or list of them
        One model (used for every pair; with several pairs the results are named
        ``<name>_<output>_<input>``) or one per pair, all with the same denominator (shared:
        Tischler & Remple's Eq. 2.7); each pair has its own gain, numerator and delay.
    starts : list of mapping, optional
        Extra starting values, key -> value (keys as in ``parameters``; ``"<tf name>.<key>"`` for one
        transfer function only). Missing keys are taken from the best automatic start; the gain,
        unless given, is read from the data.
    auto_starts : bool
        Also use the automatic starts: Sanathanan-Koerner (iterated Levy) rational fits for delay
        guesses 0, 0.5/w_top, 1/w_top; denominators with break frequencies log-spread over the band
        (three shifts, every first/second-order arrangement, damping 0.3/0.7) with the numerators
        solved linearly from the data; the gain from the data's mean dB offset and its sign from
        the phase offset.
    n_refine, n_polish : int
        The ``n_refine`` starts of lowest initial cost get a short optimisation; the best
        ``n_polish`` of those are run to convergence; the best result is kept.
    tau_max_s : float
        Upper bound on the delay [s] (lower bound 0).
    sort_factors : bool
        Report same-kind free factors of a structure in ascending root frequency in the written
        order (write them slowest first, e.g. ``"(1/Ts) (1/Tr)"``).
    max_nfev : int
        Function-evaluation limit of the final optimisation.

    Returns
    -------
    list of FittedTransferFunction
        One per pair, in order.

    Raises
    ------
    ConfigError
        Mismatched pairs/models, different denominators, a model whose output/input do not match
        its pair, bad start values.
    """
    if isinstance(pairs, (PairData, FrequencyResponse)):
        pairs = [pairs]
    pairs = [fit_points(p) if isinstance(p, FrequencyResponse) else p for p in pairs]
    if not pairs:
        raise ConfigError("fit_transfer_function: no pairs to fit")
    for p in pairs:
        if not isinstance(p, PairData):
            raise ConfigError(f"fit_transfer_function: pairs must be PairData or FrequencyResponse, got {type(p).__name__}")
    if isinstance(models, TransferFunctionModel):
        if len(pairs) == 1:
            models, names = [models], [models.name]
        else:
            names = [f"{models.name}_{p.output}_{p.input}" for p in pairs]
            models = [models] * len(pairs)
    else:
        models = list(models)
        if len(models) != len(pairs):
            raise ConfigError(f"fit_transfer_function: {len(models)} models for {len(pairs)} pairs (give one, or one per pair)")
        names = [m.name for m in models]
        if len(set(names)) != len(names):
            raise ConfigError(f"fit_transfer_function: model names must differ, got {names}")
    for m, p in zip(models, pairs):
        if m.denominator != models[0].denominator:
            raise ConfigError(f"transfer function {m.name!r}: denominator {str(m.denominator)!r} differs from "
                              f"{models[0].name!r}'s {str(models[0].denominator)!r}; a joint fit shares one denominator")
        if (m.output is not None and m.output != p.output) or (m.input is not None and m.input != p.input):
            raise ConfigError(f"transfer function {m.name!r} is for {m.output}/{m.input}, but its pair is {p.output}/{p.input}")
    tau_max = float(tau_max_s)
    if not tau_max >= 0:
        raise ConfigError(f"tau_max_s must be >= 0, got {tau_max_s!r}")
    prob = _Problem(pairs, models, tau_max)

    cands: list[tuple[float, np.ndarray, bool]] = []
    all_keys = {k for _, k in prob.keys}
    need_auto = auto_starts or any(not all_keys <= {str(k).rpartition(".")[2] for k in spec} | {"gain"}
                                   for spec in starts or [])
    auto = _auto_starts(prob, tau_max) if need_auto else []
    auto_scored = sorted(((prob.cost(x), i) for i, x in enumerate(auto)), key=lambda t: t[0])
    if auto_starts:
        cands += [(c, auto[i], False) for c, i in auto_scored]
    base = auto[auto_scored[0][1]] if auto_scored else prob.pack(
        [tuple(f[3]) for f in prob.den], [[tuple(f[3]) for f in n] for n in prob.num], [1.0] * len(pairs),
        [0.0] * len(pairs))
    for spec in starts or []:
        x = _parse_user_start(prob, names, spec, base)
        cands.append((prob.cost(x), x, True))
    if not cands:
        raise ConfigError("fit_transfer_function: no starting values (auto_starts=False and no starts)")

    def run(x0, nfev):
        x0 = np.clip(x0, prob.lower, prob.upper)
        try:
            return least_squares(prob.resid, x0, jac=prob.jac, bounds=(prob.lower, prob.upper), x_scale="jac",
                                 method="trf", max_nfev=nfev, xtol=1e-10, ftol=1e-10, gtol=1e-10)
        except (ValueError, np.linalg.LinAlgError):
            return None

    chosen = [x for c, x, user in cands if user]
    chosen += [x for c, x, user in sorted((t for t in cands if not t[2]), key=lambda t: t[0])[:max(1, n_refine)]]
    short = []
    for x0 in chosen:
        r = run(x0, 40 * (prob.n + 1))
        if r is not None and np.isfinite(r.cost):
            short.append((2 * r.cost, r.x))
    if not short:
        short = [(c, x) for c, x, _ in cands]
    short.sort(key=lambda t: t[0])
    best = None
    for _, x0 in short[:max(1, n_polish)]:
        r = run(x0, max_nfev)
        if r is not None and (best is None or r.cost < best.cost):
            best = r
    if best is None:
        x, success, msg = short[0][1], False, "optimiser failed from every start"
    else:
        x, success, msg = best.x, bool(best.success), str(best.message)
    if sort_factors:
        x = _canonical(prob, x)

    J = prob.jac(x)
    cr, Hdiag = _covariance(J)
    total = prob.cost(x)
    dof = max(prob.n_resid - prob.n, 1)
    resid_var = total / dof
    costs = prob.pair_costs(x)
    if not np.all(np.isfinite(cr)):
        bad = [f"{k}" for (sc, k), c in zip(prob.keys, cr) if not np.isfinite(c)]
        msg += f"; not identifiable (CR undefined): {', '.join(sorted(set(bad)))}"
    converged = success and math.isfinite(total)
    return [_result(prob, p, names, x, cr, Hdiag, costs[p], resid_var, converged, msg) for p in range(len(pairs))]


def _result(prob, p, names, x, cr, Hdiag, cost, resid_var, converged, msg) -> FittedTransferFunction:
    m, pair = prob.models[p], prob.pairs[p]
    params, crs, crp, insp = {}, {}, {}, {}
    idxs = list(range(prob.n_den)) + list(range(prob.slices[p].start, prob.slices[p].stop))
    for i in idxs:
        key = prob.keys[i][1]
        v = float(x[i])
        params[key] = v
        crs[key] = float(cr[i])
        with np.errstate(divide="ignore", invalid="ignore"):
            crp[key] = float(100.0 * cr[i] / abs(v)) if v != 0 else float("inf")
            ins = 1.0 / math.sqrt(Hdiag[i]) if Hdiag[i] > 0 else float("inf")
            insp[key] = float(100.0 * ins / abs(v)) if v != 0 else float("inf")
    factors, zeros, poles = [], [], []
    for where, facs, st, roots in (("numerator", prob.num[p], m.numerator, zeros),
                                   ("denominator", prob.den, m.denominator, poles)):
        for (kind, power, idx, fixed), f in zip(facs, st.factors):
            vals = [float(x[i]) if i >= 0 else float(fixed[j]) for j, i in enumerate(idx)]
            if kind == "s":
                factors.append({"where": where, "kind": "s", "power": power})
                roots += [0j] * power
            elif kind == "first":
                a = vals[0]
                factors.append({"where": where, "kind": "first", "name": f.names[0], "inverse_time_constant": a,
                                "time_constant_s": (1.0 / a) if a != 0 else float("inf"), "fixed": idx[0] < 0})
                roots.append(complex(-a))
            else:
                z, w = vals
                factors.append({"where": where, "kind": "second", "names": list(f.names), "zeta": z, "omega": w,
                                "fixed": [i < 0 for i in idx]})
                roots += list(_quad_roots(z, w))
    tau = float(x[prob.tau_idx[p]]) if prob.tau_idx[p] >= 0 else 0.0
    return FittedTransferFunction(
        name=names[p], output=pair.output, input=pair.input, gain=float(x[prob.gain_idx[p]]),
        zeros=_frozen(np.array(zeros, complex)), poles=_frozen(np.array(poles, complex)), delay_s=tau,
        cost=float(cost), parameters=params, cramer_rao=crs, cramer_rao_pct=crp, factors=factors,
        converged=bool(converged), message=msg, numerator=str(m.numerator), denominator=str(m.denominator),
        insensitivity_pct=insp, residual_variance=float(resid_var), fit_group=tuple(names),
        band_rad_s=tuple(float(b) for b in pair.band_rad_s))
