"""Send a recorded log over MAVLink as the vehicle sent it: ``livesweep stream``.

The monitor is tested on real autopilot output, streamed live. A log is recognised by content
(:func:`~livesweep.convert.common.sniff_format`, never by its name) and sent, paced by its own
clock at ``speed`` x real time (0: as fast as possible), through
:class:`~livesweep.telemetry.mavlink_out.MavlinkSender` and
:func:`~livesweep.telemetry.mavlink_out.stream_records`.

MAVLink telemetry log (``.tlog``)
    Every MAVLink frame the ground station recorded, byte for byte (MAVLink 1 or 2, the
    recorded sequence numbers, system ids and signatures), one frame per datagram, paced by
    the tlog's record times [µs since the UNIX epoch]. Framing is
    :meth:`~livesweep.telemetry.mavlink_in.TlogSource.raw_records`'s, so a monitor receiving
    the stream records what ``livesweep convert`` makes of the same tlog. Frames that do not
    decode (a CRC that fails) are sent as recorded too: the receiver counts them, as convert
    skips them. Non-MAVLink bytes between records are not sent.

ArduPilot DataFlash log (``.bin``, ArduCopter)
    The telemetry ArduCopter itself sends for what the log holds (values from
    :func:`~livesweep.convert.dataflash.iter_dataflash`: units declared by FMTU, multipliers
    applied), system 1, component 1, MAVLink 2:

    ====================  =========================================  ==================================
    MAVLink               from DataFlash                             ArduCopter stream
    ====================  =========================================  ==================================
    HEARTBEAT             MODE (custom_mode = its mode number), EV   none: always sent, 1 Hz
                          (armed, landed), MSG ``Frame: ...``
    STATUSTEXT            MSG (severity INFO, text in 50-character   none: sent when it happens
                          chunks)
    ATTITUDE              ATT Roll/Pitch/Yaw [deg -> rad, yaw        EXTRA1 (``SRx_EXTRA1``)
                          wrapped to -pi..pi], RATE R/P/Y
                          [deg/s -> rad/s] of the same TimeUS
    PID_TUNING            PIDR/PIDP/PIDY/PIDA -> axis 1/2/3/4:       EXTRA1, the axes in GCS_PID_MASK
                          desired = Tar, achieved = Act, FF, P, I,   (here every axis the log holds)
                          D, SRate, PDmod = Dmod
    SERVO_OUTPUT_RAW      RCOU Cn -> servon_raw (port 0)             RC_CHANNELS (``SRx_RC_CHAN``)
    RAW_IMU               IMU instance 0: mg, mrad/s, cdegC, no mag  RAW_SENSORS (``SRx_RAW_SENS``)
    SCALED_IMU2, _IMU3    IMU instances 1 and 2, same units          RAW_SENSORS
    PARAM_VALUE           PARM: every parameter's value at the       none: a ground station's fetch
                          slice start (index 0..n-1 of n), then      when it connects, and the echo
                          each change when it is logged              of a parameter set
    ====================  =========================================  ==================================

    Time fields come from TimeUS: ``time_boot_ms = TimeUS // 1000``, ``time_usec = TimeUS``
    (``SERVO_OUTPUT_RAW.time_usec`` is a uint32 and wraps as ArduPilot's ``micros()`` does).
    Each message goes out at the rate its source has in the log (the SystemID logs: 400 Hz for
    ATTITUDE and each PID_TUNING axis, 10 Hz SERVO_OUTPUT_RAW, 50 Hz RAW_IMU), or at most
    ``rate_hz`` of them per log second per message (and PID axis, IMU instance), the first in
    each ``1/rate_hz`` interval: what a telemetry stream rate (``SRx_EXTRA1 = 50``) gives. A
    radio link carries far less than 400 Hz; HEARTBEAT, STATUSTEXT and PARAM_VALUE are never thinned.

    As ArduCopter builds them: ``base_mode`` = CUSTOM_MODE_ENABLED | STABILIZE_ENABLED |
    MANUAL_INPUT_ENABLED, plus SAFETY_ARMED while armed (GUIDED_ENABLED, which ArduCopter sets
    while its position controller runs, is not known from these messages and never set).
    ``system_status`` is STANDBY while landed and ACTIVE in flight (a failsafe's CRITICAL is not
    modelled). ArduPilot logs only while armed unless ``LOG_DISARMED`` is set, so a log starts
    armed and landed; EV 10/11 (ARMED/DISARMED) and 18/28 (LAND_COMPLETE/NOT_LANDED) change
    that. The vehicle type follows the ``Frame: <CLASS>/...`` message from when it is logged
    (quadrotor before), ``custom_mode`` the MODE records (0, STABILIZE, before the first). A mode,
    arming or landing state set before ``start_s`` holds in the first heartbeats.
    ATTITUDE's rates come from the RATE record with the ATT record's TimeUS (ArduCopter writes
    both from the same loop), else from the latest RATE before it (NaN when there is none).

Times and the slice sent
    ``start_s`` and ``end_s`` are seconds after the log's first time stamp (the tlog's first
    record, the DataFlash log's first TimeUS). Heartbeats are at ``start`` + k s. A record whose
    time stamp is earlier than the one before it (DataFlash types written by different
    threads) goes out in file order at the time of the one before; such records are counted
    (``stepped_back``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

from livesweep.convert.common import sniff_format
from livesweep.errors import ConfigError, LogFormatError
from livesweep.telemetry.mavlink_out import MavlinkSender, parse_url, stream_records
from livesweep.monitor.vehicle import ARDUPILOT_AUTOPILOT, FRAME_CLASS_MAV_TYPES, frame_of_text

__all__ = ["LogMessages", "StreamSummary", "dataflash_messages", "sniff_log", "stream_log", "tlog_messages"]

_FORMAT_NAMES = {"tlog": "MAVLink tlog", "dataflash": "ArduPilot DataFlash"}

# MAVLink constants (common.xml), as ArduCopter uses them
_MAV_TYPE_QUADROTOR = 2
_BASE_MODE = 1 | 16 | 64            # CUSTOM_MODE_ENABLED | STABILIZE_ENABLED | MANUAL_INPUT_ENABLED
_SAFETY_ARMED = 128
_MAV_STATE_STANDBY, _MAV_STATE_ACTIVE = 3, 4
_MAV_SEVERITY_INFO = 6
_STATUSTEXT_LEN = 50
# DataFlash EV ids (AP_Logger LogEvent)
_EV_ARMED, _EV_DISARMED, _EV_LAND_COMPLETE, _EV_NOT_LANDED = 10, 11, 18, 28
_PID_AXES = {"PIDR": 1, "PIDP": 2, "PIDY": 3, "PIDA": 4}     # PID_TUNING_ROLL .. PID_TUNING_ACCZ
_IMU_MESSAGES = {0: "RAW_IMU", 1: "SCALED_IMU2", 2: "SCALED_IMU3"}
_GRAVITY_MSS = 9.80665
# FMT too: the first FMT record carries the log's first time stamp (records without one take it)
_DATAFLASH_TYPES = frozenset({"FMT", "MODE", "MSG", "EV", "ATT", "RATE", "RCOU", "IMU", "PARM", *_PID_AXES})
_MAV_PARAM_TYPE_REAL32 = 9
_UNTHINNED = ("HEARTBEAT", "STATUSTEXT", "PARAM_VALUE")


def sniff_log(path) -> str:
    """``"tlog"`` or ``"dataflash"``: the format of ``path`` by content.

    Raises
    ------
    LogFormatError
        Missing or empty file, or one that is neither (naming the file and what it is).
    """
    fmt = sniff_format(path)
    if fmt not in _FORMAT_NAMES:
        raise LogFormatError(f"{path}: a {fmt} file, not a log livesweep stream sends (a MAVLink .tlog or an "
                             "ArduPilot DataFlash .bin, recognised by content)")
    return fmt


def _check_window(start_s: Any, end_s: Any) -> tuple[float, float]:
    try:
        s = float(start_s)
        e = math.inf if end_s is None else float(end_s)
    except (TypeError, ValueError):
        raise ConfigError(f"--start-s {start_s!r} / --end-s {end_s!r} must be numbers of seconds") from None
    if not (math.isfinite(s) and s >= 0):
        raise ConfigError(f"--start-s must be a finite number of seconds >= 0, got {start_s!r}")
    if math.isnan(e) or e <= s:
        raise ConfigError(f"--end-s must be after --start-s ({s:g} s), got {end_s!r}")
    return s, e


class LogMessages:
    """The MAVLink messages a log gives, in send order: iterate for ``(log time [s], msgname, payload)``.

    Made by :func:`tlog_messages` (payload: the frame's bytes) or :func:`dataflash_messages`
    (payload: a record for :meth:`MavlinkSender.send_record`). One pass; the file is checked
    when this is made. Iterating a slice that holds nothing raises :class:`LogFormatError`.

    Attributes
    ----------
    path : Path
    format : str
        ``"tlog"`` or ``"dataflash"``.
    start_s, end_s : float
        The slice asked for [s after the log's first time stamp]; ``end_s`` may be ``inf``.
    first_us, last_us : int or None
        The log's first time stamp and the latest one read [µs, the log's clock: UNIX time for
        a tlog, time since boot for DataFlash].
    sent_first_us, sent_last_us : int or None
        Log times of the first and last message iterated [µs].
    stepped_back : int
        Messages whose time stamp was earlier than the one before (given that one's time).
    undecodable : int
        tlog frames that do not decode (given as recorded).
    spans : dict of str -> [int, int, int]
        Per message name: log times of its first and last message iterated [µs] and how many.
    """

    def __init__(self, path: Path, fmt: str, start_s: float, end_s: float, items: Iterator[tuple[int, str, Any]],
                 closer: Any = None) -> None:
        self.path, self.format = path, fmt
        self.start_s, self.end_s = start_s, end_s
        self._start_us = round(start_s * 1e6)
        self._end_us = None if math.isinf(end_s) else round(end_s * 1e6)
        self.first_us: int | None = None
        self.last_us: int | None = None
        self.sent_first_us: int | None = None
        self.sent_last_us: int | None = None
        self.stepped_back = 0
        self.undecodable = 0
        self.spans: dict[str, list[int]] = {}
        self._items = items
        self._closer = closer

    def __iter__(self) -> Iterator[tuple[float, str, Any]]:
        prev = None
        spans = self.spans
        for t_us, name, payload in self._items:
            if prev is not None and t_us < prev:
                self.stepped_back += 1
                t_us = prev
            if prev is None:
                self.sent_first_us = t_us
            prev = self.sent_last_us = t_us
            span = spans.get(name)
            if span is None:
                spans[name] = [t_us, t_us, 1]
            else:
                span[1] = t_us
                span[2] += 1
            yield t_us * 1e-6, name, payload
        if prev is None:
            what = "no MAVLink frames" if self.format == "tlog" else "no record livesweep stream sends"
            if self.first_us is None:
                raise LogFormatError(f"{self.path}: holds {what}")
            span = (self.last_us - self.first_us) * 1e-6
            raise LogFormatError(f"{self.path}: nothing to send from {self.start_s:g} s to {self.end_s:g} s after the "
                                 f"log's first time stamp (its records read run to {span:.3f} s)")

    def _note(self, t_us: int) -> None:
        """A record of the log was read, stamped ``t_us`` [µs]."""
        if self.first_us is None:
            self.first_us = t_us
        self.last_us = t_us

    def _where(self, t_us: int) -> int:
        """-1 when log time ``t_us`` [µs] is before the slice, 0 inside, 1 after."""
        rel = t_us - (self.first_us if self.first_us is not None else t_us)
        if rel < self._start_us:
            return -1
        return 1 if self._end_us is not None and rel > self._end_us else 0

    @property
    def slice_start_us(self) -> int | None:
        """Log time where the slice starts [µs], once the first record is read."""
        return None if self.first_us is None else self.first_us + self._start_us

    def close(self) -> None:
        """Release the file (idempotent)."""
        if self._closer is not None:
            self._closer.close()


# ----------------------------------------------------------------------------------- tlog


def tlog_messages(path, *, start_s: float = 0.0, end_s: float | None = None) -> LogMessages:
    """A tlog's MAVLink frames as recorded, with their record times.

    Parameters
    ----------
    path : str or Path
        The tlog (recognised by content).
    start_s, end_s : float
        The slice to send [s after the first record's time stamp]; default all of it.

    Returns
    -------
    LogMessages
        Items ``(record time [s since the UNIX epoch], message name, frame bytes)``; the name is
        pymavlink's (``BAD_DATA`` for a frame that does not decode).

    Raises
    ------
    LogFormatError
        ``path`` is not a tlog (naming it).
    ConfigError
        A bad slice.
    """
    from livesweep.telemetry.mavlink_in import TlogSource

    start, end = _check_window(start_s, end_s)
    path = Path(path)
    source = TlogSource(path)

    def items() -> Iterator[tuple[int, str, bytes]]:
        for ts_us, frame, msg in source.raw_records():
            out._note(ts_us)
            where = out._where(ts_us)
            if where < 0:
                continue
            if where > 0:
                return
            name = msg.get_type()
            if name == "BAD_DATA":
                out.undecodable += 1
            yield ts_us, name, frame

    out = LogMessages(path, "tlog", start, end, items(), closer=source)
    return out


# ----------------------------------------------------------------------------------- DataFlash


def _check_rate(rate_hz: Any) -> float | None:
    if rate_hz is None:
        return None
    try:
        r = float(rate_hz)
    except (TypeError, ValueError):
        raise ConfigError(f"--rate-hz {rate_hz!r} is not a number") from None
    if not (math.isfinite(r) and r > 0):
        raise ConfigError(f"--rate-hz must be a positive number of messages per second, got {rate_hz!r}")
    return r


def _i16(x: float) -> int:
    """C's float -> int16_t conversion as ArduPilot's senders do it (truncation), saturated."""
    if not math.isfinite(x):
        return 0
    return max(-32768, min(32767, int(x)))


class _Vehicle:
    """ArduCopter's state as its log tells it, and the MAVLink records it would send."""

    def __init__(self) -> None:
        self.mode = 0
        self.armed = True            # ArduPilot logs only while armed (LOG_DISARMED = 0)
        self.landed = True
        self.mav_type = _MAV_TYPE_QUADROTOR
        self.statustext_id = 0

    def note(self, name: str, v: Mapping[str, Any]) -> None:
        if name == "MODE":
            num = v.get("ModeNum", v.get("Mode"))
            if isinstance(num, int):
                self.mode = num
        elif name == "EV":
            ev = v.get("Id")
            if ev == _EV_ARMED:
                self.armed = True
            elif ev == _EV_DISARMED:
                self.armed = False
            elif ev == _EV_LAND_COMPLETE:
                self.landed = True
            elif ev == _EV_NOT_LANDED:
                self.landed = False
        elif name == "MSG":
            text = str(v.get("Message", ""))
            frame = frame_of_text(text)
            if frame is not None:
                self.mav_type = FRAME_CLASS_MAV_TYPES.get(frame[0], self.mav_type)

    def heartbeat(self) -> dict:
        return {"type": self.mav_type, "autopilot": ARDUPILOT_AUTOPILOT,
                "base_mode": _BASE_MODE | (_SAFETY_ARMED if self.armed else 0), "custom_mode": self.mode,
                "system_status": _MAV_STATE_STANDBY if self.landed else _MAV_STATE_ACTIVE, "mavlink_version": 3}

    def statustexts(self, text: str) -> list[dict]:
        """One STATUSTEXT, or 50-character chunks with a common id (MAVLink 2 long text)."""
        text = text.encode("ascii", "replace").decode("ascii").replace("\x00", "")
        if len(text) <= _STATUSTEXT_LEN:
            return [{"severity": _MAV_SEVERITY_INFO, "text": text, "id": 0, "chunk_seq": 0}]
        self.statustext_id = self.statustext_id % 65535 + 1
        chunks = [text[i:i + _STATUSTEXT_LEN] for i in range(0, len(text), _STATUSTEXT_LEN)]
        if len(chunks[-1]) == _STATUSTEXT_LEN:
            chunks.append("")        # a short last chunk ends the text
        return [{"severity": _MAV_SEVERITY_INFO, "text": c, "id": self.statustext_id, "chunk_seq": k}
                for k, c in enumerate(chunks)]


def _attitude(t_us: int, att: Mapping[str, Any], rate: Mapping[str, Any] | None) -> dict:
    yaw = math.radians(att["Yaw"])
    if yaw > math.pi:                 # ATT.Yaw is 0..360 deg; ArduPilot sends the AHRS yaw in -pi..pi
        yaw -= 2 * math.pi
    r = rate or {}
    return {"time_boot_ms": t_us // 1000, "roll": math.radians(att["Roll"]), "pitch": math.radians(att["Pitch"]),
            "yaw": yaw, "rollspeed": math.radians(r.get("R", math.nan)),
            "pitchspeed": math.radians(r.get("P", math.nan)), "yawspeed": math.radians(r.get("Y", math.nan))}


def _servo_output(t_us: int, v: Mapping[str, Any]) -> dict:
    rec = {"time_usec": t_us & 0xFFFFFFFF, "port": 0}
    for k in range(1, 17):
        rec[f"servo{k}_raw"] = int(v.get(f"C{k}", 0))
    return rec


def _pid_tuning(axis: int, v: Mapping[str, Any]) -> dict:
    g = v.get
    return {"axis": axis, "desired": g("Tar", 0.0), "achieved": g("Act", 0.0), "FF": g("FF", 0.0), "P": g("P", 0.0),
            "I": g("I", 0.0), "D": g("D", 0.0), "SRate": g("SRate", 0.0), "PDmod": g("Dmod", 0.0)}


def _param_value(name: str, value: float, index: int, count: int) -> dict:
    return {"param_id": name[:16], "param_value": float(value), "param_type": _MAV_PARAM_TYPE_REAL32,
            "param_count": count, "param_index": index}


def _imu(msgname: str, t_us: int, v: Mapping[str, Any]) -> dict:
    rec: dict[str, Any] = {"time_usec": t_us} if msgname == "RAW_IMU" else {"time_boot_ms": t_us // 1000}
    for ax in "xyz":
        rec[f"{ax}acc"] = _i16(v.get(f"Acc{ax.upper()}", 0.0) * 1000.0 / _GRAVITY_MSS)
    for ax in "xyz":
        rec[f"{ax}gyro"] = _i16(v.get(f"Gyr{ax.upper()}", 0.0) * 1000.0)
    for ax in "xyz":
        rec[f"{ax}mag"] = 0
    if msgname == "RAW_IMU":
        rec["id"] = 0
    rec["temperature"] = _i16(v.get("T", 0.0) * 100.0)
    return rec


def dataflash_messages(path, *, start_s: float = 0.0, end_s: float | None = None,
                       rate_hz: float | None = None, sysid: int = 1) -> LogMessages:
    """The MAVLink telemetry ArduCopter sends for what a DataFlash log holds (module docstring).

    Parameters
    ----------
    path : str or Path
        The DataFlash log (recognised by content).
    start_s, end_s : float
        The slice to send [s after the log's first TimeUS]; default all of it.
    rate_hz : float, optional
        At most this many messages of each kind (and PID axis, IMU instance) per second of log
        time [Hz]; default the log's own rate.
    sysid : int
        The MAVLink system id the vehicle sends as (1..255; component 1).

    Returns
    -------
    LogMessages
        Items ``(TimeUS [s since boot], message name, record)``.

    Raises
    ------
    LogFormatError
        ``path`` is not a DataFlash log, or is mostly corruption (naming it).
    ConfigError
        A bad slice or rate.
    """
    from livesweep.convert.dataflash import iter_dataflash

    start, end = _check_window(start_s, end_s)
    rate = _check_rate(rate_hz)
    if isinstance(sysid, bool) or not isinstance(sysid, int) or not 1 <= sysid <= 255:
        raise ConfigError(f"sysid {sysid!r} must be an integer from 1 to 255")
    path = Path(path)
    records = iter_dataflash(path, names=_DATAFLASH_TYPES)      # LogFormatError naming the file

    def timeline() -> Iterator[tuple[int, str, dict]]:
        """(TimeUS, msgname, record) in log order, heartbeats every second from the slice start."""
        vehicle = _Vehicle()
        params: dict[str, float] = {}              # PARM: every parameter's latest value
        dumped = False                             # the values at the slice start were sent
        att: tuple[int, dict] | None = None        # the ATT record waiting for its RATE
        rate_rec: tuple[int, dict] | None = None   # the latest RATE
        next_hb: int | None = None                 # TimeUS of the next heartbeat
        for t_us, name, v in records:
            out._note(t_us)
            if next_hb is None:
                next_hb = out.slice_start_us
            if name == "PARM" and not (isinstance(v.get("Name"), str) and isinstance(v.get("Value"), (int, float))):
                continue
            if t_us < out.slice_start_us:           # before the slice: only the state carries over
                if name == "PARM":
                    params[v["Name"]] = float(v["Value"])
                elif name == "RATE":
                    rate_rec = (t_us, v)
                elif name in ("MODE", "EV", "MSG"):
                    vehicle.note(name, v)
                continue
            if att is not None and not (name == "RATE" and t_us == att[0]):
                yield att[0], "ATTITUDE", _attitude(att[0], att[1], rate_rec and rate_rec[1])
                att = None
            while next_hb < t_us:
                yield next_hb, "HEARTBEAT", vehicle.heartbeat()
                next_hb += 1_000_000
            if not dumped:                          # a ground station fetches every parameter as it connects
                dumped = True
                for k, (pname, pvalue) in enumerate(params.items()):
                    yield t_us, "PARAM_VALUE", _param_value(pname, pvalue, k, len(params))
            if name == "PARM":                       # a parameter set during the slice: the vehicle echoes it
                params[v["Name"]] = float(v["Value"])
                yield t_us, "PARAM_VALUE", _param_value(v["Name"], v["Value"], list(params).index(v["Name"]),
                                                        len(params))
            elif name == "ATT":
                if rate_rec is not None and rate_rec[0] == t_us:
                    yield t_us, "ATTITUDE", _attitude(t_us, v, rate_rec[1])
                else:
                    att = (t_us, v)
            elif name == "RATE":
                rate_rec = (t_us, v)
                if att is not None:
                    yield t_us, "ATTITUDE", _attitude(t_us, att[1], v)
                    att = None
            elif name in _PID_AXES:
                yield t_us, "PID_TUNING", _pid_tuning(_PID_AXES[name], v)
            elif name == "RCOU":
                yield t_us, "SERVO_OUTPUT_RAW", _servo_output(t_us, v)
            elif name == "IMU":
                msgname = _IMU_MESSAGES.get(v.get("I", 0))
                if msgname is not None:
                    yield t_us, msgname, _imu(msgname, t_us, v)
            elif name == "MSG":
                vehicle.note(name, v)
                for rec in vehicle.statustexts(str(v.get("Message", ""))):
                    yield t_us, "STATUSTEXT", rec
            else:
                vehicle.note(name, v)
        if att is not None:
            yield att[0], "ATTITUDE", _attitude(att[0], att[1], rate_rec and rate_rec[1])
        if next_hb is not None and out.last_us is not None:
            while next_hb <= out.last_us:
                yield next_hb, "HEARTBEAT", vehicle.heartbeat()
                next_hb += 1_000_000

    def items() -> Iterator[tuple[int, str, dict]]:
        last_bin: dict[Any, int] = {}
        for t_us, name, rec in timeline():
            where = out._where(t_us)
            if where < 0:
                continue
            if where > 0:
                return
            if rate is not None and name not in _UNTHINNED:
                key = (name, rec.get("axis"))
                k = (t_us - out.slice_start_us) * rate // 1_000_000
                if last_bin.get(key) == k:
                    continue
                last_bin[key] = k
            rec["sysid"], rec["compid"] = sysid, 1
            yield t_us, name, rec

    out = LogMessages(path, "dataflash", start, end, items())
    return out


# ----------------------------------------------------------------------------------- sending


class _RawFrames:
    """:func:`stream_records`' sender interface for frames that are already encoded (tlog records)."""

    def __init__(self, sender: MavlinkSender) -> None:
        self._sender = sender

    @property
    def send_errors(self) -> int:
        return self._sender.send_errors

    def send_record(self, msgname: str, frame: bytes) -> None:
        self._sender.send_frame(frame, msgname)

    def send_heartbeat(self) -> None:  # pragma: no cover - stream_records is called without heartbeats
        raise AssertionError("a tlog carries its own heartbeats")


@dataclass(frozen=True)
class StreamSummary:
    """What :func:`stream_log` sent.

    Attributes
    ----------
    source : Path
    format : str
        ``"tlog"`` or ``"dataflash"``.
    url : str
    speed : float
        Asked pace [x real time]; 0 = as fast as possible.
    rate_hz : float or None
        The cap on each message's rate [Hz of log time] (DataFlash), None for none.
    log_first_s : float
        The log's first time stamp [s, its own clock: UNIX time (tlog) or since boot (DataFlash)].
    start_s, end_s : float
        The span sent [s after ``log_first_s``]: first and last message.
    wall_duration_s : float
        How long the sending took [s].
    sent : dict of str -> int
        Messages written, per MAVLink message name.
    rates_hz : dict of str -> float
        Per message name: its rate over its own span of log time [Hz] ((n - 1) / span; NaN for
        a single message), e.g. 400 for ATTITUDE from a 400 Hz ATT whatever the rest of the log.
    send_errors : int
        Messages that could not be written.
    max_lateness_s : float
        Most a message went out after its due time [s] (0 unpaced).
    stepped_back : int
        Messages whose time stamp stepped back (sent at the time of the one before).
    undecodable : int
        tlog frames that do not decode, sent as recorded (in ``sent`` as ``BAD_DATA``).
    """

    source: Path
    format: str
    url: str
    speed: float
    rate_hz: float | None
    log_first_s: float
    start_s: float
    end_s: float
    wall_duration_s: float
    sent: dict
    rates_hz: dict
    send_errors: int
    max_lateness_s: float
    stepped_back: int
    undecodable: int

    @property
    def n_sent(self) -> int:
        """Messages written."""
        return sum(self.sent.values())

    @property
    def log_duration_s(self) -> float:
        """Log time the messages sent span [s]."""
        return self.end_s - self.start_s

    @property
    def achieved_speed(self) -> float:
        """Log time sent per wall time [x real time] (inf when it took no measurable time)."""
        return self.log_duration_s / self.wall_duration_s if self.wall_duration_s > 0 else math.inf

    @property
    def message_rate_hz(self) -> float:
        """Messages written per wall second [1/s]."""
        return self.n_sent / self.wall_duration_s if self.wall_duration_s > 0 else math.inf


def _check_speed(speed: Any) -> float:
    try:
        s = float(speed)
    except (TypeError, ValueError):
        raise ConfigError(f"--speed {speed!r} is not a number") from None
    if math.isnan(s) or s < 0:
        raise ConfigError(f"--speed must be >= 0 (x real time; 0 = as fast as possible), got {speed!r}")
    return 0.0 if math.isinf(s) else s


def stream_log(path, url: str, *, speed: float = 1.0, start_s: float = 0.0, end_s: float | None = None,
               rate_hz: float | None = None, sysid: int | None = None,
               on_start: Callable[[str], Any] | None = None) -> StreamSummary:
    """Send the log ``path`` to ``url`` as MAVLink, paced by its own time (module docstring).

    Parameters
    ----------
    path : str or Path
        A MAVLink ``.tlog`` or an ArduPilot DataFlash ``.bin``, recognised by content.
    url : str
        Where to send: ``udpout:HOST:PORT`` (also ``udpin``, ``tcp``, ``tcpin``, serial; see
        :func:`~livesweep.telemetry.mavlink_out.parse_url`).
    speed : float
        x real time; 0 = as fast as possible.
    start_s, end_s : float
        The slice to send [s after the log's first time stamp].
    rate_hz : float, optional
        DataFlash only: at most this many of each message per second of log time [Hz].
    sysid : int, optional
        DataFlash only: the system id the vehicle sends as (default 1); a second vehicle on the
        same link is a second stream with another.
    on_start : callable, optional
        Called with a line saying what is about to be sent, once the arguments, the file and the
        link are checked and before the first message.

    Returns
    -------
    StreamSummary

    Raises
    ------
    ConfigError
        A negative or NaN speed, a bad slice or rate, a bad url, ``rate_hz`` for a tlog.
    LogFormatError
        A missing file, one that is neither a tlog nor DataFlash, or a slice that holds nothing.
    """
    speed = _check_speed(speed)
    _check_window(start_s, end_s)
    _check_rate(rate_hz)
    parse_url(url)
    path = Path(path)
    fmt = sniff_log(path)
    if fmt == "tlog":
        for what, value in (("--rate-hz", rate_hz), ("--sysid", sysid)):
            if value is not None:
                raise ConfigError(f"{path}: {what} applies to the messages made from a DataFlash log; a tlog is "
                                  "sent as recorded, frame for frame")
        messages = tlog_messages(path, start_s=start_s, end_s=end_s)
    else:
        messages = dataflash_messages(path, start_s=start_s, end_s=end_s, rate_hz=rate_hz,
                                      sysid=1 if sysid is None else sysid)
    try:
        # the first message before the clock starts: reaching a late --start-s reads the log up
        # to it, which must not count as sending time (the first messages would go out in a burst)
        items = iter(messages)
        first_item = next(items)            # LogFormatError when the slice holds nothing
        sender = MavlinkSender(url)
        try:
            if on_start is not None:
                pace = "as fast as possible" if speed == 0 else f"at {speed:g}x real time"
                on_start(f"{path} ({_FORMAT_NAMES[fmt]}) -> {url} {pace}")
            target = _RawFrames(sender) if fmt == "tlog" else sender
            stats = stream_records(target, itertools.chain([first_item], items), speed=speed,
                                   heartbeat_period_s=None)
            sent = dict(sender.sent_counts)
            errors = sender.send_errors
        finally:
            sender.close()
    finally:
        messages.close()
    first = messages.first_us or 0
    return StreamSummary(path, fmt, url, speed, None if rate_hz is None else float(rate_hz), first * 1e-6,
                         ((messages.sent_first_us or first) - first) * 1e-6,
                         ((messages.sent_last_us or first) - first) * 1e-6, stats["wall_duration_s"], sent,
                         {k: (n - 1) / ((b - a) * 1e-6) if b > a else math.nan for k, (a, b, n) in messages.spans.items()},
                         errors, stats["max_lateness_s"], messages.stepped_back, messages.undecodable)
