"""`livesweep sim --mavlink`: a real MAVLink 2 stream over UDP on 127.0.0.1, parsed by pymavlink."""

import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from livesweep.telemetry import mavlink_codec as codec  # sets MAVLINK20 before pymavlink loads
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.telemetry.sim_telemetry import mavlink_timeline

from pymavlink import mavutil  # noqa: E402

pytestmark = pytest.mark.slow                 # every test of this module takes over 1 s

ARGS = ["--omega-min", "1.0", "--omega-max", "10", "--duration", "13", "--repeat", "1", "--amplitude", "3",
        "--off-axis-rms", "0.2", "--seed", "9"]


class Receiver(threading.Thread):
    def __init__(self):
        super().__init__(daemon=True)
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:0")
        self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.port = self.conn.port.getsockname()[1]
        self.msgs, self.magic, self.stop = [], set(), threading.Event()

    def run(self):
        idle_since = None
        while True:
            m = self.conn.recv_match(blocking=True, timeout=0.2)
            if m is None:
                if self.stop.is_set():
                    idle_since = idle_since or time.monotonic()
                    if time.monotonic() - idle_since > 0.5:
                        return
                continue
            idle_since = None
            if m.get_type() != "BAD_DATA":
                self.magic.add(m.get_msgbuf()[0])
                self.msgs.append(m)


def test_sim_streams_valid_mavlink2_at_the_intended_rates():
    rx = Receiver()
    rx.start()
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "livesweep", "sim", *ARGS, "--mavlink",
                        f"udpout:127.0.0.1:{rx.port}", "--speed", "20"], capture_output=True, text=True, timeout=120)
    wall = time.monotonic() - t0
    rx.stop.set()
    rx.join(10)
    assert r.returncode == 0, r.stderr
    assert rx.magic == {0xFD}                       # every frame is MAVLink 2

    expected, _ = mavlink_timeline(simulate(sweep_scenario(
        "xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=1.0, omega_max_rad_s=10.0, duration_s=13.0,
        amplitudes={"da": 3.0}, off_axis_rms=0.2, seed=9)))
    by_type = {}
    for m in rx.msgs:
        by_type.setdefault(m.get_type(), []).append(m)
    for name in ("SERVO_OUTPUT_RAW", "HIGHRES_IMU", "ATTITUDE", "AOA_SSA"):
        want = [e.record for e in sorted(expected, key=lambda e: e.vehicle_time_ns) if e.msgname == name]
        got = [codec.record_from_message(m) for m in by_type[name]]
        assert len(got) == len(want), name         # no loss on loopback
        assert got == want, name                    # the same canonical records as the MCAP log holds
    # rates from the vehicle time stamps
    imu_dt = np.diff([m.time_usec for m in by_type["HIGHRES_IMU"]])
    att_dt = np.diff([m.time_boot_ms for m in by_type["ATTITUDE"]])
    servo_dt = np.diff([m.time_usec for m in by_type["SERVO_OUTPUT_RAW"]])
    assert set(imu_dt) == {10_000} and set(att_dt) == {20} and set(servo_dt) == {20_000}
    assert len(by_type["HEARTBEAT"]) >= 20            # ~1 Hz over 24 s of vehicle time
    # paced: 24 s of flight at 20x is >= 1.2 s of wall time (loose upper bound: a busy CI machine)
    duration = (by_type["HIGHRES_IMU"][-1].time_usec - by_type["HIGHRES_IMU"][0].time_usec) * 1e-6
    assert wall >= duration / 20
    assert "sent" in r.stdout


def test_mavlink_url_that_is_a_path_is_refused(tmp_path):
    r = subprocess.run([sys.executable, "-m", "livesweep", "sim", "--mavlink", str(tmp_path / "bin" / "x")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "livesweep: error:" in r.stderr
