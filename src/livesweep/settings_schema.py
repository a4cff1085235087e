"""One definition per setting: a settings dataclass's fields carry their TOML type, units, range
and meaning, and from that one definition come the parser, the error messages and the reference
tables of docs/case-file.md.

A table's dataclass declares each key as a field made by :func:`setting`:

    overlap: float = setting(0.8, number(lo=0.0, hi=0.95), "window overlap", units="fraction")

:func:`read_table` turns a TOML table into the field values (unknown keys, missing required keys
and bad values raise a one-line :class:`~livesweep.errors.ConfigError` naming the file, the key
path and the value); :func:`markdown_table` writes the table's reference rows. Adding a key is one
field in the dataclass, its use where it is needed, and ``python -m livesweep.settings_schema``
to regenerate docs/case-file.md (a test checks the page is current).

Pure: no file is read here (the generator's ``__main__`` aside).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass
from typing import Any

from livesweep.errors import ConfigError, quote

__all__ = ["require_table", "setting", "Check", "number", "integer", "string", "names", "numbers", "choices", "read_table",
           "table_keys", "markdown_table", "write_docs"]


@dataclass(frozen=True)
class Check:
    """How one key's TOML value is checked and converted.

    Attributes
    ----------
    convert : callable
        ``convert(value) -> value``; raises ``ValueError(problem)`` on a bad value.
    text : str
        The TOML type as docs/case-file.md states it ("number in [0, 0.95]").
    """

    convert: Callable[[Any], Any]
    text: str


class ItemError(ValueError):
    """A bad item of an array value: its index and the item, for the key path ``key[i]``."""

    def __init__(self, index: int, item: Any, problem: str) -> None:
        super().__init__(problem)
        self.index, self.item = index, item


def _type_name(value: Any) -> str:
    return {bool: "boolean", int: "integer", float: "float", str: "string",
            list: "array", dict: "table"}.get(type(value), type(value).__name__)


def _finite(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"must be a number, not {_type_name(value)}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError("must be a finite number")
    return v


def _range_text(lo, hi, lo_open, hi_open, ascii_only: bool = False) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>=' if ascii_only else '≥'} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<=' if ascii_only else '≤'} {hi:g}"
    return ""


def number(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
           hi_open: bool = False) -> Check:
    """A finite number (TOML integer or float, not a boolean) within ``[lo, hi]`` (open ends as given)."""
    rng = _range_text(lo, hi, lo_open, hi_open)

    def convert(value):
        v = _finite(value)
        if ((lo is not None and (v < lo or (lo_open and v == lo)))
                or (hi is not None and (v > hi or (hi_open and v == hi)))):
            raise ValueError(f"must be {_range_text(lo, hi, lo_open, hi_open, ascii_only=True)}")
        return v

    return Check(convert, f"number {rng}".strip())


def integer(lo: int, hi: int) -> Check:
    """A TOML integer from ``lo`` to ``hi``."""

    def convert(value):
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise ValueError(f"must be an integer from {lo} to {hi}")
        return value

    return Check(convert, f"integer {lo}–{hi:,}".replace(",", " "))


def string(nonempty: bool = False) -> Check:
    """A string (non-empty when asked)."""

    def convert(value):
        if not isinstance(value, str):
            raise ValueError(f"must be a string, not {_type_name(value)}")
        if nonempty and not value.strip():
            raise ValueError("must be a non-empty string")
        return value

    return Check(convert, "string, non-empty" if nonempty else "string")


def names(what: str = "signal names") -> Check:
    """A non-empty array of distinct strings, as a tuple."""

    def convert(value):
        if not isinstance(value, list):
            raise ValueError(f"must be an array of strings, not {_type_name(value)}")
        if not value:
            raise ValueError("must name at least one signal")
        for i, v in enumerate(value):
            if not isinstance(v, str):
                raise ItemError(i, v, f"must be a string, not {_type_name(v)}")
            if not v.strip():
                raise ItemError(i, v, "must be a non-empty string")
            if v in value[:i]:
                raise ItemError(i, v, "is listed twice")
        return tuple(value)

    return Check(convert, f"array of {what}")


def numbers(each: Check, *, max_items: int, what: str = "values") -> Check:
    """A non-empty array of at most ``max_items`` values, each passing ``each``, as a tuple."""

    def convert(value):
        if not isinstance(value, list) or not value:
            raise ValueError(f"must be a non-empty array ({each.text})")
        if len(value) > max_items:
            raise ValueError(f"holds {len(value)} {what}; at most {max_items}")
        out = []
        for i, v in enumerate(value):
            try:
                out.append(each.convert(v))
            except ValueError as e:
                raise ItemError(i, v, str(e)) from None
        return tuple(out)

    return Check(convert, f"array of {each.text.replace('number', 'numbers')}")


def choices(options: tuple[str, ...]) -> Check:
    """A non-empty array of distinct strings, each one of ``options``."""
    base = names("strings")

    def convert(value):
        out = base.convert(value)
        for i, v in enumerate(out):
            if v not in options:
                raise ItemError(i, v, f"must be one of {', '.join(options)}")
        return out

    return Check(convert, "array of " + ", ".join(f"`\"{o}\"`" for o in options))


def setting(default: Any = MISSING, check: Check | None = None, doc: str = "", *, units: str = "—",
            default_text: str | None = None, factory: Callable[[], Any] | None = None, key: bool = True):
    """A dataclass field that is a key of a settings table.

    Parameters
    ----------
    default : optional
        The value when the key is absent; none (MISSING): the key is required.
    check : Check
        How the TOML value is checked and converted, and its type as documented; a Check whose
        ``convert`` is None: the table's own parser reads the key (cross-checks with other tables).
    doc : str
        What the key means (docs/case-file.md's "meaning" column).
    units : str
        Its units ("rad/s", "s", "fraction"), "—" for none.
    default_text : str, optional
        How the documentation states the default when ``repr`` would not do ("chosen (method §4.4)").
    factory : callable, optional
        A default factory in place of ``default`` (mutable defaults).
    key : bool
        False: a field of the dataclass that is not a TOML key (derived, not documented).
    """
    meta = {"check": check, "doc": doc, "units": units, "default_text": default_text, "key": key}
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def _keyed(cls) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if f.metadata.get("key", False)]


def table_keys(cls) -> tuple[str, ...]:
    """The TOML keys the table of ``cls`` accepts, in declaration order."""
    return tuple(f.name for f in _keyed(cls))


def read_table(raw: Any, cls, where: str, origin: Any) -> dict[str, Any]:
    """The checked values of the keys of ``cls`` present in the TOML table ``raw``.

    Parameters
    ----------
    raw : Any
        The TOML value of the table.
    cls : dataclass type
        Its fields made by :func:`setting`.
    where : str
        The table's key path for messages ("spectral", "identify[1]").
    origin : str or Path
        The file (or other origin) messages name first.

    Returns
    -------
    dict
        Key -> checked value, for the keys present whose field has a check (absent keys keep their
        defaults when the caller builds ``cls(**values)``; keys without a check are returned raw).

    Raises
    ------
    ConfigError
        Not a table, an unknown key, a missing required key, a bad value: one line naming
        ``origin``, the key path and the value.
    """
    if not isinstance(raw, dict):
        raise ConfigError(f"{origin}: {where}: must be a table, not {_type_name(raw)}, got {quote(raw)}")
    fields = {f.name: f for f in _keyed(cls)}
    for k in raw:
        if k not in fields:
            raise ConfigError(f"{origin}: {where}.{k}: unknown key {k!r}; known keys in {where}: {', '.join(fields)}")
    missing = [n for n, f in fields.items() if f.default is MISSING and f.default_factory is MISSING and n not in raw]
    if missing:
        required = [n for n, f in fields.items() if f.default is MISSING and f.default_factory is MISSING]
        raise ConfigError(f"{origin}: {where}: missing required key {missing[0]!r} "
                          f"({where} needs {', '.join(required)})")
    out = {}
    for k, v in raw.items():
        check = fields[k].metadata["check"]
        if check is None or check.convert is None:
            out[k] = v
            continue
        try:
            out[k] = check.convert(v)
        except ItemError as e:
            raise ConfigError(f"{origin}: {where}.{k}[{e.index}]: {e}, got {quote(e.item)}") from None
        except ValueError as e:
            raise ConfigError(f"{origin}: {where}.{k}: {e}, got {quote(v)}") from None
    return out


def _default_text(f: dataclasses.Field) -> str:
    if f.metadata.get("default_text"):
        return f.metadata["default_text"]
    if f.default is MISSING and f.default_factory is MISSING:
        return "—"
    value = f.default if f.default is not MISSING else f.default_factory()
    if value is None:
        return "none"
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, tuple):
        return "`[" + ", ".join(f'"{v}"' if isinstance(v, str) else f"{v:g}" for v in value) + "]`"
    return f"`{value:g}`" if isinstance(value, float) else f"`{value}`"


def markdown_table(cls) -> str:
    """docs/case-file.md's reference rows of the table of ``cls``, and its "Keys:" line."""
    rows = ["| key | type | units | default | meaning |", "|---|---|---|---|---|"]
    for f in _keyed(cls):
        m = f.metadata
        required = f.default is MISSING and f.default_factory is MISSING
        kind = (m["check"].text if m["check"] is not None else "") + (", required" if required else "")
        rows.append(f"| `{f.name}` | {kind} | {m['units']} | {_default_text(f)} | {m['doc']} |")
    rows += ["", "Keys: " + ", ".join(f"`{k}`" for k in table_keys(cls))]
    return "\n".join(rows)


_BLOCK = re.compile(r"(<!-- settings: (?P<name>[\w.]+) -->\n)(?P<body>.*?)(<!-- end settings -->)", re.S)


def write_docs(text: str, tables: Mapping[str, type]) -> str:
    """``text`` (docs/case-file.md) with every ``<!-- settings: NAME -->`` block regenerated from
    ``tables`` (marker name -> settings dataclass)."""

    def sub(m):
        return m.group(1) + markdown_table(tables[m.group("name")]) + "\n" + m.group(4)

    return _BLOCK.sub(sub, text)


def require_table(raw: Any, known, where: str) -> dict:
    """``raw`` as a table whose keys are all in ``known``, for the model tables later stages parse
    (``[transfer_functions.*]``, ``[residual]``); ConfigError naming ``where`` (file and table)."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: must be a table, got {raw!r}")
    unknown = sorted(set(raw) - set(known))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    return raw
