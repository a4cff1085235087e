"""The live monitor on a real ArduPilot stream: ArduCopter 4.4 SITL SystemID, streamed over UDP.

The shared DataFlash logs of two SystemID chirps (``sid_axis7_rate_roll.bin``, rate roll,
"SystemID Starting: axis=7" at TimeUS 78.57 s, "SystemID Finished" at 128.58 s;
``sid_axis8_rate_pitch.bin``, rate pitch, 151.63 s to 201.64 s; QUAD/PLUS) go out through
``livesweep stream`` as ArduCopter's own telemetry (ATTITUDE, PID_TUNING at the 50 Hz stream rate
``livesweep inspect`` suggests, STATUSTEXT, HEARTBEAT, the parameters as a ground station fetches
them) into ``livesweep monitor`` with every preset ``livesweep inspect`` suggests for the log's
telemetry: real subprocesses on real UDP sockets, at 1x and 10x real time, **with a process
keeping every core busy** (:class:`helpers.CpuHog`: a field laptop also runs a ground station).

Runs at 1x, concurrently: each chirp alone; the roll chirp with the pitch chirp of the other log
sent as system 2 on the same port from one second later; the roll chirp cut a third of the way
through (the stream stops: the telemetry is lost). Then each chirp at 10x.

References the monitor did not make, read with pymavlink's DataFlash reader: the autopilot's own
"SystemID Starting" and "Finished" (MSG ``TimeUS``: the vehicle clock the presets now use), the band
it was told to sweep (``SID_F_START_HZ``, ``SID_F_STOP_HZ`` in PARM) and the frequency its chirp had
reached (``SIDD.F``); the STATUSTEXT as received for the timing of the verdict; for the second
vehicle, the run without it. A replay of a recording is exact.
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

from helpers import CpuHog, copy_mcap_without
from livesweep.telemetry.mcap_log import read_messages

pytestmark = pytest.mark.slow      # every test shares the module's live runs: minutes of paced streams

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
if not DATA.is_dir():
    DATA = Path("/work/shared/data")
SID7 = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
SID8 = DATA / "ardupilot_sitl_systemid" / "sid_axis8_rate_pitch.bin"
SRC_DIR = Path(__file__).resolve().parents[1] / "src"
LOG_T0_S = 43.384306                   # both logs' first TimeUS [s]
#: chirp -> (log, axis, swept input, log seconds sent: 5 s of loiter before the chirp .. its fade-out)
CHIRPS = {"roll": (SID7, 7, "roll", 30.0, 98.0), "pitch": (SID8, 8, "pitch", 103.0, 171.0)}


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(SRC_DIR) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _livesweep(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "livesweep", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env())


def _monitor(out: Path, preset: str) -> tuple[subprocess.Popen, int]:
    mon = _livesweep("monitor", "--mavlink", "udpin:127.0.0.1:0", "--map", preset,
                     "--record", str(out), "--no-status", "--no-markers")
    line = mon.stdout.readline()                     # "monitor: listening on mavlink udpin:127.0.0.1:PORT; ..."
    assert line.startswith("monitor: listening"), (line, mon.stderr.read() if mon.poll() is not None else "")
    port = int(line.split("udpin:127.0.0.1:")[1].split(";")[0].split()[0])
    return mon, port


def _stream(log: Path, port: int, start_s: float, end_s: float, speed: float, *extra: str) -> subprocess.Popen:
    from livesweep.inspection import STREAM_RATE_HZ

    return _livesweep("stream", str(log), "--mavlink", f"udpout:127.0.0.1:{port}", "--start-s", f"{start_s:.6f}",
                      "--end-s", f"{end_s:.6f}", "--rate-hz", f"{STREAM_RATE_HZ:g}", "--speed", f"{speed:g}", *extra)


def _results(path: Path) -> dict:
    """What the recording says: test points, verdict changes, alerts and the autopilot's texts."""
    def data(topic):
        return [m.data for m in read_messages(path, topics=topic)]

    texts = [(m.log_time_ns * 1e-9, m.data) for m in read_messages(path, topics="/mavlink/STATUSTEXT")]
    last_frame = max(m.log_time_ns for m in read_messages(path) if m.topic.startswith("/mavlink/")) * 1e-9
    return {"test_points": data("/livesweep/test_point"), "verdicts": data("/livesweep/verdict"),
            "alerts": data("/livesweep/alert"), "texts": texts, "last_frame_rx": last_frame,
            "estimate_verdicts": [(e["t_s"], e["verdict"], e["reasons"]) for e in data("/livesweep/estimate")],
            "tp_logged_ns": [m.log_time_ns for m in read_messages(path, topics="/livesweep/test_point")],
            "models": data("/livesweep/model"),
            "model_logged_ns": [m.log_time_ns for m in read_messages(path, topics="/livesweep/model")]}


