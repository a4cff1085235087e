"""One vehicle, chosen once: other systems on the link are recorded and named, and change no estimate.

The fuzz test runs the real ``livesweep monitor`` on real UDP (127.0.0.1) with two and three
vehicles whose messages arrive *before* the analysed vehicle's for every message type, and with
unsigned strangers when a signing key is set; the estimates it records must equal those of the
analysed vehicle alone on the link. The unit tests drive the chooser with frames.
"""

from __future__ import annotations

import hashlib
import signal
import socket
import time
from collections import Counter

import numpy as np
import pytest

from livesweep.config import SignalSpec
from livesweep.telemetry.align import GridAligner
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.mcap_log import read_messages
from livesweep.telemetry.vehicle_choice import CHOOSE_WITHIN_FRAMES, VehicleChooser
from test_monitor_hardening import Vehicle, free_udp_port, mavlink_counts, sim_stream, start_monitor

KEY = hashlib.sha256(b"livesweep vehicle choice key").digest()
HEARTBEAT = {"type": 1, "autopilot": 3, "base_mode": 0, "custom_mode": 0, "system_status": 4, "mavlink_version": 3}
GCS_HEARTBEAT = {**HEARTBEAT, "type": 6, "autopilot": 8}


def _datagrams(scenario: str, v1: Vehicle, stream1) -> list[bytes]:
    """The link of one scenario: vehicle 1's HEARTBEAT and stream, and the others' frames."""
    out = [v1.pack("HEARTBEAT", {**HEARTBEAT, "sysid": 1, "compid": 1})]
    others = []
    if scenario in ("two", "three"):
        for sysid, seed in ((2, 6), (3, 7))[: 1 if scenario == "two" else 2]:
            others.append((Vehicle(sysid, None), [(n, {**r, "sysid": sysid}) for n, r in sim_stream(seed, 30.0)]))
    elif scenario == "unsigned":
        stranger = Vehicle(99, None)                      # unsigned: the monitor has a key
        out.insert(0, stranger.pack("HEARTBEAT", {**HEARTBEAT, "sysid": 99, "compid": 1}))
        first = {}
        for n, r in stream1:
            first.setdefault(n, r)
        for _ in range(3):
            out += [stranger.pack(n, {**r, "sysid": 99}) for n, r in first.items()]
    # every other vehicle's first message of each type goes before vehicle 1's
    for veh, stream in others:
        seen = set()
        for n, r in stream:
            if n not in seen:
                seen.add(n)
                out.append(veh.pack(n, r))
        veh.rest = [(n, r) for n, r in stream]
        veh.sent_first = seen
    if others:
        out += [o[0].pack("HEARTBEAT", {**HEARTBEAT, "sysid": o[0].mav.srcSystem, "compid": 1}) for o in others]
    iters = [iter(o[1]) for o in others]
    for k, (n, r) in enumerate(stream1):
        out.append(v1.pack(n, r))
        for it, (veh, _) in zip(iters, others):
            nxt = next(it, None)
            if nxt is not None:
                out.append(veh.pack(*nxt))
    return out


def _run(tmp_path, scenario: str, stream1) -> tuple[list[dict], str, Counter]:
    signed = scenario == "unsigned"
    out = tmp_path / f"{scenario}.mcap"
    port = free_udp_port()
    args = ["--mavlink", f"udpin:127.0.0.1:{port}", "--record", str(out), "--window", "20",
            "--update-period", "1"]
    if signed:
        key_file = tmp_path / "key.bin"
        key_file.write_bytes(KEY)
        args += ["--signing-key-file", str(key_file)]
    mon = start_monitor(args)
    v1 = Vehicle(1, KEY if signed else None)
    datagrams = _datagrams(scenario, v1, stream1)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            t0 = time.monotonic()
            for i, d in enumerate(datagrams):            # about 5 000 datagrams/s
                s.sendto(d, ("127.0.0.1", port))
                if i % 250 == 249:
                    time.sleep(max(0.0, t0 + (i + 1) / 5000 - time.monotonic()))
        time.sleep(1.0)
        mon.send_signal(signal.SIGTERM)
        stdout, stderr = mon.communicate(timeout=120)
    finally:
        if mon.poll() is None:
            mon.kill()
    assert mon.returncode == 0, stderr.decode()
    estimates = [m.data for m in read_messages(out, topics="/livesweep/estimate")]
    alerts = [m.data["message"] for m in read_messages(out, topics="/livesweep/alert")]
    return estimates, "\n".join(alerts), mavlink_counts(out)


