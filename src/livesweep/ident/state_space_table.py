"""The ``[state_space]`` table of a case, parsed and checked (docs/case-file.md; docs/method.md §8.1).

:func:`parse_table` turns the table into the fields of a
:class:`~livesweep.ident.state_space.StateSpaceModel`: signal names, matrix entries compiled by
:mod:`livesweep.ident.expression`, constants, parameters with their initial values and fixed
flags, delays per input and output [s], fitting bands [rad/s] and state units. Every message names
the key, entry and value at fault.
"""

from __future__ import annotations

import math

from livesweep.errors import ConfigError, check_band, quote
from livesweep.ident.expression import compile_entry
from livesweep.limits import MAX_MODEL_DIMENSION
from livesweep.numeric import frozen_array as _frozen

__all__ = ["parse_table"]

#: The model's matrices, in the order of ``M x' = F x + G u``, ``y = H x + J u``.
_MATRICES = ("M", "F", "G", "H", "J")
#: The keys a ``[state_space]`` table may hold.
_TABLE_KEYS = {"states", "inputs", "outputs", "M", "F", "G", "H", "J", "constants", "parameters", "delays", "output_delays",
               "input_skews", "bands", "units"}


def _names(table, key, where, required=True):
    raw = table.get(key)
    if raw is None:
        if required:
            raise ConfigError(f"{where}{key}: missing (a list of signal names)")
        return ()
    if not isinstance(raw, (list, tuple)) or not raw or not all(isinstance(n, str) and n for n in raw):
        raise ConfigError(f"{where}{key} = {quote(raw)}: must be a non-empty list of names")
    if len(raw) > MAX_MODEL_DIMENSION:
        raise ConfigError(f"{where}{key}: {len(raw)} names; a model has at most {MAX_MODEL_DIMENSION}")
    dup = sorted({n for n in raw if list(raw).count(n) > 1})
    if dup:
        raise ConfigError(f"{where}{key} = {quote(raw)}: repeated name(s) {', '.join(dup)}")
    return tuple(raw)


def _shape_of(raw, name, rows, cols, row_what, col_what, where):
    if not isinstance(raw, (list, tuple)):
        raise ConfigError(f"{where}{name}: must be a list of rows (lists of strings), got {raw!r}")
    if len(raw) != rows:
        raise ConfigError(f"{where}{name} has {len(raw)} rows, expected {rows} (one per {row_what})")
    for i, row in enumerate(raw):
        if not isinstance(row, (list, tuple)):
            raise ConfigError(f"{where}{name}[{i}] = {row!r}: must be a list of entries")
        if len(row) != cols:
            raise ConfigError(f"{where}{name}[{i}] has {len(row)} entries, expected {cols} (one per {col_what})")


def _parse_delays(table, key, names_of, what, constants, parameters, w):
    """``delays`` / ``output_delays``: per input/output, a parameter or constant name or seconds."""
    raw_d = table.get(key, {}) or {}
    if not isinstance(raw_d, dict):
        raise ConfigError(f"{w}{key} = {raw_d!r}: must be a table of {what} = delay parameter")
    for name in raw_d:
        if name not in names_of:
            raise ConfigError(f"{w}{key}.{name}: not an {what} ({what}s: {', '.join(names_of)})")
    delays, dentries = {}, []
    for name in names_of:
        val = raw_d.get(name)
        if val is None:
            delays[name] = None
            dentries.append(compile_entry("0", constants, parameters, f"{w}{key}.{name}"))
            continue
        if isinstance(val, str) and val.strip() not in parameters and val.strip() not in constants:
            raise ConfigError(f"{w}{key}.{name} = {val!r}: unknown name (must be a parameter or constant "
                              "name, or a number of seconds)")
        if not isinstance(val, str) and (isinstance(val, bool) or not isinstance(val, (int, float)) or val < 0):
            raise ConfigError(f"{w}{key}.{name} = {val!r}: must be a parameter name or a delay >= 0 s")
        delays[name] = val.strip() if isinstance(val, str) else None
        dentries.append(compile_entry(val, constants, parameters, f"{w}{key}.{name}"))
    return delays, dentries


def parse_table(table: dict, where: str = "") -> dict:
    """The fields of a :class:`~livesweep.ident.state_space.StateSpaceModel` from a ``[state_space]`` table.

    Parameters
    ----------
    table : dict
        As :meth:`StateSpaceModel.from_table <livesweep.ident.state_space.StateSpaceModel.from_table>`
        takes it.
    where : str
        Prefix for messages, e.g. the case file name.

    Returns
    -------
    dict
        Field name -> value, for the model's constructor (the entries not yet evaluated: the
        model checks them, and M, at the initial values once built).

    Raises
    ------
    ConfigError
        Unknown keys, wrong shapes, bad or unknown names, non-arithmetic entries, unused free
        parameters, bad units -- naming the key, entry and value.
    """
    w = f"{where}: " if where else ""
    if not isinstance(table, dict):
        raise ConfigError(f"{w}[state_space] must be a table, got {table!r}")
    unknown = sorted(set(table) - _TABLE_KEYS)
    if unknown:
        raise ConfigError(f"{w}unknown key(s) {', '.join(unknown)} in [state_space]; "
                          f"known: {', '.join(sorted(_TABLE_KEYS))}")
    states = _names(table, "states", w)
    inputs = _names(table, "inputs", w)
    outputs = _names(table, "outputs", w)
    constants = _constants(table, w)
    names, init, fixed, unset = _parameters(table, constants, w)
    mats = _matrices(table, len(states), len(inputs), len(outputs), constants, names, w)
    delays, dentries = _parse_delays(table, "delays", inputs, "input", constants, names, w)
    odelays, odentries = _parse_delays(table, "output_delays", outputs, "output", constants, names, w)
    iskews, isentries = _parse_delays(table, "input_skews", inputs, "input", constants, names, w)
    bands = _bands(table, outputs, inputs, w)
    _check_used(mats, (*dentries, *odentries, *isentries), names, fixed, w)
    units = _units(table, states, w)
    return {"states": states, "inputs": inputs, "outputs": outputs, **mats, "constants": constants,
            "parameters": tuple(names), "initial": _frozen(init), "fixed": tuple(fixed), "delays": delays,
            "delay_entries": tuple(dentries), "bands": bands, "where": where, "unset": tuple(unset),
            "output_delays": odelays, "output_delay_entries": tuple(odentries), "input_skews": iskews,
            "input_skew_entries": tuple(isentries), "state_units": units}