def _reference(log: Path) -> dict:
    """pymavlink's reading of a log: the SystemID texts [s, TimeUS], the SID_* band at each start
    [rad/s] and the chirp's logged frequency (SIDD.F) over time."""
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(log), zero_time_base=True)
    params, starts, ends, sidd = {}, {}, [], ([], [])
    while (m := r.recv_match(type=["PARM", "MSG", "SIDD"])) is not None:
        if m.get_type() == "PARM":
            params[m.Name] = m.Value
        elif m.get_type() == "SIDD":
            sidd[0].append(m.TimeUS * 1e-6), sidd[1].append(2 * math.pi * m.F)
        elif m.Message.startswith("SystemID Starting: axis="):
            starts[int(m.Message.split("=")[1])] = (m.TimeUS * 1e-6, 2 * math.pi * params["SID_F_START_HZ"],
                                                    2 * math.pi * params["SID_F_STOP_HZ"])
        elif m.Message == "SystemID Finished":
            ends.append(m.TimeUS * 1e-6)
    return {"starts": starts, "ends": ends, "sidd_t": np.array(sidd[0]), "sidd_w": np.array(sidd[1])}


def _finished(ref: dict, start_s: float) -> float:
    return next(t for t in ref["ends"] if t > start_s)


def _presets() -> list[str]:
    from livesweep.inspection import inspect_log

    return list(inspect_log(SID7).live_maps)


def _run_all(plan: dict, tmp: Path) -> dict:
    """Start every monitor, then every stream of ``plan`` (name -> (preset, [(log, start, end, speed,
    extra args, delay)])), wait for the streams, stop the monitors; the results per name."""
    monitors = {n: _monitor(tmp / f"{n}.mcap", preset) for n, (preset, _) in plan.items()}
    pending = sorted(((delay, n, log, a, b, speed, extra) for n, (_, streams) in plan.items()
                      for log, a, b, speed, extra, delay in streams), key=lambda x: x[0])
    procs, t0, summaries = [], time.monotonic(), {}
    try:
        for delay, n, log, a, b, speed, extra in pending:
            time.sleep(max(0.0, t0 + delay - time.monotonic()))
            procs.append(_stream(log, monitors[n][1], a, b, speed, *extra))
        for s in procs:
            _, err = s.communicate(timeout=240)
            assert s.returncode == 0, err
        time.sleep(4.0)                              # the last datagrams, and the telemetry-lost watchdog
        for n, (mon, _) in monitors.items():
            mon.send_signal(signal.SIGINT)
            out, err = mon.communicate(timeout=120)
            assert mon.returncode == 0, err
            summaries[n] = (out, err)
    finally:
        for p in [*procs, *(m for m, _ in monitors.values())]:
            if p.poll() is None:
                p.kill()
    return {n: {**_results(tmp / f"{n}.mcap"), "summary": summaries[n], "path": tmp / f"{n}.mcap"} for n in plan}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    missing = [str(p) for p in (SID7, SID8) if not p.is_file()]
    if missing:
        pytest.skip(f"third-party log(s) not found: {', '.join(missing)}")
    tmp = tmp_path_factory.mktemp("live_ardupilot")
    presets = _presets()
    assert presets, "inspect suggests no preset for the SystemID log's telemetry"
    roll, pitch = CHIRPS["roll"], CHIRPS["pitch"]
    ref7 = _reference(SID7)
    cut_end = (ref7["starts"][7][0] + (_finished(ref7, ref7["starts"][7][0]) - ref7["starts"][7][0]) / 3
               - LOG_T0_S)
    slow, fast = {}, {}
    for preset in presets:
        slow[f"roll-1x-{preset}"] = (preset, [(SID7, roll[3], roll[4], 1.0, (), 0.0)])
        slow[f"pitch-1x-{preset}"] = (preset, [(SID8, pitch[3], pitch[4], 1.0, (), 0.0)])
        fast[f"roll-10x-{preset}"] = (preset, [(SID7, roll[3], roll[4], 10.0, (), 0.0)])
        fast[f"pitch-10x-{preset}"] = (preset, [(SID8, pitch[3], pitch[4], 10.0, (), 0.0)])
    preset = presets[0]
    # the other vehicle: the pitch chirp of the second log (its TimeUS 73 s later), as system 2
    slow["second_vehicle"] = (preset, [(SID7, roll[3], roll[4], 1.0, (), 0.0),
                                       (SID8, roll[3] + 73.0, roll[4] + 72.0, 1.0, ("--sysid", "2"), 1.0)])
    slow["cut"] = (preset, [(SID7, roll[3], cut_end, 1.0, (), 0.0)])
    with CpuHog():
        got = _run_all(slow, tmp)
        got.update(_run_all(fast, tmp))
    got["_presets"] = presets
    got["_cut_end_s"] = cut_end
    return got


