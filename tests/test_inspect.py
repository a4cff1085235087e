"""`livesweep inspect` on every log in ../shared/data (third-party; skipped when absent), and
`livesweep new-case` from its suggestion: the suggested map is accepted by the live monitor
(replay) and the new case by identify, with at least one adequately excited pair where the log
was flown as a sweep."""

import math
from pathlib import Path

import numpy as np
import pytest

from livesweep import cli
from livesweep.inspect import format_inspection, inspect_log

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
    if not ins.topics:                              # ROS 2 CDR recordings: said, not crashed on
        assert any("not in JSON" in n for n in ins.notes)
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
    if not ins.maps:
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
