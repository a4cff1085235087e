"""``livesweep inspect LOG`` as a function: :func:`inspect_log`.

One job: read a log once with the reader for its format (:mod:`~livesweep.inspection.readers`,
the readers' own warnings silenced: they are counted in the notes) and put together what it holds:
the topics with their rates and fields (:mod:`~livesweep.inspection.fields`), the presets that fit
(:mod:`~livesweep.inspection.fits`) and the SystemID test points (:mod:`~livesweep.inspection.runs`).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from livesweep.errors import ConfigError
from livesweep.inspection.fields import _mavlink_units, _numeric_fields
from livesweep.inspection.fits import _candidate_maps, _fit, _stream_rates
from livesweep.inspection.rates import _rate
from livesweep.inspection.readers import _read_dataflash, _read_mcap, _read_table, _read_tlog, _read_ulog
from livesweep.inspection.results import LogInspection, TopicInfo
from livesweep.inspection.runs import _runs
from livesweep.inspection.stats import _Stats
from livesweep.inspection.thresholds import STREAM_RATE_HZ

__all__ = ["inspect_log"]


def inspect_log(path, *, columns=None, progress=None) -> LogInspection:
    """Read a log and describe it (see :mod:`livesweep.inspection`).

    Parameters
    ----------
    path : str or Path
        The log.
    columns : str or Path, optional
        Column map, for tables (``.npy``, ``.mat``, Parquet, text).
    progress : callable, optional
        ``progress(done, total, unit)`` now and then while the log is read: ``unit`` is
        ``"bytes"`` or ``"messages"``, ``total`` 0 when not known; a last call with ``done ==
        total`` at the end. :func:`stderr_progress` makes one for the command line.

    Raises
    ------
    LogFormatError, ConfigError
        A file that is not a log livesweep reads, or a table without a column map (one line
        naming the file and what to give).
    """
    from livesweep.convert.common import sniff_format

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such file")
    fmt = sniff_format(path)
    notes: list[str] = []
    maps = _candidate_maps()
    stats = _Stats(maps)
    import logging

    quiet = logging.getLogger("livesweep")       # readers' per-record warnings: counted in the notes
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        if fmt == "tlog":
            _read_tlog(path, stats, notes, progress)
        elif fmt == "mcap":
            _read_mcap(path, stats, notes, progress)
        elif fmt == "dataflash":
            _read_dataflash(path, stats, notes, progress)
        elif fmt == "ulog":
            _read_ulog(path, stats, notes, progress)
        else:
            with tempfile.TemporaryDirectory(prefix="livesweep-inspect-") as tmp:
                _read_table(path, fmt, stats, notes, progress, columns, Path(tmp))
    finally:
        quiet.setLevel(level)
        if progress is not None:
            progress(1, 1, "bytes")
    firsts = [st[1] for st in stats.topics.values()]
    t0 = min(firsts) if firsts else 0            # file order is receive order, not always time order
    infos = []
    for topic, (n, first, last, sample) in sorted(stats.topics.items()):
        encoding, decoded, schema_fields, why, units = stats.meta.get(topic, ("json", True, (), "", {}))
        if decoded:
            names = list(_numeric_fields(sample)) if isinstance(sample, dict) else []
            u = {**_mavlink_units(topic), **units}
            fields = tuple((f, u.get(f, "")) for f in names)
        else:
            fields = schema_fields
        infos.append(TopicInfo(topic, n, _rate(n, first, last), (first - t0) / 1e9, (last - t0) / 1e9, fields,
                               encoding, decoded, why))
    duration = ((stats.t_end or t0) - t0) / 1e9
    fits = [f for name, m, whole in maps if (f := _fit(stats, name, m, whole)) is not None]
    fits.sort(key=lambda f: (not f.fits, -f.pairs / f.total, -f.pairs, f.name))
    live = []
    if fmt == "dataflash":
        for name, m, whole in maps:
            if whole or not all(s.topic.startswith("/mavlink/") for s in m.signals.values()):
                continue
            rates = _stream_rates(stats, m, STREAM_RATE_HZ)
            if rates is not None and (f := _fit(stats, name, m, whole, rates=rates, live=True)) is not None:
                live.append(f)
        live.sort(key=lambda f: (not f.fits, -f.pairs / f.total, f.name))
    runs = _runs(stats, t0, maps)
    return LogInspection(path, fmt, duration, tuple(infos),
                         maps=tuple((f.name, f.pairs, f.total) for f in fits if f.fits),
                         test_points=tuple((r.start_s, r.end_s, r.what) for r in runs if r.data),
                         notes=tuple(notes), fits=tuple(fits + live), live_maps=tuple(f.name for f in live if f.fits),
                         systemid=tuple(runs))
