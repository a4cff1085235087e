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


@pytest.mark.slow
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


def test_one_stamp_a_few_seconds_ahead_neither_shifts_the_clock_nor_is_released():
    """4 s ahead at 100 Hz is within what the receive clock allows (5 s of slack), yet one stamp must
    not move the clock (it used to: the genuine stamps after it then re-anchored 5 s late)."""
    c = StampClock(1e-6, establish=True)
    raw = [10_000_000 + 10_000 * k for k in range(60)]
    raw[30] += 4_000_000
    t = feed_all(c, raw, dt_rx=0.01)
    assert t[30] is None and c.rejected == 1 and c.resets == 0 and c.offset_s == 0.0
    np.testing.assert_allclose([x for k, x in enumerate(t) if k != 30],
                               [r * 1e-6 for k, r in enumerate(raw) if k != 30], atol=1e-9)


def test_a_real_gap_releases_the_sample_after_it():
    """The link drops 3 s: the first stamp after the gap is held until the next one goes on from it."""
    c = StampClock(1e-6, establish=True)
    raw = [10_000_000 + 10_000 * k for k in range(20)] + [13_200_000 + 10_000 * k for k in range(20)]
    out = []
    for k, r in enumerate(raw):
        rx = k * 0.01 + (3.0 if k >= 20 else 0.0)
        out += [idx for _, idx in c.feed(r, rx, k)]
    assert out == list(range(40)) and c.rejected == 0 and c.resets == 0


# ----------------------------------------------------------------------------- aligner: the frames alone decide


def two_topics(lag_s=0.6, n=500, sysid=1):
    """Signal a on /a and b on /b, 50 Hz, b's frames arriving lag_s after a's (a late link)."""
    st = 1_000_000 + 20_000 * np.arange(n)
    fa = [Frame("/a", int(k * 0.02e9), None, {"sysid": sysid, "compid": 1, "t": int(s), "x": np.sin(s * 1e-6)})
          for k, s in enumerate(st)]
    fb = [Frame("/b", int((k * 0.02 + lag_s) * 1e9), None, {"sysid": sysid, "compid": 1, "t": int(s),
                                                           "x": np.cos(s * 1e-6)}) for k, s in enumerate(st)]
    return sorted(fa + fb, key=lambda f: f.receive_ns)


def blocks_with_pops_every(frames, every):
    al = GridAligner({"a": spec("a", "/a"), "b": spec("b", "/b")}, ["a", "b"], 50.0)
    out = []
    for k, f in enumerate(frames):
        al.push(f)
        if (k + 1) % every == 0 or k == len(frames) - 1:
            while (b := al.pop_ready()) is not None:
                out.append(b)
    return al, out


def test_what_the_aligner_emits_does_not_depend_on_when_it_is_asked():
    """The same frames, popped after every frame (a busy live link) and every 500 frames (a replay):
    the same grid samples, the same values, the same gaps and late drops."""
    frames = two_topics()
    (a1, b1), (a2, b2) = blocks_with_pops_every(frames, 1), blocks_with_pops_every(frames, 500)
    for al_blocks in (b1, b2):
        assert al_blocks
    v1, v2 = np.hstack([b.values for b in b1]), np.hstack([b.values for b in b2])
    ok1, ok2 = np.concatenate([b.valid for b in b1]), np.concatenate([b.valid for b in b2])
    assert b1[0].t0_s == b2[0].t0_s and v1.shape == v2.shape
    np.testing.assert_array_equal(ok1, ok2)
    np.testing.assert_array_equal(v1[:, ok1], v2[:, ok2])
    assert a1.counts == a2.counts and ok1.mean() > 0.95


