"""Tables (NumPy ``.npy``, MATLAB v5 ``.mat``, Apache Parquet and delimited text) to livesweep's
MCAP: one channel ``/table/<name>``. A ``.mat`` file's numeric 2-D variables (the most common row count) are read
side by side with the columns named ``<variable>[<j>]``, so a column map selects them with
``header = "outr[2]"``.

Every row becomes one message whose fields are the mapped columns (``scale * raw + offset``) and
``time_s``, the time column in seconds. ``log_time`` and ``publish_time`` both come from the time
column: ``round(time_s * 1e9)`` ns (relative seconds from 0; when the column has negative times
they are shifted so the smallest is 0, with a warning), or, when the column map gives
``start_utc``, ``start_utc + (time_s - time_s[first row])``.

Column map
----------
A small TOML file (or the same as a dict)::

    name = "xplane_c172"        # channel /table/<name>; default: the file's stem
    time = "time"               # the [columns] key holding time (seconds after scale/offset)
    skip_rows = 1               # text: physical lines before the header/data; default: auto
    header = true               # text: a header line follows; default "auto" (non-numeric cells)
    delimiter = "\\t"            # text: "," "\\t" ";" "|" or "whitespace"; default auto
    comment = "#"               # text: lines starting with it are skipped (default "#")
    start_utc = 2017-10-18T14:07:00Z   # optional (TOML date-time or ISO text)
    description = "free text"

    [columns.q]                 # field name in the MCAP
    index = 4                   # column number from 0, or:  header = "q"  (text with a header)
    units = "rad/s"
    scale = 1.0
    offset = 0.0

Without a column map: a text file's header names the columns (``col<i>`` without a header, or
for ``.npy``; a structured ``.npy`` uses its field names). The time column is then the one named
``time_s``, ``time``, ``t`` or ``timestamp`` (any case), else column 0 (with a warning).

Text files: UTF-8, lines ending in LF or CRLF, empty lines and comment lines skipped. Automatic
preamble: without ``skip_rows``, leading lines with a different number of fields than the body
(X-Plane's ``dt_mean N`` line) are skipped and counted (``skipped["preamble_lines"]``). Trailing
delimiters are ignored. A row with a different number of fields than the header is an error naming
the line (the file's very last line only is dropped and counted as ``truncated_tail``, the usual
way a file cut while being written ends).

Counted
-------
``skipped["nonfinite_cells"]``: NaN/inf or empty cells in mapped columns, written as ``"NaN"`` /
``"Infinity"`` / ``"-Infinity"`` (the recording's convention, :mod:`livesweep.numeric`);
``skipped["rows_nonfinite_time"]``: rows whose time is not finite (not written);
time running backwards: counted in a warning, rows kept in file order.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from livesweep.convert.common import ConversionResult, ConversionWriter, refuse_options, sniff_format
from livesweep.errors import ConfigError, LogFormatError
from livesweep.numeric import float_json_schema

__all__ = ["convert_table", "load_column_map", "ColumnMap", "ColumnSpec", "read_table"]

_MAP_KEYS = ("name", "time", "skip_rows", "header", "delimiter", "comment", "start_utc", "description", "columns")
_COLUMN_KEYS = ("index", "header", "units", "scale", "offset", "description")
_DELIMITERS = {",": ",", "\t": "\t", ";": ";", "|": "|", "whitespace": None, " ": None}
_TIME_NAMES = ("time_s", "time", "t", "timestamp")
_NAME_OK = re.compile(r"[A-Za-z0-9_.\-]+")


@dataclass(frozen=True)
class ColumnSpec:
    """One mapped column: ``value = scale * raw + offset`` in ``units``."""

    name: str
    index: int | None = None
    header: str | None = None
    units: str = ""
    scale: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class ColumnMap:
    """A parsed column map (see the module docstring). ``where`` names it in error messages."""

    where: str
    name: str | None = None
    time: str | None = None
    skip_rows: int | None = None
    header: object = "auto"           # True, False or "auto"
    delimiter: str | None = "auto"    # one character, None (whitespace) or "auto"
    comment: str = "#"
    start_utc_ns: int | None = None
    description: str = ""
    columns: tuple = ()               # of ColumnSpec; () = take the file's own names
    text: bytes | None = None         # the TOML file, for the attachment


def _err(where: str, key: str, problem: str, value=...) -> ConfigError:
    got = "" if value is ... else f", got {value!r}"
    return ConfigError(f"column map {where}: {key}: {problem}{got}")


def _number(where, value, key) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _err(where, key, "must be a finite number", value)
    return float(value)


def _utc_ns(where, value) -> int:
    if isinstance(value, str):
        try:
            value = _dt.datetime.fromisoformat(value.replace("Z", "+00:00"))
        except ValueError:
            raise _err(where, "start_utc", "must be an ISO 8601 date-time such as 2017-10-18T14:07:00Z", value) from None
    if isinstance(value, _dt.date) and not isinstance(value, _dt.datetime):
        value = _dt.datetime(value.year, value.month, value.day)
    if not isinstance(value, _dt.datetime):
        raise _err(where, "start_utc", "must be a date-time (TOML or ISO 8601 text)", value)
    if value.tzinfo is None:
        value = value.replace(tzinfo=_dt.timezone.utc)
    delta = value - _dt.datetime(1970, 1, 1, tzinfo=_dt.timezone.utc)
    ns = (delta.days * 86400 + delta.seconds) * 10**9 + delta.microseconds * 1000
    if ns < 0:
        raise _err(where, "start_utc", "must be after 1970-01-01", str(value))
    return ns


def load_column_map(column_map) -> ColumnMap | None:
    """Parse a column map given as a TOML path, a dict or None (see the module docstring).

    Raises
    ------
    ConfigError
        A missing or unreadable file, a TOML syntax error, an unknown key, a wrong type; the
        message names the map (file) and the key.
    """
    if column_map is None:
        return None
    text = None
    if isinstance(column_map, dict):
        where, data = "(dict)", column_map
    elif isinstance(column_map, (str, Path)):
        p = Path(column_map).expanduser()
        where = str(p)
        if not p.is_file():
            raise ConfigError(f"column map {p} {'is a directory' if p.is_dir() else 'does not exist'}")
        try:
            text = p.read_bytes()
            data = tomllib.loads(text.decode("utf-8"))
        except UnicodeDecodeError as e:
            raise ConfigError(f"column map {p}: not UTF-8 text (byte {e.start})") from e
        except tomllib.TOMLDecodeError as e:
            raise ConfigError(f"column map {p}: TOML syntax error: {e}") from e
    else:
        raise ConfigError(f"column_map must be a TOML file path or a dict, got {type(column_map).__name__}")
    for k in data:
        if k not in _MAP_KEYS:
            raise _err(where, k, f"unknown key; known keys: {', '.join(_MAP_KEYS)}")
    name = data.get("name")
    if name is not None and (not isinstance(name, str) or not _NAME_OK.fullmatch(name)):
        raise _err(where, "name", "must be a channel name of letters, digits, _ . -", name)
    time = data.get("time")
    if time is not None and (not isinstance(time, str) or not time):
        raise _err(where, "time", "must name a column (a key of [columns])", time)
    skip = data.get("skip_rows")
    if skip is not None and (isinstance(skip, bool) or not isinstance(skip, int) or skip < 0):
        raise _err(where, "skip_rows", "must be an integer >= 0 (lines before the header or data)", skip)
    header = data.get("header", "auto")
    if header not in (True, False, "auto"):
        raise _err(where, "header", 'must be true, false or "auto"', header)
    delim = data.get("delimiter", "auto")
    if delim != "auto":
        if delim not in _DELIMITERS:
            raise _err(where, "delimiter", f'must be one of {", ".join(map(repr, _DELIMITERS))} or "auto"', delim)
        delim = _DELIMITERS[delim]
    comment = data.get("comment", "#")
    if not isinstance(comment, str):
        raise _err(where, "comment", "must be a string (empty: no comment lines)", comment)
    start = _utc_ns(where, data["start_utc"]) if "start_utc" in data else None
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise _err(where, "description", "must be a string", desc)
    cols = []
    raw_cols = data.get("columns", {})
    if not isinstance(raw_cols, dict):
        raise _err(where, "columns", "must be a table of [columns.<name>] tables", raw_cols)
    for cname, spec in raw_cols.items():
        key = f"columns.{cname}"
        if not _NAME_OK.fullmatch(cname) or cname == "time_s":
            raise _err(where, key, "a column name is letters, digits, _ . - and not time_s (written by the converter)")
        if not isinstance(spec, dict):
            raise _err(where, key, "must be a table with index or header", spec)
        for k in spec:
            if k not in _COLUMN_KEYS:
                raise _err(where, f"{key}.{k}", f"unknown key; known keys: {', '.join(_COLUMN_KEYS)}")
        if ("index" in spec) == ("header" in spec):
            raise _err(where, key, "needs exactly one of index (column number from 0) or header (header text)")
        idx = spec.get("index")
        if idx is not None and (isinstance(idx, bool) or not isinstance(idx, int) or idx < 0):
            raise _err(where, f"{key}.index", "must be an integer >= 0 (columns count from 0)", idx)
        hdr = spec.get("header")
        if hdr is not None and (not isinstance(hdr, str) or not hdr.strip()):
            raise _err(where, f"{key}.header", "must be the column's header text", hdr)
        units = spec.get("units", "")
        if not isinstance(units, str):
            raise _err(where, f"{key}.units", "must be a string", units)
        scale = _number(where, spec.get("scale", 1.0), f"{key}.scale")
        if scale == 0.0:
            raise _err(where, f"{key}.scale", "must not be 0", spec["scale"])
        cols.append(ColumnSpec(cname, idx, hdr.strip() if hdr else None, units, scale,
                               _number(where, spec.get("offset", 0.0), f"{key}.offset")))
    if time is not None and cols and time not in raw_cols:
        raise _err(where, "time", f"names no [columns] entry (columns: {', '.join(raw_cols)})", time)
    return ColumnMap(where, name, time, skip, header, delim, comment, start, desc, tuple(cols), text)


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Table:
    values: np.ndarray            # (rows, cols) float64
    headers: tuple | None         # the file's column names, if any
    lines: np.ndarray | None      # 1-based line number of each row (text)
    version: str
    preamble: int = 0
    truncated_tail: bool = False


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _split(line: str, delim):
    cells = line.split(delim) if delim is not None else line.split()
    cells = [c.strip() for c in cells]
    while delim is not None and len(cells) > 1 and cells[-1] == "":
        cells.pop()                                   # trailing delimiter(s)
    return cells


def _read_npy(src: Path) -> _Table:
    try:
        with open(src, "rb") as f:
            major, minor = np.lib.format.read_magic(f)
        a = np.load(src, allow_pickle=False)
    except (ValueError, OSError, EOFError) as e:
        raise LogFormatError(f"{src}: cannot read as a NumPy .npy file: {e}") from e
    headers = None
    if a.dtype.names:
        headers = tuple(a.dtype.names)
        try:
            a = np.column_stack([np.asarray(a[n], dtype=np.float64).reshape(-1) for n in headers])
        except (TypeError, ValueError) as e:
            raise LogFormatError(f"{src}: structured array with a non-numeric field: {e}") from e
    if a.ndim != 2:
        raise LogFormatError(f"{src}: a table needs a 2-D array (rows x columns), got shape {a.shape}")
    if a.dtype.kind not in "biuf":
        raise LogFormatError(f"{src}: a table needs numbers, got dtype {a.dtype}")
    return _Table(a.astype(np.float64, copy=False), headers, None,
                  f"NumPy .npy v{major}.{minor}, {a.dtype}, {a.shape[0]} x {a.shape[1]}")


def _read_mat(src: Path) -> _Table:
    """A MATLAB v5 .mat file: every numeric 2-D variable with the most common row count, side by
    side, the columns named ``<variable>[<j>]`` (e.g. ``outr[2]``; a column vector is ``t[0]``)."""
    import scipy.io

    try:
        m = scipy.io.loadmat(src)
    except (ValueError, OSError, TypeError, NotImplementedError) as e:
        raise LogFormatError(f"{src}: cannot read as a MATLAB v5 .mat file: {e}") from e
    arrays = {k: np.asarray(v) for k, v in m.items() if not k.startswith("__") and isinstance(v, np.ndarray)
              and v.ndim == 2 and v.dtype.kind in "biuf" and v.size}
    if not arrays:
        raise LogFormatError(f"{src}: the .mat file holds no numeric 2-D variable")
    arrays = {k: (v if v.shape[0] >= v.shape[1] else v.T) for k, v in arrays.items()}
    rows = [v.shape[0] for v in arrays.values()]
    n = max(set(rows), key=rows.count)
    keep = {k: v for k, v in arrays.items() if v.shape[0] == n}
    headers = tuple(f"{k}[{j}]" for k, v in keep.items() for j in range(v.shape[1]))
    values = np.column_stack([v.astype(np.float64) for v in keep.values()])
    version = m.get("__header__", b"").decode("latin-1", "replace").split(",")[0].strip()
    return _Table(values, headers, None, f"{version or 'MATLAB v5'}, variables {', '.join(keep)}, {n} rows")


def _read_parquet(src: Path) -> _Table:
    """An Apache Parquet file (pyarrow, which rerun-sdk already requires): its numeric and boolean
    columns side by side under their own names; other columns are left out (named in the version
    text)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        t = pq.read_table(src)
    except (pa.ArrowException, OSError, ValueError) as e:
        raise LogFormatError(f"{src}: cannot read as a Parquet file: {e}") from e
    names, cols, dropped = [], [], []
    for name, col in zip(t.column_names, t.columns):
        typ = col.type
        if pa.types.is_integer(typ) or pa.types.is_floating(typ) or pa.types.is_boolean(typ):
            a = col.to_numpy(zero_copy_only=False)
            names.append(name)
            cols.append(np.where(np.equal(a, None), np.nan, a).astype(np.float64) if a.dtype == object
                        else a.astype(np.float64))
        else:
            dropped.append(name)
    if not cols:
        raise LogFormatError(f"{src}: the Parquet file has no numeric column")
    meta = pq.ParquetFile(src).metadata
    version = f"Parquet {meta.format_version}, {t.num_rows} rows x {len(cols)} numeric columns"
    if dropped:
        version += f" (non-numeric left out: {', '.join(dropped)})"
    return _Table(np.column_stack(cols), tuple(names), None, version)


