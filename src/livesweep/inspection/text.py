"""The text ``livesweep inspect`` prints: :func:`format_inspection`.

One job: the presentation of a :class:`~livesweep.inspection.results.LogInspection`: the topics with
their rates and fields, the SystemID test points, the presets that fit with the commands to use
them, the presets that do not fit and why, and, for a DataFlash log, the presets for its telemetry.
"""

from __future__ import annotations

import math

from livesweep.inspection.results import LogInspection, TopicInfo
from livesweep.inspection.thresholds import MAX_FIELDS, SHORT_S, STREAM_RATE_HZ

__all__ = ["format_inspection"]

#: SystemID runs without data named at most in their line.
_MAX_NAMED = 8


def _fields_line(t: TopicInfo) -> str:
    shown = t.fields[:MAX_FIELDS]
    if t.decoded:
        text = ", ".join(f"{f} [{u}]" if u else f for f, u in shown)
    else:
        text = ", ".join(f"{f} ({typ})" for f, typ in shown)
    more = f", ... ({len(t.fields)} fields in all)" if len(t.fields) > MAX_FIELDS else ""
    return "      " + text + more


def format_inspection(ins: LogInspection) -> str:
    """The text ``livesweep inspect`` prints."""
    decoded = [t for t in ins.topics if t.decoded]
    count = (f"{len(ins.topics)} topics livesweep reads" if len(decoded) == len(ins.topics) else
             f"{len(ins.topics)} topics, {len(decoded)} of them in JSON, which livesweep reads")
    lines = [f"{ins.path}: {ins.format}, {ins.duration_s:.1f} s, {count}"]
    lines += [f"  note: {n}" for n in ins.notes]
    for t in ins.topics:
        enc = "" if t.decoded else f" ({t.encoding}, not decoded)"
        lines.append(f"  {t.topic}: {t.messages} messages, {t.rate_hz:.1f} Hz, {t.start_s:.1f}-{t.end_s:.1f} s{enc}")
        if t.fields:
            lines.append(_fields_line(t))
        elif t.fields_note:
            lines.append(f"      {t.topic}: {t.fields_note}")
    if ins.systemid:
        with_data = [r for r in ins.systemid if r.data]
        without = [r for r in ins.systemid if not r.data]
        lines.append("test points (ArduPilot SystemID):")
        for r in with_data:
            span = f"{r.start_s:.1f}-{r.end_s:.1f} s" if math.isfinite(r.end_s) else f"from {r.start_s:.1f} s"
            lines.append(f"  {span}: {r.what}")
        if without:
            named = ", ".join(f"{r.what.split(',')[0].removeprefix('SystemID ')} at {r.start_s:.1f} s"
                              for r in without[:_MAX_NAMED])
            more = f", ... ({len(without)} in all)" if len(without) > _MAX_NAMED else ""
            cover = "them at the rates their bands need" if len(without) > 1 else "it at the rate its band needs"
            lines.append(f"  {'' if with_data else 'all '}{len(without)} announced but without data (no preset's "
                         f"signals cover {cover}): {named}{more}")
    fitting = [f for f in ins.fits if f.fits and not f.live]
    if fitting and ins.duration_s < SHORT_S:
        lines.append(f"only {ins.duration_s:.1f} s of data: too short for a frequency response (a sweep's lowest "
                     "frequency needs windows of tens of seconds)")
    if fitting:
        best = fitting[0].name
        lines.append("channel-map presets whose signals this log holds (pairs with data / pairs):")
        lines += [f"  {f.name}: {f.pairs}/{f.total}" for f in fitting]
        how = (f"livesweep replay {ins.path} --map {best}" if ins.format == "mcap" else
               f"livesweep convert {ins.path} --out LOG.mcap && livesweep replay LOG.mcap --map {best}")
        lines.append(f"suggested: {how}")
        lines.append(f"  a case for identify: livesweep new-case {ins.path} --map {best} --out CASE.toml")
    elif not decoded:
        encodings = sorted({t.encoding for t in ins.topics})
        lines.append("no topic livesweep decodes (it reads JSON MCAP channels"
                     + (f"; these are {', '.join(encodings)}: convert them to JSON first" if encodings else "")
                     + "): no channel map can be suggested")
    else:
        lines.append("no shipped channel map fits this log: write one ([signals], [spectral]) from the fields above "
                     "(docs/case-file.md, Channel maps)")
    unfit = [f for f in ins.fits if not f.fits and not f.live]
    if unfit:
        lines.append("presets that hold this log's signals but do not fit it:")
        lines += [f"  {f.name}: {f.why}" for f in unfit]
    live = [f for f in ins.fits if f.live]
    if live:
        lines.append(f"live, as ArduCopter's telemetry (livesweep stream {ins.path} --mavlink udpout:127.0.0.1:14550 "
                     f"--rate-hz {STREAM_RATE_HZ:g}):")
        lines += [f"  {f.name}: {f.pairs}/{f.total}" if f.fits else f"  not {f.name}: {f.why}" for f in live]
        if ins.live_maps:
            lines.append(f"  monitor it with: livesweep monitor --mavlink udpin:127.0.0.1:14550 --map {ins.live_maps[0]}")
    return "\n".join(lines)
