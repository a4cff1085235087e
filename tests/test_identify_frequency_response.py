"""`livesweep identify --stage frequency-response` end to end: report, accuracy, data quality, bad input."""

import json
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest

from livesweep.config import load_case
from livesweep.stages.frequency_response import run_frequency_response_stage
from livesweep.sim.effects import make_effect
from livesweep.sim.models import xv15_cruise
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.telemetry.sim_telemetry import write_sim_log

control = pytest.importorskip("control")
ROOT = Path(__file__).resolve().parents[1]
CHANNELS = (ROOT / "config" / "xv15_channels.toml").read_text()
SIGNALS = CHANNELS[CHANNELS.index("[signals.da]"):CHANNELS.index("[spectral]")]


def identify(case, out):
    return subprocess.run([sys.executable, "-m", "livesweep", "identify", str(case), "--out", str(out),
                           "--stage", "frequency-response"], capture_output=True, text=True, timeout=300)


def truth(omega):
    m = xv15_cruise()
    T = control.frequency_response(control.ss(m.F, m.G, m.H, m.J), omega).frdata
    return m, T * np.exp(-1j * np.outer(m.input_delays_s, omega))[None]


@pytest.fixture(scope="module")
def cruise_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("cruise")
    r = identify(ROOT / "config" / "xv15_cruise_lateral.toml", out)
    assert r.returncode == 0, r.stderr
    return out, json.loads((out / "report.json").read_text()), r.stdout


@pytest.mark.slow
def test_report_holds_every_pair_in_the_design_form(cruise_report):
    out, rep, stdout = cruise_report
    frs = rep["frequency_responses"]
    assert {(f["output"], f["input"]) for f in frs} == {(o, i) for o in ("p", "r", "ay", "beta") for i in ("da", "dr")}
    for f in frs:
        assert set(f) >= {"output", "input", "omega_rad_s", "magnitude_db", "phase_deg", "coherence", "random_error",
                          "conditioned"}
        assert f["conditioned"] is True
        assert len(f["omega_rad_s"]) == len(f["magnitude_db"]) == len(f["coherence"]) == 150
        svg = ElementTree.parse(out / f["plot"]).getroot()        # a well-formed SVG document
        assert svg.tag == "{http://www.w3.org/2000/svg}svg"
        labels = [g.get("data-label") for g in svg.iter("{http://www.w3.org/2000/svg}g") if g.get("data-label")]
        assert labels[0] == "conditioned (MISO), γ² ≥ 0.6" and labels[-1] == "partial coherence"
    html = (out / "report.html").read_text()
    assert html.count('src="data:image/svg+xml;base64,') == len(frs)     # self-contained: plots embedded
    assert "p/da" in stdout and "wrote" in stdout


@pytest.mark.slow
def test_reported_responses_match_the_true_model_within_their_random_error(cruise_report):
    """The sample logs were simulated from the seed's tables: 94 % of the magnitude and phase points
    with gamma^2 >= 0.6 lie within 2 random errors of the true response (measured 91-97 % per pair)."""
    _, rep, _ = cruise_report
    inside = total = 0
    for f in rep["frequency_responses"]:
        w = np.array(f["omega_rad_s"])
        m, T = truth(w)
        t = T[m.outputs.index(f["output"]), m.inputs.index(f["input"])]
        g = np.array([c is not None and c >= 0.6 for c in f["coherence"]])
        mag = np.array(f["magnitude_db"], float)[g]
        ph = np.array(f["phase_deg"], float)[g]
        eps = np.array(f["random_error"], float)[g]
        dmag = np.abs(np.log(10 ** (mag / 20) / np.abs(t[g])))
        dph = np.abs(np.angle(np.exp(1j * np.deg2rad(ph)) / np.exp(1j * np.angle(t[g]))))
        inside += np.sum(dmag <= 2 * eps) + np.sum(dph <= 2 * eps)
        total += 2 * g.sum()
    assert total > 1500 and inside / total >= 0.9
    p_da = next(f for f in rep["frequency_responses"] if f["output"] == "p" and f["input"] == "da")
    assert min(p_da["coherence"]) > 0.6        # the roll sweep excites p/da over the whole 0.3-20 rad/s


@pytest.mark.slow
def test_data_quality_of_clean_sample_logs(cruise_report):
    _, rep, _ = cruise_report
    dq = rep["data_quality"]
    assert len(dq["records"]) == 2 and dq["sample_rate_hz"] == 50.0
    assert dq["duration_s"] == pytest.approx(434.0, abs=0.1)
    roll = next(c for c in dq["kinematic_checks"] if c["measured"] == "phi")
    assert roll["passed"] and abs(roll["skew_s"]) < 0.005 and abs(roll["scale_factor_error"]) < 0.01
    assert all(v == 0 for r in dq["repairs"].values() for v in r.values())
    assert sum(w["replaced"] for w in dq["wild_points"].values()) <= 2   # clean logs: at most noise-tail flags
    p_da = next(e for e in dq["excitation"] if e["output"] == "p" and e["input"] == "da")
    assert p_da["fraction_of_band"] == 1.0


