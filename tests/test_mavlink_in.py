"""Live MAVLink input and tlog replay: real UDP on 127.0.0.1, real third-party tlogs, no mocks.

Independent references: records built with ``mavlink_codec.record_from_fields`` and sent by
``MavlinkSender`` (pymavlink), frames packed by a bare pymavlink ``MAVLink`` object, and
pymavlink's own ``mavutil.mavlink_connection(path)`` reading the same tlog files (run in a
subprocess, in parallel with the code under test).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import socket
import stat
import struct
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from helpers import collect_frames

from livesweep.errors import ConfigError, LogFormatError
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mavlink_in import MavlinkSource, TlogSource, parse_source_url
from livesweep.telemetry.mavlink_out import MavlinkSender
from pymavlink.dialects.v20 import ardupilotmega as mav2  # after the codec import (MAVLINK20=1)


def _data_dir() -> Path:
    p = Path(__file__).resolve().parents[2] / "shared" / "data"
    return p if p.is_dir() else Path("/work/shared/data")


DATA = _data_dir()
TLOG_DIR = DATA / "mavlink_tlog"
AUTOTEST = TLOG_DIR / "uavlogviewer_autotest_flight_logs.tlog"
VTOL = TLOG_DIR / "uavlogviewer_vtol_sitl.tlog"

KEY = hashlib.sha256(b"livesweep test key").digest()
OTHER_KEY = hashlib.sha256(b"not the key").digest()


# ----------------------------------------------------------------------------- helpers


def collect(src, n: int, timeout: float = 3.0, settle: float = 0.15) -> list[Frame]:
    return collect_frames(src, n, timeout, settle)


def wait_counts(src, pred, timeout: float = 3.0) -> dict:
    """Poll until ``pred(counts)`` holds (rejected frames produce no frames to wait for)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        src.poll(0.02)
        c = src.counts
        if pred(c):
            time.sleep(0.05)
            src.poll(0.0)
            return src.counts
    return src.counts


def udp_source(**kw) -> tuple[MavlinkSource, int]:
    src = MavlinkSource("udpin:127.0.0.1:0", **kw)
    port = src.connection.port.getsockname()[1]
    assert src.local_address == ("127.0.0.1", port)
    return src, port


def live_records(sysid: int, n: int) -> list[tuple[str, dict]]:
    """Records of several types (with and without a time field, arrays, strings)."""
    rng = np.random.default_rng(sysid)
    out = []
    for k in range(n):
        t_ms = 1000 + 20 * k
        out.append(("ATTITUDE", codec.record_from_fields(
            "ATTITUDE", {"time_boot_ms": t_ms, "roll": 0.3 * math.sin(k / 5), "pitch": float(rng.normal()),
                         "yaw": 1.2345678, "rollspeed": float(rng.normal()), "yawspeed": -1e-7},
            sysid=sysid, compid=1)))
        out.append(("HIGHRES_IMU", codec.record_from_fields(
            "HIGHRES_IMU", {"time_usec": t_ms * 1000 + 7, "xacc": float(rng.normal()), "zacc": -9.80665,
                            "temperature": 21.5, "fields_updated": 0x1FFF},
            sysid=sysid, compid=1)))
        if k % 5 == 0:
            out.append(("NAMED_VALUE_FLOAT", codec.record_from_fields(
                "NAMED_VALUE_FLOAT", {"time_boot_ms": t_ms, "name": "chirp_u", "value": 0.1 * k},
                sysid=sysid, compid=1)))
            out.append(("DEBUG_FLOAT_ARRAY", codec.record_from_fields(
                "DEBUG_FLOAT_ARRAY", {"time_usec": t_ms * 1000, "name": "coh", "array_id": k,
                                      "data": list(rng.normal(size=58))},
                sysid=sysid, compid=1)))
            out.append(("HEARTBEAT", codec.record_from_fields(
                "HEARTBEAT", {"type": 1, "autopilot": 3, "system_status": 4, "mavlink_version": 3},
                sysid=sysid, compid=1)))
    return out


