"""The live monitor's inputs from short specs: what :func:`livesweep.monitor` and ``livesweep
monitor`` open.

A spec is one of:

- a MAVLink input url: ``udpin:HOST:PORT`` (``udp:`` is the same; port 0 picks a free port),
  ``tcp:HOST:PORT`` (connect to a server such as SITL), ``tcpin:HOST:PORT`` (listen for clients),
  a serial device (``/dev/ttyUSB0,57600``, ``COM3,57600``);
- ``zenoh:KEYEXPR``: JSON samples on a Zenoh key expression (e.g. ``zenoh:drone/**``);
- a source object (anything implementing ``livesweep.telemetry.frames.Source``), used as it is.

UDP links are read by the recorder process (:class:`~livesweep.telemetry.capture.LiveCapture`),
so a busy analysis cannot starve them; every other link is opened here, in this process.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

from livesweep.errors import ConfigError

__all__ = ["SourceSpec", "parse_source_spec", "open_source", "open_publisher", "zenoh_settings"]

#: What a MAVLink spec starts with (a serial device aside): its url scheme.
_MAVLINK_SCHEME = re.compile(r"^(udpin|udp|udpout|tcp|tcpin):")
#: A serial device: ``/dev/...`` or ``COMn``, with an optional ``,BAUD``.
_SERIAL = re.compile(r"^(/dev/\S+|COM\d+)(,\d+)?$", re.IGNORECASE)
ZENOH_PREFIX = "zenoh:"


@dataclass(frozen=True)
class SourceSpec:
    """One parsed spec.

    Attributes
    ----------
    kind : str
        ``"udpin"`` (read by the recorder process), ``"mavlink"`` (TCP or serial, read here),
        ``"zenoh"`` or ``"object"``.
    value : object
        The url, the key expression, or the source object.
    """

    kind: str
    value: object


def parse_source_spec(spec) -> SourceSpec:
    """What ``spec`` asks for; nothing is opened.

    Raises
    ------
    ConfigError
        One line naming ``spec`` when it is neither a MAVLink input url nor ``zenoh:KEYEXPR`` (a
        file path, ``udpout``, a port out of range, an empty key expression).
    """
    if isinstance(spec, os.PathLike):
        raise ConfigError(f"source {os.fspath(spec)!r} is a file, not a live link: livesweep.replay() reads "
                          "recordings (livesweep.convert.convert() turns other logs into MCAP first)")
    if not isinstance(spec, str):
        if not all(callable(getattr(spec, name, None)) for name in ("poll", "close")):
            raise ConfigError(f"source {spec!r} is neither a spec (a MAVLink url or zenoh:KEYEXPR) nor a source "
                              "object (livesweep.telemetry.frames.Source)")
        return SourceSpec("object", spec)
    if spec.startswith(ZENOH_PREFIX):
        key = spec[len(ZENOH_PREFIX):]
        if not key:
            raise ConfigError(f"source {spec!r}: give the Zenoh key expression after zenoh:, e.g. zenoh:drone/**")
        return SourceSpec("zenoh", key)
    from livesweep.telemetry.mavlink_in import parse_source_url

    if not (_MAVLINK_SCHEME.match(spec) or _SERIAL.match(spec)):
        raise ConfigError(f"source {spec!r} is neither a MAVLink input url (udpin:HOST:PORT, tcp:HOST:PORT, "
                          "tcpin:HOST:PORT, a serial device /dev/...[,BAUD]) nor zenoh:KEYEXPR")
    target = parse_source_url(spec)             # its messages name the url as given
    return SourceSpec("udpin" if target["kind"] == "udpin" else "mavlink", spec)


def zenoh_settings(config):
    """A ``zenoh.Config`` from ``config``: None, a JSON5 file's path, or a ``zenoh.Config`` as it is."""
    if config is None or not isinstance(config, (str, os.PathLike)):
        return config
    from livesweep.telemetry.zenoh_io import zenoh_config

    return zenoh_config(config_path=config)


def open_source(spec: SourceSpec, *, signing_key: bytes | None = None, zenoh_config=None,
                zenoh_listen: int | None = None):
    """Open one source of a spec that is not ``udpin`` (those go to the recorder process).

    Parameters
    ----------
    spec : SourceSpec
    signing_key : bytes, optional
        32-byte MAVLink 2 signing key (unsigned and forged frames are refused and counted).
    zenoh_config : zenoh.Config, optional
        As :func:`zenoh_settings` gives it.
    zenoh_listen : int, optional
        A Zenoh source listens on ``tcp/127.0.0.1:<port>`` (without ``zenoh_config``).
    """
    if spec.kind == "object":
        return spec.value
    if spec.kind == "mavlink":
        from livesweep.telemetry.mavlink_in import MavlinkSource

        return MavlinkSource(spec.value, signing_key=signing_key)
    if spec.kind == "zenoh":
        from livesweep.telemetry.zenoh_io import ZenohSource

        return ZenohSource(spec.value, config=zenoh_config, listen_port=zenoh_listen)
    raise ConfigError(f"source {spec.value!r}: udpin links are read by the recorder process, not opened here")


def open_publisher(zenoh_config=None, zenoh_listen: int | None = None):
    """The Zenoh publisher of the live results (``livesweep/...``), on the sources' session settings."""
    from livesweep.telemetry.zenoh_io import ZenohPublisher

    return ZenohPublisher(config=zenoh_config, connect_port=zenoh_listen)
