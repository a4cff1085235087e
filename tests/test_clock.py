"""Time at the edge: the guarded stamp clock and the aligner's memory whatever the stamps say.

The references are the stamps themselves: a regular stream of known spacing, a reboot at a known
sample, a wrap at 2**32 µs, and poison stamps placed at known indices.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from livesweep.config import SignalSpec
from livesweep.telemetry.align import GridAligner
from livesweep.telemetry.clock import ReceiveClock, StampClock
from livesweep.telemetry.frames import Frame


def feed_all(clock, raws, dt_rx=0.02):
    """Continuous times per sample (None where held back and never released)."""
    out = [None] * len(raws)
    for k, r in enumerate(raws):
        for t, idx in clock.feed(r, k * dt_rx, k):
            out[idx] = t
    return out


def test_uint32_wrap_is_unwrapped_and_a_reboot_re_anchors_after_the_gap():
    c = StampClock(1e-6, wrap_units=2**32, establish=True)
    raw = list((np.arange(0, 200) * 20_000 + 2**32 - 2_000_000) % 2**32)        # wraps after 100 samples
    raw += [300_000 + 20_000 * k for k in range(10)]                             # reboot: 0.3 s after boot
    t = feed_all(c, raw)
    assert None not in t                           # the first anchor and the reboot release what they held
    np.testing.assert_allclose(np.diff(t[:200]), 0.02, atol=1e-9)
    assert c.wraps == 1 and c.resets == 1 and c.rejected == 0
    assert t[200] == pytest.approx(t[199] + 1.0)   # the new clock starts reset_gap_s after the last sample
    np.testing.assert_allclose(np.diff(t[200:]), 0.02, atol=1e-9)


def test_a_uint64_stamp_near_2_32_is_not_a_wrap():
    c = StampClock(1e-6, wrap_units=None)
    raw = [2**32 - 40_000 + 20_000 * k for k in range(6)]        # crosses 2**32 µs: a uint64 just goes on
    t = feed_all(c, raw)
    np.testing.assert_allclose(np.diff(t), 0.02, atol=1e-9)
    assert c.wraps == 0 and c.resets == 0


@pytest.mark.parametrize("poison", [2**64 - 1, 116 * 86_400 * 10**6, 1_700_000_000 * 10**6, 1])
def test_one_poison_stamp_is_dropped_and_does_not_move_the_clock(poison):
    c = StampClock(1e-6, establish=True)
    raw = [10_000_000 + 20_000 * k for k in range(30)]
    raw[15] = poison
    t = feed_all(c, raw)
    assert t[15] is None and c.rejected == 1 and c.resets == 0
    good = [x for k, x in enumerate(t) if k != 15]
    np.testing.assert_allclose(good, [r * 1e-6 for k, r in enumerate(raw) if k != 15], rtol=0, atol=1e-9)


def test_a_bad_first_stamp_never_becomes_the_reference():
    c = StampClock(1e-6, establish=True)
    raw = [2**63] + [5_000_000 + 20_000 * k for k in range(10)]
    t = feed_all(c, raw)
    assert t[0] is None and c.rejected == 1
    np.testing.assert_allclose(t[1:], [r * 1e-6 for r in raw[1:]], atol=1e-9)


def test_faster_than_real_time_streams_are_plausible():
    """A replay or simulator at 50x: vehicle time runs 50 s per receive second."""
    c = StampClock(1e-3)
    t = feed_all(c, [1000 * k for k in range(100)], dt_rx=0.02)           # 1 s of stamps every 20 ms
    assert None not in t and c.rejected == 0


def test_receive_clock_is_unix_time_and_never_steps_back():
    rc = ReceiveClock()
    a = rc.now_ns()
    b = rc.now_ns()
    assert abs(a - time.time_ns()) < 10**9 and b >= a


# ----------------------------------------------------------------------------- aligner memory


def frames(topic, stamps_us, values, t_rx0=0.0, dt_rx=0.02):
    return [Frame(topic, int((t_rx0 + k * dt_rx) * 1e9), None, {"t": int(s), "x": float(v)})
            for k, (s, v) in enumerate(zip(stamps_us, values))]


def run_aligner(al, fr):
    n = 0
    for f in fr:
        al.push(f)
        while (b := al.pop_ready()) is not None:
            n = max(n, b.values.shape[1])
    return n


def spec(name, topic):
    return SignalSpec(name=name, topic=topic, field="x", stamp="t", stamp_scale=1e-6)


def test_the_aligner_memory_is_bounded_whatever_the_stamps_say():
    """Back-steps and 1-3 h jumps mixed into two signals' stamps, a signal on the UNIX epoch next to
    one on the boot clock, and a signal 116 days ahead: no block is longer than max_fill_s and no
    signal keeps more than max_fill_s of samples (it asked for 640 GiB after two frames before)."""
    rng = np.random.default_rng(1)
    al = GridAligner({"a": spec("a", "/a"), "b": spec("b", "/b")}, ["a", "b"], 50.0, max_fill_s=30.0)
    stamps = 1_000_000 + 20_000 * np.arange(20_000)
    jumpy = stamps.copy()
    bad = rng.choice(len(jumpy), 400, replace=False)
    jumpy[bad] += rng.choice([-1, 1], 400) * rng.integers(3_600, 10_800, 400) * 10**6
    fa, fb = frames("/a", jumpy, np.sin(stamps * 1e-6)), frames("/b", stamps, np.cos(stamps * 1e-6))
    longest = run_aligner(al, [f for pair in zip(fa, fb) for f in pair])
    assert longest <= 30 * 50
    assert al.counts["clock_rejected"] == 400 and al.counts["resets"] == 0
    assert al.counts["samples_emitted"] >= 0.99 * 20_000 * 0.02 * 50

    epoch = GridAligner({"a": spec("a", "/a"), "b": spec("b", "/b")}, ["a", "b"], 50.0, max_fill_s=30.0)
    fa = frames("/a", stamps[:3000], np.zeros(3000))
    fb = frames("/b", 1_700_000_000 * 10**6 + stamps[:3000], np.zeros(3000))      # the UNIX epoch
    longest = run_aligner(epoch, [f for pair in zip(fa, fb) for f in pair])
    assert longest <= 30 * 50
    assert max(len(c.t) for c in epoch.ch.values()) <= 30 * 50 + 2

    ahead = GridAligner({"a": spec("a", "/a"), "b": spec("b", "/b")}, ["a", "b"], 50.0, max_fill_s=30.0)
    fa = frames("/a", stamps[:3000], np.zeros(3000))
    fb = frames("/b", stamps[:3000], np.zeros(3000))
    fb[1500] = Frame("/b", fb[1500].receive_ns, None, {"t": int(stamps[1500] + 116 * 86_400 * 10**6), "x": 0.0})
    longest = run_aligner(ahead, [f for pair in zip(fa, fb) for f in pair])
    assert longest <= 30 * 50 and ahead.counts["clock_rejected"] == 1 and ahead.counts["samples_invalid"] <= 2
