"""From a flight to its models without a case file: ``livesweep identify FLIGHT.mcap --map NAME``.

The test points of one log (:func:`livesweep.campaign.scan.scan_file`: the monitor's recorded
``/livesweep/test_point`` channel, else the autopilot's SystemID runs) are grouped by the input
they sweep (a run found offline takes its input from the map's ``[test_points] axes``), and each
input's usable test points (GO, or not judged) are identified together as one case
(:func:`livesweep.campaign.concat.identify_test_points`), each with :data:`TRIM_PAD_S` of trim on
either side. When the recording holds the monitor's models of those test points
(``/livesweep/model``), their structures are fitted too, so the report sets the in-flight model
beside the full identification.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from livesweep.campaign.identify import TRIM_PAD_S, swept_input_of, usable
from livesweep.errors import ConfigError

__all__ = ["FlightPlan", "plan_flight", "MODEL_TOPIC"]

#: The monitor's model channel in its recordings.
MODEL_TOPIC = "/livesweep/model"


@dataclass(frozen=True)
class FlightPlan:
    """What one input of a flight is identified from.

    Attributes
    ----------
    swept_input : str
    points : tuple of TestPointRef
        Its usable test points, padded with trim.
    transfer_functions : dict
        ``[transfer_functions]`` tables from the recorded models' structures (empty: none recorded).
    """

    swept_input: str
    points: tuple
    transfer_functions: dict


def _model_structures(path: Path, starts: set) -> dict:
    """``[transfer_functions]`` tables of the recorded models of the test points starting at ``starts``."""
    from livesweep.telemetry.mcap_log import read_messages

    tables = {}
    try:
        messages = list(read_messages(path, topics=MODEL_TOPIC))
    except Exception:              # a log without the channel, or not the monitor's: nothing to add
        return tables
    for m in messages:
        d = m.data if isinstance(m.data, dict) else {}
        tp = d.get("test_point") or {}
        if tp.get("start_s") not in starts:
            continue
        for p in d.get("pairs") or ():
            name = f"{p.get('output')}_{p.get('input')}".replace("/", "_")
            if name not in tables and isinstance(p.get("denominator"), str):
                tables[name] = {"output": p["output"], "input": p["input"], "numerator": p.get("numerator", ""),
                                "denominator": p["denominator"], "delay": True}
    return tables


def plan_flight(path, *, map, swept_input: str | None = None) -> list[FlightPlan]:
    """The identifications a flight log supports: one per swept input with usable test points.

    Parameters
    ----------
    path : str or Path
        An MCAP log (a monitor's recording, or a converted log with the autopilot's SystemID runs).
    map : str, Path or ChannelMap
    swept_input : str, optional
        Only this input.

    Raises
    ------
    ConfigError
        The log holds no usable test point (of ``swept_input``), naming the file.
    """
    from livesweep.campaign.concat import TestPointRef
    from livesweep.campaign.scan import scan_file
    from livesweep.maps import load_map

    path = Path(path)
    chosen = load_map(map) if isinstance(map, (str, Path)) else map
    axes = dict(chosen.test_points.axes) if chosen.test_points is not None else {}
    scanned = scan_file(path)
    groups: dict[str, list] = {}
    for tp in scanned.test_points:
        inp = swept_input_of(tp.get("swept_input"), tp.get("axis"), axes)
        if inp and usable(tp.get("start_s"), tp.get("end_s"), tp.get("record"), tp.get("verdict")) \
                and (swept_input is None or inp == swept_input):
            groups.setdefault(inp, []).append(tp)
    if not groups:
        raise ConfigError(f"{path}: no usable test point" + (f" of input {swept_input!r}" if swept_input else "")
                          + f" ({len(scanned.test_points)} test point(s) in the log: GO or unjudged ones count)")
    plans = []
    for inp, tps in groups.items():
        points = tuple(TestPointRef(path, tp["start_s"] - TRIM_PAD_S, tp["end_s"] + TRIM_PAD_S,
                                    f"TP{tp['number']} {inp}") for tp in tps)
        plans.append(FlightPlan(inp, points, _model_structures(path, {tp["start_s"] for tp in tps})))
    return plans
