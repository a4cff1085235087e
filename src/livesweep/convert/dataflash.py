"""ArduPilot DataFlash (``.bin``) and PX4 sdlog2 (``.px4log``) logs to livesweep MCAP.

Both are the same binary format: ``A3 95 <type>`` then the fields of that type, packed as its
``FMT`` record says. The file is framed here, record by record, as pymavlink's
:class:`pymavlink.DFReader.DFReader_binary` frames it, except that corruption does not end the
walk (DFReader stops at the first record whose type has no FMT): see *Damage*. The records of
each type are then decoded column-wise with numpy and written in file order.

:func:`iter_dataflash` gives the same records, valued the same way, as Python records in file
order (``livesweep stream`` sends them as MAVLink); :class:`DataflashLog` gives them column-wise,
as numpy arrays per message type (``livesweep inspect``).

Channels
    ``/dataflash/<NAME>`` per message type (``FMT``, ``PARM``, ``MSG``, ``ATT``, ``SIDD``,
    ``SIDS`` ... every type in the log), schema ``dataflash.<NAME>`` (a JSON Schema of its
    fields), message encoding ``json``. A multi-instance type (``IMU``, ``BARO``, ``GPS`` ...
    whose FMTU marks an instance field with ``#``) stays **one channel** and keeps its instance
    field (e.g. ``IMU.I``), as MAVLink topics keep ``sysid``/``compid``; the field is named in
    the channel metadata ``instance_field``. Pick one instance with a filter on that field.

Values and units
    Values are in the unit the log declares (FMTU unit ids, looked up in the UNIT table) with
    the multiplier applied: a field of format ``c``/``C``/``e``/``E`` is divided by 100 and one
    of format ``L`` by 10**7 (the multiplier the format itself implies, which FMTU repeats);
    any other numeric field is multiplied by its FMTU multiplier (MULT table) unless that is
    ``-``/``0``/``?``/1 (for example ``CTUN.CRt``, int16 cm/s with multiplier 0.01, is stored in
    m/s; ``BARO.SMS``, ms, in s). Multipliers are never applied twice. **Exception:** ``TimeUS``
    is kept as the integer it is (µs since boot, exact), so signals can use it as their stamp
    (``stamp = "TimeUS"``, ``stamp_scale = 1e-6``). Channel metadata: ``units`` (JSON
    ``{field: unit}``; ``TimeUS`` -> ``"us"``, instance fields -> ``"instance"``, "" when
    dimensionless or undeclared), ``multipliers`` (JSON ``{field: multiplier applied}``, only the
    fields that were scaled), ``format`` (the DataFlash format string), ``type_id`` and
    ``instance_field``. PX4 sdlog2 logs declare no units (``units`` is ``{}``).
    ``float`` fields are written as the shortest decimal that gives back the same float32 (as
    MAVLink records are); ``char`` fields as strings; ``a`` (int16[32]) as lists.

Time base
    The vehicle time of a message is its ``TimeUS`` (or ``TimeMS`` x 1000 in old APM logs, not
    for ACC*/GYR*); a message without a time field (FMT, PX4 sdlog2 messages) takes the time of
    the message before it (PX4: the last ``TIME.StartTime``; the first time in the log for
    records before any time stamp).
    ``publish_time`` = that vehicle time (ns since boot).
    ``log_time`` = the same shifted to UNIX time when the log has a GPS time: the first ``GPS``
    record with ``GWk > 0`` (ArduPilot: GPS week + ms of week, minus 18 leap seconds, as
    pymavlink does) or ``GPSTime > 0`` (PX4, µs UNIX time) fixes the offset; otherwise
    ``log_time`` = ``publish_time`` (boot-relative ns). The offset used, in ns, is stored in the
    ``dataflash`` metadata record (``time_base`` ``"gps"`` or ``"boot"``, ``boot_to_unix_ns``).
    ``gps_time=False`` forces boot-relative times.

    Records are written in file order, so ``log_time`` may step back a little where types
    interleave (each record keeps its own stamp); readers sort by time per topic.

Damage
    A log cut mid-message (the last record incomplete) ends cleanly:
    ``skipped["truncated_tail"]`` and a warning. Bytes that are not records (flipped or zeroed
    bytes, an overwritten header, records of a type whose FMT is missing) are skipped up to the
    next ``A3 95 <type with an FMT>`` whose record is followed by another record header, and
    counted per run in ``skipped["garbage"]`` with a warning giving the bytes, their share of the
    file and the first offset. An FMT record that is unusable (bad name, format characters,
    column count or length) or that redefines a type differently is not used (the first
    definition of a type wins); records of a type without a usable FMT are framed by the length
    it declares and counted in ``skipped["bad_format"]``. If less than
    ``MIN_RECORD_FRACTION`` (half) of the file's bytes are records that convert, nothing is
    written and :class:`~livesweep.errors.LogFormatError` gives the fraction, unless ``partial``
    (``livesweep convert --partial``) asks to convert what is readable. DataFlash has no
    checksum, so a record overwritten in place is converted as it reads; a time stamp beyond
    10**15 µs is replaced by the previous record's time (``repaired["implausible_time"]``). A
    file that does not start with an FMT record (``A3 95 80``) defining a usable type
    (ArduPilot's first FMT defines FMT itself; sdlog2's defines another type) raises
    :class:`~livesweep.errors.LogFormatError` naming the file, and nothing is written.

Memory: the file, the record offsets and the decoded numpy records are held in memory (a few
times the file size); Python values are built 65 536 records at a time.

``format_version``: the firmware string of ``VER.FWS`` or of the first ``MSG`` that names the
firmware (e.g. ``"ArduCopter V4.0.3"``; the git hash in brackets is dropped; it stays in the
``MSG``/``VER`` channels), or ``"PX4 sdlog2 (<Arch>, git <hash>)"``; "" when the log has none.
"""

