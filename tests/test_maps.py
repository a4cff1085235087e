"""Named channel maps for real vehicles (livesweep.maps, data/maps/*.toml), their schema, and the CLI.

Every preset loads; its motor mixes are checked against the motor angles and directions of
ArduPilot's AP_MotorsMatrix (tabled here by hand: roll factor cos(angle + 90 deg), pitch factor
cos(angle), yaw +1 CCW / -1 CW) and their signs against ArduCopter's own rate-controller outputs
in the shared SITL SystemID logs; the presets read the shared DataFlash, ULog and tlog data, and
what they read is compared with pymavlink's and pyulog's readings of the same files and with plain
scipy. Third-party logs are read in place from ``../shared/data``; tests that need one skip when
it is absent.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps

from livesweep.config import RecordSpec, SignalSpec, TestPointSettings, load_channel_map, read_channel_map
from livesweep.errors import ConfigError
from livesweep.maps import PRESET_DIR, list_maps, load_map, preset_names
from livesweep.telemetry.align import GridAligner
from livesweep.telemetry.extract import compile_signal
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mavlink_codec import record_from_fields
from livesweep.telemetry.mcap_log import read_topics_fields
from livesweep.telemetry.signals import read_signals

ROOT = Path(__file__).resolve().parents[1]
R2D = 180.0 / math.pi


def _data_dir() -> Path:
    p = ROOT.parent / "shared" / "data"
    return p if p.is_dir() else Path("/work/shared/data")


DATA = _data_dir()
SID7 = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
SID8 = DATA / "ardupilot_sitl_systemid" / "sid_axis8_rate_pitch.bin"
ULG = DATA / "px4_ulog" / "sample.ulg"
VTOL = DATA / "mavlink_tlog" / "uavlogviewer_vtol_sitl.tlog"

PRESETS = ["ardupilot-copter-hexa-x", "ardupilot-copter-pid", "ardupilot-copter-quad-plus", "ardupilot-copter-quad-x",
           "ardupilot-plane", "ardupilot-sysid-dataflash", "px4-multicopter", "px4-ulog-multicopter"]


def need(*paths: Path) -> None:
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"third-party log(s) not found: {', '.join(missing)}")


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    """Each shared log converted once per module (``livesweep convert``), on first use."""
    from livesweep.convert import convert

    done: dict[Path, Path] = {}
    folder = tmp_path_factory.mktemp("maps")

    def get(src: Path) -> Path:
        need(src)
        if src not in done:
            done[src] = folder / (src.stem + ".mcap")
            convert(src, done[src])
        return done[src]

    return get


# ----------------------------------------------------------------------------- the presets


def test_every_preset_loads_with_its_header_units_one_clock_and_test_points():
    assert preset_names() == PRESETS
    infos = {m.name: m for m in list_maps()}
    assert list(infos) == PRESETS
    for name in PRESETS:
        m = load_map(name)
        assert m.name == name and m.path == PRESET_DIR / f"{name}.toml" and infos[name].needs == m.needs
        assert m.description and m.needs and m.spectral is not None and isinstance(m.test_points, TestPointSettings)
        assert all(s.units for s in m.signals.values()), name
        assert len({s.stamp is None for s in m.signals.values()}) == 1, name        # one clock
        sp, tp = m.spectral, m.test_points
        # the required pairs default to, and here are, the on-axis output of each input
        assert tp.required == {i: (sp.outputs[k],) for k, i in enumerate(sp.inputs)}
        assert set(tp.axes.values()) <= set(sp.inputs) and tp.min_duration_s == 10.0
        # load_channel_map keeps working on a preset file
        signals, spectral = load_channel_map(m.path)
        assert signals == m.signals and spectral == m.spectral
    # the rate-loop maps see the input, recovery and rate axes (the chirp enters the rate demand);
    # the motor-mix maps see the mixer axes too (it enters the mixer)
    rate_loop = {1: "roll", 2: "pitch", 3: "yaw", 4: "roll", 5: "pitch", 6: "yaw", 7: "roll", 8: "pitch", 9: "yaw"}
    mixer = {**rate_loop, 10: "roll", 11: "pitch", 12: "yaw"}
    for name in PRESETS:
        tp = load_map(name).test_points
        if name.startswith("ardupilot-copter") or name == "ardupilot-sysid-dataflash":
            want = rate_loop if name in ("ardupilot-copter-pid", "ardupilot-sysid-dataflash") else mixer
            assert tp.axes == want and tp.sources == ("autopilot", "marker", "sweep")
        else:
            assert tp.axes == {} and tp.sources == ("marker", "sweep")
    pid = load_map("ardupilot-copter-pid")
    # PID_TUNING has no time field: it borrows the boot clock of the ATTITUDE sent in the same tick
    assert all(s.stamp_topic == "/mavlink/ATTITUDE" and s.stamp == "time_boot_ms"
               for s in pid.signals.values() if s.topic == "/mavlink/PID_TUNING")
    assert [dict(pid.signals[n].where) for n in ("roll", "pitch", "yaw", "p", "q", "r")] == \
        [{"axis": 1}, {"axis": 2}, {"axis": 3}, {"axis": 1}, {"axis": 2}, {"axis": 3}]


def test_pid_tuning_has_no_time_field_in_the_dialect():
    """Why the PID preset runs on receive time: pymavlink's ardupilotmega PID_TUNING carries none."""
    from pymavlink.dialects.v20 import ardupilotmega

    assert ardupilotmega.MAVLink_pid_tuning_message.fieldnames == ["axis", "desired", "achieved", "FF", "P", "I", "D",
                                                                     "SRate", "PDmod"]


