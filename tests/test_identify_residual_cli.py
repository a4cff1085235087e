"""`livesweep identify` end to end on MCAP logs with an undeclared sensor skew (60 ms on the roll
gyro): the residual loop finds it, writes the augmented case, and identifying from that case again
adds nothing. Real MCAP files written by the simulator, the real CLI in a subprocess."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from livesweep.config import load_case
from livesweep.sim.effects import make_effect
from livesweep.sim.scenario import simulate, sweep_scenario, verification_scenario
from livesweep.telemetry.sim_telemetry import write_sim_log

pytestmark = pytest.mark.slow                 # every test of this module takes over 1 s

ROOT = Path(__file__).resolve().parents[1]
SKEW_S = 0.06


def _identify(case, out, *extra):
    r = subprocess.run([sys.executable, "-m", "livesweep", "identify", str(case), "--out", str(out), *extra],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    return r.stdout, json.loads((Path(out) / "report.json").read_text())


@pytest.fixture(scope="module")
def skewed_case(tmp_path_factory):
    d = tmp_path_factory.mktemp("skew")
    eff = (make_effect("sensor_skew", output="p", delay_s=SKEW_S),)
    for ax, seed in (("da", 11), ("dr", 12)):
        sc = sweep_scenario("xv15-cruise", axes=(ax,), repeats=2, omega_min_rad_s=0.3, omega_max_rad_s=20.0,
                            duration_s=100.0, amplitudes={ax: 3.0}, off_axis_rms=0.2, seed=seed, effects=eff,
                            turbulence_scale=0.5)
        write_sim_log(simulate(sc), d / f"xv15_cruise_sweeps_{ax}.mcap")
    vs = verification_scenario("xv15-cruise", manoeuvres=(("da", "doublet", 2.0, 1.0), ("dr", "doublet", 3.0, 1.5),
                                                          ("da", "3211", 1.5, 0.7)), effects=eff, seed=13,
                               turbulence_scale=0.3)
    write_sim_log(simulate(vs), d / "xv15_cruise_verify.mcap")
    text = (ROOT / "config" / "xv15_cruise_lateral.toml").read_text().replace("../replay_logs/", "")
    case = d / "case.toml"
    case.write_text(text)
    return case


def test_identify_finds_the_skew_and_writes_a_case_that_closes_the_loop(skewed_case, tmp_path):
    out, rep = _identify(skewed_case, tmp_path / "first")
    rl = rep["residual_loop"]
    assert "residual-loop" in rep["stages"]
    step = rl["steps"][0]
    assert (step["effect"]["kind"], step["effect"]["where"]) == ("sensor_skew", "p")
    (skew,) = step["effect"]["parameters"]
    assert skew["name"] == "skew_p"
    assert abs(skew["value"] - SKEW_S) <= 3 * skew["cramer_rao_pct"] / 100 * skew["value"]
    assert step["cost_after"] <= 0.5 * step["cost_before"]
    assert step["verification_after"]["j_rms"] <= 1.05 * step["verification_before"]["j_rms"]
    assert "sensor_skew at p" in out and "skew_p" in out
    # the report carries the residual plots and the residuals behind them
    assert (tmp_path / "first" / step["plot"]).is_file()
    assert len(step["residuals_before"]) == len(step["residuals_after"]) == 8
    assert "Residual loop" in (tmp_path / "first" / "report.html").read_text()
    (final,) = rl["verification_final"]
    assert final["j_rms"] <= 1.05 * step["verification_before"]["j_rms"] and (tmp_path / "first" / final["plot"]).is_file()
    # the augmented case: readable, runnable, with the skew as a parameter of its model
    aug = tmp_path / "first" / rl["augmented_case"]
    case = load_case(aug)
    assert case.tables["state_space"]["output_delays"] == {"p": "skew_p"}
    assert aug.read_text().startswith("# Written by livesweep's residual loop")
    _, rep2 = _identify(aug, tmp_path / "second")
    assert rep2["residual_loop"]["steps"][0]["effect"] is None
    assert rep2["state_space"]["cost"]["average"] <= 0.5 * rep["state_space"]["cost"]["average"]


def test_bad_residual_table_is_one_line_exit_2(tmp_path):
    case = tmp_path / "case.toml"
    text = (ROOT / "config" / "xv15_cruise_lateral.toml").read_text().replace("../replay_logs/", str(ROOT / "replay_logs") + "/")
    case.write_text(text + '\n[residual]\nkinds = ["time_delay", "gremlins"]\n')
    r = subprocess.run([sys.executable, "-m", "livesweep", "identify", str(case), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert "[residual].kinds[1] = 'gremlins'" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
