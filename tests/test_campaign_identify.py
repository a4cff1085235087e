"""``campaign identify``: from flights in the campaign to one identification across them.

Two simulated XV-15 cruise flights of the same aileron sweep (different noise seeds) go through
the monitor (``livesweep.replay`` with the XV-15 map, recorded: their test points are detected
from the sweep and judged), into a campaign, and out again as one identification of the test
points of ``da`` across both flights. The known answers: the concatenation holds both test
points as records at the recorded times; its random error is about 1/sqrt(2) of each flight's
alone (pooled averages); it agrees with each within their random errors.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.telemetry.sim_telemetry import write_sim_log

pytestmark = pytest.mark.slow     # two simulated flights, two replays, three identifications

ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "config" / "xv15_channels.toml"
BAND = (1.0, 12.0)
WINDOWS = (5.0, 10.0, 20.0)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    import livesweep
    import livesweep.campaign as lc

    tmp = tmp_path_factory.mktemp("campaign_identify")
    recordings = []
    for k, seed in enumerate((31, 32)):
        sc = sweep_scenario("xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=0.7, omega_max_rad_s=15.0,
                            duration_s=100.0, amplitudes={"da": 3.0}, seed=seed)
        log = tmp / f"flight{k}.mcap"
        write_sim_log(simulate(sc), log)
        rec = tmp / f"flight{k}.rec.mcap"
        livesweep.replay(log, case=MAP, record=rec)
        recordings.append(rec)
    c = lc.open(tmp / "campaign.db")
    report = c.add(recordings)
    assert len(report.added) == 2, report
    yield c, tmp
    c.close()


def test_the_go_test_points_of_both_flights_are_identified_as_one(campaign):
    from livesweep.campaign.identify import identify_selection

    c, tmp = campaign
    rows = c.test_points(swept_input="da", verdict="GO")
    assert len(rows) == 2 and len({r.flight_id for r in rows}) == 2
    kw = dict(map=MAP, swept_input="da", outputs=["p"], band_rad_s=BAND, windows_s=WINDOWS)
    alone = [identify_selection(c, tmp / f"alone{r.flight_id}", flight=r.flight_id, **kw) for r in rows]
    both = identify_selection(c, tmp / "both", **kw)
    # the case holds both test points, padded with trim, at their recorded times
    recs = both.identification.case.identify
    assert [(r.start_s, r.end_s) for r in recs] == [pytest.approx((t.start_s - 3.0, t.end_s + 3.0)) for t in rows]
    assert both.report.is_file() and {r.id for r in both.test_points} == {r.id for r in rows}
    frs = [a.identification.responses.pair("p", "da") for a in alone] + [both.identification.responses.pair("p", "da")]
    ok = np.all([f.coherence >= 0.6 for f in frs], axis=0)
    assert ok.mean() > 0.9
    for single in frs[:2]:
        ratio = np.median(single.random_error[ok] / frs[2].random_error[ok])
        assert 1.2 <= ratio <= 1.6, ratio          # about sqrt(2): twice the averages
        assert np.mean(frs[2].random_error[ok] < single.random_error[ok]) >= 0.9
        tol = 3 * np.hypot(single.random_error[ok], frs[2].random_error[ok])
        assert np.mean(np.abs(frs[2].H[ok] / single.H[ok] - 1) <= tol) >= 0.95
    # stored in the campaign
    [row] = [r for r in c.connection.execute("SELECT id, kind FROM results WHERE id = ?", (both.result_id,))]
    assert row[1] == "identification"


def test_no_matching_test_point_is_a_clear_error(campaign):
    from livesweep.campaign.identify import identify_selection
    from livesweep.errors import ConfigError

    c, tmp = campaign
    with pytest.raises(ConfigError, match="no test point of input 'dr' matches"):
        identify_selection(c, tmp / "none", map=MAP, swept_input="dr")


def test_systemid_runs_found_offline_are_identified_from_the_command_line(tmp_path):
    """The two SITL DataFlash logs through ``livesweep campaign add`` and ``campaign identify --input
    roll``: the run of axis 7 (the map's roll), found offline from the autopilot's texts, converted
    once, gives RDes -> R as the shared data's README measured it with scipy (Welch, nperseg 4096:
    0.93 / -21 deg at 2 Hz, 0.78 / -60 deg at 8 Hz; two decimals, and a windowing bias of about 1 %
    there, so 3 % and 3 deg)."""
    import json
    import os
    import subprocess
    import sys

    from conftest import SITL_LOGS

    if not all(p.is_file() for p in SITL_LOGS.values()):
        pytest.skip("shared ArduPilot SITL SystemID logs not found")
    db, out = tmp_path / "c.db", tmp_path / "roll"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}

    def run(*args):
        p = subprocess.run([sys.executable, "-m", "livesweep", "campaign", *args], capture_output=True, text=True,
                           env=env, timeout=600)
        assert p.returncode == 0, p.stderr
        return p.stdout

    run("add", str(db), *map(str, SITL_LOGS.values()))
    said = run("identify", str(db), "--map", "ardupilot-sysid-dataflash", "--input", "roll", "--out", str(out))
    assert "1 test point(s) of roll concatenated" in said, said
    report = json.loads((out / "report" / "report.json").read_text())
    fr = next(p for p in report["frequency_responses"] if (p["output"], p["input"]) == ("p", "roll"))
    w = np.asarray(fr["omega_rad_s"])
    H = 10 ** (np.asarray(fr["magnitude_db"]) / 20) * np.exp(1j * np.radians(fr["phase_deg"]))
    for hz, mag, deg in ((2.0, 0.93, -21.0), (8.0, 0.78, -60.0)):
        h = H[np.argmin(abs(w - 2 * np.pi * hz))]
        assert abs(abs(h) / mag - 1) <= 0.03 and abs(np.degrees(np.angle(h)) - deg) <= 3.0, (hz, abs(h), np.angle(h, deg=True))
    assert (tmp_path / "converted").is_dir()


def test_a_flight_is_identified_from_its_recorded_test_points_without_a_case_file(sitl_replays, tmp_path, capsys):
    """``livesweep identify REC.mcap --map NAME``: the monitor's recording of the SITL roll chirp
    gives one report for roll, over its GO test point padded with trim, and fits the recorded
    model's structure, which agrees with the in-flight model within their combined bounds."""
    import json

    from livesweep.campaign.flight import plan_flight
    from livesweep.cli import main

    rec = sitl_replays["roll"].recording
    go = [t for t in sitl_replays["roll"].test_points if t["verdict"] == "GO"]
    [plan] = plan_flight(rec, map="ardupilot-sysid-dataflash")
    assert plan.swept_input == "roll" and len(plan.points) == len(go) == 1
    assert (plan.points[0].start_s, plan.points[0].end_s) == pytest.approx((go[0]["start_s"] - 3.0, go[0]["end_s"] + 3.0))
    assert list(plan.transfer_functions.values()) == [
        {"output": "p", "input": "roll", "numerator": "", "denominator": "(1/T)", "delay": True}]
    assert main(["identify", str(rec), "--map", "ardupilot-sysid-dataflash", "--out", str(tmp_path / "f"),
                 "--no-plots"]) == 0
    report = json.loads((tmp_path / "f" / "roll" / "report.json").read_text())
    [live] = report["live_models"]
    [pair] = live["pairs"]
    assert pair["comparison"] is not None
    assert all(abs(row["bounds"]) <= 1.0 for row in pair["comparison"]["parameters"]), pair["comparison"]


