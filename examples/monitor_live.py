"""The live monitor from Python: what ``livesweep monitor`` does, as a library call.

A simulated XV-15 aileron sweep is sent as MAVLink 2 over UDP loopback (as a vehicle or SITL would
send it) into ``livesweep.monitor()``, which runs in a background thread and records the session;
the script watches the operator's verdict while the sweep flies, then prints the closed test points.

    python examples/monitor_live.py [--speed 10] [--record live.mcap]

Against a real vehicle: ``livesweep.monitor("udpin:0.0.0.0:14550", map="ardupilot-copter-quad-x")``.
"""

import argparse
import threading
import time

import livesweep
from livesweep.monitor.session import map_settings
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.telemetry.mavlink_out import MavlinkSender, stream_records
from livesweep.telemetry.sim_telemetry import mavlink_timeline


def vehicle(port: int, speed: float) -> None:
    """The simulated vehicle: one aileron sweep, its telemetry sent to 127.0.0.1:``port``."""
    res = simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=0.5, omega_max_rad_s=20.0,
                                  duration_s=45.0, amplitudes={"da": 3.0}, off_axis_rms=0.3, seed=4))
    records, _ = mavlink_timeline(res)
    records.sort(key=lambda r: (r.vehicle_time_ns, r.msgname))
    tx = MavlinkSender(f"udpout:127.0.0.1:{port}")
    try:
        stream_records(tx, ((r.vehicle_time_ns * 1e-9, r.msgname, r.record) for r in records), speed=speed)
    finally:
        tx.close()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=10.0, help="the vehicle's pace, x real time (default 10)")
    ap.add_argument("--record", help="MCAP file to record (default: none)")
    args = ap.parse_args(argv)

    settings = map_settings(window_s=30.0, required_pairs=["p/da"])      # the packaged XV-15 map, a 30 s window
    with livesweep.monitor("udpin:127.0.0.1:0", settings, record=args.record, overwrite=True) as live:
        port = int(live.urls[0].rsplit(":", 1)[1])
        print(f"monitor listening on {live.urls[0]}")
        sender = threading.Thread(target=vehicle, args=(port, args.speed))
        sender.start()
        while sender.is_alive():
            sender.join(1.0)
            frames = sum(sum(s["received"].values()) for s in live.counters.get("sources", []))
            print(f"  {frames:6d} frames, verdict {live.verdict}")
        time.sleep(1.0)                                    # the last datagrams in flight
        summary = live.stop()
    for tp in live.test_points:                            # as the recording's /livesweep/test_point holds them
        print(f"test point: {tp['swept_input']} {tp['source']} {tp['start_s']:.1f}-{tp['end_s']:.1f} s: {tp['label']}")
    print(f"{summary['frames']} frames, {summary['estimates']} estimates over {summary['data_s']:.0f} s of data")
    print(f"verdict: {live.verdict}")
    return summary


if __name__ == "__main__":
    main()
