"""The ``[state_space]`` table as the residual loop changes it.

The loop adds an effect by writing it into the case's table, as a user would (new states,
parameters, delays: :meth:`~livesweep.effects.Effect.augment`), and keeps each fit's values in the
table it refits from next.
"""

from __future__ import annotations

import copy

from livesweep.effects import EFFECT_KINDS, SEARCHED_KINDS, Candidate
from livesweep.effects.table import normalised
from livesweep.errors import ConfigError
from livesweep.ident.state_space import StateSpaceFit

__all__ = ["KINDS", "table_with_fit", "augment_table"]

#: The kinds the loop looks for (the catalogue's searched kinds).
KINDS = SEARCHED_KINDS


def table_with_fit(table: dict, fit: StateSpaceFit) -> dict:
    """A copy of ``table`` whose parameter values (and fixed flags) are the fit's."""
    t = copy.deepcopy(table)
    t["parameters"] = {n: {"value": float(v), **({"fixed": True} if f else {})}
                       for n, v, f in zip(fit.model.parameters, fit.theta, fit.model.fixed)}
    return t


def augment_table(table: dict, candidate: Candidate) -> tuple[dict, list[str]]:
    """The ``[state_space]`` table with ``candidate``'s effect added.

    Returns
    -------
    table : dict
        A new table (the input is not modified).
    new_parameters : list of str
        Names of the parameters the effect added (or freed).
    """
    cls = EFFECT_KINDS.get(candidate.kind)
    if cls is None or not cls.searched:
        raise ConfigError(f"unknown effect kind {candidate.kind!r}; known: {', '.join(KINDS)}")
    return cls.augment(normalised(table), candidate.where, dict(candidate.parameters))
