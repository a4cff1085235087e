"""What the vehicle says about itself: its parameters, its frame and the sweeps it is told to fly.

An ArduPilot vehicle sends its parameters as MAVLink PARAM_VALUE (every one when a ground station
connects, and each again when it is set) and logs them as DataFlash PARM; it says its frame in a
"Frame: QUAD/PLUS" text and its type in every HEARTBEAT; and each SystemID run is defined by its
``SID_*`` parameters (in a DataFlash log also by the SIDS record written at the start).
:class:`VehicleInfo` keeps what the analysed vehicle said, so that

* a test point the autopilot opens knows the sweep it was told to inject
  (:meth:`VehicleInfo.injection`, :mod:`livesweep.spectral.injection`): the judged band is the
  band the autopilot was told to sweep;
* a channel map made for one airframe (its ``[map.vehicle]`` table: ``FRAME_CLASS``,
  ``FRAME_TYPE``, ``MAV_TYPE``) can say at once that the vehicle is another one
  (:meth:`VehicleInfo.contradiction`).

Everything depends on the frames alone, so a replay learns the same things at the same frames.
"""

from __future__ import annotations

import math
import re

from livesweep.errors import ConfigError
from livesweep.spectral.injection import SweepInjection, ardupilot_chirp
from livesweep.telemetry.frames import Frame

__all__ = ["VehicleInfo", "ARDUPILOT_AUTOPILOT", "MULTIROTOR_TYPES", "FRAME_CLASS_MAV_TYPES",
           "frame_of_text", "AXIS_NAMES", "FRAME_CLASSES", "FRAME_TYPES", "axis_name", "frame_name", "TOPICS"]

#: ArduCopter SystemID axes (``SID_AXIS``, mode_systemid.h ``AxisType``).
AXIS_NAMES = {1: "input roll (angle)", 2: "input pitch (angle)", 3: "input yaw (rate)", 4: "recovery roll",
              5: "recovery pitch", 6: "recovery yaw", 7: "rate roll", 8: "rate pitch", 9: "rate yaw",
              10: "mixer roll", 11: "mixer pitch", 12: "mixer yaw", 13: "mixer thrust"}
#: ArduPilot ``FRAME_CLASS`` and ``FRAME_TYPE`` values and the names its "Frame: CLASS/TYPE" text gives them
#: (AP_Motors ``motor_frame_class``, ``motor_frame_type``).
FRAME_CLASSES = {1: "QUAD", 2: "HEXA", 3: "OCTA", 4: "OCTAQUAD", 5: "Y6", 6: "HELI", 7: "TRI", 8: "SINGLE",
                 9: "COAX", 10: "BICOPTER", 11: "HELI_DUAL", 12: "DODECAHEXA", 13: "HELI_QUAD", 14: "DECA"}
FRAME_TYPES = {0: "PLUS", 1: "X", 2: "V", 3: "H", 4: "V_TAIL", 5: "A_TAIL", 10: "Y6B", 11: "Y6F", 12: "BF_X",
               13: "DJI_X", 14: "CW_X", 15: "I", 16: "NYT_PLUS", 17: "NYT_X", 18: "BF_X_REV", 19: "Y4"}
#: The topics a :class:`VehicleInfo` reads.
TOPICS = ("/mavlink/PARAM_VALUE", "/dataflash/PARM", "/dataflash/SIDS", "/mavlink/STATUSTEXT", "/dataflash/MSG",
          "/mavlink/HEARTBEAT")

#: ArduCopter's frame class as its "Frame: CLASS/TYPE" text names it -> the HEARTBEAT's MAV_TYPE
#: (GCS_Copter::frame_type).
FRAME_CLASS_MAV_TYPES = {"QUAD": 2, "HEXA": 13, "Y6": 13, "OCTA": 14, "OCTAQUAD": 14, "TRI": 15, "HELI": 4,
                         "HELI_DUAL": 4, "HELI_QUAD": 4, "SINGLE": 3, "COAX": 3, "DODECAHEXA": 29, "DECA": 35}
