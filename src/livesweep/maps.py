"""Named channel maps shipped with livesweep: real vehicles' telemetry and logs, ready to monitor.

A preset is a channel map (``[signals]``, ``[spectral]``) with a ``[map]`` table (``name``,
``description``, ``needs``: what telemetry, rates and parameters it needs) and a
``[test_points]`` table, in ``livesweep/data/maps/<name>.toml``; its comments say where every
field, sign and motor mix comes from. ``livesweep maps`` lists them; ``livesweep monitor --map
NAME`` and ``livesweep replay LOG --map NAME`` use one (or a map file given by its path).

The presets: ``ardupilot-copter-quad-plus``, ``ardupilot-copter-quad-x``,
``ardupilot-copter-hexa-x`` (ArduCopter motor-PWM mixes -> ATTITUDE rates and angles over
MAVLink), ``ardupilot-copter-pid`` (PID_TUNING demanded -> achieved rates), ``ardupilot-plane``
(servo PWMs -> ATTITUDE), ``ardupilot-sysid-dataflash`` (converted SystemID DataFlash logs, RATE
and SIDD at 400 Hz), ``px4-multicopter`` (ACTUATOR_CONTROL_TARGET -> ATTITUDE over MAVLink) and
``px4-ulog-multicopter`` (converted ULog).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from livesweep.config import ChannelMap, TestPointSettings, read_channel_map
from livesweep.errors import ConfigError

__all__ = ["MapInfo", "ChannelMap", "TestPointSettings", "PRESET_DIR", "preset_names", "list_maps", "load_map",
           "presets_for", "vehicle_fits"]

#: Where the presets live (package data).
PRESET_DIR = Path(__file__).resolve().parent / "data" / "maps"


@dataclass(frozen=True)
class MapInfo:
    """What ``livesweep maps`` lists about a preset.

    Attributes
    ----------
    name, description, needs : str
        From its ``[map]`` table.
    inputs, outputs : tuple of str
        Its ``[spectral]`` inputs and outputs.
    path : pathlib.Path
        The preset file.
    """

    name: str
    description: str
    needs: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    path: Path


def preset_names() -> list[str]:
    """The names of the shipped presets, sorted."""
    return sorted(p.stem for p in PRESET_DIR.glob("*.toml"))


def list_maps() -> list[MapInfo]:
    """Every shipped preset, loaded and validated, sorted by name."""
    out = []
    for name in preset_names():
        m = load_map(name)
        sp = m.spectral
        out.append(MapInfo(name=m.name, description=m.description, needs=m.needs,
                           inputs=tuple(sp.inputs) if sp else (), outputs=tuple(sp.outputs) if sp else (),
                           path=m.path))
    return out


def _is_path(text: str) -> bool:
    return os.sep in text or "/" in text or text.endswith(".toml")


def load_map(name_or_path: str | os.PathLike[str]) -> ChannelMap:
    """A preset by name, or a channel-map file by path.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        A preset name (``livesweep maps`` lists them), or a TOML file: a path object, or text with
        a directory separator or ending in ``.toml``.

    Returns
    -------
    ChannelMap
        ``signals``, ``spectral``, ``test_points``, ``name``, ``description``, ``needs``, ``path``.

    Raises
    ------
    ConfigError
        An unknown preset name (the presets are listed); anything
        :func:`livesweep.config.read_channel_map` refuses in the file (naming file, key and
        value); a preset whose ``[map].name`` is not its file name.
    """
    if isinstance(name_or_path, os.PathLike) or _is_path(str(name_or_path)):
        return read_channel_map(name_or_path)
    name = str(name_or_path)
    names = preset_names()
    if name not in names:
        raise ConfigError(f"--map {name!r}: no such preset (presets: {', '.join(names)}); "
                          "give a preset name or a map file (a path ending in .toml)")
    m = read_channel_map(PRESET_DIR / f"{name}.toml")
    if m.name != name:
        raise ConfigError(f"{m.path}: map.name: a preset's name must be its file name {name!r}, got {m.name!r}")
    return m


def vehicle_fits(vehicle: dict, have: dict) -> bool:
    """Whether a map's ``[map.vehicle]`` (name -> allowed values) agrees with what a vehicle is known
    to have (name -> value); a name the vehicle has not said is no contradiction."""
    return all(k not in have or any(abs(float(have[k]) - float(a)) < 1e-6 for a in allowed)
               for k, allowed in vehicle.items())


def presets_for(frame_class: int | None, frame_type: int | None, mav_type: int | None = None) -> list[str]:
    """The presets made for a vehicle's frame (``FRAME_CLASS``, ``FRAME_TYPE``) and HEARTBEAT type:
    those whose ``[map.vehicle]`` names the frame and agrees with it, sorted by name."""
    have = {k: v for k, v in (("FRAME_CLASS", frame_class), ("FRAME_TYPE", frame_type), ("MAV_TYPE", mav_type))
            if v is not None}
    if "FRAME_CLASS" not in have:
        return []
    out = []
    for name in preset_names():
        m = load_map(name)
        if "FRAME_CLASS" in m.vehicle and vehicle_fits(m.vehicle, have):
            out.append(name)
    return out
