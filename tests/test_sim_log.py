"""Simulated test points written as MCAP logs and read back: values, time stamps, rates, metadata."""

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from livesweep.sim.effects import make_effect
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.telemetry.mcap_log import read_attachments, read_fields, read_messages, read_summary
from livesweep.telemetry.sim_telemetry import DEFAULT_START_UTC_NS, write_sim_log

CONFIG = Path(__file__).resolve().parents[1] / "config"


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    sc = sweep_scenario("xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=1.0, omega_max_rad_s=10.0,
                        duration_s=13.0, amplitudes={"da": 3.0}, off_axis_rms=0.2, seed=3,
                        effects=(make_effect("dropouts", output="ay", count=2, duration_s=0.3),))
    res = simulate(sc)
    path = tmp_path_factory.mktemp("log") / "short.mcap"
    info = write_sim_log(res, path)
    return res, path, info


def test_channels_are_json_with_json_schemas(short_log):
    _, path, _ = short_log
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    topics = {c.topic: c for c in summary.channels.values()}
    assert set(topics) == {"/mavlink/SERVO_OUTPUT_RAW", "/mavlink/HIGHRES_IMU", "/mavlink/ATTITUDE",
                           "/mavlink/AOA_SSA", "/mavlink/HEARTBEAT"}
    for c in topics.values():
        assert c.message_encoding == "json"
        assert summary.schemas[c.schema_id].encoding == "jsonschema"


def test_values_and_time_stamps_round_trip(short_log):
    res, path, _ = short_log
    imu = list(read_messages(path, topics="/mavlink/HIGHRES_IMU"))
    t_usec = np.array([m.data["time_usec"] for m in imu])
    assert all(m.publish_time_ns == m.data["time_usec"] * 1000 for m in imu)
    p = res.outputs["p"]
    keep = np.isin(np.round(p.t_s * 1e6).astype(np.int64), t_usec)
    np.testing.assert_array_equal(t_usec, np.round(p.t_s[keep] * 1e6).astype(np.int64))
    xgyro = np.array([m.data["xgyro"] for m in imu])
    np.testing.assert_allclose(np.rad2deg(xgyro), p.values[keep], rtol=1e-6, atol=1e-5)  # float32 on the wire
    np.testing.assert_allclose(np.array([m.data["yacc"] for m in imu]) / 0.3048,
                               res.outputs["ay"].values[keep], rtol=1e-6, atol=1e-5)
    # receive time = fixed UTC start + vehicle time since start + 4 ms latency or more, monotonic
    log_ns = np.array([m.log_time_ns for m in imu])
    lat = log_ns - (DEFAULT_START_UTC_NS + (t_usec * 1000 - round(res.scenario.boot_time_s * 1e9)))
    assert lat.min() >= 4_000_000 and np.median(lat) < 10_000_000
    assert np.all(np.diff(log_ns) >= 0)


def test_streams_have_their_own_rates(short_log):
    _, path, _ = short_log
    dt = {}
    for topic, field, unit in [("/mavlink/SERVO_OUTPUT_RAW", "time_usec", 1e-6), ("/mavlink/ATTITUDE", "time_boot_ms", 1e-3),
                               ("/mavlink/AOA_SSA", "time_usec", 1e-6), ("/mavlink/HIGHRES_IMU", "time_usec", 1e-6)]:
        stamps = np.array([m.data[field] for m in read_messages(path, topics=topic)], dtype=float) * unit
        dt[topic] = np.median(np.diff(stamps))
    assert dt["/mavlink/SERVO_OUTPUT_RAW"] == pytest.approx(0.02)
    assert dt["/mavlink/ATTITUDE"] == pytest.approx(0.02)
    assert dt["/mavlink/AOA_SSA"] == pytest.approx(0.02)
    assert dt["/mavlink/HIGHRES_IMU"] == pytest.approx(0.01)