@pytest.mark.slow
def test_other_vehicles_and_unsigned_strangers_change_no_estimate(tmp_path):
    stream1 = sim_stream(5, 30.0)
    alone, _, _ = _run(tmp_path, "alone", stream1)
    assert len(alone) >= 5
    for scenario in ("two", "three", "unsigned"):
        got, alerts, recorded = _run(tmp_path, scenario, stream1)
        assert len(got) == len(alone), scenario
        for a, b in zip(alone, got):
            assert a["t_s"] == pytest.approx(b["t_s"], abs=1e-9), scenario
            assert a["n_segments"] == b["n_segments"], scenario
            for pa, pb in zip(a["pairs"], b["pairs"]):
                assert pa["name"] == pb["name"]
                for key in ("coherence", "magnitude_db", "phase_deg"):
                    np.testing.assert_allclose(np.asarray(pb[key], float), np.asarray(pa[key], float),
                                               rtol=1e-9, atol=1e-9, err_msg=f"{scenario} {pa['name']} {key}")
        systems = {sy for (_, sy) in recorded}
        if scenario == "unsigned":
            assert systems == {1}                        # the unsigned frames are refused (and counted)
        else:
            assert systems == {1, 2} if scenario == "two" else systems == {1, 2, 3}   # recorded, all of them
            named = [line for line in alerts.splitlines() if "another system on the link" in line]
            assert named and all("follows system 1" in line for line in named), alerts
            assert set("".join(named).split("system id ")[1].split(")")[0].split(", ")) == \
                {str(s) for s in systems - {1}}


# ----------------------------------------------------------------------------- the chooser itself


def _frames(sysid: int, topics, t0_s: float, n: int, rate_hz: float = 50.0, **extra) -> list[Frame]:
    return [Frame(t, int((t0_s + k / rate_hz) * 1e9), None, {"sysid": sysid, "compid": 1, "x": float(k), **extra})
            for k in range(n) for t in topics]


def test_a_ground_station_is_never_chosen_and_a_heartbeat_orders_the_vehicles():
    topics = ("/mavlink/A", "/mavlink/B")
    ch = VehicleChooser(topics)
    gcs = [Frame("/mavlink/HEARTBEAT", 0, None, {"sysid": 255, "compid": 190, **GCS_HEARTBEAT})]
    hb = [Frame("/mavlink/HEARTBEAT", int(0.05e9), None, {"sysid": 4, "compid": 1, **HEARTBEAT})]
    frames = gcs + _frames(255, topics, 0.0, 100) + hb + _frames(7, topics, 0.1, 100) + _frames(4, topics, 0.2, 100)
    frames.sort(key=lambda f: f.receive_ns)
    got = None
    for f in frames:
        got = ch.push(f)
        if got is not None:
            break
    # system 7 sent first and qualified first, but 4 said HEARTBEAT first: 4 is waited for and chosen
    assert got == (4, {"/mavlink/A": 1, "/mavlink/B": 1})
    assert f.receive_ns * 1e-9 == pytest.approx(0.2 + 9 / 50, abs=0.001)      # its tenth frame of each


def test_a_vehicle_that_never_sends_a_mapped_message_is_followed_after_the_wait():
    topics = ("/mavlink/A", "/mavlink/B")
    ch = VehicleChooser(topics)
    got = None
    for f in _frames(3, topics[:1], 0.0, 2_100) + _frames(5, topics, 0.0, 2):
        got = got or ch.push(f)
    assert got == (3, {"/mavlink/A": 1})             # the most mapped types, then the most frames
    assert "sent the most" in ch.reason
    assert len(ch.held) >= CHOOSE_WITHIN_FRAMES


def test_a_stream_without_system_ids_is_taken_at_once():
    spec = {"a": SignalSpec("a", "/zenoh/a", "x")}
    al = GridAligner(spec, ["a"], 50.0)
    for k in range(100):
        al.push(Frame("/zenoh/a", int(k * 0.02e9), None, {"x": float(k)}))
    assert al.system is None and al.counts["frames_used"] == 100