def _replay(path: Path, out: Path) -> dict:
    """What a replay of ``path`` with its recorded settings records (the library's own replay path)."""
    from livesweep.cli import _recorded_settings
    from livesweep.monitor.pipeline import MonitorPipeline
    from livesweep.telemetry.recorder import McapRecorder
    from livesweep.telemetry.replay import McapReplaySource

    MonitorPipeline(_recorded_settings(str(path)), [McapReplaySource(path)], recorder=McapRecorder(out)).run()
    return _results(out)


def _text_rx(res: dict, text: str, after: float = 0.0) -> float:
    return next(t for t, d in res["texts"] if d["text"] == text and t > after)


@pytest.mark.parametrize("chirp", ["roll", "pitch"])
@pytest.mark.parametrize("speed", ["1x", "10x"])
def test_each_systemid_chirp_is_go_on_the_band_the_autopilot_was_told_to_sweep(runs, chirp, speed):
    """Every chirp, at 1x and 10x, into every preset inspect suggests, with every core busy: one test
    point from the autopilot's texts, at the autopilot's own times; judged over exactly SID_F_START_HZ
    to SID_F_STOP_HZ; GO, recorded within 5 s of the autopilot's "SystemID Finished"; no GO before the
    injection, and nothing reversed."""
    log, axis, swept, _, _ = CHIRPS[chirp]
    ref = _reference(log)
    t_start, w_lo, w_hi = ref["starts"][axis]
    t_end = _finished(ref, t_start)
    for preset in runs["_presets"]:
        res = runs[f"{chirp}-{speed}-{preset}"]
        (tp,) = res["test_points"]
        assert (tp["source"], tp["swept_input"], tp["verdict"], tp["axis"]) == ("autopilot", swept, "GO", axis), tp
        assert abs(tp["start_s"] - t_start) < 0.1 and abs(tp["end_s"] - t_end) < 0.1
        assert tp["judged_band_rad_s"] == pytest.approx([w_lo, w_hi], rel=1e-4)
        assert tp["swept_band_rad_s"] == pytest.approx([w_lo, w_hi], rel=1e-4)
        assert not tp["marginal"] and all(p["adequate_fraction"] >= 0.6 for p in tp["pairs"])
        # the closed test point is in the recording within 5 s of the autopilot's "Finished" (receipt)
        assert res["tp_logged_ns"][0] * 1e-9 - _text_rx(res, "SystemID Finished") <= 5.0
        # no GO before the injection: the verdict is WAIT until the test point closes, then GO
        assert [v["verdict"] for v in res["verdicts"]] == ["WAIT", "GO"], res["verdicts"]
        assert res["verdicts"][-1]["t_s"] >= tp["end_s"] - 1e-6


