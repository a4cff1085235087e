"""What to fly next after a test point (livesweep.spectral.recommend), against references it did not make.

References: the method's sweep schedule written out here (method.md §2.3: omega(t) = omega_min + C2 (exp(C1
t / T) - 1) (omega_max - omega_min), C1 = 4, C2 = 0.0187) for where a cut sweep had got to; the simulator
flying the recommended sweep with another noise seed, judged by judge_test_point; the simulator flying the
same record with the input scaled (same turbulence and noise) for the coherence a factor buys; a filter's
own frequency response for the hole it cuts; ArduCopter's own SystemID record (SIDS), texts (MSG) and
logged chirp frequency (SIDD.F) in the shared SITL log, and ArduPilot's chirp schedule (chirp.cpp).
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from livesweep.sim.inputs import FrequencySweep
from livesweep.sim.scenario import Segment, simulate, sweep_scenario
from livesweep.spectral.injection import ardupilot_chirp
from livesweep.spectral.recommend import MAX_AMPLITUDE_FACTOR, recommend_next
from livesweep.spectral.verdict import MARGINAL_SIGMAS, coherence_sigma, judge_test_point

FS = 50.0
BAND = (0.3, 20.0)                     # the XV-15 cruise map's band [rad/s]
SWEEP_KEYS = ("omega_min_rad_s", "omega_max_rad_s", "duration_s", "amplitude", "trim_s", "fade_in_s", "fade_out_s")
DECADE_TENTH = 10 ** 0.1               # the judge's granularity: adequate islands and swept holes under 0.1 decade


def method_omega(t, wmin, wmax, T):
    """omega(t) of the method's sweep (§2.3) [rad/s], t since the sweep's start [s]."""
    return wmin + 0.0187 * (math.exp(4.0 * t / T) - 1.0) * (wmax - wmin)


def fly(signals, seed: int, turbulence_scale: float = 1.0):
    """The XV-15 in cruise (light turbulence, sensor noise) flying ``signals`` on the aileron back to back, on a
    100 Hz simulation grid (the fastest sensor's rate, five times the band's top: 4x quicker than the default)."""
    scn = sweep_scenario("xv15-cruise", axes=("da",), repeats=1, seed=seed, turbulence_scale=turbulence_scale)
    segs = tuple(Segment(f"da sweep {k + 1}", "sweep", "da", s) for k, s in enumerate(signals))
    return simulate(replace(scn, segments=(scn.segments[0], *segs), internal_rate_hz=100.0))


def samples(res, until_s: float | None = None) -> np.ndarray:
    """(da, p) on a 50 Hz grid from the first sweep's start to the last one's end (or ``until_s``)."""
    sw = [s for s in res.segments if s.kind == "sweep"]
    t = np.arange(sw[0].start_s, sw[-1].end_s if until_s is None else until_s, 1 / FS)
    return np.vstack([np.interp(t, res.inputs["da"].t_s, res.inputs["da"].values),
                      np.interp(t, res.outputs["p"].t_s, res.outputs["p"].values)])


def judge(v):
    return judge_test_point(v, ["da", "p"], FS, "da", ["p"], BAND, final=True)


def fly_recommended(rec, seed: int, turbulence_scale: float = 1.0):
    """The recommended sweep, ``n_sweeps`` times, built from the recommendation's JSON."""
    sweep = json.loads(json.dumps(rec.to_dict()))["sweep"]
    one = FrequencySweep(**{k: sweep[k] for k in SWEEP_KEYS})
    return judge(samples(fly([one] * sweep["n_sweeps"], seed, turbulence_scale)))


def test_a_go_test_point_needs_nothing():
    j = judge(samples(fly([FrequencySweep(*BAND, 100.0, 3.0)], seed=1)))
    assert j.verdict == "GO"
    rec = recommend_next(j, amplitude=3.0)
    d = json.loads(json.dumps(rec.to_dict()))
    assert not rec.needed and d["missing"] == [] and d["sweep"] is None and d["ardupilot"] is None
    assert d["lines"] == ["GO: nothing more is needed for da."]


