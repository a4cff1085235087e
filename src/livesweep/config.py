"""Case files and channel maps (TOML, docs/case-file.md): load and validate.

A *case file* names the records to identify from (``[[identify]]``, concatenated in order), the
records to verify against (``[[verify]]``), where each signal lives in the logs (``[signals]``),
the spectral settings (``[spectral]``) and, for later stages, the models (``[transfer_functions]``,
``[state_space]``, ...). A *channel map* is a file with ``[signals]``, an optional ``[spectral]``
table (what the live monitor needs) and, for a named map (:mod:`livesweep.maps`), ``[map]``
(``name``, ``description``, ``needs``) and ``[test_points]`` (:class:`TestPointSettings`).

A signal's ``field`` is a field name or path, or arithmetic of them
(:func:`livesweep.telemetry.extract.parse_field`); ``sysid``, ``compid`` and ``where`` select the
messages it is taken from. On a ``/mavlink/<MSG>`` topic every field a signal names (operands,
stamp, selection) is checked against the MAVLink definition of ``MSG`` when the file is loaded.

Every problem raises :class:`~livesweep.errors.ConfigError` with a one-line message that names
the file, the key path (``signals.p.scale``, ``identify[1].start_s``; array indices count from 0)
and the offending value. Nothing is silently dropped: an unknown key in a table parsed here is an
error. The tables of later stages (``transfer_functions``, ``state_space``, ``residual``) are kept raw in :attr:`Case.tables` and validated by the stages
that use them.

Units: times in seconds on the signals' stamp clock (vehicle time), frequencies in rad/s, sample
rates in Hz.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from livesweep import limits
from livesweep.errors import ConfigError, check_band, quote
from livesweep.ident.envelope import NO_LIMITS, EnvelopeLimits, ModelSettings, Prediction
from livesweep.tf_tables import specs_of_tables
from livesweep.settings import (TEST_POINT_SOURCES, Case, ChannelMap, Criteria, RecordSpec, SignalSpec,
                                SpectralSettings, TestPointSettings)
from livesweep.settings_schema import read_table, require_table, table_keys

__all__ = [
    "SignalSpec",
    "RecordSpec",
    "TestPointSettings",
    "ChannelMap",
    "read_channel_map",
    "channel_map_from_tables",
    "TEST_POINT_SOURCES",
    "SpectralSettings",
    "Criteria",
    "Case",
    "load_case",
    "load_channel_map",
    "require_table",
    "CASE_KEYS",
    "RAW_TABLE_KEYS",
]

#: Top-level tables the stages after frequency-response estimation parse themselves.
RAW_TABLE_KEYS = ("transfer_functions", "state_space", "residual")
#: Tables a case file once could hold but nothing reads: refused with what to do instead.
_UNREAD_TABLES = {
    "consistency": "the kinematic checks need no settings: they run on the [signals] named p/phi, q/theta, r/psi",
    "verification": "time-domain verification runs on the [[verify]] records and has no settings",
}
#: Every top-level key a case file may hold.
CASE_KEYS = ("case", "identify", "verify", "signals", "spectral", "criteria", "predictions", "limits") + RAW_TABLE_KEYS

_CASE_TABLE_KEYS = table_keys(Case)
_RECORD_KEYS = table_keys(RecordSpec)
_SIGNAL_KEYS = ("topic", "field", "stamp", "stamp_topic", "stamp_scale", "scale", "offset", "units", "sysid", "compid",
                "where")
#: Top-level tables of a channel map (a case file's keys are accepted too: ``--case`` takes one).
MAP_KEYS = ("map", "signals", "spectral", "test_points", "criteria", "transfer_functions", "predictions", "limits")
_MAP_TABLE_KEYS = ("name", "description", "needs", "vehicle", "sysid", "compid")
#: ``[map.vehicle]`` keys are parameter names (``FRAME_CLASS``) or ``MAV_TYPE`` (the HEARTBEAT type).
_VEHICLE_KEY = re.compile(r"[A-Z][A-Z0-9_]{0,15}")
_TEST_POINT_KEYS = table_keys(TestPointSettings)
_MAX_VEHICLE_ID = 255           # MAVLink system and component ids are one byte
_SPECTRAL_KEYS = table_keys(SpectralSettings)
#: A signal name: letters, digits, ``_``, and ``.``/``-`` inside (never ``..``); never a path.
_SIGNAL_NAME = re.compile(r"[A-Za-z0-9_](?:[A-Za-z0-9_.\-]*[A-Za-z0-9_])?")


# --------------------------------------------------------------------------------------------
# small validators: each names the file, the key path and the value
# --------------------------------------------------------------------------------------------


class _Ctx:
    """The file being validated, for error messages."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def error(self, key: str, problem: str, value: Any = ...) -> ConfigError:
        got = "" if value is ... else f", got {quote(value)}"
        return ConfigError(f"{self.path}: {key}: {problem}{got}")


