"""Units of a state-space model's parameters, from the states' units (the case's
``[state_space.units]``) and the signals' units.

A parameter that is the whole entry of a matrix element gets the element's units:

- ``F[i][j]`` (``x_i' = ... + F_ij x_j``): units of ``x_i`` per second over units of ``x_j``;
- ``G[i][j]``: units of ``x_i`` per second over units of input ``j``;
- ``H[i][j]``, ``J[i][j]``: units of output ``i`` over units of state ``j`` / input ``j``;
- ``M[i][j]``: units of ``x_i`` over units of ``x_j``;
- delays, output delays and input skews: s.

A parameter the residual loop added has the units its effect declares
(:attr:`livesweep.effects.Effect.parameter_roles`). Anything else (a parameter only inside an
expression) has no units here (None).
"""

from __future__ import annotations

from livesweep.effects import parameter_role

__all__ = ["parameter_units", "rate_of", "ratio"]

_DIMENSIONLESS = {"", "1", "-"}


def _norm(unit: str) -> str:
    return unit.strip().replace("^2", "²").replace("^3", "³").replace("**2", "²")


def rate_of(unit: str) -> str:
    """Units of the time derivative: ``rad`` -> ``rad/s``, ``ft/s`` -> ``ft/s²``, ``1`` -> ``1/s``."""
    u = _norm(unit)
    if u in _DIMENSIONLESS:
        return "1/s"
    if u.endswith("/s²"):
        return u[:-3] + "/s³"
    if u.endswith("/s"):
        return u[:-2] + "/s²"
    return f"{u}/s"


def ratio(num: str, den: str) -> str:
    """``num`` over ``den``, simplified where one cancels: ``(rad/s²)/(rad/s)`` -> ``1/s``."""
    a, b = _norm(num), _norm(den)
    if b in _DIMENSIONLESS:
        return a or "-"
    if a == b:
        return "-"
    if a == rate_of(b):
        return "1/s"
    if a in _DIMENSIONLESS:
        return f"1/({b})" if "/" in b else f"1/{b}"
    wrap = (lambda u: f"({u})" if "/" in u or " " in u else u)
    return f"{wrap(a)}/{wrap(b)}"


def parameter_units(table: dict, signal_units: dict) -> dict:
    """Units of each parameter of a ``[state_space]`` table.

    Parameters
    ----------
    table : dict
        The table (``states``, ``inputs``, ``outputs``, matrices of entry strings, ``parameters``,
        ``delays``, ``output_delays``, ``input_skews``, ``units``).
    signal_units : dict of str -> str
        Units of the case's signals (the model's inputs and outputs are signals).

    Returns
    -------
    dict of str -> str or None
        Parameter name -> units text; None when the units cannot be told (a state without
        declared units, or a parameter only inside an expression).
    """
    states, inputs, outputs = list(table["states"]), list(table["inputs"]), list(table["outputs"])
    su = dict(table.get("units") or {})
    params = list((table.get("parameters") or {}).keys())
    rows = {"M": (states, states), "F": (states, states), "G": (states, inputs), "H": (outputs, states),
            "J": (outputs, inputs)}

    def unit_of(kind: str, name: str):
        if kind == "state":
            return su.get(name)
        return signal_units.get(name)

    out: dict = {}
    for key in ("F", "G", "M", "H", "J"):
        row_names, col_names = rows[key]
        row_kind = "state" if key in ("M", "F", "G") else "signal"
        col_kind = "state" if key in ("M", "F", "H") else "signal"
        for i, row in enumerate(table.get(key) or []):
            for j, entry in enumerate(row):
                text = str(entry).strip().lstrip("-+").strip()
                if text not in params or text in out:
                    continue
                ru, cu = unit_of(row_kind, row_names[i]), unit_of(col_kind, col_names[j])
                if ru is None or cu is None:
                    continue
                out[text] = ratio(rate_of(ru) if key in ("F", "G") else ru, cu)
    for key in ("delays", "output_delays", "input_skews"):
        for v in (table.get(key) or {}).values():
            if isinstance(v, str) and v in params:
                out.setdefault(v, "s")
    for name in params:
        if name not in out:           # a parameter an effect added: the units its effect declares
            role = parameter_role(name)
            out[name] = role.unit if role is not None else None
    return out
