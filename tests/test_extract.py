"""Signal expressions and selection (telemetry/extract.py): one compiled form for the live aligner and
the offline reader, and the diagnosis of a map that finds nothing.

References are hand computations on MAVLink records built with the codec
(``record_from_fields``, the dialect's own field layout), the values in the logs as pymavlink reads
them (the shared autotest tlog), and, for live against offline, the offline reader's samples
interpolated with ``numpy.interp`` at the aligner's grid times.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from livesweep.config import RecordSpec, SignalSpec, load_channel_map
from livesweep.errors import ConfigError, LogFormatError
from livesweep.telemetry.align import GridAligner
from livesweep.telemetry.extract import compile_signal, diagnose, parse_field, topics_seen_from
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mavlink_codec import record_from_fields
from livesweep.telemetry.mcap_log import iter_file_order, read_topics_fields
from livesweep.telemetry.signals import read_signals

ROOT = Path(__file__).resolve().parents[1]


def _data_dir() -> Path:
    p = ROOT.parent / "shared" / "data"
    return p if p.is_dir() else Path("/work/shared/data")


DATA = _data_dir()
AUTOTEST = DATA / "mavlink_tlog" / "uavlogviewer_autotest_flight_logs.tlog"


def need(*paths: Path) -> None:
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"third-party log(s) not found: {', '.join(missing)}")


def frame(msg: str, t_ns: int, sysid: int = 1, compid: int = 1, **fields) -> Frame:
    return Frame(f"/mavlink/{msg}", t_ns, None, record_from_fields(msg, fields, sysid=sysid, compid=compid))


def servo(t_us: int, s1: int, s2: int, s3: int = 1500, s4: int = 1500, **kw) -> Frame:
    return frame("SERVO_OUTPUT_RAW", t_us * 1000, time_usec=t_us, servo1_raw=s1, servo2_raw=s2, servo3_raw=s3,
                 servo4_raw=s4, **kw)


# ----------------------------------------------------------------------------- expressions


def test_motor_mix_on_servo_output_raw_records_is_the_hand_computed_value():
    spec = SignalSpec("roll", "/mavlink/SERVO_OUTPUT_RAW", "0.5 * (servo2_raw - servo1_raw)", "time_usec", 1e-6,
                      scale=2.0, offset=-3.0, units="us")
    ex = compile_signal(spec)
    assert ex.expression.operands == ("servo2_raw", "servo1_raw")
    assert ex.read_fields == ("servo2_raw", "servo1_raw", "time_usec")
    # 2 * 0.5 * (1620 - 1390) - 3 = 227
    assert ex.value(servo(1000, 1390, 1620).data) == (227.0, None)
    mean = compile_signal(SignalSpec("thr", "/mavlink/SERVO_OUTPUT_RAW", "0.5 * (servo1_raw + servo2_raw) - 1500"))
    assert mean.value(servo(1000, 1390, 1620).data) == (5.0, None)           # (1390 + 1620) / 2 - 1500
    rate = compile_signal(SignalSpec("p", "/mavlink/ATTITUDE", "rollspeed * 57.29578"))
    att = frame("ATTITUDE", 0, time_boot_ms=5, rollspeed=0.5)
    assert rate.value(att.data)[0] == pytest.approx(0.5 * 57.29578, rel=1e-7)  # float32 0.5 is exact
    # a plain field stays the fast path: read as it is, no tree
    assert compile_signal(SignalSpec("s1", "/mavlink/SERVO_OUTPUT_RAW", "servo1_raw")).expression.tree is None


def test_dotted_and_bracketed_operands():
    act = frame("ACTUATOR_CONTROL_TARGET", 0, time_usec=7, group_mlx=0, controls=[0.25, -0.5, 0.125] + [0.0] * 5)
    ex = compile_signal(SignalSpec("u", "/mavlink/ACTUATOR_CONTROL_TARGET", "controls.0 - 2 * controls.1"))
    assert ex.expression.operands == ("controls.0", "controls.1")
    assert ex.value(act.data) == (1.25, None)                    # 0.25 - 2 * -0.5
    nested = {"gyro": {"x": 3.0, "y": -1.0}, "gyro_x": 10.0}     # a path and a key that look alike
    ex = compile_signal(SignalSpec("g", "/rig", "gyro.x - gyro_x + gyro.y"))
    assert ex.value(nested) == (-8.0, None)
    ulog = {"control[0]": 0.5, "control[1]": 0.25, "timestamp": 1}   # pyulog's flattened array fields
    assert compile_signal(SignalSpec("t", "/ulog/actuator_controls_0", "control[0] / control[1]")).value(ulog) == (2.0, None)
    assert compile_signal(SignalSpec("t", "/ulog/x", "control[1]")).value(ulog) == (0.25, None)


def test_live_value_and_offline_columns_agree_to_the_bit_and_missing_samples_match():
    ex = compile_signal(SignalSpec("m", "/x", "(a - b) / (c + 0.1) * 3.7 - -a", scale=0.3, offset=11.0))
    rng = np.random.default_rng(4)
    cols = {k: rng.normal(size=500) * 1e3 for k in "abc"}
    cols["c"][7] = -0.1                                          # a division by zero
    cols["a"][9] = np.nan                                        # a null in the log
    offline = ex.values(cols)
    for i in range(500):
        v, problem = ex.value({k: float(cols[k][i]) if np.isfinite(cols[k][i]) else None for k in "abc"})
        if i in (7, 9):
            assert v is None and problem == "not_a_number" and np.isnan(offline[i])
        else:
            assert problem is None and v == offline[i]           # the same IEEE operations, in the same order


def test_bad_field_expressions_name_the_key_and_the_position():
    with pytest.raises(ConfigError, match=r"^m\.toml: signals\.x\.field = 'servo2_raw - ': unexpected end of expression$"):
        parse_field("servo2_raw - ", "m.toml: signals.x.field")
    with pytest.raises(ConfigError, match=r"'gyro\.x \$ 2': unexpected character '\$' at position 7"):
        parse_field("gyro.x $ 2", "f")
    with pytest.raises(ConfigError, match="reads no field"):
        parse_field("2 * 3", "f")


# ----------------------------------------------------------------------------- selection, live


def pid(t_ns: int, axis: int, desired: float, achieved: float, sysid: int = 1) -> Frame:
    return frame("PID_TUNING", t_ns, sysid=sysid, axis=axis, desired=desired, achieved=achieved)


def test_where_takes_only_its_axis_of_pid_tuning_live_and_offline(tmp_path):
    from livesweep.telemetry.mavlink_codec import json_schema
    from livesweep.telemetry.mcap_log import McapLogWriter

    frames = []
    for k in range(300):                                          # one message type, three axes in turn
        t = 1_000_000_000 + k * 20_000_000
        frames += [pid(t, 1, 0.01 * k, 0.02 * k), pid(t + 1_000_000, 2, -0.5 * k, 1.0), pid(t + 2_000_000, 3, 7.0, 8.0)]
    sigs = {"roll": SignalSpec("roll", "/mavlink/PID_TUNING", "desired", where={"axis": 1}),
            "pitch": SignalSpec("pitch", "/mavlink/PID_TUNING", "desired", where=(("axis", 2),))}
    al = GridAligner(sigs, ["roll", "pitch"], 50.0)
    for f in frames:
        al.push(f)
    assert al.signal_counts["roll"] == {"samples": 300, "missing_field": 0, "not_a_number": 0, "filtered": 600,
                                        "other_vehicle": 0}
    assert al.signal_counts["pitch"]["samples"] == 300 and al.counts["frames_used"] == 600   # axis 3 used by none
    blocks = [b for b in iter(al.pop_ready, None)]
    v = np.hstack([b.values for b in blocks])
    t = blocks[0].t0_s + np.arange(v.shape[1]) / 50.0
    ok = np.concatenate([b.valid for b in blocks])
    # roll: desired = 0.01 k at receive time 1 + 0.02 k s -> 0.5 (t - 1); pitch -0.5 k at 1.001 + 0.02 k s
    np.testing.assert_allclose(v[0, ok], 0.5 * (t[ok] - 1.0), atol=1e-6)
    np.testing.assert_allclose(v[1, ok], -25.0 * (t[ok] - 1.001), atol=1e-5)
    # offline: the same selection on the recording
    path = tmp_path / "pid.mcap"
    with McapLogWriter(path) as w:
        w.add_channel("/mavlink/PID_TUNING", "mavlink.PID_TUNING", json_schema("PID_TUNING"))
        for f in frames:
            w.write(f.topic, f.data, log_time_ns=f.receive_ns)
    out = read_signals(RecordSpec(path), sigs, ["roll", "pitch"])
    np.testing.assert_allclose(out["roll"].values, 0.01 * np.arange(300), rtol=1e-6)      # float32 on the wire
    np.testing.assert_array_equal(out["roll"].t_s, (1_000_000_000 + np.arange(300) * 20_000_000) / 1e9)
    assert out["pitch"].source == "pid.mcap:/mavlink/PID_TUNING.desired [axis = 2]"
    none = {"q": SignalSpec("q", "/mavlink/PID_TUNING", "desired", where={"axis": 4})}
    with pytest.raises(LogFormatError, match=r"signal 'q' .*900 messages on the topic, none with axis = 4"):
        read_signals(RecordSpec(path), none, ["q"])


def test_explicit_sysid_overrides_the_vehicle_lock_for_its_own_frames():
    """System 1 is seen first and locked; a signal that names sysid 2 takes system 2's frames (and
    only those), with a clock of its own, while the locked signals keep ignoring system 2."""
    sigs = {"p1": SignalSpec("p1", "/mavlink/ATTITUDE", "rollspeed", "time_boot_ms", 1e-3),
            "p2": SignalSpec("p2", "/mavlink/ATTITUDE", "rollspeed", "time_boot_ms", 1e-3, sysid=2),
            "c3": SignalSpec("c3", "/mavlink/ATTITUDE", "rollspeed", "time_boot_ms", 1e-3, sysid=2, compid=3)}
    al = GridAligner(sigs, ["p1", "p2"], 50.0)
    frames = []
    for k in range(200):
        frames.append(frame("ATTITUDE", k * 10_000_000, sysid=1, time_boot_ms=1000 + 10 * k, rollspeed=1.0))
        # system 2 booted 500 s earlier: its stamps would wreck system 1's clock if they shared it
        frames.append(frame("ATTITUDE", k * 10_000_000 + 1, sysid=2, time_boot_ms=501_000 + 10 * k, rollspeed=2.0))
    for f in frames:
        al.push(f)
    assert al.system == 1 and al.counts["other_system"] == 200
    assert al.signal_counts["p1"]["samples"] == 200 and al.signal_counts["p1"]["other_vehicle"] == 200
    assert al.signal_counts["p2"]["samples"] == 200 and al.signal_counts["p2"]["filtered"] == 200
    assert al.counts["clock_rejected"] == 0 and al.counts["resets"] == 0
    assert set(al.clocks) == {("/mavlink/ATTITUDE", "time_boot_ms"), ("/mavlink/ATTITUDE", "time_boot_ms", 2, None)}
    al3 = GridAligner(sigs, ["c3"], 50.0)
    for f in frames:
        al3.push(f)
    assert al3.signal_counts["c3"]["filtered"] == 400 and al3.system is None     # nothing locked


@pytest.mark.slow
def test_sysid_selection_on_a_real_three_system_tlog_matches_pymavlink(tmp_path):
    """The autotest tlog holds systems 1, 250 and 0; TIMESYNC comes from 1 and 250. A signal with
    sysid = 250 gets exactly system 250's TIMESYNC ts1 values as pymavlink reads them, offline and live."""
    need(AUTOTEST)
    from pymavlink import mavutil

    from livesweep.convert import convert

    r = mavutil.mavmmaplog(str(AUTOTEST))                    # pymavlink's own tlog reader, built directly
    ref = {}
    while (m := r.recv_match(type="TIMESYNC")) is not None:
        ref.setdefault(m.get_srcSystem(), []).append(float(m.ts1))
    assert sorted(ref) == [1, 250] and len(ref[250]) == 18
    out = tmp_path / "autotest.mcap"
    convert(AUTOTEST, out)
    sigs = {"gcs": SignalSpec("gcs", "/mavlink/TIMESYNC", "ts1", sysid=250),
            "fc": SignalSpec("fc", "/mavlink/TIMESYNC", "ts1", sysid=1, compid=1),
            "roll": SignalSpec("roll", "/mavlink/ATTITUDE", "roll")}
    got = read_signals(RecordSpec(out), sigs, ["gcs", "fc"])
    np.testing.assert_array_equal(got["gcs"].values, ref[250])
    np.testing.assert_array_equal(got["fc"].values, ref[1])
    al = GridAligner(sigs, ["roll", "gcs"], 10.0)
    for m in iter_file_order(out):
        al.push(Frame(m.topic, m.log_time_ns, None, m.data))
    assert al.system == 1                                    # the lock follows ATTITUDE: system 1
    assert al.signal_counts["gcs"]["samples"] == 18 and al.signal_counts["gcs"]["filtered"] == len(ref[1])


