"""A DataFlash message type's records decoded and valued: :class:`_Type` and its conversions.

One job: turn the raw records of one message type into the values written: numpy columns decoded
from the file's bytes (:func:`_decode_raw`), units and multipliers from the log's own UNIT, MULT and
FMTU tables (:func:`_lookup_tables`, :func:`_plan`), float32 fields as their shortest decimal
(:func:`_f32_decimal`), and the JSON Schema of the type's channel (:func:`_schema`). The rules are
described under *Values and units* in :mod:`livesweep.convert.dataflash`.
"""

from __future__ import annotations

import numpy as np

from livesweep.convert.dataflash_framing import _text
from livesweep.numeric import float_json_schema

# format characters whose multiplier is implied by the format itself (divisors, exact)
_IMPLIED = {"c": 100, "C": 100, "e": 100, "E": 100, "L": 10_000_000}
_STRINGS = frozenset("nNZ")
_FLOATS = frozenset("fdg")
_NO_MULT = frozenset("-0?")     # FMTU multiplier ids that mean "none", "1" and "unknown"


def _f32_decimal(x: np.ndarray) -> np.ndarray:
    """float64 values that print (``repr``) as the shortest decimal giving back the same float32.

    Vectorised version of ``float(str(np.float32(v)))``: for 1..9 significant digits, the
    nearest decimal of that many digits is kept where it rounds to the same float32.
    """
    out = np.array(x, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        x32 = out.astype(np.float32)        # values beyond float32 (after a multiplier) stay float64
    idx = np.flatnonzero(np.isfinite(x32) & (x32 != 0.0))
    if idx.size == 0:
        return out
    v = x32[idx].astype(np.float64)
    v32 = x32[idx]
    e = np.floor(np.log10(np.abs(v)))
    res = v.copy()
    # powers of ten are exact up to 1e22: outside that range (|v| < 1e-14 or > 1e22, rare) use str()
    odd = np.flatnonzero((e < -14) | (e > 22))
    for i in odd.tolist():
        res[i] = float(str(v32[i]))
    pending = np.flatnonzero((e >= -14) & (e <= 22))
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        for p in range(1, 10):
            if pending.size == 0:
                break
            vp, k = v[pending], p - 1 - e[pending]
            up = np.power(10.0, np.abs(k))
            cand = np.where(k >= 0, np.round(vp * up) / up, np.round(vp / up) * up)
            ok = cand.astype(np.float32) == v32[pending]
            res[pending[ok]] = cand[ok]
            pending = pending[~ok]
    out[idx] = res
    return out


class _Type:
    """One message type: its format, raw records, and how they become JSON values."""

    __slots__ = ("tid", "name", "fmt", "columns", "offsets", "raw", "convs", "units", "mults", "instance",
                 "topic")

    def __init__(self, tid: int, name: str, fmt: str, columns: list[str]):
        self.tid, self.name, self.fmt, self.columns = tid, name, fmt, columns
        self.offsets = np.zeros(0, dtype=np.int64)
        self.raw = None
        self.convs: list = []          # per field: numpy column slice -> list of JSON values
        self.units: dict[str, str] = {}
        self.mults: dict[str, float] = {}
        self.instance = ""
        self.topic = ""

    def rows(self, lo: int, hi: int) -> list[tuple]:
        """Records ``lo:hi`` as tuples of JSON values (converted a slice at a time, to bound memory)."""
        if not self.convs:
            return [()] * (hi - lo)
        raw = self.raw[lo:hi]
        return list(zip(*(conv(raw[f"f{i}"]) for i, conv in enumerate(self.convs))))

    def column(self, name: str) -> list:
        i = self.columns.index(name)
        return self.convs[i](self.raw[f"f{i}"])


def _decode_raw(buf: np.ndarray, offsets: np.ndarray, length: int, dtype: np.dtype) -> np.ndarray:
    body = length - 3
    if body == 0:
        return np.zeros(offsets.size, dtype=dtype)
    rows = buf[(offsets + 3)[:, None] + np.arange(body)[None, :]]
    return np.ascontiguousarray(rows).view(dtype).reshape(-1)


def _lookup_tables(types: dict[int, _Type]):
    """UNIT id -> label, MULT id -> multiplier, type id -> (unit ids, mult ids), from the log itself."""
    units: dict[str, str] = {}
    mults: dict[str, float] = {}
    fmtu: dict[int, tuple[str, str]] = {}
    by_name = {t.name: t for t in types.values()}
    u = by_name.get("UNIT")
    if u is not None and u.raw is not None and {"Id", "Label"} <= set(u.columns):
        ids, labels = u.raw[f"f{u.columns.index('Id')}"], u.raw[f"f{u.columns.index('Label')}"]
        for i, lab in zip(ids.tolist(), labels.tolist()):
            units[chr(i & 0xFF)] = _text(lab)
    m = by_name.get("MULT")
    if m is not None and m.raw is not None and {"Id", "Mult"} <= set(m.columns):
        ids, vals = m.raw[f"f{m.columns.index('Id')}"], m.raw[f"f{m.columns.index('Mult')}"]
        for i, v in zip(ids.tolist(), vals.tolist()):
            mults[chr(i & 0xFF)] = float("%.7g" % v)     # logged as float32 cast to double
    f = by_name.get("FMTU")
    if f is not None and f.raw is not None and {"FmtType", "UnitIds", "MultIds"} <= set(f.columns):
        c = f.columns
        for t, ui, mi in zip(f.raw[f"f{c.index('FmtType')}"].tolist(), f.raw[f"f{c.index('UnitIds')}"].tolist(),
                             f.raw[f"f{c.index('MultIds')}"].tolist()):
            fmtu[int(t)] = (_text(ui), _text(mi))
    return units, mults, fmtu


def _scale(col: np.ndarray, mult: float) -> np.ndarray:
    """``col * mult`` computed as a division by 1/mult when that is an integer (exact decimals)."""
    x = col.astype(np.float64)
    if 0.0 < mult < 1.0:
        inv = 1.0 / mult
        if abs(inv - round(inv)) < 1e-9 * inv:
            return x / round(inv)
    return x * mult


def _as_list(col: np.ndarray) -> list:
    return col.tolist()


def _as_text(col: np.ndarray) -> list:
    return [_text(b) for b in col.tolist()]


def _as_f32(col: np.ndarray) -> list:
    return _f32_decimal(col).tolist()


def _divided(div: int):
    return lambda col: (col.astype(np.float64) / div).tolist()


def _multiplied(mult: float, f32: bool):
    if f32:
        return lambda col: _f32_decimal(_scale(col, mult)).tolist()
    return lambda col: _scale(col, mult).tolist()


def _plan(t: _Type, unit_tab: dict, mult_tab: dict, fmtu: dict) -> None:
    """Units, multipliers and the value conversion of every field of one type."""
    uids, mids = fmtu.get(t.tid, ("", ""))
    if "#" in uids:
        k = uids.index("#")
        if k < len(t.columns):
            t.instance = t.columns[k]
    convs = []
    for i, (name, ch) in enumerate(zip(t.columns, t.fmt)):
        uid = uids[i] if i < len(uids) else ""
        mid = mids[i] if i < len(mids) else ""
        unit = "instance" if uid == "#" else unit_tab.get(uid, "")
        if unit == "UNKNOWN":
            unit = ""
        if name == "TimeUS" and ch in "QqIi":          # kept as the exact integer µs since boot
            t.units[name] = "us"
            convs.append(_as_list)
            continue
        if uids or unit:
            t.units[name] = unit
        if ch in _STRINGS:
            convs.append(_as_text)
        elif ch == "a":
            convs.append(_as_list)
        elif ch in _IMPLIED:                            # the format's own multiplier, never FMTU's too
            t.mults[name] = 1.0 / _IMPLIED[ch]
            convs.append(_divided(_IMPLIED[ch]))
        else:
            mult = mult_tab.get(mid) if mid and mid not in _NO_MULT else None
            if mult is not None and mult not in (0.0, 1.0):
                t.mults[name] = mult
                convs.append(_multiplied(mult, ch == "f"))
            elif ch == "f":
                convs.append(_as_f32)
            else:   # integers, double, half float: exact as they are
                convs.append(_as_list)
    t.convs = convs


def _schema(t: _Type) -> dict:
    props = {}
    for name, ch in zip(t.columns, t.fmt):
        unit = t.units.get(name, "")
        desc = f"DataFlash format {ch!r}" + (f", {unit}" if unit else "")
        if name in t.mults:
            desc += f" (raw x {t.mults[name]:g})"
        if ch in _STRINGS:
            p = {"type": "string"}
        elif ch == "a":
            p = {"type": "array", "items": {"type": "integer"}, "minItems": 32, "maxItems": 32}
        elif ch in _FLOATS or name in t.mults:
            p = float_json_schema()
        else:
            p = {"type": "integer"}
        p["description"] = desc
        props[name] = p
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": t.name,
        "description": f"DataFlash message {t.name} (type {t.tid}, format {t.fmt!r}); values in the declared "
                       "units with multipliers applied; TimeUS in integer microseconds since boot",
        "type": "object",
        "properties": props,
        "required": list(t.columns),
    }
