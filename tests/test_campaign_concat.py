"""Identification across flights: test points of one axis concatenated into one response.

Two simulated XV-15 cruise runs of the same aileron sweep, differing only in the noise seed
(turbulence and sensor noise), are identified alone and concatenated (two ``[[identify]]``
records). The known answers: pooling the spectral averages of two equal runs lowers the random
error by about sqrt(2); the pooled response agrees with each run within their random errors; all
three agree with the simulator's linear model within their random errors.
"""

from pathlib import Path

import numpy as np
import pytest

from livesweep.campaign.concat import TestPointRef, case_for_test_points, identify_test_points
from livesweep.config import load_case, read_channel_map
from livesweep.errors import ConfigError
from livesweep.settings import SignalSpec
from livesweep.sim.models import xv15_cruise
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.spectral.criteria import Criteria
from livesweep.telemetry.sim_telemetry import write_sim_log

control = pytest.importorskip("control")
ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "config" / "xv15_channels.toml"
BAND = (1.0, 12.0)                   # rad/s: the 20 s window resolves 3 periods from 0.94 rad/s
WINDOWS = (5.0, 10.0, 20.0)          # s: fixed, so single and pooled runs use the same windows


def _run(tmp, k: int, seed: int) -> TestPointRef:
    """One run: 5 s trim, then a 100 s aileron sweep 0.7-15 rad/s with 3 s of trim each side."""
    sc = sweep_scenario("xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=0.7, omega_max_rad_s=15.0,
                        duration_s=100.0, amplitudes={"da": 3.0}, seed=seed)
    res = simulate(sc)
    path = tmp / f"run{k}.mcap"
    write_sim_log(res, path)
    sweep = next(s for s in res.segments if s.kind == "sweep")
    return TestPointRef(path, sweep.start_s, sweep.end_s, f"roll sweep, run {k}")


@pytest.fixture(scope="module")
def three(tmp_path_factory):
    """p/da of run 1 alone, run 2 alone and both concatenated, and the true response."""
    tmp = tmp_path_factory.mktemp("concat")
    points = [_run(tmp, 1, 21), _run(tmp, 2, 22)]
    kw = dict(map=MAP, inputs=["da"], outputs=["p"], band_rad_s=BAND, windows_s=WINDOWS)
    idents = [identify_test_points([p], **kw) for p in points]
    idents.append(identify_test_points(points, **kw, out_dir=tmp / "case", name="roll sweeps x2"))
    frs = [i.responses.pair("p", "da") for i in idents]
    m = xv15_cruise()
    w = frs[0].omega
    T = control.frequency_response(control.ss(m.F, m.G, m.H, m.J), w).frdata
    T = T * np.exp(-1j * np.outer(m.input_delays_s, w))[None]
    true = T[m.outputs.index("p"), m.inputs.index("da")]
    coherent = np.all([f.coherence >= 0.6 for f in frs], axis=0)   # the band where all three are usable
    return points, idents, frs, true, coherent, tmp


@pytest.mark.slow
def test_case_holds_one_record_per_test_point_and_the_stage_joins_them(three):
    points, idents, frs, _, coherent, tmp = three
    case = idents[2].case
    assert case.path == (tmp / "case" / "roll_sweeps_x2.toml").resolve() and case.path.exists()
    assert [(r.log, r.start_s, r.end_s, r.label) for r in case.identify] == [
        (p.log.resolve(), p.start_s, p.end_s, p.label) for p in points]
    assert set(case.signals) == {"da", "p", "phi"}     # phi: the roll-rate kinematic check comes along
    dq = idents[2].frequency_response.data_quality
    n = [i.frequency_response.record.n_samples for i in idents]
    assert n[2] == n[0] + n[1] and dq["joins_s"] == [pytest.approx(n[0] / 50.0)]
    # same windows in all three; the pooled record has a little over twice the averages of each
    # run (the windows that span the join add a few)
    neff = [[ws.n_eff for ws in i.frequency_response.analysis.windows] for i in idents]
    assert [ws.window_s for ws in idents[2].frequency_response.analysis.windows] == list(WINDOWS)
    for a, b, c in zip(*neff):
        assert 2.0 <= c / ((a + b) / 2) <= 2.3
    assert coherent.mean() >= 0.9          # the roll sweep makes p/da coherent over the band


@pytest.mark.slow
def test_concatenation_lowers_the_random_error_by_about_root_two(three):
    """eps_r = sqrt(1 - g) / (sqrt(g) sqrt(2 n_eff)) for each window length, and the composite
    takes the smallest over the windows: twice the averages at the same coherence is 1/sqrt(2) the
    error. Measured median ratios 1.38 and 1.40 (other seed pairs 1.31-1.43; frequencies where the
    pooled error is lower: 99-100 %). The band 1.2-1.6 allows for the scatter of the coherence
    estimates (the measured coherence of either run is itself random, a little more so with fewer
    averages). With longer windows of few averages (30 s windows at n_eff 3.6 in a 76 s record) the
    single-run error is optimistic and the ratio falls to about 1.15: keep >= ~9 averages."""
    _, _, frs, _, coherent, _ = three
    e1, e2, ec = (f.random_error[coherent] for f in frs)
    for ei in (e1, e2):
        assert np.mean(ec < ei) >= 0.9
        assert np.median(ec) < np.median(ei)
        assert 1.2 <= np.median(ei / ec) <= 1.6


