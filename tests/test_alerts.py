"""Alerts an operator reads, and what the vehicle says of itself.

References: counts of alerts written here by hand; ArduPilot's frame parameters and names
(AP_Motors: FRAME_CLASS 1 quad, 2 hexa; FRAME_TYPE 0 plus, 1 X) and the presets' own files.
"""

from __future__ import annotations

import pytest

from livesweep.maps import load_map, presets_for, vehicle_fits
from livesweep.monitor.alerts import ALERT_INTERVAL_S, AlertGate
from livesweep.monitor.vehicle import VehicleInfo, axis_name
from livesweep.spectral.excitation import Alert
from livesweep.telemetry.frames import Frame


def test_one_alert_per_subject_per_interval_and_the_held_back_ones_counted():
    gate = AlertGate()
    said = []
    for k in range(50):                                # five estimates a second for 10 s
        t = 100.0 + 0.2 * k
        for a in (Alert("coherence_collapse", f"p/da: median coherence fell by 0.{30 + k % 9}", 0.3),
                  Alert("coherence_collapse", "r/dr: median coherence fell by 0.5", 0.5),
                  Alert("packet_loss", f"{k + 1} telemetry packet(s) lost since the last update", 1.0)):
            if (out := gate.admit(t, a)) is not None:
                said.append((t, out.message))
    # each subject once at the start, then once more when the interval has passed, with the count
    assert [m.split(":")[0] for _, m in said[:3]] == ["p/da", "r/dr", "1 telemetry packet(s) lost since the last update"]
    assert len(said) == 3 + 3 * int((50 * 0.2 - 1e-9) // ALERT_INTERVAL_S)
    assert gate.held_back == 3 * 50 - len(said)
    assert all(m.endswith(f"({int(ALERT_INTERVAL_S / 0.2) - 1} more in the last 10 s)") for _, m in said[3:])
    assert gate.admit(None, Alert("map", "signal p: no frames", 1.0)) is not None     # before any data: said


def test_the_vehicle_s_parameters_and_texts_tell_its_frame_and_which_presets_fit():
    v = VehicleInfo()
    for name, value in (("FRAME_CLASS", 1.0), ("FRAME_TYPE", 0.0)):
        v.take(Frame("/mavlink/PARAM_VALUE", 0, None, {"sysid": 1, "param_id": name, "param_value": value}))
    v.take(Frame("/mavlink/HEARTBEAT", 0, None, {"sysid": 1, "type": 2, "autopilot": 3}))
    assert v.frame() == (1, 0)
    quad_x, quad_plus = load_map("ardupilot-copter-quad-x"), load_map("ardupilot-copter-quad-plus")
    assert v.contradiction(quad_plus.vehicle) is None
    why = v.contradiction(quad_x.vehicle)
    assert why == "the vehicle is QUAD/PLUS (FRAME_CLASS 1, FRAME_TYPE 0): FRAME_TYPE 0 (the map is for 1)"
    assert presets_for(1, 0, 2) == ["ardupilot-copter-quad-plus"]
    assert presets_for(1, 1) == ["ardupilot-copter-quad-x"] and presets_for(2, 1, 13) == ["ardupilot-copter-hexa-x"]
    # the "Frame: QUAD/X" text says it without the parameters
    w = VehicleInfo()
    w.take(Frame("/mavlink/STATUSTEXT", 0, None, {"text": "Frame: QUAD/X"}))
    assert w.frame() == (1, 1) and w.contradiction(quad_x.vehicle) is None
    assert vehicle_fits({"MAV_TYPE": (2.0,)}, {}) and not vehicle_fits({"MAV_TYPE": (2.0,)}, {"MAV_TYPE": 13.0})
    assert axis_name(7) == "axis 7 (rate roll)" and axis_name(42) == "axis 42"


def test_a_ground_station_s_heartbeat_is_not_the_vehicle_s():
    v = VehicleInfo()
    v.take(Frame("/mavlink/HEARTBEAT", 0, None, {"sysid": 255, "type": 6, "autopilot": 8}))
    assert v.mav_type is None


@pytest.mark.parametrize("bad", [{"param_id": "SID_F_STOP_HZ", "param_value": "x"},
                                 {"param_id": 5, "param_value": 1.0},
                                 {"param_id": "SID_F_STOP_HZ", "param_value": float("nan")}, "not a dict"])
def test_malformed_parameters_are_ignored(bad):
    v = VehicleInfo()
    v.take(Frame("/mavlink/PARAM_VALUE", 0, None, bad))
    assert v.parameters == {} and v.injection(7) is None
