"""`livesweep inspect` on every log in ../shared/data (third-party; skipped when absent), and
`livesweep new-case` from its suggestion: the suggested map is accepted by the live monitor
(replay) and the new case by identify, with at least one adequately excited pair where the log
was flown as a sweep."""

import math
from pathlib import Path

import numpy as np
import pytest

from livesweep import cli
from livesweep.inspection import format_inspection, inspect_log

ROOT = Path(__file__).resolve().parents[1]
_DATA = ROOT.parent / "shared" / "data"
DATA = _DATA if _DATA.is_dir() else Path("/work/shared/data")
LOGS = sorted(p for p in DATA.rglob("*") if p.is_file() and p.suffix.lower() != ".md" and p.name != "LICENSE") \
    if DATA.is_dir() else []
pytestmark = [pytest.mark.skipif(not LOGS, reason="../shared/data is not here"), pytest.mark.slow]


@pytest.fixture(scope="module")
def inspections():
    return {p: inspect_log(p) for p in LOGS}


@pytest.mark.parametrize("log", LOGS, ids=lambda p: p.name)
def test_inspect_describes_every_log_and_its_fields_with_units(inspections, log):
    ins = inspections[log]
    assert ins.duration_s > 0
    if not any(t.decoded for t in ins.topics):      # ROS 2 CDR recordings: counted and said, not crashed on
        assert ins.topics and any("does not decode" in n for n in ins.notes)
        assert all(t.messages > 0 and t.encoding == "cdr" for t in ins.topics)
        return
    for t in ins.topics:
        assert t.messages > 0 and t.end_s >= t.start_s >= 0 and math.isfinite(t.rate_hz)
    if "/mavlink/ATTITUDE" in {t.topic for t in ins.topics}:      # units from MAVLink's own definitions
        att = next(t for t in ins.topics if t.topic == "/mavlink/ATTITUDE")
        assert dict(att.fields)["rollspeed"] == "rad/s"
    if ins.format == "dataflash":                                  # units from the log's FMTU
        rate = next((t for t in ins.topics if t.topic == "/dataflash/RATE"), None)
        assert rate is None or dict(rate.fields)["R"] == "deg/s"


def test_the_systemid_logs_show_their_test_points(inspections):
    sid = [p for p in LOGS if p.parent.name == "ardupilot_sitl_systemid"]
    if not sid:
        pytest.skip("no SystemID log")
    for p in sid:
        tps = inspections[p].test_points
        assert tps and all(b > a for a, b, _ in tps if math.isfinite(b))
        assert all("SystemID axis" in w for _, _, w in tps)


@pytest.mark.parametrize("log", LOGS, ids=lambda p: p.name)
def test_the_suggested_map_is_accepted_by_the_monitor(inspections, log, tmp_path):
    """Replay the log (converted) through the live pipeline with the map inspect puts first."""
    from livesweep.config import read_channel_map
    from livesweep.convert import convert
    from livesweep.maps import load_map
    from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
    from livesweep.telemetry.replay import McapReplaySource

    ins = inspections[log]
    if not ins.maps:                    # said, with why each preset that holds the signals does not fit
        text = format_inspection(ins)
        assert "no shipped channel map fits this log" in text or "no channel map can be suggested" in text
        assert all(f.why for f in ins.fits if not f.fits)
        pytest.skip("inspect suggests no map for this log (no shipped map fits it)")
    name = ins.maps[0][0]
    if ins.duration_s < 10.0:
        assert "too short for a frequency response" in format_inspection(ins)
        pytest.skip(f"{ins.duration_s:.1f} s of data: no frequency response to estimate (inspect says so)")
    m = load_map(name) if not name.endswith(".toml") else read_channel_map(name, one_clock=False)
    mcap = log if ins.format == "mcap" else convert(log, tmp_path / "log.mcap").output
    s = MonitorSettings(signals=m.signals, inputs=tuple(m.spectral.inputs), outputs=tuple(m.spectral.outputs),
                        band_rad_s=tuple(m.spectral.band_rad_s), sample_rate_hz=m.spectral.sample_rate_hz,
                        references=tuple(m.spectral.references) if m.spectral.references else None,
                        test_points=m.test_points)
    pipe = MonitorPipeline(s, [McapReplaySource(mcap, speed=0.0)], keep_estimates=1)
    summary = pipe.run()
    assert summary["estimates"] > 0, summary
    coh = np.asarray(pipe.estimates[-1].coherence, float)
    assert np.isfinite(coh).any()


