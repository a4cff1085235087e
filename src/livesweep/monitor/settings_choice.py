"""Which settings a monitor session runs with: a recording's own, a channel map's with the
command's defaults, and options (window, pairs, actuator limits, ...) in place of theirs.

What :func:`livesweep.replay`, :func:`livesweep.monitor` and the ``monitor`` and ``replay``
commands choose; :mod:`livesweep.monitor.session` re-exports each name.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from livesweep.errors import ConfigError

__all__ = ["DEFAULT_MAP", "recorded_settings", "map_settings", "with_options", "replay_settings"]

#: The channel map ``livesweep monitor`` and ``replay`` use when neither a case nor a map is given.
DEFAULT_MAP = Path(__file__).resolve().parents[1] / "data" / "xv15_channels.toml"


def recorded_settings(path):
    """The monitor settings a recording was made with (its ``livesweep_settings.json``), or None.

    Raises
    ------
    ConfigError
        One line naming the file and key when the attachment is not JSON or asks for what a map
        could not (:meth:`MonitorSettings.from_dict`).
    """
    from livesweep.monitor.pipeline import MonitorSettings
    from livesweep.telemetry.mcap_log import read_attachments

    raw = read_attachments(path).get("livesweep_settings.json")
    if raw is None:
        return None
    try:
        d = json.loads(raw)
    except ValueError as e:
        raise ConfigError(f"{path}: livesweep_settings.json is not JSON ({e}); give --case or --map") from None
    return MonitorSettings.from_dict(d, where=f"{path}: livesweep_settings.json", path=path)


def map_settings(case=None, map=None, *, window_s=None, update_period_s=None, system=None, required_pairs=None,
                 saturation_limits=None, names=None):
    """Monitor settings from a channel map: ``map`` (a preset name or map file), else ``case`` (a
    case file or map file with ``[signals]`` and ``[spectral]``), else the packaged XV-15 map,
    with the command's defaults (``livesweep monitor --map NAME`` with no other option) where an
    option is not given.

    Parameters
    ----------
    case, map : str or os.PathLike, optional
        One of the two (a map also by its preset's name, ``livesweep maps``).
    window_s, update_period_s, system, required_pairs, saturation_limits, names
        As :func:`with_options`; None keeps the default (a 120 s window, updates every 0.2 s of
        data, the map's ``sysid``, the on-axis pairs, no actuator limits).

    Raises
    ------
    ConfigError
        Both given; a map without a ``[spectral]`` table; anything the map's reader refuses; an
        option that does not fit the map or the monitor's limits.
    """
    from livesweep.config import read_channel_map
    from livesweep.maps import load_map
    from livesweep.monitor.pipeline import MonitorSettings
    from livesweep.spectral import DEFAULT_WINDOW_S

    if map and case:
        raise ConfigError(f"give --case or --map, not both (--case {str(case)!r}, --map {str(map)!r})")
    chosen = load_map(map) if map else read_channel_map(case or DEFAULT_MAP, one_clock=False)
    spectral, where = chosen.spectral, chosen.path
    if spectral is None:
        raise ConfigError(f"{where}: the monitor needs a [spectral] table (inputs, outputs, band_rad_s, sample_rate_hz)")
    settings = MonitorSettings(
        signals=chosen.signals, inputs=tuple(spectral.inputs), outputs=tuple(spectral.outputs),
        band_rad_s=tuple(spectral.band_rad_s), sample_rate_hz=spectral.sample_rate_hz, window_s=DEFAULT_WINDOW_S,
        update_period_s=0.2, required_pairs=None, saturation_limits=None,
        references=tuple(spectral.references) if spectral.references else None,
        test_points=chosen.test_points, map_name=chosen.name, vehicle=dict(chosen.vehicle) or None,
        system=chosen.system, criteria=chosen.criteria, models=chosen.models,
    )
    return with_options(settings, str(where), window_s=window_s, update_period_s=update_period_s, system=system,
                        required_pairs=required_pairs, saturation_limits=saturation_limits,
                        names={**(names or {}), "outputs": f"{where}: spectral.outputs"})


def with_options(settings, where: str = "settings", *, window_s=None, update_period_s=None, system=None,
                 required_pairs=None, saturation_limits=None, names=None):
    """``settings`` with each option given in place of its own, checked against the monitor's
    limits (:meth:`MonitorSettings.check_limits`): what ``--window``, ``--update-period``,
    ``--sysid``, ``--require`` and ``--saturation`` do to a map's or a recording's settings.

    Parameters
    ----------
    settings : MonitorSettings
    where : str
        What a message names first: the file the settings came from.
    window_s : float, optional
        Sliding window [s].
    update_period_s : float, optional
        Estimate every this much data time [s].
    system : int or (int, int or None), optional
        The MAVLink system (and component) to analyse.
    required_pairs : iterable of str or (str, str), optional
        The pairs a test point must excite for a GO, as ``"OUT/IN"`` (``"p/da"``) or
        ``(output, input)``.
    saturation_limits : dict of str -> (float, float), or iterable of str, optional
        Actuator limits for the saturation alert [input units]: ``{"da": (-20, 20)}`` or
        ``["da=-20:20"]``.
    names : dict of str -> str, optional
        How messages call an option instead of its keyword, e.g. ``{"window_s": "--window",
        "required_pairs": "--require"}``.

    Returns
    -------
    MonitorSettings

    Raises
    ------
    ConfigError
        One line naming the option and value: a pair or input the settings do not have, limits
        whose low end is not below the high end, a value beyond the monitor's limits.
    """
    from dataclasses import replace

    names = names or {}
    if isinstance(system, int) and not isinstance(system, bool):
        system = (system, None)
    changed = {key: value for key, value in (("window_s", window_s), ("update_period_s", update_period_s),
                                             ("system", system)) if value is not None}
    if required_pairs:
        changed["required_pairs"] = _required(required_pairs, settings, names.get("required_pairs", "required_pairs"))
    if saturation_limits:
        changed["saturation_limits"] = _saturation(saturation_limits, settings,
                                                   names.get("saturation_limits", "saturation_limits"))
    return (replace(settings, **changed) if changed else settings).check_limits(where, names=names)


def _required(items, settings, label: str) -> tuple:
    """``(output, input)`` pairs of ``"OUT/IN"`` texts or pairs; one line naming an item that is
    not a pair of the settings."""
    pairs = []
    for item in [items] if isinstance(items, str) else items:
        if isinstance(item, str):
            out, sep, inp = item.partition("/")
        else:
            out, inp = _two(item)
            sep = "/" if out is not None else ""
        if not sep or out not in settings.outputs or inp not in settings.inputs:
            raise ConfigError(f"{label} {item!r}: give OUTPUT/INPUT with an output of {list(settings.outputs)} "
                              f"and an input of {list(settings.inputs)}")
        pairs.append((out, inp))
    return tuple(pairs)


def _saturation(items, settings, label: str) -> dict:
    """Input -> (low, high) [input units] of ``"IN=LOW:HIGH"`` texts or a dict; one line naming an
    item that is not an input of the settings with low < high."""
    limits = {}
    for item in list(items.items()) if isinstance(items, dict) else [items] if isinstance(items, str) else items:
        if isinstance(item, str):
            name, sep, rng = item.partition("=")
            lo, sep2, hi = rng.partition(":")
            ok = bool(sep and sep2)
        else:
            name, bounds = _two(item)
            lo, hi = _two(bounds)
            ok = name is not None and lo is not None
        try:
            lo_f, hi_f = float(lo), float(hi)
        except (TypeError, ValueError):
            lo_f = hi_f = math.nan
        if not ok or name not in settings.inputs or not (lo_f < hi_f):
            raise ConfigError(f"{label} {item!r}: give INPUT=LOW:HIGH in input units with an input of "
                              f"{list(settings.inputs)}, e.g. da=-20:20")
        limits[name] = (lo_f, hi_f)
    return limits


def _two(item) -> tuple:
    """``item`` as two values, or ``(None, None)`` when it is not a pair."""
    try:
        a, b = item
    except (TypeError, ValueError):
        return None, None
    return a, b


def replay_settings(path, case=None, map=None, *, settings=None):
    """``(settings, source)`` as :func:`livesweep.replay` chooses them: ``settings`` when given,
    else the recording's own unless ``case`` or ``map`` is given, else the map
    (:func:`map_settings`); ``source`` is :attr:`livesweep.ReplayResult.settings_source`."""
    if settings is not None:
        if case or map:
            raise ConfigError("give settings, or a case or map, not both")
        return settings.check_limits("settings"), "settings"
    if not case and not map:
        saved = recorded_settings(path)
        if saved is not None:
            return saved, "recording"
    return map_settings(case, map), "map" if map else "case" if case else "default"