#: MAV_TYPE of the multirotors whose frame FRAME_CLASS / FRAME_TYPE name.
MULTIROTOR_TYPES = frozenset(FRAME_CLASS_MAV_TYPES.values())
_FRAME_TEXT = re.compile(r"^Frame:\s*([A-Z0-9_]+)(?:/([A-Z0-9_]+))?")


_CLASS_OF_NAME = {v: k for k, v in FRAME_CLASSES.items()}
_TYPE_OF_NAME = {v: k for k, v in FRAME_TYPES.items()}


def frame_of_text(text: str) -> tuple[str, str | None] | None:
    """ArduPilot's "Frame: QUAD/PLUS" text -> ``("QUAD", "PLUS")``; None for any other text."""
    m = _FRAME_TEXT.match(str(text).strip())
    return (m.group(1), m.group(2)) if m else None
#: HEARTBEAT ``autopilot`` of ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA).
ARDUPILOT_AUTOPILOT = 3
_GCS_AUTOPILOT = 8                      # MAV_AUTOPILOT_INVALID: a ground station's heartbeat


def axis_name(axis: int | None) -> str:
    """``"axis 7 (rate roll)"``."""
    if axis is None:
        return "axis ?"
    name = AXIS_NAMES.get(int(axis))
    return f"axis {axis} ({name})" if name else f"axis {axis}"


def frame_name(frame_class: int | None, frame_type: int | None) -> str:
    """``"QUAD/PLUS (FRAME_CLASS 1, FRAME_TYPE 0)"`` (the parts the vehicle said)."""
    c = FRAME_CLASSES.get(frame_class, "?") if frame_class is not None else "?"
    t = FRAME_TYPES.get(frame_type, "?") if frame_type is not None else "?"
    said = ", ".join(f"{k} {v}" for k, v in (("FRAME_CLASS", frame_class), ("FRAME_TYPE", frame_type)) if v is not None)
    return f"{c}/{t} ({said})"