def test_new_case_from_a_systemid_log_is_identified(tmp_path, capsys):
    sid = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
    if not sid.is_file():
        pytest.skip("no SystemID roll log")
    case = tmp_path / "roll.toml"
    assert cli.main(["new-case", str(sid), "--map", "ardupilot-sysid-dataflash", "--out", str(case)]) == 0
    text = case.read_text()
    assert "[signals.p]" in text and "[spectral]" in text and "# [state_space]" in text
    assert cli.main(["identify", str(case), "--out", str(tmp_path / "rep"), "--stage", "frequency-response"]) == 0
    import json

    rep = json.loads((tmp_path / "rep" / "report.json").read_text())
    p_roll = next(e for e in rep["data_quality"]["excitation"] if (e["output"], e["input"]) == ("p", "roll"))
    assert p_roll["fraction_of_band"] >= 0.5           # the roll chirp excites roll: the case works as written
    assert cli.main(["new-case", str(sid), "--map", "ardupilot-sysid-dataflash", "--out", str(case)]) == 2
    assert "exists; give --force" in capsys.readouterr().err


def _sid_tlog(path, start_s: float, end_s: float, more=()) -> float:
    """The SystemID log's telemetry as a ground station records it (a tlog: [uint64 BE us][frame]),
    at the 50 Hz stream rate inspect suggests, from ``start_s`` to ``end_s``, then each further
    ``(start, end, shift [s])`` slice of ``more`` recorded ``shift`` later; returns the log's first
    TimeUS [s]."""
    import struct

    from livesweep.telemetry import mavlink_codec as codec
    from livesweep.telemetry.stream_log import dataflash_messages
    from pymavlink.dialects.v20 import ardupilotmega as mav2

    mav = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    log = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
    msgs = dataflash_messages(log, start_s=start_s, end_s=end_s, rate_hz=50.0)
    slices = [(msgs, 0.0), *((dataflash_messages(log, start_s=a, end_s=b, rate_hz=50.0), dt) for a, b, dt in more)]
    with open(path, "wb") as f:
        for t, name, rec in ((t + dt, name, rec) for sl, dt in slices for t, name, rec in sl):
            fields = {fl.name: rec.get(fl.name, 0) for fl in codec._spec(name).fields}
            for fl in codec._spec(name).fields:
                if fl.kind == "char":
                    fields[fl.name] = str(fields[fl.name] or "").encode()
                elif fl.length and not isinstance(fields[fl.name], list):
                    fields[fl.name] = [0] * fl.length
            frame = bytes(getattr(mav, name.lower() + "_encode")(**fields).pack(mav))
            f.write(struct.pack(">Q", 1_700_000_000_000_000 + round(t * 1e6)) + frame)
    return msgs.first_us * 1e-6