def _type_name(value: Any) -> str:
    return {bool: "boolean", int: "integer", float: "float", str: "string",
            list: "array", dict: "table"}.get(type(value), type(value).__name__)


def _check_keys(ctx: _Ctx, table: Mapping[str, Any], known: tuple[str, ...], where: str) -> None:
    """Raise on the first key of ``table`` not in ``known``."""
    for key in table:
        if not where and key in _UNREAD_TABLES:
            raise ConfigError(f"{ctx.path}: [{key}]: livesweep reads no [{key}] table ({_UNREAD_TABLES[key]}); "
                              "remove it")
        if key not in known:
            path = f"{where}.{key}" if where else key
            raise ConfigError(
                f"{ctx.path}: {path}: unknown key {key!r}; known keys{' in ' + where if where else ''}: "
                f"{', '.join(known)}"
            )


def _table(ctx: _Ctx, value: Any, key: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ctx.error(key, f"must be a table, not {_type_name(value)}", value)
    return value


def _string(ctx: _Ctx, value: Any, key: str, *, nonempty: bool = True) -> str:
    if not isinstance(value, str):
        raise ctx.error(key, f"must be a string, not {_type_name(value)}", value)
    if nonempty and not value.strip():
        raise ctx.error(key, "must be a non-empty string", value)
    return value


def _number(ctx: _Ctx, value: Any, key: str) -> float:
    """A finite TOML integer or float (booleans are not numbers here)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ctx.error(key, f"must be a number, not {_type_name(value)}", value)
    v = float(value)
    if not math.isfinite(v):
        raise ctx.error(key, "must be a finite number", value)
    return v


def _positive(ctx: _Ctx, value: Any, key: str) -> float:
    v = _number(ctx, value, key)
    if v <= 0:
        raise ctx.error(key, "must be > 0", value)
    return v


def _string_list(ctx: _Ctx, value: Any, key: str) -> tuple[str, ...]:
    if not isinstance(value, list):
        raise ctx.error(key, f"must be an array of strings, not {_type_name(value)}", value)
    if not value:
        raise ctx.error(key, "must name at least one signal", value)
    out = tuple(_string(ctx, v, f"{key}[{i}]") for i, v in enumerate(value))
    for i, v in enumerate(out):
        if v in out[:i]:
            raise ctx.error(f"{key}[{i}]", "is listed twice", v)
    return out


# --------------------------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------------------------


def _parse_signal(ctx: _Ctx, name: str, raw: Any) -> SignalSpec:
    where = f"signals.{name}"
    t = _table(ctx, raw, where)
    _check_keys(ctx, t, _SIGNAL_KEYS, where)
    for req in ("topic", "field"):
        if req not in t:
            raise ctx.error(where, f"missing required key {req!r} (a signal needs topic and field)")
    stamp = _string(ctx, t["stamp"], f"{where}.stamp") if "stamp" in t else None
    stamp_topic = _string(ctx, t["stamp_topic"], f"{where}.stamp_topic") if "stamp_topic" in t else None
    if stamp_topic is not None and stamp is None:
        raise ctx.error(f"{where}.stamp_topic", "is given without 'stamp' (the field of that topic that holds the time)",
                        stamp_topic)
    if "stamp_scale" in t and stamp is None:
        raise ctx.error(f"{where}.stamp_scale", "is given without 'stamp' (log_time is already in ns -> s)",
                        t["stamp_scale"])
    scale = _number(ctx, t.get("scale", 1.0), f"{where}.scale")
    if scale == 0.0:
        raise ctx.error(f"{where}.scale", "must not be 0 (the signal would be constant)", t["scale"])
    from livesweep.telemetry.extract import is_field_path, parse_field

    topic = _string(ctx, t["topic"], f"{where}.topic")
    text = _string(ctx, t["field"], f"{where}.field")
    expression = parse_field(text, f"{ctx.path}: {where}.field")
    if stamp is not None and not is_field_path(stamp):
        raise ctx.error(f"{where}.stamp", "must be one field name or dotted path (no arithmetic)", stamp)
    selection = _parse_where(ctx, t["where"], f"{where}.where") if "where" in t else ()
    ids = {k: _vehicle_id(ctx, t[k], f"{where}.{k}") for k in ("sysid", "compid") if k in t}
    if topic.startswith("/mavlink/"):
        named = [(f"{where}.field", f) for f in expression.operands]
        named += [(f"{where}.stamp", stamp)] if stamp is not None and stamp_topic is None else []
        named += [(f"{where}.where.{k}", k) for k, _ in selection]
        _check_mavlink_fields(ctx, where, topic, named)
    if stamp_topic is not None and stamp_topic.startswith("/mavlink/"):
        _check_mavlink_fields(ctx, where, stamp_topic, [(f"{where}.stamp", stamp)], topic_key="stamp_topic")
    return SignalSpec(
        name=name,
        topic=topic,
        field=text,
        stamp=stamp,
        stamp_scale=_positive(ctx, t["stamp_scale"], f"{where}.stamp_scale") if "stamp_scale" in t else 1.0,
        scale=scale,
        offset=_number(ctx, t.get("offset", 0.0), f"{where}.offset"),
        units=_string(ctx, t["units"], f"{where}.units", nonempty=False) if "units" in t else "",
        sysid=ids.get("sysid"),
        compid=ids.get("compid"),
        where=selection,
        stamp_topic=stamp_topic,
    )


def _vehicle_id(ctx: _Ctx, value: Any, key: str) -> int:
    """A MAVLink system or component id: an integer from 0 to 255."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= _MAX_VEHICLE_ID:
        raise ctx.error(key, f"must be an integer from 0 to {_MAX_VEHICLE_ID} (a MAVLink id)", value)
    return value


def _parse_where(ctx: _Ctx, raw: Any, key: str) -> tuple[tuple[str, int | float], ...]:
    """``where = { field = value, ... }``: field names or paths -> finite numbers."""
    from livesweep.telemetry.extract import is_field_path

    t = _table(ctx, raw, key)
    if not t:
        raise ctx.error(key, "must name at least one field = value (or leave 'where' out)", raw)
    out = []
    for f, v in t.items():
        if not is_field_path(f):
            raise ctx.error(f"{key}.{quote(f)}", "a 'where' key is one field name or dotted path", f)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ctx.error(f"{key}.{f}", "must be a finite number (messages whose field equals it are taken)", v)
        out.append((f, v))
    return tuple(out)


def _check_mavlink_fields(ctx: _Ctx, where: str, topic: str, named: list[tuple[str, str]], *,
                          topic_key: str = "topic") -> None:
    """Every field a signal on ``/mavlink/<MSG>`` names must be a field of that MAVLink message
    (``sysid``, ``compid`` or a field of the dialect's definition; an array element as
    ``name.index`` with the index in range)."""
    from livesweep.telemetry.mavlink_codec import DIALECT, message_class

    msg = topic.split("/", 2)[2]
    try:
        cls = message_class(msg)
    except ConfigError as e:
        raise ctx.error(f"{where}.{topic_key}", f"{e} (a /mavlink/ topic is /mavlink/<MESSAGE NAME>)", topic) from None
    lengths = {"sysid": 0, "compid": 0}
    for i, n in enumerate(cls.fieldnames):
        lengths[n] = 0 if cls.fieldtypes[i] == "char" else int(cls.array_lengths[cls.orders[i]])
    for key, path in named:
        base, _, rest = path.partition(".")
        n = lengths.get(base)
        if n is None:
            raise ctx.error(key, f"{base!r} is not a field of MAVLink {msg} in dialect {DIALECT} (fields: "
                            f"{', '.join(lengths)})", path)
        if n and not (rest.isdigit() and int(rest) < n):
            raise ctx.error(key, f"{base!r} of MAVLink {msg} is an array of {n}: name one element, "
                            f"{base}.0 to {base}.{n - 1}", path)
        if not n and rest:
            raise ctx.error(key, f"{base!r} of MAVLink {msg} is a single value, not an array or object", path)


def _parse_signals(ctx: _Ctx, raw: Any) -> dict[str, SignalSpec]:
    t = _table(ctx, raw, "signals")
    if not t:
        raise ctx.error("signals", "must define at least one signal ([signals.NAME] with topic and field)")
    out: dict[str, SignalSpec] = {}
    for name, spec in t.items():
        _check_signal_name(ctx, name)
        out[name] = _parse_signal(ctx, name, spec)
    return out


def _check_signal_name(ctx: _Ctx, name: str) -> None:
    """A signal name is a name, never a path: it becomes part of plot file names."""
    if not name.strip():
        raise ctx.error("signals", "a signal name must not be empty", name)
    if len(name) > limits.MAX_NAME_CHARS:
        raise ctx.error("signals", f"a signal name must be at most {limits.MAX_NAME_CHARS} characters "
                        f"(this one has {len(name)})", name)
    if not _SIGNAL_NAME.fullmatch(name) or ".." in name:
        raise ctx.error(f"signals.{quote(name)}", "a signal name may hold only letters, digits, '_', and "
                        "'.' or '-' between them (no '/', no '..', no spaces)", name)


def _parse_spectral(ctx: _Ctx, raw: Any, signals: Mapping[str, SignalSpec]) -> SpectralSettings:
    t = read_table(raw, SpectralSettings, "spectral", ctx.path)       # keys, required keys, plain values
    inputs = _string_list(ctx, t["inputs"], "spectral.inputs")
    outputs = _string_list(ctx, t["outputs"], "spectral.outputs")
    for key, names in (("spectral.inputs", inputs), ("spectral.outputs", outputs)):
        for i, n in enumerate(names):
            if n not in signals:
                raise ctx.error(f"{key}[{i}]", f"names no signal in [signals] (defined: {', '.join(signals)})", n)
    for i, n in enumerate(inputs):
        if n in outputs:
            raise ctx.error(f"spectral.inputs[{i}]", "is also listed in spectral.outputs; "
                            "a signal is an input or an output, not both", n)
    fs = t["sample_rate_hz"]
    lo, hi = check_band(t["band_rad_s"], f"{ctx.path}: spectral.band_rad_s", sample_rate_hz=fs)
    windows = t.get("windows_s")
    n_freq = t.get("n_freq", SpectralSettings.n_freq)
    n_windows = len(windows) if windows else limits.MAX_WINDOWS     # the stage chooses fewer
    composite = len(outputs) * len(inputs) * n_freq * n_windows
    if composite > limits.MAX_SPECTRAL_VALUES:
        raise ctx.error("spectral.n_freq", f"{len(outputs)} outputs x {len(inputs)} inputs x {n_freq} frequencies x "
                        f"{n_windows} windows = {composite} response values; at most {limits.MAX_SPECTRAL_VALUES}",
                        n_freq)
    references = None
    if "references" in t:
        references = _string_list(ctx, t["references"], "spectral.references")
        if len(references) != len(inputs):
            raise ctx.error("spectral.references", f"needs one reference per input ({len(inputs)}: "
                            f"{', '.join(inputs)}), in the same order", t["references"])
        for i, n in enumerate(references):
            if n not in signals:
                raise ctx.error(f"spectral.references[{i}]", f"names no signal in [signals] (defined: {', '.join(signals)})", n)
            if n in inputs or n in outputs:
                raise ctx.error(f"spectral.references[{i}]", "is also an input or output; a reference is the "
                                "exogenous injection, a signal of its own", n)
    return SpectralSettings(**{**t, "inputs": inputs, "outputs": outputs, "band_rad_s": (lo, hi),
                               "references": references})


def _parse_criteria(ctx: _Ctx, raw: Any) -> Criteria:
    """``[criteria]``: what makes a response adequate and a test point GO."""
    return Criteria(**read_table(raw, Criteria, "criteria", ctx.path))


def _parse_models(ctx: _Ctx, data: Mapping[str, Any], signals: dict) -> ModelSettings:
    """``[transfer_functions.*]``, ``[predictions.*]`` and ``[limits]``: what each test point's model
    is fitted with and held to (every pair's signals in ``[signals]``)."""
    raw_tf = data.get("transfer_functions") or {}
    specs = specs_of_tables(raw_tf, ctx.path) if raw_tf else ()
    limits = EnvelopeLimits(**read_table(data["limits"], EnvelopeLimits, "limits", ctx.path)) \
        if "limits" in data else NO_LIMITS
    for i, pair in enumerate(limits.broken_loop):
        out, _, inp = pair.partition("/")
        if out not in signals or inp not in signals:
            raise ctx.error(f"limits.broken_loop[{i}]", "must be \"output/input\" of signals in [signals]", pair)
    preds = []
    raw_p = data.get("predictions") or {}
    if not isinstance(raw_p, dict):
        raise ctx.error("predictions", "must be a table of [predictions.NAME] tables", raw_p)
    for name, raw in raw_p.items():
        p = Prediction(name=name, **read_table(raw, Prediction, f"predictions.{name}", ctx.path))
        for key in ("output", "input"):
            if getattr(p, key) not in signals:
                raise ctx.error(f"predictions.{name}.{key}", f"names no signal in [signals] (defined: "
                                f"{', '.join(signals)})", getattr(p, key))
        p.structures(f"{ctx.path}: predictions.{name}")
        preds.append(p)
    for s in specs:
        for key in ("output", "input"):
            if getattr(s.model, key) not in signals:
                raise ctx.error(f"transfer_functions.{s.model.name}.{key}", "names no signal in [signals]",
                                getattr(s.model, key))
    return ModelSettings(tuple(specs), tuple(preds), limits, dict(raw_tf) or None)


def _parse_test_points(ctx: _Ctx, raw: Any, spectral: SpectralSettings | None,
                       signals: dict | None = None) -> TestPointSettings:
    """``[test_points]``: sources, axes, required, min_duration_s (every name a declared input or output)."""
    t = read_table(raw, TestPointSettings, "test_points", ctx.path)
    if spectral is None:
        raise ctx.error("test_points", "needs a [spectral] table: its names are spectral inputs and outputs")
    inputs, outputs = spectral.inputs, spectral.outputs
    axes: dict[int, str] = {}
    for k, v in _table(ctx, t.get("axes", {}), "test_points.axes").items():
        key = f"test_points.axes.{quote(k)}"
        if not (k.isascii() and k.isdigit()) or not 1 <= int(k) <= _MAX_VEHICLE_ID:
            raise ctx.error(key, "a key is an ArduPilot SID_AXIS number, \"1\" to \"255\" (1/2/3 input roll/pitch/yaw, "
                            "4-6 recovery, 7-9 rate, 10-12 mixer)", k)
        if not isinstance(v, str) or v not in inputs:
            raise ctx.error(key, f"must name a spectral input ({', '.join(inputs)})", v)
        axes[int(k)] = v
    required: dict[str, tuple[str, ...]] = {}
    named = _table(ctx, t.get("required", {}), "test_points.required")
    for k, v in named.items():
        key = f"test_points.required.{quote(k)}"
        if k not in inputs:
            raise ctx.error(key, f"names no spectral input ({', '.join(inputs)})", k)
        outs = _string_list(ctx, v, key)
        for i, o in enumerate(outs):
            if o not in outputs:
                raise ctx.error(f"{key}[{i}]", f"names no spectral output ({', '.join(outputs)})", o)
        required[k] = outs
    for k, name in enumerate(inputs):            # the default: the on-axis output
        if name not in required:
            required[name] = (outputs[k],) if k < len(outputs) else tuple(outputs)
    required = {name: required[name] for name in inputs}
    for i, n in enumerate(t.get("conditions", ())):
        if signals is not None and n not in signals:
            raise ctx.error(f"test_points.conditions[{i}]", f"names no signal in [signals] (defined: "
                            f"{', '.join(signals)})", n)
    return TestPointSettings(**{**t, "axes": axes, "required": required})


def _parse_map_table(ctx: _Ctx, raw: Any) -> dict[str, Any]:
    """``[map]``: name, description, needs (strings) and ``vehicle`` (parameter -> value or values)."""
    t = _table(ctx, raw, "map")
    _check_keys(ctx, t, _MAP_TABLE_KEYS, "map")
    out: dict[str, Any] = {k: _string(ctx, t[k], f"map.{k}", nonempty=(k == "name"))
                           for k in ("name", "description", "needs") if k in t}
    if "compid" in t and "sysid" not in t:
        raise ctx.error("map.compid", "needs map.sysid (the component of which system)", t["compid"])
    if "sysid" in t:
        out["system"] = (_vehicle_id(ctx, t["sysid"], "map.sysid"),
                         _vehicle_id(ctx, t["compid"], "map.compid") if "compid" in t else None)
    vehicle = {}
    for k, v in _table(ctx, t.get("vehicle", {}), "map.vehicle").items():
        key = f"map.vehicle.{quote(k)}"
        if not _VEHICLE_KEY.fullmatch(k):
            raise ctx.error(key, "a key is a vehicle parameter name (FRAME_CLASS) or MAV_TYPE", k)
        values = v if isinstance(v, list) else [v]
        if not values:
            raise ctx.error(key, "must be a number or a non-empty array of numbers", v)
        vehicle[k] = tuple(_number(ctx, x, key) for x in values)
    out["vehicle"] = vehicle
    if "name" in out and (len(out["name"]) > limits.MAX_NAME_CHARS or not _SIGNAL_NAME.fullmatch(out["name"])):
        raise ctx.error("map.name", "a map name holds letters, digits, '_', and '.' or '-' between them "
                        f"(at most {limits.MAX_NAME_CHARS} characters)", out["name"])
    return out


def _one_clock(ctx: _Ctx, signals: Mapping[str, SignalSpec]) -> None:
    """Every signal of a map is timed by a vehicle stamp, or none is: the live aligner puts them on
    one clock, and receive time and vehicle time are not comparable."""
    stamped = [n for n, s in signals.items() if s.stamp is not None]
    if stamped and len(stamped) != len(signals):
        rx = [n for n in signals if n not in stamped]
        raise ctx.error("signals", f"{', '.join(stamped)} are timed by a vehicle stamp but {', '.join(rx)} by receive "
                        "time (no 'stamp'); a map gives every signal a stamp field, or none, so they share one clock")


def _parse_record(ctx: _Ctx, raw: Any, where: str, base: Path) -> RecordSpec:
    t = read_table(raw, RecordSpec, where, ctx.path)
    log_text = _string(ctx, t["log"], f"{where}.log")
    log = (base / Path(log_text).expanduser()).resolve()
    if not log.is_file():
        what = "is a directory, not a log file" if log.is_dir() else "does not exist"
        raise ConfigError(f"{ctx.path}: {where}.log: {log} {what} (from log = {log_text!r})")
    start, end = t.get("start_s"), t.get("end_s")
    if start is not None and end is not None and start >= end:
        raise ctx.error(f"{where}.start_s", f"must be before end_s = {raw['end_s']!r}", raw["start_s"])
    return RecordSpec(**{**t, "log": log})


def _parse_records(ctx: _Ctx, raw: Any, key: str, base: Path, *, required: bool) -> tuple[RecordSpec, ...]:
    if raw is None:
        if required:
            raise ctx.error(key, f"missing: a case needs at least one [[{key}]] record")
        return ()
    if not isinstance(raw, list):
        raise ctx.error(key, f"must be an array of tables ([[{key}]]), not {_type_name(raw)}", raw)
    if required and not raw:
        raise ctx.error(key, f"a case needs at least one [[{key}]] record", raw)
    return tuple(_parse_record(ctx, r, f"{key}[{i}]", base) for i, r in enumerate(raw))


def _read_toml(path: str | os.PathLike[str]) -> tuple[_Ctx, dict[str, Any]]:
    p = Path(path).resolve()
    if not p.is_file():
        what = "is a directory" if p.is_dir() else "does not exist"
        raise ConfigError(f"config file {p} {what}")
    try:
        with open(p, "rb") as f:
            raw = f.read(limits.MAX_CONFIG_BYTES + 1)
    except OSError as e:
        raise ConfigError(f"config file {p} cannot be read: {e.strerror or e}") from e
    if len(raw) > limits.MAX_CONFIG_BYTES:
        raise ConfigError(f"config file {p} is larger than {limits.MAX_CONFIG_BYTES} bytes; a case file is a few kB")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError(f"{p}: not UTF-8 text (byte {e.start}): TOML files must be UTF-8") from e
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: TOML syntax error: {e}") from e
    except RecursionError:
        raise ConfigError(f"{p}: arrays or tables nested too deeply to read (TOML parser recursion limit)") from None
    return _Ctx(p), data


# --------------------------------------------------------------------------------------------
# public
# --------------------------------------------------------------------------------------------


def load_case(path: str | os.PathLike[str]) -> Case:
    """Load and validate a case file.

    Parameters
    ----------
    path : str or os.PathLike
        The TOML case file. Log paths in it are relative to its directory.

    Returns
    -------
    Case

    Raises
    ------
    ConfigError
        On a TOML syntax error (file and line), an unknown key, a wrong type, a missing required
        key, a non-finite number, ``start_s >= end_s``, a log that does not exist (the resolved
        path is named), spectral inputs/outputs that name no signal or are both, a band with
        ``lo <= 0``, ``lo >= hi`` or ``hi`` at or above Nyquist, ``overlap`` outside
        ``[0, 0.95]``, non-positive ``windows_s`` or ``sample_rate_hz``, a signal name that is
        not a plain name (letters, digits, ``_``, inner ``.``/``-``), a file too large or nested
        too deeply to parse, and sizes beyond :mod:`livesweep.limits` (``sample_rate_hz``,
        ``n_freq``, ``windows_s`` and the composite outputs x inputs x n_freq x windows). The
        message names the file, the key path and the value.
    """
    ctx, data = _read_toml(path)
    _check_keys(ctx, data, CASE_KEYS, "")
    if "case" not in data:
        raise ctx.error("case", "missing: a case file needs a [case] table with at least name")
    head = read_table(data["case"], Case, "case", ctx.path)
    if "signals" not in data:
        raise ctx.error("signals", "missing: a case file needs a [signals] table")
    base = ctx.path.parent
    signals = _parse_signals(ctx, data["signals"])
    spectral = _parse_spectral(ctx, data["spectral"], signals) if "spectral" in data else None
    return Case(
        path=ctx.path,
        **head,
        identify=_parse_records(ctx, data.get("identify"), "identify", base, required=True),
        verify=_parse_records(ctx, data.get("verify"), "verify", base, required=False),
        signals=signals,
        spectral=spectral,
        tables={k: data[k] for k in RAW_TABLE_KEYS if k in data},
        criteria=_parse_criteria(ctx, data["criteria"]) if "criteria" in data else Criteria(),
    )


def load_channel_map(path: str | os.PathLike[str]) -> tuple[dict[str, SignalSpec], SpectralSettings | None]:
    """Load the ``[signals]`` and optional ``[spectral]`` tables of a channel map.

    A channel map holds those two tables (``config/xv15_channels.toml``) and, for a named map,
    ``[map]`` and ``[test_points]`` (validated too; :func:`read_channel_map` returns them). A full
    case file is accepted too, as the live monitor's ``--case`` takes one: its other tables must be
    known case tables but are not validated here (its logs need not exist yet).

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file.

    Returns
    -------
    (dict[str, SignalSpec], SpectralSettings or None)

    Raises
    ------
    ConfigError
        As :func:`load_case`, for the two tables read and for unknown top-level keys.
    """
    m = read_channel_map(path, one_clock=False)
    return m.signals, m.spectral


def read_channel_map(path: str | os.PathLike[str], *, one_clock: bool = True) -> ChannelMap:
    """Load and validate a channel map with its ``[map]`` and ``[test_points]`` tables.

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file: ``[signals]`` (required), ``[spectral]``, ``[map]`` (``name``,
        ``description``, ``needs``: strings), ``[test_points]`` (``sources``, ``axes``,
        ``required``, ``min_duration_s``: :class:`TestPointSettings`). A case file's tables are
        accepted too and not validated here.
    one_clock : bool
        Refuse a map that times some signals by a vehicle stamp and others by receive time.

    Returns
    -------
    ChannelMap

    Raises
    ------
    ConfigError
        As :func:`load_case` for ``[signals]`` and ``[spectral]``; an unknown key in ``[map]`` or
        ``[test_points]``; a test-point source not in ``autopilot``, ``marker``, ``sweep``; an axis
        key that is not a whole number from 1 to 255; a name in ``axes`` or ``required`` that is
        not a spectral input (keys) or output (values); ``[test_points]`` without ``[spectral]``;
        ``min_duration_s`` < 0; mixed clocks (with ``one_clock``). The message names the file, the
        key path and the value.
    """
    ctx, data = _read_toml(path)
    _check_keys(ctx, data, tuple(dict.fromkeys(MAP_KEYS + CASE_KEYS)), "")
    if "signals" not in data:
        raise ctx.error("signals", "missing: a channel map needs a [signals] table")
    return _channel_map(ctx, data, ctx.path, one_clock=one_clock)


def _channel_map(ctx: _Ctx, data: Mapping[str, Any], path: Path, *, one_clock: bool) -> ChannelMap:
    """The :class:`ChannelMap` of checked top-level tables (``signals`` present)."""
    head = _parse_map_table(ctx, data["map"]) if "map" in data else {}
    signals = _parse_signals(ctx, data["signals"])
    if one_clock:
        _one_clock(ctx, signals)
    spectral = _parse_spectral(ctx, data["spectral"], signals) if "spectral" in data else None
    test_points = _parse_test_points(ctx, data["test_points"], spectral, signals) if "test_points" in data else None
    criteria = _parse_criteria(ctx, data["criteria"]) if "criteria" in data else Criteria()
    return ChannelMap(name=head.get("name", path.stem), description=head.get("description", ""),
                      needs=head.get("needs", ""), path=path, signals=signals, spectral=spectral,
                      test_points=test_points, vehicle=head.get("vehicle", {}), system=head.get("system"),
                      criteria=criteria, models=_parse_models(ctx, data, signals))


def channel_map_from_tables(tables: Mapping[str, Any], path: str | os.PathLike[str], *,
                            where: str | None = None) -> ChannelMap:
    """Validate channel-map tables that come from somewhere other than a TOML file (the monitor
    settings stored in a recording) exactly as :func:`read_channel_map` validates a map file, with
    every limit of :mod:`livesweep.limits` a map gets.

    Parameters
    ----------
    tables : mapping
        ``signals`` (required), ``spectral``, ``map``, ``test_points``, shaped as the TOML tables
        of a channel map (docs/case-file.md).
    path : str or os.PathLike
        The file the tables came from (the result's ``path``; its stem is the default name).
    where : str, optional
        How messages name the tables' origin, e.g. ``"rec.mcap: livesweep_settings.json"``;
        default ``path``.

    Returns
    -------
    ChannelMap

    Raises
    ------
    ConfigError
        As :func:`read_channel_map` (mixed clocks allowed); the message names ``where``, the key
        path and the value.
    """
    p = Path(path)
    ctx = _Ctx(where if where is not None else p)
    data = _table(ctx, tables, "settings")
    _check_keys(ctx, data, MAP_KEYS, "")
    if "signals" not in data:
        raise ctx.error("signals", "missing: monitor settings need a signals table")
    return _channel_map(ctx, data, p, one_clock=False)