def test_a_chirp_cut_to_a_third_is_no_go_naming_the_band_never_swept_and_the_lost_telemetry(runs):
    """The stream stops a third of the way into the chirp: the monitor closes the test point NO-GO
    for lost telemetry within 3 s of the last frame, and names the band the chirp never reached:
    from the frequency ArduPilot's chirp had reached (its SIDD.F) to SID_F_STOP_HZ."""
    ref = _reference(SID7)
    t_start, _, w_hi = ref["starts"][7]
    t_cut = runs["_cut_end_s"] + LOG_T0_S
    w_cut = float(np.interp(t_cut, ref["sidd_t"], ref["sidd_w"]))

    res = runs["cut"]
    (tp,) = res["test_points"]
    assert (tp["source"], tp["swept_input"], tp["verdict"]) == ("autopilot", "roll", "NO-GO")
    assert tp["duration_s"] == pytest.approx(t_cut - t_start, abs=1.0)
    assert any(m.startswith("telemetry lost") for m in tp["missing"]), tp["missing"]
    assert res["tp_logged_ns"][0] * 1e-9 - res["last_frame_rx"] <= 3.0
    gap = next(m for m in tp["missing"] if m.startswith("roll needs a sweep over"))
    lo, hi = (float(x) for x in gap.split("over ")[1].split(" rad/s")[0].split("-"))
    assert hi == pytest.approx(w_hi, rel=1e-3)
    # the frequency the chirp had reached at the last sample, give or take a 50 Hz grid step
    assert w_cut * 0.97 <= lo <= w_cut * 1.03, (gap, w_cut)
    assert all(v["verdict"] != "GO" for v in res["verdicts"])

    # what to fly next: the band never reached, the SID_* parameters that cover it (the chirp's
    # own: it was cut, not badly designed), and to hold SystemID to its end
    nxt = tp["next"]
    assert nxt["needed"]
    [band] = [m for m in nxt["missing"] if m["cause"] == "not_swept"]
    assert w_cut * 0.9 <= band["band_rad_s"][0] <= w_cut * 1.03, (band, w_cut)
    assert band["band_rad_s"][1] == pytest.approx(min(w_hi, tp["judged_band_rad_s"][1]), rel=1e-3)
    ap = nxt["ardupilot"]
    assert ap["SID_F_START_HZ"] <= band["band_rad_s"][0] / (2 * math.pi)
    assert ap["SID_F_STOP_HZ"] >= band["band_rad_s"][1] / (2 * math.pi) * (1 - 1e-3)
    assert ap["SID_T_REC"] >= 40.0
    assert any("SystemID Finished" in line for line in nxt["lines"]), nxt["lines"]


def _without_system(path: Path, out: Path, sysid: int) -> int:
    """Copy a recording without the messages of ``sysid``; returns how many were left out."""
    import json

    return copy_mcap_without(path, out, lambda topic, data: topic.startswith("/mavlink/")
                             and json.loads(data).get("sysid") == sysid)


def test_a_second_vehicle_on_the_link_changes_no_test_point(runs, tmp_path):
    """System 2 (another log's chirp, its own clock and SystemID texts) on the same port: the monitor
    keeps to system 1 and counts the other. Exactly: a replay of the recording with system 2's
    messages taken out finds the same test points, verdicts and estimates to the last digit. Live:
    the same test point as the run without system 2."""
    a, b = runs[f"roll-1x-{runs['_presets'][0]}"], runs["second_vehicle"]
    assert "systems {1:" in b["summary"][0] and " 2: " in b["summary"][0]
    stripped = tmp_path / "system1_only.mcap"
    assert _without_system(b["path"], stripped, 2) > 1000          # system 2 was there, and is gone
    with_two = _replay(b["path"], tmp_path / "with_two.mcap")
    without = _replay(stripped, tmp_path / "without.mcap")
    assert with_two["test_points"] == without["test_points"] and len(without["test_points"]) == 1
    assert with_two["verdicts"] == without["verdicts"]
    assert with_two["estimate_verdicts"] == without["estimate_verdicts"]
    assert len(b["test_points"]) == len(a["test_points"]) == 1
    ta, tb = a["test_points"][0], b["test_points"][0]
    for k in ("source", "swept_input", "verdict", "note", "end_note", "judged_band_rad_s"):
        assert ta[k] == tb[k], k
    assert tb["end_s"] - tb["start_s"] == pytest.approx(ta["end_s"] - ta["start_s"], abs=0.1)
    assert [v["verdict"] for v in b["verdicts"]] == [v["verdict"] for v in a["verdicts"]]


