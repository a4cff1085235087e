"""A radio drops frames: 2 % of a recording lost at random changes no verdict that is not marginal.

Recordings: the shipped XV-15 aileron sweeps (two test points found by the sweep itself), and the
shared ArduCopter SITL SystemID roll chirp as its telemetry arrives over MAVLink (whole, and cut a
third of the way through). Each is replayed whole, then with 2 % of its messages (any topic: data,
SystemID texts, parameters, heartbeats) taken out at random with the standard mcap reader and
writer, for several seeds. Reference: the whole recording's own verdicts; a test point that reads
"(marginal)" there is allowed to go either way, every other one must not move.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers import copy_mcap_without
from livesweep.cli import _monitor_settings, build_parser
from livesweep.monitor.pipeline import MonitorPipeline
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.recorder import McapRecorder
from livesweep.telemetry.replay import McapReplaySource
from livesweep.telemetry.stream_log import dataflash_messages

pytestmark = pytest.mark.slow                 # every test of this module takes over 1 s

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" if (ROOT.parent / "shared" / "data").is_dir() else Path("/work/shared/data")
SID7 = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
SEEDS = (1, 2, 3, 4)


def _settings(*args):
    return _monitor_settings(build_parser().parse_args(["replay", "x.mcap", *args]))


def _drop(src: Path, out: Path, fraction: float, seed: int) -> int:
    """Copy a recording without ``fraction`` of its messages (livesweep's own results aside)."""
    rng = np.random.default_rng(seed)
    return copy_mcap_without(src, out, lambda topic, data: not topic.startswith("/livesweep/")
                             and rng.random() < fraction)


def _verdicts(log: Path, settings) -> list[tuple]:
    s = MonitorPipeline(settings, [McapReplaySource(log)], keep_estimates=False).run()
    return [(tp["swept_input"], tp["verdict"], tp["marginal"], round(tp["start_s"], 1)) for tp in s["test_points"]]


def _with_frames_lost(log: Path, settings, tmp: Path) -> tuple[list, list]:
    """The test points of ``log`` replayed whole, and per seed of :data:`SEEDS` with 2 % of its
    frames lost at random: ``(whole, [(seed, frames lost, test points), ...])``, each test point
    ``(swept input, verdict, marginal, start [s])``."""
    whole = _verdicts(log, settings)
    runs = []
    for seed in SEEDS:
        out = tmp / f"drop{seed}.mcap"
        n = _drop(log, out, 0.02, seed)
        runs.append((seed, n, _verdicts(out, settings)))
    return whole, runs


def _disagreements(whole: list, got: list) -> list:
    """Where ``got`` differs from ``whole``: another number of test points, another input or start
    (by over 1.5 s), or another verdict of a test point that was not marginal."""
    if len(got) != len(whole):
        return [("test points", len(whole), len(got))]
    return [(a, b) for a, b in zip(whole, got)
            if b[0] != a[0] or abs(b[3] - a[3]) >= 1.5 or (not a[2] and b[1] != a[1])]


def test_the_xv15_sweeps_keep_their_verdicts_when_frames_are_lost(tmp_path):
    whole, runs = _with_frames_lost(
        ROOT / "replay_logs" / "xv15_cruise_sweeps_da.mcap",
        _settings("--case", str(ROOT / "config" / "xv15_channels.toml"), "--window", "240", "--require", "p/da"),
        tmp_path)
    assert [v for _, v, _, _ in whole] == ["GO", "GO"], whole
    for seed, lost, got in runs:
        assert lost > 100 and _disagreements(whole, got) == [], (seed, lost, got, whole)


@pytest.fixture(scope="module")
def sitl_recordings(tmp_path_factory):
    """The SystemID roll chirp as its 50 Hz telemetry arrives, recorded by the monitor (whole, and
    cut a third of the way into the chirp)."""
    if not SID7.is_file():
        pytest.skip(f"third-party log not found: {SID7}")
    tmp = tmp_path_factory.mktemp("sitl_drop")
    settings = _settings("--map", "ardupilot-copter-pid")
    out = {}
    for name, end_s in (("whole", 98.0), ("cut", 78.571892 + 50.0 / 3 - 43.384306)):
        frames, first = [], None
        for t, msg, rec in dataflash_messages(SID7, start_s=30.0, end_s=end_s, rate_hz=50.0):
            first = t if first is None else first
            r = codec.record_from_fields(msg, {k: v for k, v in rec.items() if k not in ("sysid", "compid")},
                                         sysid=rec["sysid"], compid=rec["compid"])
            frames.append(Frame(f"/mavlink/{msg}", 1_800_000_000 * 10**9 + int((t - first) * 1e9),
                                codec.vehicle_time_ns(r, msg), r))

        class Frames:
            live, finished, counts = False, False, {}

            def poll(self, timeout_s=0.05, max_frames=2000):
                nonlocal frames
                got, frames = frames[:max_frames], frames[max_frames:]
                self.finished = not frames
                return got

            def close(self):
                pass

        log = tmp / f"{name}.mcap"
        MonitorPipeline(settings, [Frames()], recorder=McapRecorder(log, settings=settings.to_dict()),
                        keep_estimates=False).run()
        out[name] = log
    return settings, out


@pytest.mark.parametrize("name, want", [("whole", ["GO"]), ("cut", ["NO-GO"])])
def test_the_systemid_chirp_keeps_its_verdict_when_frames_are_lost(sitl_recordings, name, want, tmp_path):
    settings, logs = sitl_recordings
    whole, runs = _with_frames_lost(logs[name], settings, tmp_path)
    assert [v for _, v, _, _ in whole] == want, whole
    for seed, lost, got in runs:
        assert lost > 100 and _disagreements(whole, got) == [], (seed, lost, got, whole)
