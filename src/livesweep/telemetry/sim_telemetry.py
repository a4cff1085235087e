"""Simulated test points as MAVLink telemetry: an MCAP log (docs/outputs.md, MCAP recordings) or a live UDP stream.

Each simulated signal goes where a real vehicle would send it, at that stream's rate, with the
vehicle time stamp of the sample:

=====================  ========  =================================================================
message                rate      fields (simulator units -> MAVLink units)
=====================  ========  =================================================================
``SERVO_OUTPUT_RAW``   inputs    ``servo1_raw`` = 1500 + 10 us/deg x da, ``servo4_raw`` = ... x dr
                                 (commands, whole microseconds; clipped to 1000..2000 and counted)
``ACTUATOR_CONTROL_``  inputs    quadrotor: ``controls[0]``/``controls[1]`` = roll_cmd/pitch_cmd
``TARGET``                       (normalised -1..1, ``group_mlx`` 0, PX4's attitude group)
``HIGHRES_IMU``        p, q, r,  ``xgyro``/``ygyro``/``zgyro`` = p, q, r [rad/s]; ``xacc``/``yacc`` =
                       ax, ay    ax, ay [m/s^2]; ``zacc`` = -9.80665 (level trim)
``ATTITUDE``           phi,      ``roll``/``pitch`` = phi, theta [rad], ``rollspeed``/``pitchspeed``/
                       theta     ``yawspeed`` = p, q, r [rad/s], ``yaw`` = integral of r [rad]
``AOA_SSA``            beta      ``SSA`` = beta [deg], ``AOA`` = trim angle of attack [deg]
``ODOMETRY``           v         ``vy`` = v [m/s] body frame (FRD), ``vx`` = U0 [m/s]
``DEBUG_VECT``         inputs    closed-loop test points only (a pilot loop flies them): the
                                 exogenous injection (sweep, doublet, off-axis noise) before the
                                 loop's feedback, ``name`` = ``"SWEEP_INJ"``, ``x``/``y``/``z`` =
                                 da/de/dr [deg] (quadrotor: ``x``/``y`` = roll_cmd/pitch_cmd); the
                                 common reference of docs/method.md §4.6
``HEARTBEAT``          1 Hz      MAV_TYPE_VTOL_TILTROTOR (quadrotor: MAV_TYPE_QUADROTOR)
=====================  ========  =================================================================

``publish_time`` is the vehicle time of the sample (boot clock); ``log_time`` is the simulated
receive time: a fixed UTC start plus the vehicle time plus a small random link latency (kept
monotonic per stream).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from livesweep import __version__
from livesweep.errors import ConfigError
from livesweep.sim.effects import Effect
from livesweep.sim.scenario import SimResult
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.mcap_log import McapLogWriter

__all__ = [
    "PWM_US_PER_DEG",
    "PWM_CENTER_US",
    "FT_TO_M",
    "TimedRecord",
    "mavlink_timeline",
    "write_sim_log",
    "scenario_config",
]

PWM_CENTER_US = 1500
PWM_US_PER_DEG = 10.0
PWM_LIMITS_US = (1000, 2000)
FT_TO_M = 0.3048
G_M_S2 = 9.80665
DEG2RAD = math.pi / 180.0
SERVO_CHANNEL = {"da": "servo1_raw", "de": "servo2_raw", "dt": "servo3_raw", "dr": "servo4_raw"}
#: Normalised moment commands -> index in ACTUATOR_CONTROL_TARGET.controls (group 0: PX4's attitude group).
CONTROL_INDEX = {"roll_cmd": 0, "pitch_cmd": 1}
INJECTION_NAME = "SWEEP_INJ"
INJECTION_FIELD = {"da": "x", "de": "y", "dr": "z", "roll_cmd": "x", "pitch_cmd": "y"}
DEFAULT_START_UTC_NS = 1_778_594_400 * 10**9  # 2026-05-12T14:00:00Z, fixed so logs are reproducible
MAV_TYPE_VTOL_TILTROTOR = 21
MAV_TYPE_QUADROTOR = 2
#: Vehicle type and aircraft name per model (others: the XV-15's).
VEHICLE = {"quad-attitude": (MAV_TYPE_QUADROTOR, "quadrotor (1 kg, 450 mm X frame)")}
MAV_FRAME_BODY_FRD = 12
MAV_FRAME_LOCAL_FRD = 20


@dataclass(frozen=True)
class TimedRecord:
    """One MAVLink message of the simulated stream.

    Attributes
    ----------
    vehicle_time_ns : int
        Sample time on the vehicle's boot clock [ns].
    log_time_ns : int
        Simulated receive time [ns since the UNIX epoch].
    msgname : str
    record : dict
        Canonical JSON record (``livesweep.telemetry.mavlink_codec``).
    """

    vehicle_time_ns: int
    log_time_ns: int
    msgname: str
    record: dict


def _stamp_us(t_s: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(t_s) * 1e6).astype(np.int64)


def _accel_scale(model, name: str) -> float:
    """Factor from the model's units of acceleration output ``name`` to m/s^2."""
    units = model.output_units[model.output_index(name)]
    return FT_TO_M if units == "ft/s^2" else 1.0


