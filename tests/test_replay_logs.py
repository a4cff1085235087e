"""The shipped sample logs: small, regenerated to within one storage quantum per value, and
faithful to the model they came from.

Regeneration is not compared bit for bit. The simulator's float64 signals come out of BLAS
(``x @ Phi``, ``expm``) and numpy's SIMD transcendentals, whose last bits depend on the OpenBLAS
kernel and the CPU: between the SkylakeX, Haswell and Sandybridge kernels, with and without
numpy's AVX512 and AVX2 paths, 58-73 % of the float64 samples differ, by at most 0.011 float32 ulp
of the value. A log stores float32 fields and integers rounded from them, so such a scatter can
move a stored value by one quantum at most (one float32 ulp; one count of a PWM rounded from a
simulated command), and only where the float64 value lies that close to a rounding boundary.
The shipped bytes themselves stay pinned by SHA256SUMS.
"""

import hashlib
import re
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps

from livesweep.sim.models import xv15_cruise
from livesweep.sim.samples import SAMPLE_LOGS, sample_scenario
from livesweep.sim.scenario import simulate
from livesweep.telemetry.mcap_log import read_attachments, read_fields, read_messages, read_summary
from livesweep.telemetry.sim_telemetry import write_sim_log

LOGS = Path(__file__).resolve().parents[1] / "replay_logs"
#: integer fields rounded from simulated signals (PWM = round(1500 + 10 x deflection)): one count of slack
ROUNDED_FROM_SIGNALS = re.compile(r"servo\d+_raw")


def sums():
    return dict(reversed(line.split()) for line in (LOGS / "SHA256SUMS").read_text().splitlines())


def test_every_sample_log_is_shipped_listed_and_under_5_mb():
    assert set(sums()) == set(SAMPLE_LOGS)
    for name in SAMPLE_LOGS:
        assert (LOGS / name).stat().st_size < 5_000_000
        assert hashlib.sha256((LOGS / name).read_bytes()).hexdigest() == sums()[name]


def _columns(path: Path) -> dict[tuple[str, str], list]:
    """Every value of a log's messages as one column per (topic, field), with the record's times
    [ns] and sequence number as further columns."""
    cols = defaultdict(list)
    for m in read_messages(path):
        header = {"log_time_ns": m.log_time_ns, "publish_time_ns": m.publish_time_ns, "sequence": m.sequence}
        for field, value in {**header, **m.data}.items():
            cols[m.topic, field].append(value)
    return cols


def _assert_within_one_quantum(where: str, field: str, got: list, want: list):
    """Integers exact (one count for :data:`ROUNDED_FROM_SIGNALS`), strings exact, float32 values
    and arrays within one float32 ulp of the shipped value, nulls in the same places."""
    assert len(got) == len(want), f"{where}: {len(got)} values, shipped {len(want)}"
    if all(type(v) is int for v in want):
        slack = 1 if ROUNDED_FROM_SIGNALS.fullmatch(field) else 0
        diff = np.abs(np.array(got, np.int64) - np.array(want, np.int64))
        assert diff.max() <= slack, f"{where}: off by up to {diff.max()} (allowed {slack})"
    elif any(isinstance(v, str) for v in want):
        assert got == want, where
    else:
        g, w = np.array(got, float), np.array(want, float)           # JSON null -> NaN
        assert np.array_equal(np.isnan(g), np.isnan(w)), f"{where}: nulls in other places"
        ok = ~np.isnan(w)
        ulp = np.spacing(np.abs(w[ok]).astype(np.float32)).astype(float)
        excess = np.abs(g[ok] - w[ok]) / ulp
        assert np.all(excess <= 1.0), f"{where}: off by up to {excess.max():.3g} float32 ulp"


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SAMPLE_LOGS))
def test_sample_log_regenerates_within_one_storage_quantum(name, tmp_path):
    """Same topics, messages, record times, metadata and attachments; every stored value within
    one quantum of the shipped one (module docstring: why not bit for bit)."""
    path = tmp_path / name
    write_sim_log(simulate(sample_scenario(name)), path, notes=SAMPLE_LOGS[name][0])
    shipped, regenerated = read_summary(LOGS / name), read_summary(path)
    assert regenerated.message_counts == shipped.message_counts and regenerated.schemas == shipped.schemas
    assert regenerated.metadata == shipped.metadata
    assert read_attachments(path) == read_attachments(LOGS / name)
    want, got = _columns(LOGS / name), _columns(path)
    assert set(got) == set(want)
    for (topic, field), values in want.items():
        _assert_within_one_quantum(f"{name} {topic} {field}", field, got[topic, field], values)


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
