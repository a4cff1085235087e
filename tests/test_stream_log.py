"""``livesweep stream``: real autopilot output streamed live over UDP loopback into the real receivers.

The logs are third-party (``../shared/data``, see its README.md) and read in place; every test
that needs one skips when it is absent. References are computed here without livesweep's
readers: pymavlink's own tlog reader (``mavutil.mavmmaplog``, built directly) and a byte walk of
the tlog records; pymavlink's ``DFReader_binary`` for the DataFlash log. The streams run in a
``livesweep stream`` subprocess (the other core) into :class:`MavlinkSource` in this process, or
into a ``livesweep monitor --record`` subprocess.
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from livesweep.cli import main
from livesweep.telemetry.mavlink_in import MavlinkSource


def _data_dir() -> Path:
    p = Path(__file__).resolve().parents[2] / "shared" / "data"
    return p if p.is_dir() else Path("/work/shared/data")


DATA = _data_dir()
VTOL = DATA / "mavlink_tlog" / "uavlogviewer_vtol_sitl.tlog"
SID7 = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
SRC_DIR = Path(__file__).resolve().parents[1] / "src"
GRAVITY_MSS = 9.80665


def need(*paths: Path) -> None:
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"third-party log(s) not found: {', '.join(missing)}")


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(SRC_DIR) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _livesweep(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "livesweep", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(), **kw)


def _sent_table(stdout: str) -> dict[str, int]:
    """The ``message  sent  Hz`` table ``livesweep stream`` prints."""
    return {m.group(1): int(m.group(2))
            for m in re.finditer(r"^  ([A-Z][A-Z0-9_]+) +(\d+) +(?:[\d.]+|nan)$", stdout, re.MULTILINE)}


def _stream_into_source(*args: str) -> tuple[list, dict, str]:
    """Run ``livesweep stream LOG ... --mavlink udpout:...`` into a MavlinkSource; every frame it got."""
    src = MavlinkSource("udpin:127.0.0.1:0")
    port = src.local_address[1]
    proc = _livesweep("stream", *args, "--mavlink", f"udpout:127.0.0.1:{port}")
    frames: list = []
    try:
        while True:
            got = src.poll(timeout_s=0.05, max_frames=100_000)
            frames += got
            if not got and proc.poll() is not None:
                late = src.poll(timeout_s=0.3, max_frames=100_000)   # what is still in the socket
                frames += late
                if not late:
                    break
        out, err = proc.communicate(timeout=60)
        src.refresh_kernel_drops()
        counts = src.counts
    finally:
        src.close()
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    return frames, counts, out


def _by_topic(frames, name: str) -> list[dict]:
    return [f.data for f in frames if f.topic == f"/mavlink/{name}"]


def _f32_close(a, b) -> bool:
    """Equal as float32 within one unit in the last place (the wire is float32)."""
    a32, b32 = np.float32(a), np.float32(b)
    return bool(abs(a32 - b32) <= np.spacing(np.abs(b32)))


# ----------------------------------------------------------------------------- references


@pytest.fixture(scope="module")
def sid7():
    """pymavlink's DFReader over the SystemID log: the records the stream is made from."""
    need(SID7)
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(SID7), zero_time_base=True)
    keep = {"ATT", "RATE", "RCOU", "PIDR", "PIDP", "PIDY", "IMU", "MSG", "MODE", "PARM"}
    recs: dict[str, list[dict]] = {k: [] for k in keep}
    first = None
    while True:
        m = r.recv_msg()
        if m is None:
            break
        t = m.get_type()
        tu = getattr(m, "TimeUS", None)
        if first is None and tu is not None:
            first = tu
        if t in keep:
            recs[t].append(m.to_dict())
    recs["first_us"] = first
    return recs


def _window(recs: list[dict], lo_us: int, hi_us: int) -> list[dict]:
    return [r for r in recs if lo_us <= r["TimeUS"] <= hi_us]


# ----------------------------------------------------------------------------- tlog


def _mcap_mavlink(path: Path) -> list[tuple[str, dict]]:
    """(topic, record) of every /mavlink/ message, in file order, read with the mcap library."""
    from mcap.reader import make_reader

    out = []
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.topic.startswith("/mavlink/"):
                out.append((channel.topic, json.loads(message.data)))
    return out


