"""MAVLink 2 codec and live output: real UDP packets on 127.0.0.1, no mocks of the network."""

from __future__ import annotations

import hashlib
import json
import math
import re
import os
import select
import socket
import stat
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from livesweep.errors import ConfigError, LivesweepError
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.mavlink_out import MavlinkSender, parse_url, stream_records
from pymavlink import mavutil  # after the codec import: MAVLINK20=1 is set

T0 = 100.0  # vehicle boot time of the first sample [s]
DURATION = 2.0
SPEED = 10.0


# ----------------------------------------------------------------------------- helpers


class Receiver(threading.Thread):
    """A pymavlink udpin receiver on a free port, draining in a thread."""

    def __init__(self, signing_key: bytes | None = None):
        super().__init__(daemon=True)
        # binding port 0 picks a free port with no race between choosing and binding it
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:0")
        self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.port = self.conn.port.getsockname()[1]
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=False, allow_unsigned_callback=None)
        self.msgs: list = []
        self.done = threading.Event()

    def run(self) -> None:
        while True:
            ready, _, _ = select.select([self.conn.port], [], [], 0.05)
            if ready:
                m = self.conn.recv_msg()  # one datagram per call; we send one frame per datagram
                if m is not None:
                    self.msgs.append(m)
            elif self.done.is_set():
                return

    def finish(self) -> list:
        self.done.set()
        self.join(timeout=5)
        assert not self.is_alive()
        self.conn.close()
        return self.msgs


