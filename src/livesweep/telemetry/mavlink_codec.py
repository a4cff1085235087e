"""MAVLink 2 message <-> JSON record conversion.

One canonical record form is shared by everything that produces MAVLink records:
the simulator builds records directly (:func:`record_from_fields`,
:func:`records_from_columns`), the live recorder converts received pymavlink messages
(:func:`record_from_message`), and both give *equal* dicts for the same message.

Canonical record
    ``{"sysid": int, "compid": int, <field>: value, ...}`` with the fields in the
    pymavlink class's ``fieldnames`` order (the order of the message definition, not the
    wire order). Values are what the wire can carry:

    * ``float`` fields: rounded to float32, then represented by the shortest decimal that
      round-trips to the same float32 (``float(str(np.float32(x)))``). The record is
      compact when printed as JSON and exact with respect to the wire. Non-finite values
      stay ``nan``/``inf`` here; the MCAP writer stores them as ``null`` and counts them.
      ``None`` (a stored ``null``) is read back as ``nan``.
    * ``double`` fields (few, e.g. ``WHEEL_DISTANCE.distance``): Python floats, unchanged.
    * integer fields: Python ``int`` in the C type's range. Integral floats (``3.0``) are
      accepted; anything else (``3.5``, ``nan``, strings) is a :class:`ConfigError`.
    * ``char[n]`` fields: ``str`` of at most ``n`` ASCII characters, no NUL.
    * arrays: lists of exactly ``n`` elements with the element rule above.

Dialect: ``ardupilotmega`` (MAVLink 2), which includes ``common`` and ArduPilot messages
such as ``AOA_SSA`` (id 11020).

Importing this module sets ``MAVLINK20=1`` before pymavlink is imported. If pymavlink was
already imported with MAVLink 1 (or with a dialect that lacks the ardupilotmega
messages), ``mavutil.set_dialect("ardupilotmega")`` switches the process-wide dialect to
MAVLink 2 ardupilotmega so later connections frame MAVLink 2 (magic 0xFD).
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass
from itertools import repeat
from typing import Any, Mapping

os.environ["MAVLINK20"] = "1"  # before the first pymavlink import: else mavutil packs MAVLink 1
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")  # mavutil's default would be "all"

import numpy as np  # noqa: E402
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as _dialect  # noqa: E402

from livesweep.errors import ConfigError, LivesweepError  # noqa: E402
from livesweep.numeric import float_json_schema, nonfinite_value  # noqa: E402

__all__ = [
    "DIALECT",
    "ensure_mavlink2",
    "json_schema",
    "message_class",
    "record_from_fields",
    "record_from_message",
    "records_from_columns",
    "stamp_wrap_units",
    "vehicle_time_field",
    "vehicle_time_ns",
]

DIALECT = "ardupilotmega"

# Finite magnitudes at or above 2**128 - 2**103 round to inf when cast to float32
# (round-to-nearest); struct.pack("<f") refuses them, so they are errors here too.
_F32_OVERFLOW = 2.0**128 - 2.0**103

_INT_RANGES: dict[str, tuple[int, int]] = {
    "int8_t": (-(2**7), 2**7 - 1),
    "uint8_t": (0, 2**8 - 1),
    "int16_t": (-(2**15), 2**15 - 1),
    "uint16_t": (0, 2**16 - 1),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
    "uint64_t": (0, 2**64 - 1),
}

# Fields that carry vehicle time, first match wins, with nanoseconds per unit.
_TIME_FIELDS = (("time_usec", 1_000), ("time_boot_ms", 1_000_000))


def ensure_mavlink2() -> None:
    """Make ``mavutil``'s process-wide dialect MAVLink 2 with the ardupilotmega messages.

    Called on import and again by every :class:`~livesweep.telemetry.mavlink_out.MavlinkSender`
    (some other code may have switched the dialect since). A MAVLink 2 dialect that is a
    superset (for example ``all``) is kept.
    """
    os.environ["MAVLINK20"] = "1"
    mod = mavutil.mavlink
    is_v2 = str(getattr(mod, "WIRE_PROTOCOL_VERSION", "")) == "2.0"
    if not is_v2 or not hasattr(mod, "MAVLINK_MSG_ID_AOA_SSA"):
        mavutil.set_dialect(DIALECT)
        mod = mavutil.mavlink
        if str(getattr(mod, "WIRE_PROTOCOL_VERSION", "")) != "2.0":  # pragma: no cover
            raise LivesweepError(
                f"pymavlink dialect {getattr(mod, '__name__', mod)!r} is not MAVLink 2 "
                "after set_dialect; cannot send MAVLink 2 frames"
            )


ensure_mavlink2()


# --------------------------------------------------------------------------------------
# Message specs
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Field:
    name: str
    ctype: str  # "float", "double", "char", "uint8_t", ...
    kind: str  # "f32", "f64", "int", "char"
    length: int  # 0 for a scalar; n for an array (char[n]: maximum string length)
    lo: int = 0
    hi: int = 0
    units: str = ""


@dataclass(frozen=True)
class _Spec:
    msgname: str
    cls: type
    fields: tuple[_Field, ...]
    by_name: Mapping[str, _Field]
    keys: tuple[str, ...]  # ("sysid", "compid", *fieldnames)
    time_field: str | None
    time_scale_ns: int


_BY_NAME: dict[str, type] = {cls.msgname: cls for cls in _dialect.mavlink_map.values()}


def message_class(msgname: str) -> type:
    """The pymavlink (MAVLink 2, ardupilotmega) class of message ``msgname``, e.g. ``"ATTITUDE"``.

    An unknown name raises :class:`ConfigError` naming it. Names are upper case, as in the
    MAVLink definitions.
    """
    try:
        return _BY_NAME[msgname]
    except (KeyError, TypeError):
        pass
    hint = ""
    if isinstance(msgname, str) and msgname.upper() in _BY_NAME:
        hint = f" (message names are upper case: {msgname.upper()!r})"
    raise ConfigError(f"unknown MAVLink message {msgname!r} in dialect {DIALECT}{hint}")


@functools.lru_cache(maxsize=None)
def _spec(msgname: str) -> _Spec:
    cls = message_class(msgname)
    fields = []
    units = getattr(cls, "fieldunits_by_name", {}) or {}
    for i, (name, ctype) in enumerate(zip(cls.fieldnames, cls.fieldtypes)):
        length = int(cls.array_lengths[cls.orders[i]])
        if ctype == "float":
            f = _Field(name, ctype, "f32", length, units=units.get(name, ""))
        elif ctype == "double":
            f = _Field(name, ctype, "f64", length, units=units.get(name, ""))
        elif ctype == "char":
            f = _Field(name, ctype, "char", max(length, 1), units=units.get(name, ""))
        elif ctype in _INT_RANGES:
            lo, hi = _INT_RANGES[ctype]
            f = _Field(name, ctype, "int", length, lo, hi, units=units.get(name, ""))
        else:  # pragma: no cover - all types of the pinned dialect are handled above
            raise LivesweepError(f"MAVLink {msgname}.{name}: unsupported field type {ctype!r}")
        fields.append(f)
    time_field, scale = None, 0
    for tname, tscale in _TIME_FIELDS:
        if tname in cls.fieldnames:
            time_field, scale = tname, tscale
            break
    by_name = {f.name: f for f in fields}
    return _Spec(
        msgname=msgname,
        cls=cls,
        fields=tuple(fields),
        by_name=by_name,
        keys=("sysid", "compid", *cls.fieldnames),
        time_field=time_field,
        time_scale_ns=scale,
    )


# --------------------------------------------------------------------------------------
# JSON schema
# --------------------------------------------------------------------------------------


def _item_schema(f: _Field) -> dict[str, Any]:
    if f.kind in ("f32", "f64"):
        return float_json_schema()
    return {"type": "integer", "minimum": f.lo, "maximum": f.hi}


def json_schema(msgname: str) -> dict[str, Any]:
    """JSON Schema (draft 2020-12) of the canonical record of ``msgname``.

    Properties: ``sysid``, ``compid``, then every field in ``fieldnames`` order. Floats are
    numbers, or one of the strings ``"NaN"``, ``"Infinity"``, ``"-Infinity"`` for non-finite
    values (:mod:`livesweep.numeric`; ``null`` in logs written before), integers carry
    their C range, ``char[n]`` is a string of at most ``n`` characters and arrays are
    ``{"type": "array", "items": ..., "minItems": n, "maxItems": n}``. A fresh dict is
    returned on every call.
    """
    spec = _spec(msgname)
    props: dict[str, Any] = {
        "sysid": {"type": "integer", "minimum": 0, "maximum": 255,
                  "description": "MAVLink source system id"},
        "compid": {"type": "integer", "minimum": 0, "maximum": 255,
                   "description": "MAVLink source component id"},
    }
    for f in spec.fields:
        desc = f.ctype + (f"[{f.length}]" if f.length else "")
        if f.units:
            desc += f", units {f.units}"
        if f.kind == "char":
            prop: dict[str, Any] = {"type": "string", "maxLength": f.length}
        elif f.length:
            prop = {"type": "array", "items": _item_schema(f),
                    "minItems": f.length, "maxItems": f.length}
        else:
            prop = _item_schema(f)
        prop["description"] = desc
        props[f.name] = prop
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": msgname,
        "description": (
            f"MAVLink 2 message {msgname} (id {spec.cls.id}, dialect {DIALECT}); "
            "float fields are float32 values written as their shortest round-trip decimal; "
            "non-finite floats are the strings NaN, Infinity, -Infinity"
        ),
        "type": "object",
        "properties": props,
        "required": list(spec.keys),
    }


# --------------------------------------------------------------------------------------
# Scalar coercion (the reference rule; the vectorised path must give identical results)
# --------------------------------------------------------------------------------------


def _str_is_shortest() -> bool:
    """numpy's ``str(np.float32)`` is the shortest round-trip repr unless legacy printing is on."""
    return not np.get_printoptions().get("legacy", False)


