"""Small numeric helpers shared across livesweep: read-only arrays for frozen results, and numbers
made JSON-safe (non-finite -> None)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["frozen_array", "finite_or_none"]


def frozen_array(a, dtype=float) -> np.ndarray:
    """A read-only copy of ``a`` (``dtype=None`` keeps the input's type, e.g. complex)."""
    arr = np.array(a, dtype=dtype)
    arr.setflags(write=False)
    return arr


def finite_or_none(x, digits: int | None = None) -> float | None:
    """``float(x)`` (rounded to ``digits`` when given), or None when it is not a finite number."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(x):
        return None
    return round(x, digits) if digits is not None else x