@pytest.mark.slow
def test_tlog_streamed_into_the_monitor_records_what_the_tlog_holds(tmp_path):
    need(VTOL)
    from livesweep.telemetry import mavlink_codec  # noqa: F401  (MAVLINK20=1 before pymavlink)
    from pymavlink import mavutil

    rec = tmp_path / "live.mcap"
    mon = _livesweep("monitor", "--mavlink", "udpin:127.0.0.1:0", "--record", str(rec))
    try:
        line = mon.stdout.readline()
        m = re.search(r"udpin:127\.0\.0\.1:(\d+)", line)
        assert m, (line, mon.stderr.read() if mon.poll() is not None else "")
        # 50x real time: 208 s of log in ~4 s, ~5 800 frames/s, a quarter of the monitor's
        # measured lossless rate on two cores (README), so other processes cannot make it drop
        stream = _livesweep("stream", str(VTOL), "--mavlink", f"udpout:127.0.0.1:{m.group(1)}", "--speed", "50")
        s_out, s_err = stream.communicate(timeout=120)
        assert stream.returncode == 0, s_err
        mon.send_signal(signal.SIGTERM)          # finishes the file after reading what the socket holds
        m_out, m_err = mon.communicate(timeout=60)
    finally:
        if mon.poll() is None:
            mon.kill()
    assert mon.returncode == 0, m_err

    # pymavlink's own reader of the same file
    ref_counts: dict[str, int] = {}
    ref_att = []
    r = mavutil.mavmmaplog(str(VTOL))
    while True:
        msg = r.recv_msg()
        if msg is None:
            break
        t = msg.get_type()
        ref_counts[t] = ref_counts.get(t, 0) + 1
        if t == "ATTITUDE":
            ref_att.append(msg)
    assert sum(ref_counts.values()) == 23894

    sent = _sent_table(s_out)
    assert sent == ref_counts                                      # every frame went out
    assert re.search(r"^monitor: 23894 frames", m_out, re.MULTILINE), m_out   # and every one came in
    assert "kernel_drops" not in m_out
    # every stamp the vehicle sent is taken as its time: SITL's clock stepping back is no implausible stamp
    from livesweep.telemetry.mcap_log import read_summary
    from livesweep.telemetry.recorder import COUNTERS_METADATA

    counters = json.loads(read_summary(rec).metadata[COUNTERS_METADATA]["sources"])[0]
    assert counters["clock_implausible"] == 0 and counters["clock_unrepresentable"] == 0

    conv = tmp_path / "conv.mcap"
    c = _livesweep("convert", str(VTOL), "--out", str(conv))
    c_out, c_err = c.communicate(timeout=120)
    assert c.returncode == 0, c_err

    live, converted = _mcap_mavlink(rec), _mcap_mavlink(conv)
    def per_topic_system(msgs):
        out: dict[tuple, int] = {}
        for topic, d in msgs:
            key = (topic, d["sysid"], d["compid"])
            out[key] = out.get(key, 0) + 1
        return out

    assert {k[0][len("/mavlink/"):]: v for k, v in per_topic_system(live).items()} == ref_counts
    assert per_topic_system(live) == per_topic_system(converted)
    # decoded values: every 50th message of each topic, and its last, equal between the two files
    def sample(msgs):
        by: dict[str, list] = {}
        for topic, d in msgs:
            by.setdefault(topic, []).append(d)
        return {t: v[::50] + v[-1:] for t, v in by.items()}

    s_live, s_conv = sample(live), sample(converted)
    assert s_live.keys() == s_conv.keys()
    n_compared = 0
    for topic in s_live:
        assert s_live[topic] == s_conv[topic], topic
        n_compared += len(s_live[topic])
    assert n_compared > 500
    # and every recorded ATTITUDE is pymavlink's (float32 on the wire)
    att = [d for t, d in live if t == "/mavlink/ATTITUDE"]
    assert len(att) == len(ref_att) == 888
    for d, m in zip(att, ref_att):
        assert d["time_boot_ms"] == m.time_boot_ms
        for f in ("roll", "pitch", "yaw", "rollspeed", "pitchspeed", "yawspeed"):
            assert np.float32(d[f]) == np.float32(getattr(m, f)), f


