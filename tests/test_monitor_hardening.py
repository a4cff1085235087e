"""The live monitor against what a radio link can carry: real UDP on 127.0.0.1, the real command in a
subprocess, real MCAP files read back with the standard ``mcap`` reader. Nothing mocked.

The fuzz test mixes, on one port, two vehicles' signed frames with garbage, corrupted frames,
unsigned frames, a forged signed frame, replays and poison time stamps, and checks that the monitor
keeps running, that every valid frame is in the recording, that every bad one is counted (in the
summary and in the file) and that its memory stays bounded.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from helpers import CpuHog
from livesweep.errors import LogFormatError
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.mcap_log import read_messages, read_summary
from livesweep.telemetry.recorder import COUNTERS_METADATA, McapRecorder
from livesweep.telemetry.sim_telemetry import mavlink_timeline
from livesweep.sim.scenario import simulate, sweep_scenario
from pymavlink.dialects.v20 import ardupilotmega as mav2  # after the codec import (MAVLINK20=1)

KEY = hashlib.sha256(b"livesweep fuzz key").digest()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_monitor(args: list[str]) -> subprocess.Popen:
    mon = subprocess.Popen([sys.executable, "-m", "livesweep", "monitor", *args],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    line = mon.stdout.readline()
    assert line.startswith(b"monitor: listening"), line + mon.stderr.read()
    return mon


def peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def mavlink_counts(path) -> Counter:
    """(message type, sysid) -> messages, read with the standard mcap reader (independent of ours)."""
    out = Counter()
    with open(path, "rb") as f:
        for _schema, channel, msg in make_reader(f).iter_messages():
            if channel.topic.startswith("/mavlink/"):
                out[(channel.topic.split("/")[-1], json.loads(msg.data)["sysid"])] += 1
    return out


class Vehicle:
    """A bare pymavlink MAVLink 2 encoder for one system (independent of livesweep's sender)."""

    def __init__(self, sysid: int, key: bytes | None):
        self.mav = mav2.MAVLink(None, srcSystem=sysid, srcComponent=1)
        if key is not None:
            s = self.mav.signing
            s.secret_key, s.sign_outgoing, s.link_id = key, True, 1
            s.timestamp = int((time.time() - 1_420_070_400) * 100_000)

    def pack(self, name: str, record: dict) -> bytes:
        spec = codec._spec(name)
        kw = {f.name: record[f.name] for f in spec.fields}
        for f in spec.fields:
            if f.kind == "char" and isinstance(kw[f.name], str):
                kw[f.name] = kw[f.name].encode()
            if f.kind in ("f32", "f64") and kw[f.name] is None:
                kw[f.name] = float("nan")
        msg = getattr(self.mav, name.lower() + "_encode")(**kw)
        buf = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256          # pack() leaves the sequence to send()
        return buf


def sim_stream(seed: int, duration_s: float) -> list[tuple[str, dict]]:
    res = simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=0.5, omega_max_rad_s=20.0,
                                  duration_s=duration_s, amplitudes={"da": 3.0}, off_axis_rms=0.3, seed=seed))
    recs, _ = mavlink_timeline(res)
    recs.sort(key=lambda r: (r.vehicle_time_ns, r.msgname))
    return [(r.msgname, r.record) for r in recs if r.msgname != "HEARTBEAT"]


# ----------------------------------------------------------------------------- the fuzz test