def test_a_sweep_cut_at_a_third_names_the_band_it_never_reached_and_the_recommended_sweep_is_go():
    T, trim = 100.0, 3.0
    res = fly([FrequencySweep(*BAND, T, 3.0, trim_s=trim)], seed=1)
    sweep_start = res.segments[1].start_s + trim
    v = samples(res, until_s=sweep_start + T / 3)
    j = judge(v)
    assert j.verdict == "NO-GO"
    rec = recommend_next(j, input_samples=(v[0], FS), amplitude=3.0)
    top = next(m for m in rec.missing if m.band_rad_s[1] == pytest.approx(BAND[1]))
    assert top.cause == "not_swept" and "reached only" in top.detail
    # the sweep had reached w_cut; the last half-period the record holds ends at its last zero crossing, at most
    # a half-period before the cut (one more if the last swing stays under the crossing's hysteresis), and is
    # measured at its midpoint: from two half-periods (a period) before the cut up to the cut
    w_cut = method_omega(T / 3, *BAND, T)
    assert method_omega(T / 3 - 2 * math.pi / w_cut, *BAND, T) <= top.band_rad_s[0] <= w_cut, (top, w_cut)
    assert top.band_hz[0] == pytest.approx(top.band_rad_s[0] / (2 * math.pi))
    # the bottom: the cut record is too short for it
    assert any(m.cause == "short_record" and m.band_rad_s[1] <= j.resolvable_from_rad_s * 1.0001 for m in rec.missing)
    sweep = rec.sweep
    assert (sweep["omega_min_rad_s"], sweep["omega_max_rad_s"]) == BAND
    assert sweep["duration_s"] >= 5 * 2 * math.pi / BAND[0]             # T_rec >= 4-5 T_max (method §2.1)
    assert sweep["amplitude"] == 3.0 and sweep["amplitude_factor"] == 1.0 and sweep["n_sweeps"] >= 2
    assert rec.ardupilot is None and any(line.startswith("Sweep 0.3-20 rad/s") for line in rec.lines)
    assert fly_recommended(rec, seed=101).verdict == "GO"


def test_a_weak_sweep_in_turbulence_asks_for_more_amplitude_and_the_louder_sweep_is_go():
    v = samples(fly([FrequencySweep(*BAND, 100.0, 0.35)], seed=3))
    j = judge(v)
    assert j.verdict == "NO-GO" and j.excited_fraction >= 0.6       # swept, yet not coherent enough
    rec = recommend_next(j, input_samples=(v[0], FS), amplitude=0.35)
    assert any(m.cause == "incoherent" and m.amplitude_factor >= 1.0 for m in rec.missing)
    assert not any(m.cause == "not_swept" and m.band_rad_s[1] == pytest.approx(BAND[1]) for m in rec.missing)
    factor = rec.sweep["amplitude_factor"]
    assert 1.0 < factor <= MAX_AMPLITUDE_FACTOR and rec.sweep["amplitude"] == pytest.approx(0.35 * factor, abs=1e-3)
    again = fly_recommended(rec, seed=103)
    assert again.verdict == "GO" and again.pairs[0].adequate_fraction > j.pairs[0].adequate_fraction


def test_a_bands_amplitude_factor_brings_its_median_coherence_to_the_threshold():
    """The same record (same turbulence and noise) with the input scaled by the factor a band asks for:
    its median coherence lands on 0.6 within the judge's one-sigma bracket of a coherence estimate there."""
    amp, seed = 0.2, 3
    v = samples(fly([FrequencySweep(*BAND, 100.0, amp)], seed))
    rec = recommend_next(judge(v), input_samples=(v[0], FS), amplitude=amp)
    band = max((m for m in rec.missing if m.cause == "incoherent"), key=lambda m: m.band_rad_s[1] / m.band_rad_s[0])
    assert band.median_coherence < 0.5 and 1.2 < band.amplitude_factor
    r = judge(samples(fly([FrequencySweep(*BAND, 100.0, amp * band.amplitude_factor)], seed))).pairs[0].response
    m = (r.omega >= band.band_rad_s[0]) & (r.omega <= band.band_rad_s[1])
    tol = MARGINAL_SIGMAS * float(coherence_sigma(np.array([0.6]), np.array([np.median(r.random_error[m])]))[0])
    assert abs(np.median(r.coherence[m]) - 0.6) <= tol, (np.median(r.coherence[m]), tol)


class _Holed:
    """A sweep at ``depth`` of its amplitude while its frequency is inside ``band`` [rad/s]."""

    def __init__(self, sweep: FrequencySweep, band, depth: float):
        self.sweep, self.band, self.depth, self.total_duration_s = sweep, band, depth, sweep.total_duration_s

    def __call__(self, t):
        w = self.sweep.omega(np.asarray(t, float) - self.sweep.trim_s)
        return self.sweep(t) * np.where((w >= self.band[0]) & (w <= self.band[1]), self.depth, 1.0)


def test_a_sweep_that_skipped_a_band_is_told_it_was_not_swept_there():
    hole = (1.5, 10.0)
    v = samples(fly([_Holed(FrequencySweep(*BAND, 100.0, 3.0), hole, 0.03)], seed=7))
    j = judge(v)
    assert j.verdict == "NO-GO"
    rec = recommend_next(j, input_samples=(v[0], FS), amplitude=3.0)
    m = next(m for m in rec.missing if m.band_rad_s[0] > BAND[0] * DECADE_TENTH)
    assert m.cause == "not_swept" and "skipped" in m.detail
    assert hole[0] / DECADE_TENTH <= m.band_rad_s[0] <= hole[0] * DECADE_TENTH, m
    assert hole[1] / DECADE_TENTH <= m.band_rad_s[1] <= hole[1] * DECADE_TENTH, m


