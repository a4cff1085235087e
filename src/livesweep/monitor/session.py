"""The monitor over a recording, as a library call: what ``livesweep replay`` runs.

:func:`replay` runs an MCAP log through the live monitor's pipeline
(:class:`~livesweep.monitor.pipeline.MonitorPipeline`: aligner, sliding-window estimator, test
points, verdicts, alerts) and returns a frozen :class:`ReplayResult` with what the live run
would have recorded on its ``/livesweep/test_point``, ``/livesweep/verdict`` and
``/livesweep/alert`` channels, as those channels carry it (the same JSON: non-finite numbers as
``"NaN"``, tuples as lists), and the counters the command prints. Headless by default: no Rerun,
no terminal output (the map's warnings go to :mod:`logging`, ``livesweep.monitor.pipeline``).

    >>> import livesweep
    >>> r = livesweep.replay("flight.mcap")                        # doctest: +SKIP
    >>> [(tp["swept_input"], tp["verdict"]) for tp in r.test_points]  # doctest: +SKIP
    [('da', 'GO')]

The settings are the ones the recording carries (the monitor attaches them as
``livesweep_settings.json``; the demo's ``live.mcap`` has them), else the channel map or case
given, else the packaged XV-15 map: as ``livesweep replay`` chooses them.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from livesweep.errors import ConfigError

__all__ = ["ReplayResult", "replay", "replay_settings", "recorded_settings", "map_settings"]

#: The channel map ``livesweep monitor`` and ``replay`` use when neither a case nor a map is given.
DEFAULT_MAP = Path(__file__).resolve().parents[1] / "data" / "xv15_channels.toml"
#: The channels a :class:`ReplayResult` keeps, by the ``/livesweep/<name>`` name.
KEPT = ("test_point", "verdict", "alert", "link")


@dataclass(frozen=True)
class ReplayResult:
    """What a replay of one log gave.

    Attributes
    ----------
    path : Path
        The log replayed.
    settings : MonitorSettings
        The settings it ran with.
    settings_source : str
        Where they came from: ``"recording"`` (the log's ``livesweep_settings.json``), ``"case"``,
        ``"map"``, ``"default"`` (the packaged XV-15 map) or ``"settings"`` (given).
    test_points : tuple of dict
        Every closed test point, in order, as ``/livesweep/test_point`` carries it (``source``,
        ``swept_input``, ``start_s``, ``end_s``, ``verdict``, ``label``, ``pairs``, ``reasons``, ...).
    verdicts : tuple of dict
        Every change of the operator's verdict, as ``/livesweep/verdict`` carries it (``t_s``,
        ``verdict``, ``previous``, ``reasons``, ``test_point``).
    alerts : tuple of dict
        Every alert raised, as ``/livesweep/alert`` carries it (``t_s``, ``kind``, ``message``,
        ``value``).
    counters : dict
        The final counters the command's summary prints: ``sources`` (per source), ``aligner``
        (repairs and gaps) and ``pipeline``.
    link : dict or None
        The last ``/livesweep/link`` record (the counters as recorded at the end).
    summary : dict
        Everything :meth:`MonitorPipeline.run` returned (frames, estimates, ``data_s``,
        ``wall_s``, ``verdict``, ``reasons``, ``map_problems``, ...): what ``livesweep replay`` prints.
    recording : Path or None
        The MCAP the replay recorded (``record=``), else None.
    """

    path: Path
    settings: object
    settings_source: str
    test_points: tuple
    verdicts: tuple
    alerts: tuple
    counters: dict
    link: dict | None
    summary: dict
    recording: Path | None = None

    @property
    def verdict(self) -> str | None:
        """The operator's verdict at the end (``"GO"``, ``"NO-GO"``, ``"WAIT"``), None before any."""
        return self.summary.get("verdict")


def _as_recorded(payload: dict) -> dict:
    """``payload`` as the recording's JSON channel carries it (what a reader decodes)."""
    try:
        text = json.dumps(payload, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError):
        from livesweep.numeric import json_safe

        text = json.dumps(json_safe(payload)[0], separators=(",", ":"), allow_nan=False)
    return json.loads(text)


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