# ArduPilot AP_MotorsMatrix::setup_motors: (angle [deg], yaw factor) of motors 1..n
MOTORS = {
    "ardupilot-copter-quad-plus": [(90, +1), (-90, +1), (0, -1), (180, -1)],
    "ardupilot-copter-quad-x": [(45, +1), (-135, +1), (-45, -1), (135, -1)],
    "ardupilot-copter-hexa-x": [(90, -1), (-90, +1), (-30, -1), (150, +1), (30, +1), (-150, -1)],
}


@pytest.mark.parametrize("name", sorted(MOTORS))
def test_motor_mixes_are_the_least_squares_projection_of_ardupilots_motor_factors(name):
    """Coefficient of servo i in each mix = f_i / sum(f^2), f the motor factors from the angles."""
    m = load_map(name)
    motors = MOTORS[name]
    angles = np.radians([a for a, _ in motors])
    factors = {"roll": np.cos(angles + np.pi / 2), "pitch": np.cos(angles), "yaw": np.array([y for _, y in motors], float)}
    for axis, f in factors.items():
        f = np.where(np.abs(f) < 1e-12, 0.0, f)
        expected = f / np.sum(f ** 2)
        ex = compile_signal(m.signals[axis])
        base = {f"servo{i}_raw": 0 for i in range(1, 17)}
        got = [ex.value({**base, f"servo{i + 1}_raw": 1})[0] - ex.value(base)[0] for i in range(len(motors))]
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15, err_msg=f"{name} {axis}")
        # the other outputs do not enter
        assert all(ex.value({**base, f"servo{i}_raw": 1})[0] == ex.value(base)[0] for i in range(len(motors) + 1, 17))
        # throttle (all motors alike) cancels
        assert abs(ex.value({**base, **{f"servo{i + 1}_raw": 1500 for i in range(len(motors))}})[0]) < 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("log,swept", [(SID7, "roll"), (SID8, "pitch")])
def test_quad_plus_mix_signs_follow_arducopters_rate_controller_outputs(converted, log, swept):
    """The shared SITL logs fly ArduCopter's QUAD/PLUS frame. The preset's mixes, applied to the
    DataFlash RCOU record (C1..C4 = servo1..4, 10 Hz), follow the rate controllers' outputs
    RATE.ROut/POut/YOut at the RCOU times with positive correlation. Measured: the swept axis
    0.998, the others 0.63-0.72 (PWM is whole microseconds and they barely move); a wrong sign
    or a roll/pitch swap would make them negative or near 0."""
    path = converted(log)
    m = load_map("ardupilot-copter-quad-plus")
    sigs = {n: SignalSpec(n, "/dataflash/RCOU", re.sub(r"servo(\d+)_raw", r"C\1", m.signals[n].field), "TimeUS", 1e-6)
            for n in ("roll", "pitch", "yaw")}
    mix = read_signals(RecordSpec(path), sigs, list(sigs))
    rate = read_topics_fields(path, {"/dataflash/RATE": ["TimeUS", "ROut", "POut", "YOut"]})["/dataflash/RATE"]
    for n, out in (("roll", "ROut"), ("pitch", "POut"), ("yaw", "YOut")):
        y = np.interp(mix[n].t_s, rate["TimeUS"] * 1e-6, rate[out])
        r = np.corrcoef(mix[n].values, y)[0, 1]
        assert r > (0.99 if n == swept else 0.5), (n, r)