@pytest.mark.slow
def test_tlog_frames_arrive_byte_for_byte():
    need(VTOL)
    data = VTOL.read_bytes()
    records, p = [], 0
    while p < len(data):                      # the clean v1 tlog: [uint64 BE us][FE len ...], len + 8 bytes
        (ts,) = struct.unpack_from(">Q", data, p)
        assert data[p + 8] == 0xFE
        ln = data[p + 9] + 8
        records.append((ts, data[p + 8:p + 8 + ln]))
        p += 8 + ln
    t0 = records[0][0]
    expected = [fr for ts, fr in records if t0 + 60_000_000 <= ts <= t0 + 70_000_000]

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.5)
    got = []
    try:
        proc = _livesweep("stream", str(VTOL), "--mavlink", f"udpout:127.0.0.1:{sock.getsockname()[1]}",
                          "--start-s", "60", "--end-s", "70", "--speed", "0")
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err
        while True:
            try:
                got.append(sock.recv(65535))
            except socket.timeout:
                break
    finally:
        sock.close()
    assert len(expected) > 1000
    assert got == expected                     # one recorded frame per datagram, the same bytes, in order
    assert sum(_sent_table(out).values()) == len(expected)


# ----------------------------------------------------------------------------- DataFlash


def _mode_at(modes: list[dict], t_us: int) -> int:
    mode = None
    for m in modes:
        if m["TimeUS"] <= t_us:
            mode = m["ModeNum"]
    return mode


