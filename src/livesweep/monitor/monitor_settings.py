"""The live monitor's settings: what it estimates and how, their limits, and their saved form.

:class:`MonitorSettings` is what :class:`~livesweep.monitor.pipeline.MonitorPipeline` runs with.
:meth:`MonitorSettings.to_dict` is the form a recording keeps (``livesweep_settings.json``);
:meth:`MonitorSettings.from_dict` reads it back, checked as a channel map file is and against the
monitor's own limits (:meth:`MonitorSettings.check_limits`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

from livesweep.errors import ConfigError, quote, require_number
from livesweep.ident.envelope import NO_MODEL_SETTINGS, ModelSettings
from livesweep.spectral import DEFAULT_WINDOW_S
from livesweep.spectral.criteria import DEFAULT_CRITERIA, Criteria
from livesweep.spectral.online import OnlineSpectralEstimator

__all__ = ["MonitorSettings"]


@dataclass(frozen=True)
class MonitorSettings:
    """What the monitor estimates, and how.

    Attributes
    ----------
    signals : dict of str -> SignalSpec
        The channel map.
    inputs, outputs : tuple of str
    band_rad_s : (float, float)
    sample_rate_hz : float
        Estimator grid [Hz].
    window_s : float
        Sliding window [s].
    segment_s : float or None
        Segment (FFT window) length [s]; None: the estimator's default.
    update_period_s : float
        Estimate every this much data time [s] (0.2 s = 5 updates/s).
    results_every : int
        Record every n-th estimate in the MCAP (1 = all).
    saturation_limits : dict of input -> (lo, hi), optional
        Actuator limits in input units.
    required_pairs : tuple of (output, input), optional
        The pairs this test point must excite for a GO (default: the on-axis pairs).
    view_period_s : float
        Send an estimate to the Rerun view at most this often [s of data]: every estimate re-logs
        every pair's curves and waterfall (about 0.3 MB for 4 x 12 pairs), so the view refreshes
        at 1 Hz by default while the estimates themselves run at ``update_period_s``.
    references : tuple of str, optional
        One exogenous reference per input (a closed-loop test point's logged sweep injection): the
        live responses and coherences are then formed through them (docs/method.md §4.6), free of the
        feedback bias; while a reference is silent the direct estimate is shown.
    test_points : livesweep.config.TestPointSettings, optional
        Where test points come from, which input each SystemID axis sweeps and which pairs each
        swept input must cover (a map's ``[test_points]`` table); None: every source, the
        on-axis output of the swept input, 10 s at least.
    map_name : str, optional
        The channel map's name (what a ``map`` alert calls it).
    vehicle : dict of str -> tuple of float, optional
        The vehicle the map is made for (its ``[map.vehicle]``: ``FRAME_CLASS``, ``FRAME_TYPE``,
        ``MAV_TYPE``); checked against what the vehicle says of itself.
    system : (int, int or None), optional
        The MAVLink system and component to analyse (``--sysid``, ``[map].sysid``); None: the first
        vehicle that sends every mapped message (:mod:`livesweep.telemetry.vehicle_choice`).
    criteria : Criteria
        What makes a response adequate and a test point GO (the map's ``[criteria]``): used by the
        verdict, each test point's judgement, the view's threshold and the status text.
    models : ModelSettings
        What each closed test point's model is fitted with and held to (the map's
        ``[transfer_functions]``, ``[predictions]`` and ``[limits]``).
    """

    signals: dict
    inputs: tuple
    outputs: tuple
    band_rad_s: tuple
    sample_rate_hz: float = 50.0
    window_s: float = DEFAULT_WINDOW_S
    segment_s: float | None = None
    update_period_s: float = 0.2
    results_every: int = 5
    saturation_limits: dict | None = None
    required_pairs: tuple | None = None
    view_period_s: float = 1.0
    references: tuple | None = None
    test_points: object | None = None
    map_name: str | None = None
    vehicle: dict | None = None
    system: tuple | None = None
    criteria: Criteria = DEFAULT_CRITERIA
    models: ModelSettings = NO_MODEL_SETTINGS

    def to_dict(self) -> dict:
        """Everything a replay needs to run as the live monitor did (the recording's settings attachment)."""
        tp = self.test_points
        return {
            "signals": {n: asdict(s) for n, s in self.signals.items()},
            "inputs": list(self.inputs), "outputs": list(self.outputs), "band_rad_s": list(self.band_rad_s),
            "sample_rate_hz": self.sample_rate_hz, "window_s": self.window_s, "segment_s": self.segment_s,
            "update_period_s": self.update_period_s,
            "required_pairs": None if self.required_pairs is None else [list(p) for p in self.required_pairs],
            "references": None if not self.references else list(self.references),
            "saturation_limits": None if not self.saturation_limits else
            {k: list(v) for k, v in self.saturation_limits.items()},
            "test_points": None if tp is None else {
                "sources": list(tp.sources), "axes": {str(k): v for k, v in tp.axes.items()},
                "required": {k: list(v) for k, v in tp.required.items()}, "min_duration_s": tp.min_duration_s,
                **({"conditions": list(tp.conditions)} if tp.conditions else {})},
            "map_name": self.map_name,
            "vehicle": None if not self.vehicle else {k: list(v) for k, v in self.vehicle.items()},
            "system": None if self.system is None else list(self.system),
            "criteria": self.criteria.to_dict(),
            "models": self.models.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict, *, where: str = "settings", path=None) -> "MonitorSettings":
        """The settings :meth:`to_dict` wrote (a recording's ``livesweep_settings.json``).

        Validated as a channel map file is (:func:`livesweep.config.channel_map_from_tables`: names,
        fields, band, ``sample_rate_hz`` and every other limit a map gets) and then against the
        monitor's own limits (:meth:`check_limits`), so a crafted recording cannot ask for more than
        a map or the command line could.

        Parameters
        ----------
        d : dict
            The decoded JSON.
        where : str
            How messages name the settings, e.g. ``"rec.mcap: livesweep_settings.json"``.
        path : str or os.PathLike, optional
            The file they came from (default ``where``).

        Raises
        ------
        ConfigError
            One line naming ``where``, the key (as the JSON spells it) and the value.
        """
        from livesweep.config import channel_map_from_tables

        if not isinstance(d, dict):
            raise ConfigError(f"{where}: must be a JSON object of monitor settings, got {quote(d)}")
        try:
            m = channel_map_from_tables(_map_tables(d, where), path if path is not None else where, where=where)
        except ConfigError as e:           # the map's key paths, as the settings' JSON spells them
            text = str(e)
            for table, key in ((f"{where}: spectral: ", f"{where}: "), (f"{where}: spectral.", f"{where}: "),
                               (f"{where}: map.vehicle", f"{where}: vehicle")):
                if text.startswith(table):
                    text = key + text[len(table):]
                    break
            raise ConfigError(text) from None
        if m.spectral is None:
            raise ConfigError(f"{where}: missing the spectral settings (inputs, outputs, band_rad_s, sample_rate_hz)")
        sp = m.spectral
        map_name = d.get("map_name")
        if map_name is not None and not isinstance(map_name, str):
            raise ConfigError(f"{where}: map_name: must be a string, got {quote(map_name)}")
        try:
            system = _system(d.get("system"))
        except (TypeError, ValueError) as e:
            raise ConfigError(f"{where}: not monitor settings livesweep can use ({type(e).__name__}: {e})") from None
        segment = d.get("segment_s")
        settings = cls(
            signals=m.signals, inputs=sp.inputs, outputs=sp.outputs, band_rad_s=sp.band_rad_s,
            sample_rate_hz=sp.sample_rate_hz,
            window_s=require_number(d["window_s"] if "window_s" in d else None, f"{where}: window_s"),
            segment_s=None if segment is None else require_number(segment, f"{where}: segment_s"),
            update_period_s=require_number(d.get("update_period_s", 0.2), f"{where}: update_period_s"),
            references=sp.references, test_points=m.test_points, map_name=map_name,
            vehicle=dict(m.vehicle) or None, system=system, criteria=m.criteria, models=m.models,
        ).check_limits(where)
        return replace(settings,
                       required_pairs=_saved_pairs(d.get("required_pairs"), sp, f"{where}: required_pairs"),
                       saturation_limits=_saved_saturation(d.get("saturation_limits"), sp,
                                                           f"{where}: saturation_limits"))

    def check_limits(self, where: str = "", names: dict | None = None) -> "MonitorSettings":
        """These settings, or ConfigError when they ask for more than :mod:`livesweep.limits` allows
        the live monitor: a window of at most ``MAX_WINDOW_S`` [s] holding at most
        ``MAX_RECORD_VALUES`` samples x signals, with segment transforms of at most
        ``MAX_SPECTRAL_VALUES`` values; a segment [s] no longer than the window; an update period of
        at least ``MIN_UPDATE_PERIOD_S`` [s]; a grid of at most ``MAX_MONITOR_RATE_HZ`` [Hz]; at most
        ``MAX_MONITOR_PAIRS`` pairs.

        Parameters
        ----------
        where : str
            What the message names first (the file the settings came from); may be empty.
        names : dict of str -> str, optional
            How the message calls a setting instead of ``"<where>: <attribute>"``, e.g.
            ``{"update_period_s": "--update-period"}`` (``"outputs"`` names the pair count).

        Returns
        -------
        MonitorSettings
            ``self``.
        """
        import inspect

        from livesweep import limits
        from livesweep.spectral.online import default_segment_s

        def error(key, problem, value):
            label = (names or {}).get(key) or (f"{where}: {key}" if where else key)
            return ConfigError(f"{label}: {problem}, got {quote(value)}")

        window = self.window_s
        if not (isinstance(window, (int, float)) and math.isfinite(window) and 0 < window <= limits.MAX_WINDOW_S):
            raise error("window_s", f"the sliding window must be > 0 and at most {limits.MAX_WINDOW_S:g} s", window)
        seg = self.segment_s
        if seg is not None and not (isinstance(seg, (int, float)) and math.isfinite(seg) and 0 < seg <= window):
            raise error("segment_s", f"a segment must be > 0 s and at most the sliding window ({window:g} s)", seg)
        period = self.update_period_s
        if not (isinstance(period, (int, float)) and math.isfinite(period) and period >= limits.MIN_UPDATE_PERIOD_S):
            raise error("update_period_s", f"must be at least {limits.MIN_UPDATE_PERIOD_S:g} s", period)
        fs = self.sample_rate_hz
        if not (isinstance(fs, (int, float)) and math.isfinite(fs) and 0 < fs <= limits.MAX_MONITOR_RATE_HZ):
            raise error("sample_rate_hz", f"the live monitor's grid runs at most at {limits.MAX_MONITOR_RATE_HZ:g} Hz",
                        fs)
        pairs = len(self.inputs) * len(self.outputs)
        if pairs > limits.MAX_MONITOR_PAIRS:
            raise error("outputs", f"{len(self.outputs)} outputs x {len(self.inputs)} inputs = {pairs} pairs; the "
                        f"monitor analyses at most {limits.MAX_MONITOR_PAIRS}", len(self.outputs))
        n_signals = len(set((*self.inputs, *self.outputs, *(self.references or ()))))
        samples = int(round(window * fs))
        if samples * n_signals > limits.MAX_RECORD_VALUES:
            raise error("window_s", f"{window:g} s x {fs:g} Hz x {n_signals} signals = {samples * n_signals} samples "
                        f"in the sliding window; at most {limits.MAX_RECORD_VALUES}", window)
        overlap = inspect.signature(OnlineSpectralEstimator).parameters["overlap"].default    # what the pipeline uses
        values = limits.window_spectra_values(n_signals, samples, fs, seg or default_segment_s(self.band_rad_s, window),
                                              overlap, self.band_rad_s)
        if values > limits.MAX_SPECTRAL_VALUES:
            raise error("window_s", f"its segment transforms hold {values} values; at most "
                        f"{limits.MAX_SPECTRAL_VALUES} (a shorter window or fewer signals)", window)
        return self


def _map_tables(d: dict, where: str = "settings") -> dict:
    """The channel-map part of saved settings, shaped as a map file's TOML tables."""
    tables = {}
    if "signals" in d:
        sigs = d["signals"]
        tables["signals"] = {n: _signal_table(v) for n, v in sigs.items()} if isinstance(sigs, dict) else sigs
    spectral = {k: d[k] for k in ("inputs", "outputs", "band_rad_s", "sample_rate_hz", "references")
                if d.get(k) is not None}
    if spectral:
        tables["spectral"] = spectral
    if d.get("test_points") is not None:
        tables["test_points"] = d["test_points"]
    if d.get("vehicle"):
        tables["map"] = {"vehicle": d["vehicle"]}
    if d.get("criteria") is not None:
        tables["criteria"] = d["criteria"]
    models = d.get("models")
    if models is not None:
        if not isinstance(models, dict):
            raise ConfigError(f"{where}: models: must be an object of transfer_functions, predictions, limits, got {quote(models)}")
        for k, v in models.items():
            if k not in ("transfer_functions", "predictions", "limits"):
                raise ConfigError(f"{where}: models.{k}: unknown; known: transfer_functions, predictions, limits")
            tables[k] = v
    return tables


def _signal_table(v):
    """A saved :class:`~livesweep.config.SignalSpec` (``asdict``) as its ``[signals.NAME]`` table."""
    if not isinstance(v, dict):
        return v
    t = {k: x for k, x in v.items() if k != "name" and x is not None}
    if "stamp" not in t:
        t.pop("stamp_scale", None)          # 1.0, the field's default, for a signal on receive time
    where = t.get("where")
    if isinstance(where, list):
        if not where:
            del t["where"]
        elif all(isinstance(p, list) and len(p) == 2 and isinstance(p[0], str) for p in where):
            t["where"] = dict(where)
    return t


def _saved_pairs(value, spectral, where: str) -> tuple | None:
    """Saved ``required_pairs``: None or ``[[output, input], ...]`` of the spectral outputs and inputs."""
    if value is None:
        return None
    if not isinstance(value, list) or len(value) > len(spectral.inputs) * len(spectral.outputs):
        raise ConfigError(f"{where}: must be a list of [output, input] pairs of the spectral settings, got {quote(value)}")
    for i, p in enumerate(value):
        if not (isinstance(p, list) and len(p) == 2 and p[0] in spectral.outputs and p[1] in spectral.inputs):
            raise ConfigError(f"{where}[{i}]: must be [output, input] with an output of {quote(list(spectral.outputs))} "
                              f"and an input of {quote(list(spectral.inputs))}, got {quote(p)}")
    return tuple((str(o), str(i)) for o, i in value)


def _saved_saturation(value, spectral, where: str) -> dict | None:
    """Saved ``saturation_limits``: None or ``{input: [low, high]}`` in input units, ``low < high``."""
    if not value:
        return None
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: must be an object of input: [low, high], got {quote(value)}")
    out = {}
    for name, v in value.items():
        ok = (name in spectral.inputs and isinstance(v, list) and len(v) == 2
              and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
              and v[0] < v[1])
        if not ok:
            raise ConfigError(f"{where}.{quote(name)}: must be [low, high] with low < high, for an input of "
                              f"{quote(list(spectral.inputs))}, got {quote(v)}")
        out[name] = (float(v[0]), float(v[1]))
    return out


def _system(value) -> tuple | None:
    """Saved ``system``: None or [sysid, compid or None], each a MAVLink id (0-255)."""
    if value is None:
        return None
    sysid, compid = value
    for v in (sysid, compid):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 255):
            raise ValueError(f"system {value!r}: a MAVLink id is an integer from 0 to 255")
    if sysid is None:
        raise ValueError(f"system {value!r}: needs a system id")
    return int(sysid), None if compid is None else int(compid)