# ----------------------------------------------------------------------------- one path, live = offline


@pytest.mark.slow
def test_live_aligner_equals_offline_reader_on_the_same_recording():
    """The simulated cruise sweep log: an expression signal (a servo mix) and a scaled rate, pushed
    frame by frame through the aligner, equal the offline reader's samples interpolated at the
    aligner's grid times (the aligner's linear interpolation; rounding only)."""
    log = ROOT / "replay_logs" / "xv15_cruise_sweeps_da.mcap"
    signals, _ = load_channel_map(ROOT / "config" / "xv15_channels.toml")
    sigs = {"mix": SignalSpec("mix", "/mavlink/SERVO_OUTPUT_RAW", "0.1 * (servo1_raw - servo4_raw) + 0.5 * servo1_raw",
                              "time_usec", 1e-6, scale=0.5, offset=-300.0, units="deg"),
            "p": signals["p"]}
    offline = read_signals(RecordSpec(log), sigs, ["mix", "p"])
    al = GridAligner(sigs, ["mix", "p"], 50.0)
    blocks = []
    for m in iter_file_order(log, ["/mavlink/SERVO_OUTPUT_RAW", "/mavlink/HIGHRES_IMU"]):
        al.push(Frame(m.topic, m.log_time_ns, m.publish_time_ns, m.data))
        while (b := al.pop_ready()) is not None:
            blocks.append(b)
    assert al.counts["clock_rejected"] == al.counts["resets"] == al.counts["late_dropped"] == 0
    for n in ("mix", "p"):
        assert al.signal_counts[n]["samples"] == offline[n].t_s.size
    v = np.hstack([b.values for b in blocks])
    ok = np.concatenate([b.valid for b in blocks])
    t = blocks[0].t0_s + np.arange(v.shape[1]) / 50.0
    assert ok.mean() > 0.99 and t[-1] > 200.0
    for i, n in enumerate(("mix", "p")):
        o = offline[n]
        ref = np.interp(t[ok], o.t_s, o.values)
        np.testing.assert_allclose(v[i, ok], ref, rtol=1e-12, atol=1e-9 * np.max(np.abs(o.values)))