def _guess_delim(line: str):
    for d in ("\t", ",", ";", "|"):
        if d in line:
            return d
    return None


def _read_text(src: Path, cmap: ColumnMap | None) -> _Table:
    try:
        text = src.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise LogFormatError(f"{src}: not UTF-8 text (byte {e.start})") from e
    comment = cmap.comment if cmap else "#"
    skip = cmap.skip_rows if cmap else None
    header_opt = cmap.header if cmap else "auto"
    delim = cmap.delimiter if cmap else "auto"
    physical = text.splitlines()
    if skip is not None and skip >= len(physical):
        raise ConfigError(f"column map {cmap.where}: skip_rows: {skip} skips the whole file {src} "
                          f"({len(physical)} lines)")
    content = [(i + 1, ln.strip()) for i, ln in enumerate(physical)
               if i >= (skip or 0) and ln.strip() and not (comment and ln.strip().startswith(comment))]
    if not content:
        raise LogFormatError(f"{src}: no data lines")
    if delim == "auto":
        delim = _guess_delim(content[min(len(content) - 1, 20)][1])
    preamble = 0
    if skip is None:
        # automatic preamble: the body's field count is the commonest among the first lines
        head = [len(_split(ln, delim)) for _, ln in content[:200]]
        body_n = max(set(head), key=lambda n: (head.count(n), -head.index(n)))
        preamble = head.index(body_n)
        content = content[preamble:]
    first = _split(content[0][1], delim)
    has_header = header_opt if header_opt != "auto" else not all(_is_number(c) for c in first if c)
    headers = None
    if has_header:
        headers = tuple(first)
        header_line = content[0][0]
        content = content[1:]
        if len(set(headers)) != len(headers):
            dup = sorted({h for h in headers if headers.count(h) > 1})
            raise LogFormatError(f"{src}: line {header_line}: header names {', '.join(map(repr, dup))} more than once; "
                                 "give a column map that maps the columns by index")
    ncols = len(headers) if headers else (len(_split(content[0][1], delim)) if content else 0)
    if not content:
        raise LogFormatError(f"{src}: a header but no data lines")
    rows, lines = [], []
    truncated = False
    last_line = content[-1][0]
    for lineno, ln in content:
        cells = _split(ln, delim)
        if len(cells) != ncols:
            if lineno == last_line and len(cells) < ncols:
                truncated = True
                break
            raise LogFormatError(f"{src}: line {lineno}: {len(cells)} fields, expected {ncols} "
                                 f"(as {'the header' if headers else 'the first data line'}); ragged rows "
                                 "cannot be matched to columns")
        try:
            rows.append([float(c) if c else math.nan for c in cells])
        except ValueError:
            bad = next(j for j, c in enumerate(cells) if c and not _is_number(c))
            name = f" ({headers[bad]!r})" if headers else ""
            raise LogFormatError(f"{src}: line {lineno}, column {bad}{name}: {cells[bad]!r} is not a number") from None
        lines.append(lineno)
    dname = {None: "whitespace", "\t": "tab", ",": "comma", ";": "semicolon", "|": "bar"}[delim]
    version = (f"delimited text ({dname}-separated, {'header + ' if headers else ''}{len(rows)} rows x {ncols} columns"
               f"{f', {preamble + (skip or 0)} line(s) before' if preamble or skip else ''})")
    values = np.array(rows, dtype=np.float64).reshape(len(rows), ncols)
    return _Table(values, headers, np.array(lines), version, preamble, truncated)


