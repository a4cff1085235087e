"""livesweep.telemetry.signals: named signals read from real MCAP files, checked against mcap's own
reader; time cropping; generic (non-MAVLink) JSON logs; errors that name file, topic and field."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from livesweep.config import RecordSpec, SignalSpec, load_case
from livesweep.errors import ConfigError, LogFormatError
from livesweep.telemetry.mcap_log import McapLogWriter
from livesweep.telemetry.signals import RawSignal, read_signals

REPO = Path(__file__).resolve().parents[1]
CASE = REPO / "config" / "xv15_cruise_lateral.toml"
LOG = REPO / "replay_logs" / "xv15_cruise_sweeps_da.mcap"


def _independent(path: Path, topics: list[str]) -> dict[str, list[dict]]:
    """Decoded messages per topic in log-time order, read with mcap's own reader and json.loads."""
    out: dict[str, list[dict]] = {t: [] for t in topics}
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(topics=topics, log_time_order=True):
            out[channel.topic].append(json.loads(message.data))
    return out


START_S, END_S = 150.0, 250.0  # exact stamp values of both topics (time_usec * 1e-6)


@pytest.fixture(scope="module")
def cruise():
    """p, r (one topic) and da from the shipped cruise log through the case file's [signals],
    cropped to [150 s, 250 s) on the vehicle clock, and the same topics read independently."""
    case = load_case(CASE)
    record = RecordSpec(LOG, "middle of the sweeps", start_s=START_S, end_s=END_S)
    signals = read_signals(record, case.signals, ["p", "da", "r"])
    return signals, _independent(LOG, ["/mavlink/HIGHRES_IMU", "/mavlink/SERVO_OUTPUT_RAW"])


def test_sample_log_matches_mcap_reader_and_crops_half_open(cruise):
    signals, messages = cruise
    assert list(signals) == ["p", "da", "r"]
    # scale / offset / stamp written here, not taken from the case file
    checks = {
        "p": ("/mavlink/HIGHRES_IMU", "xgyro", "time_usec", 1e-6, 57.29577951308232, 0.0, "deg/s"),
        "r": ("/mavlink/HIGHRES_IMU", "zgyro", "time_usec", 1e-6, 57.29577951308232, 0.0, "deg/s"),
        "da": ("/mavlink/SERVO_OUTPUT_RAW", "servo1_raw", "time_usec", 1e-6, 0.1, -150.0, "deg"),
    }
    for name, (topic, field, stamp, ss, scale, offset, units) in checks.items():
        sig = signals[name]
        assert isinstance(sig, RawSignal)
        t = np.array([m[stamp] * ss for m in messages[topic]])
        v = np.array([scale * m[field] + offset for m in messages[topic]])
        keep = (t >= START_S) & (t < END_S)
        assert sig.name == name and sig.units == units
        assert sig.source == f"xv15_cruise_sweeps_da.mcap:{topic}.{field}"
        assert sig.t_s.shape == t[keep].shape and sig.values.shape == v[keep].shape
        np.testing.assert_array_equal(sig.t_s, t[keep])
        np.testing.assert_allclose(sig.values, v[keep], rtol=1e-15, atol=1e-12)
    # [150, 250): the first sample is at 150.0 exactly, 250.0 is excluded
    # (100 Hz IMU: 10000 samples, 50 Hz servos: 5000)
    assert signals["p"].t_s.size == 10000 and signals["da"].t_s.size == 5000
    assert signals["p"].t_s[0] == 150.0 and signals["p"].t_s[-1] == pytest.approx(249.99, abs=1e-9)
    assert signals["da"].t_s[0] == 150.0 and signals["da"].t_s[-1] == pytest.approx(249.98, abs=1e-9)
    assert np.median(np.diff(signals["p"].t_s)) == pytest.approx(0.01, abs=1e-9)
    # the sweep is +/-3 deg of aileron (seed test point) and the values are read-only
    assert 2.5 < np.max(np.abs(signals["da"].values)) <= 3.05
    assert not signals["da"].values.flags.writeable