@pytest.mark.parametrize("name", ["roll-1x", "pitch-10x", "second_vehicle", "cut"])
def test_replay_of_each_recording_reproduces_its_test_points_verdicts_and_alerts(runs, name, tmp_path):
    """The recording's own settings, replayed: the same records, equal to the last digit (the link's
    own alerts aside: a file has no link)."""
    live = runs[name if name in runs else f"{name}-{runs['_presets'][0]}"]
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
# faster than real time:
#
# * ``before_data``: log seconds 5-35 at 4x: the map finds nothing for its first 6 s of receive time.
# * ``no_data``: log seconds 80-195 at 10x: the roll chirp's end, then the pitch run's texts
#   ("SystemID Starting: axis=8" ... "Finished") with no telemetry between them (HEARTBEATs go on).
DATA_FROM_S = 30.18792                 # the first ATT/PIDR/RATE after the log's first stamp [s]


@pytest.fixture(scope="module")
def quiet_runs(tmp_path_factory):
    if not SID7.is_file():
        pytest.skip(f"third-party log not found: {SID7}")
    tmp = tmp_path_factory.mktemp("live_ardupilot_quiet")
    plan = {"before_data": ("ardupilot-copter-pid", [(SID7, 5.0, 35.0, 4.0, (), 0.0)]),
            "no_data": ("ardupilot-copter-pid", [(SID7, 80.0, 195.0, 10.0, (), 0.0)])}
    return _run_all(plan, tmp)


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
    # all the log has then: heartbeats and the parameters a ground station fetched
    assert all("(topics seen: /mavlink/HEARTBEAT, /mavlink/PARAM_VALUE)" in x for _, x in missing), missing
    assert {x.split(":")[0].removeprefix("signal ") for _, x in found} == names
    # at the first rate-loop and attitude messages: within a few 50 Hz frames (sent at 4x)
    assert all(0 <= t - data_rx < 0.25 for t, _ in found), ([t - data_rx for t, _ in found])
    assert found[-1][1].endswith("found now (every signal found)")
    assert "no frames on" in res["summary"][1] and "found now" in res["summary"][1]


def test_a_test_point_without_telemetry_is_judged_no_go_soon_after_its_end(quiet_runs):
    """The pitch run's texts with no samples between them: a test point, NO-GO for want of samples,
    at the autopilot's own times (the data's pace, 10 data seconds per second here, carries the
    texts' times across the stretch without samples), decided by the first frame received
    CLOSE_WAIT_S of data time after "SystemID Finished" (not at the monitor's stop)."""
    from livesweep.monitor.testpoints import CLOSE_WAIT_S

    ref = _reference(SID7)
    t_start = ref["starts"][8][0]
    res = quiet_runs["no_data"]
    (tp,) = [x for x in res["test_points"] if x["swept_input"] == "pitch"]
    assert (tp["source"], tp["verdict"]) == ("autopilot", "NO-GO")
    assert any("no samples" in m for m in tp["missing"])
    # carried from the last sample (log second 97.2 after the first stamp) at the pace the sender
    # kept, measured on the data before: within 2 % of the stretch without samples
    last_sample = LOG_T0_S + 97.2
    for got, want in ((tp["start_s"], t_start), (tp["end_s"], _finished(ref, t_start))):
        assert abs(got - want) <= 0.02 * (want - last_sample), (got, want)
    (logged,) = [t for t, x in zip(res["tp_logged_ns"], res["test_points"]) if x is tp or x == tp]
    t_end_rx = _text_rx(res, "SystemID Finished", after=_text_rx(res, "SystemID Starting: axis=8"))
    # CLOSE_WAIT_S of data time is a tenth of it in receive time at 10x; HEARTBEATs at 10 Hz decide it
    assert CLOSE_WAIT_S / 10 - 0.05 <= logged * 1e-9 - t_end_rx <= CLOSE_WAIT_S / 10 + 0.25
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
    assert rep["estimate_verdicts"] == live["estimate_verdicts"]
    if name == "before_data":
        assert sum(x["kind"] == "map" for x in rep["alerts"]) == 16


