"""What a test point's model must show before the next point of the envelope: limits and predictions.

Two tables of a case or a channel map, read into frozen settings (docs/case-file.md):

* ``[limits]`` (:class:`EnvelopeLimits`): a minimum phase and gain margin (of a broken-loop pair),
  a band the bandwidth must lie in, a damping floor, a largest delay, and how far a prediction may
  be from the data. Every limit is off unless set, except the prediction's, which is the method's
  own cost guideline (J <= 100: a model that describes the data, docs/method.md §7.2).
* ``[predictions.NAME]`` (:class:`Prediction`): the transfer function the aircraft was predicted
  to have for one pair (from a simulation, a wind-tunnel model or an earlier flight), in the
  factored shorthand of ``[transfer_functions]`` with every value given.

Pure: no I/O. The monitor checks each test point's model against them
(:mod:`livesweep.ident.test_point_model`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.ident.accuracy import MAX_COST
from livesweep.ident.transfer_function_structure import Structure, parse_structure
from livesweep import limits
from livesweep.settings_schema import Check, integer, names, number, setting, string

__all__ = ["EnvelopeLimits", "Prediction", "ModelSettings", "NO_LIMITS", "NO_MODEL_SETTINGS", "structure_response"]


def _band_check() -> Check:
    def convert(value):
        if not (isinstance(value, list) and len(value) == 2):
            raise ValueError("must be [low, high] in rad/s")
        lo, hi = (number(0.0, lo_open=True).convert(v) for v in value)
        if not lo < hi:
            raise ValueError("must be [low, high] with low < high")
        return (lo, hi)

    return Check(convert, "[low, high], 0 < low < high")


@dataclass(frozen=True)
class EnvelopeLimits:
    """``[limits]``: what each test point's model must show (off unless set).

    Attributes
    ----------
    min_phase_margin_deg : float or None
        Smallest phase margin [deg] of a broken-loop pair (``broken_loop``).
    min_gain_margin_db : float or None
        Smallest gain margin [dB] of a broken-loop pair.
    bandwidth_rad_s : (float, float) or None
        The band [rad/s] the bandwidth of every attitude or rate pair must lie in.
    min_damping : float or None
        Damping floor [-] of every second-order denominator factor of a fitted model.
    max_delay_s : float or None
        Largest equivalent delay [s] of a fitted model.
    max_prediction_cost : float
        Largest cost J of a pair's prediction against its measured response over the model's
        band (the method's J <= 100 for a model that describes the data).
    broken_loop : tuple of str
        Pairs ``"output/input"`` whose response is a broken-loop one (the margins are read there).
    """

    min_phase_margin_deg: float | None = setting(None, number(0.0, 180.0), "smallest phase margin of a broken-loop "
                                                 "pair", units="deg", default_text="none")
    min_gain_margin_db: float | None = setting(None, number(0.0), "smallest gain margin of a broken-loop pair",
                                               units="dB", default_text="none")
    bandwidth_rad_s: tuple | None = setting(None, _band_check(), "the band the bandwidth of every attitude or rate "
                                            "pair must lie in", units="rad/s", default_text="none")
    min_damping: float | None = setting(None, number(-1.0, 2.0), "damping floor of every second-order denominator "
                                        "factor of a test point's model", default_text="none")
    max_delay_s: float | None = setting(None, number(0.0, lo_open=True), "largest equivalent delay of a test "
                                        "point's model", units="s", default_text="none")
    max_prediction_cost: float = setting(MAX_COST, number(0.0, lo_open=True),
                                         "largest cost J of a prediction against the measured response over the "
                                         "model's band (the method's J ≤ 100: a model that describes the data)")
    broken_loop: tuple = setting((), names("pairs"), "pairs `\"output/input\"` whose response is a broken-loop "
                                 "one: their crossover, phase and gain margins are read", default_text="none")

    def to_dict(self) -> dict:
        """The ``[limits]`` table (only the limits that are set, and the prediction's)."""
        d = {"max_prediction_cost": self.max_prediction_cost}
        for k in ("min_phase_margin_deg", "min_gain_margin_db", "min_damping", "max_delay_s"):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k)
        if self.bandwidth_rad_s is not None:
            d["bandwidth_rad_s"] = list(self.bandwidth_rad_s)
        if self.broken_loop:
            d["broken_loop"] = list(self.broken_loop)
        return d


NO_LIMITS = EnvelopeLimits()


def structure_response(gain: float, numerator: Structure, denominator: Structure, delay_s: float, omega) -> np.ndarray:
    """``K * prod(numerator) / prod(denominator) * e^(-tau s)`` at ``s = j omega`` for structures whose
    every value is fixed (complex, output units per input unit)."""
    s = 1j * np.asarray(omega, float)

    def product(st: Structure):
        out = np.ones(s.shape, complex)
        for f in st.factors:
            if f.kind == "s":
                out = out * s ** f.power
            elif f.kind == "first":
                out = out * (s + f.fixed[0])
            else:
                z, w = f.fixed
                out = out * (s * s + 2.0 * z * w * s + w * w)
        return out

    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return gain * product(numerator) / product(denominator) * np.exp(-s * float(delay_s))


def _state_space_check() -> Check:
    def matrix(name, value):
        if not (isinstance(value, list) and value and all(isinstance(r, list) and r for r in value)):
            raise ValueError(f"{name}: must be an array of rows (arrays of numbers)")
        if len({len(r) for r in value}) != 1:
            raise ValueError(f"{name}: rows of different lengths")
        if len(value) > limits.MAX_MODEL_DIMENSION or len(value[0]) > limits.MAX_MODEL_DIMENSION:
            raise ValueError(f"{name}: larger than {limits.MAX_MODEL_DIMENSION} x {limits.MAX_MODEL_DIMENSION}")
        out = []
        for r in value:
            out.append(tuple(number().convert(v) for v in r))
        return tuple(out)

    def convert(value):
        if not isinstance(value, dict) or set(value) != {"a", "b", "c", "d"}:
            raise ValueError("must be a table of the matrices a, b, c, d (arrays of rows)")
        m = {k: matrix(k, value[k]) for k in ("a", "b", "c", "d")}
        n, ni, no = len(m["a"]), len(m["b"][0]), len(m["c"])
        shapes = {"a": (n, n), "b": (n, ni), "c": (no, n), "d": (no, ni)}
        for k, (r, c) in shapes.items():
            if (len(m[k]), len(m[k][0])) != (r, c):
                raise ValueError(f"{k} is {len(m[k])} x {len(m[k][0])}, must be {r} x {c} (a is n x n, b n x inputs, "
                                 "c outputs x n, d outputs x inputs)")
        return m

    return Check(convert, "table of matrices a, b, c, d")


@dataclass(frozen=True)
class Prediction:
    """``[predictions.NAME]``: the response predicted for one pair, every value given: a transfer
    function in the factored shorthand, or a state-space model.

    Attributes
    ----------
    name : str
        The table's name.
    output, input : str
        The pair (signals of the map or case).
    gain : float or None
        K of the factored form (output units per input unit times s^(relative degree)); None with
        ``state_space``.
    numerator, denominator : str
        Factors in the shorthand of ``[transfer_functions]`` with numbers, e.g. ``"[0.7, 25]"``
        for ``s^2 + 35 s + 625``, ``"(1/0.1)"`` for ``s + 10``.
    state_space : dict or None
        ``{"a", "b", "c", "d"}``: matrices (tuples of rows) of ``x' = A x + B u``, ``y = C x + D u``;
        the pair is output ``row`` over input ``column``.
    row, column : int
        Which output and input of ``state_space`` the pair is (0-based).
    delay_s : float
        Equivalent delay [s].
    """

    name: str = setting(key=False)
    output: str = setting(check=string(nonempty=True), doc="the pair's output signal")
    input: str = setting(check=string(nonempty=True), doc="the pair's input signal")
    gain: float | None = setting(None, number(), "K of the factored form (output per input units × s^(relative "
                                 "degree)); required unless `state_space` is given", default_text="none")
    numerator: str = setting("", string(), "numerator factors with their values (the shorthand of "
                             "[transfer_functions])", default_text='"" (none)')
    denominator: str = setting("", string(), "denominator factors with their values", default_text='"" (none)')
    state_space: dict | None = setting(None, _state_space_check(), "instead of the factors: the matrices `a`, `b`, "
                                       "`c`, `d` (arrays of rows) of x′ = A x + B u, y = C x + D u",
                                       default_text="none")
    row: int = setting(0, integer(0, limits.MAX_MODEL_DIMENSION - 1), "the output of `state_space` the pair is "
                       "(0-based)")
    column: int = setting(0, integer(0, limits.MAX_MODEL_DIMENSION - 1), "the input of `state_space` the pair is "
                          "(0-based)")
    delay_s: float = setting(0.0, number(0.0), "equivalent delay", units="s")

    def structures(self, where: str = "") -> tuple[Structure, Structure] | None:
        """The parsed numerator and denominator (None for a state-space prediction); ConfigError
        naming ``where`` when a value is missing or the two forms are mixed."""
        if self.state_space is not None:
            if self.gain is not None or self.numerator or self.denominator:
                raise ConfigError(f"{where}: give either state_space or gain with numerator and denominator, not both")
            ss = self.state_space
            if self.row >= len(ss["c"]) or self.column >= len(ss["b"][0]):
                raise ConfigError(f"{where}: row {self.row}, column {self.column} is outside the {len(ss['c'])} "
                                  f"outputs x {len(ss['b'][0])} inputs of state_space")
            return None
        out = []
        for key in ("numerator", "denominator"):
            try:
                st = parse_structure(getattr(self, key))
            except ConfigError as e:
                raise ConfigError(f"{where}.{key}: {e}") from None
            free = [k for f in st.factors for k in f.keys if k is not None]
            if free:
                raise ConfigError(f"{where}.{key}: a prediction gives every value; {free[0]!r} is a name, got "
                                  f"{getattr(self, key)!r}")
            out.append(st)
        if self.gain is None or not math.isfinite(self.gain) or self.gain == 0:
            raise ConfigError(f"{where}.gain: must be a finite, non-zero number (or give state_space), got {self.gain!r}")
        return out[0], out[1]

    def response(self, omega) -> np.ndarray:
        """The predicted response at ``omega`` [rad/s] (complex)."""
        st = self.structures(f"predictions.{self.name}")
        w = np.asarray(omega, float)
        if st is not None:
            return structure_response(self.gain, st[0], st[1], self.delay_s, w)
        A, B, C, D = (np.asarray(self.state_space[k], float) for k in ("a", "b", "c", "d"))
        eye = np.eye(A.shape[0])
        b, c = B[:, self.column], C[self.row]
        H = np.array([c @ np.linalg.solve(1j * x * eye - A, b) for x in w.ravel()], complex).reshape(w.shape)
        return (H + D[self.row, self.column]) * np.exp(-1j * w * self.delay_s)

    def to_dict(self) -> dict:
        """The ``[predictions.NAME]`` table."""
        d = {"output": self.output, "input": self.input, "delay_s": self.delay_s}
        if self.state_space is not None:
            return {**d, "state_space": {k: [list(r) for r in v] for k, v in self.state_space.items()},
                    "row": self.row, "column": self.column}
        return {**d, "gain": self.gain, "numerator": self.numerator, "denominator": self.denominator}


@dataclass(frozen=True)
class ModelSettings:
    """What a test point's model is fitted with and held to (a map's or case's tables).

    Attributes
    ----------
    specs : tuple of TransferFunctionSpec
        ``[transfer_functions.*]``: the structure (and band) of a pair's model; a pair without one
        gets the low-order equivalent systems of :mod:`livesweep.ident.test_point_model`.
    predictions : tuple of Prediction
        ``[predictions.*]``.
    limits : EnvelopeLimits
        ``[limits]``.
    tables : dict
        The ``transfer_functions`` tables as written (what a recording keeps for its replay).
    """

    specs: tuple = ()
    predictions: tuple = ()
    limits: EnvelopeLimits = NO_LIMITS
    tables: dict | None = None

    def to_dict(self) -> dict:
        """The tables a map would hold (``transfer_functions``, ``predictions``, ``limits``), only those set."""
        out = {}
        if self.tables:
            out["transfer_functions"] = self.tables
        if self.predictions:
            out["predictions"] = {p.name: p.to_dict() for p in self.predictions}
        if self.limits != NO_LIMITS:
            out["limits"] = self.limits.to_dict()
        return out


NO_MODEL_SETTINGS = ModelSettings()
