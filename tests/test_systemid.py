"""SystemID runs from what ArduCopter sends: one parser for the live tracker and ``inspect``.

References the code did not make: ArduCopter's own texts and mode numbers (mode_systemid.cpp:
"SystemID Starting: axis=%d", "SystemID Finished", SYSTEMID = 25) and the SID_* parameters as a
ground station downloads them.
"""

from __future__ import annotations

import math

from livesweep.monitor.systemid import SystemIdWatch, better_injection
from livesweep.monitor.vehicle import VehicleInfo
from livesweep.spectral.injection import ardupilot_chirp
from livesweep.telemetry.frames import Frame

PARAMS = {"SID_AXIS": 8, "SID_F_START_HZ": 0.5, "SID_F_STOP_HZ": 12.0, "SID_T_REC": 40.0, "SID_MAGNITUDE": 15.0}


def _vehicle() -> VehicleInfo:
    v = VehicleInfo()
    for name, value in PARAMS.items():
        v.take(Frame("/mavlink/PARAM_VALUE", 0, None, {"param_id": name, "param_value": value}))
    return v


def _heartbeat(mode: int) -> dict:
    return {"type": 2, "autopilot": 3, "custom_mode": mode}


def test_a_mode_change_into_and_out_of_systemid_starts_and_ends_a_run_on_the_sid_axis():
    """A pilot who switches to SYSTEMID and back (no texts): a run on SID_AXIS with the sweep its
    parameters set, ended by leaving the mode; heartbeats that keep the mode say nothing."""
    v, watch = _vehicle(), SystemIdWatch()
    events = [watch.feed("/mavlink/HEARTBEAT", _heartbeat(m), v) for m in (5, 5, 25, 25, 5)]
    assert events[0] is None and events[1] is None and events[3] is None
    start, end = events[2], events[4]
    assert (start.action, start.axis, end.action) == ("start", 8, "end")
    assert start.injection.band_rad_s == (math.pi, 24 * math.pi) and start.injection.magnitude == 15.0
    assert end.note == "mode 25 -> 5"
    # a ground station's heartbeat (MAV_AUTOPILOT_INVALID) is no mode change
    assert watch.feed("/mavlink/HEARTBEAT", {"type": 6, "autopilot": 8, "custom_mode": 25}, v) is None


def test_texts_and_sids_say_the_same_run_and_sids_carries_the_sweep():
    v, watch = _vehicle(), SystemIdWatch()
    text = watch.feed("/dataflash/MSG", {"Message": "SystemID Starting: axis=7"}, v)
    sids = watch.feed("/dataflash/SIDS", {"Ax": 7, "FSt": 0.5, "FSp": 6.0, "TR": 30.0, "Mag": 10.0}, v)
    assert (text.axis, sids.axis) == (7, 7)
    assert text.injection.source == "SID_* parameters" and sids.injection.source == "SIDS"
    kept = better_injection(text.injection, sids.injection)
    assert kept is sids.injection and kept.band_rad_s == (math.pi, 12 * math.pi)
    assert better_injection(sids.injection, text.injection) is sids.injection
    assert watch.feed("/mavlink/STATUSTEXT", {"text": "SystemID Finished"}, v).action == "end"
    assert watch.feed("/mavlink/STATUSTEXT", {"text": "PreArm: Gyros not calibrated"}, v) is None
    assert ardupilot_chirp(0.5, 6.0, 30.0).band_rad_s == kept.band_rad_s