def test_clocks_of_one_vehicle_re_anchor_together_at_a_reboot():
    """A reboot seen on two messages at different rates (servo 50 Hz, IMU 100 Hz): both continue with
    one offset, so the pair stays aligned to the sample across the reboot."""
    al = GridAligner({"a": spec("a", "/a"), "b": spec("b", "/b")}, ["a", "b"], 50.0)
    boot1 = 5_000_000 + 10_000 * np.arange(1000)              # 10 s of boot clock, then a reboot to 0.25 s
    boot2 = 250_000 + 10_000 * np.arange(1000)
    frames = []
    for part, (stamps, rx0) in enumerate(((boot1, 0.0), (boot2, 12.0))):
        for k, s in enumerate(stamps):
            rx = rx0 + k * 0.01
            frames.append(Frame("/b", int(rx * 1e9), None, {"sysid": 1, "compid": 1, "t": int(s), "x": float(s)}))
            if k % 2 == 0:
                frames.append(Frame("/a", int(rx * 1e9), None, {"sysid": 1, "compid": 1, "t": int(s), "x": float(s)}))
    blocks = []
    for f in frames:
        al.push(f)
        while (b := al.pop_ready()) is not None:
            blocks.append(b)
    v = np.hstack([b.values for b in blocks])
    ok = np.concatenate([b.valid for b in blocks])
    assert al.counts["resets"] == 2                            # one per clock, one shared offset
    np.testing.assert_allclose(v[0, ok], v[1, ok], atol=1e-6)  # both carry their own stamp: equal when aligned
    assert ok[-200:].all()


def test_a_strangers_frames_arriving_first_choose_nothing():
    """A few frames of system 2 before system 1's stream: system 1 (the one sending every mapped
    message for the settling time) is analysed from its first frame, exactly as if alone."""
    one, two = two_topics(0.0, 300, sysid=1), two_topics(0.0, 300, sysid=2)
    stranger = [f for f in two if f.topic == "/b"][:5]
    alone = GridAligner({"a": spec("a", "/a"), "b": spec("b", "/b")}, ["a", "b"], 50.0)
    mixed = GridAligner({"a": spec("a", "/a"), "b": spec("b", "/b")}, ["a", "b"], 50.0)
    got = {}
    for name, al, frames in (("alone", alone, one), ("mixed", mixed, stranger + one)):
        for f in frames:
            al.push(f)
        al.settle_choice()
        got[name] = np.hstack([b.values for b in iter(al.pop_ready, None)])
    assert mixed.system == 1 and mixed.counts["other_system"] == 5 and mixed.counts["frames_used"] == 600
    np.testing.assert_array_equal(got["mixed"], got["alone"])


def test_a_named_system_is_analysed_whoever_comes_first():
    one, two = two_topics(0.0, 300, sysid=1), two_topics(0.0, 300, sysid=2)
    al = GridAligner({"a": spec("a", "/a"), "b": spec("b", "/b")}, ["a", "b"], 50.0, system=(2, None))
    for f in sorted(one + two, key=lambda f: f.receive_ns):
        al.push(f)
    assert al.system == 2 and al.choice == "named"
    assert al.counts["other_system"] == 600 and al.counts["frames_used"] == 600


def test_dotted_fields_are_read_live_as_offline():
    """``gyro.x`` and ``servo.1`` (nested objects, lists) reach the aligner as they reach read_fields."""
    sigs = {"a": SignalSpec(name="a", topic="/n", field="gyro.x", stamp="t", stamp_scale=1e-6),
            "b": SignalSpec(name="b", topic="/n", field="servo.1", stamp="t", stamp_scale=1e-6)}
    al = GridAligner(sigs, ["a", "b"], 50.0)
    for k in range(200):
        al.push(Frame("/n", int(k * 0.02e9), None, {"t": 1_000_000 + 20_000 * k, "gyro": {"x": 0.5 * k},
                                                    "servo": [0, 2.0 * k]}))
    b = al.pop_ready()
    assert b is not None and b.valid.all() and al.counts["missing_field"] == 0
    np.testing.assert_allclose(b.values[1], 4 * b.values[0])
