"""The live monitor on a real ArduPilot stream: ArduCopter 4.4 SITL SystemID, streamed over UDP.

The shared DataFlash log of a SystemID rate-roll chirp (``sid_axis7_rate_roll.bin``: QUAD/PLUS,
loiter, "SystemID Starting: axis=7" at TimeUS 78.57 s, "SystemID Finished" at 128.58 s) goes out
through ``livesweep stream`` as ArduCopter's own telemetry (ATTITUDE, PID_TUNING at a 50 Hz stream
rate, STATUSTEXT, HEARTBEAT) at 1x real time into ``livesweep monitor --map ardupilot-copter-pid``,
a real subprocess on a real UDP socket. That map times every signal by its receive time (PID_TUNING
carries no time field), so only 1x real time is faithful: the three runs share one minute.

Runs, concurrently:

* ``alone``: the loiter and the chirp (log seconds 30-98 after its first time stamp).
* ``second_vehicle``: the same stream, plus the pitch chirp of the other log sent as system 2 on
  the same port from one second later (its own clock, its own "SystemID Starting: axis=8").
* ``cut``: the stream stopped a third of the way through the chirp.

References the monitor did not make: the autopilot's own STATUSTEXT as received (the injection's
start and end), the chirp frequency ArduPilot logged (``SIDD.F``, read with pymavlink's
DFReader), and, for the second vehicle, the run without it. The two live runs differ by receive
jitter only, hence tolerances there; a replay of a recording is exact.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from livesweep.telemetry.mcap_log import read_messages

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
if not DATA.is_dir():
    DATA = Path("/work/shared/data")
SID7 = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
SID8 = DATA / "ardupilot_sitl_systemid" / "sid_axis8_rate_pitch.bin"
SRC_DIR = Path(__file__).resolve().parents[1] / "src"

START_S, END_S = 30.0, 98.0            # log seconds sent: 5 s of loiter before the chirp .. its fade-out
INJECTION_S = (78.571892, 128.58188)   # TimeUS of "SystemID Starting"/"Finished" [s]
LOG_T0_S = 43.384306                   # the log's first TimeUS [s]
CUT_END_S = INJECTION_S[0] + (INJECTION_S[1] - INJECTION_S[0]) / 3 - LOG_T0_S


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(SRC_DIR) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _livesweep(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "livesweep", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env())


def _monitor(out: Path) -> tuple[subprocess.Popen, int]:
    mon = _livesweep("monitor", "--mavlink", "udpin:127.0.0.1:0", "--map", "ardupilot-copter-pid",
                     "--record", str(out), "--no-status", "--no-markers")
    line = mon.stdout.readline()                     # "monitor: listening on mavlink udpin:127.0.0.1:PORT; ..."
    assert line.startswith("monitor: listening"), (line, mon.stderr.read() if mon.poll() is not None else "")
    port = int(line.split("udpin:127.0.0.1:")[1].split(";")[0].split()[0])
    return mon, port


def _stream(log: Path, port: int, start_s: float, end_s: float, *extra: str) -> subprocess.Popen:
    return _livesweep("stream", str(log), "--mavlink", f"udpout:127.0.0.1:{port}", "--start-s", f"{start_s:.6f}",
                      "--end-s", f"{end_s:.6f}", "--rate-hz", "50", *extra)


def _results(path: Path) -> dict:
    """What the recording says: test points, verdict changes, alerts and the autopilot's texts."""
    def data(topic):
        return [m.data for m in read_messages(path, topics=topic)]

    texts = [(m.log_time_ns * 1e-9, m.data) for m in read_messages(path, topics="/mavlink/STATUSTEXT")]
    return {"test_points": data("/livesweep/test_point"), "verdicts": data("/livesweep/verdict"),
            "alerts": data("/livesweep/alert"), "texts": texts,
            "estimate_verdicts": [(e["t_s"], e["verdict"], e["reasons"]) for e in data("/livesweep/estimate")],
            "tp_logged_ns": [m.log_time_ns for m in read_messages(path, topics="/livesweep/test_point")]}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    missing = [str(p) for p in (SID7, SID8) if not p.is_file()]
    if missing:
        pytest.skip(f"third-party log(s) not found: {', '.join(missing)}")
    tmp = tmp_path_factory.mktemp("live_ardupilot")
    names = ("alone", "second_vehicle", "cut")
    monitors = {n: _monitor(tmp / f"{n}.mcap") for n in names}
    streams = [_stream(SID7, monitors["alone"][1], START_S, END_S),
               _stream(SID7, monitors["second_vehicle"][1], START_S, END_S),
               _stream(SID7, monitors["cut"][1], START_S, CUT_END_S)]
    time.sleep(1.0)
    # the other vehicle: the pitch chirp of the second log (its TimeUS 103 s later), as system 2
    streams.append(_stream(SID8, monitors["second_vehicle"][1], START_S + 73.0, END_S + 72.0, "--sysid", "2"))
    summaries = {}
    try:
        for s in streams:
            out, err = s.communicate(timeout=180)
            assert s.returncode == 0, err
        time.sleep(1.5)                              # the last datagrams through the monitors
        for n, (mon, _) in monitors.items():
            mon.send_signal(signal.SIGINT)
            out, err = mon.communicate(timeout=60)
            assert mon.returncode == 0, err
            summaries[n] = out
    finally:
        for p in [*streams, *(m for m, _ in monitors.values())]:
            if p.poll() is None:
                p.kill()
    return {n: {**_results(tmp / f"{n}.mcap"), "summary": summaries[n], "path": tmp / f"{n}.mcap"} for n in names}


