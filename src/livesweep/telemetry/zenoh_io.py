"""Zenoh input (JSON samples -> :class:`~livesweep.telemetry.frames.Frame`) and JSON output.

Configuration (docs/user-guide.md, Zenoh): a Zenoh peer listens on ``tcp/[::]:0`` (all
interfaces) unless told otherwise, and scouts by UDP multicast. :func:`zenoh_config` never
keeps that default: it listens on nothing, or on ``tcp/127.0.0.1:<port>``, with multicast and
gossip scouting off. Real deployments (routers, TLS, several machines) pass their own JSON5
file as ``config_path``; it is used as written, except that a file which names no listen
endpoints still does not get the all-interfaces listener.

Threads: Zenoh calls the subscriber callback on its own Python thread, holding the GIL.
:class:`ZenohSource`'s callback only appends ``(time, key, bytes)`` to a deque; JSON decoding
happens in :meth:`ZenohSource.poll`, on the caller's thread.

Payloads: a JSON object is one sample; a JSON array of objects is a block of samples (each
object becomes a frame, in order). Malformed JSON (also nested deeper than 32 levels, or an
integer with more digits than Python converts) and non-objects are counted, never fatal. A
stamp that is not a finite number, does not fit an MCAP time, or does not follow its key's recent
clock (:class:`~livesweep.telemetry.clock.StampClock`) leaves the frame without a vehicle time
(recorded with its receive time) and is counted in ``bad_stamp``. Receive times come from a
:func:`~livesweep.telemetry.clock.receive_ns` (they never step with the wall clock).
:class:`ZenohPublisher` puts with ``CongestionControl.BLOCK`` so results are not dropped.
"""

from __future__ import annotations

import collections
import json
import logging
import math
import os
import re
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from livesweep.errors import ConfigError, LivesweepError
from livesweep.numeric import json_safe
from livesweep.telemetry.clock import UINT64_NS_MAX, StampClock, receive_ns
from livesweep.telemetry.frames import Frame

__all__ = ["ZenohPublisher", "ZenohSource", "zenoh_config"]

log = logging.getLogger(__name__)

_MODES = ("peer", "client", "router")
_DEFAULT_LISTEN = zenoh.Config().get_json("listen/endpoints")
_WILD = ("*", "$", "?", "#")
# distinct sample keys a source takes (each becomes a recording channel); samples on further keys
# are counted in ``keys_over_limit`` and dropped, so a flood of keys cannot exhaust memory
_MAX_KEYS = 10_000
# telemetry records are flat; deeper JSON (which the recorder would have to re-encode) is malformed
_MAX_DEPTH = 32


def _endpoint(e: Any, what: str) -> str:
    """A port number -> ``tcp/127.0.0.1:<port>``; an endpoint string is kept as given."""
    if isinstance(e, bool):
        raise ConfigError(f"zenoh {what} endpoint {e!r} is not a port or an endpoint string")
    if isinstance(e, int):
        if not 0 <= e <= 65535:
            raise ConfigError(f"zenoh {what} port {e!r} is not in 0..65535")
        return f"tcp/127.0.0.1:{e}"
    if isinstance(e, str) and "/" in e and e.strip() == e and e:
        return e
    raise ConfigError(
        f"zenoh {what} endpoint {e!r} is not a port number or an endpoint such as 'tcp/127.0.0.1:7447'"
    )


def _insert(c: zenoh.Config, key: str, value: Any, where: str) -> None:
    try:
        c.insert_json5(key, json.dumps(value))
    except zenoh.ZError as e:
        raise ConfigError(f"zenoh config {where}: cannot set {key} = {value!r} ({e})") from None