def _bad(msgname: str, field: str, value: Any, why: str) -> ConfigError:
    return ConfigError(f"MAVLink {msgname}.{field}: value {value!r} {why}")


def _coerce_float(msgname: str, f: _Field, v: Any) -> float:
    if type(v) is float and f.kind == "f32" and abs(v) < _F32_OVERFLOW:  # fast path
        return float(str(np.float32(v)))
    if v is None:
        return math.nan
    special = nonfinite_value(v)          # "NaN" / "Infinity" / "-Infinity" as recorded
    if special is not None:
        return special
    if isinstance(v, (str, bytes, bytearray)) or not isinstance(
        v, (int, float, np.integer, np.floating, np.bool_)
    ):
        raise _bad(msgname, f.name, v, f"is not a number ({f.ctype} field)")
    x = float(v)  # value -> float64 (then -> float32 for float fields), same as the vector path
    if f.kind == "f64":
        return x
    if abs(x) >= _F32_OVERFLOW and math.isfinite(x):
        raise _bad(msgname, f.name, v, "overflows float32 (the wire type)")
    return float(str(np.float32(x)))


def _coerce_int(msgname: str, f: _Field, v: Any) -> int:
    if type(v) is int and f.lo <= v <= f.hi:  # fast path
        return v
    if isinstance(v, (bool, np.bool_, int, np.integer)):
        i = int(v)
    elif isinstance(v, (float, np.floating)):
        x = float(v)
        if not (math.isfinite(x) and x.is_integer()):
            raise _bad(msgname, f.name, v, f"is not an integer ({f.ctype} field)")
        i = int(x)
    else:
        raise _bad(msgname, f.name, v, f"is not an integer ({f.ctype} field)")
    if not f.lo <= i <= f.hi:
        raise _bad(msgname, f.name, v, f"is out of range for {f.ctype} [{f.lo}, {f.hi}]")
    return i