def packer(sysid: int = 1, compid: int = 1, key: bytes | None = None):
    """A bare pymavlink MAVLink 2 object packing frames (independent of livesweep's sender)."""
    mav = mav2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.link_id = 3
        mav.signing.timestamp = int((time.time() - 1_420_070_400) * 100_000)

    def pack(k: int) -> bytes:
        msg = mav.attitude_encode(1000 + k, 0.01 * k, 0.0, 0.0, 0.0, 0.0, 0.0)
        buf = bytes(msg.pack(mav))
        mav.seq = (mav.seq + 1) % 256
        return buf

    return pack


def att_record(k: int, sysid: int = 1, compid: int = 1) -> dict:
    return codec.record_from_fields("ATTITUDE", {"time_boot_ms": 1000 + k, "roll": 0.01 * k},
                                    sysid=sysid, compid=compid)


# ----------------------------------------------------------------------------- live UDP


def test_udp_records_round_trip_two_systems():
    src, port = udp_source()
    sent = {1: live_records(1, 60), 7: live_records(7, 40)}
    t_before = time.time_ns()
    try:
        assert all(callable(getattr(src, m)) for m in ("poll", "close"))  # frames.Source shape
        assert isinstance(src.counts, dict)
        assert src.finished is False
        with MavlinkSender(f"udpout:127.0.0.1:{port}", source_system=1) as tx:
            # interleave the two systems
            items = [x for pair in zip(sent[1], sent[7]) for x in pair] + sent[1][len(sent[7]):]
            for name, rec in items:
                tx.send_record(name, rec)
            assert tx.send_errors == 0
            frames = collect(src, len(items))
            counts = src.counts
            sent_counts, sent_bytes = dict(tx.sent_counts), tx.bytes_sent
    finally:
        src.close()
    t_after = time.time_ns()

    assert len(frames) == len(items)
    for sysid, recs in sent.items():
        got = [f for f in frames if f.data["sysid"] == sysid]
        assert [f.topic for f in got] == [f"/mavlink/{name}" for name, _ in recs]
        assert [f.data for f in got] == [rec for _, rec in recs]  # canonical records, exactly
        for f, (name, rec) in zip(got, recs):
            assert f.vehicle_ns == codec.vehicle_time_ns(rec, name)
            assert t_before <= f.receive_ns <= t_after
    assert next(f for f in frames if f.topic == "/mavlink/HEARTBEAT").vehicle_ns is None
    assert counts["received"] == sent_counts == dict(Counter(n for n, _ in items))
    assert counts["by_system"] == {1: len(sent[1]), 7: len(sent[7])}
    assert counts["bytes"] == sent_bytes
    for k in ("bad_crc", "bad_prefix_or_garbage", "rejected_unsigned", "bad_signature", "bad_other",
              "unknown_message", "seq_repeats"):
        assert counts[k] == 0, k
    assert counts["seq_gaps"] == {}  # the sender keeps one seq counter per (sysid, compid)


def test_poll_max_frames_keeps_the_rest_and_never_blocks_when_data_is_there():
    src, port = udp_source()
    pack = packer()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            # one datagram holding 30 frames, then 10 single-frame datagrams
            s.sendto(b"".join(pack(k) for k in range(30)), ("127.0.0.1", port))
            for k in range(30, 40):
                s.sendto(pack(k), ("127.0.0.1", port))
            time.sleep(0.1)
        t0 = time.monotonic()
        first = src.poll(timeout_s=5.0, max_frames=25)
        rest = src.poll(timeout_s=5.0)
        assert time.monotonic() - t0 < 1.0  # data was there: no waiting
        t0 = time.monotonic()
        assert src.poll(timeout_s=0.2) == []  # nothing there: waits about timeout_s
        assert 0.15 <= time.monotonic() - t0 < 1.5
    finally:
        src.close()
    assert len(first) == 25
    assert [f.data for f in first + rest] == [att_record(k) for k in range(40)]


