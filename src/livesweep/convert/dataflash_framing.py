"""Framing a DataFlash / sdlog2 file into records: :func:`_index`.

One job: find where every record of the file is (``A3 95 <type>`` plus the length its FMT gives),
resynchronising past corruption, and say what is not a record: the FMT definitions that can be
used, the runs of garbage, a record cut by the end of the file, and whether enough of the file is
records to convert (:func:`_check_coverage`). The rules are described under *Damage* in
:mod:`livesweep.convert.dataflash`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from livesweep.convert.common import MIN_RECORD_FRACTION
from livesweep.errors import LogFormatError

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

