"""Logs in the autopilot's own format to livesweep's MCAP (docs/outputs.md, MCAP recordings): ``livesweep convert``.

Formats are recognised by content (:func:`sniff_format`), never by file name. One module per
format converts a file with a :class:`ConversionWriter` (:mod:`livesweep.convert.common`), which
stores the source's name, SHA-256 and format version in the MCAP metadata and the counts of
messages read, skipped and repaired.

=============  ==========================================  ======================================
format         module                                      channels
=============  ==========================================  ======================================
``tlog``       :mod:`livesweep.convert.tlog`               ``/mavlink/<MSG>``
``dataflash``  :mod:`livesweep.convert.dataflash`          ``/dataflash/<MSG>`` (also PX4 sdlog2)
``ulog``       :mod:`livesweep.convert.ulog` (pyulog)      ``/ulog/<topic>`` (``/<topic>/<i>``)
``numpy``      :mod:`livesweep.convert.table`              ``/table/<name>`` (column map)
``text``       :mod:`livesweep.convert.table`              ``/table/<name>`` (column map)
``matlab``     :mod:`livesweep.convert.table`              ``/table/<name>`` (v5 .mat, column map)
``parquet``    :mod:`livesweep.convert.table`              ``/table/<name>`` (column map optional)
``mcap``       (already MCAP: refused with a clear error)
=============  ==========================================  ======================================
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path

from livesweep.convert.common import ConversionResult, sniff_format
from livesweep.errors import LogFormatError
from livesweep.locks import check_file_free

__all__ = ["ConversionResult", "sniff_format", "convert", "check_output", "CONVERTERS"]

#: format -> "module:function"; each function is ``f(src: Path, out: Path, **options) -> ConversionResult``
CONVERTERS = {
    "tlog": "livesweep.convert.tlog:convert_tlog",
    "dataflash": "livesweep.convert.dataflash:convert_dataflash",
    "ulog": "livesweep.convert.ulog:convert_ulog",
    "numpy": "livesweep.convert.table:convert_table",
    "text": "livesweep.convert.table:convert_table",
    "matlab": "livesweep.convert.table:convert_table",
    "parquet": "livesweep.convert.table:convert_table",
}


def _same_file(a: Path, b: Path) -> bool:
    """True when ``a`` and ``b`` are one file (also through symbolic or hard links: same device
    and inode)."""
    try:
        return os.path.samefile(a, b)
    except OSError:              # either does not exist (or cannot be looked at): not the same file
        return False


def check_output(out, inputs, *, force: bool = False) -> None:
    """Refuse an output that is one of the inputs (always) or that exists (unless ``force``).

    The converters write ``<out>.partial`` and rename it onto ``out``, so both names are checked
    against every input.

    Parameters
    ----------
    out : str or Path
        The MCAP file to write.
    inputs : iterable of str or Path
        Files the conversion reads (the log, a column map).
    force : bool
        Replace an existing ``out`` that is not an input (never one another process is writing,
        such as a recording in progress).

    Raises
    ------
    LogFormatError
        Naming the output and the input it is, or saying it exists and ``--force`` replaces it.
    """
    out = Path(out)
    for src in map(Path, inputs):
        for target in (out, out.with_name(out.name + ".partial")):
            if _same_file(src, target):
                raise LogFormatError(f"--out {out}: {target} is the input {src} (the same file); an input is never "
                                     "overwritten")
    if out.is_dir():
        raise LogFormatError(f"--out {out} is a directory; give a file name ending in .mcap")
    if out.exists() and not force:
        raise LogFormatError(f"--out {out} exists; it is not overwritten unless asked (--force)")
    check_file_free(out, overwrite=force, error=LogFormatError)


def convert(src, out, *, force: bool = False, **options) -> ConversionResult:
    """Convert ``src`` (any supported format, recognised by content) to the MCAP file ``out``.

    Parameters
    ----------
    src, out : str or Path
    force : bool
        Replace an existing ``out`` (never one that is ``src`` or the column map).
    **options
        Passed to the format's converter (e.g. ``column_map`` for tables, ``partial`` for
        DataFlash and ULog).

    Raises
    ------
    LogFormatError
        Unknown or unsupported format, a corrupt file, an output that is an input or exists
        (without ``force``) or cannot be written; nothing is written then.
    ConfigError
        Bad options (e.g. a column map naming a missing column).
    """
    src, out = Path(src), Path(out)
    column_map = options.get("column_map")
    check_output(out, [src] + ([column_map] if isinstance(column_map, (str, os.PathLike)) else []), force=force)
    fmt = sniff_format(src)
    if fmt == "mcap":
        from livesweep.telemetry.mcap_log import read_summary

        try:
            unfinished = not read_summary(src).complete
        except LogFormatError:
            unfinished = False
        if unfinished:
            raise LogFormatError(f"{src}: an unfinished MCAP recording (its process was killed): "
                                 f"`livesweep recover {src}` writes a finished copy")
        raise LogFormatError(f"{src}: already an MCAP file; nothing to convert")
    module, func = CONVERTERS[fmt].split(":")
    return getattr(importlib.import_module(module), func)(src, out, **options)