from __future__ import annotations

import json
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, NamedTuple

import numpy as np

from livesweep.convert.common import (MAX_BOOT_US, MIN_RECORD_FRACTION, UNIX_RANGE_S, ConversionResult,
                                      ConversionWriter, refuse_options)
from livesweep.errors import LogFormatError
from livesweep.numeric import float_json_schema

__all__ = ["DataflashRecord", "DataflashLog", "convert_dataflash", "iter_dataflash"]

_HEAD = b"\xa3\x95"
_FMT_TYPE = 0x80
_FMT_LEN = 89

# DataFlash format character -> numpy dtype (little endian, packed)
_NP = {
    "b": "i1", "B": "u1", "M": "u1", "h": "<i2", "H": "<u2", "i": "<i4", "I": "<u4",
    "q": "<i8", "Q": "<u8", "f": "<f4", "d": "<f8", "g": "<f2",
    "n": "S4", "N": "S16", "Z": "S64", "a": ("<i2", (32,)),
    "c": "<i2", "C": "<u2", "e": "<i4", "E": "<u4", "L": "<i4",
}
# format characters whose multiplier is implied by the format itself (divisors, exact)
_IMPLIED = {"c": 100, "C": 100, "e": 100, "E": 100, "L": 10_000_000}
_STRINGS = frozenset("nNZ")
_FLOATS = frozenset("fdg")
_NO_MULT = frozenset("-0?")     # FMTU multiplier ids that mean "none", "1" and "unknown"

_FIRMWARE_RE = re.compile(r"^((?:Ardu\w+|APM:\w+|APMrover2|Rover|Blimp|AntennaTracker|ArduSub|PX4\w*)"
                          r"\s+V?\d[\w.\-]*)")
_GPS_EPOCH_S = 315_964_800          # 1980-01-06 in UNIX seconds
_GPS_LEAP_S = 18                    # GPS - UTC since 2017 (what pymavlink's DFReader subtracts)
_UNIX_MIN_NS, _UNIX_MAX_NS = (s * 10**9 for s in UNIX_RANGE_S)
_WINDOW = 65_536                    # records turned into Python values at a time (bounds memory)
_PROGRESS_RECORDS = 50_000          # records framed between two progress calls


class _Fmt(NamedTuple):
    """One FMT definition: type name, format characters, column names, record length [bytes]."""

    name: str
    fmt: str
    columns: list
    len: int


def _text(b: bytes) -> str:
    b = b.split(b"\x00", 1)[0]
    try:
        return b.decode("utf-8")
    except UnicodeDecodeError:
        return b.decode("latin-1")


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


def _dtype(fmt: str) -> np.dtype:
    names = [f"f{i}" for i in range(len(fmt))]
    return np.dtype({"names": names, "formats": [_NP[c] for c in fmt]})


def _fmt_problem(ftype: int, flen: int, name: str, fmt: str, cols: list[str]) -> str:
    """Why an FMT record cannot define a message type ("" when it can)."""
    if not (1 <= len(name) <= 4 and name.isascii() and name.isprintable()):
        return f"name {name!r} is not 1-4 printable characters"
    if any(c not in _NP for c in fmt):
        return f"format {fmt!r} has characters DataFlash does not define"
    if len(cols) != len(fmt):
        return f"{len(cols)} column names for the {len(fmt)} fields of format {fmt!r}"
    if _dtype(fmt).itemsize + 3 != flen:
        return f"length {flen} does not match format {fmt!r} ({_dtype(fmt).itemsize + 3} bytes)"
    if ftype == _FMT_TYPE and (name != "FMT" or flen != _FMT_LEN):
        return f"type 128 must be FMT of length {_FMT_LEN}, got {name!r} of length {flen}"
    return ""