def _control_columns(result: SimResult) -> dict | None:
    """ACTUATOR_CONTROL_TARGET columns for the model's normalised moment commands (None: it has none)."""
    model = result.scenario.model
    names = [n for n in model.inputs if n in CONTROL_INDEX]
    if not names:
        return None
    t_in = result.inputs[names[0]].t_s
    controls = np.zeros((t_in.size, 8))
    for n in names:
        controls[:, CONTROL_INDEX[n]] = result.inputs[n].values
    return {"time_usec": _stamp_us(t_in), "group_mlx": np.int64(0), "controls": controls}


def _aligned(sig, t_ref: np.ndarray) -> np.ndarray:
    """Values of a SampledSignal at the reference times (which are a subset of its times)."""
    idx = np.searchsorted(sig.t_s, t_ref - 1e-9)
    if np.any(idx >= sig.t_s.size) or np.any(np.abs(sig.t_s[idx] - t_ref) > 1e-6):
        raise ConfigError(f"signal {sig.name} is not sampled at the times of the stream that carries it")
    return sig.values[idx]


def mavlink_timeline(result: SimResult, *, sysid: int = 1, compid: int = 1,
                     start_utc_ns: int = DEFAULT_START_UTC_NS) -> tuple[list[TimedRecord], dict]:
    """The simulated test point as a time-ordered list of MAVLink records.

    Parameters
    ----------
    result : SimResult
    sysid, compid : int
        MAVLink system and component id of the simulated vehicle.
    start_utc_ns : int
        Receive time of the first sample [ns since epoch].

    Returns
    -------
    records : list of TimedRecord
        Sorted by receive time.
    stats : dict
        ``{"pwm_clipped": {input: count}, "dropped": {msgname: count}}``: what the mapping had
        to repair or drop (samples removed by dropout effects drop the message carrying them).
    """
    model = result.scenario.model
    boot = result.scenario.boot_time_s
    rng = np.random.default_rng(np.random.SeedSequence([result.scenario.seed, 7]))
    out: list[TimedRecord] = []
    stats = {"pwm_clipped": {}, "dropped": {}}

    def emit(msgname, t_s, columns, valid=None):
        n = len(t_s)
        keep = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
        stats["dropped"][msgname] = int(n - keep.sum())
        if not keep.any():
            return
        cols = {k: (v[keep] if np.ndim(v) >= 1 and np.shape(v)[0] == n else v) for k, v in columns.items()}
        t_keep = t_s[keep]
        recs = codec.records_from_columns(msgname, cols, sysid=sysid, compid=compid)
        veh_ns = np.round(t_keep * 1e9).astype(np.int64)
        latency_ns = np.round((4e-3 + rng.exponential(2e-3, t_keep.size)) * 1e9).astype(np.int64)
        log_ns = start_utc_ns + np.round((t_keep - boot) * 1e9).astype(np.int64) + latency_ns
        log_ns = np.maximum.accumulate(log_ns)
        out.extend(TimedRecord(int(a), int(b), msgname, r) for a, b, r in zip(veh_ns, log_ns, recs))

    # Control commands.
    t_in = result.inputs[model.inputs[0]].t_s
    controls = _control_columns(result)
    if controls is not None:
        emit("ACTUATOR_CONTROL_TARGET", t_in, controls)
    servo = {}
    for name in model.inputs:
        field = SERVO_CHANNEL.get(name)
        if field is None:
            continue
        pwm = np.round(PWM_CENTER_US + PWM_US_PER_DEG * result.inputs[name].values)
        clipped = (pwm < PWM_LIMITS_US[0]) | (pwm > PWM_LIMITS_US[1])
        stats["pwm_clipped"][name] = int(clipped.sum())
        servo[field] = np.clip(pwm, *PWM_LIMITS_US).astype(np.int64)
    if servo:
        for field in ("servo1_raw", "servo2_raw", "servo3_raw", "servo4_raw"):
            servo.setdefault(field, np.int64(PWM_CENTER_US))
        servo["time_usec"] = _stamp_us(t_in) % 2**32
        emit("SERVO_OUTPUT_RAW", t_in, servo)
    if result.scenario.pilot is not None:
        # A closed loop feeds disturbances back into the commands; the exogenous injection is the
        # reference that removes that bias (docs/method.md §4.6), so it is logged as flown.
        inj = {f: np.float64(0.0) for f in ("x", "y", "z")}
        for name, field in INJECTION_FIELD.items():
            if name in result.injections:
                inj[field] = result.injections[name].values
        emit("DEBUG_VECT", t_in, {"name": INJECTION_NAME, "time_usec": _stamp_us(t_in), **inj})

    outs = result.outputs
    # Inertial measurement unit.
    if "p" in outs:
        t = outs["p"].t_s
        cols = {"time_usec": _stamp_us(t), "xgyro": DEG2RAD * outs["p"].values, "zacc": np.float64(-G_M_S2),
                "fields_updated": np.int64(0b111111)}
        valid = outs["p"].valid
        for name, field, scale in (("q", "ygyro", DEG2RAD), ("r", "zgyro", DEG2RAD), ("ax", "xacc", None),
                                   ("ay", "yacc", None)):
            if name in outs:
                k = _accel_scale(model, name) if scale is None else scale
                cols[field] = k * _aligned(outs[name], t)
                valid = valid & np.isfinite(cols[field])
        emit("HIGHRES_IMU", t, cols, valid)
    # Attitude.
    if "phi" in outs:
        t = outs["phi"].t_s
        roll = DEG2RAD * outs["phi"].values
        cols = {"time_boot_ms": np.round(t * 1e3).astype(np.int64), "roll": roll}
        valid = np.isfinite(roll)
        for name, field in (("theta", "pitch"), ("p", "rollspeed"), ("q", "pitchspeed")):
            if name in outs:
                cols[field] = DEG2RAD * _aligned(outs[name], t)
                valid &= np.isfinite(cols[field])
        if "r" in outs:
            r = DEG2RAD * _aligned(outs["r"], t)
            cols["yawspeed"] = r
            valid &= np.isfinite(r)
            r_clean = np.where(np.isfinite(r), r, 0.0)
            yaw = np.concatenate([[0.0], np.cumsum(0.5 * (r_clean[1:] + r_clean[:-1]) * np.diff(t))])
            cols["yaw"] = np.angle(np.exp(1j * yaw))
        emit("ATTITUDE", t, cols, valid)
    # Air data.
    if "beta" in outs:
        t = outs["beta"].t_s
        emit("AOA_SSA", t, {"time_usec": _stamp_us(t), "SSA": outs["beta"].values, "AOA": np.float64(2.0)},
             outs["beta"].valid)
    # Body velocity (hover: reconstructed lateral velocity).
    if "v" in outs:
        t = outs["v"].t_s
        U0 = model.constants.get("U0_ft_s", 0.0)
        vel_cov = np.zeros(21)
        sigma_v = next((s.noise_std for s in result.scenario.sensors if s.output == "v"), 0.0)
        vel_cov[[0, 6, 11]] = (FT_TO_M * sigma_v) ** 2
        pose_cov = np.zeros(21)
        pose_cov[0] = np.nan  # MAVLink: NaN in the first element = pose covariance unknown
        emit("ODOMETRY", t, {
            "time_usec": _stamp_us(t), "frame_id": np.int64(MAV_FRAME_LOCAL_FRD),
            "child_frame_id": np.int64(MAV_FRAME_BODY_FRD), "q": np.array([1.0, 0.0, 0.0, 0.0]),
            "vx": np.float64(FT_TO_M * U0), "vy": FT_TO_M * outs["v"].values,
            "pose_covariance": pose_cov, "velocity_covariance": vel_cov,
        }, outs["v"].valid)
    # Heartbeat once a second.
    t_hb = np.arange(math.ceil(boot), result.t_fine_s[-1], 1.0)
    mav_type = VEHICLE.get(model.name, (MAV_TYPE_VTOL_TILTROTOR, ""))[0]
    emit("HEARTBEAT", t_hb, {"type": np.full(t_hb.size, mav_type), "autopilot": np.int64(0),
                             "base_mode": np.int64(0), "custom_mode": np.int64(0),
                             "system_status": np.int64(4), "mavlink_version": np.int64(3)})
    out.sort(key=lambda r: (r.log_time_ns, r.msgname))
    return out, stats