def zenoh_config(
    *,
    listen: list[str | int] | None = None,
    connect: list[str | int] | None = None,
    mode: str | None = None,
    config_path: str | os.PathLike | None = None,
) -> zenoh.Config:
    """A Zenoh configuration that never listens on all interfaces by accident.

    Parameters
    ----------
    listen, connect : list of endpoint strings or ports, optional
        Ports become ``tcp/127.0.0.1:<port>``; strings (``"tcp/10.0.0.5:7447"``,
        ``"tls/host:7447"``) are used as given. Without ``config_path``, ``listen=None``
        listens on nothing and ``connect=None`` connects to nothing.
    mode : {"peer", "client", "router"}, optional
        Default ``"peer"`` (or the file's mode with ``config_path``).
    config_path : path, optional
        A user's Zenoh JSON5 file (routers, TLS, several machines), loaded with
        ``zenoh.Config.from_file``. Its settings are kept; ``listen`` / ``connect`` / ``mode``
        given here override it. What the file does not say stays as safe as without a file: a
        file that names no listen endpoints listens on nothing (not on Zenoh's default
        ``tcp/[::]:0``), and one that does not set ``enabled`` in its ``multicast`` (or ``gossip``)
        scouting block has it off (Zenoh's default is on: the session would announce itself on
        the network). Missing
        or invalid files raise :class:`ConfigError` naming the file.
    """
    if mode is not None and mode not in _MODES:
        raise ConfigError(f"zenoh mode {mode!r} is not one of {', '.join(_MODES)}")
    listen_eps = None if listen is None else [_endpoint(e, "listen") for e in _as_list(listen, "listen")]
    connect_eps = None if connect is None else [_endpoint(e, "connect") for e in _as_list(connect, "connect")]
    if config_path is not None:
        path = Path(config_path)
        if not path.is_file():
            raise ConfigError(f"zenoh config file {str(path)!r} does not exist or is not a file")
        try:
            c = zenoh.Config.from_file(str(path))
        except zenoh.ZError as e:
            first = str(e).strip().splitlines()
            raise ConfigError(f"zenoh config file {str(path)!r} is invalid: {' '.join(x.strip() for x in first)}") from None
        where = f"file {str(path)!r}"
        if mode is not None:
            _insert(c, "mode", mode, where)
        if listen_eps is not None:
            _insert(c, "listen/endpoints", listen_eps, where)
        elif c.get_json("listen/endpoints") == _DEFAULT_LISTEN:
            log.info("zenoh config %s names no listen endpoints: listening on none (not on all interfaces)", path)
            _insert(c, "listen/endpoints", [], where)
        if connect_eps is not None:
            _insert(c, "connect/endpoints", connect_eps, where)
        text = _without_comments(path.read_text(errors="replace"))
        for kind in ("multicast", "gossip"):
            if not _sets_key(text, kind, "enabled"):
                log.info("zenoh config %s does not set %s scouting's 'enabled': it stays off", path, kind)
                _insert(c, f"scouting/{kind}/enabled", False, where)
        return c
    c = zenoh.Config()
    where = "defaults"
    _insert(c, "mode", mode or "peer", where)
    _insert(c, "listen/endpoints", listen_eps or [], where)
    _insert(c, "connect/endpoints", connect_eps or [], where)
    _insert(c, "scouting/multicast/enabled", False, where)
    _insert(c, "scouting/gossip/enabled", False, where)
    return c


def _depth(value: Any) -> int:
    """Nesting depth of a parsed JSON value (iterative: any depth the parser accepted)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, dict):
            v = v.values()
        elif not isinstance(v, list):
            continue
        deepest = max(deepest, d)
        stack.extend((x, d + 1) for x in v)
    return deepest


_STRING_OR_COMMENT = re.compile(r'"(?:\\.|[^"\\])*"|\'(?:\\.|[^\'\\])*\'|//[^\n]*|/\*.*?\*/', re.S)


def _without_comments(text: str) -> str:
    """JSON5 text without ``//`` and ``/* */`` comments (strings, which may hold ``//``, are kept)."""
    return _STRING_OR_COMMENT.sub(lambda m: m.group(0) if m.group(0)[0] in "\"'" else " ", text)


def _sets_key(text: str, block: str, key: str) -> bool:
    """Whether JSON5 ``text`` sets ``key`` directly inside a ``block: { ... }`` object."""
    for m in re.finditer(rf"[\"']?\b{block}\b[\"']?\s*:\s*\{{", text):
        depth, i = 1, m.end()
        start = i
        while i < len(text) and depth:
            depth += {"{": 1, "}": -1}.get(text[i], 0)
            i += 1
        flat, prev = text[start:i - 1], None
        while flat != prev:                           # nested objects removed, innermost first
            prev, flat = flat, re.sub(r"\{[^{}]*\}", "", flat)
        if re.search(rf"[\"']?\b{key}\b[\"']?\s*:", flat):
            return True
    return False


def _as_list(v: Any, what: str) -> list:
    if isinstance(v, (str, int)):
        return [v]
    try:
        return list(v)
    except TypeError:
        raise ConfigError(f"zenoh {what} endpoints {v!r} are not a list") from None


