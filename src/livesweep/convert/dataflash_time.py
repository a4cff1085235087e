"""The time base of a DataFlash log: each record's vehicle time, and the shift to UNIX time.

One job: the vehicle time [µs since boot] a record of a type carries (:func:`_time_us`: ``TimeUS``,
``TimeMS`` or PX4's ``TIME.StartTime``, -1 where implausible), and the offset from boot time to
UNIX time given by the first GPS record with a valid GPS time (:func:`_gps_offset_ns`). The rules
are described under *Time base* in :mod:`livesweep.convert.dataflash`.
"""

from __future__ import annotations

import numpy as np

from livesweep.convert.common import MAX_BOOT_US, UNIX_RANGE_S
from livesweep.convert.dataflash_values import _Type

_GPS_EPOCH_S = 315_964_800          # 1980-01-06 in UNIX seconds
_GPS_LEAP_S = 18                    # GPS - UTC since 2017 (what pymavlink's DFReader subtracts)
_UNIX_MIN_NS, _UNIX_MAX_NS = (s * 10**9 for s in UNIX_RANGE_S)


def _time_us(t: _Type) -> np.ndarray | None:
    """The vehicle time [µs since boot] each record of ``t`` carries (-1 where implausible), or None."""
    cols = t.columns
    if "TimeUS" in cols:
        raw, scale = t.raw[f"f{cols.index('TimeUS')}"], 1
    elif cols and cols[0] == "TimeMS" and not t.name.startswith(("ACC", "GYR")):
        raw, scale = t.raw["f0"], 1000
    elif t.name == "TIME" and "StartTime" in cols:                  # PX4 sdlog2
        raw, scale = t.raw[f"f{cols.index('StartTime')}"], 1
    else:
        return None
    if raw.dtype.kind not in "iu":
        return None
    x = raw.astype(np.float64) * scale          # range check first: uint64 garbage would wrap in int64
    ok = (x >= 0) & (x <= MAX_BOOT_US)
    return np.where(ok, raw.astype(np.int64) * scale, -1)


def _gps_offset_ns(types: dict[int, _Type], order_pos: dict[int, np.ndarray], vt_us: np.ndarray) -> int | None:
    """UNIX ns minus boot ns, from the first GPS record with a valid GPS time (None: no GPS time)."""
    best = None    # (global position, offset_ns)
    for t in types.values():
        if not t.name.startswith("GPS") or t.raw is None or not t.offsets.size:
            continue
        c = t.columns
        pos = order_pos[t.tid]
        if {"GWk", "GMS"} <= set(c) and "TimeUS" in c:
            wk = t.raw[f"f{c.index('GWk')}"].astype(np.int64)
            ms = t.raw[f"f{c.index('GMS')}"].astype(np.int64)
            unix_ns = ((_GPS_EPOCH_S - _GPS_LEAP_S + 604_800 * wk) * 1000 + ms) * 1_000_000
            ok = np.flatnonzero((wk > 0) & (unix_ns >= _UNIX_MIN_NS) & (unix_ns <= _UNIX_MAX_NS) & (vt_us[pos] >= 0))
            if ok.size:
                i = ok[0]
                cand = (int(pos[i]), int(unix_ns[i]) - int(vt_us[pos[i]]) * 1000)
                best = cand if best is None or cand[0] < best[0] else best
        elif "GPSTime" in c:
            graw = t.raw[f"f{c.index('GPSTime')}"]
            gns = graw.astype(np.float64) * 1000           # range check in float: garbage would wrap
            ok = np.flatnonzero((gns >= _UNIX_MIN_NS) & (gns <= _UNIX_MAX_NS))
            gt = graw.astype(np.int64)
            if ok.size:
                i = ok[0]
                cand = (int(pos[i]), int(gt[i]) * 1000 - int(vt_us[pos[i]]) * 1000)
                best = cand if best is None or cand[0] < best[0] else best
    return None if best is None else best[1]