def _replay(path: Path, out: Path) -> dict:
    """What a replay of ``path`` with its recorded settings records (the library's own replay path)."""
    from livesweep.cli import _recorded_settings
    from livesweep.monitor.pipeline import MonitorPipeline
    from livesweep.telemetry.recorder import McapRecorder
    from livesweep.telemetry.replay import McapReplaySource

    MonitorPipeline(_recorded_settings(str(path)), [McapReplaySource(path)], recorder=McapRecorder(out)).run()
    return _results(out)


def _text_time(res: dict, text: str) -> float:
    return next(t for t, d in res["texts"] if d["text"] == text)


def test_the_chirp_is_one_test_point_from_the_autopilot_and_go_on_time(runs):
    """No GO before the injection starts; the test point spans the autopilot's SystemID run and is
    GO, recorded within 5 s of the injection's end."""
    res = runs["alone"]
    t_start, t_end = _text_time(res, "SystemID Starting: axis=7"), _text_time(res, "SystemID Finished")
    assert t_end - t_start == pytest.approx(INJECTION_S[1] - INJECTION_S[0], abs=0.25)   # sent at 1x
    (tp,) = res["test_points"]
    assert (tp["source"], tp["swept_input"], tp["verdict"]) == ("autopilot", "roll", "GO")
    # start and end on the receive clock of this map, at the texts' receipt
    assert abs(tp["start_s"] - t_start) < 0.1 and abs(tp["end_s"] - t_end) < 0.1
    (pair,) = tp["pairs"]
    assert (pair["output"], pair["input"], pair["coherence"]) == ("p", "roll", "ordinary")
    assert pair["adequate_fraction"] >= 0.6
    # the closed test point is in the recording within 5 s of the end of the injection
    assert res["tp_logged_ns"][0] * 1e-9 - t_end <= 5.0
    # no GO before the first injection; the verdict ends GO
    before = [v for v in res["verdicts"] if v["t_s"] < tp["start_s"]]
    assert before and all(v["verdict"] == "WAIT" for v in before)
    assert res["verdicts"][-1]["verdict"] == "GO"
    assert all(v["verdict"] != "NO-GO" for v in res["verdicts"])