def same(a, b) -> bool:
    """Equality that treats NaN as equal to NaN (and checks float vs int types)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return type(a) is type(b) and a == b


def flight_records():
    """2 s of vehicle time: ATTITUDE 50 Hz, HIGHRES_IMU 100 Hz, SERVO_OUTPUT_RAW 50 Hz, AOA_SSA 50 Hz."""
    rng = np.random.default_rng(7)
    out = {}
    k50 = np.arange(int(DURATION * 50))
    k100 = np.arange(int(DURATION * 100))
    t50 = T0 + k50 / 50.0
    t100 = T0 + k100 / 100.0
    w = 2 * np.pi * (0.2 + 1.5 * k50 / len(k50))  # a sweep-like signal
    out["ATTITUDE"] = (t50, codec.records_from_columns(
        "ATTITUDE",
        {
            "time_boot_ms": np.round(t50 * 1e3).astype(np.int64),
            "roll": 0.2 * np.sin(w * (t50 - T0)),
            "pitch": 0.05 + 0.01 * rng.standard_normal(len(k50)),
            "yaw": np.full(len(k50), 1.2345678),
            "rollspeed": rng.standard_normal(len(k50)),
            "pitchspeed": rng.standard_normal(len(k50)).astype(np.float32),
            "yawspeed": 1e-3 * rng.standard_normal(len(k50)),
        },
        sysid=1, compid=1,
    ))
    imu_cols = {"time_usec": np.round(t100 * 1e6).astype(np.uint64), "fields_updated": 0x1FFF, "id": 0}
    for name in ["xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "xmag", "ymag", "zmag",
                 "abs_pressure", "diff_pressure", "pressure_alt", "temperature"]:
        imu_cols[name] = rng.standard_normal(len(k100)) * 10.0 ** rng.integers(-3, 4)
    out["HIGHRES_IMU"] = (t100, codec.records_from_columns("HIGHRES_IMU", imu_cols, sysid=1, compid=1))
    servo = {"time_usec": np.round((t50 - T0) * 1e6).astype(np.uint32), "port": 0}
    for i in range(1, 9):
        servo[f"servo{i}_raw"] = (1500 + 400 * np.sin(w * (t50 - T0) + i)).astype(np.int64)
    out["SERVO_OUTPUT_RAW"] = (t50, codec.records_from_columns("SERVO_OUTPUT_RAW", servo, sysid=1, compid=1))
    out["AOA_SSA"] = (t50, codec.records_from_columns(
        "AOA_SSA",
        {"time_usec": np.round(t50 * 1e6).astype(np.uint64),
         "AOA": 4.0 + rng.standard_normal(len(k50)), "SSA": 0.1 * rng.standard_normal(len(k50))},
        sysid=1, compid=1,
    ))
    timed = [(float(t), name, rec) for name, (ts, recs) in out.items() for t, rec in zip(ts, recs)]
    timed.sort(key=lambda item: item[0])  # stable: same-time records keep type order
    return out, timed


# ----------------------------------------------------------------------------- live UDP


def test_udp_paced_stream_round_trip():
    sent_by_type, timed = flight_records()
    rx = Receiver()
    rx.start()
    with MavlinkSender(f"udpout:127.0.0.1:{rx.port}", source_system=1, source_component=1) as tx:
        stats = stream_records(tx, timed, speed=SPEED)
        # let the last datagrams arrive, then stop the receiver
        deadline = time.monotonic() + 3.0
        n_expected = sum(stats["counts"].values())
        while len(rx.msgs) < n_expected and time.monotonic() < deadline:
            time.sleep(0.01)
        msgs = rx.finish()
        assert tx.send_errors == 0
        assert tx.sent_counts == stats["counts"]

    # every frame is MAVLink 2 (raw first byte of the received buffer), none is bad data
    assert all(m.get_type() != "BAD_DATA" for m in msgs)
    assert all(m.get_msgbuf()[0] == 0xFD for m in msgs)
    assert all(len(m.get_msgbuf()) == m.get_header().mlen + 12 for m in msgs)  # 10 header + 2 crc

    by_type: dict[str, list] = {}
    for m in msgs:
        by_type.setdefault(m.get_type(), []).append(m)

    # counts per type equal what was sent (loopback, paced: no loss expected)
    assert {k: len(v) for k, v in by_type.items()} == stats["counts"]
    for name, (_, recs) in sent_by_type.items():
        assert stats["counts"][name] == len(recs)
    assert stats["counts"]["HEARTBEAT"] == 2  # t = 0 s and t = 1 s of vehicle time
    hb = by_type["HEARTBEAT"][0]
    assert hb.type == mavutil.mavlink.MAV_TYPE_FIXED_WING and hb.get_srcSystem() == 1
    assert rx.conn.mav_loss == 0

    # decoded records equal the sent canonical records exactly (float32 shortest-repr rule)
    for name, (_, recs) in sent_by_type.items():
        got = [codec.record_from_message(m) for m in by_type[name]]
        assert got == recs, name

    # rates from the received vehicle time stamps
    for name, rate in [("ATTITUDE", 50.0), ("HIGHRES_IMU", 100.0), ("SERVO_OUTPUT_RAW", 50.0), ("AOA_SSA", 50.0)]:
        t_ns = [codec.vehicle_time_ns(codec.record_from_message(m), name) for m in by_type[name]]
        assert all(b > a for a, b in zip(t_ns, t_ns[1:])), name
        measured = (len(t_ns) - 1) / ((t_ns[-1] - t_ns[0]) * 1e-9)
        assert measured == pytest.approx(rate, rel=5e-3), name

    # pacing: ~ DURATION / SPEED of wall time; only lateness is asserted tightly
    assert stats["max_lateness_s"] < 0.5
    last_t = timed[-1][0] - timed[0][0]
    assert stats["wall_duration_s"] >= last_t / SPEED * 0.95
    assert stats["wall_duration_s"] < 10 * DURATION / SPEED + 1.0
    assert stats["n_records"] == len(timed)
    assert stats["vehicle_duration_s"] == pytest.approx(last_t)


def test_signed_frames_and_record_source_ids():
    key = hashlib.sha256(b"livesweep test").digest()
    rx = Receiver(signing_key=key)
    rx.start()
    recs = codec.records_from_columns(
        "NAMED_VALUE_FLOAT",
        {"time_boot_ms": np.arange(300) * 10, "name": ["chirp_u"] * 300, "value": np.linspace(-1, 1, 300)},
        sysid=7, compid=158,
    )
    with MavlinkSender(f"udpout:127.0.0.1:{rx.port}", signing_key=key) as tx:
        tx.send_heartbeat()
        for r in recs:
            tx.send_record("NAMED_VALUE_FLOAT", r)
        deadline = time.monotonic() + 3.0
        while len(rx.msgs) < 301 and time.monotonic() < deadline:
            time.sleep(0.01)
    msgs = rx.finish()
    assert [m.get_type() for m in msgs] == ["HEARTBEAT"] + ["NAMED_VALUE_FLOAT"] * 300
    assert rx.conn.mav.signing.goodsig_count == 301 and rx.conn.mav.signing.badsig_count == 0
    assert all(m.get_signed() for m in msgs)
    nvf = msgs[1:]
    assert [codec.record_from_message(m) for m in nvf] == recs  # sysid 7 / compid 158 kept
    # one sequence per source: the record source's seq runs 0, 1, 2, ... with no gap
    assert [m.get_seq() for m in nvf] == [i % 256 for i in range(300)]
    assert msgs[0].get_srcSystem() == 1 and msgs[0].get_srcComponent() == 1


def test_mavlink2_even_if_pymavlink_was_imported_as_v1():
    """A process that imported pymavlink without MAVLINK20 still sends MAVLink 2 frames."""
    rx_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx_sock.bind(("127.0.0.1", 0))
    rx_sock.settimeout(10.0)
    port = rx_sock.getsockname()[1]
    code = (
        "from pymavlink import mavutil\n"
        "assert mavutil.mavlink.WIRE_PROTOCOL_VERSION == '1.0', mavutil.mavlink.WIRE_PROTOCOL_VERSION\n"
        "from livesweep.telemetry.mavlink_out import MavlinkSender\n"
        f"tx = MavlinkSender('udpout:127.0.0.1:{port}')\n"
        "assert tx.connection.mavlink20()\n"
        "tx.send_record('AOA_SSA', {'time_usec': 5, 'AOA': 1.5, 'SSA': -0.25})\n"
        "tx.close()\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("MAVLINK20", "MAVLINK_DIALECT")}
    env["MAVLINK_DIALECT"] = "common"
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    data, _ = rx_sock.recvfrom(65535)
    rx_sock.close()
    assert data[0] == 0xFD
    mav = mavutil.mavlink.MAVLink(None)
    msg = mav.parse_char(data)
    assert codec.record_from_message(msg) == {"sysid": 1, "compid": 1, "time_usec": 5, "AOA": 1.5, "SSA": -0.25}


@pytest.mark.parametrize(
    "url",
    [
        "", " udpout:127.0.0.1:14550", "udpout:127.0.0.1", "udpout:127.0.0.1:0", "udpout:127.0.0.1:70000",
        "udpout::14550", "UDPOUT:127.0.0.1:14550", "udpbcast:127.0.0.1:14550", "mcast:", "wsserver:0.0.0.0:5760",
        "csv:x.csv", "flight.tlog", "log.bin", "/tmp/x.tlog", "/usr/bin/true", "/dev/null", "/dev/ttyS0,1234",
        "udpout:127.0.0.1:14550:1", "udpout:bad host:14550", "tcp:[::1]:5760", 14550,
    ],
)
def test_bad_url_is_config_error(url):
    with pytest.raises(ConfigError) as e:
        MavlinkSender(url)
    assert repr(url) in str(e.value)


def test_bin_path_is_never_handed_to_pymavlink(tmp_path):
    """pymavlink executes existing files under .../bin/; the sender must refuse them."""
    marker = tmp_path / "executed"
    script = tmp_path / "bin" / "evil"
    script.parent.mkdir()
    script.write_text(f"#!/bin/sh\ntouch {marker}\n")
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    with pytest.raises(ConfigError):
        MavlinkSender(str(script))
    link = tmp_path / "dev_link"
    link.symlink_to(script)
    with pytest.raises(ConfigError):
        MavlinkSender(str(link))
    time.sleep(0.05)
    assert not marker.exists()


def test_url_forms_and_sender_arguments():
    assert parse_url("udpout:127.0.0.1:14550") == {"kind": "udpout", "host": "127.0.0.1", "port": 14550}
    assert parse_url("udp:0.0.0.0:14550")["kind"] == "udpin"
    assert parse_url("tcp:localhost:5760")["kind"] == "tcp"
    assert parse_url("COM3,57600") == {"kind": "serial", "device": "COM3", "baud": 57600}
    with pytest.raises(ConfigError, match="source_system"):
        MavlinkSender("udpout:127.0.0.1:14550", source_system=0)
    with pytest.raises(ConfigError, match="32 bytes"):
        MavlinkSender("udpout:127.0.0.1:14550", signing_key=b"short")
    with pytest.raises(LivesweepError, match="cannot be opened"):
        # nobody listens: a refused TCP connection is a clear error, not a hang
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        s.close()
        MavlinkSender(f"tcp:127.0.0.1:{port}")


def test_send_record_validation():
    rx = Receiver()
    rx.start()
    with MavlinkSender(f"udpout:127.0.0.1:{rx.port}") as tx:
        with pytest.raises(ConfigError, match="NOT_A_MESSAGE"):
            tx.send_record("NOT_A_MESSAGE", {})
        with pytest.raises(ConfigError, match="bogus"):
            tx.send_record("ATTITUDE", {"time_boot_ms": 1, "bogus": 2.0})
        full = codec.record_from_fields("ATTITUDE", {"time_boot_ms": 1}, sysid=1, compid=1)
        with pytest.raises(ConfigError, match=r"ATTITUDE\.time_boot_ms.*-5"):
            tx.send_record("ATTITUDE", {**full, "time_boot_ms": -5})
        # a non-canonical but valid record (partial, integral float) is coerced and sent
        tx.send_record("ATTITUDE", {"time_boot_ms": 2.0, "roll": 0.1})
        tx.send_record("ATTITUDE", {**full, "roll": None})  # stored null -> NaN
        assert tx.sent_counts == {"ATTITUDE": 2}
    deadline = time.monotonic() + 3.0
    while len(rx.msgs) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    msgs = rx.finish()
    recs = [codec.record_from_message(m) for m in msgs]
    assert recs[0]["time_boot_ms"] == 2 and recs[0]["roll"] == 0.1
    assert math.isnan(recs[1]["roll"])
    with pytest.raises(LivesweepError, match="closed"):
        tx.send_heartbeat()


# ----------------------------------------------------------------------------- pacing


class FakeSender:
    def __init__(self):
        self.log: list = []
        self.send_errors = 0

    def send_record(self, msgname, record):
        self.log.append(msgname)

    def send_heartbeat(self):
        self.log.append("HEARTBEAT")


class FakeClock:
    def __init__(self):
        self.now = 50.0
        self.sleeps: list[float] = []

    def clock(self):
        return self.now

    def sleep(self, dt):
        self.sleeps.append(dt)
        self.now += dt


def test_stream_records_pacing_logic():
    items = [(10.0 + i * 0.01, "ATTITUDE", {}) for i in range(300)]  # 2.99 s of vehicle time
    fs, fc = FakeSender(), FakeClock()
    stats = stream_records(fs, items, speed=2.0, clock=fc.clock, sleep=fc.sleep, heartbeat_period_s=1.0)
    assert stats["wall_duration_s"] == pytest.approx(2.99 / 2.0)
    assert sum(fc.sleeps) == pytest.approx(2.99 / 2.0)
    assert stats["max_lateness_s"] == 0.0
    assert stats["counts"] == {"ATTITUDE": 300, "HEARTBEAT": 3}  # t = 0, 1, 2 s
    assert fs.log[0] == "HEARTBEAT" and fs.log[101] == "HEARTBEAT"

    for speed in (math.inf, 0):  # as fast as possible: never sleeps
        fs, fc = FakeSender(), FakeClock()
        stats = stream_records(fs, items, speed=speed, clock=fc.clock, sleep=fc.sleep, heartbeat_period_s=None)
        assert fc.sleeps == [] and stats["counts"] == {"ATTITUDE": 300}

    # a gap in vehicle time sends one heartbeat, not one per missed period
    fs, fc = FakeSender(), FakeClock()
    stats = stream_records(fs, [(0.0, "A", {}), (100.5, "A", {})], speed=math.inf, clock=fc.clock, sleep=fc.sleep)
    assert fs.log == ["HEARTBEAT", "A", "HEARTBEAT", "A"]


@pytest.mark.parametrize("speed", [-1.0, -math.inf, math.nan, "fast", None])
def test_bad_speed_is_config_error(speed):
    with pytest.raises(ConfigError, match="speed"):
        stream_records(FakeSender(), [], speed=speed)


def test_stream_records_input_errors():
    with pytest.raises(ConfigError, match="heartbeat"):
        stream_records(FakeSender(), [], speed=1.0, heartbeat_period_s=0.0)
    with pytest.raises(ConfigError, match="before the previous"):
        stream_records(FakeSender(), [(1.0, "A", {}), (0.5, "B", {})], speed=math.inf)
    with pytest.raises(ConfigError, match="not finite"):
        stream_records(FakeSender(), [(math.nan, "A", {})], speed=math.inf)
    assert stream_records(FakeSender(), [], speed=1.0)["counts"] == {}


# ----------------------------------------------------------------------------- codec


def test_message_class_and_dialect():
    assert codec.message_class("ATTITUDE").id == 30
    assert codec.message_class("AOA_SSA").id == 11020
    with pytest.raises(ConfigError, match="NOPE"):
        codec.message_class("NOPE")
    with pytest.raises(ConfigError, match="'ATTITUDE'"):  # hints at the upper-case name
        codec.message_class("attitude")
    assert os.environ["MAVLINK20"] == "1"
    assert mavutil.mavlink.WIRE_PROTOCOL_VERSION == "2.0"


def test_float32_shortest_repr_rule():
    vals = [0.1, 1 / 3, math.pi, -0.0, 1e-45, 1.17549435e-38, 3.4028234e38, 123456789.0, 16777217.0, -2.5e-7]
    for v in vals:
        rec = codec.record_from_fields("AOA_SSA", {"AOA": v}, sysid=1, compid=1)
        x = rec["AOA"]
        assert x == float(str(np.float32(v)))
        assert np.float32(x) == np.float32(v)  # lossless w.r.t. the wire
        assert len(repr(x)) <= len(repr(float(np.float32(v))))  # compact
    assert codec.record_from_fields("AOA_SSA", {"AOA": 0.1}, sysid=1, compid=1)["AOA"] == 0.1
    assert codec.record_from_fields("AOA_SSA", {"AOA": 1 / 3}, sysid=1, compid=1)["AOA"] == 0.33333334
    rec = codec.record_from_fields("AOA_SSA", {"AOA": math.nan, "SSA": None}, sysid=1, compid=1)
    assert math.isnan(rec["AOA"]) and math.isnan(rec["SSA"])  # non-finite stays NaN here
    assert codec.record_from_fields("AOA_SSA", {"AOA": math.inf}, sysid=1, compid=1)["AOA"] == math.inf
    # legacy numpy printing must not change the rule
    with np.printoptions(legacy="1.13"):
        assert codec.record_from_fields("AOA_SSA", {"AOA": 1 / 3}, sysid=1, compid=1)["AOA"] == 0.33333334
        assert codec.records_from_columns("AOA_SSA", {"AOA": np.array([1 / 3])}, sysid=1, compid=1)[0]["AOA"] == 0.33333334


def test_record_defaults_and_key_order():
    rec = codec.record_from_fields("ACTUATOR_OUTPUT_STATUS", {}, sysid=1, compid=2)
    assert list(rec) == ["sysid", "compid", "time_usec", "active", "actuator"]
    assert rec["actuator"] == [0.0] * 32 and rec["time_usec"] == 0 and rec["sysid"] == 1 and rec["compid"] == 2
    rec = codec.record_from_fields("NAMED_VALUE_FLOAT", {"name": b"coh\x00\x00"}, sysid=1, compid=1)
    assert rec["name"] == "coh"
    assert codec.record_from_fields("NAMED_VALUE_FLOAT", {}, sysid=1, compid=1)["name"] == ""
    rec = codec.record_from_fields("HIGHRES_IMU", {"time_usec": 3.0, "id": np.uint8(2)}, sysid=1, compid=1)
    assert rec["time_usec"] == 3 and type(rec["time_usec"]) is int and rec["id"] == 2


@pytest.mark.parametrize(
    "msgname, fields, pattern",
    [
        ("ATTITUDE", {"rol": 0.1}, r"ATTITUDE.*'rol'"),
        ("ATTITUDE", {"time_boot_ms": -1}, r"ATTITUDE\.time_boot_ms.*-1.*out of range.*uint32_t"),
        ("ATTITUDE", {"time_boot_ms": 2**32}, r"ATTITUDE\.time_boot_ms.*4294967296.*out of range"),
        ("HIGHRES_IMU", {"id": 256}, r"HIGHRES_IMU\.id.*256.*uint8_t"),
        ("HIGHRES_IMU", {"time_usec": 2**64}, r"HIGHRES_IMU\.time_usec.*out of range.*uint64_t"),
        ("ATTITUDE", {"time_boot_ms": 1.5}, r"ATTITUDE\.time_boot_ms.*1\.5.*not an integer"),
        ("ATTITUDE", {"time_boot_ms": math.nan}, r"ATTITUDE\.time_boot_ms.*nan.*not an integer"),
        ("ATTITUDE", {"time_boot_ms": "12"}, r"ATTITUDE\.time_boot_ms.*'12'.*not an integer"),
        ("ATTITUDE", {"roll": "0.1"}, r"ATTITUDE\.roll.*'0\.1'.*not a number"),
        ("ATTITUDE", {"roll": 1e39}, r"ATTITUDE\.roll.*1e\+39.*overflows float32"),
        ("NAMED_VALUE_FLOAT", {"name": "a_very_long_name"}, r"NAMED_VALUE_FLOAT\.name.*a_very_long_name.*longer than 10"),
        ("NAMED_VALUE_FLOAT", {"name": "wärme"}, r"NAMED_VALUE_FLOAT\.name.*ASCII"),
        ("NAMED_VALUE_FLOAT", {"name": "a\x00b"}, r"NAMED_VALUE_FLOAT\.name.*NUL"),
        ("ACTUATOR_OUTPUT_STATUS", {"actuator": [0.0] * 31}, r"ACTUATOR_OUTPUT_STATUS\.actuator.*31 elements"),
        ("NO_SUCH_MSG", {}, r"NO_SUCH_MSG"),
    ],
)
def test_record_from_fields_errors(msgname, fields, pattern):
    with pytest.raises(ConfigError, match=pattern):
        codec.record_from_fields(msgname, fields, sysid=1, compid=1)


def test_bad_ids():
    with pytest.raises(ConfigError, match="sysid 256"):
        codec.record_from_fields("ATTITUDE", {}, sysid=256, compid=1)
    with pytest.raises(ConfigError, match="compid -1"):
        codec.records_from_columns("ATTITUDE", {"roll": np.zeros(3)}, sysid=1, compid=-1)


def test_records_from_columns_equals_row_by_row():
    rng = np.random.default_rng(3)
    n = 400
    special = np.array([np.nan, np.inf, -np.inf, -0.0, 0.0, 1e-45, 1e-40, 3.4028234e38, -3.4028235e38,
                        0.1, 1 / 3, 1e-8, 123456.789, 16777217.0])
    f = rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30, n)
    f[: len(special)] = special
    f[50:80] = 0.25  # repeated values take the de-duplicating path
    cases = {
        "ATTITUDE": {"time_boot_ms": np.arange(n, dtype=np.uint32) * 20, "roll": f, "pitch": f.astype(np.float32),
                     "yaw": np.arange(n), "rollspeed": rng.standard_normal(n), "yawspeed": 0.5},
        "HIGHRES_IMU": {"time_usec": (np.arange(n) * 10_000 + 2**40).astype(np.float64), "xacc": -f,
                        "fields_updated": np.full(n, 65535, dtype=np.int64), "id": np.zeros(n, dtype=bool),
                        "temperature": np.where(np.arange(n) % 2 == 0, 25.0, np.nan)},
        "SERVO_OUTPUT_RAW": {"time_usec": np.arange(n, dtype=np.uint64) * 20_000,
                             **{f"servo{i}_raw": rng.integers(1000, 2001, n) for i in range(1, 17)}},
        "ACTUATOR_OUTPUT_STATUS": {"time_usec": np.arange(n) * 1000, "active": 2**32 - 1,
                                   "actuator": rng.standard_normal((n, 32))},
        "NAMED_VALUE_FLOAT": {"time_boot_ms": np.arange(n), "name": ["chirp_u", b"coh", "x" * 10, ""] * (n // 4),
                              "value": np.array([None, 1.5] * (n // 2), dtype=object)},
        "DEBUG_FLOAT_ARRAY": {"time_usec": np.arange(n), "name": np.array(["coh"] * n), "array_id": 7,
                              "data": np.tile(np.linspace(0, 1, 58), (n, 1))},
        "GPS_RAW_INT": {"lat": rng.integers(-900_000_000, 900_000_000, n), "alt": np.full(n, -12.0),
                        "time_usec": [2**64 - 1 - i for i in range(n)], "yaw": list(range(n))},
    }
    for msgname, cols in cases.items():
        vec = codec.records_from_columns(msgname, cols, sysid=3, compid=4)
        assert len(vec) == n
        props = codec.json_schema(msgname)["properties"]
        per_row_ndim = {k: 1 if props[k]["type"] == "array" else 0 for k in cols}
        for i in range(n):
            row = {k: v[i] if np.ndim(v) > per_row_ndim[k] else v for k, v in cols.items()}
            ref = codec.record_from_fields(msgname, row, sysid=3, compid=4)
            assert same(vec[i], ref), (msgname, i, vec[i], ref)
    # array-field broadcast copies (no aliasing between rows)
    recs = codec.records_from_columns("ACTUATOR_OUTPUT_STATUS", {"time_usec": np.arange(3)}, sysid=1, compid=1)
    recs[0]["actuator"][0] = 9.0
    assert recs[1]["actuator"][0] == 0.0


def test_records_from_columns_errors():
    with pytest.raises(ConfigError, match="'rol'"):
        codec.records_from_columns("ATTITUDE", {"rol": np.zeros(3)}, sysid=1, compid=1)
    with pytest.raises(ConfigError, match="3 rows; other columns have 4"):
        codec.records_from_columns("ATTITUDE", {"roll": np.zeros(4), "pitch": np.zeros(3)}, sysid=1, compid=1)
    with pytest.raises(ConfigError, match="number of rows"):
        codec.records_from_columns("ATTITUDE", {"roll": 0.0}, sysid=1, compid=1)
    with pytest.raises(ConfigError, match=r"ATTITUDE\.time_boot_ms.*row 2.*out of range"):
        codec.records_from_columns("ATTITUDE", {"time_boot_ms": np.array([0, 1, -1])}, sysid=1, compid=1)
    with pytest.raises(ConfigError, match=r"ATTITUDE\.time_boot_ms.*0\.5.*row 1.*not an integer"):
        codec.records_from_columns("ATTITUDE", {"time_boot_ms": np.array([0.0, 0.5])}, sysid=1, compid=1)
    with pytest.raises(ConfigError, match=r"HIGHRES_IMU\.time_usec.*out of range"):
        codec.records_from_columns("HIGHRES_IMU", {"time_usec": np.array([2.0**64])}, sysid=1, compid=1)
    with pytest.raises(ConfigError, match=r"ATTITUDE\.roll.*row 1.*overflows float32"):
        codec.records_from_columns("ATTITUDE", {"roll": np.array([0.0, 1e300])}, sysid=1, compid=1)
    with pytest.raises(ConfigError, match=r"ACTUATOR_OUTPUT_STATUS\.actuator.*\(2, 31\)"):
        codec.records_from_columns("ACTUATOR_OUTPUT_STATUS", {"actuator": np.zeros((2, 31))}, sysid=1, compid=1)


def _check_against_schema(value, schema, where):
    t = schema["type"]
    types = t if isinstance(t, list) else [t]
    py = {"number": (int, float), "integer": (int,), "string": (str,), "array": (list,), "null": (type(None),)}
    if isinstance(value, float) and not math.isfinite(value):
        value = "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")  # as the MCAP writer stores them
        assert re.fullmatch(schema["pattern"], value), where
    assert any(isinstance(value, py[x]) and not isinstance(value, bool) for x in types), (where, value, t)
    if isinstance(value, int) and "integer" in types:
        assert schema["minimum"] <= value <= schema["maximum"], where
    if isinstance(value, str):
        assert len(value) <= schema["maxLength"], where
    if isinstance(value, list):
        assert schema["minItems"] <= len(value) <= schema["maxItems"], where
        for i, x in enumerate(value):
            _check_against_schema(x, schema["items"], f"{where}[{i}]")


@pytest.mark.parametrize("msgname", ["ATTITUDE", "HIGHRES_IMU", "SERVO_OUTPUT_RAW", "AOA_SSA", "HEARTBEAT",
                                     "NAMED_VALUE_FLOAT", "DEBUG_FLOAT_ARRAY", "ACTUATOR_OUTPUT_STATUS",
                                     "GPS_RAW_INT", "WHEEL_DISTANCE", "STATUSTEXT"])
def test_json_schema_matches_records(msgname):
    schema = codec.json_schema(msgname)
    json.dumps(schema)  # plain JSON
    assert schema["title"] == msgname and schema["type"] == "object"
    assert "2020-12" in schema["$schema"]
    cls = codec.message_class(msgname)
    assert list(schema["properties"]) == ["sysid", "compid", *cls.fieldnames]
    assert schema["required"] == list(schema["properties"])
    rec = codec.record_from_fields(msgname, {}, sysid=255, compid=190)
    assert list(rec) == list(schema["properties"])
    for k, v in rec.items():
        _check_against_schema(v, schema["properties"][k], f"{msgname}.{k}")
    for k, prop in schema["properties"].items():
        if k in ("sysid", "compid"):
            continue
        ctype = cls.fieldtypes[cls.fieldnames.index(k)]
        base = prop["items"]["type"] if prop["type"] == "array" else prop["type"]
        if ctype in ("float", "double"):
            assert base == ["number", "string", "null"], k
        elif ctype == "char":
            assert prop["type"] == "string", k
        else:
            assert base == "integer", k


def test_schema_for_sent_records_and_vehicle_time():
    sent_by_type, _ = flight_records()
    for name, (_, recs) in sent_by_type.items():
        schema = codec.json_schema(name)
        for rec in recs[:20]:
            for k, v in rec.items():
                _check_against_schema(v, schema["properties"][k], f"{name}.{k}")
    att = sent_by_type["ATTITUDE"][1][1]
    assert codec.vehicle_time_ns(att, "ATTITUDE") == att["time_boot_ms"] * 1_000_000
    imu = sent_by_type["HIGHRES_IMU"][1][1]
    assert codec.vehicle_time_ns(imu, "HIGHRES_IMU") == imu["time_usec"] * 1_000
    assert codec.vehicle_time_ns(imu, "HIGHRES_IMU") == int(round((T0 + 0.01) * 1e9))
    assert codec.vehicle_time_ns({"type": 1}, "HEARTBEAT") is None
    with pytest.raises(LivesweepError, match="time_boot_ms"):
        codec.vehicle_time_ns({}, "ATTITUDE")


def _free_port(kind=socket.SOCK_DGRAM) -> int:
    s = socket.socket(socket.AF_INET, kind)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def _parse_frames(data: bytes) -> list:
    mav = mavutil.mavlink.MAVLink(None)
    msgs = mav.parse_buffer(data) or []
    assert all(m.get_type() != "BAD_DATA" for m in msgs)
    return msgs


def test_udpin_sends_only_to_known_peers():
    port = _free_port()
    rec = codec.record_from_fields("AOA_SSA", {"time_usec": 1, "AOA": 2.5}, sysid=1, compid=1)
    with MavlinkSender(f"udpin:127.0.0.1:{port}") as tx:
        tx.send_record("AOA_SSA", rec)  # nobody has spoken yet: counted, not silently lost
        assert tx.send_errors == 1 and tx.sent_counts == {}
        peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        peer.bind(("127.0.0.1", 0))
        peer.settimeout(5.0)
        peer.sendto(b"hello", ("127.0.0.1", port))
        time.sleep(0.05)
        tx.send_record("AOA_SSA", rec)
        data, _ = peer.recvfrom(65535)
        peer.close()
        assert tx.sent_counts == {"AOA_SSA": 1}
    [msg] = _parse_frames(data)
    assert data[0] == 0xFD and codec.record_from_message(msg) == rec


@pytest.mark.parametrize("mode", ["tcp", "tcpin"])
def test_tcp_links_carry_whole_frames(mode):
    recs = codec.records_from_columns(
        "HIGHRES_IMU", {"time_usec": np.arange(500) * 10_000, "xacc": np.linspace(-9, 9, 500)}, sysid=1, compid=1
    )
    if mode == "tcp":
        server = socket.socket()
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        tx = MavlinkSender(f"tcp:127.0.0.1:{server.getsockname()[1]}")
        peer, _ = server.accept()
        server.close()
    else:
        port = _free_port(socket.SOCK_STREAM)
        tx = MavlinkSender(f"tcpin:127.0.0.1:{port}")
        peer = socket.create_connection(("127.0.0.1", port), timeout=5.0)
    peer.settimeout(5.0)
    with tx:
        for r in recs:
            tx.send_record("HIGHRES_IMU", r)
        assert tx.sent_counts == {"HIGHRES_IMU": 500} and tx.send_errors == 0
        expected = tx.bytes_sent
    data = b""
    while len(data) < expected:
        chunk = peer.recv(1 << 16)
        if not chunk:
            break
        data += chunk
    peer.close()
    msgs = _parse_frames(data)
    assert [codec.record_from_message(m) for m in msgs] == recs
