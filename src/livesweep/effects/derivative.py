"""A derivative the model lacks: a fixed parameter that should be free, or an absent entry."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from livesweep.effects.base import Candidate, Effect
from livesweep.effects.table import EFFECT_STATE_PREFIXES, add_entry, fresh, has_parameter, is_zero, normalised

__all__ = ["MissingDerivative", "derivative_slots"]


def _dynamic_rows(table, params) -> list[int]:
    """Vehicle state equations with at least one parameter (kinematic rows like phi' = p and the
    states of added effects are left alone)."""
    rows = []
    for i in range(len(table["states"])):
        if table["states"][i].startswith(EFFECT_STATE_PREFIXES):
            continue
        entries = list(table["F"][i]) + list(table["G"][i])
        if any(has_parameter(e, params) for e in entries):
            rows.append(i)
    return rows


def derivative_slots(table, model):
    """(parameter name, index or None, entry ``"F[i][j]"``) of the fixed parameters (delays and
    skews aside) and of the absent entries in the dynamic rows of F and G.

    An absent entry in the column of a kinematic state (a vehicle state whose row holds no
    parameter: phi' = p, theta' = q) is not a slot. Forces and moments do not depend on the
    attitude, which enters the force equations only through gravity, a known constant; and in a
    response estimated without references a pilot's attitude feedback biases the estimate in just
    that shape (a hover log with turbulence gains a "roll moment due to bank angle" F[p][phi] that
    halves J_ave with no effect in it).
    """
    params = set(table.get("parameters", {}))
    slots = []
    for n, f in zip(model.parameters, model.fixed):
        if f and not n.startswith(("tau", "skew")):
            slots.append((n, model.index(n), n))
    states, inputs = table["states"], table["inputs"]
    dynamic = _dynamic_rows(table, params)
    kinematic = {j for j, s in enumerate(states) if j not in dynamic and not s.startswith(EFFECT_STATE_PREFIXES)}
    for i in dynamic:
        for key, cols in (("F", states), ("G", inputs)):
            for j, e in enumerate(table[key][i]):
                if key == "F" and j in kinematic:
                    continue
                if is_zero(e) and not (key == "F" and states[j].startswith(EFFECT_STATE_PREFIXES)):
                    name = fresh(f"{key}_{states[i]}_{cols[j]}", params)
                    slots.append((name, None, f"{key}[{states[i]}][{cols[j]}]"))
    return slots


#: Multiples of the linearised step at which a missing derivative's evidence is evaluated exactly.
LINE_STEPS = (0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, -0.25, -0.5, -1.0, -2.0, -4.0, -8.0)


def _line_search(space, model, theta, k, a):
    """The step along parameter ``k`` (from ``theta``) among :data:`LINE_STEPS` times the linearised
    one ``a`` whose exact residual drops most, and that drop. The log response is not linear in a
    derivative: where the model's response to an input is small without it (a yaw control
    derivative the fit left out, J_ave in the hundreds), the linearised step is a fraction of the
    one the data ask for, and the linearised evidence a fraction of what the refit finds."""
    best = (a, -np.inf)
    th = np.array(theta, float)
    for m in LINE_STEPS:
        th[k] = theta[k] + m * a
        with np.errstate(all="ignore"):
            ev = space.evidence_at(model, th)
        if np.isfinite(ev) and ev > best[1]:
            best = (m * a, ev)
    return best if np.isfinite(best[1]) else (a, 0.0)


class MissingDerivative(Effect):
    """A stability or control derivative the model lacks (not simulated: a property of the model).

    Residual signature: the model's own sensitivity (log-response Jacobian) to the parameter,
    a fixed one freed or an absent entry of F or G given a new parameter ``F_<row>_<col>``.
    """

    kind: ClassVar[str] = "missing_derivative"
    acts_on: ClassVar[str] = "entry"
    searched: ClassVar[bool] = True
    n_parameters: ClassVar[int] = 1

    @classmethod
    def candidates(cls, space, table):
        from livesweep.ident.state_space import StateSpaceModel

        model, theta = space.model, space.theta
        out = []
        for name, k, target in derivative_slots(table, model):
            if k is not None:
                m2, th2, k2 = model, np.array(theta, float), k
            else:
                aug = normalised(table)
                add_entry(aug, target, name)
                m2 = StateSpaceModel.from_table(aug)
                th2 = np.array([theta[model.index(n)] if n in model.parameters else 0.0 for n in m2.parameters])
                k2 = m2.index(name)
            a, ev = space.linear(space.log_jacobian(m2, th2, k2))
            cur = float(th2[k2])
            if a != 0.0:
                a, ev = _line_search(space, m2, th2, k2, a)
            out.append(Candidate(cls.kind, name if k is not None else target, {"name": name, "value": cur + a}, ev,
                                 cls.n_parameters))
        return out

    @classmethod
    def augment(cls, t, where, par):
        name = par["name"]
        if name in t["parameters"]:
            t["parameters"][name] = {"value": float(par["value"])}
            return t, [name]
        return t, add_entry(t, where, name, par["value"])