def _signal_toml(name: str, spec) -> str:
    """A ``[signals.NAME]`` table of a map's signal (what an offline case needs to read it)."""
    lines = [f"[signals.{name}]"]
    for key in ("topic", "field", "stamp", "stamp_topic", "units"):
        if getattr(spec, key) is not None:
            lines.append(f"{key} = {getattr(spec, key)!r}".replace("'", '"'))
    for key in ("stamp_scale", "scale", "offset"):
        lines.append(f"{key} = {float(getattr(spec, key))!r}")
    for key in ("sysid", "compid"):
        if getattr(spec, key) is not None:
            lines.append(f"{key} = {int(getattr(spec, key))}")
    if spec.where:
        lines.append("where = { " + ", ".join(f"{k} = {v!r}" for k, v in spec.where) + " }")
    return "\n".join(lines) + "\n\n"


@pytest.mark.parametrize("chirp", ["roll", "pitch"])
@pytest.mark.parametrize("speed", ["1x", "10x"])
def test_each_go_test_point_gets_its_model_within_a_second_equal_to_offline_identify(runs, chirp, speed, tmp_path):
    """Streamed live with every core busy: each GO test point's /livesweep/model is recorded within
    1 s of its /livesweep/test_point record (receive clock), and its values equal offline identify
    of the recording over the test point's span (the identify stage resamples the raw telemetry
    itself) within their Cramer-Rao bounds."""
    from livesweep.maps import load_map
    from livesweep.stages.identify import identify

    for preset in runs["_presets"]:
        res = runs[f"{chirp}-{speed}-{preset}"]
        signals = load_map(preset).signals
        go = [(tp, ns) for tp, ns in zip(res["test_points"], res["tp_logged_ns"]) if tp["verdict"] == "GO"]
        assert go, (preset, [tp["label"] for tp in res["test_points"]])
        for tp, ns in go:
            [(model, mns)] = [(m, n) for m, n in zip(res["models"], res["model_logged_ns"])
                              if m["test_point"]["start_s"] == tp["start_s"]]
            assert 0 <= (mns - ns) * 1e-9 < 1.0, (preset, (mns - ns) * 1e-9)
            for pair in model["pairs"]:
                lo, hi = tp["judged_band_rad_s"]
                settings = load_map(preset).spectral
                case = tmp_path / f"{preset}-{pair['output']}.toml"
                case.write_text(
                    f'[case]\nname = "tp"\n\n[[identify]]\nlog = "{res["path"]}"\nstart_s = {tp["start_s"]}\n'
                    f'end_s = {tp["end_s"]}\n\n' + _signal_toml(pair["input"], signals[pair["input"]])
                    + _signal_toml(pair["output"], signals[pair["output"]])
                    + f'[spectral]\ninputs = ["{pair["input"]}"]\noutputs = ["{pair["output"]}"]\n'
                    f'band_rad_s = [{lo}, {hi}]\nsample_rate_hz = {settings.sample_rate_hz}\n\n'
                    f'[transfer_functions.fit]\noutput = "{pair["output"]}"\ninput = "{pair["input"]}"\n'
                    f'numerator = "{pair["numerator"]}"\ndenominator = "{pair["denominator"]}"\n')
                fit = identify(case, until="transfer-functions", parallel=False).transfer_functions.fits[0]
                for p in pair["parameters"]:
                    assert p["cramer_rao"] is not None, (preset, p)
                    assert abs(p["value"] - fit.parameters[p["name"]]) <= p["cramer_rao"], \
                        (preset, speed, pair["name"], p, fit.parameters[p["name"]])