def read_table(src, cmap: ColumnMap | None = None):
    """The table as ``(values (rows, cols) float64, header names or None, format_version)``."""
    src = Path(src)
    fmt = sniff_format(src)
    t = _read_any(src, fmt, cmap)
    return t.values, t.headers, t.version


def _read_any(src: Path, fmt: str, cmap) -> _Table:
    if fmt == "numpy":
        return _read_npy(src)
    if fmt == "matlab":
        return _read_mat(src)
    if fmt == "parquet":
        return _read_parquet(src)
    return _read_text(src, cmap)


# ---------------------------------------------------------------------------------------------
# converting
# ---------------------------------------------------------------------------------------------


def _resolve_columns(src: Path, table: _Table, cmap: ColumnMap | None, warn) -> tuple[list, str]:
    """(list of (ColumnSpec, column index), time column name)."""
    ncols = table.values.shape[1]
    if cmap is not None and cmap.columns:
        out = []
        for c in cmap.columns:
            if c.index is not None:
                if c.index >= ncols:
                    raise ConfigError(f"column map {cmap.where}: columns.{c.name}.index: {c.index} is out of range: "
                                      f"{src} has {ncols} columns (0..{ncols - 1})")
                out.append((c, c.index))
            else:
                if table.headers is None:
                    raise ConfigError(f"column map {cmap.where}: columns.{c.name}.header: {c.header!r} cannot be "
                                      f"found: {src} has no header line (map it by index)")
                if c.header not in table.headers:
                    raise ConfigError(f"column map {cmap.where}: columns.{c.name}.header: {c.header!r} is not in the "
                                      f"header of {src} ({', '.join(map(repr, table.headers))})")
                out.append((c, table.headers.index(c.header)))
        time = cmap.time
        if time is None:
            names = [c.name for c, _ in out]
            time = next((n for t in _TIME_NAMES for n in names if n.lower() == t), names[0])
            if time.lower() not in _TIME_NAMES:
                warn(f"the column map names no time column: {time!r} (the first) is taken as time in s")
        return out, time
    names = list(table.headers) if table.headers else [f"col{i}" for i in range(ncols)]
    safe = [n if _NAME_OK.fullmatch(n) and n != "time_s" else re.sub(r"[^A-Za-z0-9_.\-]", "_", n) or f"col{i}"
            for i, n in enumerate(names)]
    safe = [n if n != "time_s" else "time_s_col" for n in safe]
    out = [(ColumnSpec(n), i) for i, n in enumerate(safe)]
    time = cmap.time if cmap is not None and cmap.time else None
    if time is not None and time not in safe:
        raise ConfigError(f"column map {cmap.where}: time: {time!r} is not a column of {src} (columns: {', '.join(safe)})")
    if time is None:
        time = next((n for t in _TIME_NAMES for n in safe if n.lower() == t), None)
        if time is None:
            time = safe[0]
            warn(f"no column map and no column named {'/'.join(_TIME_NAMES)}: column 0 ({time!r}) is taken as time in s")
    return out, time


