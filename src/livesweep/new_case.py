"""``livesweep new-case LOG --map NAME``: an annotated case file for a log and a channel map.

The case names the log (converted to MCAP next to the case first when it is a tlog, DataFlash,
PX4 or ULog log), copies the map's ``[signals]`` and ``[spectral]`` tables, and carries commented
templates of the later stages (transfer functions, state space, verification, residual loop)
with pointers to ``docs/case-file.md``. ``livesweep identify`` accepts it as written; the
frequency-response stage runs on it at once.
"""

from __future__ import annotations

import datetime
import json
import os
from pathlib import Path

from livesweep.errors import ConfigError

__all__ = ["write_new_case"]

_TEMPLATE = """# Case file written by `livesweep new-case` on {date} for
#   {log_src}
# with the channel map {map_name} ({map_desc}).
#
# Next: edit [case], check [spectral] (band, windows) against your sweep, crop [[identify]] to the
# sweeps with start_s/end_s (the signals' stamp clock, s), then
#   livesweep identify {case_name} --out report
# Every table and key: docs/case-file.md.

[case]
name = "{name}"
aircraft = "{aircraft}"                 # edit: the airframe
condition = "{condition}"               # edit: the flight condition of the test point

[[identify]]                            # the sweeps (one entry per log; they are concatenated)
log = "{log}"
label = "{label}"
# start_s = 30.0                        # crop to the sweep, on the signals' stamp clock [s]
# end_s = 95.0

# [[verify]]                            # dissimilar manoeuvres (doublets, 3-2-1-1) for time-domain
# log = "verify.mcap"                   # verification of the identified model
# label = "doublets"

{tables}
# --- later stages: uncomment and edit (docs/case-file.md) -----------------------------------
#
# [transfer_functions.{tf_name}]        # a low-order model of one pair
# output = "{out0}"
# input = "{in0}"
# denominator = "(1/T)"                 # (1/T) first order, [zeta, w] second order, s integrator
# numerator = ""
# delay = true
#
# [state_space]                         # derivatives: M x' = F x + G u(t - tau), y = H x + J u
# states = ["..."]
# inputs = {inputs}
# outputs = {outputs}
# F = [[...]]                           # entries: numbers, parameter names or expressions
# G = [[...]]
# H = [[...]]
# [state_space.units]                   # units of the states, for the report's derivative units
# [state_space.parameters]              # name = {{ value = ..., fixed = false }}
#
# [residual]                            # the residual loop (on by default with [state_space])
# false_alarm = 0.01
"""


def _sections(path: Path, keep=("signals", "spectral")) -> str:
    """The text of a TOML file's ``[signals.*]`` and ``[spectral]`` tables, comments included."""
    out, on = [], False
    for line in path.read_text().splitlines():
        s = line.strip()
        if s.startswith("[") and not s.startswith("[["):
            head = s.strip("[]").split(".")[0].strip()
            on = head in keep
        elif s.startswith("[["):
            on = False
        if on:
            out.append(line)
    return "\n".join(out).strip() + "\n"


def write_new_case(log, map_name: str, out, *, force: bool = False) -> dict:
    """Write a case file for ``log`` with the channel map ``map_name``.

    Parameters
    ----------
    log : str or Path
        Any log livesweep reads; not MCAP: converted to ``<case folder>/<log stem>.mcap`` first
        (kept when it exists).
    map_name : str
        A preset name (``livesweep maps``) or a channel-map file.
    out : str or Path
        The case file to write.
    force : bool
        Replace an existing ``out``.

    Returns
    -------
    dict
        ``case`` (path), ``log`` (the MCAP the case names), ``converted`` (bool).
    """
    from livesweep.convert.common import sniff_format
    from livesweep.maps import load_map

    log, out = Path(log), Path(out)
    if not log.is_file():
        raise ConfigError(f"{log}: no such file")
    if out.exists() and not force:
        raise ConfigError(f"--out {str(out)!r} exists; give --force to replace it")
    m = load_map(map_name)
    if m.spectral is None:
        raise ConfigError(f"{m.path}: the map has no [spectral] table (inputs, outputs, band): a case needs one")
    out.parent.mkdir(parents=True, exist_ok=True)
    converted = False
    mcap = log
    if sniff_format(log) != "mcap":
        from livesweep.convert import convert

        mcap = out.parent / (log.stem + ".mcap")
        if not mcap.exists():
            convert(log, mcap)
            converted = True
    rel = os.path.relpath(mcap.resolve(), out.parent.resolve())
    sp = m.spectral
    text = _TEMPLATE.format(
        date=datetime.date.today().isoformat(), log_src=log, map_name=m.name or map_name,
        map_desc=(m.description or "").strip().splitlines()[0] if m.description else "a channel map",
        case_name=out.name, name=log.stem, aircraft="unknown", condition="unknown", log=rel.replace(os.sep, "/"),
        label=log.name, tables=_sections(m.path), tf_name=f"{sp.outputs[0]}_{sp.inputs[0]}",
        out0=sp.outputs[0], in0=sp.inputs[0], inputs=json.dumps(list(sp.inputs)), outputs=json.dumps(list(sp.outputs)))
    out.write_text(text)
    return {"case": out, "log": mcap, "converted": converted}