# --------------------------------------------------------------------------------------------
# a generic JSON log (not MAVLink)
# --------------------------------------------------------------------------------------------

RIG_SCHEMA = {
    "type": "object",
    "properties": {
        "header": {"type": "object", "properties": {"stamp_ns": {"type": "integer"}}},
        "gyro": {"type": "object", "properties": {"x": {"type": ["number", "null"]}}},
        "cmd": {"type": "array", "items": {"type": "number"}},
        "flat": {"type": "number"},
        "gone": {"type": ["number", "null"]},
    },
}
LOG_T0_NS = 1_700_000_000_000_000_000


def _rig_log(path: Path, n: int = 200) -> dict:
    """A rig at 100 Hz: vehicle stamp in ns in header.stamp_ns (starting at 5 s), a receive time
    3 ms later, gyro.x with three nulls, a command array, a constant and an all-null field."""
    k = np.arange(n)
    stamp_ns = 5_000_000_000 + k * 10_000_000
    gyro = np.sin(0.3 * k)
    nulls = {17, 18, 150}
    with McapLogWriter(path) as w:
        w.add_channel("/rig/imu", "rig.Imu", RIG_SCHEMA)
        w.add_channel("/rig/empty", "rig.Imu", RIG_SCHEMA)
        for i in range(n):
            msg = {"header": {"stamp_ns": int(stamp_ns[i])},
                   "gyro": {"x": None if i in nulls else float(gyro[i])},
                   "cmd": [float(i), -2.0 * i], "flat": 4.0, "gone": None}
            w.write("/rig/imu", msg, log_time_ns=LOG_T0_NS + int(stamp_ns[i]) + 3_000_000)
    return {"stamp_ns": stamp_ns, "gyro": gyro, "nulls": sorted(nulls)}


@pytest.fixture()
def rig(tmp_path):
    path = tmp_path / "rig.mcap"
    return path, _rig_log(path)


RIG_SIGNALS = {
    "q": SignalSpec("q", "/rig/imu", "gyro.x", stamp="header.stamp_ns", stamp_scale=1e-9, scale=2.0, offset=0.5,
                    units="rad/s"),
    "u": SignalSpec("u", "/rig/imu", "cmd.1", stamp="header.stamp_ns", stamp_scale=1e-9, units="%"),
    "u_rx": SignalSpec("u_rx", "/rig/imu", "cmd.0"),  # no stamp: log_time
    "flat": SignalSpec("flat", "/rig/imu", "flat", stamp="header.stamp_ns", stamp_scale=1e-9),
    "gone": SignalSpec("gone", "/rig/imu", "gone", stamp="header.stamp_ns", stamp_scale=1e-9),
    "nofield": SignalSpec("nofield", "/rig/imu", "gyro.y", stamp="header.stamp_ns", stamp_scale=1e-9),
    "notopic": SignalSpec("notopic", "/rig/baro", "alt"),
    "empty": SignalSpec("empty", "/rig/empty", "flat"),
}


def test_generic_json_log_through_signal_specs(rig):
    path, truth = rig
    out = read_signals(RecordSpec(path), RIG_SIGNALS, ["q", "u", "u_rx"])
    t_expected = truth["stamp_ns"] * 1e-9
    np.testing.assert_array_equal(out["q"].t_s, t_expected)
    expected_q = 2.0 * truth["gyro"] + 0.5
    expected_q[truth["nulls"]] = np.nan
    np.testing.assert_array_equal(out["q"].values, expected_q)  # nulls kept as NaN, same places
    assert np.flatnonzero(np.isnan(out["q"].values)).tolist() == [17, 18, 150]
    assert out["q"].units == "rad/s" and out["q"].source == "rig.mcap:/rig/imu.gyro.x"
    np.testing.assert_array_equal(out["u"].values, -2.0 * np.arange(200))
    # log_time clock: receive time in s since the UNIX epoch, 3 ms after the stamp
    np.testing.assert_allclose(out["u_rx"].t_s, (LOG_T0_NS + truth["stamp_ns"] + 3_000_000) / 1e9, rtol=0, atol=1e-6)


