"""What an autopilot was told to inject, against what it logged it injected.

References the code did not make: ArduCopter's own SystemID logs (the shared SITL DataFlash logs,
read with pymavlink's DFReader): the injected chirp ``SIDD.Targ`` and its instantaneous frequency
``SIDD.F``, sample by sample, and the SystemID parameters at the start (``SIDS``, ``PARM``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from livesweep.errors import ConfigError
from livesweep.monitor.vehicle import VehicleInfo
from livesweep.spectral.injection import ARDUPILOT_SYSTEMID_DELAY_S, SweepInjection, ardupilot_chirp
from livesweep.telemetry.frames import Frame

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" if (ROOT.parent / "shared" / "data").is_dir() else Path("/work/shared/data")
LOGS = [DATA / "ardupilot_sitl_systemid" / n for n in ("sid_axis7_rate_roll.bin", "sid_axis8_rate_pitch.bin")]


def _sid(log: Path) -> dict:
    if not log.is_file():
        pytest.skip(f"third-party log not found: {log}")
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(log), zero_time_base=False)
    out = {"sidd": [], "sids": [], "parm": {}}
    while (m := r.recv_match(type=["SIDD", "SIDS", "PARM"])) is not None:
        t = m.get_type()
        if t == "SIDD":
            out["sidd"].append((m.Time, m.Targ, m.F))
        elif t == "SIDS":
            out["sids"].append(m.to_dict())
        elif m.Name.startswith("SID_") and not out["sids"]:      # the parameters as the first run starts
            out["parm"][m.Name] = m.Value
    out["sidd"] = np.array(out["sidd"])
    return out


@pytest.mark.slow
@pytest.mark.parametrize("log", LOGS, ids=lambda p: p.stem)
def test_the_chirp_is_the_one_arducopter_logged_it_injected(log):
    """From the SID_* parameters alone: the injected signal equals SIDD.Targ to float32 precision
    (the autopilot computes in float32: 0.003 of a 15 deg/s amplitude) and the frequency equals
    SIDD.F, at every one of ~23 000 samples of the chirp's own time."""
    sid = _sid(log)
    p = sid["parm"]
    inj = ardupilot_chirp(p["SID_F_START_HZ"], p["SID_F_STOP_HZ"], p["SID_T_REC"], t_fade_in_s=p["SID_T_FADE_IN"],
                          t_fade_out_s=p["SID_T_FADE_OUT"], magnitude=p["SID_MAGNITUDE"])
    time_s, targ, f_hz = sid["sidd"].T                 # SIDD.Time: seconds since "SystemID Starting"
    assert time_s.size > 20_000
    np.testing.assert_allclose(inj.signal(time_s), targ, atol=0.004 * p["SID_MAGNITUDE"] / 15)
    np.testing.assert_allclose(inj.omega_at(time_s) / (2 * math.pi), f_hz, atol=1e-5)
    # the chirp starts SYSTEM_ID_DELAY after the start and has power until SID_T_REC after that
    live = np.abs(targ) > 1e-6
    assert time_s[live][0] == pytest.approx(ARDUPILOT_SYSTEMID_DELAY_S, abs=0.01)
    assert time_s[live][-1] == pytest.approx(inj.duration_s, abs=0.01)


@pytest.mark.slow
@pytest.mark.parametrize("log", LOGS, ids=lambda p: p.stem)
def test_sids_and_the_parameters_give_the_same_sweep(log):
    """The SIDS record at a start and the SID_* parameters the vehicle sent before it describe one chirp."""
    sid = _sid(log)
    sids = sid["sids"][0]
    info = VehicleInfo()
    for name, value in sid["parm"].items():
        info.take(Frame("/mavlink/PARAM_VALUE", 0, None, {"param_id": name, "param_value": value}))
    a = info.injection(int(sids["Ax"]))
    b = info.injection(int(sids["Ax"]), sids=sids)
    assert a.source != b.source == "SIDS"
    for k in ("omega_start_rad_s", "omega_stop_rad_s", "t_record_s", "t_const_s", "t_fade_in_s", "t_fade_out_s",
              "delay_s", "magnitude"):
        assert getattr(a, k) == pytest.approx(getattr(b, k)), k
    assert a.band_rad_s == pytest.approx((2 * math.pi * sids["FSt"], 2 * math.pi * sids["FSp"]))


def test_the_band_swept_so_far_follows_the_schedule():
    inj = ardupilot_chirp(0.5, 12.0, 40.0, t_fade_in_s=3.0, t_fade_out_s=2.0)
    assert inj.swept_band(0.5) is None                                  # before the chirp starts
    lo, hi = inj.swept_band(1.0 + 4.0 + 18.0)                           # half way up the exponential
    assert lo == pytest.approx(math.pi) and hi == pytest.approx(math.pi * math.sqrt(24.0), rel=1e-9)
    assert inj.swept_band(100.0) == pytest.approx((math.pi, 24 * math.pi))   # all of it, and no further
    assert inj.describe() == "0.5-12 Hz (3.14-75.4 rad/s) in 40 s (injection)"


@pytest.mark.parametrize("args, words", [((12.0, 0.5, 40.0), "SID_F_START_HZ 12, SID_F_STOP_HZ 0.5: no sweep"),
                                         ((0.0, 12.0, 40.0), "SID_F_START_HZ 0, SID_F_STOP_HZ 12: no sweep"),
                                         (("x", 12.0, 40.0), "are not numbers"),
                                         ((0.5, 12.0, 3.0), "t_record_s 3 must exceed t_const_s 4")])
def test_parameters_that_define_no_sweep_say_which(args, words):
    with pytest.raises(ConfigError, match=words):
        ardupilot_chirp(*args)


def test_a_sweep_injection_checks_its_band():
    with pytest.raises(ConfigError, match="0 < start < stop"):
        SweepInjection(5.0, 1.0, 10.0)
