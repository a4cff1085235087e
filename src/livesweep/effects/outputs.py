"""Effects between the vehicle and the logged measurement: structural modes and sensor errors.

In the simulator they act in the order skew -> dynamics -> scale -> bias -> noise -> spikes ->
dropouts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from livesweep.effects.base import Effect, ParameterRole, check_number
from livesweep.effects.inputs import _delay_slope, resonance_screen
from livesweep.effects.table import add_parameter, add_state, product
from livesweep.errors import ConfigError

__all__ = ["StructuralMode", "SensorSkew", "ScaleFactor", "SensorBias", "Spikes", "Dropouts"]


@dataclass(frozen=True)
class StructuralMode(Effect):
    """A lightly damped structural mode seen by one sensor, in the dipole form of the flight-test
    literature: a pole pair and a zero pair at nearby frequencies with their own dampings,

    ``k (s^2 + 2 zeta_zero w_z s + w_z^2) / (s^2 + 2 zeta_pole w s + w^2)``, ``k = w^2/w_z^2``

    (unity at low frequency). ``omega_zero_rad_s`` = 0 puts the zero at the pole's frequency
    ``omega_rad_s``; then the peak is ``zeta_zero/zeta_pole`` at ``w`` (a notch when < 1) and the
    factor tends to 1 at both ends.

    Residual signature (the residual loop looks for the zero at the pole's frequency, the form
    a few frequency points per decade can support): ``1 + g 2 zeta w s/(s^2 + 2 zeta w s + w^2)``
    on one output's pairs, i.e. ``zeta_pole = zeta``, ``zeta_zero = zeta (1 + g)``; frequency and
    damping on a grid, ``g`` linear. Added as states ``mode_``/``moderate_<output>`` driven by the
    output, with ``w_mode_``, ``zeta_mode_`` (pole) and ``zeta_zero_mode_<output>``.
    """
    parameter_roles = (ParameterRole("w_mode", "frequency", "rad/s"),
                       ParameterRole("zeta_mode", "damping", "-"),
                       ParameterRole("zeta_zero_mode", "damping", "-"))

    output: str
    omega_rad_s: float
    zeta_pole: float
    zeta_zero: float
    omega_zero_rad_s: float = 0.0
    kind: ClassVar[str] = "structural_mode"
    acts_on: ClassVar[str] = "output"
    dynamics: ClassVar[str] = "output_block"
    searched: ClassVar[bool] = True
    places: ClassVar[tuple] = ("output",)
    n_parameters: ClassVar[int] = 3

    def __post_init__(self):
        check_number(self.kind, "omega_rad_s", self.omega_rad_s, positive=True, upper=1e4)
        check_number(self.kind, "zeta_pole", self.zeta_pole, positive=True, upper=1.0)
        check_number(self.kind, "zeta_zero", self.zeta_zero, positive=True, upper=5.0)
        check_number(self.kind, "omega_zero_rad_s", self.omega_zero_rad_s, nonneg=True, upper=1e4)

    @property
    def _wz(self) -> float:
        return self.omega_zero_rad_s or self.omega_rad_s

    def frequency_response(self, omega_rad_s):
        s = 1j * np.asarray(omega_rad_s, dtype=float)
        w, wz = self.omega_rad_s, self._wz
        return (w / wz) ** 2 * (s**2 + 2 * self.zeta_zero * wz * s + wz**2) / (s**2 + 2 * self.zeta_pole * w * s + w**2)

    def state_space(self):
        """(A, B, C, D) of the whole factor (direct term included)."""
        w, wz, zp, zz = self.omega_rad_s, self._wz, self.zeta_pole, self.zeta_zero
        k = (w / wz) ** 2
        A = np.array([[0.0, 1.0], [-(w**2), -2 * zp * w]])
        C = np.array([[k * (wz**2 - w**2), k * (2 * zz * wz - 2 * zp * w)]])
        return A, np.array([[0.0], [1.0]]), C, np.array([[k]])

    @classmethod
    def screen(cls, space, place, select):
        w, z, g, ev = resonance_screen(space, select)
        return {"omega_rad_s": w, "zeta_pole": z, "zeta_zero": z * (1.0 + g)}, ev

    @classmethod
    def augment(cls, t, where, par):
        o = t["outputs"].index(where)
        w = add_parameter(t, cls.parameter_name("w_mode", where), par["omega_rad_s"])
        zp = add_parameter(t, cls.parameter_name("zeta_mode", where), par["zeta_pole"])
        zz = add_parameter(t, cls.parameter_name("zeta_zero_mode", where), par["zeta_zero"])
        h_row, j_row = list(t["H"][o]), list(t["J"][o])
        x, v = add_state(t, [f"mode_{where}", f"moderate_{where}"])
        for c, e in enumerate(h_row):
            t["F"][v][c] = e
        t["F"][x][v] = "1"
        t["F"][v][x] = f"-{w}*{w}"
        t["F"][v][v] = f"-2*{zp}*{w}"
        t["G"][v] = j_row
        t["H"][o][v] = f"2*({zz}-{zp})*{w}"
        return t, [w, zp, zz]


@dataclass(frozen=True)
class SensorSkew(Effect):
    """The sensor's sample is taken ``delay_s`` before its time stamp: ``exp(-s delay_s)``.

    Residual signature: phase linear in frequency on one output's pairs only (a lag), or a lead
    on every pair of one input (the input is logged late). Added as the output's
    ``output_delays`` or the input's ``input_skews`` parameter ``skew_<name>`` [s].
    """
    parameter_roles = (ParameterRole("skew", "delay", "s"),)

    output: str
    delay_s: float
    kind: ClassVar[str] = "sensor_skew"
    acts_on: ClassVar[str] = "output"
    searched: ClassVar[bool] = True
    places: ClassVar[tuple] = ("input", "output")
    n_parameters: ClassVar[int] = 1

    def __post_init__(self):
        if check_number(self.kind, "delay_s", self.delay_s, upper=1.0) == 0:
            raise ConfigError(f"effect {self.kind}: delay_s must be non-zero")

    def frequency_response(self, omega_rad_s):
        return np.exp(-1j * np.asarray(omega_rad_s, dtype=float) * self.delay_s)

    @classmethod
    def screen(cls, space, place, select):
        model = space.model
        a, ev = _delay_slope(space, select)
        if place in model.inputs:
            if a < 0 and model.input_skews.get(place) not in space.free_names:
                return {"delay_s": -a}, ev
            return None
        if a > 0 and model.output_delays.get(place) not in space.free_names:
            return {"delay_s": a}, ev
        return None

    @classmethod
    def augment(cls, t, where, par):
        if where in t["inputs"]:
            name = add_parameter(t, cls.parameter_name("skew", where), par["delay_s"])
            t.setdefault("input_skews", {})[where] = name
            delay = (t.get("delays") or {}).get(where)
            if isinstance(delay, str) and delay in t["parameters"] and not t["parameters"][delay].get("fixed"):
                # only the net delay tau - skew is identifiable: a delay the fit held at 0 stays there
                if abs(float(t["parameters"][delay].get("value", 0.0))) <= 1e-6:
                    t["parameters"][delay] = {"value": 0.0, "fixed": True}
            return t, [name]
        cur = (t.get("output_delays") or {}).get(where)
        if isinstance(cur, str) and cur in t["parameters"]:
            t["parameters"][cur] = {"value": float(t["parameters"][cur].get("value", 0.0)) + par["delay_s"]}
            return t, [cur]
        name = add_parameter(t, cls.parameter_name("skew", where), par["delay_s"])
        t.setdefault("output_delays", {})[where] = name
        return t, [name]


@dataclass(frozen=True)
class ScaleFactor(Effect):
    """Sensor scale factor: measurement = ``factor`` x truth (1.1 = +10 % error).

    Residual signature: a constant dB offset on one output's pairs. Added as ``k_<output>``
    multiplying the output's rows of H and J. Often absorbed by the derivatives (a rescaled
    state): then the loop reports it as not identifiable rather than guessing.
    """
    parameter_roles = (ParameterRole("k", "gain", "-"),)

    output: str
    factor: float
    kind: ClassVar[str] = "scale_factor"
    acts_on: ClassVar[str] = "output"
    searched: ClassVar[bool] = True
    places: ClassVar[tuple] = ("output",)
    n_parameters: ClassVar[int] = 1

    def __post_init__(self):
        check_number(self.kind, "factor", self.factor, positive=True, upper=100.0)

    def frequency_response(self, omega_rad_s):
        return np.full(np.shape(omega_rad_s), complex(self.factor))

    @classmethod
    def screen(cls, space, place, select):
        a, ev = space.linear(space.signature(lambda w: np.ones_like(w, dtype=complex), select))
        return {"factor": float(math.exp(a))}, ev

    @classmethod
    def sensitivity(cls, space, place, select):
        return space.sensitivity(space.signature(lambda w: np.ones_like(w, dtype=complex), select))

    @classmethod
    def augment(cls, t, where, par):
        o = t["outputs"].index(where)
        name = add_parameter(t, cls.parameter_name("k", where), par["factor"])
        t["H"][o] = [product(name, e) for e in t["H"][o]]
        t["J"][o] = [product(name, e) for e in t["J"][o]]
        return t, [name]


@dataclass(frozen=True)
class SensorBias(Effect):
    """Constant sensor bias ``bias`` in output units (no dynamic effect)."""

    output: str
    bias: float
    kind: ClassVar[str] = "sensor_bias"
    acts_on: ClassVar[str] = "output"
    linear: ClassVar[bool] = False

    def __post_init__(self):
        check_number(self.kind, "bias", self.bias)


@dataclass(frozen=True)
class Spikes(Effect):
    """Wild points: ``+/- magnitude`` (output units) at Poisson-distributed samples, ``rate_hz`` per s."""

    output: str
    rate_hz: float
    magnitude: float
    kind: ClassVar[str] = "spikes"
    acts_on: ClassVar[str] = "output"
    linear: ClassVar[bool] = False

    def __post_init__(self):
        check_number(self.kind, "rate_hz", self.rate_hz, positive=True, upper=100.0)
        check_number(self.kind, "magnitude", self.magnitude, positive=True)


@dataclass(frozen=True)
class Dropouts(Effect):
    """``count`` gaps of ``duration_s`` seconds where the sensor delivers no samples."""

    output: str
    count: int
    duration_s: float
    kind: ClassVar[str] = "dropouts"
    acts_on: ClassVar[str] = "output"
    linear: ClassVar[bool] = False

    def __post_init__(self):
        c = check_number(self.kind, "count", self.count, positive=True, upper=10000)
        if c != int(c):
            raise ConfigError(f"effect {self.kind}: count must be a whole number, got {self.count!r}")
        object.__setattr__(self, "count", int(c))
        check_number(self.kind, "duration_s", self.duration_s, positive=True, upper=600.0)
