"""Effects between the logged control command and the vehicle: delay, actuators, filters."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from livesweep.effects.base import Effect, ParameterRole, check_number
from livesweep.effects.table import add_parameter, add_state, product, route_input
from livesweep.errors import ConfigError

__all__ = ["TimeDelay", "ActuatorLag", "ActuatorSecondOrder", "NotchFilter", "resonance", "resonance_screen",
           "ZETA_ACT_GRID"]

#: Damping ratios the screening grid of a second-order actuator tries.
ZETA_ACT_GRID = (0.3, 0.5, 0.7, 1.0)
#: Damping ratios the screening grids of resonant shapes (notch, structural mode) try.
ZETA_RES_GRID = (0.03, 0.06, 0.1, 0.2, 0.4)
#: Grid points per screened frequency range.
N_GRID = 48
#: Grid points (best linearised evidence first) whose gain is searched with the exact factor.
N_EXACT = 6
#: Multiples of the linearised gain tried there. A deep notch is not linear in its depth
#: (``ln(1 - 0.7) = -1.2``, not ``-0.7``, at its centre): the linearised evidence underrates it.
GAIN_STEPS = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0)


def resonance(omega_rad_s, w: float, z: float, gain: float, direct: float = 1.0):
    """``direct + gain 2 z w s/(s^2 + 2 z w s + w^2)`` at ``omega_rad_s`` [rad/s]: a notch
    (``gain`` < 0) or a resonance (``gain`` > 0) about ``w`` [rad/s]."""
    s = 1j * np.asarray(omega_rad_s, dtype=float)
    return direct + gain * 2 * z * w * s / (s**2 + 2 * z * w * s + w**2)


def resonance_ss(w: float, z: float, gain: float, direct: float = 1.0):
    """(A, B, C, D) of :func:`resonance`."""
    A = np.array([[0.0, 1.0], [-(w**2), -2 * z * w]])
    return A, np.array([[0.0], [1.0]]), np.array([[0.0, gain * 2 * z * w]]), np.array([[direct]])


def resonance_screen(space, select):
    """Best ``(w, zeta, gain)`` and evidence of ``1 + gain B(s)`` on the selected pairs, the
    bandpass ``B`` on a frequency x damping grid and the gain linear (``gain > -0.95``: the
    factor keeps its sign)."""
    lo, hi = space.band
    V, params = [], []
    for w0 in np.geomspace(lo, hi, N_GRID):
        for z in ZETA_RES_GRID:
            V.append(space.signature(lambda w, w0=w0, z=z: resonance(w, w0, z, 1.0, 0.0), select))
            params.append((float(w0), z))
    a, ev = space.linear_grid(np.column_stack(V))
    ev = np.where(a > -0.95, ev, -np.inf)
    best = (0.0, 0.0, 0.0, -np.inf)
    for k in np.argsort(-ev)[:N_EXACT]:
        if not np.isfinite(ev[k]):
            break
        w0, z = params[k]
        for m in GAIN_STEPS:
            g = max(float(a[k]) * m, -0.95)
            e = space.shape(space.signature(lambda w, w0=w0, z=z, g=g: np.log(resonance(w, w0, z, g)), select))
            if e > best[3]:
                best = (w0, z, g, e)
    return best[0], best[1], best[2], float(best[3])


def _delay_slope(space, select):
    """Best ``a`` of the signature ``-j w a`` (a pure delay, positive = lag) and its evidence."""
    return space.linear(space.signature(lambda w: -1j * w, select))


@dataclass(frozen=True)
class TimeDelay(Effect):
    """Extra pure time delay on an input: ``exp(-s delay_s)``, ``delay_s`` > 0 [s].

    Residual signature: phase growing linearly with frequency on every pair of the input,
    magnitude flat. Added to a model as (or onto) the input's delay parameter ``tau_<input>``.
    """
    parameter_roles = (ParameterRole("tau", "delay", "s"),)

    input: str
    delay_s: float
    kind: ClassVar[str] = "time_delay"
    acts_on: ClassVar[str] = "input"
    dynamics: ClassVar[str] = "delay"
    searched: ClassVar[bool] = True
    places: ClassVar[tuple] = ("input",)
    n_parameters: ClassVar[int] = 1

    def __post_init__(self):
        check_number(self.kind, "delay_s", self.delay_s, positive=True, upper=5.0)

    def frequency_response(self, omega_rad_s):
        return np.exp(-1j * np.asarray(omega_rad_s, dtype=float) * self.delay_s)

    @classmethod
    def screen(cls, space, place, select):
        a, ev = _delay_slope(space, select)
        if a > 0 and space.model.delays.get(place) not in space.free_names:
            return {"delay_s": a}, ev
        return None

    @classmethod
    def augment(cls, t, where, par):
        cur = (t.get("delays") or {}).get(where)
        start = par["delay_s"]
        if isinstance(cur, str) and cur in t["parameters"]:
            start += float(t["parameters"][cur].get("value", 0.0))
            t["parameters"][cur] = {"value": start}
            return t, [cur]
        if isinstance(cur, str) and cur in (t.get("constants") or {}):
            start += float(t["constants"][cur])
        elif isinstance(cur, (int, float)):
            start += float(cur)
        name = add_parameter(t, cls.parameter_name("tau", where), start)
        t.setdefault("delays", {})[where] = name
        return t, [name]


@dataclass(frozen=True)
class ActuatorLag(Effect):
    """First-order actuator between command and surface: ``1/(T s + 1)``, T = ``time_constant_s`` [s].

    Residual signature: ``w_a/(s + w_a)`` on every pair of the input, the corner ``w_a = 1/T``
    on a grid. Added as a state ``act_<input>`` with the parameter ``w_act_<input>`` [rad/s].
    """
    parameter_roles = (ParameterRole("w_act", "frequency", "rad/s"),)

    input: str
    time_constant_s: float
    kind: ClassVar[str] = "actuator_lag"
    acts_on: ClassVar[str] = "input"
    dynamics: ClassVar[str] = "input_block"
    searched: ClassVar[bool] = True
    places: ClassVar[tuple] = ("input",)
    n_parameters: ClassVar[int] = 1

    def __post_init__(self):
        check_number(self.kind, "time_constant_s", self.time_constant_s, positive=True, upper=10.0)

    def frequency_response(self, omega_rad_s):
        s = 1j * np.asarray(omega_rad_s, dtype=float)
        return 1.0 / (self.time_constant_s * s + 1.0)

    def state_space(self):
        """(A, B, C, D) of the actuator, unit DC gain."""
        T = self.time_constant_s
        return np.array([[-1.0 / T]]), np.array([[1.0 / T]]), np.array([[1.0]]), np.array([[0.0]])

    @classmethod
    def screen(cls, space, place, select):
        lo, hi = space.band
        grid = np.geomspace(lo / 2, 3 * hi, 60)
        evs = [space.shape(space.signature(lambda w, a=a: np.log(a / (1j * w + a)), select)) for a in grid]
        k = int(np.argmax(evs))
        return {"time_constant_s": float(1.0 / grid[k])}, evs[k]

    @classmethod
    def augment(cls, t, where, par):
        n0, j = len(t["states"]), t["inputs"].index(where)
        w = add_parameter(t, cls.parameter_name("w_act", where), 1.0 / par["time_constant_s"])
        (a,) = add_state(t, [f"act_{where}"])
        route_input(t, j, a, n0)
        t["F"][a][a] = f"-{w}"
        t["G"][a][j] = w
        return t, [w]


@dataclass(frozen=True)
class ActuatorSecondOrder(Effect):
    """Second-order actuator: ``w^2/(s^2 + 2 zeta w s + w^2)``, w = ``omega_rad_s`` [rad/s].

    Residual signature: that factor on every pair of the input, ``w`` and ``zeta`` on a grid.
    Added as states ``act_``/``actrate_<input>`` with ``wn_act_<input>`` [rad/s] and
    ``zeta_act_<input>``.
    """
    parameter_roles = (ParameterRole("wn_act", "frequency", "rad/s"), ParameterRole("zeta_act", "damping", "-"))

    input: str
    omega_rad_s: float
    zeta: float
    kind: ClassVar[str] = "actuator_second_order"
    acts_on: ClassVar[str] = "input"
    dynamics: ClassVar[str] = "input_block"
    searched: ClassVar[bool] = True
    places: ClassVar[tuple] = ("input",)
    n_parameters: ClassVar[int] = 2

    def __post_init__(self):
        check_number(self.kind, "omega_rad_s", self.omega_rad_s, positive=True, upper=1e4)
        check_number(self.kind, "zeta", self.zeta, positive=True, upper=5.0)

    def frequency_response(self, omega_rad_s):
        s = 1j * np.asarray(omega_rad_s, dtype=float)
        w, z = self.omega_rad_s, self.zeta
        return w**2 / (s**2 + 2 * z * w * s + w**2)

    def state_space(self):
        w, z = self.omega_rad_s, self.zeta
        A = np.array([[0.0, 1.0], [-(w**2), -2 * z * w]])
        return A, np.array([[0.0], [w**2]]), np.array([[1.0, 0.0]]), np.array([[0.0]])

    @classmethod
    def screen(cls, space, place, select):
        lo, hi = space.band
        best = (-np.inf, None)
        for wn in np.geomspace(lo, 3 * hi, 40):
            for z in ZETA_ACT_GRID:
                ev = space.shape(space.signature(
                    lambda w, wn=wn, z=z: np.log(wn**2 / ((1j * w) ** 2 + 2 * z * wn * 1j * w + wn**2)), select))
                if ev > best[0]:
                    best = (ev, {"omega_rad_s": float(wn), "zeta": z})
        return best[1], best[0]

    @classmethod
    def augment(cls, t, where, par):
        n0, j = len(t["states"]), t["inputs"].index(where)
        wn = add_parameter(t, cls.parameter_name("wn_act", where), par["omega_rad_s"])
        z = add_parameter(t, cls.parameter_name("zeta_act", where), par["zeta"])
        a, ad = add_state(t, [f"act_{where}", f"actrate_{where}"])
        route_input(t, j, a, n0)
        t["F"][a][ad] = "1"
        t["F"][ad][a] = f"-{wn}*{wn}"
        t["F"][ad][ad] = f"-2*{z}*{wn}"
        t["G"][ad][j] = f"{wn}*{wn}"
        return t, [wn, z]


@dataclass(frozen=True)
class NotchFilter(Effect):
    """Notch (or, with ``depth`` < 0, resonant) filter in a control path:
    ``1 - depth 2 zeta w s/(s^2 + 2 zeta w s + w^2)``.

    ``depth`` = 1 is the ideal notch ``(s^2 + w^2)/(s^2 + 2 zeta w s + w^2)`` (zero gain at
    ``omega_rad_s``); the magnitude at ``omega_rad_s`` is ``1 - depth``. Residual signature: that
    factor on every pair of the input (frequency and damping on a grid, depth linear). Added as
    states ``notch_``/``notchrate_<input>`` with ``w_notch_``, ``zeta_notch_``, ``depth_notch_<input>``.
    """
    parameter_roles = (ParameterRole("w_notch", "frequency", "rad/s"),
                       ParameterRole("zeta_notch", "damping", "-"),
                       ParameterRole("depth_notch", "shape", "-"))

    input: str
    omega_rad_s: float
    zeta: float
    depth: float
    kind: ClassVar[str] = "notch_filter"
    acts_on: ClassVar[str] = "input"
    dynamics: ClassVar[str] = "input_block"
    searched: ClassVar[bool] = True
    places: ClassVar[tuple] = ("input",)
    n_parameters: ClassVar[int] = 3

    def __post_init__(self):
        check_number(self.kind, "omega_rad_s", self.omega_rad_s, positive=True, upper=1e4)
        check_number(self.kind, "zeta", self.zeta, positive=True, upper=5.0)
        if not (isinstance(self.depth, (int, float)) and -10.0 <= self.depth <= 1.0 and self.depth != 0.0):
            raise ConfigError(f"{self.kind}: depth must be a number in [-10, 1] other than 0, got {self.depth!r}")

    def frequency_response(self, omega_rad_s):
        return resonance(omega_rad_s, self.omega_rad_s, self.zeta, -self.depth)

    def state_space(self):
        return resonance_ss(self.omega_rad_s, self.zeta, -self.depth)

    @classmethod
    def screen(cls, space, place, select):
        w, z, g, ev = resonance_screen(space, select)
        return {"omega_rad_s": w, "zeta": z, "depth": -g}, ev

    @classmethod
    def augment(cls, t, where, par):
        n0, j = len(t["states"]), t["inputs"].index(where)
        w = add_parameter(t, cls.parameter_name("w_notch", where), par["omega_rad_s"])
        z = add_parameter(t, cls.parameter_name("zeta_notch", where), par["zeta"])
        d = add_parameter(t, cls.parameter_name("depth_notch", where), par["depth"])
        x, v = add_state(t, [f"notch_{where}", f"notchrate_{where}"])
        gain = f"-2*{d}*{z}*{w}"
        for i in range(n0):
            t["F"][i][v] = product(t["G"][i][j], gain)
        for o in range(len(t["outputs"])):
            t["H"][o][v] = product(t["J"][o][j], gain)
        t["F"][x][v] = "1"
        t["F"][v][x] = f"-{w}*{w}"
        t["F"][v][v] = f"-2*{z}*{w}"
        t["G"][v][j] = "1"
        return t, [w, z, d]