def test_nested_stamp_and_value_paths_live_as_offline():
    """A generic JSON source: the value at ``gyro.x`` and the stamp at ``header.stamp_ns`` are
    found live as the offline reader finds them (the stamp clock keeps the stamps' own time)."""
    spec = SignalSpec("q", "/rig/imu", "gyro.x * 2", stamp="header.stamp_ns", stamp_scale=1e-9)
    al = GridAligner({"q": spec}, ["q"], 100.0)
    for k in range(300):
        al.push(Frame("/rig/imu", k, None, {"header": {"stamp_ns": 10**9 + k * 10_000_000}, "gyro": {"x": 0.001 * k}}))
    assert al.signal_counts["q"]["samples"] == 300 and al.counts["missing_field"] == 0
    blocks = list(iter(al.pop_ready, None))
    v = np.hstack([b.values for b in blocks])
    t = blocks[0].t0_s + np.arange(v.shape[1]) / 100.0
    np.testing.assert_allclose(v[0], 0.2 * (t - 1.0), atol=1e-9)


# ----------------------------------------------------------------------------- diagnosis


def test_diagnosis_names_an_absent_topic_a_misspelt_field_and_a_selection_nothing_matches():
    frames = [frame("HEARTBEAT", k, type=2, autopilot=3) for k in range(5)]
    frames += [pid(10 + k, 1, 0.1, 0.2) for k in range(500)]
    frames += [frame("SERVO_OUTPUT_RAW", 1000 + k, time_usec=k, servo1_raw=1500) for k in range(40)]
    sigs = {"p": SignalSpec("p", "/mavlink/ATTITUDE", "rollspeed"),
            "da": SignalSpec("da", "/mavlink/SERVO_OUTPUT_RAW", "servo1_rawx - servo2_raw"),
            "q": SignalSpec("q", "/mavlink/PID_TUNING", "achieved", where={"axis": 2}),
            "roll": SignalSpec("roll", "/mavlink/PID_TUNING", "desired", where={"axis": 1})}
    al = GridAligner(sigs, list(sigs), 50.0)
    for f in frames:
        al.push(f)
    al.settle_choice()                    # ATTITUDE never came: the system that sent the rest is followed
    assert al.signal_counts["da"]["missing_field"] == 40 and al.signal_counts["q"]["filtered"] == 500
    lines = diagnose(sigs, al.signal_counts, topics_seen_from(frames))
    assert lines[0] == ("signal p: no frames on /mavlink/ATTITUDE (topics seen: /mavlink/HEARTBEAT, "
                        "/mavlink/PID_TUNING, /mavlink/SERVO_OUTPUT_RAW)")
    assert lines[1].startswith("signal da: field 'servo1_rawx' missing from /mavlink/SERVO_OUTPUT_RAW "
                               "(fields there: compid, port, servo10_raw, servo11_raw, ")
    assert lines[2] == "signal q: 500 frames of /mavlink/PID_TUNING, none with axis = 2"
    assert len(lines) == 3                                   # roll found its samples
    # the same from field names alone, and before any frame
    seen = {t: (n, set(sample)) for t, (n, sample) in topics_seen_from(frames).items()}
    assert diagnose(sigs, al.signal_counts, seen)[1].startswith("signal da: field 'servo1_rawx' missing")
    assert diagnose({"p": sigs["p"]}, None, {}) == ["signal p: no frames on /mavlink/ATTITUDE (no frames at all yet)"]