@pytest.mark.slow
def test_dataflash_paced_stream_is_what_arducopter_sends(sid7):
    # 33..93 s after the log's start: LOITER, SystemID axis 7 (mode 25) from 35.2 s, LOITER again
    # at 92.2 s; 50 Hz per message as SRx_EXTRA1 = 50 would send it
    frames, counts, out = _stream_into_source(str(SID7), "--speed", "20", "--start-s", "33", "--end-s", "93",
                                              "--rate-hz", "50")
    lo, hi = sid7["first_us"] + 33_000_000, sid7["first_us"] + 93_000_000

    # counted: sent == received, nothing lost, damaged or from another system
    assert _sent_table(out) == counts["received"]
    assert counts["seq_gaps"] == {} and counts["bad_crc"] == 0 and counts["kernel_drops"] == 0
    assert counts["by_system"] == {1: len(frames)}
    assert {(f.data["sysid"], f.data["compid"]) for f in frames} == {(1, 1)}

    # HEARTBEAT at 1 Hz from the slice start, custom_mode = the DataFlash MODE in effect
    hb = _by_topic(frames, "HEARTBEAT")
    assert len(hb) == 61
    assert [h["custom_mode"] for h in hb] == [_mode_at(sid7["MODE"], lo + k * 1_000_000) for k in range(61)]
    assert [h["custom_mode"] for h in hb][3:60] == [25] * 57            # SystemID, as the log says
    assert {(h["type"], h["autopilot"], h["base_mode"] & 128, h["system_status"]) for h in hb} == {(2, 3, 128, 4)}

    # STATUSTEXT: the log's MSG texts in order
    st = _by_topic(frames, "STATUSTEXT")
    assert [s["text"] for s in st] == [m["Message"] for m in _window(sid7["MSG"], lo, hi)] \
        == ["SystemID Starting: axis=7", "SystemID Finished"]
    assert {s["severity"] for s in st} == {6}

    # ATTITUDE: 50 Hz, time_boot_ms = TimeUS // 1000, angles from ATT, rates = RATE.R/P/Y in rad/s
    att = _by_topic(frames, "ATTITUDE")
    assert abs(len(att) - 50 * 60) <= 1                               # one per 20 ms of a 60 s slice
    att_by_ms = {r["TimeUS"] // 1000: r for r in _window(sid7["ATT"], lo, hi)}
    rate_by_ms = {r["TimeUS"] // 1000: r for r in _window(sid7["RATE"], lo, hi)}
    for a in att:
        src, rate = att_by_ms[a["time_boot_ms"]], rate_by_ms[a["time_boot_ms"]]
        assert _f32_close(a["rollspeed"], math.radians(rate["R"]))
        assert _f32_close(a["pitchspeed"], math.radians(rate["P"]))
        assert _f32_close(a["yawspeed"], math.radians(rate["Y"]))
        assert _f32_close(a["roll"], math.radians(src["Roll"]))
        assert _f32_close(a["pitch"], math.radians(src["Pitch"]))
        assert _f32_close(a["yaw"], math.remainder(math.radians(src["Yaw"]), 2 * math.pi))
    assert max(abs(a["rollspeed"]) for a in att) > 0.2                # the chirp is in there (15 deg/s)

    # SERVO_OUTPUT_RAW: every RCOU record (10 Hz, under the cap), C1..C8 and TimeUS
    so = _by_topic(frames, "SERVO_OUTPUT_RAW")
    assert [(s["time_usec"], *(s[f"servo{k}_raw"] for k in range(1, 9))) for s in so] == \
        [(r["TimeUS"], *(r[f"C{k}"] for k in range(1, 9))) for r in _window(sid7["RCOU"], lo, hi)]
    assert len(so) == 600

    # pacing: 60 s of log at 20x take 3 s. Receive times of the first and last ATTITUDE are
    # read here, so the difference carries the sender's sleep granularity and this process's
    # poll latency (<= 50 ms each end) plus scheduling on a shared two-core machine: 5 % + 0.1 s
    span_log = (att[-1]["time_boot_ms"] - att[0]["time_boot_ms"]) / 1000 / 20
    rx = [f.receive_ns for f in frames if f.topic == "/mavlink/ATTITUDE"]
    span_rx = (rx[-1] - rx[0]) / 1e9
    assert span_log == pytest.approx(3.0, abs=0.03)
    assert abs(span_rx - span_log) <= 0.05 * span_log + 0.1, (span_rx, span_log)


@pytest.mark.slow
def test_dataflash_full_rate_pid_tuning_and_imu_equal_the_log(sid7):
    # 2 s of the chirp as fast as possible, at the log's own 400 Hz
    frames, counts, out = _stream_into_source(str(SID7), "--speed", "0", "--start-s", "40", "--end-s", "42")
    lo, hi = sid7["first_us"] + 40_000_000, sid7["first_us"] + 42_000_000
    imu = _window(sid7["IMU"], lo, hi)
    expected = {"HEARTBEAT": 3, "ATTITUDE": len(_window(sid7["ATT"], lo, hi)),
                "PID_TUNING": sum(len(_window(sid7[k], lo, hi)) for k in ("PIDR", "PIDP", "PIDY")),
                "SERVO_OUTPUT_RAW": len(_window(sid7["RCOU"], lo, hi)),
                "RAW_IMU": sum(r["I"] == 0 for r in imu), "SCALED_IMU2": sum(r["I"] == 1 for r in imu),
                # a ground station's parameter fetch at the slice start: every parameter logged before it
                "PARAM_VALUE": len({r["Name"] for r in sid7["PARM"] if r["TimeUS"] < lo})}
    assert expected["ATTITUDE"] > 790
    assert _sent_table(out) == counts["received"] == expected
    assert counts["seq_gaps"] == {}

    pid = _by_topic(frames, "PID_TUNING")
    for axis, name in ((1, "PIDR"), (2, "PIDP"), (3, "PIDY")):
        got = [p for p in pid if p["axis"] == axis]
        ref = _window(sid7[name], lo, hi)
        assert len(got) == len(ref)
        for p, r in zip(got, ref):          # float32 in the log, float32 on the wire: equal
            for mine, theirs in (("desired", "Tar"), ("achieved", "Act"), ("FF", "FF"), ("P", "P"), ("I", "I"),
                                 ("D", "D"), ("SRate", "SRate"), ("PDmod", "Dmod")):
                assert np.float32(p[mine]) == np.float32(r[theirs]), (axis, mine)

    raw = _by_topic(frames, "RAW_IMU")
    ref0 = [r for r in imu if r["I"] == 0]
    assert [x["time_usec"] for x in raw] == [r["TimeUS"] for r in ref0]
    for x, r in zip(raw, ref0):            # ArduPilot: mg, mrad/s, cdegC, truncated to int16 (one count)
        for ax in "xyz":
            assert abs(x[f"{ax}acc"] - int(r[f"Acc{ax.upper()}"] * 1000 / GRAVITY_MSS)) <= 1
            assert abs(x[f"{ax}gyro"] - int(r[f"Gyr{ax.upper()}"] * 1000)) <= 1
        assert abs(x["temperature"] - int(r["T"] * 100)) <= 1
    assert min(x["zacc"] for x in raw) < -900                          # gravity, in mg


# ----------------------------------------------------------------------------- bad input


def _one_error_line(capsys, argv) -> str:
    code = main(argv)
    cap = capsys.readouterr()
    assert code == 2
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("livesweep: error: "), cap.err
    assert "Traceback" not in cap.err and cap.out == ""
    return lines[0]


@pytest.mark.parametrize("kind", ["text", "random", "missing", "empty"])
def test_a_file_that_is_not_a_log_is_one_line(tmp_path, capsys, kind):
    f = tmp_path / f"flight_{kind}.tlog"           # the name says tlog; the content decides
    if kind == "text":
        f.write_text("time,roll\n0.0,0.1\n")
    elif kind == "random":
        f.write_bytes(np.random.default_rng(3).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    elif kind == "empty":
        f.write_bytes(b"")
    line = _one_error_line(capsys, ["stream", str(f), "--mavlink", "udpout:127.0.0.1:14550"])
    assert str(f) in line
    assert {"text": "not a log", "random": "unknown or unsupported format", "missing": "no such file",
            "empty": "empty"}[kind] in line


@pytest.mark.parametrize("url", ["udpout:127.0.0.1", "udpout:127.0.0.1:99999", "telnet:host:1", "/tmp/x/bin/sh"])
def test_a_bad_url_is_one_line(tmp_path, capsys, url):
    f = tmp_path / "t.tlog"
    f.write_bytes(b"")                              # the url is judged before the file
    line = _one_error_line(capsys, ["stream", str(f), "--mavlink", url])
    assert repr(url) in line


@pytest.mark.parametrize("args, words", [
    (["--speed", "-1"], "--speed"), (["--speed", "nan"], "--speed"),
    (["--start-s", "-2"], "--start-s"), (["--start-s", "5", "--end-s", "5"], "--end-s"),
    (["--rate-hz", "0"], "--rate-hz"), (["--rate-hz", "inf"], "--rate-hz"),
])
def test_bad_numbers_are_one_line(tmp_path, capsys, args, words):
    f = tmp_path / "t.tlog"
    f.write_bytes(b"")
    line = _one_error_line(capsys, ["stream", str(f), "--mavlink", "udpout:127.0.0.1:14550", *args])
    assert words in line and args[-1] in line


def test_rate_cap_on_a_tlog_and_an_empty_slice_are_one_line(capsys):
    need(VTOL, SID7)
    line = _one_error_line(capsys, ["stream", str(VTOL), "--mavlink", "udpout:127.0.0.1:14550", "--rate-hz", "50"])
    assert str(VTOL) in line and "--rate-hz" in line
    line = _one_error_line(capsys, ["stream", str(SID7), "--mavlink", "udpout:127.0.0.1:14550",
                                    "--start-s", "10000"])
    assert str(SID7) in line and "nothing to send from 10000 s" in line


@pytest.mark.slow
def test_dataflash_parameters_go_out_as_a_fetch_then_as_each_change(sid7):
    """PARAM_VALUE: at the slice start every parameter with its value then (what a ground station
    fetches as it connects), then each one set during the slice when the log records it (the
    vehicle's echo): here SID_AXIS = 7 set 8.9 s before SystemID axis 7 starts."""
    frames, counts, out = _stream_into_source(str(SID7), "--speed", "0", "--start-s", "20", "--end-s", "30")
    lo, hi = sid7["first_us"] + 20_000_000, sid7["first_us"] + 30_000_000
    before: dict = {}
    for r in sid7["PARM"]:
        if r["TimeUS"] < lo:
            before[r["Name"]] = r["Value"]
    changes = [r for r in sid7["PARM"] if lo <= r["TimeUS"] <= hi]
    got = _by_topic(frames, "PARAM_VALUE")
    dump, echo = got[:len(before)], got[len(before):]
    assert {p["param_id"]: p["param_value"] for p in dump} == pytest.approx(before, rel=1e-7)
    assert all(p["param_count"] == len(before) for p in dump)
    assert sorted(p["param_index"] for p in dump) == list(range(len(before)))
    assert [(p["param_id"], p["param_value"]) for p in echo] == [(r["Name"], r["Value"]) for r in changes]
    assert ("SID_AXIS", 7.0) in [(p["param_id"], p["param_value"]) for p in echo]
    # the chirp the monitor learns from them: ArduCopter's SID_F_START_HZ 0.5, SID_F_STOP_HZ 12, SID_T_REC 40
    assert (before["SID_F_START_HZ"], before["SID_F_STOP_HZ"], before["SID_T_REC"]) == (0.5, 12.0, 40.0)
