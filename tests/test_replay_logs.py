"""The shipped sample logs: small, regenerated bit-for-bit, and faithful to the model they came from."""

import hashlib
from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps

from livesweep.sim.models import xv15_cruise
from livesweep.sim.samples import SAMPLE_LOGS, sample_scenario
from livesweep.sim.scenario import simulate
from livesweep.telemetry.mcap_log import read_fields, read_summary
from livesweep.telemetry.sim_telemetry import write_sim_log

LOGS = Path(__file__).resolve().parents[1] / "replay_logs"


def sums():
    return dict(reversed(line.split()) for line in (LOGS / "SHA256SUMS").read_text().splitlines())


def test_every_sample_log_is_shipped_listed_and_under_5_mb():
    assert set(sums()) == set(SAMPLE_LOGS)
    for name in SAMPLE_LOGS:
        assert (LOGS / name).stat().st_size < 5_000_000
        assert hashlib.sha256((LOGS / name).read_bytes()).hexdigest() == sums()[name]


@pytest.mark.parametrize("name", list(SAMPLE_LOGS))
def test_sample_log_regenerates_bit_for_bit(name, tmp_path):
    path = tmp_path / name
    write_sim_log(simulate(sample_scenario(name)), path, notes=SAMPLE_LOGS[name][0])
    assert hashlib.sha256(path.read_bytes()).hexdigest() == sums()[name]


def test_cruise_aileron_log_gives_the_model_response_by_plain_scipy():
    """p/da from the log with scipy's Welch H1 (independent of livesweep's spectral code) matches
    the XV-15 model within 1 dB and 5 deg wherever the coherence is above 0.95."""
    path = LOGS / "xv15_cruise_sweeps_da.mcap"
    servo = read_fields(path, "/mavlink/SERVO_OUTPUT_RAW", ["servo1_raw", "time_usec"])
    imu = read_fields(path, "/mavlink/HIGHRES_IMU", ["xgyro", "time_usec"])
    fs = 50.0
    t = np.arange(servo["time_usec"][0], servo["time_usec"][-1], 1e6 / fs)
    da = np.interp(t, servo["time_usec"], 0.1 * servo["servo1_raw"] - 150.0)
    p = np.interp(t, imu["time_usec"], np.rad2deg(imu["xgyro"]))
    kw = dict(fs=fs, window="hann", nperseg=2048, noverlap=1638)
    f, Pxy = sps.csd(da, p, **kw)
    _, Pxx = sps.welch(da, **kw)
    _, coh = sps.coherence(da, p, **kw)
    w = 2 * np.pi * f
    band = (w >= 0.5) & (w <= 15) & (coh > 0.95)
    assert band.sum() >= 0.8 * np.sum((w >= 0.5) & (w <= 15))  # coherent over most of the band
    T = xv15_cruise().frequency_response(w[band])[0, 0]
    H = Pxy[band] / Pxx[band]
    assert np.max(np.abs(20 * np.log10(np.abs(H / T)))) < 1.0
    assert np.max(np.abs(np.angle(H / T, deg=True))) < 5.0
    s = read_summary(path)
    assert sum(1 for k, v in s.metadata.items() if k.startswith("segment_") and v["kind"] == "sweep") == 2
