"""Which channel-map presets fit a log: :func:`_fit`.

One job: the map suggestion. The candidate maps (:func:`_candidate_maps`: the shipped presets and
the packaged XV-15 map), and for each how it fits: its signals are there and vary, the vehicle is
the one it is made for, and each signal arrives fast enough for the band the map's monitor judges
(:func:`_band_top_hz`); for a DataFlash log, the rates its telemetry would have as ``livesweep
stream`` sends it (:func:`_stream_rates`).
"""

from __future__ import annotations

import math
from pathlib import Path

from livesweep.inspection.rates import _rate, _signal_rate
from livesweep.inspection.results import MapFit
from livesweep.inspection.stats import _Stats
from livesweep.inspection.thresholds import RATE_PER_TOP_FREQUENCY
from livesweep.spectral.verdict import NYQUIST_FRACTION

#: What ``livesweep stream`` makes of a DataFlash log: MAVLink topic -> the DataFlash records it comes
#: from (its rate is the slowest of them, capped at the stream rate); PID_TUNING per axis.
_STREAM_OF_DATAFLASH = {"/mavlink/ATTITUDE": ("/dataflash/ATT", "/dataflash/RATE"),
                        "/mavlink/SERVO_OUTPUT_RAW": ("/dataflash/RCOU",),
                        "/mavlink/RAW_IMU": ("/dataflash/IMU",), "/mavlink/HEARTBEAT": (),
                        "/mavlink/STATUSTEXT": ("/dataflash/MSG",), "/mavlink/PARAM_VALUE": ("/dataflash/PARM",)}
_PID_RECORDS = {1: "/dataflash/PIDR", 2: "/dataflash/PIDP", 3: "/dataflash/PIDY"}


def _candidate_maps():
    """``(name, ChannelMap, whole)`` of the shipped presets and the packaged XV-15 map (the demo's,
    which counts only when all of it fits)."""
    from livesweep.config import read_channel_map
    from livesweep.maps import list_maps, load_map

    out = [(info.name, load_map(info.name), False) for info in list_maps()]
    xv15 = Path(__file__).resolve().parents[1] / "data" / "xv15_channels.toml"
    out.append((str(xv15), read_channel_map(xv15, one_clock=False), True))
    return out


def _judged_top_hz(top_hz: float, what: str, m) -> tuple[float, str]:
    """The top of a band [Hz] as the map's monitor judges it: at most NYQUIST_FRACTION of its
    grid's Nyquist frequency."""
    grid_top = NYQUIST_FRACTION * m.spectral.sample_rate_hz / 2
    if top_hz > grid_top:
        return grid_top, f"the map's {m.spectral.sample_rate_hz:g} Hz grid (judged up to {grid_top:.3g} Hz)"
    return top_hz, what


def _band_top_hz(stats: _Stats, m) -> tuple[float, str]:
    """The top frequency a map's signals must show [Hz], and where it comes from."""
    tops = [r["injection"].omega_stop_rad_s / (2 * math.pi) for r in stats.runs if r.get("injection") is not None]
    if tops:
        return _judged_top_hz(max(tops), "the SystemID band", m)
    return _judged_top_hz(m.spectral.band_rad_s[1] / (2 * math.pi), "the map's band", m)


def _fit(stats: _Stats, name: str, m, whole: bool, rates: dict | None = None, live: bool = False) -> MapFit | None:
    """How map ``m`` fits: None when it holds no signal of the log; ``rates`` (signal -> Hz) replaces
    the measured rates (a stream's)."""
    sp = m.spectral
    if sp is None:
        return None
    have = {}
    for sig in (*sp.inputs, *sp.outputs, *(sp.references or ())):
        spec = m.signals[sig]
        if rates is not None:
            r = rates.get(sig)
            have[sig] = None if r is None else (True, r)
            continue
        s = stats.signal(spec)
        have[sig] = None if s.n == 0 else (s.hi > s.lo, _signal_rate(stats, s))
    if not all(have[r] is not None and have[r][0] for r in sp.references or ()):
        return None
    ins = [i for i in sp.inputs if have[i] is not None and have[i][0]]
    outs = [o for o in sp.outputs if have[o] is not None and have[o][0]]
    n, total = len(ins) * len(outs), len(sp.inputs) * len(sp.outputs)
    if not n or (whole and n != total):
        return None
    why = stats.vehicle.contradiction(m.vehicle) or ""
    if not why:
        top_hz, what = _band_top_hz(stats, m)
        need = RATE_PER_TOP_FREQUENCY * top_hz
        slow = sorted((have[s][1], s) for s in (*ins, *outs) if have[s][1] < need)
        if slow:
            per_message: dict[str, tuple[float, str]] = {}
            for rate, sig in slow:                          # the slowest signal of each message
                per_message.setdefault(m.signals[sig].topic.rsplit("/", 1)[-1], (rate, sig))
            parts = [f"{sig} ({msg}) {('would go at' if live else 'arrives at') if k == 0 else 'at'} {rate:.3g} Hz"
                     for k, (msg, (rate, sig)) in enumerate(per_message.items())]
            why = f"{', '.join(parts)}: {what} up to {top_hz:.3g} Hz needs {need:.3g} Hz"
    return MapFit(name, n, total, why, live)


def _stream_rates(stats: _Stats, m, rate_hz: float) -> dict | None:
    """The rate each signal of MAVLink map ``m`` would arrive at when ``livesweep stream --rate-hz``
    sends this DataFlash log; None when the stream lacks one of the map's topics."""
    def rec_rate(topic):
        st = stats.topics.get(topic)
        return 0.0 if st is None else _rate(st[0], st[1], st[2])

    out = {}
    for sig, spec in m.signals.items():
        if spec.topic == "/mavlink/PID_TUNING":
            axis = dict(spec.where).get("axis")
            src = _PID_RECORDS.get(int(axis)) if axis is not None else None
            r = rec_rate(src) if src else 0.0
        elif spec.topic in _STREAM_OF_DATAFLASH:
            srcs = _STREAM_OF_DATAFLASH[spec.topic]
            r = min(rec_rate(x) for x in srcs) if srcs else 1.0
        else:
            return None
        if r <= 0:
            return None
        out[sig] = min(r, rate_hz)
    return out
