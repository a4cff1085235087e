"""A cache of decoded MCAP columns, keyed by the log's content, so re-running a case is quick.

Decoding the JSON messages of a log is most of the cost of reading it (0.2 s for each 2.6 MB
sweep log of the shipped cruise case, a fifth of an identify). An engineer re-runs ``identify``
on the same logs every time the case file changes; the columns of the second and later runs come
from a NumPy file instead.

* Key: SHA-256 of the log's bytes and of the request (topics, fields, clock, missing-field
  rule). A log that changes in any byte is decoded again; renaming or copying it is not.
* Where: ``$LIVESWEEP_CACHE_DIR``, else ``$XDG_CACHE_HOME/livesweep``, else
  ``~/.cache/livesweep``; ``LIVESWEEP_CACHE=off`` turns the cache off. At most
  ``LIVESWEEP_CACHE_MB`` megabytes (default 512): the least recently used entries go first.
* Only successful reads are stored (errors are raised again on every read), with the notes a read
  gives (unfinished or recovered logs). The cache only speeds things up: an entry that cannot be
  written, or read back, is ignored and the log is decoded.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from livesweep.errors import ConfigError
from livesweep.hashing import sha256_of

__all__ = ["cache_dir", "cached_columns"]

_FORMAT = "livesweep.decoded/1"
_NOTES = "__notes__"
_SEP = "\x1f"          # between topic and field in an entry's array names (never in either)


def cache_dir() -> Path | None:
    """The cache folder, or None when ``LIVESWEEP_CACHE`` is ``off``/``0``/``no``/``false``."""
    if os.environ.get("LIVESWEEP_CACHE", "").strip().lower() in ("off", "0", "no", "false"):
        return None
    if os.environ.get("LIVESWEEP_CACHE_DIR"):
        return Path(os.environ["LIVESWEEP_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "livesweep"


def _limit_bytes() -> int:
    """``LIVESWEEP_CACHE_MB`` in bytes; ConfigError naming the variable and its value when it is not a
    number of megabytes >= 0."""
    text = os.environ.get("LIVESWEEP_CACHE_MB", "512")
    try:
        mb = float(text)
    except ValueError:
        mb = math.nan
    if not (math.isfinite(mb) and mb >= 0):
        raise ConfigError(f"LIVESWEEP_CACHE_MB = {text!r}: must be a number of megabytes >= 0 (default 512)")
    return int(mb * 1e6)


def _key(path: Path, requests: Mapping[str, list[str]], options: Mapping[str, str]) -> str:
    """The log's content hash (always read again: a cache must never serve a changed file) and the request."""
    what = [_FORMAT, sha256_of(path), sorted((t, list(f)) for t, f in requests.items()), sorted(options.items())]
    return hashlib.sha256(json.dumps(what).encode()).hexdigest()


def _load(entry: Path, requests: Mapping[str, list[str]]):
    with np.load(entry, allow_pickle=False) as z:
        out = {t: {f: z[t + _SEP + f] for f in [*fields, "t_ns"]} for t, fields in requests.items()}
        notes = [str(n) for n in z[_NOTES]]
    return out, notes


def _store(folder: Path, entry: Path, result, notes: list[str], limit: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    arrays = {t + _SEP + f: a for t, cols in result.items() for f, a in cols.items()}
    arrays[_NOTES] = np.array(notes, dtype=str)
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".partial")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, entry)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    _prune(folder, limit)


def _prune(folder: Path, limit: int) -> None:
    """Remove the least recently used entries until the folder holds at most ``limit`` bytes."""
    entries = []
    for p in folder.glob("*.npz"):
        try:
            st = p.stat()
        except OSError:
            continue
        entries.append((st.st_mtime, st.st_size, p))
    total = sum(e[1] for e in entries)
    for _, size, p in sorted(entries):
        if total <= limit:
            break
        p.unlink(missing_ok=True)
        total -= size


def cached_columns(path, requests: Mapping[str, list[str]], read: Callable[[list], dict], **options: str) -> dict:
    """``read(notes)`` (a decode of ``requests`` from the log at ``path``), from the cache when it holds it.

    Parameters
    ----------
    path : str or Path
        The log.
    requests : mapping of topic -> list of field names
    read : callable
        ``read(notes) -> {topic: {field: array, "t_ns": array}}``, appending its notes to ``notes``.
    **options : str
        Anything else the decode depends on (the clock, the missing-field rule).

    Returns
    -------
    dict
        ``{"columns": {topic: {field: array}}, "notes": [str], "cached": bool}``.
    """
    folder = cache_dir()
    limit = _limit_bytes() if folder is not None else 0        # a bad setting is named before any work
    path = Path(path)
    entry = None
    if folder is not None:
        try:
            entry = folder / (_key(path, requests, options) + ".npz")
            if entry.is_file():
                columns, notes = _load(entry, requests)
                os.utime(entry)                                   # recently used
                return {"columns": columns, "notes": notes, "cached": True}
        except Exception:   # noqa: BLE001 - an unreadable log: read() below names it; a bad entry: decode again
            pass
    notes: list[str] = []
    columns = read(notes)
    if entry is not None:
        try:
            _store(folder, entry, columns, notes, limit)
        except (OSError, ValueError):
            pass
    return {"columns": columns, "notes": notes, "cached": False}
