"""Named signals out of MCAP logs: the I/O edge between the logs and the numerics.

A case file's ``[signals]`` table (:class:`~livesweep.config.SignalSpec`) says where each signal
lives: a topic, a field (or arithmetic of fields), the messages to take (``sysid``, ``compid``,
``where``), the field with the vehicle time stamp, and the scaling to engineering units; the
signal's :class:`~livesweep.telemetry.extract.SignalExtractor` (the live aligner's too) reads it.
:func:`read_signals` reads the signals one record (:class:`~livesweep.config.RecordSpec`)
needs and returns them raw: on the signal's own stamp clock, at the log's own (possibly
irregular) rate, with NaN where a message carried ``null``. Nothing is resampled or repaired
here; :mod:`livesweep.consistency.resample` does that and counts what it repairs.

Works on any MCAP file with JSON channels (docs/outputs.md, MCAP recordings), not only MAVLink.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from livesweep.config import RecordSpec, SignalSpec
from livesweep.errors import ConfigError, LogFormatError
from livesweep.telemetry.decoded_cache import cached_columns
from livesweep.telemetry.extract import SignalExtractor, compile_signal
from livesweep.telemetry.mcap_log import read_topics_fields

__all__ = ["RawSignal", "read_signals"]


@dataclass(frozen=True)
class RawSignal:
    """One signal as logged, scaled to engineering units.

    Attributes
    ----------
    name : str
        The signal's name in the case.
    units : str
        Units of ``values``.
    t_s : numpy.ndarray
        Sample times [s] on the signal's stamp clock: ``stamp * stamp_scale`` (vehicle time) or,
        when the signal has no stamp field, the MCAP ``log_time`` in seconds (float64, so about
        0.2 us resolution on a UNIX-epoch clock). In the log's message order (log time), which
        may not be monotonic in the stamp; read-only.
    values : numpy.ndarray
        ``scale * raw + offset`` [units] (``raw``: the field or the expression of fields); NaN
        where the message carried ``null`` or the expression has no finite value; read-only.
    source : str
        Where it came from, ``"<log file name>:<topic>.<field>"`` (the field as the map writes it,
        an expression included), with ``[sysid = 1, axis = 2]`` appended when messages are selected.
    """

    name: str
    units: str
    t_s: np.ndarray
    values: np.ndarray
    source: str


def _group_by_topic(extractors: Iterable[SignalExtractor]) -> dict[str, list[SignalExtractor]]:
    """Signals per topic, in first-seen order."""
    groups: dict[str, list[SignalExtractor]] = {}
    for ex in extractors:
        groups.setdefault(ex.spec.topic, []).append(ex)
    return groups


def _read_topics(log: Path, groups: Mapping[str, list[SignalExtractor]],
                 notes: list[str] | None) -> dict[str, dict[str, np.ndarray]]:
    """Every field (operands, stamps, selection) of every topic the signals need, in one pass over the
    log, or from the decoded-column cache when the log's bytes were decoded before
    (:mod:`livesweep.telemetry.decoded_cache`)."""
    requests: dict[str, list[str]] = {}
    for topic, extractors in groups.items():
        fields = requests.setdefault(topic, [])
        for ex in extractors:
            fields.extend(f for f in ex.read_fields if f not in fields)
    for extractors in groups.values():               # topics that lend their stamp (``stamp_topic``)
        for ex in extractors:
            if ex.spec.stamp_topic:
                fields = requests.setdefault(ex.spec.stamp_topic, [])
                if ex.spec.stamp not in fields:
                    fields.append(ex.spec.stamp)
    try:
        got = cached_columns(log, requests, lambda n: read_topics_fields(log, requests, time="log", notes=n),
                             time="log", missing="error")
    except LogFormatError as e:
        names = ", ".join(ex.spec.name for exs in groups.values() for ex in exs)
        raise LogFormatError(f"signal(s) {names}: {e}") from e
    if notes is not None:
        notes.extend(got["notes"])
    return got["columns"]


def _stamp_seconds(spec: SignalSpec, cols: Mapping[str, np.ndarray],
                   all_cols: Mapping[str, Mapping[str, np.ndarray]] | None = None) -> np.ndarray:
    if spec.stamp is None:
        return cols["t_ns"].astype(np.float64) / 1e9
    if spec.stamp_topic:
        # the stamp of the latest frame of the lending topic received before each message, as live
        # (:data:`livesweep.telemetry.align.BORROW_WITHIN_S`); NaN where there is none
        from livesweep.telemetry.align import BORROW_WITHIN_S

        lend = (all_cols or {})[spec.stamp_topic]
        lt = lend["t_ns"]
        order = np.argsort(lt, kind="stable")
        lt, stamps = lt[order], np.asarray(lend[spec.stamp], float)[order] * spec.stamp_scale
        k = np.searchsorted(lt, cols["t_ns"], side="right") - 1
        ok = (k >= 0) & (cols["t_ns"] - lt[np.clip(k, 0, None)] <= BORROW_WITHIN_S * 1e9)
        return np.where(ok, stamps[np.clip(k, 0, None)] if stamps.size else np.nan, np.nan)
    return cols[spec.stamp] * spec.stamp_scale


def _crop(t: np.ndarray, record: RecordSpec) -> np.ndarray:
    """Mask of samples in ``[start_s, end_s)``; samples with a NaN stamp are kept (the resampler
    drops and counts them)."""
    keep = np.ones(t.shape, dtype=bool)
    if record.start_s is not None:
        keep &= ~(t < record.start_s)
    if record.end_s is not None:
        keep &= ~(t >= record.end_s)
    return keep


def _range_text(record: RecordSpec) -> str:
    lo = "start" if record.start_s is None else f"{float(record.start_s)!r} s"
    hi = "end" if record.end_s is None else f"{float(record.end_s)!r} s"
    return f"[{lo}, {hi})"


def _make_signal(log: Path, record: RecordSpec, ex: SignalExtractor, cols: Mapping[str, np.ndarray],
                 all_cols: Mapping[str, Mapping[str, np.ndarray]] | None = None) -> RawSignal:
    spec = ex.spec
    where = f"{log}: signal {spec.name!r} (topic {spec.topic!r}, field {spec.field!r})"
    t = _stamp_seconds(spec, cols, all_cols)
    if t.size == 0:
        raise LogFormatError(f"{where}: the topic has no messages")
    raw = ex.values(cols)
    chosen = ex.select_columns(cols)
    if chosen is not None:
        if not chosen.any():
            raise LogFormatError(f"{where}: {t.size} messages on the topic, none with {ex.conditions_text()}")
        t, raw = t[chosen], raw[chosen]
    keep = _crop(t, record)
    if not keep.any():
        finite = t[np.isfinite(t)]
        span = f"{float(finite.min())!r} s to {float(finite.max())!r} s" if finite.size else "no finite stamps"
        clock = f"stamp {spec.stamp!r}" if spec.stamp else "log_time"
        raise LogFormatError(
            f"{where}: no samples in the requested time range {_range_text(record)}; "
            f"the log has {span} on the {clock} clock"
        )
    t = t[keep]
    values = raw[keep]
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        raise LogFormatError(f"{where}: all {values.size} values in {_range_text(record)} are NaN (null)")
    if np.ptp(finite) == 0.0:
        units = f" {spec.units}" if spec.units else ""
        raise LogFormatError(
            f"{where}: constant at {float(finite[0])!r}{units} over {_range_text(record)} "
            f"({values.size} samples); a constant signal cannot be identified"
        )
    t.setflags(write=False)
    values.setflags(write=False)
    selection = f" [{ex.conditions_text()}]" if ex.conditions else ""
    return RawSignal(name=spec.name, units=spec.units, t_s=t, values=values,
                     source=f"{log.name}:{spec.topic}.{spec.field}{selection}")


def read_signals(record: RecordSpec, signals: Mapping[str, SignalSpec], names: Iterable[str], *,
                 notes: list[str] | None = None) -> dict[str, RawSignal]:
    """Read named signals from one log.

    The log is read once for all topics (:func:`~livesweep.telemetry.mcap_log.read_topics_fields`),
    values are scaled (``scale * raw + offset``) and cropped to
    ``[record.start_s, record.end_s)`` on each signal's stamp clock [s].

    Parameters
    ----------
    record : RecordSpec
        The log and the optional time slice [s].
    signals : Mapping[str, SignalSpec]
        Where each signal lives (a case's ``[signals]``).
    names : iterable of str
        Which signals to read.
    notes : list of str, optional
        Receives a one-line note when the log was unfinished (read up to its torn end) or was
        recovered from an unfinished log (:func:`~livesweep.telemetry.mcap_log.read_topics_fields`).

    Returns
    -------
    dict[str, RawSignal]
        In the order of ``names``.

    Raises
    ------
    ConfigError
        A name not in ``signals``; ``start_s >= end_s``; a ``field`` that does not parse.
    LogFormatError
        Naming the log file, topic and field: the log is missing or not MCAP; the topic is not
        in the log (the topics present are listed); a field (operand, stamp or selection field)
        is missing or not a number; no message matches the signal's selection; no samples in the
        time range; a signal whose values are all NaN or constant.
    """
    names = list(dict.fromkeys(names))
    if not names:
        raise ConfigError(f"{record.log}: no signals asked for")
    for n in names:
        if n not in signals:
            raise ConfigError(f"{record.log}: signal {n!r} is not defined; defined signals: {', '.join(signals)}")
    if record.start_s is not None and record.end_s is not None and record.start_s >= record.end_s:
        raise ConfigError(f"{record.log}: start_s = {record.start_s!r} must be before end_s = {record.end_s!r}")
    log = Path(record.log)
    out: dict[str, RawSignal] = {}
    extractors = [compile_signal(replace(signals[n], name=n)) for n in names]  # the key is the name
    groups = _group_by_topic(extractors)
    all_cols = _read_topics(log, groups, notes)
    for topic, exs in groups.items():
        cols = all_cols[topic]
        for ex in exs:
            out[ex.spec.name] = _make_signal(log, record, ex, cols, all_cols)
    return {n: out[n] for n in names}