def test_a_test_point_cut_to_a_third_is_no_go_and_names_the_band_never_swept(runs):
    """Stopped a third of the way into the chirp: NO-GO, and the band missing starts near the
    frequency ArduPilot's chirp had reached (its SIDD.F, read with pymavlink)."""
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(SID7), zero_time_base=True)
    t_us, f_hz = [], []
    while (m := r.recv_match(type="SIDD")) is not None:
        t_us.append(m.TimeUS), f_hz.append(m.F)
    f_cut = 2 * math.pi * float(np.interp((CUT_END_S + LOG_T0_S) * 1e6, t_us, f_hz))

    res = runs["cut"]
    (tp,) = res["test_points"]
    assert (tp["source"], tp["swept_input"], tp["verdict"]) == ("autopilot", "roll", "NO-GO")
    assert tp["duration_s"] == pytest.approx((INJECTION_S[1] - INJECTION_S[0]) / 3, abs=1.0)
    gap = next(m for m in tp["missing"] if m.startswith("roll needs a sweep over"))
    lo, hi = (float(x) for x in gap.split("over ")[1].split(" rad/s")[0].split("-"))
    assert hi == pytest.approx(50.0)                 # the map's band top
    # blurred by the comparison window (at most the 60 s reference, at least the test point's own 16 s)
    bins = 2 * math.pi / 16.0
    assert f_cut - 2 * bins <= lo <= f_cut + 3 * bins, (gap, f_cut)
    assert all(v["verdict"] != "GO" for v in res["verdicts"])


def _without_system(path: Path, out: Path, sysid: int) -> int:
    """Copy a recording (schemas, channels, attachments, metadata) without the messages of
    ``sysid``, with the standard mcap reader and writer; returns how many were left out."""
    import json

    from mcap.reader import make_reader
    from mcap.writer import Writer

    dropped = 0
    with open(path, "rb") as f, open(out, "wb") as g:
        r = make_reader(f)
        w = Writer(g)
        w.start(profile=r.get_header().profile, library="test")
        schemas, channels = {}, {}
        for schema, channel, msg in r.iter_messages(log_time_order=False):
            if channel.id not in channels:
                if schema is not None and schema.id not in schemas:
                    schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding,
                                                          schemas.get(schema.id, 0) if schema else 0,
                                                          dict(channel.metadata))
            if channel.topic.startswith("/mavlink/") and json.loads(msg.data).get("sysid") == sysid:
                dropped += 1
                continue
            w.add_message(channels[channel.id], msg.log_time, msg.data, msg.publish_time, msg.sequence)
        for a in r.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        for m in r.iter_metadata():
            w.add_metadata(m.name, dict(m.metadata))
        w.finish()
    return dropped


def test_a_second_vehicle_on_the_link_changes_no_test_point(runs, tmp_path):
    """System 2 (another log's chirp, its own clock and SystemID texts) on the same port: the monitor
    keeps to system 1 and counts the other. Exactly: a replay of the recording with system 2's
    messages taken out finds the same test points, verdicts and estimates to the last digit. Live:
    the same test point as the run without system 2 (the two runs differ by receive jitter, which on
    a loaded machine moves the receive-timed coherence, hence the loose band on its fraction)."""
    a, b = runs["alone"], runs["second_vehicle"]
    assert "systems {1:" in b["summary"] and " 2: " in b["summary"]
    stripped = tmp_path / "system1_only.mcap"
    assert _without_system(b["path"], stripped, 2) > 1000          # system 2 was there, and is gone
    with_two = _replay(b["path"], tmp_path / "with_two.mcap")
    without = _replay(stripped, tmp_path / "without.mcap")
    assert with_two["test_points"] == without["test_points"] and len(without["test_points"]) == 1
    assert with_two["verdicts"] == without["verdicts"]
    assert with_two["estimate_verdicts"] == without["estimate_verdicts"]
    # the live run without system 2
    assert len(b["test_points"]) == len(a["test_points"]) == 1
    ta, tb = a["test_points"][0], b["test_points"][0]
    for k in ("source", "swept_input", "verdict", "note", "end_note"):
        assert ta[k] == tb[k], k
    assert tb["end_s"] - tb["start_s"] == pytest.approx(ta["end_s"] - ta["start_s"], abs=0.1)
    (pa,), (pb,) = ta["pairs"], tb["pairs"]
    assert (pa["output"], pa["input"]) == (pb["output"], pb["input"])
    assert pb["adequate_fraction"] == pytest.approx(pa["adequate_fraction"], abs=0.15)
    assert [v["verdict"] for v in b["verdicts"]] == [v["verdict"] for v in a["verdicts"]]