def _read_fmt(data: bytes, pos: int) -> tuple[int, int, _Fmt, str]:
    """(type id, length, format, problem) of the FMT record at ``pos`` (problem "" when usable)."""
    ftype, flen, name, fmt, cols = struct.unpack_from("<BB4s16s64s", data, pos + 3)
    name, fmt, cols = _text(name), _text(fmt), _text(cols)
    columns = cols.split(",") if cols else []
    return ftype, flen, _Fmt(name, fmt, columns, flen), _fmt_problem(ftype, flen, name, fmt, columns)


def _check_head(src: Path, data: bytes) -> None:
    if not data:
        raise LogFormatError(f"{src}: the file is empty, not a DataFlash log")
    if not data.startswith(_HEAD + bytes([_FMT_TYPE])):
        raise LogFormatError(f"{src}: not an ArduPilot DataFlash / PX4 sdlog2 log: it does not start with the FMT "
                             f"record (A3 95 80); first bytes {data[:8].hex(' ')}")
    if len(data) < _FMT_LEN:
        raise LogFormatError(f"{src}: corrupt DataFlash header: the file ({len(data)} bytes) is shorter than its "
                             f"first FMT record ({_FMT_LEN} bytes)")
    _, _, f, why = _read_fmt(data, 0)
    if not f.fmt and not why:
        why = "its format is empty"
    if why:
        raise LogFormatError(f"{src}: corrupt DataFlash header: the first record (FMT, A3 95 80) does not define a "
                             f"message type: {why}")


@dataclass
class _Index:
    """Where the records of a DataFlash file are, and what is not a record.

    Attributes
    ----------
    formats : dict[int, _Fmt]
        Usable FMT definitions by type id (the first one of each type wins).
    offsets : dict[int, list[int]]
        Byte offsets of the complete records of every usable type, in file order.
    unusable : dict[int, str]
        Type ids whose FMT is unusable (framed by its length, not decoded) and why.
    unusable_records : int
        Records of those types, and FMT records that contradict an earlier one.
    garbage : list of (int, int)
        Runs of bytes that are no record: (offset, length).
    tail : (int, int) or None
        A record cut by the end of the file: (offset, bytes present).
    """

    formats: dict
    offsets: dict
    unusable: dict = field(default_factory=dict)
    unusable_records: int = 0
    garbage: list = field(default_factory=list)
    tail: tuple | None = None

    @property
    def record_bytes(self) -> int:
        """Bytes of the records that are decoded."""
        return sum(len(o) * self.formats[t].len for t, o in self.offsets.items())