def _session_config(config: zenoh.Config | None, listen_port: int | None, connect_port: int | None) -> zenoh.Config:
    if config is not None:
        if listen_port is not None or connect_port is not None:
            raise ConfigError("give either a zenoh config or listen_port/connect_port, not both")
        return config
    return zenoh_config(
        listen=None if listen_port is None else [listen_port],
        connect=None if connect_port is None else [connect_port],
    )


def _open(config: zenoh.Config, what: str) -> zenoh.Session:
    try:
        return zenoh.open(config)
    except zenoh.ZError as e:
        try:
            eps = config.get_json("listen/endpoints")
        except zenoh.ZError:  # pragma: no cover
            eps = "?"
        raise LivesweepError(f"zenoh {what}: cannot open a session (listen endpoints {eps}): {e}") from None


def _check_key_expr(k: Any, what: str) -> str:
    if not isinstance(k, str) or not k:
        raise ConfigError(f"zenoh {what} {k!r} is not a non-empty string")
    try:
        zenoh.KeyExpr(k)
    except zenoh.ZError as e:
        raise ConfigError(f"zenoh {what} {k!r} is invalid: {str(e).split(' at ', 1)[0]}") from None
    return k


class ZenohSource:
    """JSON samples on a Zenoh key expression, as frames (implements ``frames.Source``).

    Parameters
    ----------
    key_expr : str
        What to subscribe to, e.g. ``"vehicle/telemetry/**"``.
    config : zenoh.Config, optional
        A full configuration (see :func:`zenoh_config`). Otherwise ``listen_port`` /
        ``connect_port`` give a loopback peer (``tcp/127.0.0.1:<port>``).
    stamp_field : str, optional
        Name of a numeric field holding the vehicle time stamp; ``vehicle_ns`` is
        ``round(value * stamp_scale_ns_per_unit)`` (default scale 1e9: seconds). Missing,
        non-numeric, unrepresentable or implausible values give ``vehicle_ns=None`` and are
        counted in ``bad_stamp``.
    max_queue : int
        Samples buffered between polls (100 000: seconds of a busy link, about 100 MB at 1 kB a
        sample); beyond that, samples are dropped and counted in ``dropped_queue_full`` (the
        callback must never block the Zenoh thread).

    Frames: topic ``/zenoh/<sample key>``, ``receive_ns`` = the receive clock in the
    callback, ``data`` = the JSON object. ``counts``: ``received`` {key: frames},
    ``samples`` (Zenoh samples), ``malformed`` (not JSON / not UTF-8), ``non_object``
    (JSON values, or array items, that are not objects), ``deletes`` (DELETE samples,
    ignored), ``bad_stamp``, ``dropped_queue_full``, ``keys_over_limit`` (samples on keys beyond
    the first 10 000 distinct ones: dropped, so a flood of keys cannot exhaust memory).
    """

    #: A live link: the monitor records it and may shed analysis load, never recording.
    live = True

    def __init__(
        self,
        key_expr: str,
        *,
        config: zenoh.Config | None = None,
        listen_port: int | None = None,
        connect_port: int | None = None,
        stamp_field: str | None = None,
        stamp_scale_ns_per_unit: float = 1e9,
        max_queue: int = 100_000,
    ) -> None:
        self.key_expr = _check_key_expr(key_expr, "key expression")
        if stamp_field is not None and (not isinstance(stamp_field, str) or not stamp_field):
            raise ConfigError(f"stamp_field {stamp_field!r} must be a field name")
        try:
            scale = float(stamp_scale_ns_per_unit)
        except (TypeError, ValueError):
            raise ConfigError(f"stamp_scale_ns_per_unit {stamp_scale_ns_per_unit!r} is not a number") from None
        if not (math.isfinite(scale) and scale > 0):
            raise ConfigError(f"stamp_scale_ns_per_unit {stamp_scale_ns_per_unit!r} must be > 0")
        if isinstance(max_queue, bool) or not isinstance(max_queue, int) or max_queue <= 0:
            raise ConfigError(f"max_queue {max_queue!r} must be a positive integer")
        self.stamp_field = stamp_field
        self.stamp_scale_ns_per_unit = scale
        self._max_queue = max_queue
        self._q: collections.deque = collections.deque()
        self._event = threading.Event()
        self._dropped = 0
        self._received: dict[str, int] = {}
        self._counts = {"samples": 0, "malformed": 0, "non_object": 0, "deletes": 0, "bad_stamp": 0,
                        "keys_over_limit": 0}
        self._pending: collections.deque[Frame] = collections.deque()
        self._closed = False
        self._warned: set[str] = set()
        self._stamp_clocks: dict[str, StampClock] = {}
        cfg = _session_config(config, listen_port, connect_port)
        self._session = _open(cfg, f"source {key_expr!r}")
        try:
            self._sub = self._session.declare_subscriber(self.key_expr, self._on_sample)
        except BaseException:
            self._session.close()
            raise

    # Runs on a Zenoh Python thread with the GIL: append and return, nothing else.
    def _on_sample(self, sample: zenoh.Sample) -> None:
        q = self._q
        if len(q) >= self._max_queue:
            self._dropped += 1
            return
        now = receive_ns()
        if sample.kind == zenoh.SampleKind.DELETE:
            q.append((now, str(sample.key_expr), None))
        else:
            q.append((now, str(sample.key_expr), sample.payload.to_bytes()))
        ev = self._event
        if not ev.is_set():
            ev.set()

    @property
    def session(self) -> zenoh.Session:
        return self._session

    @property
    def counts(self) -> dict:
        c: dict[str, Any] = {"received": dict(self._received)}
        c.update(self._counts)
        c["dropped_queue_full"] = self._dropped
        return c

    @property
    def finished(self) -> bool:
        return False

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            log.warning("%s", text)

    def _stamp_ns(self, t_ns: int, key: str, obj: dict) -> int | None:
        """The sample's vehicle time [ns], or None (counted in ``bad_stamp``) when it cannot be trusted."""
        v = obj.get(self.stamp_field)
        vns = None
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            scale = self.stamp_scale_ns_per_unit
            try:
                vns = v * int(scale) if isinstance(v, int) and scale.is_integer() else int(round(v * scale))
            except (OverflowError, ValueError):      # inf, nan, beyond float range
                vns = None
        if vns is not None and 0 <= vns <= UINT64_NS_MAX:
            clock = self._stamp_clocks.get(key)
            if clock is None:
                clock = self._stamp_clocks[key] = StampClock(1e-9)
            if clock.feed(vns, t_ns * 1e-9) or clock.jump_held:
                return vns
        self._counts["bad_stamp"] += 1
        return None

    def _frame(self, t_ns: int, key: str, obj: dict, out: collections.deque) -> None:
        if key not in self._received and len(self._received) >= _MAX_KEYS:
            self._counts["keys_over_limit"] += 1
            self._warn_once("keys", f"zenoh {key}: more than {_MAX_KEYS} distinct keys; samples on further keys are "
                            "dropped and counted (keys_over_limit)")
            return
        vns = None if self.stamp_field is None else self._stamp_ns(t_ns, key, obj)
        self._received[key] = self._received.get(key, 0) + 1
        out.append(Frame(f"/zenoh/{key}", t_ns, vns, obj))

    def _decode(self, t_ns: int, key: str, payload: bytes | None, out: collections.deque) -> None:
        c = self._counts
        c["samples"] += 1
        if payload is None:
            c["deletes"] += 1
            return
        try:
            value = json.loads(payload)
        except (ValueError, UnicodeDecodeError, RecursionError):
            c["malformed"] += 1
            self._warn_once("malformed", f"zenoh {key}: payload is not JSON (further ones are only counted)")
            return
        if (payload.count(b"{") + payload.count(b"[") > _MAX_DEPTH) and _depth(value) > _MAX_DEPTH:
            c["malformed"] += 1
            self._warn_once("deep", f"zenoh {key}: JSON nested deeper than {_MAX_DEPTH} levels (further ones are "
                            "only counted)")
            return
        if isinstance(value, dict):
            self._frame(t_ns, key, value, out)
        elif isinstance(value, list):
            for item in value:
                if isinstance(item, dict):
                    self._frame(t_ns, key, item, out)
                else:
                    c["non_object"] += 1
        else:
            c["non_object"] += 1
            self._warn_once("non_object", f"zenoh {key}: JSON payload is not an object (further ones are only counted)")

    def _drain(self, out: list[Frame], max_frames: int) -> None:
        pend = self._pending
        q = self._q
        while len(out) < max_frames:
            if pend:
                out.append(pend.popleft())
                continue
            try:
                t_ns, key, payload = q.popleft()
            except IndexError:
                break
            self._decode(t_ns, key, payload, pend)

    @property
    def waiting(self) -> int:
        """Samples received and not yet handed out (what a stop at this moment would not record)."""
        return len(self._q) + len(self._pending)

    def poll(self, timeout_s: float = 0.05, max_frames: int = 10_000) -> list[Frame]:
        """Frames received since the last call (waits up to ``timeout_s`` only when there are none)."""
        if self._closed:
            raise LivesweepError(f"zenoh source {self.key_expr!r} is closed")
        out: list[Frame] = []
        deadline = time.monotonic() + max(float(timeout_s or 0.0), 0.0)
        while True:
            self._event.clear()  # before looking: a sample appended later sets it again
            self._drain(out, max_frames)
            if out:
                return out
            left = deadline - time.monotonic()
            if left <= 0:
                return out
            self._event.wait(left)

    def close(self) -> None:
        """Undeclare the subscriber and close the session (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._sub.undeclare()
        except zenoh.ZError:  # pragma: no cover - session already gone
            pass
        try:
            self._session.close()
        except zenoh.ZError:  # pragma: no cover
            pass

    def __enter__(self) -> "ZenohSource":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class ZenohPublisher:
    """Publish JSON under ``<prefix>/<key>`` with ``CongestionControl.BLOCK`` (nothing dropped).

    ``config`` or ``listen_port``/``connect_port`` as for :class:`ZenohSource`. Non-finite
    floats (NaN, inf: not JSON) are published as ``"NaN"`` / ``"Infinity"`` / ``"-Infinity"``, as
    in the recording, and counted in ``non_finite``.
    ``published`` counts puts per key.
    """

    def __init__(
        self,
        *,
        config: zenoh.Config | None = None,
        listen_port: int | None = None,
        connect_port: int | None = None,
        prefix: str = "livesweep",
    ) -> None:
        self.prefix = _check_key_expr(prefix, "prefix")
        if any(w in prefix for w in _WILD):
            raise ConfigError(f"zenoh prefix {prefix!r} must not contain wildcards")
        cfg = _session_config(config, listen_port, connect_port)
        self._session = _open(cfg, f"publisher {prefix!r}")
        self._pubs: dict[str, Any] = {}
        self._closed = False
        self.published: dict[str, int] = {}
        self.non_finite = 0

    @property
    def session(self) -> zenoh.Session:
        return self._session

    def _publisher(self, key: str) -> Any:
        pub = self._pubs.get(key)
        if pub is None:
            if not isinstance(key, str) or any(w in key for w in _WILD):
                raise ConfigError(f"zenoh publish key {key!r} must be a string without wildcards")
            full = _check_key_expr(f"{self.prefix}/{key}", "publish key")
            pub = self._session.declare_publisher(
                full,
                congestion_control=zenoh.CongestionControl.BLOCK,
                encoding=zenoh.Encoding.APPLICATION_JSON,
            )
            self._pubs[key] = pub
        return pub

    def publish(self, key: str, payload: dict | list) -> None:
        """Put ``payload`` (a JSON object, or a list of objects = a block) as JSON."""
        if self._closed:
            raise LivesweepError("zenoh publisher is closed")
        if not isinstance(payload, (dict, list)):
            raise ConfigError(f"zenoh payload for {key!r} must be a dict (or a list of dicts), got {type(payload).__name__}")
        try:
            text = json.dumps(payload, allow_nan=False, separators=(",", ":"))
        except ValueError:
            clean, n = json_safe(payload)
            self.non_finite += n
            try:
                text = json.dumps(clean, allow_nan=False, separators=(",", ":"))
            except (TypeError, ValueError) as e:
                raise ConfigError(f"zenoh payload for {key!r} is not JSON-serialisable: {e}") from None
        except TypeError as e:
            raise ConfigError(f"zenoh payload for {key!r} is not JSON-serialisable: {e}") from None
        pub = self._publisher(key)
        pub.put(text.encode())
        self.published[key] = self.published.get(key, 0) + 1

    def close(self) -> None:
        """Undeclare the publishers and close the session (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for pub in self._pubs.values():
            try:
                pub.undeclare()
            except zenoh.ZError:  # pragma: no cover
                pass
        self._pubs.clear()
        try:
            self._session.close()
        except zenoh.ZError:  # pragma: no cover
            pass

    def __enter__(self) -> "ZenohPublisher":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