@pytest.mark.parametrize("name", ["alone", "second_vehicle", "cut"])
def test_replay_of_each_recording_reproduces_its_test_points_verdicts_and_alerts(runs, name, tmp_path):
    """The recording's own settings, replayed: the same records, equal to the last digit (the link's
    own alerts aside: a file has no link)."""
    live = runs[name]
    rep = _replay(live["path"], tmp_path / "replay.mcap")
    assert rep["test_points"] == live["test_points"]
    assert rep["verdicts"] == live["verdicts"]
    assert [x for x in rep["alerts"] if x.get("kind") != "link"] == \
        [x for x in live["alerts"] if x.get("kind") != "link"]
    # and each recorded estimate carries the verdict of its own data time, as live
    assert rep["estimate_verdicts"] and rep["estimate_verdicts"] == live["estimate_verdicts"]


# -- the parts of the log without telemetry ------------------------------------------------------
# The shared log holds the rate-loop and attitude messages from 30.2 s to 97.2 s after its first
# stamp only, but the autopilot's texts of the whole flight (four SystemID runs). Two more runs,
# faster than real time (their timing checks hold on the receive clock, which the map uses):
#
# * ``before_data``: log seconds 5-35 at 4x: the map finds nothing for its first 6 s of receive time.
# * ``no_data``: log seconds 80-195 at 10x: the roll chirp's end, then the pitch run's texts
#   ("SystemID Starting: axis=8" ... "Finished") with no telemetry between them.
DATA_FROM_S = 30.18792                 # the first ATT/PIDR/RATE after the log's first stamp [s]


@pytest.fixture(scope="module")
def quiet_runs(tmp_path_factory):
    if not SID7.is_file():
        pytest.skip(f"third-party log not found: {SID7}")
    tmp = tmp_path_factory.mktemp("live_ardupilot_quiet")
    names = ("before_data", "no_data")
    monitors = {n: _monitor(tmp / f"{n}.mcap") for n in names}
    streams = [_livesweep("stream", str(SID7), "--mavlink", f"udpout:127.0.0.1:{monitors['before_data'][1]}",
                          "--start-s", "5", "--end-s", "35", "--rate-hz", "50", "--speed", "4"),
               _livesweep("stream", str(SID7), "--mavlink", f"udpout:127.0.0.1:{monitors['no_data'][1]}",
                          "--start-s", "80", "--end-s", "195", "--rate-hz", "50", "--speed", "10")]
    summaries = {}
    try:
        for s in streams:
            _, err = s.communicate(timeout=120)
            assert s.returncode == 0, err
        time.sleep(1.0)
        for n, (mon, _) in monitors.items():
            mon.send_signal(signal.SIGINT)
            out, err = mon.communicate(timeout=60)
            assert mon.returncode == 0, err
            summaries[n] = (out, err)
    finally:
        for p in [*streams, *(m for m, _ in monitors.values())]:
            if p.poll() is None:
                p.kill()
    return {n: {**_results(tmp / f"{n}.mcap"), "summary": summaries[n], "path": tmp / f"{n}.mcap"} for n in names}