def _index(data: bytes, progress=None) -> _Index:
    """Frame every record of ``data``, resynchronising past corruption.

    ``progress(bytes framed, bytes in all, "bytes")``, when given, is called every
    ``_PROGRESS_RECORDS`` records.

    A record is ``A3 95 <type>`` plus the length the type's FMT gives. In sync, records follow one
    another, as DFReader reads them. Anything else (flipped or zeroed bytes, a header overwritten,
    a type without an FMT, an FMT record that is unusable and not followed by a record, so that
    it would swallow the next one) starts a run of garbage, which ends at the next
    ``A3 95 <known type>`` whose record is followed by another record header (or the end of the
    file), so a header pattern inside a payload does not restart the framing.
    """
    fmt_default = _Fmt("FMT", "BBnNZ", ["Type", "Length", "Name", "Format", "Columns"], _FMT_LEN)
    idx = _Index(formats={_FMT_TYPE: fmt_default}, offsets={})
    lengths = {_FMT_TYPE: _FMT_LEN}
    n = len(data)
    pos, garbage_from = 0, None
    until_progress = _PROGRESS_RECORDS

    formats, offsets = idx.formats, idx.offsets

    def follows(p: int) -> bool:
        return p >= n - 1 or (data[p] == 0xA3 and data[p + 1] == 0x95)

    while pos < n:
        if progress is not None:
            until_progress -= 1
            if not until_progress:
                progress(pos, n, "bytes")
                until_progress = _PROGRESS_RECORDS
        # in sync, the common case: a record of a known type (not FMT) followed by a record header
        if garbage_from is None and pos + 3 <= n and data[pos] == 0xA3 and data[pos + 1] == 0x95:
            while True:
                mtype = data[pos + 2]
                length = lengths.get(mtype)
                if mtype == _FMT_TYPE or length is None or mtype not in formats:
                    break
                nxt = pos + length
                if nxt > n or not (nxt >= n - 1 or (data[nxt] == 0xA3 and data[nxt + 1] == 0x95)):
                    break
                offsets.setdefault(mtype, []).append(pos)
                pos = nxt
                if progress is not None:
                    until_progress -= 1
                    if not until_progress:
                        progress(pos, n, "bytes")
                        until_progress = _PROGRESS_RECORDS
                if pos + 3 > n or data[pos] != 0xA3 or data[pos + 1] != 0x95:
                    break
            if pos >= n:
                break
        mtype = data[pos + 2] if pos + 2 < n and data[pos] == 0xA3 and data[pos + 1] == 0x95 else None
        length = lengths.get(mtype)
        if (length is not None and pos + length > n) or (n - pos < 3 and _HEAD.startswith(data[pos:])):
            if garbage_from is not None:                # a record cut by the end of the file
                idx.garbage.append((garbage_from, pos - garbage_from))
            idx.tail = (pos, n - pos)
            return idx
        fmt = _read_fmt(data, pos) if mtype == _FMT_TYPE else None
        if length is not None and not follows(pos + length):
            trusted = garbage_from is None and not (fmt is not None and fmt[3])
        else:
            trusted = length is not None
        if not trusted:
            if garbage_from is None:
                garbage_from = pos
            nxt = data.find(_HEAD, pos + 1)
            pos = n if nxt < 0 else nxt
            continue
        if garbage_from is not None:
            idx.garbage.append((garbage_from, pos - garbage_from))
            garbage_from = None
        if fmt is not None:
            _define(idx, lengths, *fmt)
        if mtype in idx.formats and not (fmt is not None and fmt[3]):
            idx.offsets.setdefault(mtype, []).append(pos)
        else:
            idx.unusable_records += 1
        pos += length
    if garbage_from is not None:
        idx.garbage.append((garbage_from, n - garbage_from))
    return idx


def _define(idx: _Index, lengths: dict, ftype: int, flen: int, f: _Fmt, why: str) -> None:
    """Take one FMT record into the index: the first usable definition of a type wins; an
    unusable one still frames its type's records (by its length) when the type has none yet."""
    if ftype in idx.formats:
        if idx.formats[ftype] != f:
            idx.unusable_records += 1
            idx.unusable.setdefault(ftype, f"an FMT record redefines {idx.formats[ftype].name} (type {ftype}) "
                                           f"differently ({why or f.name + ' ' + repr(f.fmt)}); the first kept")
        return
    if ftype in idx.unusable:
        return
    if why:
        idx.unusable[ftype] = f"unusable FMT for type {ftype} ({why})"
        if flen >= 3:
            lengths[ftype] = flen
        return
    idx.formats[ftype] = f
    lengths[ftype] = flen


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


def _time_us(t: _Type) -> np.ndarray | None:
    """The vehicle time [µs since boot] each record of ``t`` carries (-1 where implausible), or None."""
    cols = t.columns
    if "TimeUS" in cols:
        raw, scale = t.raw[f"f{cols.index('TimeUS')}"], 1
    elif cols and cols[0] == "TimeMS" and not t.name.startswith(("ACC", "GYR")):
        raw, scale = t.raw["f0"], 1000
    elif t.name == "TIME" and "StartTime" in cols:                  # PX4 sdlog2
        raw, scale = t.raw[f"f{cols.index('StartTime')}"], 1
    else:
        return None
    if raw.dtype.kind not in "iu":
        return None
    x = raw.astype(np.float64) * scale          # range check first: uint64 garbage would wrap in int64
    ok = (x >= 0) & (x <= MAX_BOOT_US)
    return np.where(ok, raw.astype(np.int64) * scale, -1)