def test_corrupt_datagrams_are_counted_and_good_frames_survive():
    src, port = udp_source()
    pack = packer()
    good = [pack(k) for k in range(8)]
    bad_crc = bytearray(good[1])
    bad_crc[-1] ^= 0xFF  # flipped CRC byte
    garbage = b"\x00\x11garbage, not mavlink\x42" * 3  # no 0xFD/0xFE in it
    truncated = good[3][:15]  # a header and part of the payload
    datagrams = [
        good[0],
        bytes(bad_crc),        # -> bad_crc 1 (and a seq gap of 1: seq 1 never decoded)
        garbage,               # -> bad_prefix_or_garbage 1
        good[2],
        truncated,             # -> bad_prefix_or_garbage 1 (cut frame; must not eat the next datagram)
        good[4],
        garbage + good[5],     # -> bad_prefix_or_garbage 1, then a good frame from the same datagram
        good[6] + good[7][:9],  # good frame, then a cut one -> bad_prefix_or_garbage 1
    ]
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for d in datagrams:
                s.sendto(d, ("127.0.0.1", port))
        frames = collect(src, 5)
        counts = src.counts
    finally:
        src.close()
    assert [f.data["time_boot_ms"] for f in frames] == [1000, 1002, 1004, 1005, 1006]
    assert [f.data for f in frames] == [att_record(k) for k in (0, 2, 4, 5, 6)]
    assert counts["bad_crc"] == 1
    assert counts["bad_prefix_or_garbage"] == 4
    assert counts["received"] == {"ATTITUDE": 5}
    # seq 1 (bad CRC) and seq 3 (truncated) never decoded; seq 7 was cut too but nothing follows
    assert counts["seq_gaps"] == {"1/1": 2}
    assert counts["bytes"] == sum(len(d) for d in datagrams)


def test_signing_accepts_rejects_and_counts():
    n = 12
    recs = [att_record(k, sysid=3) for k in range(n)]

    def run(src_kw, tx_key, until):
        src, port = udp_source(**src_kw)
        try:
            with MavlinkSender(f"udpout:127.0.0.1:{port}", source_system=3, signing_key=tx_key) as tx:
                for r in recs:
                    tx.send_record("ATTITUDE", r)
            c = wait_counts(src, until)
            frames = src.poll(0.0)
            return c, frames
        finally:
            src.close()

    # key on both ends: everything accepted
    src, port = udp_source(signing_key=KEY)
    try:
        with MavlinkSender(f"udpout:127.0.0.1:{port}", source_system=3, signing_key=KEY) as tx:
            for r in recs:
                tx.send_record("ATTITUDE", r)
        frames = collect(src, n)
        c = src.counts
    finally:
        src.close()
    assert [f.data for f in frames] == recs
    assert c["rejected_unsigned"] == c["bad_signature"] == c["unsigned_accepted"] == 0

    # unsigned sender, key on the receiver: rejected and counted, exactly
    c, frames = run({"signing_key": KEY}, None, lambda c: c["rejected_unsigned"] >= n)
    assert frames == [] and c["received"] == {}
    assert c["rejected_unsigned"] == n and c["bad_signature"] == 0 and c["bad_crc"] == 0

    # ... unless unsigned frames are allowed explicitly
    c, frames = run({"signing_key": KEY, "allow_unsigned": True}, None, lambda c: c["unsigned_accepted"] >= n)
    assert c["unsigned_accepted"] == n and c["rejected_unsigned"] == 0
    assert c["received"] == {"ATTITUDE": n}

    # wrong key: bad signatures, never accepted (not even with allow_unsigned)
    for allow in (False, True):
        c, frames = run({"signing_key": KEY, "allow_unsigned": allow}, OTHER_KEY,
                        lambda c: c["bad_signature"] >= n)
        assert frames == [] and c["received"] == {}
        assert c["bad_signature"] == n and c["rejected_unsigned"] == 0 and c["unsigned_accepted"] == 0

    # no key on the receiver: signed frames are accepted (signature ignored)
    c, frames = run({}, KEY, lambda c: sum(c["received"].values()) >= n)
    assert c["received"] == {"ATTITUDE": n}


def test_replayed_signed_frames_are_rejected():
    pack = packer(sysid=5, key=KEY)
    frames_bytes = [pack(k) for k in range(6)]
    src, port = udp_source(signing_key=KEY)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for d in frames_bytes:
                s.sendto(d, ("127.0.0.1", port))
            first = collect(src, 6)
            for d in frames_bytes:  # an attacker replays the captured frames
                s.sendto(d, ("127.0.0.1", port))
            c = wait_counts(src, lambda c: c["bad_signature"] >= 6)
    finally:
        src.close()
    assert [f.data for f in first] == [att_record(k, sysid=5) for k in range(6)]
    assert c["received"] == {"ATTITUDE": 6}
    assert c["bad_signature"] == 6


