"""The effect catalogue: what a real aircraft and its instrumentation add to a nominal model.

One class per kind holds everything about it: its parameters, its frequency response (used by
the simulator), its residual signature and screening grid (used by the residual loop's
diagnosis) and how it augments a ``[state_space]`` table. Adding a kind means adding one class
to :data:`EFFECT_KINDS`.

A test or a user switches effects on by name with parameters, e.g.
``parse_effect("actuator_lag:input=da,time_constant_s=0.05")``.

==========================  ========  =====================================================
kind                        where     what
==========================  ========  =====================================================
``time_delay``              input     extra pure delay ``exp(-s delay_s)``
``actuator_lag``            input     ``1 / (time_constant_s s + 1)``
``actuator_second_order``   input     ``w^2 / (s^2 + 2 zeta w s + w^2)``
``notch_filter``            input     ``1 - depth 2 zeta w s / (s^2 + 2 zeta w s + w^2)``
``structural_mode``         output    dipole ``k (s^2 + 2 zeta_zero w_z s + w_z^2) /
                                      (s^2 + 2 zeta_pole w s + w^2)``
``sensor_skew``             output    sample taken ``delay_s`` before its time stamp
                                      (the residual loop also finds a late-logged input)
``scale_factor``            output    ``factor`` (e.g. 1.15 for a +15 % scale error)
``sensor_bias``             output    ``+ bias`` (output units)
``spikes``                  output    wild points: ``+/- magnitude`` at Poisson times
``dropouts``                output    ``count`` gaps of ``duration_s`` with no samples
``missing_derivative``      entry     a derivative the model lacks (residual loop only)
==========================  ========  =====================================================

Input effects act between the logged control command and the vehicle (the log records the
command, as SERVO_OUTPUT_RAW does). Output effects act between the vehicle and the logged
measurement.
"""

from __future__ import annotations

from dataclasses import MISSING, fields

from livesweep.effects.base import ROLES, Candidate, Effect, ParameterRole
from livesweep.effects.derivative import MissingDerivative
from livesweep.effects.inputs import ActuatorLag, ActuatorSecondOrder, NotchFilter, TimeDelay
from livesweep.effects.outputs import Dropouts, ScaleFactor, SensorBias, SensorSkew, Spikes, StructuralMode
from livesweep.errors import ConfigError

__all__ = [
    "Effect", "Candidate", "TimeDelay", "ActuatorLag", "ActuatorSecondOrder", "NotchFilter", "StructuralMode",
    "SensorSkew", "ScaleFactor", "SensorBias", "Spikes", "Dropouts", "MissingDerivative",
    "EFFECT_KINDS", "SEARCHED_KINDS", "parse_effect", "make_effect", "ParameterRole", "ROLES", "parameter_role",
]

#: Every kind, by name.
EFFECT_KINDS: dict[str, type[Effect]] = {
    cls.kind: cls
    for cls in (
        TimeDelay, ActuatorLag, ActuatorSecondOrder, NotchFilter, StructuralMode,
        SensorSkew, ScaleFactor, SensorBias, Spikes, Dropouts, MissingDerivative,
    )
}
#: The kinds the residual loop looks for, in catalogue order.
SEARCHED_KINDS: tuple[str, ...] = tuple(k for k, c in EFFECT_KINDS.items() if c.searched)

#: Every parameter stem an effect declares, longest first (``zeta_zero_mode`` before ``zeta_mode``).
_ROLES_BY_STEM = sorted({r.stem: r for c in EFFECT_KINDS.values() for r in c.parameter_roles}.values(),
                        key=lambda r: -len(r.stem))


def parameter_role(name: str) -> ParameterRole | None:
    """The declared role and units of a model parameter an effect added (``w_notch_da`` ->
    frequency, rad/s); None for a parameter no effect adds (a derivative, a case's own delay)."""
    return next((r for r in _ROLES_BY_STEM if name.startswith(r.stem + "_")), None)


def make_effect(kind: str, **params) -> Effect:
    """Build an effect by name; ConfigError naming the kind or parameter when wrong."""
    cls = EFFECT_KINDS.get(kind)
    if cls is None or cls.acts_on == "entry":
        known = [k for k, c in EFFECT_KINDS.items() if c.acts_on != "entry"]
        raise ConfigError(f"unknown effect {kind!r}; known effects: {', '.join(known)}")
    names = [f.name for f in fields(cls)]
    required = [f.name for f in fields(cls) if f.default is MISSING]
    unknown = sorted(set(params) - set(names))
    missing = [n for n in required if n not in params]
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