@pytest.mark.slow
def test_fuzz_two_vehicles_garbage_poison_stamps_and_a_forged_frame(tmp_path):
    """With every core busy (a field laptop), about 8 000 datagrams/s of two signed vehicles, garbage,
    corrupted, unsigned, forged and replayed frames and stamps no clock has: every valid frame is
    recorded, every bad one counted for what it is, nothing dropped by the kernel."""
    with CpuHog():
        out, valid, sent_bad, text, rss = _fuzz(tmp_path)
    # every valid frame is in the recording, which any MCAP reader opens (finished by SIGTERM)
    assert mavlink_counts(out) == valid
    s = read_summary(out)
    assert s.complete
    counters = json.loads(s.metadata[COUNTERS_METADATA]["sources"])[0]
    assert counters["kernel_drops"] == 0
    assert counters["bad_crc"] == sent_bad["bad_crc"]
    assert counters["bad_prefix_or_garbage"] >= sent_bad["garbage"]
    assert counters["rejected_unsigned"] == sent_bad["unsigned"]
    assert counters["bad_signature"] == sent_bad["forged"] + sent_bad["replayed"]
    assert counters["replayed_signature"] == sent_bad["replayed"]
    assert counters["clock_unrepresentable"] + counters["clock_implausible"] == sent_bad["poison_stamp"]
    assert counters["seq_gaps"] == {} and counters["seq_repeats"] == 0
    assert counters["by_system"] == {"1": sum(v for (_, sy), v in valid.items() if sy == 1),
                                     "2": sum(v for (_, sy), v in valid.items() if sy == 2)}
    # ... also counted live: on /livesweep/link, as link alerts, and in the printed summary
    links = [m.data for m in read_messages(out, topics="/livesweep/link")]
    assert links and links[-1]["sources"][0]["bad_crc"] == sent_bad["bad_crc"]
    kinds = Counter(m.data["kind"] for m in read_messages(out, topics="/livesweep/alert"))
    assert kinds["link"] >= 2                    # the anomalies, and the second system
    rejected = next(ln for ln in text.splitlines() if "rejected or repaired: " in ln)
    assert f" {sent_bad['bad_crc']} bad CRC" in rejected and "systems {1:" in text and "'" not in rejected
    assert rss < 500, f"peak RSS {rss:.0f} MB"


def _fuzz(tmp_path):
    """Send the fuzz stream to a monitor and stop it; returns (recording, valid frames sent per
    (type, sysid), bad frames sent per kind, the monitor's printed summary, its peak RSS [MB])."""
    rng = np.random.default_rng(2026)
    key_file = tmp_path / "key.bin"
    key_file.write_bytes(KEY)
    out = tmp_path / "fuzz.mcap"
    port = free_udp_port()
    mon = start_monitor(["--mavlink", f"udpin:127.0.0.1:{port}", "--signing-key-file", str(key_file),
                         "--record", str(out), "--window", "30"])
    v1, v2 = Vehicle(1, KEY), Vehicle(2, KEY)
    unsigned = Vehicle(3, None)
    valid = Counter()                  # (type, sysid) -> valid frames sent
    sent_bad = Counter()
    datagrams: list[bytes] = []
    first_genuine = None
    for k, ((n1, r1), (n2, r2)) in enumerate(zip(sim_stream(31, 40.0), sim_stream(32, 40.0))):
        r2 = {**r2, "sysid": 2}
        if k % 997 == 500:                       # poison stamps: valid signed frames, stamps no clock has
            field = codec.vehicle_time_field(n1)[0]
            if codec.stamp_wrap_units(n1, field):                         # uint32: the top of its range
                r1 = {**r1, field: 2**32 - 1}
            else:                                                         # uint64: beyond MCAP, or 116 days on
                r1 = {**r1, field: (2**64 - 1, r1[field] + 116 * 86_400 * 10**6)[k % 2]}
            sent_bad["poison_stamp"] += 1
        for veh, name, rec in ((v1, n1, r1), (v2, n2, r2)):
            d = veh.pack(name, rec)
            first_genuine = first_genuine or d
            datagrams.append(d)
            valid[(name, veh.mav.srcSystem)] += 1
        if k % 211 == 0:                         # garbage with no frame marker in it
            g = rng.integers(0, 250, size=int(rng.integers(1, 200)), dtype=np.uint8).tobytes()
            datagrams.append(g.replace(b"\xfd", b"\x00").replace(b"\xfe", b"\x00"))
            sent_bad["garbage"] += 1
        if k % 223 == 0:                         # a valid frame with one payload byte flipped
            d = bytearray(v1.pack(n1, r1))
            v1.mav.seq = (v1.mav.seq - 1) % 256  # the corrupted frame does not use up a sequence number
            d[12] ^= 0x55
            datagrams.append(bytes(d))
            sent_bad["bad_crc"] += 1
        if k % 307 == 0:                         # an unsigned frame (a signing key is set)
            datagrams.append(unsigned.pack(n1, {**r1, "sysid": 3}))
            sent_bad["unsigned"] += 1
        if k == 1000:                            # the forged frame: a genuine header, 2**48-1, no key
            f = bytearray(first_genuine)
            f[-12:-6] = (2**48 - 1).to_bytes(6, "little")
            f[-6:] = rng.integers(0, 256, 6, dtype=np.uint8).tobytes()
            datagrams.append(bytes(f))
            sent_bad["forged"] += 1
        if k == 1500:                            # a captured genuine frame replayed
            datagrams.append(first_genuine)
            sent_bad["replayed"] += 1
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            t0 = time.monotonic()
            for i, d in enumerate(datagrams):    # about 8 000 datagrams/s
                s.sendto(d, ("127.0.0.1", port))
                if i % 400 == 399:
                    time.sleep(max(0.0, t0 + (i + 1) / 8000 - time.monotonic()))
        time.sleep(1.0)
        assert mon.poll() is None, mon.stderr.read()             # still running
        rss = peak_rss_mb(mon.pid)
        mon.send_signal(signal.SIGTERM)
        stdout, stderr = mon.communicate(timeout=60)
    finally:
        if mon.poll() is None:
            mon.kill()
    assert mon.returncode == 0, stderr.decode()
    print(f"\nfuzz: {len(datagrams)} datagrams, {sum(valid.values())} valid frames, bad sent {dict(sent_bad)}, "
          f"peak RSS {rss:.0f} MB\n{stdout.decode()}")
    return out, valid, sent_bad, stdout.decode(), rss


