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

Modules: this module converts (:func:`convert_dataflash`), iterates (:func:`iter_dataflash`) and
reads columns (:class:`DataflashLog`). The file is framed in
:mod:`~livesweep.convert.dataflash_framing`, its types valued in
:mod:`~livesweep.convert.dataflash_values`, timed in :mod:`~livesweep.convert.dataflash_time` and
loaded, in file order, in :mod:`~livesweep.convert.dataflash_load`.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Iterator, NamedTuple

import numpy as np

from livesweep.convert.common import ConversionResult, ConversionWriter, refuse_options
from livesweep.convert.dataflash_framing import (_FMT_LEN, _FMT_TYPE, _HEAD, _NP, _PROGRESS_RECORDS, _check_coverage,
                                                 _check_head, _define, _dtype, _Fmt, _fmt_problem, _Index, _index,
                                                 _percent, _read_fmt, _text)
from livesweep.convert.dataflash_load import _load, _Log, _name_topics
from livesweep.convert.dataflash_time import (_GPS_EPOCH_S, _GPS_LEAP_S, _UNIX_MAX_NS, _UNIX_MIN_NS, _gps_offset_ns,
                                              _time_us)
from livesweep.convert.dataflash_values import (_FLOATS, _IMPLIED, _NO_MULT, _STRINGS, _as_f32, _as_list, _as_text,
                                                _decode_raw, _divided, _f32_decimal, _lookup_tables, _multiplied,
                                                _plan, _scale, _schema, _Type)

__all__ = ["DataflashRecord", "DataflashLog", "convert_dataflash", "iter_dataflash"]

_FIRMWARE_RE = re.compile(r"^((?:Ardu\w+|APM:\w+|APMrover2|Rover|Blimp|AntennaTracker|ArduSub|PX4\w*)"
                          r"\s+V?\d[\w.\-]*)")
_WINDOW = 65_536                    # records turned into Python values at a time (bounds memory)

#: Names defined in the modules above that are also importable from here.
_MOVED = (
    _HEAD, _FMT_TYPE, _FMT_LEN, _NP, _PROGRESS_RECORDS, _Fmt, _text, _dtype, _fmt_problem, _read_fmt, _check_head,
    _Index, _index, _define, _percent, _check_coverage,
    _IMPLIED, _FLOATS, _NO_MULT, _f32_decimal, _Type, _decode_raw, _lookup_tables, _scale, _as_list, _as_text,
    _as_f32, _divided, _multiplied, _plan,
    _GPS_EPOCH_S, _GPS_LEAP_S, _UNIX_MIN_NS, _UNIX_MAX_NS, _time_us,
)


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
