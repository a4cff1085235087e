"""ArduCopter SystemID runs from what the vehicle sends: where each starts and ends, and the sweep.

ArduCopter's SystemID mode says a run's start as the text "SystemID Starting: axis=N" (MAVLink
STATUSTEXT, DataFlash MSG) and, in a DataFlash log, as a SIDS record carrying the sweep's
parameters; it says the end as "SystemID Finished". Entering or leaving the SYSTEMID flight mode
(HEARTBEAT ``custom_mode``, DataFlash MODE) starts or ends a run too (a pilot who switches modes
aborts the chirp without a "Finished"). The same start often comes twice (the text and SIDS, or the
text and the mode change); :data:`SAME_START_S` and :func:`better_injection` say how to merge them.

:class:`SystemIdWatch` reads one vehicle's frames; the live test-point tracker and ``livesweep
inspect`` both use it, so a log and its live stream find the same runs.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from livesweep.monitor.vehicle import ARDUPILOT_AUTOPILOT, MULTIROTOR_TYPES, VehicleInfo
from livesweep.spectral.injection import SweepInjection

__all__ = ["SystemIdEvent", "SystemIdWatch", "better_injection", "ARDUPILOT_SYSTEMID_MODE", "SAME_START_S", "TOPICS"]

#: ArduCopter's flight-mode number of SYSTEMID (custom_mode of HEARTBEAT, Mode of DataFlash MODE).
ARDUPILOT_SYSTEMID_MODE = 25
#: Two starts this close [s] are one run said twice (a text and SIDS, a text and the mode change).
SAME_START_S = 2.0
#: The topics that can carry a SystemID start or end.
TOPICS = ("/mavlink/STATUSTEXT", "/dataflash/MSG", "/dataflash/SIDS", "/mavlink/HEARTBEAT", "/dataflash/MODE")

_START = re.compile(r"SystemID Starting: axis=(\d+)")
_FINISHED = re.compile(r"SystemID Finished")


@dataclass(frozen=True)
class SystemIdEvent:
    """A SystemID run's start or end, as one frame says it."""

    action: str                        # "start" or "end"
    axis: int | None                   # SID_AXIS (None: the vehicle did not say)
    injection: SweepInjection | None   # the sweep it was told to fly, when known
    note: str                          # what said it ("SystemID Starting: axis=7", "SIDS axis 7", "mode 25 -> 5")


def better_injection(current: SweepInjection | None, new: SweepInjection | None) -> SweepInjection | None:
    """Of two accounts of the same run's sweep, the one to keep: SIDS carries the sweep's own
    parameters, so it wins over the ``SID_*`` parameters seen so far."""
    if new is not None and (current is None or new.source == "SIDS"):
        return new
    return current


class SystemIdWatch:
    """One vehicle's SystemID starts and ends (feed it that vehicle's frames only)."""

    def __init__(self):
        self._modes: dict = {}          # topic -> last flight mode

    def feed(self, topic: str, data: dict, vehicle: VehicleInfo) -> SystemIdEvent | None:
        """The start or end ``data`` (a frame of ``topic``) says, with the sweep from ``vehicle``'s
        parameters (or the SIDS record itself); None when it says neither."""
        if topic in ("/mavlink/STATUSTEXT", "/dataflash/MSG"):
            text = str(data.get("text", data.get("Message", "")))
            if m := _START.search(text):
                axis = int(m.group(1))
                return SystemIdEvent("start", axis, vehicle.injection(axis), text)
            if _FINISHED.search(text):
                return SystemIdEvent("end", None, None, text)
            return None
        if topic == "/dataflash/SIDS":
            ax = data.get("Ax")
            if not isinstance(ax, (int, float)):
                return None
            axis = int(ax)
            return SystemIdEvent("start", axis, vehicle.injection(axis, sids=data), f"SIDS axis {axis}")
        if topic == "/mavlink/HEARTBEAT":
            if data.get("autopilot") != ARDUPILOT_AUTOPILOT or data.get("type") not in MULTIROTOR_TYPES:
                return None
            mode = data.get("custom_mode")
        elif topic == "/dataflash/MODE":
            mode = data.get("Mode")
        else:
            return None
        before, self._modes[topic] = self._modes.get(topic), mode
        if before == ARDUPILOT_SYSTEMID_MODE and mode != ARDUPILOT_SYSTEMID_MODE:
            return SystemIdEvent("end", None, None, f"mode {before} -> {mode}")
        if before is not None and before != ARDUPILOT_SYSTEMID_MODE and mode == ARDUPILOT_SYSTEMID_MODE:
            axis = vehicle.parameters.get("SID_AXIS")
            axis = None if axis is None else int(round(axis))
            return SystemIdEvent("start", axis, None if axis is None else vehicle.injection(axis),
                                 f"mode {before} -> {mode} (SYSTEMID)")
        return None
