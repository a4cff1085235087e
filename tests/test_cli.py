"""The `livesweep` command: demo, sim to MCAP, and bad input (one line, exit 2, nothing left behind)."""

import subprocess
import sys

import pytest

from livesweep.telemetry.mcap_log import read_summary

pytestmark = pytest.mark.slow                 # every test of this module takes over 1 s


def livesweep(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "livesweep", *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def test_demo_flies_the_sweeps_live_records_them_and_identifies(tmp_path):
    import json

    from rerun.chunk import RrdReader

    r = livesweep("demo", "--out", str(tmp_path / "demo"))
    assert r.returncode == 0, r.stderr
    log = tmp_path / "demo" / "live.mcap"
    s = read_summary(log)
    assert s.complete
    recorded = int(next(ln for ln in r.stdout.splitlines() if "recorded" in ln).split()[1])
    assert sum(s.message_counts.values()) == recorded
    frames = int(next(ln for ln in r.stdout.splitlines() if ln.startswith("monitor:")).split()[1])
    assert sum(v for k, v in s.message_counts.items() if k.startswith("/mavlink/")) == frames
    assert s.message_counts["/mavlink/HIGHRES_IMU"] == pytest.approx(100 * 217, rel=0.01)   # nothing lost
    assert "verdict: GO" in r.stdout
    paths = {c.entity_path for c in RrdReader(tmp_path / "demo" / "live.rrd").stream().to_chunks()}
    assert any(p.startswith("/telemetry/") for p in paths) and any(p.startswith("/spectra/") for p in paths)
    rep = json.loads((tmp_path / "demo" / "report" / "report.json").read_text())
    p_da = next(e for e in rep["data_quality"]["excitation"] if e["output"] == "p" and e["input"] == "da")
    assert p_da["fraction_of_band"] == 1.0
    tf = rep["transfer_functions"][0]                     # the demo ends by identifying a model
    assert tf["gain"] == pytest.approx(-0.07775 * 180 / 3.141592653589793, rel=0.05) and tf["cost"] <= 50
    assert "transfer function p_da" in r.stdout and "report.html" in r.stdout

def test_sim_writes_a_verification_log_with_an_effect(tmp_path):
    out = tmp_path / "v.mcap"
    r = livesweep("sim", "--manoeuvre", "doublet", "--axis", "dr", "--amplitude", "3", "--pulse", "1.5",
                  "--effect", "scale_factor:output=r,factor=1.2", "--seed", "4", "--out", str(out))
    assert r.returncode == 0, r.stderr
    md = read_summary(out).metadata
    assert md["test_point"]["manoeuvre"] == "dr doublet"
    assert '"factor": 1.2' in md["test_point"]["effects"]


@pytest.mark.parametrize("args, message", [
    (["--omega-min", "2", "--omega-max", "1"], "omega_min_rad_s (2) must be below omega_max_rad_s (1)"),
    (["--duration", "5"], "duration_s = 5 s is too short for omega_min_rad_s = 0.3"),
    (["--amplitude", "0"], "amplitude must be > 0, got 0.0"),
    (["--model", "f16"], "unknown model 'f16'"),
    (["--effect", "gremlin:output=p"], "unknown effect 'gremlin'"),
    (["--effect", "sensor_skew:output=q,delay_s=0.05"], "unknown output 'q'"),
    (["--axis", "de"], "unknown input 'de'"),
    (["--speed", "-1", "--mavlink", "udpout:127.0.0.1:9"], "--speed must be > 0"),
])
def test_bad_input_is_one_line_exit_2_and_no_file(tmp_path, args, message):
    out = tmp_path / "x.mcap"
    r = livesweep("sim", *args, "--out", str(out))
    assert r.returncode == 2
    assert message in r.stderr
    assert r.stderr.startswith("livesweep: error: ") and r.stderr.count("\n") == 1
    assert "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_unwritable_output_path_is_refused_before_any_work(tmp_path):
    r = livesweep("sim", "--out", str(tmp_path / "missing" / "x.mcap"))
    assert r.returncode == 2 and "does not exist" in r.stderr and "Traceback" not in r.stderr
    (tmp_path / "file").write_text("x")
    r = livesweep("demo", "--out", str(tmp_path / "file"))
    assert r.returncode == 2 and "is not a directory" in r.stderr
    r = livesweep("sim")
    assert r.returncode == 2 and "--out" in r.stderr


def test_monitor_and_replay_refuse_bad_input(tmp_path):
    r = livesweep("monitor", "--duration", "1")
    assert r.returncode == 2 and "--mavlink" in r.stderr
    r = livesweep("monitor", "--mavlink", "/tmp/bin/evil.tlog", "--duration", "1")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    r = livesweep("monitor", "--mavlink", "udpin:127.0.0.1:0", "--require", "q/da", "--duration", "1")
    assert r.returncode == 2 and "--require 'q/da'" in r.stderr
    r = livesweep("replay", str(tmp_path / "missing.mcap"))
    assert r.returncode == 2 and "does not exist" in r.stderr


def test_replay_of_a_sample_log_gives_the_verdict():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    r = livesweep("replay", str(root / "replay_logs" / "xv15_cruise_sweeps_da.mcap"), "--case",
                  str(root / "config" / "xv15_channels.toml"), "--window", "240", "--require", "p/da")
    assert r.returncode == 0, r.stderr
    assert "verdict: GO" in r.stdout
    line = next(ln for ln in r.stdout.splitlines() if ln.strip().startswith("TP1 da"))   # the judged test point
    assert ": GO;" in line and int(line.split("p/da ")[1].split(" %")[0]) >= 90, line