def write_case(tmp_path, log, extra_spectral="", signals=SIGNALS, band="[0.3, 20.0]", windows="[7.0, 14.0, 28.0, 56.0, 100.0]"):
    case = tmp_path / "case.toml"
    case.write_text(f'''[case]
name = "test"
aircraft = "XV-15"

[[identify]]
log = "{log}"

{signals}
[spectral]
inputs = ["da"]
outputs = ["p", "r", "ay"]
band_rad_s = {band}
windows_s = {windows}
sample_rate_hz = 50.0
{extra_spectral}''')
    return case


@pytest.mark.slow
def test_injected_skew_scale_spikes_and_dropouts_are_found_and_counted(tmp_path):
    effects = (make_effect("sensor_skew", output="p", delay_s=0.05),
               make_effect("scale_factor", output="phi", factor=1.10),
               make_effect("spikes", output="r", rate_hz=0.1, magnitude=8.0),
               make_effect("dropouts", output="ay", count=2, duration_s=0.5))
    res = simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=2, amplitudes={"da": 3.0},
                                  off_axis_rms=0.2, effects=effects, seed=31))
    write_sim_log(res, tmp_path / "log.mcap")
    stage = run_frequency_response_stage(load_case(write_case(tmp_path, "log.mcap")))
    dq = stage.data_quality
    roll = next(c for c in dq["kinematic_checks"] if c["measured"] == "phi")
    # phi = 1.10 phi_true; p sampled 0.05 s before its stamp: phi(t) = 1.10 * integral(p)(t - (-0.05))
    assert roll["scale_factor_error"] == pytest.approx(0.10, abs=0.01)
    assert roll["skew_s"] == pytest.approx(-0.05, abs=0.005)
    assert roll["passed"] is False
    # spikes on r at 100 Hz: those on the 50 Hz grid (even samples) reach the record; all found
    r_t = res.outputs["r"].t_s
    on_grid = [i for i in res.injected["spikes"]["r"] if i % 2 == 0 and np.isfinite(res.outputs["ay"].values[i])]
    assert len(on_grid) >= 5
    assert dq["wild_points"]["r"]["replaced"] >= len(on_grid)
    found = np.array(dq["wild_points"]["r"]["times_s"])
    for i in on_grid:
        assert np.min(np.abs(found - r_t[i])) < 1e-6
    # two 0.5 s dropouts of the IMU message: excluded (not interpolated), windows touching them dropped
    rep = dq["repairs"]["ay"]
    assert rep["gaps_excluded"] == 2 and 40 <= rep["samples_excluded"] <= 52
    assert sum(a["excluded_for_gaps"] for a in stage.analysis.best.settings["averages"]) > 0


@pytest.mark.parametrize("mutate, message", [
    (lambda s: s.replace('field = "zgyro"', 'field = "zgyro_nope"'), "zgyro_nope"),
    (lambda s: s.replace('topic = "/mavlink/AOA_SSA"', 'topic = "/mavlink/NOPE"'), "/mavlink/NOPE"),
])
def test_missing_channel_or_field_is_a_clear_error(tmp_path, mutate, message):
    sig = mutate(SIGNALS)
    case = write_case(tmp_path, ROOT / "replay_logs" / "xv15_cruise_sweeps_da.mcap", signals=sig)
    if "NOPE" in message:   # beta must be read for the error to show
        case.write_text(case.read_text().replace('outputs = ["p", "r", "ay"]', 'outputs = ["p", "beta"]'))
    r = identify(case, tmp_path / "out")
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr


@pytest.mark.slow
@pytest.mark.parametrize("kwargs, message", [
    (dict(band="[0.3, 200.0]"), "Nyquist"),
    (dict(band="[0.01, 20.0]", windows="[7.0, 100.0]"), "resolves only from"),
    (dict(windows="[7.0, 150.0]"), "longer than half the record"),
])
def test_bad_spectral_settings_name_the_limit(tmp_path, kwargs, message):
    case = write_case(tmp_path, ROOT / "replay_logs" / "xv15_cruise_sweeps_da.mcap", **kwargs)
    r = identify(case, tmp_path / "out")
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr


@pytest.mark.slow
def test_constant_input_is_refused_by_name(tmp_path):
    sig = SIGNALS.replace('field = "servo1_raw"', 'field = "servo2_raw"')   # elevator: never moves
    case = write_case(tmp_path, ROOT / "replay_logs" / "xv15_cruise_sweeps_da.mcap", signals=sig)
    r = identify(case, tmp_path / "out")
    assert r.returncode == 2 and "constant" in r.stderr and "da" in r.stderr


