"""Small numeric helpers shared across livesweep: read-only arrays for frozen results, numbers made
JSON-safe for reports (non-finite -> None), and the one convention for non-finite floats in
recorded JSON messages.

JSON has no NaN or infinity. In messages livesweep records (MCAP logs, Zenoh results) a non-finite
float is written as the string ``"NaN"``, ``"Infinity"`` or ``"-Infinity"`` (the convention of the
protobuf JSON mapping), so a recording keeps which one it was; readers turn these three strings
back into floats (:func:`nonfinite_value`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["frozen_array", "finite_or_none", "NONFINITE_STRINGS", "nonfinite_text", "nonfinite_value",
           "float_json_schema", "json_safe", "percent", "points"]

#: How a non-finite float is written in a recorded JSON message, and read back.
NONFINITE_STRINGS = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def json_safe(obj):
    """``(copy, n)``: ``obj`` with every non-finite float as ``"NaN"`` / ``"Infinity"`` /
    ``"-Infinity"``, and how many there were.

    Tuples become lists, numpy arrays and scalars their Python equivalents (nested too); anything
    else is returned as it is (``json.dumps`` rejects what it cannot encode).
    """
    counter = [0]

    def walk(o):
        if isinstance(o, float):
            if math.isfinite(o):
                return o
            counter[0] += 1
            return nonfinite_text(o)
        if isinstance(o, dict):
            return {k: walk(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [walk(v) for v in o]
        if isinstance(o, np.ndarray):
            return walk(o.tolist())
        if isinstance(o, np.generic):
            return walk(o.item())
        return o

    return walk(obj), counter[0]


def float_json_schema(**extra) -> dict:
    """JSON Schema of a recorded float: a number, one of the non-finite strings, or null (``null``
    is how logs written before this convention stored non-finite values). ``pattern`` constrains
    strings only. ``extra`` keys (``description``) are added; a fresh dict on every call."""
    return {"type": ["number", "string", "null"], "pattern": "^(NaN|Infinity|-Infinity)$", **extra}


def nonfinite_text(x: float) -> str:
    """``"NaN"``, ``"Infinity"`` or ``"-Infinity"`` for a non-finite float ``x``."""
    return "NaN" if math.isnan(x) else ("Infinity" if x > 0 else "-Infinity")


def nonfinite_value(v):
    """The float a recorded ``"NaN"`` / ``"Infinity"`` / ``"-Infinity"`` stands for; None for anything else."""
    return NONFINITE_STRINGS.get(v) if isinstance(v, str) else None


def frozen_array(a, dtype=float) -> np.ndarray:
    """A read-only copy of ``a`` (``dtype=None`` keeps the input's type, e.g. complex)."""
    arr = np.array(a, dtype=dtype)
    arr.setflags(write=False)
    return arr


def finite_or_none(x, digits: int | None = None) -> float | None:
    """``float(x)`` (rounded to ``digits`` when given), or None when it is not a finite number."""
    try:
        x = float(x)
    except (TypeError, ValueError, OverflowError):      # OverflowError: an integer beyond float range
        return None
    if not math.isfinite(x):
        return None
    return round(x, digits) if digits is not None else x


def _is_finite(x) -> bool:
    try:
        return x is not None and math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def percent(fraction: float | None, threshold: float | None = None, *, missing: str = "—") -> str:
    """A fraction as a percentage, never rounded onto the other side of ``threshold``.

    Parameters
    ----------
    fraction : float or None
        The value, 0..1 (not clipped).
    threshold : float, optional
        The fraction it is judged against (e.g. 0.6). When the whole-percent rounding would put
        the shown number on the other side of it (0.5999 -> "60 %" while 0.5999 < 0.6), one
        decimal is shown, rounded *away* from the threshold (floor below it, ceiling at or above
        it): 0.5999 -> "59.9 %", 0.6 -> "60 %", 0.6049 with threshold 0.605 -> "60.4 %".
    missing : str
        Text for None, NaN or infinity.

    Returns
    -------
    str
        ``"<number> %"`` (a space before the sign, as in the adequacy tables).

    Notes
    -----
    A value strictly between 0 and 0.5 % or between 99.5 and 100 % keeps one decimal (rounded
    away from 0 and 100), so "0 %" and "100 %" mean exactly none and all.
    """
    if not _is_finite(fraction):
        return missing
    f = float(fraction)
    whole = f"{100.0 * f:.0f}"
    if (whole == "0" and f > 0.0) or (whole == "100" and f < 1.0):   # "0 %"/"100 %" mean none/all
        tenths = math.ceil(1000.0 * f) if f < 0.5 else math.floor(1000.0 * f)
        text = f"{tenths / 10.0:.1f}"
    else:
        text = whole
    if threshold is None or not _is_finite(threshold):
        return f"{text} %"
    thr = float(threshold)
    below = f < thr
    if (float(text) / 100.0 < thr) == below:
        return f"{text} %"
    tenths = math.floor(1000.0 * f) if below else math.ceil(1000.0 * f)
    if (tenths / 1000.0 < thr) != below:     # 1000 * f rounded onto an integer across the threshold
        tenths += -1 if below else 1
    return f"{tenths / 10.0:.1f} %"


def points(fraction: float, threshold: float) -> str:
    """How far a fraction is from its threshold in percentage points, signed: ``"+21 points"``,
    with one decimal within half a point of it (``"-0.2 points"``), ``"0 points"`` on it."""
    d = 100.0 * (float(fraction) - float(threshold))
    for text in (f"{d:+.0f}", f"{d:+.1f}"):         # whole points, else a tenth; never a signed zero
        if text.lstrip("+-").strip("0.") != "":
            return f"{text} points"
    return "0 points"
