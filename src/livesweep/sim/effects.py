"""Injectable effects: what a real aircraft and its instrumentation add to the nominal model.

A test or a user switches effects on by name with parameters, e.g.
``parse_effect("actuator_lag:input=da,time_constant_s=0.05")``. Each effect is exactly what its
name says; the LTI ones expose ``frequency_response(omega)``, the factor they multiply the
affected input column (input effects) or output row (output effects) of the response by.

==========================  ========  =====================================================
kind                        where     what
==========================  ========  =====================================================
``time_delay``              input     extra pure delay ``exp(-s delay_s)``
``actuator_lag``            input     ``1 / (time_constant_s s + 1)``
``actuator_second_order``   input     ``w^2 / (s^2 + 2 zeta w s + w^2)``
``structural_mode``         output    ``1 + gain 2 zeta w s / (s^2 + 2 zeta w s + w^2)``
                                      (a lightly damped mode: magnitude ``1 + gain`` at ``w``,
                                      unity at low and high frequency)
``sensor_skew``             output    sample taken ``delay_s`` before its time stamp,
                                      ``exp(-s delay_s)`` (negative: after)
``scale_factor``            output    ``factor`` (e.g. 1.15 for a +15 % scale error)
``sensor_bias``             output    ``+ bias`` (output units)
``spikes``                  output    wild points: ``+/- magnitude`` at Poisson times,
                                      ``rate_hz`` per second
``dropouts``                output    ``count`` gaps of ``duration_s`` with no samples
==========================  ========  =====================================================

Input effects act between the logged control command and the vehicle (the log records the
command, as SERVO_OUTPUT_RAW does). Output effects act between the vehicle and the logged
measurement, in the order skew -> dynamics -> scale -> bias -> noise -> spikes -> dropouts.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from livesweep.errors import ConfigError, require_number

__all__ = [
    "Effect",
    "TimeDelay",
    "ActuatorLag",
    "ActuatorSecondOrder",
    "NotchFilter",
    "StructuralMode",
    "SensorSkew",
    "ScaleFactor",
    "SensorBias",
    "Spikes",
    "Dropouts",
    "EFFECT_KINDS",
    "parse_effect",
    "make_effect",
]


def _num(kind, name, value, *, positive=False, nonneg=False, upper=None):
    return require_number(value, f"effect {kind}: {name}", positive=positive, nonnegative=nonneg, upper=upper)


class Effect:
    """Base of all effects. ``kind`` names it; ``target`` is the input or output it acts on."""

    kind: ClassVar[str]
    acts_on: ClassVar[str]  # "input" or "output"
    linear: ClassVar[bool] = True

    @property
    def target(self) -> str:
        return getattr(self, self.acts_on)

    def frequency_response(self, omega_rad_s) -> np.ndarray:
        """Complex factor the effect applies at ``omega_rad_s`` [rad/s] (1 where it has none)."""
        return np.ones(np.shape(omega_rad_s), dtype=complex)

    def as_dict(self) -> dict:
        """``{"kind": ..., <parameters>}``, the form written to logs and reports."""
        return {"kind": self.kind, **{f.name: getattr(self, f.name) for f in fields(self)}}


@dataclass(frozen=True)
class TimeDelay(Effect):
    """Extra pure time delay on an input: ``exp(-s delay_s)``, ``delay_s`` > 0 [s]."""

    input: str
    delay_s: float
    kind: ClassVar[str] = "time_delay"
    acts_on: ClassVar[str] = "input"

    def __post_init__(self):
        _num(self.kind, "delay_s", self.delay_s, positive=True, upper=5.0)

    def frequency_response(self, omega_rad_s):
        return np.exp(-1j * np.asarray(omega_rad_s, dtype=float) * self.delay_s)


@dataclass(frozen=True)
class ActuatorLag(Effect):
    """First-order actuator between command and surface: ``1/(T s + 1)``, T = ``time_constant_s`` [s]."""

    input: str
    time_constant_s: float
    kind: ClassVar[str] = "actuator_lag"
    acts_on: ClassVar[str] = "input"

    def __post_init__(self):
        _num(self.kind, "time_constant_s", self.time_constant_s, positive=True, upper=10.0)

    def frequency_response(self, omega_rad_s):
        s = 1j * np.asarray(omega_rad_s, dtype=float)
        return 1.0 / (self.time_constant_s * s + 1.0)

    def state_space(self):
        """(A, B, C, D) of the actuator, unit DC gain."""
        T = self.time_constant_s
        return np.array([[-1.0 / T]]), np.array([[1.0 / T]]), np.array([[1.0]]), np.array([[0.0]])


@dataclass(frozen=True)
class ActuatorSecondOrder(Effect):
    """Second-order actuator: ``w^2/(s^2 + 2 zeta w s + w^2)``, w = ``omega_rad_s`` [rad/s]."""

    input: str
    omega_rad_s: float
    zeta: float
    kind: ClassVar[str] = "actuator_second_order"
    acts_on: ClassVar[str] = "input"

    def __post_init__(self):
        _num(self.kind, "omega_rad_s", self.omega_rad_s, positive=True, upper=1e4)
        _num(self.kind, "zeta", self.zeta, positive=True, upper=5.0)

    def frequency_response(self, omega_rad_s):
        s = 1j * np.asarray(omega_rad_s, dtype=float)
        w, z = self.omega_rad_s, self.zeta
        return w**2 / (s**2 + 2 * z * w * s + w**2)

    def state_space(self):
        w, z = self.omega_rad_s, self.zeta
        A = np.array([[0.0, 1.0], [-(w**2), -2 * z * w]])
        return A, np.array([[0.0], [w**2]]), np.array([[1.0, 0.0]]), np.array([[0.0]])


def _resonance(omega_rad_s, w: float, z: float, gain: float, direct: float):
    """``direct + gain 2 z w s/(s^2 + 2 z w s + w^2)``: the frequency response of a notch
    (``gain`` < 0) or a resonance (``gain`` > 0) about ``w`` [rad/s]."""
    s = 1j * np.asarray(omega_rad_s, dtype=float)
    return direct + gain * 2 * z * w * s / (s**2 + 2 * z * w * s + w**2)


def _resonance_ss(w: float, z: float, gain: float, direct: float):
    """(A, B, C, D) of :func:`_resonance`."""
    A = np.array([[0.0, 1.0], [-(w**2), -2 * z * w]])
    return A, np.array([[0.0], [1.0]]), np.array([[0.0, gain * 2 * z * w]]), np.array([[direct]])


@dataclass(frozen=True)
class NotchFilter(Effect):
    """Notch (or, with ``depth`` < 0, resonant) filter in a control path:
    ``1 - depth 2 zeta w s/(s^2 + 2 zeta w s + w^2)``.

    ``depth`` = 1 is the ideal notch ``(s^2 + w^2)/(s^2 + 2 zeta w s + w^2)`` (zero gain at
    ``omega_rad_s``); the magnitude at ``omega_rad_s`` is ``1 - depth``.
    """

    input: str
    omega_rad_s: float
    zeta: float
    depth: float
    kind: ClassVar[str] = "notch_filter"
    acts_on: ClassVar[str] = "input"

    def __post_init__(self):
        _num(self.kind, "omega_rad_s", self.omega_rad_s, positive=True, upper=1e4)
        _num(self.kind, "zeta", self.zeta, positive=True, upper=5.0)
        if not (isinstance(self.depth, (int, float)) and -10.0 <= self.depth <= 1.0 and self.depth != 0.0):
            raise ConfigError(f"{self.kind}: depth must be a number in [-10, 1] other than 0, got {self.depth!r}")

    def frequency_response(self, omega_rad_s):
        return _resonance(omega_rad_s, self.omega_rad_s, self.zeta, -self.depth, 1.0)

    def state_space(self):
        return _resonance_ss(self.omega_rad_s, self.zeta, -self.depth, 1.0)


@dataclass(frozen=True)
class StructuralMode(Effect):
    """Lightly damped mode seen by one sensor: ``1 + gain 2 zeta w s/(s^2 + 2 zeta w s + w^2)``.

    The magnitude is ``1 + gain`` at ``omega_rad_s`` and tends to 1 away from it; the phase
    swings through zero at the mode. ``zeta`` is the mode damping ratio.
    """

    output: str
    omega_rad_s: float
    zeta: float
    gain: float
    kind: ClassVar[str] = "structural_mode"
    acts_on: ClassVar[str] = "output"

    def __post_init__(self):
        _num(self.kind, "omega_rad_s", self.omega_rad_s, positive=True, upper=1e4)
        _num(self.kind, "zeta", self.zeta, positive=True, upper=1.0)
        _num(self.kind, "gain", self.gain, positive=True, upper=100.0)

    def frequency_response(self, omega_rad_s):
        return _resonance(omega_rad_s, self.omega_rad_s, self.zeta, self.gain, 1.0)

    def state_space(self):
        """(A, B, C, D) of the additive part ``gain 2 zeta w s/(s^2 + 2 zeta w s + w^2)``."""
        return _resonance_ss(self.omega_rad_s, self.zeta, self.gain, 0.0)


@dataclass(frozen=True)
class SensorSkew(Effect):
    """The sensor's sample is taken ``delay_s`` before its time stamp: ``exp(-s delay_s)``."""

    output: str
    delay_s: float
    kind: ClassVar[str] = "sensor_skew"
    acts_on: ClassVar[str] = "output"

    def __post_init__(self):
        if _num(self.kind, "delay_s", self.delay_s, upper=1.0) == 0:
            raise ConfigError(f"effect {self.kind}: delay_s must be non-zero")

    def frequency_response(self, omega_rad_s):
        return np.exp(-1j * np.asarray(omega_rad_s, dtype=float) * self.delay_s)