def _gps_offset_ns(types: dict[int, _Type], order_pos: dict[int, np.ndarray], vt_us: np.ndarray) -> int | None:
    """UNIX ns minus boot ns, from the first GPS record with a valid GPS time (None: no GPS time)."""
    best = None    # (global position, offset_ns)
    for t in types.values():
        if not t.name.startswith("GPS") or t.raw is None or not t.offsets.size:
            continue
        c = t.columns
        pos = order_pos[t.tid]
        if {"GWk", "GMS"} <= set(c) and "TimeUS" in c:
            wk = t.raw[f"f{c.index('GWk')}"].astype(np.int64)
            ms = t.raw[f"f{c.index('GMS')}"].astype(np.int64)
            unix_ns = ((_GPS_EPOCH_S - _GPS_LEAP_S + 604_800 * wk) * 1000 + ms) * 1_000_000
            ok = np.flatnonzero((wk > 0) & (unix_ns >= _UNIX_MIN_NS) & (unix_ns <= _UNIX_MAX_NS) & (vt_us[pos] >= 0))
            if ok.size:
                i = ok[0]
                cand = (int(pos[i]), int(unix_ns[i]) - int(vt_us[pos[i]]) * 1000)
                best = cand if best is None or cand[0] < best[0] else best
        elif "GPSTime" in c:
            graw = t.raw[f"f{c.index('GPSTime')}"]
            gns = graw.astype(np.float64) * 1000           # range check in float: garbage would wrap
            ok = np.flatnonzero((gns >= _UNIX_MIN_NS) & (gns <= _UNIX_MAX_NS))
            gt = graw.astype(np.int64)
            if ok.size:
                i = ok[0]
                cand = (int(pos[i]), int(gt[i]) * 1000 - int(vt_us[pos[i]]) * 1000)
                best = cand if best is None or cand[0] < best[0] else best
    return None if best is None else best[1]


def _firmware(types: dict[int, _Type]) -> str:
    by_name = {t.name: t for t in types.values() if t.offsets.size}
    ver, msg = by_name.get("VER"), by_name.get("MSG")
    for t, column in ((ver, "FWS"), (msg, "Message")):
        if t is not None and column in t.columns:
            for s in t.column(column):
                m = _FIRMWARE_RE.match(s.strip())
                if m:
                    return m.group(1)
    if ver is not None and "FwGit" in ver.columns:
        arch = ver.column("Arch")[0] if "Arch" in ver.columns else "?"
        return f"PX4 sdlog2 ({arch}, git {ver.column('FwGit')[0][:8]})"
    return ""


def _percent(part: int, whole: int) -> str:
    pct = 100 * part / whole
    return f"{pct:.2f} %" if pct >= 0.01 else "< 0.01 %"


def _check_coverage(src: Path, idx: _Index, n_bytes: int, partial: bool) -> None:
    """LogFormatError, before anything is written, when less than MIN_RECORD_FRACTION of the file's
    bytes are records that can be converted (unless ``partial``)."""
    read = idx.record_bytes
    if partial or read >= MIN_RECORD_FRACTION * n_bytes:
        return
    lost = sum(length for _, length in idx.garbage)
    first = f", first at offset {idx.garbage[0][0]}" if idx.garbage else ""
    raise LogFormatError(
        f"{src}: only {_percent(read, n_bytes)} of the file ({read} of {n_bytes} bytes) reads as DataFlash records "
        f"that can be converted ({lost} bytes of corruption in {len(idx.garbage)} runs{first}; "
        f"{idx.unusable_records} records without a usable FMT): nothing converted; pass --partial to convert what is "
        "readable")


class DataflashRecord(NamedTuple):
    """One record of a DataFlash log, as :func:`convert_dataflash` writes it.

    Attributes
    ----------
    time_us : int
        Its vehicle time [µs since boot] (``TimeUS``; a record without one takes the time of the
        record before it, as in the MCAP ``publish_time``).
    name : str
        The message type (``ATT``, ``RATE``, ``MSG`` ...).
    values : dict
        ``{column: value}`` in the declared units with the multipliers applied (the module
        docstring), exactly the JSON record of the ``/dataflash/<name>`` channel.
    """

    time_us: int
    name: str
    values: dict


@dataclass
class _Log:
    """A DataFlash file decoded: its types, the type and time of every record in file order, and
    what was skipped or repaired on the way."""

    types: dict             # type id -> _Type, values planned
    live: list              # the types that have records
    tsel: np.ndarray        # per record, in file order: its index in ``live``
    vt: np.ndarray          # per record, in file order: vehicle time [µs since boot]
    order_pos: dict         # type id -> the file-order positions of its records
    fmtu: dict
    skipped: dict
    warnings: list
    bad_time: int


