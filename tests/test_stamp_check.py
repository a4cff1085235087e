"""A vehicle's genuine stamps are never called implausible; stamps no clock of it has still are.

Real tlogs from ``../shared/data`` (an ArduPilot autotest flight with a reboot, a VTOL SITL run whose
clock steps back) and a 72-minute uptime built with pymavlink (a uint32 ``time_usec`` past its wrap,
UNIX-time GPS_RAW_INT, SYSTEM_TIME, a uint64 boot clock) go through the decoder the monitor and
the recorder use.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from livesweep.telemetry.clock import StampCheck
from livesweep.telemetry.mavlink_in import MavlinkDecoder, TlogSource
from test_monitor_hardening import Vehicle

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
if not DATA.is_dir():
    DATA = Path("/work/shared/data")
TLOGS = DATA / "mavlink_tlog"


@pytest.mark.parametrize("name", [pytest.param("uavlogviewer_autotest_flight_logs.tlog", marks=pytest.mark.slow),
                                  "uavlogviewer_vtol_sitl.tlog"])
def test_the_shared_tlogs_have_no_implausible_stamp(name):
    path = TLOGS / name
    if not path.is_file():
        pytest.skip(f"{path} not present")
    src = TlogSource(path)
    stamped = {}
    while not src.finished:
        for f in src.poll(max_frames=20_000):
            if f.topic in ("/mavlink/GPS_RAW_INT", "/mavlink/SYSTEM_TIME", "/mavlink/SERVO_OUTPUT_RAW"):
                n, with_time = stamped.get(f.topic, (0, 0))
                stamped[f.topic] = (n + 1, with_time + (f.vehicle_ns is not None))
    assert src.counts["clock_implausible"] == 0 and src.counts["clock_unrepresentable"] == 0
    assert set(stamped) == {"/mavlink/GPS_RAW_INT", "/mavlink/SYSTEM_TIME", "/mavlink/SERVO_OUTPUT_RAW"}
    for topic, (n, with_time) in stamped.items():
        assert n > 500 and with_time == n, topic          # each carries the vehicle's own time


UPTIME_S = 72 * 60                 # past the uint32 time_usec wrap (71.58 min)
UNIX_US = 1_764_300_000 * 10**6    # the GPS's calendar time


def _uptime_stream(seconds: float, rate_hz: float = 10.0):
    """(receive ns, message, record) of a vehicle booted UPTIME_S ago, for ``seconds``."""
    out = []
    rx0 = 1_800_000_000 * 10**9
    for k in range(int(seconds * rate_hz)):
        boot_us = (UPTIME_S - 30) * 10**6 + int(k * 1e6 / rate_hz)       # crosses 2**32 us about 24 s in
        rx = rx0 + int(k * 1e9 / rate_hz)
        out.append((rx, "SERVO_OUTPUT_RAW", {"time_usec": boot_us % 2**32, "port": 0,
                                             **{f"servo{i}_raw": 1500 for i in range(1, 17)}}))
        out.append((rx, "HIGHRES_IMU", {"time_usec": boot_us, **{f: 0.0 for f in (
            "xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "xmag", "ymag", "zmag", "abs_pressure",
            "diff_pressure", "pressure_alt", "temperature")}, "fields_updated": 0, "id": 0}))
        out.append((rx, "SYSTEM_TIME", {"time_unix_usec": UNIX_US + boot_us, "time_boot_ms": boot_us // 1000}))
        gps_time = 0 if k < 20 else UNIX_US + boot_us                    # no fix at first: 0, then UNIX time
        out.append((rx, "GPS_RAW_INT", {"time_usec": gps_time, "fix_type": 3, "lat": 0, "lon": 0, "alt": 0,
                                        "eph": 0, "epv": 0, "vel": 0, "cog": 0, "satellites_visible": 9,
                                        "alt_ellipsoid": 0, "h_acc": 0, "v_acc": 0, "vel_acc": 0, "hdg_acc": 0,
                                        "yaw": 0}))
    return out


def test_a_72_minute_uptime_and_a_uint32_wrap_are_genuine_but_poison_is_not():
    veh = Vehicle(1, None)
    dec = MavlinkDecoder(None, True, live=True)
    frames = []
    stream = _uptime_stream(60.0)
    wrapped = [r["time_usec"] for _, n, r in stream if n == "SERVO_OUTPUT_RAW"]
    assert max(wrapped) > 2**32 - 10**6 and min(wrapped) < 30 * 10**6        # the stream does wrap
    for rx, name, rec in stream:
        dec.datagram(veh.pack(name, {"sysid": 1, "compid": 1, **rec}), rx, frames)
    assert dec.counts["clock_implausible"] == 0 and dec.counts["clock_unrepresentable"] == 0
    assert len(frames) == len(stream)
    # stamps no clock of this vehicle has: the top of a uint32, 116 days on a boot clock
    rx = stream[-1][0] + 10**8
    poison = [("SERVO_OUTPUT_RAW", {**stream[-4][2], "time_usec": 2**32 - 1}),
              ("HIGHRES_IMU", {**stream[-3][2], "time_usec": stream[-3][2]["time_usec"] + 116 * 86_400 * 10**6})]
    for name, rec in poison:
        dec.datagram(veh.pack(name, {"sysid": 1, "compid": 1, **rec}), rx, frames)
    assert dec.counts["clock_implausible"] == 2
    assert frames[-1].vehicle_ns is None and frames[-2].vehicle_ns is None     # recorded, on receive time


def test_stamps_ahead_of_every_epoch_start_a_new_one_only_when_they_agree():
    c = StampCheck(confirm=3)
    rx = 10**18
    assert all(c.check(10**9 + k * 10**7, rx + k * 10**7) for k in range(100))      # one second of boot clock
    rx += 10**9
    assert c.check(5 * 10**8, rx)                  # a reboot: back to 0.5 s, a new epoch
    assert c.check(2 * 10**9 + 10**7, rx + 10**7)  # the old epoch goes on too (reordered frames)
    far = 10**9 * 3600 * 24 * 30                   # a month ahead of both
    assert not c.check(far, rx + 2 * 10**7)
    assert not c.check(far + 10**7, rx + 3 * 10**7)
    assert not c.check(far + 2 * 10**7, rx + 4 * 10**7)    # the third that agrees starts the epoch ...
    assert c.check(far + 3 * 10**7, rx + 5 * 10**7)        # ... so the stream's clock moved on


def test_signed_frames_refused_on_the_way_are_no_sequence_gap_but_a_lost_frame_is():
    """A signed stream where some genuine frames are refused (their signing time stamp is not newer:
    a replay) and one frame never arrives: the refused ones arrived, so only the missing one is a
    gap of the 8-bit sequence."""
    import hashlib

    key = hashlib.sha256(b"livesweep seq key").digest()
    veh = Vehicle(1, key)
    dec = MavlinkDecoder(key, False, live=True)
    frames = []
    rx = 1_800_000_000 * 10**9
    rec = {"sysid": 1, "compid": 1, **_uptime_stream(0.1)[1][2]}          # a HIGHRES_IMU
    refused = lost = 0
    for k in range(200):
        rec = {**rec, "time_usec": rec["time_usec"] + 10_000}
        if k % 20 == 10:                                                     # its stamp is not newer: a replay
            saved = veh.mav.signing.timestamp
            veh.mav.signing.timestamp = saved - 1_000
            d = veh.pack("HIGHRES_IMU", rec)
            veh.mav.signing.timestamp = saved + 1
            refused += 1
        else:
            d = veh.pack("HIGHRES_IMU", rec)
        if k == 155:
            lost += 1                                                        # never arrives
            continue
        dec.datagram(d, rx + k * 10**7, frames)
    assert dec.counts["replayed_signature"] == refused == 10
    assert len(frames) == 200 - refused - lost
    assert dec.counts["seq_gaps"] == {"1/1": 1}