# ----------------------------------------------------------------------------- stop, overwrite, lock


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_finish_the_recording(tmp_path, sig):
    port = free_udp_port()
    out = tmp_path / "run.mcap"
    mon = start_monitor(["--mavlink", f"udpin:127.0.0.1:{port}", "--record", str(out)])
    v = Vehicle(1, None)
    frames = sim_stream(5, 30.0)[:400]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for name, rec in frames:
            s.sendto(v.pack(name, rec), ("127.0.0.1", port))
    time.sleep(0.5)
    mon.send_signal(sig)
    stdout, stderr = mon.communicate(timeout=30)
    assert mon.returncode == 0, stderr.decode()
    with open(out, "rb") as f:                   # the standard reader needs the summary and footer
        summary = make_reader(f).get_summary()
    n = sum(summary.statistics.channel_message_counts[cid] for cid, ch in summary.channels.items()
            if ch.topic.startswith("/mavlink/"))
    assert n == len(frames)
    assert f"wrote {out}" in stdout.decode()


@pytest.mark.slow
def test_an_existing_recording_is_not_overwritten_unless_forced(tmp_path):
    out = tmp_path / "flight.mcap"
    out.write_bytes(b"an earlier flight")
    port = free_udp_port()
    r = subprocess.run([sys.executable, "-m", "livesweep", "monitor", "--mavlink", f"udpin:127.0.0.1:{port}",
                        "--record", str(out), "--duration", "0.5"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and out.read_bytes() == b"an earlier flight"
    assert r.stderr.count("\n") == 1 and "exists" in r.stderr and "--force" in r.stderr
    r = subprocess.run([sys.executable, "-m", "livesweep", "monitor", "--mavlink", f"udpin:127.0.0.1:{port}",
                        "--record", str(out), "--duration", "0.5", "--force"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    assert read_summary(out).complete


def test_two_recorders_cannot_share_a_file(tmp_path):
    out = tmp_path / "one.mcap"
    first = McapRecorder(out)
    try:
        with pytest.raises(LogFormatError, match="exists"):
            McapRecorder(out)
        with pytest.raises(LogFormatError, match="another process is writing"):
            McapRecorder(out, overwrite=True)
    finally:
        first.close()
    assert read_summary(out).complete


@pytest.mark.slow
def test_a_missing_or_wrong_signing_key_file_is_one_line(tmp_path):
    port = free_udp_port()
    short = tmp_path / "short.key"
    short.write_bytes(b"x" * 7)
    for path, words in ((tmp_path / "absent.key", "cannot be read"), (short, "holds 7 bytes")):
        r = subprocess.run([sys.executable, "-m", "livesweep", "monitor", "--mavlink", f"udpin:127.0.0.1:{port}",
                            "--signing-key-file", str(path), "--duration", "0.2"], capture_output=True, text=True,
                           timeout=60)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and words in r.stderr and str(path) in r.stderr


@pytest.mark.slow
def test_crafted_json_on_zenoh_neither_stops_the_monitor_nor_its_replay(tmp_path):
    """A 400-digit integer in a signal and in the stamp, JSON nested 500 and 5 000 deep, a 5 000-digit
    integer, a bare array: each counted; the valid samples recorded, analysed and replayed."""
    import zenoh

    from livesweep.config import SignalSpec
    from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
    from livesweep.telemetry.replay import McapReplaySource
    from livesweep.telemetry.zenoh_io import ZenohSource, zenoh_config

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    src = ZenohSource("uav/**", listen_port=port, stamp_field="t")
    pub = zenoh.open(zenoh_config(connect=[port]))
    sigs = {n: SignalSpec(name=n, topic="/zenoh/uav/imu", field=n, stamp="t", stamp_scale=1.0) for n in ("u", "y")}
    st = MonitorSettings(signals=sigs, inputs=("u",), outputs=("y",), band_rad_s=(1.0, 20.0), window_s=20.0,
                         segment_s=5.0, sample_rate_hz=50.0)
    out = tmp_path / "zenoh.mcap"
    from livesweep.telemetry.recorder import McapRecorder

    pipe = MonitorPipeline(st, [src], recorder=McapRecorder(out))
    t = np.arange(0, 30, 0.02)
    u = np.sin(3 * t)
    def crafted(tk: float) -> list[bytes]:
        now = json.dumps(tk).encode()
        return [b'{"t": ' + now + b', "u": ' + b"9" * 400 + b', "y": 0}', b'{"t": ' + b"7" * 400 + b', "u": 1, "y": 1}',
                b'{"t": ' + now + b', "a": ' + b"[" * 500 + b"]" * 500 + b"}", b"[" * 5000 + b"]" * 5000,
                b'{"t": ' + now + b', "u": ' + b"1" * 5000 + b"}", b"[1, 2, 3]"]
    sent = 0
    try:
        time.sleep(0.5)
        for k in range(len(t)):
            pub.put("uav/imu", json.dumps({"t": float(t[k]), "u": float(u[k]), "y": float(0.5 * u[k])}),
                    congestion_control=zenoh.CongestionControl.BLOCK)     # the default DROP loses samples under load
            sent += 1
            if k % 300 == 150:
                for c in crafted(float(t[k])):
                    pub.put("uav/imu", c, congestion_control=zenoh.CongestionControl.BLOCK)
        deadline = time.monotonic() + 20
        pipe.run(stop=lambda: pipe.totals.frames >= sent + 2 or time.monotonic() > deadline)
    finally:
        pub.close()
    counts = pipe.summary()["counters"]["sources"][0]
    n_rounds = sum(1 for k in range(len(t)) if k % 300 == 150)
    assert counts["malformed"] == 3 * n_rounds            # 500 deep, 5 000 deep, 5 000 digits
    assert counts["non_object"] == 3 * n_rounds           # the bare array's three numbers
    assert counts["bad_stamp"] == n_rounds                # the 400-digit stamp
    assert pipe.aligner.counts["not_a_number"] >= n_rounds  # the 400-digit value
    recorded = read_summary(out)
    assert recorded.complete and recorded.message_counts["/zenoh/uav/imu"] == sent + 2 * n_rounds
    assert pipe.estimates and np.median(pipe.estimates[-1].coherence[0, 0]) > 0.9
    replay = MonitorPipeline(st, [McapReplaySource(out)])
    replay.run()
    assert replay.aligner.counts["not_a_number"] == pipe.aligner.counts["not_a_number"]
    assert replay.estimates[-1].t_s == pytest.approx(pipe.estimates[-1].t_s)


def test_replay_skips_and_counts_damaged_messages(tmp_path):
    """A recording with a JSON array, invalid JSON and JSON nested 5 000 deep among its messages
    (written with the standard mcap writer): the replay goes on, counts the three, and analyses
    every other message."""
    from mcap.writer import Writer

    from livesweep.config import SignalSpec
    from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
    from livesweep.telemetry.replay import McapReplaySource

    path = tmp_path / "damaged.mcap"
    t = np.arange(0, 40, 0.02)
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/x", "json", sid)
        for k, tk in enumerate(t):
            data = json.dumps({"t": tk, "u": np.sin(3 * tk), "y": 0.5 * np.sin(3 * tk)}).encode()
            w.add_message(cid, int(1e9 + tk * 1e9), data, int(1e9 + tk * 1e9))
            if k in (500, 1000, 1500):
                bad = {500: b"[1, 2]", 1000: b"{not json", 1500: b"[" * 5000 + b"]" * 5000}[k]
                w.add_message(cid, int(1e9 + tk * 1e9), bad, int(1e9 + tk * 1e9))
        w.finish()
    sigs = {n: SignalSpec(name=n, topic="/x", field=n, stamp="t", stamp_scale=1.0) for n in ("u", "y")}
    st = MonitorSettings(signals=sigs, inputs=("u",), outputs=("y",), band_rad_s=(1.0, 20.0), window_s=20.0,
                         segment_s=5.0)
    src = McapReplaySource(path)
    pipe = MonitorPipeline(st, [src])
    summary = pipe.run()
    assert src.counts["skipped_messages"] == 3
    assert summary["frames"] == len(t) and pipe.aligner.counts["samples"] == 2 * len(t)
    assert np.median(pipe.estimates[-1].coherence[0, 0]) > 0.99


@pytest.mark.slow
def test_slow_analysis_sheds_frames_but_the_recording_keeps_every_one(tmp_path):
    """A view that takes 50 ms per call stands for an analysis that cannot keep up: the frames it
    cannot take are skipped and counted, and every frame is still in the recording."""
    from livesweep.config import load_channel_map
    from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
    from livesweep.telemetry.mavlink_in import MavlinkSource

    class SlowView:
        def log_timeseries(self, *a, **k):
            time.sleep(0.05)

        def log_estimate(self, *a, **k):
            time.sleep(0.05)

        def log_alerts(self, *a, **k):
            pass

        def close(self):
            pass

    signals, _ = load_channel_map(Path(__file__).resolve().parents[1] / "config" / "xv15_channels.toml")
    st = MonitorSettings(signals=signals, inputs=("da",), outputs=("p",), band_rad_s=(1.0, 20.0), window_s=30.0,
                         segment_s=10.0)
    src = MavlinkSource("udpin:127.0.0.1:0")
    port = src.local_address[1]
    out = tmp_path / "slow.mcap"
    pipe = MonitorPipeline(st, [src], recorder=McapRecorder(out), view=SlowView(), queue_limit=500)
    v = Vehicle(1, None)
    frames = sim_stream(8, 40.0)
    done = []

    def stop():
        if not done:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                for i, (name, rec) in enumerate(frames):
                    s.sendto(v.pack(name, rec), ("127.0.0.1", port))
                    if i % 500 == 499:
                        time.sleep(0.02)
            done.append(time.monotonic())
        return time.monotonic() - done[0] > 1.0

    summary = pipe.run(stop=stop)
    assert sum(v for k, v in read_summary(out).message_counts.items() if k.startswith("/mavlink/")) == len(frames)
    assert summary["frames"] == len(frames)
    wanted = {signals[n].topic for n in ("da", "p")}               # what the analysis takes
    n_wanted = sum(1 for name, _ in frames if f"/mavlink/{name}" in wanted)
    n_other_topics = len({name for name, _ in frames if f"/mavlink/{name}" not in wanted})  # their first frames
    shed = summary["counters"]["pipeline"]["analysis_shed"]
    assert shed > 0 and summary["counters"]["pipeline"]["frames_analysed"] + shed == n_wanted + n_other_topics


def test_a_full_queue_keeps_the_test_point_evidence_in_order_and_counts_what_it_sheds():
    """Room for 4 of 10 frames: the two STATUSTEXTs are kept whatever the room, the data frames up
    to what is left of it (the earliest ones), all in the order they came; the other 6 counted."""
    from livesweep.monitor.ingest import FrameQueue
    from livesweep.telemetry.frames import Frame

    q = FrameQueue(4, shed=True)
    topics = ["/mavlink/ATTITUDE"] * 3 + ["/mavlink/STATUSTEXT"] + ["/mavlink/ATTITUDE"] * 5 + ["/mavlink/STATUSTEXT"]
    frames = [Frame(t, k, None, {"k": k}) for k, t in enumerate(topics)]
    q.put(frames, keep=lambda topic: topic == "/mavlink/STATUSTEXT")
    got = q.get(0.0)
    assert [f.receive_ns for f in got] == [0, 1, 3, 9] and q.shed == 6


@pytest.mark.slow
def test_sigterm_during_a_zenoh_burst_records_every_sample_it_counted(tmp_path):
    """SIGTERM right after a burst of 100 000 Zenoh samples (real session on loopback): the monitor
    reads what was still in flight, records it, and every sample it counts as received is in the
    file or counted as not taken; nothing vanishes between the two."""
    import zenoh

    from livesweep.telemetry.recorder import COUNTERS_METADATA
    from livesweep.telemetry.zenoh_io import zenoh_config

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "burst.mcap"
    mon = subprocess.Popen([sys.executable, "-m", "livesweep", "monitor", "--zenoh", "uav/**", "--zenoh-listen",
                            str(port), "--record", str(out), "--no-status", "--no-markers"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert mon.stdout.readline().startswith(b"monitor: listening")
    pub = zenoh.open(zenoh_config(connect=[port]))
    n = 100_000
    try:
        time.sleep(1.0)
        for k in range(n):
            pub.put("uav/imu", json.dumps({"t": k * 0.001, "u": 0.1 * k}), congestion_control=zenoh.CongestionControl.BLOCK)
        mon.send_signal(signal.SIGTERM)
        _, stderr = mon.communicate(timeout=120)
    finally:
        pub.close()
        if mon.poll() is None:
            mon.kill()
    assert mon.returncode == 0, stderr.decode()
    s = read_summary(out)
    assert s.complete
    counters = s.metadata[COUNTERS_METADATA]
    (zsrc,) = json.loads(counters["sources"])
    pipe = json.loads(counters["pipeline"])
    received = zsrc["received"]["uav/imu"]
    recorded = s.message_counts["/zenoh/uav/imu"]
    assert received >= recorded                      # decoded, then recorded
    assert recorded + pipe["not_taken_at_stop"] + zsrc["dropped_queue_full"] == n    # every sample accounted for
