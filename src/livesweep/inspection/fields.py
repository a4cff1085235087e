"""The fields of a topic, listed with their units or types.

One job: name a message's numeric fields (dotted paths for nested values), the units a log
declares for them (MAVLink's message definitions, a channel's ``units`` metadata), and, for a
channel livesweep does not decode, every field its ROS message definition declares with its type.
"""

from __future__ import annotations

import json
import re

from livesweep.errors import ConfigError


def _numeric_fields(obj, prefix=""):
    if isinstance(obj, bool):
        return
    if isinstance(obj, (int, float)):
        yield prefix
    elif isinstance(obj, dict):
        for k, v in obj.items():
            yield from _numeric_fields(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(obj, list) and len(obj) <= 32:
        for i, v in enumerate(obj):
            yield from _numeric_fields(v, f"{prefix}.{i}" if prefix else str(i))


def _mavlink_units(topic: str) -> dict:
    if not topic.startswith("/mavlink/"):
        return {}
    try:
        from livesweep.telemetry.mavlink_codec import message_class

        cls = message_class(topic.split("/")[2])
    except (ConfigError, IndexError):
        return {}
    return dict(getattr(cls, "fieldunits_by_name", {}) or {})


def _channel_units(metadata) -> dict:
    """``{field: unit}`` from a channel's ``units`` metadata (DataFlash, tables); {} without."""
    raw = (metadata or {}).get("units")
    if raw:
        try:
            return {str(k): str(v) for k, v in json.loads(raw).items()}
        except (ValueError, AttributeError):
            pass
    return {}


#: ROS message definition types that are one number each (``bool`` is left out, as in JSON messages).
_ROS_NUMBERS = frozenset(("byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
                          "uint32", "int64", "uint64"))
_ROS_PRIMITIVES = _ROS_NUMBERS | {"bool", "string", "wstring"}
#: ROS 1 built-in types that are messages of two fields.
_ROS1_TIME = {"time": (("secs", "uint32"), ("nsecs", "uint32")), "duration": (("secs", "int32"), ("nsecs", "int32"))}
_ROS_TYPE = re.compile(r"^([A-Za-z_][\w/]*)(?:<=\d+)?(\[(?:<=)?(\d*)\])?$")


def _ros_fields(schema_name: str, text: str) -> tuple[list[tuple[str, str]] | None, str]:
    """Every field of a ``ros2msg`` / ``ros1msg`` definition, flattened (``stamp.sec``), with its
    type; ``(None, why)`` when the text cannot be read as one message definition."""
    if re.search(r"^---\s*$", text, flags=re.M):
        return None, "its schema is a service or action definition, not the message's own fields"
    sections = re.split(r"^={20,}\s*$", text, flags=re.M)
    defs: dict[str, str] = {}
    for sec in sections[1:]:
        body = sec.lstrip("\n")
        head, _, rest = body.partition("\n")
        if head.startswith("MSG:"):
            full = head[4:].strip()
            pkg, _, short = full.rpartition("/")
            for key in (full, f"{pkg.split('/')[0]}/msg/{short}", f"{pkg.split('/')[0]}/{short}"):
                defs.setdefault(key, rest)
    pkg = schema_name.split("/")[0] if "/" in schema_name else ""
    out: list[tuple[str, str]] = []

    def walk(body: str, prefix: str, package: str, depth: int) -> None:
        for line in body.splitlines():
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            parts = line.split()
            if len(parts) < 2 or "=" in parts[1] or "=" in parts[0]:
                continue                                   # a constant (NAME=value), not a field
            typ, name = parts[0], parts[1]
            m = _ROS_TYPE.match(typ)
            path = f"{prefix}.{name}" if prefix else name
            if m is None:
                out.append((path, typ))
                continue
            base, array = m.group(1), m.group(2)
            if array or base in _ROS_PRIMITIVES:
                out.append((path, typ))
                continue
            if base in _ROS1_TIME:
                out.extend((f"{path}.{n}", t) for n, t in _ROS1_TIME[base])
                continue
            own = base if "/" in base else f"{package}/{base}"
            full = own if own in defs else base.replace("/msg/", "/") if base.replace("/msg/", "/") in defs else ""
            if base == "Header" and not full:
                full = "std_msgs/Header" if "std_msgs/Header" in defs else ""
            if not full or depth > 8:
                out.append((path, typ))
                continue
            walk(defs[full], path, full.split("/")[0], depth + 1)

    walk(sections[0], "", pkg, 0)
    return out, ""


def _schema_fields(encoding: str, schema) -> tuple[tuple, str]:
    """``(fields, why not)`` of a channel livesweep does not decode, from its schema."""
    what = f"{encoding} messages" + (f" with a {schema.encoding} schema" if schema is not None and schema.encoding
                                     else " without a schema")
    if schema is None or schema.encoding not in ("ros2msg", "ros1msg"):
        return (), f"{what}: livesweep cannot list their fields"
    try:
        text = bytes(schema.data).decode("utf-8")
    except UnicodeDecodeError:
        return (), f"{what}: the schema is not UTF-8 text, its fields cannot be listed"
    fields, why = _ros_fields(schema.name, text)
    if fields is None:
        return (), f"{what} ({schema.name}): {why}, so they cannot be listed"
    return tuple(fields), ""