def _load(src: Path, partial: bool, progress=None) -> _Log:
    """Frame, decode and time every record of ``src`` (LogFormatError as convert_dataflash);
    ``progress(done, total, unit)`` while framing (:func:`_index`) and decoding (``"message
    types"``)."""
    try:
        data = src.read_bytes()
    except OSError as e:
        raise LogFormatError(f"{src}: cannot be read: {e.strerror or e}") from None
    _check_head(src, data)
    idx = _index(data, progress)
    n_bytes = len(data)
    _check_coverage(src, idx, n_bytes, partial)
    buf = np.frombuffer(data, dtype=np.uint8)

    warnings: list[str] = []
    skipped: dict[str, int] = {}

    def skip(reason: str, n: int, text: str) -> None:
        skipped[reason] = skipped.get(reason, 0) + n
        warnings.append(text)

    # ---- decode every type, column-wise
    types: dict[int, _Type] = {}
    for k, tid in enumerate(sorted(idx.offsets)):   # channels in type-id order
        if progress is not None:
            progress(k, len(idx.offsets), "message types")
        f = idx.formats[tid]
        t = _Type(tid, f.name, f.fmt, list(f.columns))
        t.offsets = np.asarray(idx.offsets[tid], dtype=np.int64)
        t.raw = _decode_raw(buf, t.offsets, f.len, _dtype(f.fmt))
        types[tid] = t

    # ---- damage: bytes no record covers, records no usable FMT describes, a cut last record
    if idx.unusable_records:
        skip("bad_format", idx.unusable_records, f"{idx.unusable_records} records not converted: "
                                                 + "; ".join(idx.unusable.values()))
    if idx.garbage:
        nbytes = sum(length for _, length in idx.garbage)
        skip("garbage", len(idx.garbage), f"{len(idx.garbage)} runs of bytes that are not DataFlash records skipped "
                                          f"({nbytes} bytes, {_percent(nbytes, n_bytes)} of the file, first at "
                                          f"offset {idx.garbage[0][0]})")
    if idx.tail is not None:
        at, have = idx.tail
        skip("truncated_tail", 1, f"the log ends mid-message: the last record (at offset {at}) is cut; {have} bytes "
                                  "ignored" if have >= 3 else
                                  f"the log ends mid-message: {have} bytes of a cut record at offset {at} ignored")
    if partial and idx.record_bytes < MIN_RECORD_FRACTION * n_bytes:
        warnings.append(f"only {_percent(idx.record_bytes, n_bytes)} of the file's bytes are converted records "
                        "(converted as asked, --partial)")

    # ---- values, units, multipliers
    unit_tab, mult_tab, fmtu = _lookup_tables(types)
    for t in types.values():
        _plan(t, unit_tab, mult_tab, fmtu)

    # ---- file order and times
    live = [t for t in types.values() if t.offsets.size]
    all_offs = np.concatenate([t.offsets for t in live]) if live else np.zeros(0, dtype=np.int64)
    type_of = np.concatenate([np.full(t.offsets.size, k) for k, t in enumerate(live)]) if live else all_offs
    order = np.argsort(all_offs, kind="stable")
    n = order.size
    vt = np.full(n, -1, dtype=np.int64)             # vehicle time [µs], in file order
    order_pos: dict[int, np.ndarray] = {}
    inv = np.empty(n, dtype=np.int64)
    inv[order] = np.arange(n)
    start = 0
    bad_time = 0
    for t in live:
        pos = inv[start:start + t.offsets.size]
        order_pos[t.tid] = pos
        tu = _time_us(t)
        if tu is not None:
            vt[pos] = tu
            bad_time += int((tu < 0).sum())
        start += t.offsets.size
    have = vt >= 0
    if have.any():
        first = int(vt[np.argmax(have)])
        idx = np.where(have, np.arange(n), -1)
        np.maximum.accumulate(idx, out=idx)
        vt = np.where(idx >= 0, vt[np.maximum(idx, 0)], first)
    else:
        vt[:] = 0
        warnings.append("no record carries a time stamp (TimeUS/TimeMS/TIME): every time is 0")
    if bad_time:
        warnings.append(f"{bad_time} records with an impossible time stamp (over {MAX_BOOT_US} us since boot) "
                        "take the time of the record before them")
    return _Log(types, live, type_of[order], vt, order_pos, fmtu, skipped, warnings, bad_time)


def _name_topics(types: dict[int, _Type], warnings: list) -> None:
    """Each type's MCAP topic, ``/dataflash/<NAME>``; a second type of the same name gets
    ``/dataflash/<NAME>_<type id>`` (with a warning)."""
    names_used: dict[str, int] = {}
    for t in types.values():
        topic = f"/dataflash/{t.name}"
        if t.name in names_used and names_used[t.name] != t.tid:
            topic = f"/dataflash/{t.name}_{t.tid}"
            warnings.append(f"two FMT types are named {t.name!r} (ids {names_used[t.name]} and {t.tid}): "
                            f"the second is written on {topic}")
        names_used.setdefault(t.name, t.tid)
        t.topic = topic