def _dataflash_rate(path: Path) -> dict[str, np.ndarray]:
    """RATE and SIDD as pymavlink's DataFlash reader gives them (independent of livesweep's converter)."""
    from pymavlink import DFReader

    f = DFReader.DFReader_binary(str(path))
    rate, sidd = [], []
    while (msg := f.recv_match(type=["RATE", "SIDD"])) is not None:
        if msg.get_type() == "RATE":
            rate.append((msg.TimeUS, msg.RDes, msg.R, msg.PDes, msg.P, msg.YDes, msg.Y))
        else:
            sidd.append((msg.TimeUS, msg.Targ))
    r, s = np.array(rate, float), np.array(sidd, float)
    return {"t": r[:, 0] * 1e-6, "RDes": r[:, 1], "R": r[:, 2], "PDes": r[:, 3], "P": r[:, 4], "YDes": r[:, 5],
            "Y": r[:, 6], "sidd_t": s[:, 0] * 1e-6, "Targ": s[:, 1]}


def _h1(x, y, fs, f_hz):
    """Plain scipy H1 = Pxy / Pxx (Hann, nperseg 4096), linearly interpolated at f_hz."""
    f, pxy = sps.csd(x, y, fs=fs, nperseg=4096)
    _, pxx = sps.welch(x, fs=fs, nperseg=4096)
    h = pxy / pxx
    return np.interp(f_hz, f, h.real) + 1j * np.interp(f_hz, f, h.imag)


@pytest.mark.slow
def test_dataflash_systemid_preset_reads_400_hz_rates_that_agree_with_pymavlink_and_scipy(converted):
    """ardupilot-sysid-dataflash on the converted sid_axis7 log: every signal resolves; the rates
    come at 400 Hz with pymavlink's values and times; RDes -> R over the SIDD span at 2 Hz is the
    H1 plain scipy computes from pymavlink's reading to 1e-9 (the same samples), and the shared
    README's reference 0.93 / -21 deg within 0.01 and 1 deg (its two significant digits)."""
    path = converted(SID7)
    m = load_map("ardupilot-sysid-dataflash")
    out = read_signals(RecordSpec(path), m.signals, list(m.signals))
    ref = _dataflash_rate(SID7)
    for n, field in (("roll", "RDes"), ("p", "R"), ("pitch", "PDes"), ("q", "P"), ("yaw", "YDes"), ("r", "Y")):
        np.testing.assert_allclose(out[n].t_s, ref["t"], rtol=0, atol=1e-9)
        np.testing.assert_allclose(out[n].values, ref[field], rtol=1e-6, atol=1e-9)   # float32 fields
        assert out[n].units == "deg/s"
    assert np.median(np.diff(out["p"].t_s)) == pytest.approx(1 / 400.0, abs=2e-6)
    np.testing.assert_allclose(out["sid_targ"].values, ref["Targ"], rtol=1e-6, atol=1e-9)
    lo, hi = out["sid_targ"].t_s[0], out["sid_targ"].t_s[-1]
    k = (out["roll"].t_s >= lo) & (out["roll"].t_s <= hi)
    kr = (ref["t"] >= lo) & (ref["t"] <= hi)
    h = _h1(out["roll"].values[k], out["p"].values[k], 400.0, 2.0)
    h_ref = _h1(ref["RDes"][kr], ref["R"][kr], 400.0, 2.0)
    assert abs(h / h_ref - 1) < 1e-5
    assert abs(h) == pytest.approx(0.93, abs=0.01) and math.degrees(np.angle(h)) == pytest.approx(-21.0, abs=1.0)


