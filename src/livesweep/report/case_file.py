"""Write a case file back: the residual loop's augmented model as a case the user can read and run.

:func:`write_augmented_case` re-reads the original case file, replaces its ``[state_space]``
table, makes record paths absolute (the new file lives in the report folder) and writes TOML with
:func:`dumps_toml` (a small writer for the types a case holds: tables, arrays of tables, arrays,
strings, numbers, booleans; parameters as inline tables, as in docs/case-file.md).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

__all__ = ["dumps_toml", "write_augmented_case"]


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else '"' + k.replace('"', '\\"') + '"'


def _scalar(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"TOML cannot hold {v!r}")
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_scalar(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_scalar(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _is_table_array(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _emit(lines, path, table, inline_children=False):
    scalars = [(k, v) for k, v in table.items() if not (isinstance(v, dict) and not inline_children)
               and not _is_table_array(v)]
    if path and (scalars or not table):
        lines.append("")
        lines.append("[" + ".".join(_key(p) for p in path) + "]")
    for k, v in scalars:
        if isinstance(v, list) and v and all(isinstance(x, list) for x in v):
            lines.append(f"{_key(k)} = [")                   # one matrix row per line
            lines.extend(f"    {_scalar(x)}," for x in v)
            lines.append("]")
        else:
            lines.append(f"{_key(k)} = {_scalar(v)}")
    for k, v in table.items():
        if isinstance(v, dict) and not inline_children:
            _emit(lines, [*path, k], v, inline_children=(k == "parameters"))
        elif _is_table_array(v):
            for item in v:
                lines.append("")
                lines.append("[[" + ".".join(_key(p) for p in [*path, k]) + "]]")
                for kk, vv in item.items():
                    lines.append(f"{_key(kk)} = {_scalar(vv)}")


def dumps_toml(data: dict) -> str:
    """TOML text for ``data`` (round-trips through :mod:`tomllib`)."""
    lines: list[str] = []
    _emit(lines, [], data)
    return "\n".join(lines).lstrip("\n") + "\n"


def write_augmented_case(case_path, state_space: dict, out_path, *, header: str = "") -> Path:
    """Write ``case_path`` with its ``[state_space]`` replaced by ``state_space`` to ``out_path``.

    Parameters
    ----------
    case_path : path
        The original case file.
    state_space : dict
        The new ``[state_space]`` table.
    out_path : path
    header : str
        Comment lines put at the top (e.g. what the residual loop added).
    """
    case_path = Path(case_path).resolve()
    data = tomllib.loads(case_path.read_text())
    for key in ("identify", "verify"):
        for rec in data.get(key, []):
            if "log" in rec and not Path(rec["log"]).is_absolute():
                rec["log"] = str((case_path.parent / rec["log"]).resolve())
    data["state_space"] = state_space
    text = "".join(f"# {line}\n" for line in header.splitlines()) + dumps_toml(data)
    out = Path(out_path)
    out.write_text(text)
    return out