class DataflashLog:
    """A DataFlash / sdlog2 log read column-wise: every message type's times and values as numpy
    arrays, without a Python record per message (what ``livesweep inspect`` reads).

    Topics, times and values are those :func:`convert_dataflash` writes: topic
    ``/dataflash/<NAME>``, log time [ns] (boot time shifted to UNIX time by the first GPS time
    unless ``gps_time`` is False), values in the declared units with the multipliers applied.

    Parameters
    ----------
    src : str or Path
    gps_time, partial : bool
        As for :func:`convert_dataflash`.
    progress : callable, optional
        ``progress(done, total, unit)``, called now and then while the file is framed (``unit``
        ``"bytes"``) and its message types decoded (``"message types"``).

    Attributes
    ----------
    topics : tuple of str
        In type-id order (the order the channels are written in).
    records : int
        Records read.
    warnings : tuple of str
        What :func:`convert_dataflash` would warn of (damage, duplicate type names).
    skipped : dict of str -> int
        As :attr:`ConversionResult.skipped`.

    Raises
    ------
    LogFormatError
        As :func:`convert_dataflash`.
    """

    def __init__(self, src, *, gps_time: bool = True, partial: bool = False, progress=None):
        log = _load(Path(src), partial, progress)
        warnings = list(log.warnings)
        _name_topics(log.types, warnings)
        offset_ns = _gps_offset_ns(log.types, log.order_pos, log.vt) if gps_time else None
        self._log = log
        self._log_ns = log.vt * 1000 + (offset_ns or 0)
        self._by_topic = {t.topic: t for t in log.live}
        self.topics = tuple(self._by_topic)
        self.records = int(log.tsel.size)
        self.warnings = tuple(warnings)
        self.skipped = dict(log.skipped)

    def times_ns(self, topic: str) -> np.ndarray:
        """The log time [ns] of each record of ``topic``, in file order (int64)."""
        return self._log_ns[self._log.order_pos[self._by_topic[topic].tid]]

    def first(self, topic: str) -> dict:
        """The first record of ``topic`` as ``{column: value}`` (the JSON record convert writes)."""
        t = self._by_topic[topic]
        return dict(zip(t.columns, t.rows(0, 1)[0]))

    def units(self, topic: str) -> dict:
        """``{column: unit}`` of ``topic`` (the channel's ``units`` metadata)."""
        return dict(self._by_topic[topic].units)

    def columns(self, topic: str) -> tuple[str, ...]:
        """The column names of ``topic``."""
        return tuple(self._by_topic[topic].columns)

    def column(self, topic: str, name: str) -> np.ndarray | None:
        """Column ``name`` of ``topic`` as float64 values, the records' values in file order; None
        for a column that is not one number per record (text, arrays) or that ``topic`` lacks."""
        t = self._by_topic[topic]
        if name not in t.columns:
            return None
        i = t.columns.index(name)
        if t.fmt[i] in _STRINGS or t.fmt[i] == "a":
            return None
        return np.asarray(t.convs[i](t.raw[f"f{i}"]), dtype=np.float64)

    def iter_records(self, topics) -> Iterator[tuple[str, int, dict]]:
        """``(topic, log time [ns], {column: value})`` of the records of ``topics``, in file order."""
        log = self._log
        want = frozenset(topics)
        keep = np.array([t.topic in want for t in log.live], dtype=bool)
        sel = np.flatnonzero(keep[log.tsel]) if log.live else np.zeros(0, dtype=np.int64)
        names = [t.topic for t in log.live]
        for ti, t_ns, values in _rows(log, sel, self._log_ns):
            yield names[ti], t_ns, values


def iter_dataflash(src, *, names=None, partial: bool = False) -> Iterator[DataflashRecord]:
    """The records of a DataFlash / sdlog2 log in file order, valued as :func:`convert_dataflash` writes them.

    Parameters
    ----------
    src : str or Path
    names : iterable of str, optional
        Only these message types (e.g. ``{"ATT", "RATE"}``); default every type.
    partial : bool
        As for :func:`convert_dataflash`: read a log even when less than ``MIN_RECORD_FRACTION``
        of it is records.

    Returns
    -------
    iterator of DataflashRecord
        The file is read and checked before this returns; values are built 65 536 records at a
        time.

    Raises
    ------
    LogFormatError
        As :func:`convert_dataflash`: ``src`` missing, not DataFlash, a corrupt header, or mostly
        corruption (without ``partial``), naming the file.
    """
    log = _load(Path(src), partial)
    want = None if names is None else frozenset(names)
    keep = np.array([want is None or t.name in want for t in log.live], dtype=bool)
    sel = np.flatnonzero(keep[log.tsel]) if log.live else np.zeros(0, dtype=np.int64)
    return _records(log, sel)


