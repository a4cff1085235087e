"""Test points: the monitor opens, judges and closes them from what the flight shows, never from a
sliding window alone.

Independent references: the simulator's own sweep schedule (``SimResult.segments`` and the sweep
generator's instantaneous frequency), ArduPilot's own SystemID messages and logged chirp frequency
(``SIDD.F``) in the shared SITL DataFlash log, and the verdict criteria of method.md §2.5.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from livesweep.config import SignalSpec, load_channel_map
from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
from livesweep.monitor import testpoints
from livesweep.sim.inputs import FrequencySweep
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.replay import McapReplaySource
from livesweep.telemetry.sim_telemetry import mavlink_timeline

ROOT = Path(__file__).resolve().parents[1]
SIGNALS, _ = load_channel_map(ROOT / "config" / "xv15_channels.toml")
XV15 = MonitorSettings(signals=SIGNALS, inputs=("da", "dr"), outputs=("p", "r", "ay"), band_rad_s=(0.3, 20.0),
                       sample_rate_hz=50.0, window_s=120.0)


def shared_data() -> Path:
    for base in (ROOT.parent / "shared" / "data", Path("/work/shared/data")):
        if base.is_dir():
            return base
    pytest.skip("../shared/data is absent")


class ListSource:
    """Frames from a list, a few thousand per poll (a file's pace)."""

    def __init__(self, frames):
        self.frames, self.finished, self.counts = list(frames), False, {}

    def poll(self, timeout_s=0.05, max_frames=2_000):
        out, self.frames = self.frames[:max_frames], self.frames[max_frames:]
        self.finished = not self.frames
        return out

    def close(self):
        pass


def sim_frames(seed: int, duration_s: float = 100.0, sysid: int = 1, axes=("da",)):
    res = simulate(sweep_scenario("xv15-cruise", axes=axes, repeats=1, omega_min_rad_s=0.3, omega_max_rad_s=20.0,
                                  duration_s=duration_s, amplitudes={a: 3.0 for a in axes}, off_axis_rms=0.2,
                                  seed=seed))
    recs, _ = mavlink_timeline(res)
    recs.sort(key=lambda r: (r.vehicle_time_ns, r.msgname))
    frames = [Frame(f"/mavlink/{r.msgname}", r.log_time_ns, r.vehicle_time_ns, {**r.record, "sysid": sysid})
              for r in recs]
    return res, frames


def run(frames, settings=XV15):
    pipe = MonitorPipeline(settings, [ListSource(frames)], keep_estimates=False)
    return pipe, pipe.run()


def sweep_times(res):
    seg = next(s for s in res.segments if s.kind == "sweep")
    p = seg.parameters
    start = seg.start_s + p["trim_s"]
    return seg, start, start + p["duration_s"]


@pytest.mark.slow
def test_a_sweep_found_by_its_oscillation_is_go_and_a_third_of_it_no_go_naming_what_is_missing():
    res, frames = sim_frames(seed=21)
    seg, t0, t1 = sweep_times(res)
    pipe, s = run(frames)
    (tp,) = s["test_points"]
    assert tp["source"] == "sweep" and tp["swept_input"] == "da"
    assert abs(tp["start_s"] - t0) <= 2.0 and abs(tp["end_s"] - t1) <= 3.0
    assert tp["verdict"] == "GO" and s["verdict"] == "GO"
    (pair,) = tp["pairs"]
    assert (pair["output"], pair["input"], pair["coherence"]) == ("p", "da", "ordinary") and pair["adequate_fraction"] >= 0.6

    cut = t0 + seg.parameters["duration_s"] / 3                 # the sweep stops a third of the way through
    third = [f for f in frames if f.vehicle_ns is None or f.vehicle_ns * 1e-9 < cut]
    pipe, s = run(third)
    (tp,) = s["test_points"]
    assert tp["verdict"] == "NO-GO" and s["verdict"] == "NO-GO"
    sweep = FrequencySweep(omega_min_rad_s=0.3, omega_max_rad_s=20.0, duration_s=seg.parameters["duration_s"],
                       amplitude=3.0, trim_s=seg.parameters["trim_s"])
    w_cut = float(sweep.omega(seg.parameters["duration_s"] / 3))   # how far the sweep got [rad/s]
    gap = next(m for m in tp["missing"] if m.startswith("da needs a sweep over"))
    top_gap = gap.split("over ")[1].split(" rad/s")[0].split(", ")[-1]     # the stretch up to the band's top
    lo, hi = (float(x) for x in top_gap.split("-"))
    # the unswept band starts where the sweep stopped: the frequency of its last half-period (its
    # midpoint lies a quarter period before the cut, where the sweep was slower by exp(rate d/2) < 1.1)
    assert hi == pytest.approx(20.0) and 0.85 * w_cut <= lo <= 1.05 * w_cut, (gap, w_cut)
    assert "it oscillated over" in gap


@pytest.mark.slow
def test_telemetry_lost_after_the_sweep_ended_keeps_its_verdict_and_lost_during_it_is_no_go():
    """The link drops 3 s into the trim after the sweep (before the 5 quiet seconds that end a
    detected sweep): the sweep was over, so it is judged on what it holds (GO, ending where the
    simulator's sweep ended). Dropped two thirds of the way through the sweep: NO-GO, telemetry lost."""
    res, frames = sim_frames(seed=21)
    seg, t0, t1 = sweep_times(res)

    def lost_at(cut_s):
        kept = [f for f in frames if f.vehicle_ns is None or f.vehicle_ns * 1e-9 < cut_s]
        rx = max(f.receive_ns for f in kept) + int(testpoints.LOST_AFTER_S * 1e9)
        return kept + [Frame(testpoints.LOST_TOPIC, rx, None, {"silent_s": testpoints.LOST_AFTER_S, "sysid": 1})]

    _, s = run(lost_at(t1 + 3.0))
    (tp,) = s["test_points"]
    assert tp["verdict"] == "GO" and abs(tp["end_s"] - t1) <= 3.0, tp
    assert "da quiet for" in tp["end_note"] and "telemetry lost" in tp["end_note"]
    assert not any("telemetry lost" in m for m in tp["missing"])

    _, s = run(lost_at(t0 + 2 * (t1 - t0) / 3))
    (tp,) = s["test_points"]
    assert tp["verdict"] == "NO-GO" and any("telemetry lost" in m for m in tp["missing"]), tp


@pytest.mark.slow
def test_no_test_point_and_no_go_from_doublets_or_a_spool_up_ramp():
    """What a sliding window called GO on a real stream: a trim ramp (a motor spooling up) and
    short pilot inputs. Neither opens a test point; the verdict stays WAIT."""
    pipe, s = run(list(McapReplaySource(ROOT / "replay_logs" / "xv15_cruise_verify.mcap").poll(max_frames=10**6)))
    assert s["test_points"] == [] and s["verdict"] == "WAIT" and pipe.test_points.ignored >= 1
    res, frames = sim_frames(seed=22)
    seg, t0, _ = sweep_times(res)
    ramp = []
    for f in frames:                                           # da: the sweep replaced by a slow ramp
        t = f.vehicle_ns * 1e-9 if f.vehicle_ns is not None else 0.0
        if f.topic == "/mavlink/SERVO_OUTPUT_RAW":
            f = Frame(f.topic, f.receive_ns, f.vehicle_ns, {**f.data, "servo1_raw": int(1500 + 4 * max(t - t0, 0.0))})
        ramp.append(f)
    pipe, s = run([f for f in ramp if f.vehicle_ns is None or f.vehicle_ns * 1e-9 < t0 + 60])
    assert s["test_points"] == [] and s["verdict"] == "WAIT"


def test_markers_open_and_close_test_points_on_the_data_clock():
    tracker = testpoints.TestPointTracker(("da", "dr", "p"), ("da", "dr"), ("p",), 50.0, (0.3, 20.0))
    f = lambda topic, data: Frame(topic, 0, None, data)               # noqa: E731
    cases = [
        (f(testpoints.MARKER_TOPIC, {"action": "start", "input": "dr"}), ("start", "marker", "dr")),
        (f(testpoints.MARKER_TOPIC, {"action": "end"}), ("end", "marker", None)),
        (f("/zenoh/gcs/marker", {"action": "start", "input": "da"}), ("start", "marker", "da")),
        (f("/mavlink/STATUSTEXT", {"sysid": 1, "text": "livesweep start dr"}), ("start", "marker", "dr")),
        (f("/mavlink/STATUSTEXT", {"sysid": 1, "text": "LIVESWEEP: end"}), ("end", "marker", None)),
        (f("/mavlink/NAMED_VALUE_INT", {"sysid": 1, "name": "LS_TP", "value": 1}), ("start", "marker", "da")),
        (f("/mavlink/NAMED_VALUE_INT", {"sysid": 1, "name": "LS_TP", "value": 0}), ("end", "marker", None)),
        (f("/mavlink/STATUSTEXT", {"sysid": 2, "text": "livesweep start dr"}), None),       # another vehicle
        # the operator's ground station: system 255 by convention, or any system whose HEARTBEAT is a GCS
        (f("/mavlink/NAMED_VALUE_INT", {"sysid": 255, "name": "LS_TP", "value": 2}), ("start", "marker", "dr")),
        (f("/mavlink/STATUSTEXT", {"sysid": 255, "text": "livesweep end"}), ("end", "marker", None)),
        (f("/mavlink/STATUSTEXT", {"sysid": 255, "text": "SystemID Starting: axis=7"}), None),  # not its say
        (f("/mavlink/NAMED_VALUE_INT", {"sysid": 250, "name": "LS_TP", "value": 1}), None),
        (f("/mavlink/HEARTBEAT", {"sysid": 250, "type": 6, "autopilot": 8}), None),
        (f("/mavlink/NAMED_VALUE_INT", {"sysid": 250, "name": "LS_TP", "value": 1}), ("start", "marker", "da")),
        (f("/mavlink/STATUSTEXT", {"sysid": 1, "text": "PreArm: Gyros not calibrated"}), None),
    ]
    for frame, want in cases:
        assert tracker.wants(frame.topic)
        evs = tracker.events_of(frame, 12.5, system=1)
        got = None if not evs else (evs[0].action, evs[0].source, evs[0].swept_input)
        assert got == want, frame
        assert all(e.t_s == 12.5 for e in evs)


@pytest.mark.slow
def test_a_second_vehicle_on_the_link_changes_no_test_point():
    """Vehicle 2 flies its own sweep (another seed, another time) and says "SystemID Finished" in the
    middle of vehicle 1's sweep: the test points are vehicle 1's, as without vehicle 2."""
    res1, one = sim_frames(seed=23, sysid=1)
    _, two = sim_frames(seed=24, sysid=2, axes=("dr",))
    shift = 37 * 10**9
    two = [Frame(f.topic, f.receive_ns + shift, None if f.vehicle_ns is None else f.vehicle_ns + shift, f.data)
           for f in two]
    _, t0, _ = sweep_times(res1)
    noise = Frame("/mavlink/STATUSTEXT", int((t0 + 40) * 1e9), None, {"sysid": 2, "compid": 1, "severity": 6,
                                                                       "text": "SystemID Finished"})
    alone = run(one)[1]["test_points"]
    both = run(sorted(one + two + [noise], key=lambda f: f.receive_ns))[1]["test_points"]
    assert len(alone) == 1 and both == alone


# ----------------------------------------------------------------------------- a real autopilot


AXES = {1: "roll", 4: "roll", 7: "roll", 10: "roll", 2: "pitch", 5: "pitch", 8: "pitch", 11: "pitch",
        3: "yaw", 6: "yaw", 9: "yaw", 12: "yaw"}


@pytest.fixture(scope="module")
def sid7(tmp_path_factory):
    from livesweep.convert import convert

    out = tmp_path_factory.mktemp("sid") / "sid7.mcap"
    convert(shared_data() / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin", out)
    return out


def dataflash_settings():
    s = lambda n, f: SignalSpec(name=n, topic="/dataflash/RATE", field=f, stamp="TimeUS", stamp_scale=1e-6)  # noqa
    signals = {"roll": s("roll", "RDes"), "pitch": s("pitch", "PDes"), "yaw": s("yaw", "YDes"),
               "p": s("p", "R"), "q": s("q", "P"), "r": s("r", "Y")}
    tp = SimpleNamespace(sources=("autopilot", "marker", "sweep"), axes=AXES, min_duration_s=10.0,
                         required={"roll": ("p",), "pitch": ("q",), "yaw": ("r",)})
    return MonitorSettings(signals=signals, inputs=("roll", "pitch", "yaw"), outputs=("p", "q", "r"),
                           band_rad_s=(3.0, 60.0), sample_rate_hz=200.0, window_s=60.0, test_points=tp)


@pytest.mark.slow
def test_arducopter_systemid_opens_and_closes_the_test_point_and_judges_it(sid7):
    """ArduCopter 4.4 SITL, SystemID axis 7 (rate roll), chirp 0.5-12 Hz: the test point runs from
    "SystemID Starting: axis=7" to "SystemID Finished" (MSG), sweeps roll, and is GO; the same log cut
    a third of the way through the chirp is NO-GO and names the band the chirp never reached."""
    from livesweep.telemetry.mcap_log import read_fields, read_messages

    msgs = [(m.publish_time_ns * 1e-9, m.data["Message"]) for m in read_messages(sid7, topics="/dataflash/MSG")]
    t_start = next(t for t, text in msgs if text == "SystemID Starting: axis=7")
    t_end = next(t for t, text in msgs if text == "SystemID Finished" and t > t_start)
    pipe = MonitorPipeline(dataflash_settings(), [McapReplaySource(sid7)], keep_estimates=False)
    s = pipe.run()
    tp = s["test_points"][0]
    assert (tp["source"], tp["swept_input"]) == ("autopilot", "roll")
    assert abs(tp["start_s"] - t_start) < 0.05 and abs(tp["end_s"] - t_end) < 0.05
    assert tp["verdict"] == "GO" and tp["pairs"][0]["adequate_fraction"] >= 0.6
    # the filtered log holds RATE only around axis 7: the later SystemID runs have no data, and say so
    assert all(r["verdict"] == "NO-GO" and r["pairs"] == [] for r in s["test_points"][1:])
    # no GO before the injection: every verdict change before the start is WAIT
    assert s["counters"]["aligner"]["samples"] > 0

    sidd = read_fields(sid7, "/dataflash/SIDD", ["F", "TimeUS"])
    t_cut = t_start + (t_end - t_start) / 3
    f_cut_rad_s = 2 * math.pi * float(np.interp(t_cut, sidd["TimeUS"] * 1e-6, sidd["F"]))   # the chirp's own frequency

    class Cut(McapReplaySource):
        def poll(self, timeout_s=0.05, max_frames=10_000):
            return [f for f in super().poll(timeout_s, max_frames) if f.data.get("TimeUS", 0) * 1e-6 < t_cut]

    s = MonitorPipeline(dataflash_settings(), [Cut(sid7)], keep_estimates=False).run()
    tp = s["test_points"][0]
    assert tp["verdict"] == "NO-GO"
    gap = next(m for m in tp["missing"] if m.startswith("roll needs a sweep over"))
    lo = float(gap.split("over ")[1].split("-")[0])
    # blurred by the comparison window (the 5 s of loiter logged before the chirp: 2 pi / 5 s bins)
    bins = 2 * math.pi / 5.0
    assert f_cut_rad_s - bins <= lo <= f_cut_rad_s + 3 * bins, (gap, f_cut_rad_s)


@pytest.mark.slow
def test_telemetry_lost_after_the_autopilots_chirp_ended_is_judged_on_what_it_holds(sid7):
    """The link drops right after ArduPilot's chirp has faded out, before "SystemID Finished": the
    test point ends where the chirp ended (ArduPilot's own SIDD log: its last sample of the chirp)
    and is judged GO; the same link dropped 5 s before the chirp's end is NO-GO, telemetry lost."""
    from livesweep.telemetry.mcap_log import read_fields

    sidd = read_fields(sid7, "/dataflash/SIDD", ["Targ", "TimeUS"])
    chirp_end = float(sidd["TimeUS"][np.nonzero(sidd["Targ"])[0][-1]]) * 1e-6

    def dropped_at(t_drop):
        class Dropped(McapReplaySource):
            last_rx = 0

            def poll(self, timeout_s=0.05, max_frames=10_000):
                out = [f for f in super().poll(timeout_s, max_frames)
                       if f.data.get("TimeUS", 0) * 1e-6 < t_drop and (f.vehicle_ns is None or f.vehicle_ns * 1e-9 < t_drop)]
                if out:
                    self.last_rx = max(self.last_rx, max(f.receive_ns for f in out))
                if self.finished:
                    out.append(Frame(testpoints.LOST_TOPIC, self.last_rx + int(testpoints.LOST_AFTER_S * 1e9), None,
                                     {"silent_s": testpoints.LOST_AFTER_S}))
                return out
        return MonitorPipeline(dataflash_settings(), [Dropped(sid7)], keep_estimates=False).run()["test_points"][0]

    tp = dropped_at(chirp_end + 0.2)
    assert tp["verdict"] == "GO" and abs(tp["end_s"] - chirp_end) < 0.1, tp
    assert "injection had ended" in tp["end_note"]
    tp = dropped_at(chirp_end - 5.0)
    assert tp["verdict"] == "NO-GO" and any("telemetry lost" in m for m in tp["missing"]), tp


@pytest.mark.slow
def test_terminal_markers_reach_the_recording_and_open_a_test_point(tmp_path):
    """The monitor command with --markers: lines typed on its standard input open and close a test
    point over a simulated sweep streamed over UDP, and are in the recording for a replay."""
    import socket
    import subprocess
    import sys
    import time

    from livesweep.telemetry.mavlink_out import MavlinkSender
    from livesweep.telemetry.mcap_log import read_messages

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "markers.mcap"
    mon = subprocess.Popen([sys.executable, "-m", "livesweep", "monitor", "--mavlink", f"udpin:127.0.0.1:{port}",
                            "--record", str(out), "--markers", "--require", "p/dr"], stdin=subprocess.PIPE,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert mon.stdout.readline().startswith("monitor: listening")
    assert "markers" in mon.stdout.readline()
    res, frames = sim_frames(seed=25, duration_s=60.0, axes=("dr",))
    tx = MavlinkSender(f"udpout:127.0.0.1:{port}")
    t_first = frames[0].vehicle_ns * 1e-9
    started = ended = False
    t0 = time.monotonic()
    try:
        for f in frames:
            t = f.vehicle_ns * 1e-9
            while (t - t_first) / 20 > time.monotonic() - t0:      # 20x real time
                time.sleep(0.002)
            if not started and t > t_first + 5:
                mon.stdin.write("s dr\n"), mon.stdin.flush()
                started = True
            if not ended and t > t_first + 70:
                mon.stdin.write("e\n"), mon.stdin.flush()
                ended = True
            tx.send_record(f.topic.split("/")[-1], f.data)
        time.sleep(0.5)
    finally:
        tx.close()
        mon.send_signal(2)
        stdout, stderr = mon.communicate(timeout=60)
    assert mon.returncode == 0, stderr
    marks = [m.data["action"] for m in read_messages(out, topics=testpoints.MARKER_TOPIC)]
    (tp,) = [m.data for m in read_messages(out, topics="/livesweep/test_point")]
    assert marks == ["start", "end"] and (tp["source"], tp["swept_input"]) == ("marker", "dr")
    assert 60 <= tp["end_s"] - tp["start_s"] <= 70 and tp["verdict"] == "GO"


def test_a_map_that_matches_nothing_says_which_signals_and_why():
    """The XV-15 map on a real ArduPilot stream (the shared QuadPlane tlog): every signal is named,
    with the topic it looked for and what the link carries instead."""
    from livesweep.telemetry.mavlink_in import TlogSource

    src = TlogSource(shared_data() / "mavlink_tlog" / "uavlogviewer_vtol_sitl.tlog")
    pipe = MonitorPipeline(XV15, [src], keep_estimates=False)
    s = pipe.run()
    assert s["estimates"] == 0
    topics = set(src.counts["received"])                   # what the tlog carries (its message types)
    absent = [n for n in pipe.names if XV15.signals[n].topic.split("/")[-1] not in topics]
    assert absent == ["p", "r", "ay"]                       # SERVO_OUTPUT_RAW is there, HIGHRES_IMU is not
    assert [line.split(":")[0] for line in s["map_problems"]] == [f"signal {n}" for n in absent]
    assert all("no frames on /mavlink/HIGHRES_IMU" in line and "/mavlink/ATTITUDE" in line
               for line in s["map_problems"])
