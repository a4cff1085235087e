"""The monitor's aligner: one clock (wrap, reboot), multi-rate alignment, gaps, order independence,
memory bounded whatever the stamps say."""

from pathlib import Path

import numpy as np
import pytest

from livesweep.config import SignalSpec, load_case
from livesweep.consistency.resample import resample_uniform
from livesweep.errors import ConfigError
from livesweep.telemetry.align import GridAligner
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.replay import McapReplaySource
from livesweep.telemetry.signals import read_signals

ROOT = Path(__file__).resolve().parents[1]


def spec(field, topic="/t"):
    return SignalSpec(name=field, topic=topic, field=field, stamp="ms", stamp_scale=1e-3)


def frames_for(topic, field, t_ms, values):
    return [Frame(topic, int(k * 1e6), None, {"ms": int(tm), field: float(v)}) for k, (tm, v) in enumerate(zip(t_ms, values))]


def test_multirate_signals_are_aligned_and_gaps_excluded():
    sigs = {"x": spec("x", "/a"), "y": spec("y", "/b")}
    al = GridAligner(sigs, ["x", "y"], 50.0)
    ta = np.arange(0, 20_000, 10)            # 100 Hz
    tb = np.arange(0, 20_000, 20)            # 50 Hz
    tb = tb[(tb < 8_000) | (tb > 8_600)]     # 0.6 s gap on y
    fa = frames_for("/a", "x", ta, np.sin(ta * 1e-3))
    fb = frames_for("/b", "y", tb, np.cos(tb * 1e-3))
    arrivals = sorted(fa + fb, key=lambda f: f.data["ms"])
    blocks = []
    for i in range(0, len(arrivals), 37):                 # arrival in time order, odd-sized bursts
        for f in arrivals[i:i + 37]:
            al.push(f)
        b = al.pop_ready()
        if b is not None:
            blocks.append(b)
    v = np.hstack([b.values for b in blocks])
    ok = np.concatenate([b.valid for b in blocks])
    tg = blocks[0].t0_s + np.arange(v.shape[1]) / 50.0
    np.testing.assert_allclose(v[0, ok], np.sin(tg[ok]), atol=2e-4)       # linear interpolation error bound
    np.testing.assert_allclose(v[1, ok], np.cos(tg[ok]), atol=1e-12)      # on its own grid: exact
    assert np.all(~ok[(tg > 8.0) & (tg < 8.6)]) and np.all(ok[(tg < 7.98) | (tg > 8.62)])
    assert al.counts["samples_invalid"] == np.sum(~ok)


def test_a_silent_channel_does_not_stall_the_others():
    sigs = {"x": spec("x", "/a"), "y": spec("y", "/b")}
    al = GridAligner(sigs, ["x", "y"], 50.0, gap_timeout_s=0.5)
    for f in frames_for("/a", "x", np.arange(0, 1000, 20), np.ones(50)) + frames_for("/b", "y", np.arange(0, 1000, 20), np.ones(50)):
        al.push(f)
    b1 = al.pop_ready()
    for f in frames_for("/a", "x", np.arange(1000, 5000, 20), np.ones(200)):   # y goes silent
        al.push(f)
    b2 = al.pop_ready()
    assert b2 is not None and b2.t0_s == pytest.approx(b1.t0_s + b1.values.shape[1] / 50.0)
    t_end = b2.t0_s + (b2.values.shape[1] - 1) / 50.0
    assert t_end == pytest.approx(4.98 - 0.5, abs=0.02)
    assert not b2.valid[-1]


def test_mixed_clocks_are_refused():
    sigs = {"x": spec("x"), "y": SignalSpec(name="y", topic="/t", field="y")}
    with pytest.raises(ConfigError, match="share one clock"):
        GridAligner(sigs, ["x", "y"], 50.0)


@pytest.mark.slow
def test_replayed_log_aligns_like_the_batch_resampler():
    case = load_case(ROOT / "config" / "xv15_cruise_lateral.toml")
    names = ["da", "dr", "p", "r", "ay", "beta"]
    al = GridAligner(case.signals, names, 50.0)
    src = McapReplaySource(case.identify[0].log)
    blocks = []
    while not src.finished:
        for f in src.poll(max_frames=997):
            al.push(f)
        b = al.pop_ready()
        if b is not None:
            blocks.append(b)
    live = np.hstack([b.values for b in blocks])
    raw = read_signals(case.identify[0], case.signals, names)
    batch = resample_uniform({n: (s.t_s, s.values) for n, s in raw.items()}, 50.0)
    assert blocks[0].t0_s == batch.t0_s
    n = min(live.shape[1], batch.values.shape[1])
    assert n >= batch.values.shape[1] - 1
    # the aligner snaps stamps within 0.1 us onto the grid; the batch resampler interpolates a
    # round-off away from them: the two agree to ~1e-12
    np.testing.assert_allclose(live[:, :n], batch.values[:, :n], rtol=0, atol=1e-9)