def _records(log: _Log, sel: np.ndarray) -> Iterator[DataflashRecord]:
    live = log.live
    for ti, t_us, values in _rows(log, sel, log.vt):
        yield DataflashRecord(t_us, live[ti].name, values)


def _rows(log: _Log, sel: np.ndarray, times: np.ndarray) -> Iterator[tuple[int, int, dict]]:
    """``(type index, times[k], {column: value})`` of the records ``sel`` (indices into the file's
    records, in file order), values built :data:`_WINDOW` records at a time."""
    live = log.live
    keys = [t.columns for t in live]
    cursor = [0] * len(live)
    for k0 in range(0, sel.size, _WINDOW):
        at = sel[k0:k0 + _WINDOW]
        win = log.tsel[at]
        pending = {}
        for ti, cnt in enumerate(np.bincount(win, minlength=len(live)).tolist()):
            if cnt:
                pending[ti] = iter(live[ti].rows(cursor[ti], cursor[ti] + cnt))
                cursor[ti] += cnt
        for ti, t in zip(win.tolist(), times[at].tolist()):
            yield ti, t, dict(zip(keys[ti], next(pending[ti])))


def convert_dataflash(src, out, *, gps_time: bool = True, partial: bool = False, **options) -> ConversionResult:
    """Convert the DataFlash / sdlog2 log ``src`` to the MCAP file ``out`` (see the module docstring).

    Parameters
    ----------
    src, out : str or Path
    gps_time : bool
        Shift ``log_time`` to UNIX time with the log's first GPS time (default); False keeps
        boot-relative times.
    partial : bool
        Convert even when less than ``MIN_RECORD_FRACTION`` of the file's bytes are records
        that can be converted (the default refuses, so a badly damaged log never passes for a
        whole one).

    Returns
    -------
    ConversionResult

    Raises
    ------
    LogFormatError
        ``src`` missing, empty, not DataFlash or with a corrupt header (naming the file), less
        than ``MIN_RECORD_FRACTION`` of it converts (without ``partial``; the message gives
        the fraction and where the corruption starts), or ``out`` cannot be written; nothing is
        left at ``out`` then.
    ConfigError
        An option this converter does not take.
    """
    src, out = Path(src), Path(out)
    refuse_options(src, "a DataFlash log", options, "gps_time and partial only")
    log = _load(src, partial)
    types, warnings = log.types, log.warnings
    offset_ns = _gps_offset_ns(types, log.order_pos, log.vt) if gps_time else None
    time_base = "gps" if offset_ns is not None else "boot"
    pub_ns = log.vt * 1000
    log_ns = pub_ns + (offset_ns or 0)

    # ---- write
    with ConversionWriter(src, out, "dataflash", _firmware(types)) as w:
        writer = w.writer
        _name_topics(types, warnings)
        for t in types.values():
            topic = t.topic
            meta = {"units": json.dumps(t.units), "multipliers": json.dumps(t.mults), "format": t.fmt,
                    "type_id": str(t.tid), "instance_field": t.instance}
            writer.add_channel(topic, f"dataflash.{t.name}", _schema(t), meta)
        writer.add_metadata("dataflash", {"time_base": time_base, "boot_to_unix_ns": str(offset_ns or 0),
                                          "units_declared": str(bool(log.fmtu)).lower()})
        live = log.live
        keys = [t.columns for t in live]
        topics = [t.topic for t in live]
        write = writer.write
        tsel = log.tsel
        n = tsel.size
        cursor = [0] * len(live)
        for k0 in range(0, n, _WINDOW):            # Python values for a window of records at a time
            k1 = min(n, k0 + _WINDOW)
            win = tsel[k0:k1]
            pending = {}
            for ti, cnt in enumerate(np.bincount(win, minlength=len(live)).tolist()):
                if cnt:
                    pending[ti] = iter(live[ti].rows(cursor[ti], cursor[ti] + cnt))
                    cursor[ti] += cnt
            for ti, lt, pt in zip(win.tolist(), log_ns[k0:k1].tolist(), pub_ns[k0:k1].tolist()):
                write(topics[ti], dict(zip(keys[ti], next(pending[ti]))), log_time_ns=lt, publish_time_ns=pt)
        w.messages_read = int(n)
        if log.bad_time:
            w.repair("implausible_time", log.bad_time)
        for reason, count in log.skipped.items():
            w.skip(reason, count)
        for text in warnings:
            w.warn(text)
        return w.finish()