def test_diagnosis_tells_another_vehicle_and_non_numbers():
    sigs = {"p": SignalSpec("p", "/mavlink/ATTITUDE", "rollspeed"), "s": SignalSpec("s", "/zenoh/x", "v")}
    al = GridAligner(sigs, ["p", "s"], 50.0, system=(1, None))
    frames = [Frame("/mavlink/HEARTBEAT", 0, None, {"sysid": 7, "compid": 1})]
    al.push(Frame("/mavlink/ATTITUDE", 0, None, {"sysid": 1, "compid": 1, "rollspeed": 0.1}))
    frames += [frame("ATTITUDE", k, sysid=2, rollspeed=0.2) for k in range(30)]
    frames += [Frame("/zenoh/x", k, None, {"v": "fast"}) for k in range(12)]
    for f in frames:
        al.push(f)
    lines = diagnose({"s": sigs["s"]}, al.signal_counts, topics_seen_from(frames))
    assert lines == ["signal s: 12 frames of /zenoh/x gave no number (null, text, a non-finite value or a "
                     "division by zero in 'v')"]
    al2 = GridAligner({"p": sigs["p"]}, ["p"], 50.0, system=(1, None))
    al2.push(Frame("/mavlink/ATTITUDE", 0, None, {"sysid": 1, "compid": 1}))   # gives nothing
    for f in frames:
        al2.push(f)
    assert al2.signal_counts["p"] == {"samples": 0, "missing_field": 1, "not_a_number": 0, "filtered": 0,
                                      "other_vehicle": 30}
    (line,) = diagnose({"p": sigs["p"]}, al2.signal_counts, topics_seen_from(frames))
    assert line.startswith("signal p: 30 frames of /mavlink/ATTITUDE, none from the vehicle analysed")