@pytest.mark.slow
def test_ulog_preset_on_the_px4_sample_reads_what_pyulog_reads(converted):
    """px4-ulog-multicopter on sample.ulg: every signal resolves, with pyulog's values (scaled) and
    time stamps; roll-rate setpoint -> roll rate is coherent (the shared README: about 0.99 over
    0.5-10 Hz; plain scipy on the signals linearly resampled at 100 Hz: median 0.998)."""
    pyulog = pytest.importorskip("pyulog")
    path = converted(ULG)
    m = load_map("px4-ulog-multicopter")
    out = read_signals(RecordSpec(path), m.signals, list(m.signals))
    u = pyulog.ULog(str(ULG), ["vehicle_rates_setpoint", "vehicle_attitude", "actuator_controls_0", "sensor_combined"])
    for n, s in m.signals.items():
        d = u.get_dataset(s.topic.split("/")[2]).data
        np.testing.assert_array_equal(out[n].t_s, d["timestamp"] * 1e-6)
        np.testing.assert_allclose(out[n].values, s.scale * d[s.field].astype(float), rtol=1e-6, atol=1e-9, err_msg=n)
    t = np.arange(max(out["roll"].t_s[0], out["p"].t_s[0]), min(out["roll"].t_s[-1], out["p"].t_s[-1]), 0.01)
    f, c = sps.coherence(np.interp(t, out["roll"].t_s, out["roll"].values), np.interp(t, out["p"].t_s, out["p"].values),
                         fs=100.0, nperseg=512)
    assert np.median(c[(f >= 0.5) & (f <= 10.0)]) > 0.98


@pytest.mark.slow
def test_plane_and_copter_presets_on_the_quadplane_tlog_read_what_pymavlink_reads(converted):
    """The shared QuadPlane SITL tlog carries SERVO_OUTPUT_RAW and ATTITUDE (MAVLink 1, ~4 Hz):
    ardupilot-plane resolves every signal with pymavlink's values (servo - 1500 us, rad -> deg),
    and the quad-plus roll mix is 0.5 (servo2 - servo1) of pymavlink's servos."""
    from pymavlink import mavutil

    path = converted(VTOL)
    r = mavutil.mavmmaplog(str(VTOL))                  # pymavlink's own tlog reader, built directly
    servo, att = [], []
    while (msg := r.recv_match(type=["SERVO_OUTPUT_RAW", "ATTITUDE"])) is not None:
        if msg.get_type() == "SERVO_OUTPUT_RAW":
            servo.append((msg.time_usec, msg.servo1_raw, msg.servo2_raw, msg.servo4_raw))
        else:
            att.append((msg.time_boot_ms, msg.rollspeed, msg.pitchspeed, msg.yawspeed, msg.roll, msg.pitch))
    servo, att = np.array(servo, float), np.array(att, float)
    m = load_map("ardupilot-plane")
    out = read_signals(RecordSpec(path), m.signals, list(m.signals))
    for k, n in enumerate(("da", "de", "dr"), start=1):
        np.testing.assert_array_equal(out[n].values, servo[:, k] - 1500.0)
        np.testing.assert_array_equal(out[n].t_s, servo[:, 0] * 1e-6)
    for k, n in enumerate(("p", "q", "r", "phi", "theta"), start=1):
        np.testing.assert_allclose(out[n].values, att[:, k] * R2D, rtol=1e-6, atol=1e-9)
        np.testing.assert_array_equal(out[n].t_s, att[:, 0] * 1e-3)
    copter = load_map("ardupilot-copter-quad-plus")
    roll = read_signals(RecordSpec(path), copter.signals, ["roll"])["roll"]
    r = mavutil.mavmmaplog(str(VTOL))
    s12 = np.array([(msg.servo1_raw, msg.servo2_raw) for msg in iter(lambda: r.recv_match(type="SERVO_OUTPUT_RAW"), None)])
    np.testing.assert_array_equal(roll.values, 0.5 * (s12[:, 1] - s12[:, 0]))


