"""livesweep.consistency.resample: onto one uniform grid, checked against analytic signals, a real
X-Plane log with irregular sampling, simulated dropouts and np.interp; every repair counted."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from livesweep.consistency.resample import RepairCounts, UniformRecord, concatenate, resample_uniform
from livesweep.errors import ConfigError

R2D = 180.0 / math.pi


def _shared_data() -> Path | None:
    for base in (Path(__file__).resolve().parents[2] / "shared" / "data", Path("/work/shared/data")):
        if base.is_dir():
            return base
    return None


# --------------------------------------------------------------------------------------------
# (a) a jittered sine against the analytic sine
# --------------------------------------------------------------------------------------------


def _jittered_stamps(rng: np.random.Generator, duration_s: float, t0: float = 0.0) -> np.ndarray:
    """Stamps with independent intervals uniform in [10, 33] ms (like the X-Plane logs)."""
    dt = rng.uniform(0.010, 0.033, size=int(duration_s / 0.010) + 10)
    t = t0 + np.concatenate(([0.0], np.cumsum(dt)))
    return t[t <= t0 + duration_s]


def test_jittered_sine_matches_analytic_within_the_linear_interpolation_bound():
    """Linear interpolation between stamps a < t < b of f = A sin(w t + ph) errs by at most
    (t - a)(b - t) max|f''| / 2 = (t - a)(b - t) A w^2 / 2 <= A (w h)^2 / 8 (h = b - a); the
    test asserts that pointwise bound (plus 1e-12 for rounding) at every grid sample."""
    rng = np.random.default_rng(20171018)
    A, w, ph = 2.0, 2 * math.pi * 1.5, 0.3  # 1.5 Hz, the top of the X-Plane sweeps
    tx = _jittered_stamps(rng, 60.0)
    ty = _jittered_stamps(rng, 60.0, t0=0.004)  # a second signal on its own stamps
    f = lambda t: A * np.sin(w * t + ph)  # noqa: E731
    rec = resample_uniform({"x": (tx, f(tx)), "y": (ty, -f(ty))}, 50.0)
    g = rec.t_s
    assert rec.t0_s == ty[0] and rec.sample_rate_hz == 50.0
    assert g[-1] <= min(tx[-1], ty[-1]) and g[-1] + 0.02 > min(tx[-1], ty[-1])
    assert rec.all_valid().all()  # every interval < 0.1 s: interpolated, none excluded
    for name, t, sign in (("x", tx, 1.0), ("y", ty, -1.0)):
        k = np.clip(np.searchsorted(t, g, side="right") - 1, 0, t.size - 2)
        a, b = t[k], t[k + 1]
        bound = (g - a) * (b - g) * A * w**2 / 2
        err = np.abs(rec.signal(name) - sign * f(g))
        assert np.all(err <= bound + 1e-12), float(np.max(err - bound))
        global_bound = A * (w * np.max(np.diff(t))) ** 2 / 8
        assert global_bound < 0.025  # A (w h)^2 / 8 with h <= 33 ms: about 1.2 % of A
        assert 0.2 * global_bound < err.max() <= global_bound  # the bound is not vacuous
    # no NaN, no duplicate, no backward stamps; intervals over 1.5 x median are counted
    for name, t in (("x", tx), ("y", ty)):
        c = rec.repairs[name]
        assert (c.nan_samples, c.duplicate_stamps, c.backward_stamps, c.gaps_excluded) == (0, 0, 0, 0)
        dt = np.diff(t)
        long = dt > 1.5 * np.median(dt)
        on_grid = long & (t[1:] > g[0]) & (t[:-1] < g[-1])
        assert c.gaps_interpolated == int(on_grid.sum()) > 0


# --------------------------------------------------------------------------------------------
# (b) the real X-Plane log
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def xplane() -> np.ndarray:
    base = _shared_data()
    path = None if base is None else base / "xplane_c172_pitch_sweeps" / "sweep_data_2017_10_18_14_07.npy"
    if path is None or not path.is_file():
        pytest.skip("third-party data (shared/data/xplane_c172_pitch_sweeps) is not available")
    return np.load(path)


def test_xplane_log_resampled_at_50_hz(xplane):
    t = xplane[:, 0]
    cols = {"elevator": 1, "theta": 2, "q": 4}
    rec = resample_uniform({n: (t, xplane[:, c]) for n, c in cols.items()}, 50.0, label="c172 sweeps")
    # what the file is: 21909 samples, dt 9.8-33.4 ms (median 11.7 ms), stamps strictly increasing
    dt = np.diff(t)
    assert t.size == 21909 and np.all(dt > 0)
    assert 0.0097 < dt.min() and dt.max() < 0.0335 and np.median(dt) == pytest.approx(0.01171875)
    # the grid: from the first stamp, exactly k / 50 s, up to the last stamp
    n = int(math.floor((t[-1] - t[0]) * 50.0)) + 1
    grid = t[0] + np.arange(n) / 50.0
    assert rec.t0_s == t[0] and rec.values.shape == (3, n) == (3, 14500)
    np.testing.assert_array_equal(rec.t_s, grid)
    np.testing.assert_allclose(np.diff(rec.t_s), 0.02, rtol=0, atol=1e-11)
    assert rec.labels == ("c172 sweeps",) and rec.joins == ()
    for name, c in cols.items():
        np.testing.assert_array_equal(rec.signal(name), np.interp(grid, t, xplane[:, c]))
    # repairs: no NaN, duplicate or backward stamps; the intervals above 1.5 x median dt
    # (17.6 ms; the log's 21-22 ms frames) are interpolated and counted, none excluded
    thr = 1.5 * np.median(dt)
    k = np.searchsorted(t, grid, side="right") - 1
    k = np.minimum(k, t.size - 2)
    inside_gap = (t[k] != grid) & (dt[k] > thr)
    expected = RepairCounts(0, 0, 0, int((dt > thr).sum()), int(inside_gap.sum()), 0, 0)
    assert expected.gaps_interpolated == 3690 and expected.samples_interpolated == 3781
    for name in cols:
        assert rec.repairs[name] == expected
    assert rec.all_valid().all()
    # the channels stay aligned: d(theta)/dt [deg/s] against 57.3 q [rad/s] peaks at zero lag
    dtheta = np.gradient(rec.signal("theta"), 1 / 50.0)
    q = R2D * rec.signal("q")
    corr = {lag: np.corrcoef(dtheta[10 + lag:-10 + lag], q[10:-10])[0, 1] for lag in (-1, 0, 1)}
    assert corr[0] > 0.999
    assert corr[0] > corr[-1] and corr[0] > corr[1]


# --------------------------------------------------------------------------------------------
# (c) gaps, NaN, duplicates and reordering
# --------------------------------------------------------------------------------------------


def _ramp_100hz(n: int = 1001):
    """Stamps k / 100 s (exact k/100), values 3 t + 1 (linear: interpolation is exact)."""
    t = np.arange(n) / 100.0
    return t, 3.0 * t + 1.0


def test_long_gap_is_excluded_short_gap_interpolated_nans_counted():
    t, v = _ramp_100hz()
    v = v.copy()
    v[[700, 701, 702]] = np.nan  # 7.00, 7.01, 7.02: an interval 6.99 -> 7.03 (40 ms)
    keep = ~((t > 3.0) & (t < 3.5)) & ~((t > 5.0) & (t < 5.05))  # 0.5 s and 0.05 s gaps
    ref_t, ref_v = _ramp_100hz()
    rec = resample_uniform({"y": (t[keep], v[keep]), "u": (ref_t, ref_v)}, 50.0)
    g = rec.t_s
    assert rec.values.shape == (2, 501) and g[0] == 0.0 and g[-1] == 10.0
    invalid = ~rec.valid_of("y")
    # strictly inside (3.0, 3.5): 3.02 ... 3.48, 24 grid samples; 3.0 and 3.5 are real samples
    np.testing.assert_array_equal(np.flatnonzero(invalid), np.arange(151, 175))
    assert np.all(np.isnan(rec.signal("y")[invalid]))
    assert rec.valid_of("u").all()
    np.testing.assert_array_equal(rec.all_valid(), ~invalid)
    np.testing.assert_allclose(rec.signal("y")[~invalid], 3.0 * g[~invalid] + 1.0, rtol=0, atol=1e-12)
    # 0.05 s gap (5.00 -> 5.05): 5.02, 5.04 interpolated; NaN gap (6.99 -> 7.03): 7.00, 7.02
    assert rec.repairs["y"] == RepairCounts(nan_samples=3, duplicate_stamps=0, backward_stamps=0,
                                            gaps_interpolated=2, samples_interpolated=4,
                                            gaps_excluded=1, samples_excluded=24)
    assert rec.repairs["u"] == RepairCounts()
    assert rec.repairs["u"].total == 0 and rec.repairs["y"].total == 34


def test_max_interp_gap_decides_what_is_excluded():
    t, v = _ramp_100hz()
    keep = ~((t > 5.0) & (t < 5.05))
    rec = resample_uniform({"y": (t[keep], v[keep])}, 50.0, max_interp_gap_s=0.04)
    assert rec.repairs["y"].gaps_excluded == 1 and rec.repairs["y"].samples_excluded == 2
    assert rec.repairs["y"].gaps_interpolated == 0
    np.testing.assert_array_equal(np.flatnonzero(~rec.valid_of("y")), [251, 252])


def test_duplicates_and_small_reorderings_are_repaired_and_counted():
    t, v = _ramp_100hz(201)
    order = np.arange(201)
    order[[50, 51]] = [51, 50]  # one swapped pair: one backward step
    order[[120, 122]] = [122, 120]  # 1.20, 1.21, 1.22 -> 1.22, 1.21, 1.20: two backward steps
    td, vd = t[order], v[order]
    td = np.insert(td, 80, td[80])  # a repeated stamp (same value)
    vd = np.insert(vd, 80, vd[80])
    rec = resample_uniform({"y": (td, vd)}, 100.0)
    assert rec.repairs["y"] == RepairCounts(duplicate_stamps=1, backward_stamps=3)
    np.testing.assert_allclose(rec.signal("y"), 3.0 * t + 1.0, rtol=0, atol=1e-12)
    # a duplicate with a different value: the first one is kept
    rec = resample_uniform({"y": (np.array([0.0, 1.0, 1.0, 2.0]), np.array([0.0, 5.0, 9.0, 0.0]))}, 2.0)
    np.testing.assert_array_equal(rec.signal("y"), [0.0, 2.5, 5.0, 2.5, 0.0])


def test_backward_clock_jump_is_an_error_naming_signal_and_time():
    t = np.concatenate((np.arange(0, 1001) / 100.0, 5.0 + np.arange(0, 501) / 100.0))  # 10 s -> 5 s
    v = np.sin(t)
    with pytest.raises(ConfigError, match=r"signal 'theta': stamp clock jumps back by 5 s at sample 1001 "
                                          r"\(t = 5\.0 s after t = 10\.0 s\)"):
        resample_uniform({"q": (np.arange(0, 1001) / 100.0, v[:1001]), "theta": (t, v)}, 50.0)
    t2 = t.copy()
    t2[1001:] = 9.2 + np.arange(0, 501) / 100.0  # back by 0.8 s: reordered, counted (no error)
    rec = resample_uniform({"theta": (t2, np.sin(t2))}, 50.0)
    assert rec.repairs["theta"].backward_stamps == 1


def test_argument_errors():
    t, v = _ramp_100hz(11)
    for fs in (0.0, -50.0, math.nan, math.inf):
        with pytest.raises(ConfigError, match="sample_rate_hz"):
            resample_uniform({"y": (t, v)}, fs)
    with pytest.raises(ConfigError, match=r"do not overlap \(a: 0\.0 to 0\.1 s; b: 0\.2 to 0\.3\d* s\)"):
        resample_uniform({"a": (t, v), "b": (t + 0.2, v)}, 50.0)
    with pytest.raises(ConfigError, match="fewer than 2 grid samples"):
        resample_uniform({"a": (t, v), "b": (t + 0.09, v)}, 50.0)  # 10 ms overlap at 50 Hz
    with pytest.raises(ConfigError, match=r"signal 'a': fewer than 2 usable samples \(1 "):
        resample_uniform({"a": (np.array([0.0, 1.0]), np.array([1.0, np.nan]))}, 50.0)
    with pytest.raises(ConfigError, match=r"signal 'a': t_s \(11,\) and values \(10,\)"):
        resample_uniform({"a": (t, v[:10])}, 50.0)
    with pytest.raises(ConfigError, match="no signals"):
        resample_uniform({}, 50.0)
    with pytest.raises(ConfigError, match="max_interp_gap_s"):
        resample_uniform({"a": (t, v)}, 50.0, max_interp_gap_s=-1.0)
    rec = resample_uniform({"a": (t, v)}, 50.0)
    with pytest.raises(ConfigError, match=r"signal 'b' is not in this record; signals: a"):
        rec.signal("b")
    assert not rec.values.flags.writeable and not rec.valid.flags.writeable


def test_simulated_dropouts_are_excluded_where_they_happened():
    """The simulator's dropouts effect (NaN in the sensor stream, 0.4 s each) lands as invalid
    grid samples inside the injected intervals, and nowhere else."""
    from livesweep.sim.effects import make_effect
    from livesweep.sim.scenario import simulate, sweep_scenario

    effect = make_effect("dropouts", output="p", count=3, duration_s=0.4)
    res = simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=1.0, duration_s=20.0,
                                  effects=(effect,), seed=3))
    p, da = res.outputs["p"], res.inputs["da"]
    rec = resample_uniform({"da": (da.t_s, da.values), "p": (p.t_s, p.values)}, 50.0)
    intervals = res.injected["dropouts"]["p"]
    c = rec.repairs["p"]
    assert c.nan_samples == int(np.isnan(p.values).sum()) == 120  # 3 x 40 samples at 100 Hz
    assert c.gaps_excluded == 3 and c.gaps_interpolated == 0
    g = rec.t_s[~rec.valid_of("p")]
    inside = np.zeros(g.size, bool)
    for a, b in intervals:
        hits = (g > a - 0.01) & (g < b + 0.01)  # within one source interval of the dropout
        assert 19 <= hits.sum() <= 21  # 0.4 s at 50 Hz
        inside |= hits
    assert inside.all() and c.samples_excluded == g.size
    assert rec.valid_of("da").all() and rec.repairs["da"].total == 0
    ok = rec.valid_of("p")
    np.testing.assert_allclose(rec.signal("p")[ok], np.interp(rec.t_s[ok], p.t_s[~np.isnan(p.values)],
                                                              p.values[~np.isnan(p.values)]), rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# (d) concatenate
# --------------------------------------------------------------------------------------------


def test_concatenate_two_records():
    t, v = _ramp_100hz()
    keep = ~((t > 3.0) & (t < 3.5))
    r1 = resample_uniform({"u": (t, v), "y": (t[keep], 2 * v[keep])}, 50.0, label="sweep 1")
    t2 = 100.0 + np.arange(601) / 100.0
    y2 = np.sin(t2)
    y2[10] = np.nan
    r2 = resample_uniform({"y": (t2, y2), "u": (t2, np.cos(t2))}, 50.0, label="sweep 2")  # other row order
    both = concatenate([r1, r2])
    assert isinstance(both, UniformRecord)
    assert both.names == ("u", "y") and both.labels == ("sweep 1", "sweep 2")
    assert (r1.n_samples, r2.n_samples, both.n_samples) == (501, 301, 802)
    assert both.joins == (501,)
    assert both.t0_s == 0.0 and both.t_s[501] == 501 / 50.0  # continuing grid
    np.testing.assert_array_equal(both.signal("u"), np.concatenate((r1.signal("u"), r2.signal("u"))))
    np.testing.assert_array_equal(both.valid_of("y"), np.concatenate((r1.valid_of("y"), r2.valid_of("y"))))
    assert both.repairs["y"] == RepairCounts(nan_samples=1, gaps_interpolated=1, samples_interpolated=1,
                                             gaps_excluded=1, samples_excluded=24)
    assert both.repairs["y"] == r1.repairs["y"] + r2.repairs["y"]
    assert both.repairs["u"] == RepairCounts()
    # joins inside a part are kept and shifted; a single record comes back unchanged
    three = concatenate([r2, both])
    assert three.joins == (301, 301 + 501) and three.labels == ("sweep 2", "sweep 1", "sweep 2")
    one = concatenate([r1])
    assert one.joins == () and np.array_equal(one.values, r1.values, equal_nan=True)


def test_concatenate_errors():
    t, v = _ramp_100hz(101)
    a = resample_uniform({"u": (t, v)}, 50.0, label="a")
    with pytest.raises(ConfigError, match=r"record 1 \('b'\) is at 25\.0 Hz, record 0 at 50\.0 Hz"):
        concatenate([a, resample_uniform({"u": (t, v)}, 25.0, label="b")])
    with pytest.raises(ConfigError, match=r"record 1 \('c'\) has signals w; record 0 has u"):
        concatenate([a, resample_uniform({"w": (t, v)}, 50.0, label="c")])
    with pytest.raises(ConfigError, match="no records"):
        concatenate([])


# --------------------------------------------------------------------------------------------
# (e) property: interpolation never overshoots its two neighbours
# --------------------------------------------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(
    dts=st.lists(st.floats(1e-3, 0.3), min_size=1, max_size=80),
    values=st.lists(st.floats(-1e3, 1e3), min_size=81, max_size=81),
    t0=st.floats(-100.0, 100.0),
    fs=st.floats(1.0, 200.0),
    max_gap=st.floats(0.0, 0.3),
)
def test_valid_samples_lie_between_their_neighbouring_source_samples(dts, values, t0, fs, max_gap):
    t = t0 + np.concatenate(([0.0], np.cumsum(dts)))
    assume(np.all(np.diff(t) > 0) and (t[-1] - t[0]) * fs >= 1.0 + 1e-6)
    v = np.asarray(values[: t.size])
    rec = resample_uniform({"x": (t, v)}, fs, max_interp_gap_s=max_gap)
    g, y, ok = rec.t_s, rec.signal("x"), rec.valid_of("x")
    assert g[0] == t[0] and g[-1] <= t[-1] + 1e-9
    k = np.clip(np.searchsorted(t, g, side="right") - 1, 0, t.size - 2)
    lo = np.minimum(v[k], v[k + 1])
    hi = np.maximum(v[k], v[k + 1])
    tol = 1e-9 * (1.0 + np.abs(v).max())
    assert np.all((y[ok] >= lo[ok] - tol) & (y[ok] <= hi[ok] + tol))
    # an invalid sample sits strictly inside an interval longer than the limit, and is NaN
    dt = np.diff(t)
    limit = max(max_gap, 1.5 * np.median(dt))
    bad = ~ok
    assert np.all(np.isnan(y[bad]))
    assert np.all((dt[k[bad]] > limit) & (g[bad] > t[k[bad]]) & (g[bad] < t[k[bad] + 1]))
    assert rec.repairs["x"].samples_excluded == int(bad.sum())


def test_resample_imports_no_io_package():
    code = ("import sys, livesweep.consistency.resample; "
            "print([m for m in ('mcap', 'pymavlink', 'zenoh', 'rerun', 'livesweep.telemetry') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
