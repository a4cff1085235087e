"""Edits of a ``[state_space]`` table (docs/method.md §0) that add an effect, as a user would write
them: new states, parameters, delays and entries, so the augmented case stays readable."""

from __future__ import annotations

import copy
import re

__all__ = ["restart_from", "normalised", "is_zero", "has_parameter", "fresh", "add_state", "add_parameter", "product",
           "add_entry", "route_input", "EFFECT_STATE_PREFIXES"]

#: States the effects add (their equations are the effect's, not the vehicle's).
EFFECT_STATE_PREFIXES = ("act_", "actrate_", "notch_", "notchrate_", "mode_", "moderate_")


def normalised(table: dict) -> dict:
    """A deep copy with every key an effect may edit present and every matrix a list of lists."""
    t = copy.deepcopy(table)
    t.setdefault("parameters", {})
    t.setdefault("J", [["0"] * len(t["inputs"]) for _ in t["outputs"]])
    for key in ("F", "G", "H", "J"):
        t[key] = [list(r) for r in t[key]]
    if t.get("M"):
        t["M"] = [list(r) for r in t["M"]]
    t["states"] = list(t["states"])
    return t


def is_zero(entry) -> bool:
    """Whether a matrix entry is the number 0."""
    try:
        return float(str(entry)) == 0.0
    except ValueError:
        return False


def has_parameter(entry, names) -> bool:
    """Whether an entry expression uses one of ``names``."""
    return any(tok in names for tok in re.findall(r"[A-Za-z_][A-Za-z_0-9]*", str(entry)))


def fresh(name: str, taken) -> str:
    """``name``, or ``name_2``, ``name_3``... when taken."""
    base, k = name, 2
    while name in taken:
        name = f"{base}_{k}"
        k += 1
    return name


def add_state(t: dict, names) -> list[int]:
    """Append states (identity rows/columns of M, zero rows/columns elsewhere); their indices."""
    idx = []
    for name in names:
        n = len(t["states"])
        t["states"].append(fresh(name, set(t["states"])))
        t["M"] = [row + ["0"] for row in t.get("M") or [["1" if a == b else "0" for b in range(n)] for a in range(n)]]
        t["M"].append(["0"] * n + ["1"])
        t["F"] = [row + ["0"] for row in t["F"]]
        t["F"].append(["0"] * (n + 1))
        t["G"].append(["0"] * len(t["inputs"]))
        t["H"] = [row + ["0"] for row in t["H"]]
        idx.append(n)
    return idx


def add_parameter(t: dict, name: str, value: float) -> str:
    """A new free parameter (a fresh name) with start ``value``; its name."""
    name = fresh(name, set(t["parameters"]) | set(t.get("constants", {})))
    t["parameters"][name] = {"value": float(value)}
    return name


def product(a, b) -> str:
    """The entry ``a*b`` ("0" when either is 0)."""
    if is_zero(a) or is_zero(b):
        return "0"
    return f"({a})*({b})"


def add_entry(t: dict, target: str, name: str, value: float = 0.0) -> list[str]:
    """Put a new parameter into an absent entry ``"F[row][col]"`` / ``"G[row][col]"``."""
    key, rest = target[0], target[2:-1]
    row, col = rest.split("][")
    i = t["states"].index(row)
    j = (t["states"] if key == "F" else t["inputs"]).index(col)
    t["parameters"][name] = {"value": float(value)}
    t[key][i][j] = name
    return [name]


def route_input(t: dict, j: int, a: int, n0: int) -> None:
    """Input ``j`` now reaches the first ``n0`` states and the outputs through state ``a``."""
    for i in range(n0):
        t["F"][i][a] = t["G"][i][j]
        t["G"][i][j] = "0"
    for o in range(len(t["outputs"])):
        t["H"][o][a] = t["J"][o][j]
        t["J"][o][j] = "0"


def restart_from(aug: dict, origin: dict) -> dict:
    """``aug`` with the model's own parameters back at the case's starting values (``origin``'s), the
    effects' parameters as they are."""
    t = copy.deepcopy(aug)
    for name, entry in origin.get("parameters", {}).items():
        if name in t["parameters"]:
            t["parameters"][name] = copy.deepcopy(entry)
    return t