def map_settings(case=None, map=None):
    """Monitor settings from a channel map: ``map`` (a preset name or map file), else ``case`` (a
    case file or map file with ``[signals]`` and ``[spectral]``), else the packaged XV-15 map,
    with the command's defaults (``livesweep monitor --map NAME`` with no other option).

    Raises
    ------
    ConfigError
        Both given; a map without a ``[spectral]`` table; anything the map's reader refuses.
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
    return MonitorSettings(
        signals=chosen.signals, inputs=tuple(spectral.inputs), outputs=tuple(spectral.outputs),
        band_rad_s=tuple(spectral.band_rad_s), sample_rate_hz=spectral.sample_rate_hz, window_s=DEFAULT_WINDOW_S,
        update_period_s=0.2, required_pairs=None, saturation_limits=None,
        references=tuple(spectral.references) if spectral.references else None,
        test_points=chosen.test_points, map_name=chosen.name, vehicle=dict(chosen.vehicle) or None,
        system=chosen.system,
    ).check_limits(str(where), names={"outputs": f"{where}: spectral.outputs"})


def replay_settings(path, case=None, map=None, *, settings=None):
    """``(settings, source)`` as :func:`replay` chooses them: ``settings`` when given, else the
    recording's own unless ``case`` or ``map`` is given, else the map (:func:`map_settings`);
    ``source`` is :attr:`ReplayResult.settings_source`."""
    if settings is not None:
        if case or map:
            raise ConfigError("give settings, or a case or map, not both")
        return settings.check_limits("settings"), "settings"
    if not case and not map:
        saved = recorded_settings(path)
        if saved is not None:
            return saved, "recording"
    return map_settings(case, map), "map" if map else "case" if case else "default"


def _view(rerun, settings):
    """The Rerun view ``rerun`` asks for: None/False none, True the desktop viewer, a path an .rrd
    file, anything else a view object as it is."""
    if rerun is None or rerun is False:
        return None
    if rerun is True or isinstance(rerun, (str, os.PathLike)):
        from livesweep.monitor.rerun_view import RerunView

        return RerunView(list(settings.inputs), list(settings.outputs), recording_id="replay",
                         save_path=None if rerun is True else rerun, spawn=rerun is True)
    return rerun


def replay(path, case=None, map=None, *, settings=None, record=None, rerun=None, speed: float = 0.0,
           overwrite: bool = False) -> ReplayResult:
    """Run the monitor over the MCAP log ``path``, as ``livesweep replay`` does.

    Parameters
    ----------
    path : str or os.PathLike
        An MCAP log: a monitor's recording, the demo's ``live.mcap``, a converted log
        (``livesweep.convert.convert``).
    case, map : str or os.PathLike, optional
        A case or map file, or a map preset's name (``livesweep maps``), in place of the settings
        the recording carries (one of the two). Default: the recording's, else the packaged
        XV-15 map.
    settings : MonitorSettings, optional
        Exactly these settings (not with ``case`` or ``map``); checked against the monitor's limits.
    record : str or os.PathLike, optional
        Also write an MCAP recording of the replay: every frame replayed and the live results,
        with the settings attached (so it replays again). An existing file is refused unless
        ``overwrite``; never the log itself.
    rerun : bool, str, os.PathLike or view, optional
        None (default): headless. A path: the Rerun recording to that ``.rrd`` file. True: the
        Rerun desktop viewer. A view object (:class:`~livesweep.monitor.rerun_view.RerunView`)
        is used as it is; it is closed when the replay ends.
    speed : float
        0 (default): as fast as possible; N: N x the log's own pace.
    overwrite : bool
        Replace an existing ``record`` file.

    Returns
    -------
    ReplayResult

    Raises
    ------
    ConfigError
        A missing log, both a case and a map, settings beyond the monitor's limits, a bad speed.
    LogFormatError
        A log that is not MCAP; a ``record`` file that exists.
    """
    from livesweep.monitor.pipeline import MonitorPipeline
    from livesweep.telemetry.replay import McapReplaySource

    view = rerun if rerun is not None and not isinstance(rerun, (bool, str, os.PathLike)) else None
    frames = recorder = None
    kept: dict[str, list] = {name: [] for name in KEPT}

    def keep(name: str, payload: dict) -> None:
        if name in kept:
            kept[name].append(_as_recorded(payload))

    try:                     # a view handed in is the replay's to close, also when it cannot start
        log = Path(path)
        if not log.is_file():
            raise ConfigError(f"log {str(path)!r} does not exist")
        chosen, source = replay_settings(path, case, map, settings=settings)
        frames = McapReplaySource(path, speed=speed or 0.0)      # named as given (the counters say it)
        view = _view(rerun, chosen)
        if record is not None:              # the recording last: nothing after it can fail but the pipeline
            if Path(record).resolve() == log.resolve():
                raise ConfigError(f"record {str(record)!r} is the log being replayed; give another file")
            from livesweep.telemetry.recorder import McapRecorder

            recorder = McapRecorder(record, settings=chosen.to_dict(), overwrite=overwrite,
                                    metadata={"test_point": {"source": "livesweep replay", "log": str(path)}})
        pipe = MonitorPipeline(chosen, [frames], recorder=recorder, view=view, keep_estimates=False, results=keep)
    except BaseException:
        for part in (frames, recorder, view):
            if part is not None:
                part.close()
        raise
    summary = pipe.run()
    return ReplayResult(path=log, settings=chosen, settings_source=source, test_points=tuple(kept["test_point"]),
                        verdicts=tuple(kept["verdict"]), alerts=tuple(kept["alert"]), counters=summary["counters"],
                        link=kept["link"][-1] if kept["link"] else None, summary=summary,
                        recording=None if recorder is None else Path(recorder.path))