def test_px4_and_pid_presets_resolve_on_mavlink_records():
    """No shared log carries ACTUATOR_CONTROL_TARGET or PID_TUNING: records built by the codec from
    the dialect's definitions stand in. Group 1 and axis 4 messages are left out by 'where'."""
    px4 = load_map("px4-multicopter")
    frames = []
    for k in range(100):
        t_us = 5_000_000 + 20_000 * k
        for group, scale in ((0, 1.0), (1, 100.0)):
            rec = record_from_fields("ACTUATOR_CONTROL_TARGET", {"time_usec": t_us, "group_mlx": group,
                                     "controls": [scale * 0.01 * k, -0.5 * scale, 0.25 * scale, 0, 0, 0, 0, 0]},
                                     sysid=1, compid=1)
            frames.append(Frame("/mavlink/ACTUATOR_CONTROL_TARGET", t_us * 1000, None, rec))
    for n, want in (("roll", 0.01 * np.arange(100)), ("pitch", np.full(100, -0.5)), ("yaw", np.full(100, 0.25))):
        ex = compile_signal(px4.signals[n])
        got = [ex.value(f.data)[0] for f in frames if ex.selects(f.data)]
        np.testing.assert_allclose(got, want, rtol=1e-6)
    pid = load_map("ardupilot-copter-pid")
    recs = [record_from_fields("PID_TUNING", {"axis": a, "desired": 0.1 * a, "achieved": -0.1 * a}, sysid=1, compid=1)
            for a in (1, 2, 3, 4)]
    for n, axis, sign in (("roll", 1, 1), ("pitch", 2, 1), ("yaw", 3, 1), ("p", 1, -1), ("q", 2, -1), ("r", 3, -1)):
        ex = compile_signal(pid.signals[n])
        (taken,) = [rec for rec in recs if ex.selects(rec)]
        assert taken["axis"] == axis
        assert ex.value(taken)[0] == pytest.approx(sign * 0.1 * axis * R2D, rel=1e-6)   # rad/s -> deg/s


@pytest.mark.slow
def test_a_preset_runs_through_the_live_aligner(converted):
    """ardupilot-sysid-dataflash through the live aligner on the converted log: 400 Hz grid, every
    signal counted, nothing dropped by the clocks."""
    from livesweep.telemetry.mcap_log import iter_file_order

    path = converted(SID7)
    m = load_map("ardupilot-sysid-dataflash")
    names = (*m.spectral.inputs, *m.spectral.outputs)
    al = GridAligner(m.signals, names, m.spectral.sample_rate_hz)
    n = 0
    for msg in iter_file_order(path, ["/dataflash/RATE"]):
        al.push(Frame(msg.topic, msg.log_time_ns, msg.publish_time_ns, msg.data))
        n += 1
        while al.pop_ready() is not None:
            pass
    assert all(al.signal_counts[k] == {"samples": n, "missing_field": 0, "not_a_number": 0, "filtered": 0,
                                       "other_vehicle": 0} for k in names)
    assert al.counts["clock_rejected"] == 0 and al.counts["samples_emitted"] == pytest.approx(n, abs=2)


# ----------------------------------------------------------------------------- schema errors


GOOD = """
[map]
name = "mine"
description = "test map"
needs = "ATTITUDE"

[signals.roll]
topic = "/mavlink/SERVO_OUTPUT_RAW"
field = "servo2_raw - servo1_raw"
stamp = "time_usec"
stamp_scale = 1e-6
units = "us"

[signals.p]
topic = "/mavlink/ATTITUDE"
field = "rollspeed"
stamp = "time_boot_ms"
stamp_scale = 1e-3
sysid = 1
compid = 1
units = "rad/s"

[spectral]
inputs = ["roll"]
outputs = ["p"]
band_rad_s = [1.0, 40.0]
sample_rate_hz = 50.0

[test_points]
axes = { "7" = "roll" }
"""


