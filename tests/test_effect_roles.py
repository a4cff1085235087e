"""Every parameter an effect adds to a model declares its role and units where the effect is
defined: the report's units, the residual loop's choice of what may be fixed and its band check
read the declaration, never the name. Judged against the effects' own physics: a frequency in
rad/s, a damping or depth dimensionless, a delay in s, a scale factor dimensionless."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from livesweep.effects import EFFECT_KINDS, SEARCHED_KINDS, Effect, ParameterRole, parameter_role
from livesweep.effects.table import normalised
from livesweep.ident.residual import FIXABLE_ROLES, FREQUENCY_ROLES
from livesweep.report.units import parameter_units

ROOT = Path(__file__).resolve().parents[1]

#: Each searched kind's augment parameters (the screening's names) and where it acts.
ADD = {"time_delay": ("da", {"delay_s": 0.05}), "actuator_lag": ("da", {"time_constant_s": 0.05}),
       "actuator_second_order": ("da", {"omega_rad_s": 30.0, "zeta": 0.6}),
       "notch_filter": ("dr", {"omega_rad_s": 12.0, "zeta": 0.3, "depth": 0.8}),
       "structural_mode": ("p", {"omega_rad_s": 25.0, "zeta_pole": 0.05, "zeta_zero": 0.1}),
       "sensor_skew": ("p", {"delay_s": 0.03}), "scale_factor": ("p", {"factor": 1.1})}
#: What each role's units are, from physics.
UNITS = {"frequency": "rad/s", "damping": "-", "shape": "-", "delay": "s", "gain": "-"}


def _table():
    """The cruise model without its own input delays (so a time delay adds its parameter)."""
    t = normalised(tomllib.loads((ROOT / "config" / "xv15_cruise_lateral.toml").read_text())["state_space"])
    for name in (t.pop("delays", None) or {}).values():
        t["parameters"].pop(name, None)
    return t


@pytest.mark.parametrize("kind", [k for k in SEARCHED_KINDS if k != "missing_derivative"])
def test_every_parameter_an_effect_adds_has_a_declared_role_and_units(kind):
    assert kind in ADD, f"{kind}: add its augment parameters to this test"
    cls = EFFECT_KINDS[kind]
    t = _table()
    before = set(t["parameters"])
    where, par = ADD[kind]
    _, names = cls.augment(t, where, par)
    added = set(t["parameters"]) - before
    assert added and added == set(names), kind
    declared = {r.name(where): r for r in cls.parameter_roles}
    units = parameter_units(t, {"da": "deg", "dr": "deg", "p": "deg/s", "r": "deg/s", "ay": "ft/s^2",
                                "beta": "deg"})
    for name in added:
        assert name in declared, f"{kind} adds {name}, which it does not declare"
        role = parameter_role(name)
        assert role == declared[name]
        assert role.unit == UNITS[role.role] and units[name] == UNITS[role.role], name
    # what the residual loop may fix, and what it checks against the band, follow the roles
    assert {r.role for r in cls.parameter_roles if r.role in FREQUENCY_ROLES} <= {"frequency"}
    assert not set(FIXABLE_ROLES) & {"frequency", "delay", "gain"}


def test_an_undeclared_parameter_is_refused_and_a_bad_role_too():
    class Gremlin(Effect):
        kind = "gremlin"
        acts_on = "input"
        parameter_roles = (ParameterRole("g_grem", "gain", "-"),)

    assert Gremlin.parameter_name("g_grem", "da") == "g_grem_da"
    with pytest.raises(KeyError, match="gremlin"):
        Gremlin.parameter_name("w_grem", "da")
    with pytest.raises(ValueError, match="role"):
        ParameterRole("x", "colour", "-")
    assert parameter_role("Lp") is None and parameter_role("zeta_zero_mode_p").stem == "zeta_zero_mode"