def test_time_cropping_is_half_open_on_the_stamp_clock(rig):
    path, truth = rig
    t = truth["stamp_ns"] * 1e-9
    start, end = t[40], t[120]  # exact stamp values on both boundaries
    out = read_signals(RecordSpec(path, start_s=start, end_s=end), RIG_SIGNALS, ["u"])["u"]
    assert out.t_s.size == 80
    assert out.t_s[0] == start and out.t_s[-1] == t[119]
    np.testing.assert_array_equal(out.values, -2.0 * np.arange(40, 120))
    only_start = read_signals(RecordSpec(path, start_s=t[197]), RIG_SIGNALS, ["u"])["u"]
    assert only_start.values.tolist() == [-394.0, -396.0, -398.0]
    only_end = read_signals(RecordSpec(path, end_s=t[3]), RIG_SIGNALS, ["u"])["u"]
    assert only_end.values.tolist() == [0.0, -2.0, -4.0]
    # one sample in range is constant by definition and is rejected, naming the range
    with pytest.raises(LogFormatError, match=r"'u' .*constant at -398\.0 % over \[6\.99 s, end\) \(1 samples\)"):
        read_signals(RecordSpec(path, start_s=t[199]), RIG_SIGNALS, ["u"])


def test_missing_topic_names_file_topic_and_topics_present(rig):
    path, _ = rig
    with pytest.raises(LogFormatError) as err:
        read_signals(RecordSpec(path), RIG_SIGNALS, ["notopic"])
    msg = str(err.value)
    assert str(path) in msg and "'/rig/baro'" in msg and "notopic" in msg
    assert "/rig/imu" in msg and "/rig/empty" in msg  # what is there


def test_missing_field_names_file_topic_and_field(rig):
    path, _ = rig
    with pytest.raises(LogFormatError) as err:
        read_signals(RecordSpec(path), RIG_SIGNALS, ["q", "nofield"])
    msg = str(err.value)
    assert str(path) in msg and "'/rig/imu'" in msg and "'gyro.y'" in msg and "nofield" in msg


def test_constant_and_all_nan_signals_are_rejected_by_name(rig):
    path, _ = rig
    with pytest.raises(LogFormatError, match=r"signal 'flat' \(topic '/rig/imu', field 'flat'\): constant at 4\.0"):
        read_signals(RecordSpec(path), RIG_SIGNALS, ["q", "flat"])
    with pytest.raises(LogFormatError, match=r"signal 'gone' .*all 200 values .* NaN") as err:
        read_signals(RecordSpec(path), RIG_SIGNALS, ["gone"])
    assert str(path) in str(err.value)


def test_no_samples_in_range_and_empty_topic(rig):
    path, _ = rig
    with pytest.raises(LogFormatError) as err:
        read_signals(RecordSpec(path, start_s=100.0, end_s=200.0), RIG_SIGNALS, ["u"])
    msg = str(err.value)
    assert "no samples in the requested time range [100.0 s, 200.0 s)" in msg
    assert "'/rig/imu'" in msg and "'cmd.1'" in msg and "5.0 s to 6.99 s" in msg and str(path) in msg
    with pytest.raises(LogFormatError, match=r"signal 'empty' .*'/rig/empty'.*no messages"):
        read_signals(RecordSpec(path), RIG_SIGNALS, ["empty"])


def test_config_errors(rig):
    path, _ = rig
    with pytest.raises(ConfigError, match=r"signal 'w' is not defined; defined signals: q, u"):
        read_signals(RecordSpec(path), RIG_SIGNALS, ["q", "w"])
    with pytest.raises(ConfigError, match=r"start_s = 6\.0 must be before end_s = 6\.0"):
        read_signals(RecordSpec(path, start_s=6.0, end_s=6.0), RIG_SIGNALS, ["q"])
    with pytest.raises(LogFormatError, match=r"missing\.mcap does not exist"):
        read_signals(RecordSpec(path.with_name("missing.mcap")), RIG_SIGNALS, ["q"])