def _coerce_char(msgname: str, f: _Field, v: Any) -> str:
    if isinstance(v, (bytes, bytearray, np.bytes_)):
        raw = bytes(v).rstrip(b"\x00")
        try:
            s = raw.decode("ascii")
        except UnicodeDecodeError:
            raise _bad(msgname, f.name, v, "is not ASCII") from None
    elif isinstance(v, str):
        s = v.rstrip("\x00")
        if not s.isascii():
            raise _bad(msgname, f.name, v, "is not ASCII")
    elif isinstance(v, (int, np.integer)) and int(v) == 0:
        s = ""  # "missing fields default to 0"
    else:
        raise _bad(msgname, f.name, v, f"is not a string (char[{f.length}] field)")
    if "\x00" in s:
        raise _bad(msgname, f.name, v, "contains a NUL character (the receiver would cut it there)")
    if len(s) > f.length:
        raise _bad(msgname, f.name, v, f"is longer than {f.length} characters (char[{f.length}])")
    return s


def _coerce_scalar(msgname: str, f: _Field, v: Any) -> Any:
    if f.kind == "int":
        return _coerce_int(msgname, f, v)
    if f.kind == "char":
        return _coerce_char(msgname, f, v)
    return _coerce_float(msgname, f, v)


def _coerce_value(msgname: str, f: _Field, v: Any) -> Any:
    if f.length == 0 or f.kind == "char":
        return _coerce_scalar(msgname, f, v)
    if isinstance(v, (str, bytes, bytearray)) or np.ndim(v) != 1:
        raise _bad(msgname, f.name, v, f"is not a 1-D array of {f.length} elements")
    seq = list(v)
    if len(seq) != f.length:
        raise _bad(msgname, f.name, v, f"has {len(seq)} elements; {f.ctype}[{f.length}] needs {f.length}")
    if f.kind == "int":
        return [_coerce_int(msgname, f, x) for x in seq]
    return [_coerce_float(msgname, f, x) for x in seq]