def test_dropouts_remove_the_messages_that_carry_the_sample(short_log):
    res, path, info = short_log
    n_missing = int(np.sum(~res.outputs["ay"].valid))
    assert n_missing >= 30
    assert info["stats"]["dropped"]["HIGHRES_IMU"] == n_missing
    assert read_summary(path).message_counts["/mavlink/HIGHRES_IMU"] == res.outputs["ay"].t_s.size - n_missing


def test_servo_pwm_is_the_command_in_whole_microseconds(short_log):
    res, path, _ = short_log
    servo = list(read_messages(path, topics="/mavlink/SERVO_OUTPUT_RAW"))
    pwm = np.array([m.data["servo1_raw"] for m in servo])
    np.testing.assert_array_equal(pwm, np.round(1500 + 10 * res.inputs["da"].values).astype(int))
    assert {m.data["servo4_raw"] for m in servo} != {1500}   # off-axis pilot noise on the rudder


def test_test_point_metadata_and_config_attachment(short_log):
    res, path, _ = short_log
    s = read_summary(path)
    tp = s.metadata["test_point"]
    assert tp["aircraft"] == "XV-15" and tp["model"] == "xv15-cruise" and tp["seed"] == "3"
    assert json.loads(tp["effects"]) == [{"kind": "dropouts", "output": "ay", "count": 2, "duration_s": 0.3}]
    sweeps = [v for k, v in s.metadata.items() if k.startswith("segment_") and v["kind"] == "sweep"]
    assert len(sweeps) == 1
    seg = [x for x in res.segments if x.kind == "sweep"][0]
    assert float(sweeps[0]["start_s"]) == seg.start_s and float(sweeps[0]["end_s"]) == seg.end_s
    cfg = json.loads(read_attachments(path)["sim_config.json"])
    assert cfg["seed"] == 3 and cfg["model"] == "xv15-cruise"
    assert cfg["segments"][1]["parameters"]["omega_min_rad_s"] == 1.0


def test_channel_map_reads_the_simulated_signals_back_in_model_units(short_log):
    """config/xv15_channels.toml: value = scale * raw + offset, stamp * stamp_scale = vehicle seconds."""
    res, path, _ = short_log
    signals = tomllib.loads((CONFIG / "xv15_channels.toml").read_text())["signals"]
    truth = {**res.inputs, **res.outputs}
    for name in ("da", "dr", "p", "r", "ay", "beta", "phi"):
        sig = signals[name]
        cols = read_fields(path, sig["topic"], [sig["field"], sig["stamp"]])
        t = cols[sig["stamp"]] * sig["stamp_scale"]
        value = sig.get("scale", 1.0) * cols[sig["field"]] + sig.get("offset", 0.0)
        ref = truth[name]
        idx = np.searchsorted(ref.t_s, t - 1e-7)
        np.testing.assert_allclose(ref.t_s[idx], t, atol=1e-6)
        # PWM is whole microseconds: 0.05 deg; floats are float32 on the wire
        tol = 0.05 + 1e-9 if name in ("da", "dr") else 1e-5 + 1e-6 * np.abs(ref.values[idx])
        assert np.all(np.abs(value - ref.values[idx]) <= tol), name


def test_case_files_name_only_signals_the_channel_map_knows():
    chan = tomllib.loads((CONFIG / "xv15_channels.toml").read_text())["signals"]
    for case in ("xv15_cruise_lateral.toml", "xv15_hover_lateral.toml"):
        c = tomllib.loads((CONFIG / case).read_text())
        for name, sig in c["signals"].items():
            assert sig == chan[name], (case, name)
        sp = c["spectral"]
        assert set(sp["inputs"]) | set(sp["outputs"]) <= set(c["signals"])
        for rec in c["identify"] + c.get("verify", []):
            assert (CONFIG / rec["log"]).resolve().exists(), rec["log"]


def test_packaged_channel_map_is_the_config_one():
    """`livesweep demo` reads the copy inside the package (it must work from a plain install)."""
    import livesweep

    packaged = Path(livesweep.__file__).parent / "data" / "xv15_channels.toml"
    assert packaged.read_text() == (CONFIG / "xv15_channels.toml").read_text()