class VehicleInfo:
    """Parameters, frame and heartbeat type of the analysed vehicle, from its frames.

    Attributes
    ----------
    parameters : dict of str -> float
        The latest value of every parameter seen (PARAM_VALUE, PARM).
    frame_text : (str, str) or None
        Class and type names of the last "Frame: CLASS/TYPE" text.
    mav_type : int or None
        The autopilot's HEARTBEAT ``type``.
    sids : dict or None
        The last DataFlash SIDS record (the parameters of the last SystemID start).
    """

    def __init__(self) -> None:
        self.parameters: dict[str, float] = {}
        self.frame_text: tuple[str, str | None] | None = None
        self.mav_type: int | None = None
        self.sids: dict | None = None

    @staticmethod
    def wants(topic: str) -> bool:
        """Whether frames of ``topic`` tell something about the vehicle."""
        return topic in TOPICS

    def take(self, frame: Frame) -> None:
        """Learn from one frame of the analysed vehicle (other topics are ignored)."""
        d, topic = frame.data, frame.topic
        if not isinstance(d, dict):
            return
        if topic == "/mavlink/PARAM_VALUE":
            self._param(d.get("param_id"), d.get("param_value"))
        elif topic == "/dataflash/PARM":
            self._param(d.get("Name"), d.get("Value"))
        elif topic == "/dataflash/SIDS":
            self.sids = dict(d)
        elif topic in ("/mavlink/STATUSTEXT", "/dataflash/MSG"):
            frame = frame_of_text(d.get("text", d.get("Message", "")))
            if frame is not None:
                self.frame_text = frame
        elif topic == "/mavlink/HEARTBEAT":
            if d.get("autopilot") not in (None, _GCS_AUTOPILOT) and isinstance(d.get("type"), int):
                self.mav_type = d["type"]

    def _param(self, name, value) -> None:
        if not isinstance(name, str) or isinstance(value, bool) or not isinstance(value, (int, float)):
            return
        name = name.strip("\x00 ")
        if name and math.isfinite(value):
            self.parameters[name] = float(value)

    # -- the sweep -------------------------------------------------------------------------------
    def injection(self, axis: int | None, *, sids: dict | None = None) -> SweepInjection | None:
        """The chirp ArduCopter injects for a SystemID start on ``axis``: from a SIDS record when
        given (it carries every parameter), else from the ``SID_*`` parameters seen so far; None
        when they are not known (a monitor that joined after the ground station fetched them) or
        define no sweep."""
        if sids is not None:
            try:
                return ardupilot_chirp(sids.get("FSt"), sids.get("FSp"), sids.get("TR"),
                                       t_fade_in_s=sids.get("TFin", 0.0) or 0.0,
                                       t_fade_out_s=sids.get("TFout", 0.0) or 0.0, t_const_s=sids.get("TC"),
                                       magnitude=sids.get("Mag", 1.0) or 1.0, axis=axis, source="SIDS")
            except (ConfigError, TypeError, ValueError):
                return None
        p = self.parameters
        need = ("SID_F_START_HZ", "SID_F_STOP_HZ", "SID_T_REC")
        if not all(k in p for k in need):
            return None
        try:
            return ardupilot_chirp(p["SID_F_START_HZ"], p["SID_F_STOP_HZ"], p["SID_T_REC"],
                                   t_fade_in_s=p.get("SID_T_FADE_IN", 0.0), t_fade_out_s=p.get("SID_T_FADE_OUT", 0.0),
                                   magnitude=p.get("SID_MAGNITUDE", 1.0), axis=axis, source="SID_* parameters")
        except ConfigError:
            return None

    # -- the airframe ----------------------------------------------------------------------------
    def frame(self) -> tuple[int | None, int | None]:
        """(FRAME_CLASS, FRAME_TYPE): the parameters, else what the "Frame:" text names."""
        c, t = self.parameters.get("FRAME_CLASS"), self.parameters.get("FRAME_TYPE")
        c = None if c is None else int(round(c))
        t = None if t is None else int(round(t))
        if self.frame_text is not None:
            c = _CLASS_OF_NAME.get(self.frame_text[0], c) if c is None else c
            t = _TYPE_OF_NAME.get(self.frame_text[1], t) if t is None and self.frame_text[1] else t
        return c, t

    def known(self, names) -> dict:
        """What the vehicle has said of ``names`` (name -> value): its parameters, with
        ``FRAME_CLASS`` and ``FRAME_TYPE`` also from its "Frame:" text and ``MAV_TYPE`` from its
        HEARTBEAT; a name it has not said is left out."""
        c, t = self.frame()
        said = {"FRAME_CLASS": c, "FRAME_TYPE": t, "MAV_TYPE": self.mav_type}
        out = {}
        for n in names:
            v = said.get(n)
            v = self.parameters.get(n) if v is None else v
            if v is not None:
                out[n] = float(v)
        return out

    def contradiction(self, expected: dict) -> str | None:
        """Why a map made for ``expected`` (parameter -> value or values; ``MAV_TYPE`` for the
        heartbeat type) does not fit this vehicle, or None while nothing said contradicts it."""
        from livesweep.maps import vehicle_fits

        if not expected:
            return None
        have = self.known(expected)
        if vehicle_fits(expected, have):
            return None
        wrong = []
        for name, want in expected.items():
            allowed = want if isinstance(want, (list, tuple)) else (want,)
            if name in have and not vehicle_fits({name: tuple(allowed)}, have):
                shown = " or ".join(f"{float(a):g}" for a in allowed)
                wrong.append(f"{name} {have[name]:g} (the map is for {shown})")
        copter = self.mav_type is None or self.mav_type in MULTIROTOR_TYPES
        c, t = self.frame()
        said = f"the vehicle is {frame_name(c, t)}" if c is not None and copter else "the vehicle says"
        return f"{said}: {', '.join(wrong)}"
