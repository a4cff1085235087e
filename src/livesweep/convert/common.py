"""What every converter shares: recognising a file by content, and the MCAP writer that records
where the data came from and what the conversion had to skip or repair."""

from __future__ import annotations

import json
import struct
from dataclasses import asdict, dataclass, field
from pathlib import Path

from livesweep import __version__
from livesweep.errors import ConfigError, LogFormatError
from livesweep.hashing import sha256_of  # re-exported: converters and callers import it from here
from livesweep.telemetry.mcap_log import McapLogWriter

__all__ = ["ConversionResult", "ConversionWriter", "sniff_format", "sha256_of", "refuse_options", "MAX_BOOT_US",
           "UNIX_RANGE_S", "MIN_RECORD_FRACTION"]

#: Largest plausible time since boot [us] (~32 years): anything larger is a corrupt time stamp.
MAX_BOOT_US = 10**15
#: Plausible UNIX times [s], 2000-01-01 to 2100-01-01: a GPS or UTC time outside is no fix or corrupt.
UNIX_RANGE_S = (946_684_800, 4_102_444_800)
#: Least fraction of a damaged log's bytes that must convert; below it a converter refuses unless
#: asked (``partial``): a log that is mostly corruption must not pass for a whole one.
MIN_RECORD_FRACTION = 0.5

#: (first bytes, format) for the formats with a signature at the start of the file
_MAGIC = (
    (b"\x89MCAP0\r\n", "mcap"),
    (b"ULog\x01\x12\x35", "ulog"),
    (b"\x93NUMPY", "numpy"),
    (b"MATLAB 5.0 MAT-file", "matlab"),
    (b"PAR1", "parquet"),
    (b"\xa3\x95\x80", "dataflash"),         # HEAD1 HEAD2 FMT: every DataFlash / sdlog2 log starts with FMT
)


def refuse_options(src, what: str, options: dict, known: str) -> None:
    """ConfigError naming the file when a converter is given options it does not take."""
    if options:
        raise ConfigError(f"{src}: option(s) {', '.join(sorted(options))} do not apply to {what} (it takes {known})")


def _plausible_tlog(head: bytes) -> bool:
    """``[uint64 BE us UNIX time 2000..2100][0xFE|0xFD ...]`` somewhere in the first records."""
    lo, hi = (s * 10**6 for s in UNIX_RANGE_S)
    if len(head) < 9:
        return False
    (t0,) = struct.unpack(">Q", head[:8])
    if not lo <= t0 <= hi:
        return False
    for i in range(0, len(head) - 9):
        (t,) = struct.unpack(">Q", head[i:i + 8])
        if lo <= t <= hi and head[i + 8] in (0xFE, 0xFD):
            return True
    return False


def sniff_format(path) -> str:
    """The file's format from its first bytes: ``mcap``, ``ulog``, ``dataflash``, ``numpy``,
    ``matlab`` (v5 .mat), ``parquet``, ``tlog`` or ``text``.

    Raises
    ------
    LogFormatError
        Missing or empty file, or content none of the converters reads (naming the file).
    """
    path = Path(path)
    if not path.is_file():
        raise LogFormatError(f"{path}: no such file")
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    if not head:
        raise LogFormatError(f"{path}: the file is empty")
    for magic, fmt in _MAGIC:
        if head.startswith(magic):
            return fmt
    if _plausible_tlog(head):
        return "tlog"
    sample = head[:4096]
    try:
        text = sample.decode("utf-8")
    except UnicodeDecodeError:
        text = None
    if text is not None and all(c.isprintable() or c in "\r\n\t" for c in text):
        return "text"
    raise LogFormatError(f"{path}: unknown or unsupported format (first bytes {head[:8].hex(' ')}); livesweep "
                         "converts MAVLink .tlog, ArduPilot DataFlash .bin (and PX4 sdlog2), PX4 ULog, "
                         "NumPy .npy, MATLAB v5 .mat, Parquet and delimited text")


@dataclass(frozen=True)
class ConversionResult:
    """What a conversion did.

    Attributes
    ----------
    source, output : Path
    format, format_version : str
        As recognised (e.g. ``"dataflash"``, ``"ArduCopter V4.0.3"`` or ``"ULog v1"``).
    sha256 : str
        Of the source file.
    messages_read : int
        Records/messages decoded from the source.
    messages_written : int
    skipped : dict of str -> int
        Records not converted, by reason (e.g. ``bad_data``, ``truncated_tail``).
    repaired : dict of str -> int
        Records converted after a repair, by kind.
    topics : dict of str -> int
        Messages written per MCAP topic.
    warnings : tuple of str
    """

    source: Path
    output: Path
    format: str
    format_version: str
    sha256: str
    messages_read: int
    messages_written: int
    skipped: dict = field(default_factory=dict)
    repaired: dict = field(default_factory=dict)
    topics: dict = field(default_factory=dict)
    warnings: tuple = ()

    def to_dict(self) -> dict:
        d = asdict(self)
        d["source"], d["output"] = str(self.source), str(self.output)
        d["warnings"] = list(self.warnings)
        return d


class ConversionWriter:
    """An atomic :class:`McapLogWriter` for one conversion, with provenance and counts.

    Use as a context manager; call :meth:`finish` at the end of a successful conversion (it writes
    the ``conversion`` metadata record and returns the :class:`ConversionResult`). On an exception
    nothing is left behind.

    Metadata records written: ``source`` (``name``, ``sha256``, ``format``, ``format_version``,
    ``size_bytes``, ``converter``) and ``conversion`` (``messages_read``, ``messages_written``,
    ``skipped`` and ``repaired`` as JSON, ``warnings`` as JSON).
    """

    def __init__(self, src: Path, out: Path, fmt: str, format_version: str = ""):
        self.src, self.out, self.fmt = Path(src), Path(out), fmt
        self.format_version = format_version
        self.sha256 = sha256_of(self.src)
        self.writer = McapLogWriter(self.out, library=f"livesweep {__version__} convert")
        self.messages_read = 0
        self.skipped: dict[str, int] = {}
        self.repaired: dict[str, int] = {}
        self.warnings: list[str] = []

    def __enter__(self) -> "ConversionWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is not None:
            self.writer.abort()
        return False

    def skip(self, reason: str, n: int = 1) -> None:
        self.skipped[reason] = self.skipped.get(reason, 0) + n

    def repair(self, kind: str, n: int = 1) -> None:
        self.repaired[kind] = self.repaired.get(kind, 0) + n

    def warn(self, text: str) -> None:
        self.warnings.append(text)

    def finish(self) -> ConversionResult:
        counts = self.writer.message_counts
        written = sum(counts.values())
        self.writer.add_metadata("source", {
            "name": self.src.name, "sha256": self.sha256, "format": self.fmt, "format_version": self.format_version,
            "size_bytes": str(self.src.stat().st_size), "converter": f"livesweep {__version__}"})
        self.writer.add_metadata("conversion", {
            "messages_read": str(self.messages_read), "messages_written": str(written),
            "skipped": json.dumps(self.skipped, sort_keys=True), "repaired": json.dumps(self.repaired, sort_keys=True),
            "warnings": json.dumps(self.warnings)})
        self.writer.close()
        return ConversionResult(self.src, self.out, self.fmt, self.format_version, self.sha256, self.messages_read,
                                written, dict(self.skipped), dict(self.repaired), dict(counts), tuple(self.warnings))