def _constants(table, w) -> dict:
    """``constants``: name -> finite number."""
    constants = {}
    raw_c = table.get("constants", {}) or {}
    if not isinstance(raw_c, dict):
        raise ConfigError(f"{w}constants = {raw_c!r}: must be a table of name = number")
    for name, val in raw_c.items():
        if not name.isidentifier():
            raise ConfigError(f"{w}constants.{name}: not a valid name")
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
            raise ConfigError(f"{w}constants.{name} = {val!r}: must be a finite number")
        constants[name] = float(val)
    return constants


def _parameters(table, constants, w):
    """``parameters``: names, initial values (0 for a free one without ``value``), fixed flags, and
    the names given no value."""
    raw_p = table.get("parameters", {}) or {}
    if not isinstance(raw_p, dict):
        raise ConfigError(f"{w}parameters = {raw_p!r}: must be a table of name = {{value, fixed}}")
    names, init, fixed, unset = [], [], [], []
    for name, spec in raw_p.items():
        if not name.isidentifier():
            raise ConfigError(f"{w}parameters.{name}: not a valid name")
        if name in constants:
            raise ConfigError(f"{w}parameters.{name}: the name is also a constant")
        if isinstance(spec, dict):
            bad = sorted(set(spec) - {"value", "fixed"})
            if bad:
                raise ConfigError(f"{w}parameters.{name}: unknown key(s) {', '.join(bad)} (use value, fixed)")
            val, fx = spec.get("value"), spec.get("fixed", False)
            if val is None:
                if fx:
                    raise ConfigError(f"{w}parameters.{name}: fixed but has no value")
                unset.append(name)
                val = 0.0
        else:
            val, fx = spec, False
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
            raise ConfigError(f"{w}parameters.{name}.value = {val!r}: must be a finite number")
        if not isinstance(fx, bool):
            raise ConfigError(f"{w}parameters.{name}.fixed = {fx!r}: must be true or false")
        names.append(name)
        init.append(float(val))
        fixed.append(fx)
    return names, init, fixed, unset


def _matrices(table, n, m, p, constants, names, w) -> dict:
    """``M`` (default identity), ``F``, ``G``, ``H``, ``J`` (default zero) for ``n`` states,
    ``m`` inputs and ``p`` outputs: their entries compiled."""
    defaults = {"M": [["1" if i == j else "0" for j in range(n)] for i in range(n)],
                "J": [["0"] * m for _ in range(p)]}
    shapes = {"M": (n, n, "state", "state"), "F": (n, n, "state", "state"), "G": (n, m, "state", "input"),
              "H": (p, n, "output", "state"), "J": (p, m, "output", "input")}
    mats = {}
    for key in _MATRICES:
        raw = table.get(key, defaults.get(key))
        if raw is None:
            raise ConfigError(f"{w}{key}: missing (a list of rows of entry strings)")
        rows, cols, rw, cw = shapes[key]
        _shape_of(raw, key, rows, cols, rw, cw, w)
        mats[key] = tuple(tuple(compile_entry(e, constants, names, f"{w}{key}[{i}][{j}]")
                                for j, e in enumerate(row)) for i, row in enumerate(raw))
    return mats


def _bands(table, outputs, inputs, w) -> dict:
    """``bands``: (output, input) -> (lo, hi) [rad/s]."""
    bands = {}
    raw_b = table.get("bands", {}) or {}
    if not isinstance(raw_b, dict):
        raise ConfigError(f"{w}bands = {raw_b!r}: must be a table of \"output/input\" = [lo, hi]")
    for key, val in raw_b.items():
        parts = key.split("/")
        if len(parts) != 2 or parts[0] not in outputs or parts[1] not in inputs:
            raise ConfigError(f"{w}bands.{key!r}: must name a pair \"output/input\" of the model")
        bands[(parts[0], parts[1])] = check_band(val, f"{w}bands.{key}")
    return bands


def _check_used(mats, delay_entries, names, fixed, w) -> None:
    """Every free parameter must appear in some matrix entry or delay."""
    used = set()
    for key in _MATRICES:
        for row in mats[key]:
            for e in row:
                used.update(e.parameters)
    for e in delay_entries:
        used.update(e.parameters)
    for name, fx in zip(names, fixed):
        if not fx and name not in used:
            raise ConfigError(f"{w}parameters.{name}: free but used in no matrix entry or delay")


def _units(table, states, w) -> dict:
    """``units``: state -> units text."""
    raw_u = table.get("units") or {}
    if not isinstance(raw_u, dict):
        raise ConfigError(f"{w}units = {quote(raw_u)}: must be a table of state = \"units\"")
    for name, unit in raw_u.items():
        if name not in states:
            raise ConfigError(f"{w}units.{name}: not a state (states: {', '.join(states)})")
        if not isinstance(unit, str):
            raise ConfigError(f"{w}units.{name} = {quote(unit)}: must be a string such as \"rad/s\"")
    return dict(raw_u)