def _default(f: _Field) -> Any:
    if f.kind == "char":
        return ""
    zero: Any = 0 if f.kind == "int" else 0.0
    return [zero] * f.length if f.length else zero


def _check_id(name: str, v: Any) -> int:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not 0 <= int(v) <= 255:
        raise ConfigError(f"MAVLink {name} {v!r} is not an integer in [0, 255]")
    return int(v)


class _LegacyGuard:
    """Temporarily turns off numpy legacy printing (it changes ``str(np.float32)``)."""

    __slots__ = ("_ctx",)

    def __enter__(self) -> None:
        self._ctx = None
        if not _str_is_shortest():
            self._ctx = np.printoptions(legacy=False)
            self._ctx.__enter__()

    def __exit__(self, *exc: Any) -> None:
        if self._ctx is not None:
            self._ctx.__exit__(*exc)


def _spec_with_fields(msgname: str, names) -> _Spec:
    """The message's spec, after checking every given field name exists (ConfigError otherwise)."""
    spec = _spec(msgname)
    unknown = [k for k in names if k not in spec.by_name]
    if unknown:
        raise ConfigError(
            f"MAVLink {msgname}: unknown field(s) {', '.join(map(repr, unknown))}; "
            f"fields are {', '.join(spec.cls.fieldnames)}"
        )
    return spec


def record_from_fields(msgname: str, fields: Mapping[str, Any], *, sysid: int, compid: int) -> dict[str, Any]:
    """Canonical record of message ``msgname`` from field values (see the module docstring).

    Missing fields default to 0 (arrays: zeros of the right length; ``char``: ``""``).
    Unknown field names, out-of-range or non-integer integers, non-numbers and strings too
    long for their ``char[n]`` raise :class:`ConfigError` naming message, field and value.
    """
    spec = _spec_with_fields(msgname, fields)
    rec: dict[str, Any] = {"sysid": _check_id("sysid", sysid), "compid": _check_id("compid", compid)}
    with _LegacyGuard():
        for f in spec.fields:
            rec[f.name] = _coerce_value(msgname, f, fields[f.name]) if f.name in fields else _default(f)
    return rec


def record_from_message(msg: Any) -> dict[str, Any]:
    """Canonical record of a received (or encoded) pymavlink message object.

    Uses ``msg.get_srcSystem()``/``msg.get_srcComponent()`` and the same float32
    shortest-repr rule as :func:`record_from_fields`, so a record built by the simulator and
    the record of that message after a UDP round trip are equal dicts.
    ``BAD_DATA``/unknown messages raise :class:`LivesweepError`.
    """
    try:
        msgname = msg.get_type()
    except AttributeError:
        raise LivesweepError(f"not a pymavlink message: {msg!r}") from None
    if msgname not in _BY_NAME:
        raise LivesweepError(f"cannot convert MAVLink message {msgname!r} to a record "
                             f"(bad data or not in dialect {DIALECT})")
    spec = _spec(msgname)
    rec: dict[str, Any] = {"sysid": int(msg.get_srcSystem()), "compid": int(msg.get_srcComponent())}
    with _LegacyGuard():
        for f in spec.fields:
            v = getattr(msg, f.name)
            k = f.kind
            if k == "f32":
                if f.length:
                    rec[f.name] = [float(str(np.float32(x))) for x in v]
                else:
                    rec[f.name] = float(str(np.float32(v)))
            elif k == "int":
                rec[f.name] = [int(x) for x in v] if f.length else int(v)
            elif k == "char":
                if isinstance(v, (bytes, bytearray)):
                    v = bytes(v).split(b"\x00", 1)[0].decode("ascii", errors="replace")
                rec[f.name] = v
            else:  # f64
                rec[f.name] = [float(x) for x in v] if f.length else float(v)
    return rec


