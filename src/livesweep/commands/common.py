"""What several commands share: output paths checked before any work, counts as words, how to
run a console script from this environment."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from livesweep.errors import ConfigError

__all__ = ["check_out_path", "counts_text", "command_name"]


def check_out_path(path: str) -> Path:
    """Fail before any work when the output cannot be written."""
    p = Path(path)
    if p.exists() and p.is_dir():
        raise ConfigError(f"--out {path!r} is a directory; give a file name ending in .mcap")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ConfigError(f"--out {path!r}: directory {str(parent)!r} does not exist")
    if not os.access(parent, os.W_OK):
        raise ConfigError(f"--out {path!r}: directory {str(parent)!r} is not writable")
    return p


def counts_text(counts: dict, words: dict | None = None) -> str:
    """Counts for people: ``{"truncated_tail": 1, "bad_crc": 0}`` -> ``"1 truncated tail"``: zeros left
    out; a key's words from ``words`` (a string, or ``(one, many)``), else the key with spaces;
    "none" when nothing is left."""
    parts = []
    for k, v in counts.items():
        if v:
            w = (words or {}).get(k, str(k).replace("_", " "))
            parts.append(f"{v} {w if isinstance(w, str) else w[v != 1]}")
    return ", ".join(parts) or "none"


def command_name(name: str) -> str:
    """How to run the console script ``name`` (``rerun``, ``livesweep``) from this environment: the
    bare name when it is on PATH, else the one installed next to this Python (a virtual
    environment that is not activated), else ``python -m``."""
    import shutil

    if shutil.which(name):
        return name
    beside = Path(sys.executable).parent / name
    return str(beside) if beside.exists() else f"{sys.executable} -m {name}"