def write(tmp_path, text, name="map.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_a_map_file_with_every_new_key_and_the_defaults(tmp_path):
    m = load_map(write(tmp_path, GOOD))
    assert (m.name, m.description, m.needs) == ("mine", "test map", "ATTITUDE")
    assert m.signals["p"].sysid == 1 and m.signals["p"].compid == 1 and m.signals["roll"].where == ()
    assert m.test_points == TestPointSettings(sources=("autopilot", "marker", "sweep"), axes={7: "roll"},
                                              required={"roll": ("p",)}, min_duration_s=10.0)
    bare = read_channel_map(write(tmp_path, GOOD.split("[test_points]")[0], "b.toml"))
    assert bare.test_points is None
    nohead = read_channel_map(write(tmp_path, "[signals.roll]" + GOOD.split("[signals.roll]", 1)[1], "c.toml"))
    assert (nohead.name, nohead.description, nohead.needs) == ("c", "", "")


@pytest.mark.parametrize("edit,pattern", [
    (('field = "rollspeed"', 'field = "rollspeed"\ncolour = 1'), r"signals\.p\.colour: unknown key 'colour'"),
    (('"servo2_raw - servo1_raw"', '"servo2_raw - (servo1_raw"'),
     r"signals\.roll\.field = 'servo2_raw - \(servo1_raw': missing '\)' for '\(' at position 13"),
    (('"servo2_raw - servo1_raw"', '"servo2_raw - servo1_rawx"'),
     r"signals\.roll\.field: 'servo1_rawx' is not a field of MAVLink SERVO_OUTPUT_RAW .*got 'servo1_rawx'"),
    (('"rollspeed"', '"rollspeed.1"'), r"signals\.p\.field: 'rollspeed' of MAVLink ATTITUDE is a single value"),
    (('"/mavlink/ATTITUDE"', '"/mavlink/ATTITUDEX"'), r"signals\.p\.topic: unknown MAVLink message 'ATTITUDEX'"),
    (('sysid = 1', 'sysid = 256'), r"signals\.p\.sysid: must be an integer from 0 to 255 .*got 256"),
    (('compid = 1', 'compid = true'), r"signals\.p\.compid: must be an integer"),
    (('compid = 1', 'where = { axis = 1 }'), r"signals\.p\.where\.axis: 'axis' is not a field of MAVLink ATTITUDE"),
    (('compid = 1', 'where = { time_boot_ms = "x" }'), r"signals\.p\.where\.time_boot_ms: must be a finite number .*got 'x'"),
    (('compid = 1', 'where = {}'), r"signals\.p\.where: must name at least one field"),
    (('stamp = "time_boot_ms"', 'stamp = "time_usec"'), r"signals\.p\.stamp: 'time_usec' is not a field of MAVLink ATTITUDE"),
    (('axes = { "7" = "roll" }', 'axes = { "7" = "p" }'), r"test_points\.axes\.'7': must name a spectral input \(roll\), got 'p'"),
    (('axes = { "7" = "roll" }', 'axes = { "x7" = "roll" }'), r"test_points\.axes\.'x7': a key is an ArduPilot SID_AXIS"),
    (('axes = { "7" = "roll" }', 'required = { roll = ["q"] }'), r"test_points\.required\.'roll'\[0\]: names no spectral output \(p\), got 'q'"),
    (('axes = { "7" = "roll" }', 'required = { pitch = ["p"] }'), r"test_points\.required\.'pitch': names no spectral input"),
    (('axes = { "7" = "roll" }', 'sources = ["autopilot", "radio"]'), r"test_points\.sources\[1\]: must be one of autopilot, marker, sweep, got 'radio'"),
    (('axes = { "7" = "roll" }', 'min_duration_s = -1'), r"test_points\.min_duration_s: must be >= 0, got -1"),
    (('axes = { "7" = "roll" }', 'every = 2'), r"test_points\.every: unknown key 'every'"),
    (('needs = "ATTITUDE"', 'needs = "ATTITUDE"\nauthor = "x"'), r"map\.author: unknown key 'author'"),
    (('stamp = "time_usec"\nstamp_scale = 1e-6\nunits = "us"', 'units = "us"'),
     r"signals: p are timed by a vehicle stamp but roll by receive time"),
])
def test_bad_map_files_are_one_line_naming_file_key_and_value(tmp_path, edit, pattern):
    old, new = edit
    assert old in GOOD
    path = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ConfigError) as err:
        load_map(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(path)) and re.search(pattern, msg), msg


def test_unknown_preset_names_the_presets():
    with pytest.raises(ConfigError, match=r"--map 'quad': no such preset \(presets: ardupilot-copter-hexa-x, .*\)"):
        load_map("quad")


def test_settings_from_a_map_survive_the_recordings_settings_round_trip():
    """What the monitor records (MonitorSettings.to_dict, JSON) gives back the same signals,
    'where' and test points included: a replay analyses as the live run did."""
    from livesweep.monitor.pipeline import MonitorSettings

    m = load_map("ardupilot-copter-pid")
    s = MonitorSettings(signals=m.signals, inputs=m.spectral.inputs, outputs=m.spectral.outputs,
                        band_rad_s=m.spectral.band_rad_s, test_points=m.test_points)
    back = MonitorSettings.from_dict(json.loads(json.dumps(s.to_dict())))
    assert back.signals == m.signals and back.test_points == m.test_points
    sysid = replace(m.signals["p"], sysid=3, compid=1)
    assert SignalSpec(**json.loads(json.dumps(sysid.__dict__))) == sysid