def vehicle_time_ns(record: Mapping[str, Any], msgname: str) -> int | None:
    """Vehicle time of a record in integer nanoseconds, or ``None`` if the message has none.

    From ``time_usec`` (µs) when the message has that field, else ``time_boot_ms`` (ms).
    The value is converted as is: ``time_usec`` of some messages (e.g. ``SERVO_OUTPUT_RAW``)
    is uint32 and wraps every ~71.6 min, and some messages allow UNIX time there; callers
    that need continuity must unwrap. A record lacking the field raises LivesweepError. The
    result may exceed what an MCAP time can hold (a uint64 ``time_usec`` near 2**64 µs): the
    sources check it (:func:`livesweep.telemetry.clock.UINT64_NS_MAX`) before recording it.
    """
    spec = _spec(msgname)
    if spec.time_field is None:
        return None
    try:
        v = record[spec.time_field]
    except KeyError:
        raise LivesweepError(f"MAVLink {msgname} record has no {spec.time_field!r} field") from None
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        raise LivesweepError(f"MAVLink {msgname}.{spec.time_field}: {v!r} is not an integer time stamp")
    return int(v) * spec.time_scale_ns


def vehicle_time_field(msgname: str) -> tuple[str, int] | None:
    """(field, nanoseconds per unit) of the vehicle time of ``msgname``, or None if it has none."""
    spec = _spec(msgname)
    return None if spec.time_field is None else (spec.time_field, spec.time_scale_ns)


def stamp_wrap_units(msgname: str, field: str) -> int | None:
    """2**32 when ``field`` of ``msgname`` is a uint32 (a time stamp there wraps), else None.

    Unknown messages or fields give None: only a field known to be 32 bits wide may be unwrapped
    (a uint64 ``time_usec`` near 2**32 µs is not a wrap).
    """
    try:
        f = _spec(msgname).by_name.get(field)
    except ConfigError:
        return None
    return 2**32 if f is not None and f.ctype == "uint32_t" else None


# --------------------------------------------------------------------------------------
# Vectorised conversion
# --------------------------------------------------------------------------------------


def _format_f32(values: np.ndarray, msgname: str, f: _Field) -> np.ndarray:
    """float64 array -> float64 array of shortest-repr float32 values (same rule as scalars).

    Each distinct float32 bit pattern is formatted once (repeated values such as constant
    or quantised channels cost almost nothing).
    """
    x = np.asarray(values, dtype=np.float64)
    big = (np.abs(x) >= _F32_OVERFLOW) & np.isfinite(x)
    if big.any():
        i = int(np.flatnonzero(big.ravel())[0])
        raise _bad(msgname, f.name, float(x.ravel()[i]), f"(row {i // max(f.length, 1)}) overflows float32 (the wire type)")
    f32 = x.astype(np.float32)
    bits = f32.view(np.uint32).ravel()
    uniq, inverse = np.unique(bits, return_inverse=True)
    if len(uniq) * 4 < len(bits) * 3:
        formatted = np.fromiter(map(float, map(str, uniq.view(np.float32))), dtype=np.float64, count=len(uniq))
        return formatted[inverse].reshape(f32.shape)
    return np.fromiter(map(float, map(str, f32.ravel())), dtype=np.float64, count=f32.size).reshape(f32.shape)


def _rowwise(fn: Any, values: list[Any], per_row: int) -> list[Any]:
    """``[fn(v) for v in values]``, with the row number added to a ConfigError."""
    out = []
    for i, v in enumerate(values):
        try:
            out.append(fn(v))
        except ConfigError as e:
            raise ConfigError(f"{e} (row {i // per_row})") from None
    return out


def _ints(values: Any, msgname: str, f: _Field) -> list[Any]:
    # lists take the scalar rule (np.asarray would turn [2**64 - 1, 5] into float64)
    a = values if isinstance(values, np.ndarray) else np.asarray(values, dtype=object)
    kind = a.dtype.kind
    if kind == "b":
        a = a.astype(np.int64)
        kind = "i"
    if kind == "f":
        ok = np.isfinite(a) & (a == np.floor(a))
        if not ok.all():
            i = int(np.flatnonzero(~ok.ravel())[0])
            raise _bad(msgname, f.name, float(a.ravel()[i]), f"(row {i // max(f.length, 1)}) is not an integer ({f.ctype} field)")
        # hi + 1 and lo are powers of two, exact in float64 (hi itself may not be)
        rng = (a >= float(f.lo)) & (a < float(f.hi + 1))
        if not rng.all():
            i = int(np.flatnonzero(~rng.ravel())[0])
            raise _bad(msgname, f.name, float(a.ravel()[i]), f"(row {i // max(f.length, 1)}) is out of range for {f.ctype} [{f.lo}, {f.hi}]")
        return a.astype(np.uint64 if f.lo == 0 else np.int64).tolist()
    if kind in "iu":
        if a.size:
            rng = (a >= f.lo) & (a <= f.hi)
            if not rng.all():
                i = int(np.flatnonzero(~rng.ravel())[0])
                raise _bad(msgname, f.name, int(a.ravel()[i]), f"(row {i // max(f.length, 1)}) is out of range for {f.ctype} [{f.lo}, {f.hi}]")
        return a.tolist()
    # object / anything else: element by element with the scalar rule
    flat = _rowwise(lambda v: _coerce_int(msgname, f, v), a.ravel().tolist(), max(f.length, 1))
    if a.ndim == 2:
        n = a.shape[1]
        return [flat[i : i + n] for i in range(0, len(flat), n)]
    return flat