def test_a_flight_without_usable_test_points_says_so(tmp_path):
    from livesweep.campaign.flight import plan_flight
    from livesweep.errors import ConfigError

    log = tmp_path / "quiet.mcap"
    write_sim_log(simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=0.7,
                                          omega_max_rad_s=15.0, duration_s=20.0, amplitudes={"da": 3.0}, seed=3)), log)
    with pytest.raises(ConfigError, match="no usable test point"):
        plan_flight(log, map=MAP)


def test_the_maps_conditions_of_a_recording_are_the_test_points_conditions(sitl_mcaps, tmp_path):
    """A recording made with ``[test_points] conditions = ["alt"]`` (CTUN.Alt) gives its test point
    that altitude in the campaign, and a condition range selects it; the value is the mean over the
    test point that pymavlink's reading of CTUN gives (tests/test_model_sitl.py checks that mean)."""
    import livesweep
    import livesweep.campaign as lc

    base = ROOT / "src" / "livesweep" / "data" / "maps" / "ardupilot-sysid-dataflash.toml"
    text = base.read_text().replace("min_duration_s = 10.0", 'min_duration_s = 10.0\nconditions = ["alt"]')
    text = text.replace("[spectral]", '[signals.alt]\ntopic = "/dataflash/CTUN"\nfield = "Alt"\nstamp = "TimeUS"\n'
                        'stamp_scale = 1e-6\nunits = "m"\n\n[spectral]')
    (tmp_path / "map.toml").write_text(text)
    r = livesweep.replay(sitl_mcaps["roll"], map=str(tmp_path / "map.toml"), record=tmp_path / "rec.mcap")
    alt = r.models[0]["test_point"]["conditions"]["alt"]
    with lc.open(tmp_path / "c.db") as c:
        c.add([tmp_path / "rec.mcap"])
        [row] = c.test_points(conditions={"alt": (alt - 1.0, alt + 1.0)})
        assert row.verdict == "GO" and row.condition("alt") == pytest.approx(alt)
        assert c.test_points(conditions={"alt": (0.0, alt - 5.0)}) == []


def test_every_input_runs_on_the_batch_engine_as_the_direct_call_does(campaign):
    """``identify_all``: one case per swept input with usable test points, run by the batch engine
    (a process pool); its report's p/da response is the one the direct call computes on the same
    test points (same case, other process)."""
    import json

    from livesweep.campaign.identify import identify_all, identify_selection

    c, tmp = campaign
    rows = identify_all(c, tmp / "all", map=MAP, workers=1)
    assert [Path(r["case"]).name for r in rows] == ["da.toml"] and rows[0]["status"] == "ok", rows
    report = json.loads((Path(rows[0]["out"]) / "report.json").read_text())
    batch = next(p for p in report["frequency_responses"] if (p["output"], p["input"]) == ("p", "da"))
    direct = identify_selection(c, tmp / "direct", map=MAP, swept_input="da").identification.responses.pair("p", "da")
    assert np.allclose(batch["omega_rad_s"], direct.omega, rtol=1e-9)
    mag = np.array(batch["magnitude_db"], dtype=float)           # null (not finite) as NaN
    assert np.allclose(mag, direct.magnitude_db, atol=1e-6, equal_nan=True)