@pytest.mark.slow
def test_concatenated_response_agrees_with_each_run_within_their_random_errors(three):
    """eps_r is one sigma of |H| (relative) and of the phase (rad), so |H_c / H_i - 1| has about
    sqrt(eps_c^2 + eps_i^2) per component (treating the two as independent; they share run i's
    data, which only makes the difference smaller), and the complex |H_c / H_i - 1| bounds both
    components at once. 3 sigma holds at >= 95 % of points even with the errors' own scatter;
    measured 100 % (median difference 0.3 and 0.35 sigma: the shared data)."""
    _, _, frs, _, coherent, _ = three
    hc, ec = frs[2].H[coherent], frs[2].random_error[coherent]
    for f in frs[:2]:
        d = np.abs(hc / f.H[coherent] - 1)
        assert np.mean(d <= 3 * np.hypot(ec, f.random_error[coherent])) >= 0.95


@pytest.mark.slow
def test_all_three_agree_with_the_true_model_within_three_random_errors(three):
    """The simulator's linear model (with its input delay) is the truth. Magnitude (log ratio) and
    phase each within 3 eps_r at >= 90 % of the coherent points. Measured: run 1 and run 2 100 % /
    100 %, pooled 96 % (magnitude) / 93 % (phase); median |H/T - 1| / eps_r 1.3, 1.3 and 1.6. The
    misses are near 1.3-1.7 rad/s (up to 8 deg), by the Dutch-roll dipole, where the 20 s window's
    resolution (main lobe about +-0.6 rad/s) gives a bias common to both runs: pooling halves the
    random error, not the bias, hence 3 eps_r rather than 2 (at 2 eps_r the pooled phase holds at
    79 % only)."""
    _, _, frs, true, coherent, _ = three
    t = true[coherent]
    for f in frs:
        rel, e = f.H[coherent] / t, f.random_error[coherent]
        assert np.mean(np.abs(np.log(np.abs(rel))) <= 3 * e) >= 0.9
        assert np.mean(np.abs(np.angle(rel)) <= 3 * e) >= 0.9


@pytest.mark.slow
def test_transfer_functions_are_fitted_to_the_concatenated_response(three):
    """Tischler & Remple's Eq. 2.7 structure for p/da on the pooled runs: the fit converges with a
    cost well inside the usual J <= 100 guideline (measured 0.4) and recovers the model's aileron
    delay."""
    points = three[0]
    tf = {"p_da": {"output": "p", "input": "da", "numerator": "s [zeta_phi, w_phi]",
                   "denominator": "(1/Ts) (1/Tr) [zeta_dr, w_dr]", "delay": True}}
    ident = identify_test_points(points, map=MAP, inputs=["da"], outputs=["p"], band_rad_s=BAND, windows_s=WINDOWS,
                                 transfer_functions=tf)
    assert ident.stages == ("frequency-response", "transfer-functions")
    (fit,) = ident.transfer_functions.fits
    assert fit.converged and fit.cost < 100
    assert fit.delay_s == pytest.approx(xv15_cruise().input_delays_s[0], abs=0.005)   # 0.0892 s; fitted 0.0882
    assert not ident.case.path.exists()          # written to a temporary folder, removed on return


def test_case_text_round_trips_every_signal_field(tmp_path):
    log = tmp_path / "a.mcap"
    log.write_bytes(b"")
    signals = {
        "u": SignalSpec("u", "/mavlink/PID_TUNING", "desired", stamp="time_boot_ms", stamp_scale=1e-3,
                        stamp_topic="/mavlink/ATTITUDE", scale=57.29577951308232, offset=-1.5, units="deg/s",
                        sysid=1, compid=1, where={"axis": 1}),
        "y": SignalSpec("y", "/mavlink/HIGHRES_IMU", "xgyro"),
    }
    pts = [TestPointRef(log, 10.0, 90.0, "flight 1"), TestPointRef(str(log), 200.0, 280.5)]
    text = case_for_test_points(pts, signals=signals, inputs=["u"], outputs=["y"], band_rad_s=(0.5, 20.0),
                                sample_rate_hz=50.0, name="roll x2", criteria=Criteria(min_coherence=0.7),
                                windows_s=(5.0, 20.0),
                                transfer_functions={"roll": {"output": "y", "input": "u", "numerator": "[K]",
                                                             "denominator": "(1/Tr)", "delay": True}})
    case_path = tmp_path / "c.toml"
    case_path.write_text(text)
    case = load_case(case_path)
    assert case.name == "roll x2"
    assert [(r.log, r.label, r.start_s, r.end_s) for r in case.identify] == [
        (log.resolve(), "flight 1", 10.0, 90.0), (log.resolve(), "", 200.0, 280.5)]
    assert case.signals == signals
    sp = case.spectral
    assert (sp.inputs, sp.outputs, sp.band_rad_s, sp.sample_rate_hz, sp.windows_s) == (
        ("u",), ("y",), (0.5, 20.0), 50.0, (5.0, 20.0))
    assert case.criteria == Criteria(min_coherence=0.7)
    assert case.tables["transfer_functions"] == {"roll": {"output": "y", "input": "u", "numerator": "[K]",
                                                          "denominator": "(1/Tr)", "delay": True}}


def test_bad_test_points_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="before end_s"):
        TestPointRef(tmp_path / "a.mcap", 5.0, 5.0)
    sig = read_channel_map(MAP).signals
    with pytest.raises(ConfigError, match="no test points"):
        case_for_test_points([], signals=sig, inputs=["da"], outputs=["p"], band_rad_s=BAND, sample_rate_hz=50.0,
                             name="x")
    with pytest.raises(ConfigError, match="q not among the signals"):
        case_for_test_points([TestPointRef(tmp_path / "a.mcap", 0.0, 1.0)], signals=sig, inputs=["da"],
                             outputs=["q"], band_rad_s=BAND, sample_rate_hz=50.0, name="x")