def test_a_tlog_is_read_in_one_pass_with_its_systemid_test_points_and_the_presets_its_rates_allow(tmp_path):
    """A whole flight's tlog: the SystemID runs at the autopilot's own times (its STATUSTEXT; the
    DataFlash MSG TimeUS, read with pymavlink, as reference), with the band its SID_* parameters set,
    and whether telemetry covers each; the presets its rates and its frame allow, and why not the others."""
    import os

    log = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
    if not log.is_file():
        pytest.skip("no SystemID roll log")
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(log), zero_time_base=False)
    texts = []
    while (m := r.recv_match(type="MSG")) is not None:
        if m.Message.startswith("SystemID"):
            texts.append((m.TimeUS * 1e-6, m.Message))
    tlog = tmp_path / "flight.tlog"
    t0 = _sid_tlog(tlog, 20.0, 170.0)
    ins = inspect_log(tlog)
    assert ins.format == "tlog"
    starts = [t for t, x in texts if x == "SystemID Starting: axis=7"] + [t for t, x in texts if x.endswith("axis=8")]
    ends = [t for t, x in texts if x == "SystemID Finished"][:2]
    first_rx = t0 + 20.0                                      # the tlog's first record: the slice's start
    assert [run.axis for run in ins.systemid] == [7, 8]
    for run, a, b in zip(ins.systemid, starts, ends):
        assert abs(run.start_s - (a - first_rx)) < 0.05 and abs(run.end_s - (b - first_rx)) < 0.05
        assert "0.5-12 Hz (3.14-75.4 rad/s) in 40 s" in run.what and "magnitude 15" in run.what
    assert [run.data for run in ins.systemid] == [True, False]     # the log was filtered around axis 7
    fits = {f.name: f for f in ins.fits}
    assert ins.maps[0][0] == "ardupilot-copter-pid" and fits["ardupilot-copter-pid"].fits
    assert "SERVO_OUTPUT_RAW) arrives at 10 Hz" in fits["ardupilot-copter-quad-plus"].why
    assert "the SystemID band up to 12 Hz needs 30 Hz" in fits["ardupilot-copter-quad-plus"].why
    assert fits["ardupilot-copter-quad-x"].why.startswith("the vehicle is QUAD/PLUS")
    text = format_inspection(ins)
    assert "test points (ArduPilot SystemID):" in text and "1 announced but without data" in text


def test_a_dataflash_log_names_the_presets_for_its_streamed_telemetry(inspections):
    """The SystemID DataFlash log: its own preset to replay, and for its telemetry as `livesweep
    stream` sends it, the rate-loop preset (PID_TUNING at the stream rate) but not the motor mixes
    (RCOU logged at 10 Hz) nor another frame's."""
    sid = [p for p in LOGS if p.name == "sid_axis7_rate_roll.bin"]
    if not sid:
        pytest.skip("no SystemID roll log")
    ins = inspections[sid[0]]
    assert ins.maps[0][0] == "ardupilot-sysid-dataflash" and ins.live_maps == ("ardupilot-copter-pid",)
    live = {f.name: f for f in ins.fits if f.live}
    assert "would go at 10 Hz" in live["ardupilot-copter-quad-plus"].why
    assert live["ardupilot-copter-quad-x"].why.startswith("the vehicle is QUAD/PLUS")


def test_a_signal_rate_is_the_one_during_the_systemid_runs_not_the_mean_over_gaps(tmp_path):
    """The roll chirp's telemetry at 50 Hz, and the same again 300 s later, nothing between: the mean
    rate over the log's span is about 17 Hz per axis, but PID_TUNING arrived at 50 Hz while the
    chirps ran (the stream rate the test wrote), so the rate-loop preset fits."""
    log = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
    if not log.is_file():
        pytest.skip("no SystemID roll log")
    tlog = tmp_path / "gappy.tlog"
    _sid_tlog(tlog, 20.0, 100.0, more=[(20.0, 100.0, 300.0)])
    ins = inspect_log(tlog)
    pid = next(t for t in ins.topics if t.topic == "/mavlink/PID_TUNING")
    assert pid.rate_hz / 3 < 30.0                 # three axes: the mean over the span would reject the preset
    assert len(ins.systemid) == 2 and all(run.data for run in ins.systemid)
    fits = {f.name: f for f in ins.fits}
    assert fits["ardupilot-copter-pid"].fits, fits["ardupilot-copter-pid"].why