def test_source_url_validation(tmp_path):
    tl = tmp_path / "flight.tlog"
    tl.write_bytes(b"x")
    for url in (str(tl), "flight.tlog", "./x/y", "logs/00000001.BIN"):
        with pytest.raises(ConfigError, match="TlogSource"):
            MavlinkSource(url)
    with pytest.raises(ConfigError, match="udpin"):
        MavlinkSource("udpout:127.0.0.1:14550")
    for url in ("udpin:127.0.0.1:70000", "udpin:127.0.0.1", "http://x:1", "", " udpin:127.0.0.1:1",
                "/dev/../bin/sh", "/dev/null"):
        with pytest.raises(ConfigError):
            MavlinkSource(url)
    with pytest.raises(ConfigError, match="32 bytes"):
        MavlinkSource("udpin:127.0.0.1:0", signing_key=b"short")
    # short forms bind loopback; other hosts only when written out
    assert parse_source_url("udpin:14550") == {"kind": "udpin", "host": "127.0.0.1", "port": 14550}
    assert parse_source_url("udpin::0")["port"] == 0
    assert parse_source_url("udp:0.0.0.0:14550")["host"] == "0.0.0.0"
    with MavlinkSource("udpin:0") as src:
        host, port = src.local_address
        assert host == "127.0.0.1" and port > 0


def test_tcp_source_reads_a_stream():
    """tcpin: a client connects and writes frames split at arbitrary points (a byte stream)."""
    src = MavlinkSource("tcpin:127.0.0.1:0")
    port = src.local_address[1]
    pack = packer()
    blob = b"".join(pack(k) for k in range(50))
    try:
        frames: list[Frame] = []
        with socket.create_connection(("127.0.0.1", port)) as c:
            for i in range(0, len(blob), 37):
                c.sendall(blob[i:i + 37])
                if i % 370 == 0:
                    frames += src.poll(0.0)
            frames += collect(src, 50 - len(frames))
    finally:
        src.close()
    assert [f.data for f in frames] == [att_record(k) for k in range(50)]


def test_tcp_client_source_and_server_close():
    """tcp: the source connects to a server (e.g. SITL's tcp:5760); a closed server is not fatal."""
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    pack = packer(sysid=4)
    try:
        src = MavlinkSource(f"tcp:127.0.0.1:{port}")
        conn, _ = server.accept()
        with conn:
            conn.sendall(b"".join(pack(k) for k in range(20)))
            frames = collect(src, 20)
        # server side closed: polls return nothing, wait their timeout, raise nothing
        t0 = time.monotonic()
        assert src.poll(0.1) == [] and src.poll(0.1) == []
        assert time.monotonic() - t0 >= 0.15
        assert src.link_events == 1 and src.finished is False
        src.close()
    finally:
        server.close()
    assert [f.data for f in frames] == [att_record(k, sysid=4) for k in range(20)]
    with pytest.raises(Exception) as e:  # nothing listens there any more
        MavlinkSource(f"tcp:127.0.0.1:{port}")
    assert "cannot be opened" in str(e.value)


# ----------------------------------------------------------------------------- tlog: reference count

_COUNT_SCRIPT = r"""
import json, os, sys
os.environ["MAVLINK20"] = "1"
os.environ["MAVLINK_DIALECT"] = "ardupilotmega"
from pymavlink import mavutil
path = sys.argv[1]
r = mavutil.mavlink_connection(path)          # pymavlink's own reader (mavmmaplog)
types, systems, gaps, last = {}, {}, {}, {}
bad = 0; first_ts = None; last_ts = None; att = []
while True:
    m = r.recv_msg()  # what recv_match() does without a type filter, minus its overhead
    if m is None:
        break
    t = m.get_type()
    if t == "BAD_DATA":
        bad += 1
        continue
    types[t] = types.get(t, 0) + 1
    if t.startswith("UNKNOWN_"):
        continue
    key = "%d/%d" % (m.get_srcSystem(), m.get_srcComponent())
    systems[key] = systems.get(key, 0) + 1
    s = m.get_seq()
    if key in last:
        g = (s - last[key] - 1) % 256
        if g and g != 255:
            gaps[key] = gaps.get(key, 0) + g
    last[key] = s
    if first_ts is None:
        first_ts = round(m._timestamp * 1e6)
    last_ts = round(m._timestamp * 1e6)
    if t == "ATTITUDE" and len(att) < 200:
        att.append(m.to_dict())
print(json.dumps({"types": types, "bad_data": bad, "systems": systems, "gaps": gaps,
                  "first_us": first_ts, "last_us": last_ts, "attitude": att}))
"""