# --- ArduCopter SystemID ---------------------------------------------------------------------------------------
K, WB = 2.0, 6.0                       # a first-order roll-rate response, s-plane gain and bandwidth


def fly_chirp(inj, noise: float, seed: int, bandstop_hz=None):
    """The chirp ArduCopter injects (``inj.signal``) through K / (s / WB + 1), white noise on the output;
    optionally through a band-stop filter first (a notch the autopilot applies to its output)."""
    t = np.arange(int((inj.duration_s + 2.0) * FS)) / FS
    u = inj.signal(t)
    if bandstop_hz is not None:
        u = signal.sosfiltfilt(signal.butter(3, bandstop_hz, btype="bandstop", fs=FS, output="sos"), u)
    b, a = signal.bilinear([K], [1 / WB, 1.0], fs=FS)
    y = signal.lfilter(b, a, u) + noise * np.random.default_rng(seed).standard_normal(t.size)
    return judge_test_point(np.vstack([u, y]), ["roll", "p"], FS, "roll", ["p"], (1.0, 10.0), injection=inj), u


def chirp_of(sid: dict):
    return ardupilot_chirp(sid["SID_F_START_HZ"], sid["SID_F_STOP_HZ"], sid["SID_T_REC"],
                           t_fade_in_s=sid["SID_T_FADE_IN"], t_fade_out_s=sid["SID_T_FADE_OUT"],
                           magnitude=sid["SID_MAGNITUDE"])


def test_a_systemid_record_too_short_for_its_start_frequency_gets_a_longer_sid_t_rec():
    inj = ardupilot_chirp(0.1, 0.4, 30.0, t_fade_in_s=1.0, t_fade_out_s=1.0, magnitude=10.0)
    j, _ = fly_chirp(inj, 0.05, seed=1)
    assert j.verdict == "NO-GO"
    rec = recommend_next(j)
    (m,) = rec.missing
    assert m.cause == "short_record" and m.band_rad_s[0] == pytest.approx(2 * math.pi * 0.1)
    assert rec.ardupilot_changed == ("SID_T_REC",) and rec.ardupilot["SID_T_REC"] >= 5 / 0.1   # 4-5 T_max
    assert {k: rec.ardupilot[k] for k in ("SID_F_START_HZ", "SID_F_STOP_HZ", "SID_MAGNITUDE")} == \
        {"SID_F_START_HZ": 0.1, "SID_F_STOP_HZ": 0.4, "SID_MAGNITUDE": 10.0}
    assert rec.chirp_cut_s is None and not any("cut" in line for line in rec.lines)
    assert fly_chirp(chirp_of(rec.ardupilot), 0.05, seed=2)[0].verdict == "GO"


def test_a_weak_systemid_chirp_gets_a_larger_sid_magnitude():
    inj = ardupilot_chirp(0.5, 5.0, 40.0, t_fade_in_s=1.0, t_fade_out_s=1.0, magnitude=1.0)
    j, _ = fly_chirp(inj, 2.0, seed=1)
    assert j.verdict == "NO-GO"
    rec = recommend_next(j)
    assert rec.ardupilot_changed == ("SID_MAGNITUDE",) and 1.0 < rec.ardupilot["SID_MAGNITUDE"] <= MAX_AMPLITUDE_FACTOR
    assert any(line.startswith("Set SID_MAGNITUDE 1 -> ") for line in rec.lines)
    assert fly_chirp(chirp_of(rec.ardupilot), 2.0, seed=20)[0].verdict == "GO"


def test_a_notch_on_the_input_is_a_hole_in_its_spectrum_not_a_lack_of_amplitude():
    """The autopilot was told to sweep 0.5-5 Hz but a band-stop filter took 1-3.5 Hz out of its output: with
    the input's spectrum the stretch is not swept (inside the band where the filter, applied forward and
    backward, takes 20 dB or more, as its own frequency response says); without it, it reads incoherent."""
    inj = ardupilot_chirp(0.5, 5.0, 40.0, t_fade_in_s=1.0, t_fade_out_s=1.0, magnitude=1.0)
    j, u = fly_chirp(inj, 0.3, seed=1, bandstop_hz=(1.0, 3.5))
    assert j.verdict == "NO-GO"
    w, h = signal.sosfreqz(signal.butter(3, (1.0, 3.5), btype="bandstop", fs=FS, output="sos"),
                           worN=np.geomspace(1.0, 60.0, 4000), fs=2 * math.pi * FS)
    dark = w[40 * np.log10(np.abs(h) + 1e-300) < -20]
    f, g = signal.welch(u, fs=FS, nperseg=512)
    m = next(m for m in recommend_next(j, input_spectrum=(2 * math.pi * f, g)).missing if m.cause == "not_swept")
    a, b = m.band_rad_s
    assert dark.min() / DECADE_TENTH <= a < b <= dark.max() * DECADE_TENTH, (m, dark.min(), dark.max())
    assert math.log(b / a) >= 0.5 * math.log(dark.max() / dark.min())
    assert all(m.cause != "not_swept" for m in recommend_next(j).missing)