# ----------------------------------------------------------------------------- CLI


def livesweep(*args):
    return subprocess.run([sys.executable, "-m", "livesweep", *args], capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_cli_lists_the_presets_and_refuses_bad_map_arguments_in_one_line(tmp_path):
    r = livesweep("maps")
    assert r.returncode == 0, r.stderr
    names = [ln for ln in r.stdout.splitlines() if ln and not ln.startswith((" ", "use "))]
    assert names == PRESETS
    assert "    needs: SERVO_OUTPUT_RAW and ATTITUDE at >= 25 Hz" in r.stdout
    assert "    inputs: da, de, dr; outputs: p, q, r, phi, theta" in r.stdout
    log = str(ROOT / "replay_logs" / "xv15_cruise_verify.mcap")
    for args, pattern in [
        (("replay", log, "--map", "nope"), r"^livesweep: error: --map 'nope': no such preset"),
        (("replay", log, "--map", "ardupilot-plane", "--case", "x.toml"), r"^livesweep: error: give --case or --map, not both"),
        (("replay", log, "--map", str(write(tmp_path, GOOD.replace('"rollspeed"', '"rollspeed +"')))),
         r"^livesweep: error: .*map\.toml: signals\.p\.field = 'rollspeed \+': unexpected end of expression$"),
        (("monitor", "--mavlink", "udpin:127.0.0.1:0", "--map", "px4-ulog"), r"^livesweep: error: --map 'px4-ulog'"),
    ]:
        r = livesweep(*args)
        assert r.returncode == 2 and r.stdout == "" and "Traceback" not in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and re.search(pattern, r.stderr.strip()), r.stderr


@pytest.mark.slow
def test_replay_with_a_preset_analyses_the_presets_pairs():
    """The simulated XV-15 cruise log carries SERVO_OUTPUT_RAW and ATTITUDE, so ardupilot-plane's
    signals resolve on it: the replay estimates exactly the preset's 5 x 3 output/input pairs, and the
    command says so in one summary without a traceback."""
    from livesweep.cli import _monitor_settings, build_parser
    from livesweep.monitor.pipeline import MonitorPipeline
    from livesweep.telemetry.replay import McapReplaySource

    log = str(ROOT / "replay_logs" / "xv15_cruise_verify.mcap")
    r = livesweep("replay", log, "--map", "ardupilot-plane")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert "test points: 0" in r.stdout                # doublets only: no test point, no verdict on the window
    settings = _monitor_settings(build_parser().parse_args(["replay", log, "--map", "ardupilot-plane"]))
    summary = MonitorPipeline(settings, [McapReplaySource(log)], keep_estimates=False).run()
    pairs = [f"{a['output']}/{a['input']}" for a in summary["adequacy"]]
    assert pairs == [f"{o}/{i}" for o in ("p", "q", "r", "phi", "theta") for i in ("da", "de", "dr")]


def test_monitor_settings_take_the_maps_signals_and_test_points():
    """--map gives MonitorSettings the preset's signals, spectral settings and test points; --case
    a map file does the same (its [test_points] are not lost)."""
    from livesweep.cli import _monitor_settings, build_parser

    for args in (["replay", "x.mcap", "--map", "ardupilot-copter-quad-x"],
                 ["replay", "x.mcap", "--case", str(PRESET_DIR / "ardupilot-copter-quad-x.toml")]):
        s = _monitor_settings(build_parser().parse_args(args))
        m = load_map("ardupilot-copter-quad-x")
        assert s.signals == m.signals and s.test_points == m.test_points
        assert (s.inputs, s.outputs, s.sample_rate_hz) == (("roll", "pitch", "yaw"), ("p", "q", "r", "phi", "theta"), 50.0)
    s = _monitor_settings(build_parser().parse_args(["replay", "x.mcap"]))
    assert s.test_points is None and s.inputs == ("da", "dr")          # the XV-15 default, unchanged
