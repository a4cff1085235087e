"""A DataFlash / sdlog2 file read into memory: :func:`_load`.

One job: frame the file (:mod:`~livesweep.convert.dataflash_framing`), decode every message type
column-wise (:mod:`~livesweep.convert.dataflash_values`), say what was skipped, and put every
record in file order with its vehicle time (:mod:`~livesweep.convert.dataflash_time`), a record
without one taking the time of the record before it; and name each type's topic
(:func:`_name_topics`). :mod:`livesweep.convert.dataflash` converts, iterates or reads columns from
the result.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from livesweep.convert.common import MAX_BOOT_US, MIN_RECORD_FRACTION
from livesweep.convert.dataflash_framing import _check_coverage, _check_head, _dtype, _index, _percent
from livesweep.convert.dataflash_time import _time_us
from livesweep.convert.dataflash_values import _decode_raw, _lookup_tables, _plan, _Type
from livesweep.errors import LogFormatError

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