def records_from_columns(
    msgname: str, columns: Mapping[str, Any], *, sysid: int, compid: int
) -> list[dict[str, Any]]:
    """Records of ``msgname`` from columns: the same result as :func:`record_from_fields` per row.

    ``columns`` maps field names to 1-D arrays (``(n, length)`` arrays for array fields, a
    sequence of strings for ``char`` fields) of a common length ``n``; a 0-d value (or, for
    an array field, a 1-D array of its length) is broadcast to every row. Absent fields are
    0. Unknown names, length mismatches and bad values raise :class:`ConfigError`.
    """
    spec = _spec_with_fields(msgname, columns)
    sysid = _check_id("sysid", sysid)
    compid = _check_id("compid", compid)

    # number of rows
    n: int | None = None
    for name, col in columns.items():
        f = spec.by_name[name]
        per_row_ndim = 1 if (f.length and f.kind != "char") else 0
        nd = np.ndim(col)
        if nd == per_row_ndim:
            continue  # broadcast
        if nd != per_row_ndim + 1:
            raise ConfigError(
                f"MAVLink {msgname}.{name}: column has {nd} dimensions; expected {per_row_ndim + 1} "
                f"(or {per_row_ndim} to broadcast)"
            )
        rows = len(col)
        if n is None:
            n = rows
        elif rows != n:
            raise ConfigError(f"MAVLink {msgname}.{name}: column has {rows} rows; other columns have {n}")
    if n is None:
        raise ConfigError(f"MAVLink {msgname}: no column with one value per row; cannot tell the number of rows")

    cols: list[Any] = [repeat(sysid, n), repeat(compid, n)]
    with _LegacyGuard():
        for f in spec.fields:
            per_row_ndim = 1 if (f.length and f.kind != "char") else 0
            if f.name not in columns:
                d = _default(f)
                cols.append([list(d) for _ in range(n)] if isinstance(d, list) else repeat(d, n))
                continue
            col = columns[f.name]
            if np.ndim(col) == per_row_ndim:  # broadcast one value
                v = _coerce_value(msgname, f, col)
                cols.append([list(v) for _ in range(n)] if isinstance(v, list) else repeat(v, n))
                continue
            if f.length and f.kind != "char":
                arr = np.asarray(col)
                if arr.shape[1:] != (f.length,):
                    raise ConfigError(
                        f"MAVLink {msgname}.{f.name}: column shape {arr.shape}; expected ({n}, {f.length})"
                    )
            if f.kind == "char":
                cache: dict[Any, str] = {}
                out = []
                for v in (col.tolist() if isinstance(col, np.ndarray) else col):
                    key = (type(v), v) if isinstance(v, (str, bytes)) else None
                    if key is not None and key in cache:
                        out.append(cache[key])
                        continue
                    s = _coerce_char(msgname, f, v)
                    if key is not None:
                        cache[key] = s
                    out.append(s)
                cols.append(out)
            elif f.kind == "int":
                cols.append(_ints(col, msgname, f))
            else:
                arr = np.asarray(col)
                if arr.dtype.kind not in "biuf":
                    # object columns (None for null, mixed types): the scalar rule, row by row
                    if not isinstance(col, np.ndarray):
                        arr = np.asarray(col, dtype=object)  # keep [1.5, "x"] as given
                    cols.append(_rowwise(lambda v: _coerce_value(msgname, f, v), arr.tolist(), 1))
                    continue
                if f.kind == "f64":
                    cols.append(arr.astype(np.float64).tolist())
                else:
                    cols.append(_format_f32(arr, msgname, f).tolist())
    keys = spec.keys
    return [dict(zip(keys, row)) for row in zip(*cols)]