@dataclass(frozen=True)
class ScaleFactor(Effect):
    """Sensor scale factor: measurement = ``factor`` x truth (1.1 = +10 % error)."""

    output: str
    factor: float
    kind: ClassVar[str] = "scale_factor"
    acts_on: ClassVar[str] = "output"

    def __post_init__(self):
        _num(self.kind, "factor", self.factor, positive=True, upper=100.0)

    def frequency_response(self, omega_rad_s):
        return np.full(np.shape(omega_rad_s), complex(self.factor))


@dataclass(frozen=True)
class SensorBias(Effect):
    """Constant sensor bias ``bias`` in output units (no dynamic effect)."""

    output: str
    bias: float
    kind: ClassVar[str] = "sensor_bias"
    acts_on: ClassVar[str] = "output"
    linear: ClassVar[bool] = False

    def __post_init__(self):
        _num(self.kind, "bias", self.bias)


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
        _num(self.kind, "rate_hz", self.rate_hz, positive=True, upper=100.0)
        _num(self.kind, "magnitude", self.magnitude, positive=True)


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
        c = _num(self.kind, "count", self.count, positive=True, upper=10000)
        if c != int(c):
            raise ConfigError(f"effect {self.kind}: count must be a whole number, got {self.count!r}")
        object.__setattr__(self, "count", int(c))
        _num(self.kind, "duration_s", self.duration_s, positive=True, upper=600.0)


