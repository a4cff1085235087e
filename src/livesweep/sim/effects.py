"""The simulator's injectable effects: the catalogue of :mod:`livesweep.effects` (one definition
per kind, shared with the residual loop), re-exported under the simulator's name."""

from livesweep.effects import (EFFECT_KINDS, ActuatorLag, ActuatorSecondOrder, Dropouts, Effect, NotchFilter,
                               ScaleFactor, SensorBias, SensorSkew, Spikes, StructuralMode, TimeDelay, make_effect,
                               parse_effect)

__all__ = ["Effect", "TimeDelay", "ActuatorLag", "ActuatorSecondOrder", "NotchFilter", "StructuralMode", "SensorSkew",
           "ScaleFactor", "SensorBias", "Spikes", "Dropouts", "EFFECT_KINDS", "parse_effect", "make_effect"]