def convert_table(src: Path, out: Path, column_map=None, **options) -> ConversionResult:
    """Convert a NumPy ``.npy`` (2-D) or delimited text table to MCAP (see the module docstring).

    Parameters
    ----------
    src, out : Path
    column_map : str, Path, dict or None
        The column map (TOML file or the same keys as a dict).

    Raises
    ------
    ConfigError
        A bad column map, or one naming a column the file does not have (naming the map, the key
        and the file); an unknown option.
    LogFormatError
        A file that is not a 2-D numeric table, ragged text rows or a non-numeric cell (naming the
        line), no data, times that cannot be placed.
    """
    refuse_options(src, "a table", options, "column_map only")
    src, out = Path(src), Path(out)
    cmap = load_column_map(column_map)
    fmt = sniff_format(src)
    if fmt not in ("numpy", "text", "matlab", "parquet"):
        raise LogFormatError(f"{src}: is {fmt}, not a NumPy, MATLAB, Parquet or text table")
    table = _read_any(src, fmt, cmap)
    if table.values.shape[0] == 0:
        raise LogFormatError(f"{src}: the table has no rows")
    warnings: list[str] = []
    cols, time_name = _resolve_columns(src, table, cmap, warnings.append)
    name = (cmap.name if cmap and cmap.name else None) or re.sub(r"[^A-Za-z0-9_.\-]", "_", src.stem)
    topic = f"/table/{name}"

    raw = table.values
    data = np.column_stack([c.scale * raw[:, i] + c.offset for c, i in cols])
    k_time = [c.name for c, _ in cols].index(time_name)
    t = data[:, k_time]

    with ConversionWriter(src, out, fmt, table.version) as cw:
        for wtext in warnings:
            cw.warn(wtext)
        cw.messages_read = raw.shape[0]
        if table.preamble:
            cw.skip("preamble_lines", table.preamble)
            cw.warn(f"{table.preamble} line(s) before the {'header' if table.headers else 'data'} skipped "
                    "(a different number of fields than the table)")
        if table.truncated_tail:
            cw.skip("truncated_tail", 1)
            cw.warn("the last line has fewer fields than the table (file cut while written?): dropped")
        finite_t = np.isfinite(t)
        if not finite_t.all():
            cw.skip("rows_nonfinite_time", int((~finite_t).sum()))
            cw.warn(f"{int((~finite_t).sum())} row(s) with a non-finite time ({time_name!r}) not written")
        keep = np.flatnonzero(finite_t)
        if keep.size == 0:
            raise LogFormatError(f"{src}: no row has a finite time in column {time_name!r}")
        tk = t[keep]
        dt = np.diff(tk)
        n_back, n_equal = int((dt < 0).sum()), int((dt == 0).sum())
        if n_back or n_equal:
            where = ""
            if n_back:
                j = int(np.flatnonzero(dt < 0)[0]) + 1
                row = keep[j]
                where = (f"; first at {'line ' + str(int(table.lines[row])) if table.lines is not None else 'row ' + str(row)}"
                         f" ({tk[j - 1]:.6g} -> {tk[j]:.6g} s)")
            cw.warn(f"time column {time_name!r} is not increasing: {n_back} step(s) backwards, {n_equal} repeated "
                    f"time(s){where}; rows kept in file order")
        nonfinite = int((~np.isfinite(data[keep])).sum())
        if nonfinite:
            cw.skip("nonfinite_cells", nonfinite)
        if cmap is not None and cmap.start_utc_ns is not None:
            t_ns = cmap.start_utc_ns + np.round((tk - tk[0]) * 1e9).astype(np.int64)
            time_base = f"start_utc + (time_s - {tk[0]!r})"
        else:
            shift = min(0.0, float(tk.min()))
            if shift < 0:
                cw.warn(f"time column {time_name!r} has negative times (down to {shift:.6g} s): log times are "
                        f"shifted by {-shift:.6g} s so they start at 0")
            t_ns = np.round((tk - shift) * 1e9).astype(np.int64)
            time_base = "time_s * 1e9" if shift == 0 else f"(time_s + {-shift!r}) * 1e9"

        field_names = ["time_s"] + [c.name for c, _ in cols]
        units = {"time_s": "s", **{c.name: c.units for c, _ in cols}}
        sources = {c.name: (f"header {table.headers[i]!r} (column {i})" if table.headers else f"column {i}")
                   + (f", {c.scale!r} * raw + {c.offset!r}" if (c.scale, c.offset) != (1.0, 0.0) else "")
                   for c, i in cols}
        schema = {"type": "object", "title": f"table.{name}",
                  "properties": {f: float_json_schema(**({"description": units[f]} if units[f] else {}))
                                 for f in field_names}}
        w = cw.writer
        w.add_channel(topic, f"table.{name}", schema,
                      {"units": json.dumps(units), "time_column": time_name, "sources": json.dumps(sources)})
        block = np.column_stack([tk, data[keep]]).tolist()
        t_list = t_ns.tolist()
        for vals, tn in zip(block, t_list):
            w.write(topic, dict(zip(field_names, vals)), log_time_ns=tn, publish_time_ns=tn)
        w.add_metadata("table", {
            "name": name, "topic": topic, "time_column": time_name, "log_time": time_base,
            "column_map": cmap.where if cmap is not None else "(none: the file's own column names)",
            "columns": json.dumps({c.name: {"source": sources[c.name], "units": c.units, "scale": c.scale,
                                            "offset": c.offset} for c, _ in cols}),
            "description": cmap.description if cmap is not None else ""})
        if cmap is not None:
            body = cmap.text if cmap.text is not None else json.dumps(column_map, default=str).encode()
            w.add_attachment("column_map.toml" if cmap.text is not None else "column_map.json", body,
                             "application/toml" if cmap.text is not None else "application/json",
                             int(t_list[0]))
        return cw.finish()