@pytest.mark.slow
def test_full_euler_kinematics_are_used_when_every_rate_and_angle_is_logged(tmp_path):
    """Large attitudes (phi to 40 deg, theta to 25 deg) on a generic JSON log: with p, q, r, phi and
    theta the check integrates the 3-2-1 Euler rates and passes; phi against p alone would not."""
    from livesweep.consistency.kinematics import check_angle_against_rate
    from livesweep.telemetry.mcap_log import McapLogWriter

    fs = 100.0
    t = np.arange(0, 240, 1 / fs)
    sweep = lambda a, w0, k: a * np.sin(w0 * t + k * t**2)        # noqa: E731
    phi, theta, psi = np.deg2rad(sweep(40, 0.2, 0.01)), np.deg2rad(sweep(25, 0.3, 0.008)), np.deg2rad(sweep(60, 0.1, 0.005))
    dphi, dtheta, dpsi = (np.gradient(x, t, edge_order=2) for x in (phi, theta, psi))
    # inverse 3-2-1 kinematics, written here: body rates from Euler angles and their rates
    p = dphi - dpsi * np.sin(theta)
    q = dtheta * np.cos(phi) + dpsi * np.cos(theta) * np.sin(phi)
    r = -dtheta * np.sin(phi) + dpsi * np.cos(theta) * np.cos(phi)
    elev = sweep(1.0, 0.3, 0.05)
    with McapLogWriter(tmp_path / "att.mcap") as w:
        w.add_channel("/fdr/state", "fdr.State", {"type": "object"})
        for k in range(t.size):
            w.write("/fdr/state", {"t": t[k], "phi": np.rad2deg(phi[k]), "theta": np.rad2deg(theta[k]),
                                   "p": p[k], "q": q[k], "r": r[k], "de": elev[k]},
                    log_time_ns=int(round(t[k] * 1e9)) + 1)
    sig = "".join(f'[signals.{n}]\ntopic = "/fdr/state"\nfield = "{n}"\nstamp = "t"\nunits = "{u}"\n\n'
                  for n, u in [("phi", "deg"), ("theta", "deg"), ("p", "rad/s"), ("q", "rad/s"), ("r", "rad/s"), ("de", "")])
    case = tmp_path / "case.toml"
    case.write_text(f'[case]\nname = "euler"\n\n[[identify]]\nlog = "att.mcap"\n\n{sig}[spectral]\ninputs = ["de"]\n'
                    'outputs = ["q"]\nband_rad_s = [0.5, 10.0]\nsample_rate_hz = 50.0\n')
    dq = run_frequency_response_stage(load_case(case)).data_quality
    checks = {c["measured"]: c for c in dq["kinematic_checks"]}
    assert set(checks) == {"phi", "theta"}
    for c in checks.values():
        assert c["passed"] and abs(c["scale_factor_error"]) < 0.005 and abs(c["skew_s"]) < 0.002, c
    assert "Euler rate(p, q, r, phi, theta)" in checks["phi"]["reconstructed_from"]
    naive = check_angle_against_rate(np.rad2deg(phi[::2]), np.rad2deg(p[::2]), 50.0, band_rad_s=(0.3, 10.0))
    assert not naive.passed


@pytest.mark.slow
def test_the_full_response_set_is_saved_for_later_stages(cruise_report):
    from livesweep.report.writer import load_response_set

    out, rep, _ = cruise_report
    frs = load_response_set(out / rep["frequency_response_set"])
    assert frs.conditioned and frs.outputs == ("p", "r", "ay", "beta") and frs.inputs == ("da", "dr")
    assert frs.settings["windows_s"] == [7.0, 12.0, 20.0, 40.0, 80.0]
    p_da = next(f for f in rep["frequency_responses"] if f["output"] == "p" and f["input"] == "da")
    np.testing.assert_allclose(frs.pair("p", "da").magnitude_db, p_da["magnitude_db"], rtol=1e-12)
    np.testing.assert_allclose(frs.pair("p", "da").phase_deg, p_da["phase_deg"], rtol=1e-12)
    ordinary = load_response_set(out / ("ordinary_" + rep["frequency_response_set"]))
    assert not ordinary.conditioned


@pytest.mark.slow
def test_doublets_are_called_pulse_like_and_sweeps_are_not():
    """The data-quality section says why doublets give poor spectra: their input power falls far
    faster across the band than a sweep's (theory for a constant-amplitude exponential sweep:
    10 dB/decade)."""
    import dataclasses

    from livesweep.config import load_case
    from livesweep.stages.frequency_response import run_frequency_response_stage

    case = load_case(Path(__file__).resolve().parents[1] / "config" / "xv15_cruise_lateral.toml")
    sweeps = run_frequency_response_stage(case).data_quality
    assert all(-12.0 < s < -6.0 for s in sweeps["input_power_slope_db_per_decade"].values())
    assert not any("pulse-like" in n for n in sweeps["notes"])
    doublets = run_frequency_response_stage(dataclasses.replace(
        case, identify=case.verify,
        spectral=dataclasses.replace(case.spectral, windows_s=(5.0, 10.0, 20.0), band_rad_s=(1.0, 20.0)))).data_quality
    assert all(s < -16.0 for s in doublets["input_power_slope_db_per_decade"].values())
    assert sum("pulse-like" in n for n in doublets["notes"]) == 2