def _effect_dict(e: Effect) -> dict:
    return e.as_dict()


def scenario_config(result: SimResult) -> dict:
    """The scenario as a JSON-able dict (stored as the log's ``sim_config.json`` attachment)."""
    sc = result.scenario
    return {
        "livesweep_version": __version__,
        "model": sc.model.name,
        "condition": sc.condition,
        "seed": sc.seed,
        "internal_rate_hz": sc.internal_rate_hz,
        "input_rate_hz": sc.input_rate_hz,
        "boot_time_s": sc.boot_time_s,
        "sensors": [{"output": s.output, "rate_hz": s.rate_hz, "noise_std": s.noise_std} for s in sc.sensors],
        "turbulence": None if sc.turbulence is None else {
            "sigmas": list(sc.turbulence.sigmas), "gusts": list(sc.model.gust_names),
            "correlation_time_s": sc.turbulence.correlation_time_s},
        "pilot": None if sc.pilot is None else {"gains": [list(g) for g in sc.pilot.gains], "delay_s": sc.pilot.delay_s},
        "effects": [_effect_dict(e) for e in sc.effects],
        "segments": [
            {"label": s.label, "kind": s.kind, "axis": s.axis, "start_s": s.start_s, "end_s": s.end_s,
             "parameters": {k: (list(v) if isinstance(v, tuple) else v) for k, v in s.parameters.items()}}
            for s in result.segments
        ],
        "injected": result.injected,
    }