class _Reference:
    """pymavlink counts of a tlog, computed in a subprocess started ahead of time."""

    def __init__(self, path: Path):
        env = dict(os.environ, MAVLINK20="1", MAVLINK_DIALECT="ardupilotmega")
        self.proc = subprocess.Popen([sys.executable, "-c", _COUNT_SCRIPT, str(path)],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
        self._result = None

    def result(self) -> dict:
        if self._result is None:
            out, err = self.proc.communicate(timeout=120)
            assert self.proc.returncode == 0, err
            self._result = json.loads(out)
        return self._result


@pytest.fixture(scope="module", autouse=True)
def _reference_counts():
    """Started with the module's first test, so pymavlink's reading overlaps the live tests."""
    refs = {p.name: _Reference(p) for p in (AUTOTEST, VTOL) if p.is_file()}
    yield refs
    for r in refs.values():
        if r.proc.poll() is None:
            r.proc.kill()
        r.proc.communicate()


@pytest.fixture
def reference(_reference_counts):
    if not AUTOTEST.is_file() or not VTOL.is_file():
        pytest.skip(f"third-party tlogs not found under {TLOG_DIR}")
    return _reference_counts


def read_all(src) -> list[Frame]:
    out: list[Frame] = []
    while not src.finished:
        out += src.poll()
    return out


@pytest.mark.slow
def test_autotest_tlog_vs_pymavlink(reference):
    """The awkward autotest log: three sources, console text logged one byte per record.

    pymavlink (96 784 messages, 140 BAD_DATA with recv_match, packages.md) reads each 1-byte
    text record plus the next time stamp as one "Bad prefix" BAD_DATA and then loses the
    record alignment; in doing so it swallows 5 HEARTBEATs and decodes 3 spurious
    UNKNOWN_* messages from sysid 0 out of misaligned bytes. TlogSource keeps the record
    alignment (time-stamp plausibility), so it counts the text records as 285 one-byte
    garbage runs, delivers those 5 HEARTBEATs, and no UNKNOWN messages. Every other message
    type is counted identically.
    """
    with TlogSource(AUTOTEST) as src:
        frames = read_all(src)
        c = src.counts
    ref = reference[AUTOTEST.name].result()
    ref_types = ref["types"]
    assert sum(ref_types.values()) + ref["bad_data"] == 96784 and ref["bad_data"] == 140
    spurious = {t: n for t, n in ref_types.items() if t.startswith("UNKNOWN_")}
    assert sum(spurious.values()) == 3 and ref["systems"].get("0/0", 0) == 0  # unknown ones not in systems
    mine = c["received"]
    assert set(mine) == set(ref_types) - set(spurious)
    diff = {t: mine[t] - ref_types[t] for t in mine if mine[t] != ref_types[t]}
    assert diff == {"HEARTBEAT": 5}
    assert len(frames) == sum(ref_types.values()) - 3 + 5 == 96646
    assert c["by_system"] == {1: 91243, 250: 5403}
    assert {k: v for k, v in ref["systems"].items()} == {"1/1": 91239, "250/250": 5402}
    assert c["bad_prefix_or_garbage"] == c["garbage_bytes"] == 285  # 285 one-byte text records
    assert c["bad_crc"] == c["unknown_message"] == c["truncated_tail"] == 0
    assert c["records"] == len(frames)
    # receive times are the record time stamps: non-decreasing here, within the log's span
    rn = np.array([f.receive_ns for f in frames])
    assert rn[0] >= ref["first_us"] * 1000 - 10**9 and rn[-1] == ref["last_us"] * 1000
    assert np.all(np.diff(rn) >= 0)


def test_vtol_tlog_matches_pymavlink(reference):
    with TlogSource(VTOL) as src:
        frames = read_all(src)
        c = src.counts
        assert src.poll() == [] and src.finished
    ref = reference[VTOL.name].result()
    # a clean MAVLink 1 log: identical counts, per type and per system, and identical seq gaps
    assert ref["bad_data"] == 0
    assert c["received"] == ref["types"]
    assert len(frames) == sum(ref["types"].values()) == 23894
    assert {f"{k}/1": v for k, v in c["by_system"].items()} == ref["systems"]
    assert c["seq_gaps"] == ref["gaps"]
    assert c["bad_crc"] == c["bad_prefix_or_garbage"] == c["unknown_message"] == c["truncated_tail"] == 0
    # receive_ns is the tlog time stamp; values equal pymavlink's decoding (float32 exact)
    assert frames[0].receive_ns == ref["first_us"] * 1000
    assert frames[-1].receive_ns == ref["last_us"] * 1000
    att = [f for f in frames if f.topic == "/mavlink/ATTITUDE"][: len(ref["attitude"])]
    for f, d in zip(att, ref["attitude"]):
        assert f.data["time_boot_ms"] == d["time_boot_ms"]
        assert f.vehicle_ns == d["time_boot_ms"] * 1_000_000
        for k in ("roll", "pitch", "yaw", "rollspeed", "pitchspeed", "yawspeed"):
            assert np.float32(f.data[k]) == np.float32(d[k])


# ----------------------------------------------------------------------------- tlog: own files


def write_tlog(path: Path, records: list[tuple[int, bytes]]) -> None:
    with open(path, "wb") as f:
        for ts_us, buf in records:
            f.write(struct.pack(">Q", ts_us) + buf)


T_US = 1_732_000_000_000_000  # 2024-11 in µs


def test_tlog_corruption_truncation_and_times(tmp_path, caplog):
    pack = packer(sysid=2, compid=4)
    frames_bytes = [pack(k) for k in range(10)]
    crc = bytearray(frames_bytes[3])
    crc[12] ^= 0x55  # payload byte flipped -> CRC error
    badlen = bytearray(frames_bytes[6])
    badlen[1] = 200  # corrupted length byte: the reader must not lose the following records
    recs = [
        (T_US + 0, frames_bytes[0]),
        (T_US + 10_000, frames_bytes[1]),
        (T_US + 15_000, b"some console text"),  # a non-MAVLink record
        (T_US + 20_000, frames_bytes[2]),
        (T_US + 30_000, bytes(crc)),
        (T_US + 40_000, frames_bytes[4]),
        (T_US + 50_000, frames_bytes[5]),
        (T_US + 60_000, bytes(badlen)),
        (T_US + 70_000, frames_bytes[7]),
        (T_US + 80_000, frames_bytes[8]),
    ]
    p = tmp_path / "run.tlog"
    write_tlog(p, recs)
    with open(p, "ab") as f:  # a cut last record
        f.write(struct.pack(">Q", T_US + 90_000) + frames_bytes[9][:10])
    with TlogSource(p) as src:
        got = read_all(src)
        c = src.counts
    good = [0, 1, 2, 4, 5, 7, 8]
    assert [f.data for f in got] == [att_record(k, 2, 4) for k in good]
    ts_by_k = {0: 0, 1: 10_000, 2: 20_000, 4: 40_000, 5: 50_000, 7: 70_000, 8: 80_000}
    assert [f.receive_ns for f in got] == [(T_US + ts_by_k[k]) * 1000 for k in good]
    assert [f.vehicle_ns for f in got] == [(1000 + k) * 1_000_000 for k in good]
    assert c["bad_crc"] == 1
    assert c["truncated_tail"] == 1
    assert c["bad_prefix_or_garbage"] == 2  # the text record, and the frame with a bad length
    # skipped: the 17 text bytes, the 20-byte frame whose length byte is wrong, the cut 18-byte tail
    assert c["garbage_bytes"] == 17 + 20 + 18
    assert c["received"] == {"ATTITUDE": 7} and c["by_system"] == {2: 7}
    assert c["seq_gaps"] == {"2/4": 2}
    assert "cut" in caplog.text


def test_tlog_paced_replay(tmp_path):
    pack = packer()
    p = tmp_path / "paced.tlog"
    write_tlog(p, [(T_US + 10_000 * k, pack(k)) for k in range(21)])  # 0.2 s of log time
    for speed, expect_s in ((1.0, 0.2), (4.0, 0.05)):
        with TlogSource(p, speed=speed) as src:
            t0 = time.monotonic()
            got = read_all(src)
            dt = time.monotonic() - t0
        assert len(got) == 21
        assert expect_s * 0.9 <= dt < expect_s + 0.5, (speed, dt)
    with TlogSource(p, speed=math.inf) as src:
        assert len(src.poll(max_frames=5)) == 5
        assert len(src.poll()) == 16 and src.finished
    for bad in (-1, float("nan"), "fast"):
        with pytest.raises(ConfigError):
            TlogSource(p, speed=bad)


def test_signed_tlog(tmp_path):
    signed = tmp_path / "signed.tlog"
    pack = packer(sysid=9, key=KEY)
    frames_bytes = [pack(k) for k in range(8)]
    write_tlog(signed, [(T_US + 1000 * k, b) for k, b in enumerate(frames_bytes)]
               + [(T_US + 9000, frames_bytes[2])])  # a replayed frame inside the log
    with TlogSource(signed, signing_key=KEY) as src:
        got = read_all(src)
        c = src.counts
    assert [f.data for f in got] == [att_record(k, 9) for k in range(8)]
    assert c["bad_signature"] == 1
    with TlogSource(signed, signing_key=OTHER_KEY) as src:
        assert read_all(src) == [] and src.counts["bad_signature"] == 9
    unsigned = tmp_path / "unsigned.tlog"
    pack = packer(sysid=9)
    write_tlog(unsigned, [(T_US + 1000 * k, pack(k)) for k in range(5)])
    with TlogSource(unsigned, signing_key=KEY) as src:
        assert read_all(src) == [] and src.counts["rejected_unsigned"] == 5


def test_files_that_are_not_tlogs(tmp_path):
    cases = []
    dataflash = sorted((DATA / "ardupilot_dataflash").glob("*.bin"))
    if dataflash:
        cases.append(dataflash[0])
    rnd = tmp_path / "random.tlog"
    rnd.write_bytes(np.random.default_rng(1).bytes(4096))
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    text = tmp_path / "notes.tlog"
    text.write_text("hello, this is not a telemetry log\n" * 20)
    # a plausible first time stamp, but no MAVLink frame anywhere
    nomav = tmp_path / "nomav.tlog"
    nomav.write_bytes(struct.pack(">Q", T_US) + bytes(range(0x20, 0x7F)) * 10)
    cases += [rnd, empty, text, nomav, tmp_path / "missing.tlog"]
    for p in cases:
        with pytest.raises(LogFormatError) as e:
            TlogSource(p)
        assert str(p) in str(e.value)


def test_bin_path_is_never_executed(tmp_path):
    bindir = tmp_path / "bin"
    bindir.mkdir()
    marker = tmp_path / "EXECUTED"
    script = f"#!/bin/sh\ntouch {marker}\n"
    paths = [bindir / "x.tlog", bindir / "x", bindir / "x.elf"]
    for p in paths:
        p.write_text(script)
        p.chmod(p.stat().st_mode | stat.S_IXUSR)
        with pytest.raises(LogFormatError, match="not a MAVLink tlog"):
            TlogSource(p)
        with pytest.raises(ConfigError):
            MavlinkSource(str(p))
    time.sleep(0.2)
    assert not marker.exists()
    # a real tlog under a /bin/ directory is read by content, correctly
    good = bindir / "good.tlog"
    pack = packer()
    write_tlog(good, [(T_US + 1000 * k, pack(k)) for k in range(5)])
    good.chmod(0o755)
    with TlogSource(good) as src:
        assert [f.data for f in read_all(src)] == [att_record(k) for k in range(5)]
    assert not marker.exists()


# ----------------------------------------------------------------------------- hardening


def test_a_forged_signed_frame_does_not_block_later_genuine_frames():
    """The attack: a copy of a genuine frame's header with signing time stamp 2**48-1 and a random
    signature, sent without the key. pymavlink's own check stores that time stamp before comparing
    the signature, after which every genuine frame of the stream looks like a replay."""
    pack = packer(sysid=5, key=KEY)
    genuine = [pack(k) for k in range(1010)]
    g = bytearray(genuine[10])
    g[-12:-6] = (2**48 - 1).to_bytes(6, "little")
    g[-6:] = os.urandom(6)
    src, port = udp_source(signing_key=KEY)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for d in genuine[:10] + [bytes(g)] + genuine[10:]:
                s.sendto(d, ("127.0.0.1", port))
            frames = collect(src, 1010, timeout=10)
            c = src.counts
    finally:
        src.close()
    assert [f.data["time_boot_ms"] for f in frames] == [1000 + k for k in range(1010)]
    assert c["bad_signature"] == 1 and c["replayed_signature"] == 0 and c["received"] == {"ATTITUDE": 1010}


def test_poison_stamps_are_recorded_with_their_receive_time_and_counted():
    """A uint64 time_usec of 2**64-1 µs is beyond what an MCAP time holds (2**64 ns); one frame
    116 days ahead is ahead of every clock the stream has shown. Each is delivered whole, without a
    vehicle time, and counted; the stream's clock is not disturbed. A UNIX time is a time the field
    may carry (MAVLink: "UNIX Epoch time or time since system boot"): taken as it is."""
    def imu(t_usec):
        return codec.record_from_fields("HIGHRES_IMU", {"time_usec": t_usec, "xacc": 1.0}, sysid=1, compid=1)

    t = [1_000_000 + 10_000 * k for k in range(40)]
    stamps = t[:10] + [2**64 - 1] + t[10:20] + [t[19] + 116 * 86_400 * 10**6] + t[20:30] \
        + [1_700_000_000 * 10**6] + t[30:]
    src, port = udp_source()
    try:
        with MavlinkSender(f"udpout:127.0.0.1:{port}") as tx:
            for st in stamps:
                tx.send_record("HIGHRES_IMU", imu(st))
        frames = collect(src, len(stamps))
        c = src.counts
    finally:
        src.close()
    assert [f.data["time_usec"] for f in frames] == stamps
    bad = {10, 21}
    assert [k for k, f in enumerate(frames) if f.vehicle_ns is None] == sorted(bad)
    assert all(f.vehicle_ns == f.data["time_usec"] * 1000 for k, f in enumerate(frames) if k not in bad)
    assert c["clock_unrepresentable"] == 1 and c["clock_implausible"] == 1


def test_tcpin_serves_several_clients_and_an_idle_one_blinds_nothing():
    src = MavlinkSource("tcpin:127.0.0.1:0")
    port = src.local_address[1]
    a, b = packer(sysid=7), packer(sysid=8)
    try:
        idle = socket.create_connection(("127.0.0.1", port))         # connects, never sends
        with idle, socket.create_connection(("127.0.0.1", port)) as c1, \
                socket.create_connection(("127.0.0.1", port)) as c2:
            blob1, blob2 = b"".join(a(k) for k in range(40)), b"".join(b(k) for k in range(40))
            for i in range(0, len(blob1), 29):       # the two byte streams interleave on the wire
                c1.sendall(blob1[i:i + 29])
                c2.sendall(blob2[i:i + 29])
            frames = collect(src, 80)
            counts = src.counts
    finally:
        src.close()
    by_sys = {s: [f.data["time_boot_ms"] for f in frames if f.data["sysid"] == s] for s in (7, 8)}
    assert by_sys == {7: [1000 + k for k in range(40)], 8: [1000 + k for k in range(40)]}
    assert counts["clients"] == 3 and counts["bad_crc"] == counts["bad_prefix_or_garbage"] == 0


def test_kernel_drops_are_counted():
    """A burst into a small socket buffer that nobody reads: what the kernel drops is counted, so
    received + dropped = sent (Linux). The kernel stamps its drop count on each datagram it
    queues (SO_RXQ_OVFL), so a burst's drops arrive with the next datagram; /proc/net/udp has them
    at once (refresh_kernel_drops, which the monitor calls once a second and at close)."""
    if not sys.platform.startswith("linux"):
        pytest.skip("the kernel reports drops on Linux only")
    src, port = udp_source(rcvbuf_bytes=4096)
    pack = packer(sysid=2)
    n = 3000
    try:
        frames = []
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for k in range(n - 1):
                s.sendto(pack(k), ("127.0.0.1", port))
            time.sleep(0.2)
            while chunk := src.poll(0.1):
                frames += chunk
            src.refresh_kernel_drops()
            assert len(frames) + src.counts["kernel_drops"] == n - 1
            s.sendto(pack(n - 1), ("127.0.0.1", port))
            frames += collect(src, 1)
        c = src.counts
    finally:
        src.close()
    assert c["kernel_drops"] > 0
    assert len(frames) + c["kernel_drops"] == n