def test_a_map_missing_its_messages_says_so_then_says_when_they_come(quiet_runs):
    """Before the vehicle streams its rate loops the map finds nothing, and says so 5 s after the
    first frame; when they come it says that too (the early warning does not stand)."""
    res = quiet_runs["before_data"]
    path = res["path"]
    maps = [(m.log_time_ns * 1e-9, m.data["message"])           # logged at the deciding frame's receipt
            for m in read_messages(path, topics="/livesweep/alert") if m.data["kind"] == "map"]
    first_rx = min(m.log_time_ns for m in read_messages(path) if m.topic.startswith("/mavlink/")) * 1e-9
    data_topics = ["/mavlink/PID_TUNING", "/mavlink/ATTITUDE"]
    data_rx = min(m.log_time_ns for m in read_messages(path, topics=data_topics)) * 1e-9
    assert data_rx - first_rx == pytest.approx((DATA_FROM_S - 5.0) / 4, abs=0.5)   # sent at 4x
    missing = [(t, x) for t, x in maps if "no frames on" in x]
    found = [(t, x) for t, x in maps if "found now" in x]
    names = {"roll", "pitch", "yaw", "p", "q", "r", "phi", "theta"}
    assert {x.split(":")[0].removeprefix("signal ") for _, x in missing} == names
    # due at the first frame received 5 s after the first (a HEARTBEAT each 0.25 s at 4x)
    assert all(5.0 <= t - first_rx < 5.5 for t, _ in missing)
    assert all("(topics seen: /mavlink/HEARTBEAT)" in x for _, x in missing)      # all the log has then
    assert {x.split(":")[0].removeprefix("signal ") for _, x in found} == names
    # at the first rate-loop and attitude messages: within a few 50 Hz frames (sent at 4x)
    assert all(0 <= t - data_rx < 0.25 for t, _ in found), ([t - data_rx for t, _ in found])
    assert found[-1][1].endswith("found now (every signal found)")
    assert "no frames on" in res["summary"][1] and "found now" in res["summary"][1]


def test_a_test_point_without_telemetry_is_judged_no_go_soon_after_its_end(quiet_runs):
    """The pitch run's texts with no samples between them: a test point, NO-GO for want of samples,
    decided by the first frame received CLOSE_WAIT_S after the autopilot's "SystemID Finished" (not
    at the monitor's stop: the judgement must not wait for data that never comes)."""
    from livesweep.monitor.testpoints import CLOSE_WAIT_S

    res = quiet_runs["no_data"]
    (tp,) = [x for x in res["test_points"] if x["swept_input"] == "pitch"]
    assert (tp["source"], tp["verdict"]) == ("autopilot", "NO-GO")
    assert any("no samples" in m for m in tp["missing"])
    (logged,) = [t for t, x in zip(res["tp_logged_ns"], res["test_points"]) if x is tp or x == tp]
    t_end = next(t for t, d in res["texts"] if d["text"] == "SystemID Finished" and t > tp["start_s"])
    assert abs(tp["end_s"] - t_end) < 0.1
    # logged at the receipt of the first frame CLOSE_WAIT_S after the end (HEARTBEATs at 10 Hz here)
    assert CLOSE_WAIT_S <= logged * 1e-9 - t_end <= CLOSE_WAIT_S + 0.3
    assert res["verdicts"][-1]["verdict"] == "NO-GO"


@pytest.mark.parametrize("name", ["before_data", "no_data"])
def test_replay_reproduces_the_map_alerts_and_the_judgement_without_data(quiet_runs, name, tmp_path):
    """The map alerts and the test point judged without samples come back identical in a replay."""
    live = quiet_runs[name]
    rep = _replay(live["path"], tmp_path / "replay.mcap")
    assert rep["test_points"] == live["test_points"]
    assert rep["verdicts"] == live["verdicts"]
    assert [x for x in rep["alerts"] if x.get("kind") != "link"] == \
        [x for x in live["alerts"] if x.get("kind") != "link"]
    # and each recorded estimate carries the verdict of its own data time, as live
    assert rep["estimate_verdicts"] == live["estimate_verdicts"]
    if name == "before_data":
        assert sum(x["kind"] == "map" for x in rep["alerts"]) == 16