SID7 = Path("/work/shared/data/ardupilot_sitl_systemid/sid_axis7_rate_roll.bin")


@pytest.fixture(scope="module")
def sid7():
    """RATE (RDes -> R, 400 Hz), the "SystemID Starting: axis=7" / "Finished" texts and the SIDS and SIDD
    records of the shared ArduCopter 4.4 SITL log."""
    base = Path(__file__).resolve().parents[2] / "shared" / "data" / "ardupilot_sitl_systemid"
    path = base / SID7.name if (base / SID7.name).is_file() else SID7
    if not path.is_file():
        pytest.skip(f"{SID7.name} is absent (shared data)")
    from livesweep.convert.dataflash import DataflashLog

    log = DataflashLog(path)
    said = [values for _, _, values in log.iter_records(["/dataflash/MSG", "/dataflash/SIDS"])]
    msg = [(v["TimeUS"] * 1e-6, v["Message"]) for v in said if "Message" in v]
    t0 = next(t for t, text in msg if text == "SystemID Starting: axis=7")
    t1 = next(t for t, text in msg if text == "SystemID Finished" and t > t0)
    sids = next(v for v in said if v.get("Ax") == 7)
    cols = lambda topic, names: np.column_stack([log.column(topic, n) for n in names])  # noqa: E731
    return t0, t1, sids, cols("/dataflash/RATE", ("TimeUS", "RDes", "R")), cols("/dataflash/SIDD", ("TimeUS", "F"))


def test_arducopter_chirp_cut_at_a_third_keeps_its_parameters_and_says_hold_it_to_the_end(sid7):
    from livesweep.monitor.vehicle import VehicleInfo

    t0, t1, sids, rate, sidd = sid7
    inj = VehicleInfo().injection(7, sids=sids)                       # the sweep as the repo parses SIDS
    fs = 200.0

    def judged(t_end):
        t = np.arange(t0, t_end, 1 / fs)
        v = np.vstack([np.interp(t, rate[:, 0] * 1e-6, rate[:, c]) for c in (1, 2)])
        return judge_test_point(v, ["roll", "p"], fs, "roll", ["p"], (3.0, 60.0), injection=inj,
                                elapsed_s=t_end - t0)

    assert not recommend_next(judged(t1)).needed                       # the whole chirp: GO
    t_cut = t0 + (t1 - t0) / 3
    j = judged(t_cut)
    assert j.verdict == "NO-GO"
    rec = recommend_next(j)
    (m,) = [m for m in rec.missing if m.cause == "not_swept"]
    # ArduPilot's schedule (chirp.cpp) from the SIDS record itself: 1 s delay, TC s at FSt, then exponential
    tau = t_cut - t0 - 1.0
    f_sched = sids["FSt"] * (sids["FSp"] / sids["FSt"]) ** ((tau - sids["TC"]) / (sids["TR"] - sids["TC"]))
    f_logged = float(np.interp(t_cut, sidd[:, 0] * 1e-6, sidd[:, 1]))   # what the autopilot logged it flew
    assert 1.35 < f_sched < 1.45 and f_logged == pytest.approx(f_sched, rel=0.02)
    assert m.band_hz[0] == pytest.approx(f_sched, rel=1e-3) and m.band_hz[1] == pytest.approx(sids["FSp"])
    sid = rec.ardupilot
    assert sid["SID_F_START_HZ"] <= 0.5 and sid["SID_F_STOP_HZ"] >= 12.0 and sid["SID_T_REC"] >= 40.0
    assert sid["SID_MAGNITUDE"] == 15.0 and rec.ardupilot_changed == ()
    assert rec.chirp_cut_s == pytest.approx((tau, 40.0), abs=1e-6)
    assert any(f"cut at {tau:.1f} s of its 40 s" in line and "SystemID Finished" in line for line in rec.lines)
    d = json.loads(json.dumps(rec.to_dict()))
    assert d["missing"][0]["pair"] == "p/roll" and d["missing"][0]["cause"] == "not_swept"
    assert d["ardupilot"] == dict(sid) and d["chirp_cut_s"] == [round(tau, 3), 40.0]
