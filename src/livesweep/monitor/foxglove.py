"""A Foxglove layout for a livesweep recording: the inputs, the outputs, the coherence of every
pair over time and the verdict.

The monitor writes it next to its recording (``live.mcap`` -> ``live.foxglove.json``); in
Foxglove, open the MCAP and import the layout (Layouts -> Import from file). The paths use
Foxglove's message-path syntax on the recording's JSON channels: ``/mavlink/ATTITUDE.rollspeed``,
``/mavlink/PID_TUNING{axis==1}.achieved``, ``/livesweep/estimate.pairs[:]{name=="p/da"}.median_coherence``.
"""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["foxglove_layout", "write_layout", "signal_path"]

_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf"]


def signal_path(spec) -> str | None:
    """Foxglove message path of a channel-map signal, or None when its field is an expression
    (Foxglove plots fields, not arithmetic of them)."""
    from livesweep.errors import ConfigError
    from livesweep.telemetry.extract import parse_field

    try:
        expr = parse_field(spec.field, spec.name if hasattr(spec, "name") else "field")
    except ConfigError:
        return None
    if not expr.is_plain:
        return None
    where = "".join(f"{{{k}=={json.dumps(v)}}}" for k, v in (spec.where or ()))
    if spec.sysid is not None:
        where += f"{{sysid=={spec.sysid}}}"
    field = expr.operands[0].replace("[", ".").replace("]", "")
    return f"{spec.topic}{where}.{field}"


def _plot(title: str, paths: list[tuple[str, str]]) -> dict:
    return {"title": title, "paths": [{"value": v, "label": label, "enabled": True, "timestampMethod": "receiveTime",
                                       "color": _COLORS[k % len(_COLORS)]} for k, (v, label) in enumerate(paths)],
            "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True, "legendDisplay": "floating",
            "isSynced": True, "xAxisVal": "timestamp"}


def foxglove_layout(signals: dict, inputs, outputs) -> dict:
    """The layout (Foxglove's JSON) for a recording made with these channel-map signals.

    Parameters
    ----------
    signals : dict of str -> SignalSpec
    inputs, outputs : sequence of str

    Returns
    -------
    dict
        ``configById``, ``layout`` and the other keys of a Foxglove layout file.
    """
    def paths(names):
        out = []
        for n in names:
            p = signal_path(signals[n]) if n in signals else None
            if p:
                sig = signals[n]
                scaled = sig.scale != 1.0 or sig.offset != 0.0
                out.append((p, f"{n}: raw field (livesweep scales it to {sig.units})" if scaled else
                            f"{n} [{sig.units}]" if sig.units else n))
        return out

    pairs = [f"{o}/{i}" for o in outputs for i in inputs]
    coh = [(f'/livesweep/estimate.pairs[:]{{name=="{p}"}}.median_coherence', f"{p} median coherence") for p in pairs]
    frac = [(f'/livesweep/estimate.pairs[:]{{name=="{p}"}}.adequate_fraction', f"{p} adequate fraction")
            for p in pairs]
    config = {
        "Plot!inputs": _plot("inputs", paths(inputs)),
        "Plot!outputs": _plot("outputs", paths(outputs)),
        "Plot!coherence": _plot("median coherence per pair (sliding window)", coh),
        "Plot!adequacy": _plot("adequate fraction of the band per pair", frac),
        "StateTransitions!verdict": {"paths": [{"value": "/livesweep/estimate.verdict", "timestampMethod": "receiveTime",
                                                "label": "verdict"}], "isSynced": True},
        "RawMessages!testpoint": {"topicPath": "/livesweep/test_point", "diffEnabled": False, "diffMethod": "custom",
                                  "diffTopicPath": "", "showFullMessageForDiff": False},
    }
    layout = {"direction": "row", "splitPercentage": 62,
              "first": {"direction": "column", "first": "Plot!inputs",
                        "second": {"direction": "column", "first": "Plot!outputs", "second": "StateTransitions!verdict",
                                   "splitPercentage": 75}, "splitPercentage": 35},
              "second": {"direction": "column", "first": "Plot!coherence",
                         "second": {"direction": "column", "first": "Plot!adequacy", "second": "RawMessages!testpoint"},
                         "splitPercentage": 40}}
    return {"configById": config, "globalVariables": {}, "userNodes": {}, "linkedGlobalVariables": [],
            "playbackConfig": {"speed": 1.0}, "layout": layout}


def write_layout(recording, signals: dict, inputs, outputs) -> Path:
    """Write the layout next to ``recording`` (``x.mcap`` -> ``x.foxglove.json``); returns its path."""
    path = Path(recording).with_suffix(".foxglove.json")
    path.write_text(json.dumps(foxglove_layout(signals, inputs, outputs), indent=1))
    return path