def write_sim_log(result: SimResult, path, *, aircraft: str | None = None, notes: str = "",
                  sysid: int = 1, compid: int = 1, start_utc_ns: int = DEFAULT_START_UTC_NS,
                  overwrite: bool = True) -> dict:
    """Write the simulated test point as an MCAP log (atomically: nothing is left on error).

    Parameters
    ----------
    result : SimResult
    path : str or Path
        ``.mcap`` file to create.
    aircraft, notes : str
        Test-point metadata; ``aircraft`` defaults to the model's (``"XV-15"`` for the XV-15 models).
    overwrite : bool
        Replace an existing ``path`` (never one another process is writing, such as a recording).

    Returns
    -------
    dict
        ``{"path", "message_counts", "duration_s", "stats"}``.
    """
    if aircraft is None:
        aircraft = VEHICLE.get(result.scenario.model.name, (0, "XV-15"))[1]
    records, stats = mavlink_timeline(result, sysid=sysid, compid=compid, start_utc_ns=start_utc_ns)
    config = scenario_config(result)
    with McapLogWriter(path, library=f"livesweep {__version__}", overwrite=overwrite) as w:
        for name in sorted({r.msgname for r in records}):
            w.add_channel(f"/mavlink/{name}", f"mavlink.{name}", codec.json_schema(name))
        for r in records:
            w.write(f"/mavlink/{r.msgname}", r.record, log_time_ns=r.log_time_ns, publish_time_ns=r.vehicle_time_ns)
        sc = result.scenario
        w.add_metadata("test_point", {
            "aircraft": aircraft,
            "model": sc.model.name,
            "flight_condition": sc.condition,
            "manoeuvre": "; ".join(s.label for s in result.segments if s.kind != "trim"),
            "operator_notes": notes or "simulated by livesweep",
            "seed": str(sc.seed),
            "effects": json.dumps([e.as_dict() for e in sc.effects]),
            "source": "livesweep.sim",
        })
        for i, s in enumerate(result.segments):
            w.add_metadata(f"segment_{i:03d}", {
                "label": s.label, "kind": s.kind, "axis": s.axis or "", "start_s": repr(s.start_s),
                "end_s": repr(s.end_s), "clock": "vehicle time since boot [s]"})
        w.add_attachment("sim_config.json", json.dumps(config, indent=1, sort_keys=True).encode(), "application/json")
        counts = dict(w.message_counts)
    return {"path": str(path), "message_counts": counts,
            "duration_s": float(result.t_fine_s[-1] - result.t_fine_s[0]), "stats": stats}
