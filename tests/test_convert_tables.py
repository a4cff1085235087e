"""``livesweep convert`` for tables (X-Plane .npy / .dat) and PX4 ULog, on the real shared data.

The data are read in place from ``shared/data`` (README there) and never copied into the
repository; every test that needs a file skips when it is absent, and the ULog tests skip without
pyulog. Each file is converted once per module (module-scoped fixtures).

References are independent of livesweep's own numerics: scipy (np.interp to 50 Hz +
scipy.signal csd/welch, as tests/test_xplane_real_data.py), pyulog's own arrays, hashlib, and
PX4's logged attitude gain.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps

from livesweep import cli
from livesweep.convert import convert
from livesweep.errors import ConfigError, LogFormatError
from livesweep.telemetry.mcap_log import read_attachments, read_fields, read_messages, read_metadata, read_summary

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "config"
_CANDIDATES = (REPO.parent / "shared" / "data", Path("/work/shared/data"))
DATA = next((p for p in _CANDIDATES if (p / "README.md").is_file()), None)

XPLANE = "xplane_c172_pitch_sweeps/sweep_data_2017_10_18_14_07"
FIELDS = ("time_s", "time", "de", "theta", "airspeed", "q", "q_dps", "alpha", "vvi", "alt")
DEG = 57.29578                   # the column map's scale for q_dps


def _data(rel: str) -> Path:
    if DATA is None or not (DATA / rel).is_file():
        pytest.skip(f"shared data file {rel} not found (shared/data)")
    return DATA / rel


def _pyulog():
    return pytest.importorskip("pyulog", reason="pyulog (livesweep[ulog]) is not installed")


# ---------------------------------------------------------------------------------------------
# fixtures: each file converted once
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("convert_tables")


@pytest.fixture(scope="module")
def xplane_npy(work):
    src = _data(XPLANE + ".npy")
    res = convert(src, work / "xplane_c172_pitch.mcap", column_map=CONFIG / "xplane_c172_columns.toml")
    return src, res


@pytest.fixture(scope="module")
def xplane_dat(work):
    src = _data(XPLANE + ".dat")
    res = convert(src, work / "xplane_c172_dat.mcap", column_map=str(CONFIG / "xplane_c172_columns.toml"))
    return src, res


@pytest.fixture(scope="module")
def xplane_report(work, xplane_npy):
    """``livesweep identify`` on the converted .npy: frequency responses, q/de transfer function, report."""
    case = work / "xplane_c172_pitch.toml"
    shutil.copy(CONFIG / "xplane_c172_pitch.toml", case)
    out = work / "xplane_out"
    assert cli.main(["identify", str(case), "--out", str(out), "--stage", "transfer-functions"]) == 0
    return json.loads((out / "report.json").read_text()), out


@pytest.fixture(scope="module")
def sample_ulg(work):
    _pyulog()
    src = _data("px4_ulog/sample.ulg")
    return src, convert(src, work / "px4_sample.mcap")


@pytest.fixture(scope="module")
def small_ulg(work):
    _pyulog()
    src = _data("px4_ulog/sample_log_small.ulg")
    return src, convert(src, work / "px4_small.mcap")


def _pair(report, output, input_):
    fr = next(f for f in report["frequency_responses"] if (f["output"], f["input"]) == (output, input_))
    w = np.asarray(fr["omega_rad_s"])
    H = 10 ** (np.asarray(fr["magnitude_db"]) / 20) * np.exp(1j * np.deg2rad(fr["phase_deg"]))
    return w, H, np.asarray(fr["coherence"])


# ---------------------------------------------------------------------------------------------
# X-Plane table: conversion, provenance, text == npy
# ---------------------------------------------------------------------------------------------

def test_npy_conversion_writes_one_message_per_row_with_mapped_fields(xplane_npy):
    src, res = xplane_npy
    raw = np.load(src)
    assert res.format == "numpy" and res.format_version.startswith("NumPy .npy v1.0, float64, 21909 x 8")
    assert res.topics == {"/table/xplane_c172": 21909}
    assert res.messages_read == res.messages_written == 21909
    assert res.skipped == {} and res.repaired == {} and res.warnings == ()
    cols = read_fields(res.output, "/table/xplane_c172", list(FIELDS), time="publish")
    np.testing.assert_array_equal(cols["time_s"], raw[:, 0])          # JSON floats round-trip exactly
    for name, k in (("de", 1), ("theta", 2), ("airspeed", 3), ("q", 4), ("alpha", 5), ("vvi", 6), ("alt", 7)):
        np.testing.assert_array_equal(cols[name], raw[:, k])
    np.testing.assert_allclose(cols["q_dps"], DEG * raw[:, 4], rtol=1e-15)
    # log/publish time: the time column as ns from 0 (the X-Plane clock starts near 2916 s)
    np.testing.assert_array_equal(cols["t_ns"], np.round(raw[:, 0] * 1e9).astype(np.int64))


def test_conversion_metadata_records_source_hash_and_counts(xplane_npy):
    src, res = xplane_npy
    meta = read_metadata(res.output)
    assert meta["source"]["name"] == src.name
    assert meta["source"]["sha256"] == hashlib.sha256(src.read_bytes()).hexdigest() == res.sha256
    assert meta["source"]["format"] == "numpy" and meta["source"]["format_version"] == res.format_version
    assert meta["source"]["size_bytes"] == str(src.stat().st_size)
    assert meta["conversion"]["messages_read"] == meta["conversion"]["messages_written"] == "21909"
    assert json.loads(meta["conversion"]["skipped"]) == {}
    table = meta["table"]
    assert table["topic"] == "/table/xplane_c172" and table["time_column"] == "time"
    units = {k: v["units"] for k, v in json.loads(table["columns"]).items()}
    assert units["q"] == "rad/s" and units["q_dps"] == "deg/s" and units["alt"] == "ft"
    # the column map used goes in as an attachment (DESIGN §4.1)
    assert read_attachments(res.output)["column_map.toml"] == (CONFIG / "xplane_c172_columns.toml").read_bytes()


@pytest.mark.slow
def test_dat_text_converts_to_the_same_messages_as_npy(xplane_npy, xplane_dat):
    (_, a), (_, b) = xplane_npy, xplane_dat
    assert b.format == "text" and "tab-separated" in b.format_version
    assert b.topics == a.topics and b.skipped == {}        # skip_rows = 1 in the map: no automatic preamble
    ca = read_fields(a.output, "/table/xplane_c172", list(FIELDS))
    cb = read_fields(b.output, "/table/xplane_c172", list(FIELDS))
    for f in (*FIELDS, "t_ns"):
        # the .dat holds the float32 values printed in full: the same numbers to float32 precision
        # (measured: identical to the bit)
        np.testing.assert_allclose(cb[f], ca[f], rtol=np.finfo(np.float32).eps, atol=0, err_msg=f)


def test_dat_without_column_map_uses_its_header_and_skips_the_preamble(work):
    # the .dat's first 502 lines (preamble, header, 500 rows), in the temporary folder only
    lines = _data(XPLANE + ".dat").read_bytes().splitlines(keepends=True)
    src = work / "sweep_data_head.dat"
    src.write_bytes(b"".join(lines[:502]))
    res = convert(src, work / "dat_nomap.mcap")
    assert res.topics == {"/table/sweep_data_head": 500}
    assert res.skipped == {"preamble_lines": 1}              # the "dt_mean N" line
    msg = next(read_messages(res.output))
    assert list(msg.data) == ["time_s", "time", "yokeele", "theta", "aspd", "q", "aoa", "VVI", "alt"]
    assert msg.data["time_s"] == msg.data["time"] == pytest.approx(2916.43994140625)


# ---------------------------------------------------------------------------------------------
# X-Plane: identify end to end against scipy
# ---------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_identify_q_de_agrees_with_independent_scipy_welch(xplane_npy, xplane_report):
    src, _ = xplane_npy
    report, out = xplane_report
    assert (out / "report.html").is_file()
    w, H, C = _pair(report, "q", "de")                      # deg/s per yoke unit

    # scipy: raw columns linearly interpolated to 50 Hz from the first sample, Welch (Hann,
    # nperseg 1024, 50 % overlap), H1 = Pxy / Pxx
    raw = np.load(src)
    t = raw[:, 0]
    grid = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * 50.0)) + 1) / 50.0
    x, y = np.interp(grid, t, raw[:, 1]), DEG * np.interp(grid, t, raw[:, 4])
    kw = dict(fs=50.0, window="hann", nperseg=1024, noverlap=512, detrend="constant")
    f, Pxy = sps.csd(x, y, **kw)
    _, Pxx = sps.welch(x, **kw)
    k = np.flatnonzero((2 * np.pi * f >= 1.0) & (2 * np.pi * f <= 12.6))     # 0.16-2 Hz: 38 bins
    Hs = Pxy[k] / Pxx[k]
    lq, lw = np.log(2 * np.pi * f[k]), np.log(w)
    Hl = np.interp(lq, lw, H.real) + 1j * np.interp(lq, lw, H.imag)
    d_db = 20 * np.log10(np.abs(Hl / Hs))
    d_deg = np.angle(Hl / Hs, deg=True)
    print(f"\n  q/de livesweep composite vs scipy Welch over {len(k)} bins 1-12.6 rad/s: |dB| max "
          f"{np.abs(d_db).max():.2f} rms {np.sqrt(np.mean(d_db ** 2)):.2f}, |deg| max {np.abs(d_deg).max():.1f}")
    # Measured: max 0.39 dB (rms 0.17), max 2.7 deg. The two estimates differ in windows (composite
    # of 8-145 s windows vs one 20.5 s Welch) and livesweep's repairs (49 yoke wild points replaced,
    # trim removed); the scipy estimate alone has a random error of about
    # sqrt(1 - g2) / (|g| sqrt(2 n_avg)) = 0.2 / (0.98 * sqrt(54)) = 2.8 % (0.24 dB, 1.6 deg) at
    # g2 = 0.96, so 1 dB / 6 deg is ~4 sigma of the scipy estimate and 2.5x the measured worst.
    assert np.abs(d_db).max() <= 1.0
    assert np.sqrt(np.mean(d_db ** 2)) <= 0.4
    assert np.abs(d_deg).max() <= 6.0
    # README anchor: |q/de| 0.49 rad/s per yoke (28 deg/s) at 1 Hz, gamma^2 0.99
    Hq1 = np.interp(np.log(2 * np.pi), lw, np.abs(H))
    assert Hq1 == pytest.approx(0.49 * DEG, rel=0.1)
    band = (w >= 0.4) & (w <= 15.0)
    assert np.median(C[band]) >= 0.95


@pytest.mark.slow
def test_identify_short_period_transfer_function(xplane_report):
    report, _ = xplane_report
    tf = next(t for t in report["transfer_functions"] if t["name"] == "q_de")
    p = tf["parameters"]
    w, H, _ = _pair(report, "q", "de")
    w_peak = w[np.argmax(np.abs(H))]
    print(f"\n  q/de = {p['gain']:.1f} (s + {p['1/T_theta2']:.2f}) / [{p['zeta_sp']:.3f}, {p['w_sp']:.2f}] "
          f"e^(-{p['tau']:.3f} s): J {tf['cost']:.1f}; |q/de| peaks at {w_peak:.2f} rad/s")
    # measured: J 14.3, w_sp 5.35 rad/s, zeta_sp 0.64, 1/T_theta2 2.95 rad/s, tau 0; peak 4.67 rad/s
    assert tf["converged"]
    assert tf["cost"] <= 100.0                                   # the method's "acceptable" fit
    assert 0.8 <= p["w_sp"] / w_peak <= 1.5                      # the zero at 1/T_theta2 pulls the peak below w_sp
    assert 0.3 <= p["zeta_sp"] <= 0.9
    assert p["gain"] > 0                                          # pull (+yoke) pitches up (+q) in this file
    assert len(tf["poles"]) == 2 and all(re < 0 and im != 0 for re, im in tf["poles"])


@pytest.mark.slow
def test_identify_theta_q_kinematics_pass_on_the_converted_table(xplane_report):
    report, _ = xplane_report
    checks = report["data_quality"]["kinematic_checks"]
    c = next(c for c in checks if c.get("measured") == "theta")
    assert c["passed"] and abs(c["scale_factor_error"]) < 0.01     # q_dps = 57.29578 * q matches dtheta/dt


# ---------------------------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------------------------

def test_column_map_naming_a_missing_column_is_a_config_error(work):
    src = _data(XPLANE + ".npy")
    bad = work / "bad_columns.toml"
    bad.write_text('name = "x"\ntime = "time"\n[columns.time]\nindex = 0\n[columns.flaps]\nindex = 8\n')
    with pytest.raises(ConfigError) as e:
        convert(src, work / "bad.mcap", column_map=bad)
    msg = str(e.value)
    assert str(bad) in msg and "columns.flaps.index" in msg and src.name in msg and "8 columns" in msg
    assert not (work / "bad.mcap").exists() and not (work / "bad.mcap.partial").exists()
    dat = _data(XPLANE + ".dat")
    with pytest.raises(ConfigError, match=r"columns\.de\.header: 'elevator' is not in the header"):
        convert(dat, work / "bad.mcap", column_map={"skip_rows": 1, "columns": {"de": {"header": "elevator"}}})
    with pytest.raises(ConfigError, match=r"columns\.de: unknown key|columns\.de\.idx: unknown key"):
        convert(src, work / "bad.mcap", column_map={"columns": {"de": {"idx": 1}}})


def test_ragged_text_rows_are_a_clear_error(work):
    src = work / "ragged.csv"
    src.write_text("time,de,q\n0.0,0.1,0.2\n0.02,0.1\n0.04,0.1,0.2\n")
    with pytest.raises(LogFormatError, match=r"ragged\.csv: line 3: 2 fields, expected 3"):
        convert(src, work / "ragged.mcap")
    assert not (work / "ragged.mcap").exists()


def test_nonfinite_cells_and_backward_time_are_counted_rows_kept_in_file_order(work):
    src = work / "small.csv"
    src.write_text("# a comment\ntime,de,q\n0.00,0.1,0.2\n0.02,nan,0.3\n0.01,,0.4\n0.03,0.2,inf\nnan,0.1,0.1\n")
    res = convert(src, work / "small.mcap")
    assert res.skipped == {"nonfinite_cells": 3, "rows_nonfinite_time": 1}
    assert any("1 step(s) backwards" in w and "line 5" in w for w in res.warnings)
    msgs = sorted(read_messages(res.output), key=lambda m: m.sequence)
    assert [m.data["time"] for m in msgs] == [0.0, 0.02, 0.01, 0.03]        # file order
    assert [m.data["de"] for m in msgs] == [0.1, "NaN", "NaN", 0.2]        # the recording's non-finite convention
    assert [m.data["q"] for m in msgs] == [0.2, 0.3, 0.4, "Infinity"]
    assert [m.log_time_ns for m in msgs] == [0, 20_000_000, 10_000_000, 30_000_000]
    meta = read_metadata(res.output)["conversion"]
    assert json.loads(meta["skipped"]) == res.skipped


# ---------------------------------------------------------------------------------------------
# PX4 ULog
# ---------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_ulog_sample_counts_per_topic_equal_pyulog(sample_ulg):
    pyulog = _pyulog()
    src, res = sample_ulg
    ulog = pyulog.ULog(str(src))
    expected = {f"/ulog/{d.name}": len(d.data["timestamp"]) for d in ulog.data_list}   # one instance each
    summary = read_summary(res.output)
    got = {t: n for t, n in summary.message_counts.items() if not t.startswith("/ulog/_")}
    assert got == expected and len(expected) == 15
    assert summary.message_counts["/ulog/_logged_messages"] == len(ulog.logged_messages)
    assert res.messages_read == res.messages_written == sum(summary.message_counts.values())
    assert res.format == "ulog" and res.format_version.startswith("ULog v0, PX4 fd483321") and "AUAV_X21" in res.format_version
    assert res.skipped == {"dropout_events": len(ulog.dropouts)} == {"dropout_events": 4}
    # values and times: roll rate exactly as pyulog gives it; publish time = timestamp (boot), no GPS -> log = publish
    d = next(d for d in ulog.data_list if d.name == "vehicle_attitude")
    cols = read_fields(res.output, "/ulog/vehicle_attitude", ["rollspeed", "timestamp", "q[0]"], time="publish")
    np.testing.assert_array_equal(cols["rollspeed"], d.data["rollspeed"].astype(np.float64))
    np.testing.assert_array_equal(cols["q[0]"], d.data["q[0]"].astype(np.float64))
    np.testing.assert_array_equal(cols["t_ns"], d.data["timestamp"].astype(np.int64) * 1000)
    assert read_summary(res.output).start_ns == min(int(x.data["timestamp"][0]) for x in ulog.data_list) * 1000
    meta = read_metadata(res.output)
    assert meta["ulog"]["utc_offset_us"] == "0" and meta["ulog.parameters"]["MC_ROLL_P"] == "6.5"


def test_ulog_multi_instance_topics_go_to_separate_channels(small_ulg):
    pyulog = _pyulog()
    src, res = small_ulg
    ulog = pyulog.ULog(str(src))
    instances: dict = {}
    for d in ulog.data_list:
        instances.setdefault(d.name, []).append(d)
    multi = {n for n, ds in instances.items() if len(ds) > 1}
    assert {"sensor_gyro", "sensor_accel", "vehicle_imu", "actuator_outputs"} <= multi
    counts = read_summary(res.output).message_counts
    for name, ds in instances.items():
        if name in multi:
            assert f"/ulog/{name}" not in counts
            for d in ds:
                assert counts[f"/ulog/{name}/{d.multi_id}"] == len(d.data["timestamp"]), (name, d.multi_id)
        else:
            assert counts[f"/ulog/{name}"] == len(ds[0].data["timestamp"]), name
    # instances really kept apart: gyro 1's values are gyro 1's
    g1 = next(d for d in instances["sensor_gyro"] if d.multi_id == 1)
    cols = read_fields(res.output, "/ulog/sensor_gyro/1", ["x", "device_id"])
    np.testing.assert_array_equal(cols["x"], g1.data["x"].astype(np.float64))
    assert set(cols["device_id"]) == set(g1.data["device_id"].tolist())
    # this log has GPS time: log_time = boot time + a constant UTC offset; the GPS message's own
    # time_utc_usec agrees with its log_time to within the GPS-to-log latency
    gps = read_fields(res.output, "/ulog/vehicle_gps_position", ["time_utc_usec", "timestamp"])
    offset_ns = gps["t_ns"] - gps["timestamp"].astype(np.int64) * 1000
    assert len(set(offset_ns.tolist())) == 1
    assert np.max(np.abs(gps["t_ns"] / 1e3 - gps["time_utc_usec"])) < 0.5e6            # us: < 0.5 s
    assert read_metadata(res.output)["ulog"]["time_base"].startswith("utc: vehicle_gps_position")
    assert res.skipped == {"dropout_events": 1}


@pytest.mark.slow
def test_px4_case_roll_rate_frequency_response(work, sample_ulg):
    _, res = sample_ulg
    case = work / "px4_sample_roll.toml"
    shutil.copy(CONFIG / "px4_sample_roll.toml", case)
    assert res.output == work / "px4_sample.mcap"                # the case's log = "px4_sample.mcap"
    out = work / "px4_out"
    assert cli.main(["identify", str(case), "--out", str(out), "--stage", "frequency-response"]) == 0
    report = json.loads((out / "report.json").read_text())
    w, H, C = _pair(report, "p", "p_sp")
    band = (w >= 2 * np.pi * 0.5) & (w <= 2 * np.pi * 10.0)
    frac = float(np.mean(C[band] >= 0.9))
    print(f"\n  p/p_sp 0.5-10 Hz: gamma^2 >= 0.9 on {100 * frac:.1f} % (min {C[band].min():.3f}, "
          f"median {np.median(C[band]):.3f}); omega/|H| median {np.median(w[band] / np.abs(H[band])):.2f}")
    # measured: gamma^2 >= 0.9 on 99.3 % of the band, min 0.895, median 0.994 (README: ~0.99)
    assert frac >= 0.9
    assert np.median(C[band]) >= 0.97
    # What this pair measures: in hover the rate setpoint is the attitude loop's output,
    # p_sp = MC_ROLL_P * (phi_sp - phi) with phi_sp ~ 0, so p / p_sp = -s / MC_ROLL_P whatever the
    # rate loop does. Independent anchor: the gain logged in the ULog parameters (6.5).
    k_roll = float(read_metadata(res.output)["ulog.parameters"]["MC_ROLL_P"])
    ratio = w[band] / np.abs(H[band])                  # measured 5.9-7.2, median 6.6
    assert np.median(ratio) == pytest.approx(k_roll, rel=0.15)
    phase = np.angle(H[band], deg=True)
    assert np.median(phase) == pytest.approx(-90.0, abs=10.0)


def test_ulog_without_pyulog_names_the_extra(monkeypatch, work):
    import builtins

    real_import = builtins.__import__

    def no_pyulog(name, *args, **kwargs):
        if name == "pyulog" or name.startswith("pyulog."):
            raise ImportError("No module named 'pyulog'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pyulog)
    from livesweep.convert.ulog import convert_ulog

    with pytest.raises(ConfigError, match=r"pip install 'livesweep\[ulog\]'"):
        convert_ulog(work / "none.ulg", work / "none.mcap")