EFFECT_KINDS: dict[str, type[Effect]] = {
    cls.kind: cls
    for cls in (
        TimeDelay, ActuatorLag, ActuatorSecondOrder, NotchFilter, StructuralMode,
        SensorSkew, ScaleFactor, SensorBias, Spikes, Dropouts,
    )
}


def make_effect(kind: str, **params) -> Effect:
    """Build an effect by name; ConfigError naming the kind or parameter when wrong."""
    cls = EFFECT_KINDS.get(kind)
    if cls is None:
        raise ConfigError(f"unknown effect {kind!r}; known effects: {', '.join(EFFECT_KINDS)}")
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(params) - set(names))
    missing = [n for n in names if n not in params]
    if unknown:
        raise ConfigError(f"effect {kind}: unknown parameter(s) {', '.join(unknown)}; expected {', '.join(names)}")
    if missing:
        raise ConfigError(f"effect {kind}: missing parameter(s) {', '.join(missing)}; expected {', '.join(names)}")
    return cls(**params)


def parse_effect(spec: str) -> Effect:
    """Parse ``"kind:key=value,key=value"``, e.g. ``"sensor_skew:output=p,delay_s=0.05"``."""
    kind, _, rest = spec.partition(":")
    params: dict[str, object] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise ConfigError(f"effect {spec!r}: expected key=value, got {item!r}")
        key = key.strip()
        value = value.strip()
        if key in ("input", "output"):
            params[key] = value
        else:
            try:
                params[key] = float(value)
            except ValueError:
                raise ConfigError(f"effect {kind.strip()}: {key} must be a number, got {value!r}") from None
    return make_effect(kind.strip(), **params)
