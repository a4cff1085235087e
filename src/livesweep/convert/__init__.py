"""Logs in the autopilot's own format to livesweep's MCAP (DESIGN.md §4.1): ``livesweep convert``.

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
from pathlib import Path

from livesweep.convert.common import ConversionResult, sniff_format
from livesweep.errors import LogFormatError

__all__ = ["ConversionResult", "sniff_format", "convert", "CONVERTERS"]

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


def convert(src, out, **options) -> ConversionResult:
    """Convert ``src`` (any supported format, recognised by content) to the MCAP file ``out``.

    Parameters
    ----------
    src, out : str or Path
    **options
        Passed to the format's converter (e.g. ``column_map`` for tables).

    Raises
    ------
    LogFormatError
        Unknown or unsupported format, a corrupt file, an output that cannot be written.
    ConfigError
        Bad options (e.g. a column map naming a missing column).
    """
    src, out = Path(src), Path(out)
    fmt = sniff_format(src)
    if fmt == "mcap":
        raise LogFormatError(f"{src}: already an MCAP file; nothing to convert")
    module, func = CONVERTERS[fmt].split(":")
    return getattr(importlib.import_module(module), func)(src, out, **options)
