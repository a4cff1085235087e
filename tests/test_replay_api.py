"""``livesweep.replay()``: the monitor over a recording as a library call, as ``livesweep replay`` runs it.

Independent references: the test points, verdicts and alerts the live monitor recorded in the
demo's ``live.mcap`` (read here with the ``mcap`` package's own reader and ``json``), what the
command prints for the same log, the recording ``record=`` writes, and the command's own settings
resolution (``cli._monitor_settings``).
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

import livesweep
from livesweep.errors import ConfigError, LogFormatError

ROOT = Path(__file__).resolve().parents[1]
SID7 = Path("ardupilot_sitl_systemid") / "sid_axis7_rate_roll.bin"
SYSID_MAP = "ardupilot-sysid-dataflash"
CHANNELS = ("test_point", "verdict", "alert")


def shared_data() -> Path:
    for base in (ROOT.parent / "shared" / "data", Path("/work/shared/data")):
        if base.is_dir():
            return base
    pytest.skip("../shared/data is absent")


def read_channels(path) -> dict[str, list[dict]]:
    """The ``/livesweep/<name>`` messages of ``path`` in log order, decoded by the mcap package and json."""
    from mcap.reader import make_reader

    out = {name: [] for name in CHANNELS}
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(topics=[f"/livesweep/{n}" for n in CHANNELS],
                                                                    log_time_order=False):
            out[channel.topic.rsplit("/", 1)[1]].append((message.log_time, message.sequence, json.loads(message.data)))
    return {n: [d for _t, _seq, d in sorted(v, key=lambda m: m[1])] for n, v in out.items()}   # written order


def assert_same(got, want, where="", rel=1e-9):
    """Field by field: the same keys, strings, ints and None; floats within ``rel`` (or both NaN)."""
    if isinstance(want, dict):
        assert isinstance(got, dict) and set(got) == set(want), (where, sorted(set(got) ^ set(want or {})))
        for k in want:
            assert_same(got[k], want[k], f"{where}.{k}", rel)
    elif isinstance(want, list):
        assert isinstance(got, list) and len(got) == len(want), (where, got, want)
        for k, (g, w) in enumerate(zip(got, want)):
            assert_same(g, w, f"{where}[{k}]", rel)
    elif isinstance(want, float) and not isinstance(want, bool):
        assert isinstance(got, (int, float)) and not isinstance(got, bool), (where, got, want)
        assert got == pytest.approx(want, rel=rel, abs=1e-12) or (math.isnan(got) and math.isnan(want)), \
            (where, got, want)
    else:
        assert got == want and type(got) is type(want), (where, got, want)


# --- the demo's live recording -------------------------------------------------------------------

@pytest.fixture(scope="module")
def demo_log(tmp_path_factory):
    """``livesweep demo`` run once: its ``live.mcap``, recorded live by the monitor."""
    out = tmp_path_factory.mktemp("demo") / "livesweep-demo"
    r = subprocess.run([sys.executable, "-m", "livesweep", "demo", "--out", str(out)], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return out / "live.mcap"


@pytest.mark.slow
def test_replay_of_the_demo_recording_gives_the_test_points_recorded_live(demo_log):
    live = read_channels(demo_log)
    r = livesweep.replay(demo_log)
    assert isinstance(r, livesweep.ReplayResult)
    # the settings the demo's monitor attached, not the packaged map's defaults (its window is 240 s)
    from livesweep.monitor.session import recorded_settings

    assert r.settings_source == "recording" and r.settings == recorded_settings(demo_log)
    assert r.settings.window_s == 240.0 and r.settings.required_pairs == (("p", "da"),)
    # two aileron sweeps, each a GO test point, live and replayed: equal field by field
    assert [(tp["swept_input"], tp["verdict"]) for tp in live["test_point"]] == [("da", "GO"), ("da", "GO")]
    assert_same(list(r.test_points), live["test_point"], "test_points")
    assert_same(list(r.verdicts), live["verdict"], "verdicts")
    assert_same(list(r.alerts), live["alert"], "alerts")
    assert r.verdict == live["verdict"][-1]["verdict"] == "GO"
    # the counters the command prints: one source (the log), every frame received, none shed, nothing recorded
    (src,) = r.counters["sources"]
    assert src["name"] == str(demo_log) and sum(src["replayed"].values()) == r.summary["frames"] > 0
    assert r.counters["pipeline"]["frames_received"] == r.summary["frames"] and r.recording is None
    assert r.counters["pipeline"]["analysis_shed"] == 0 and r.counters["aligner"] == r.summary["aligner"]
    assert r.link is not None and r.link["frames_recorded"] == r.summary["frames"]
    assert r.summary["recorded"] is None


# --- the shared ArduPilot SystemID log ------------------------------------------------------------

@pytest.fixture(scope="module")
def sid7(tmp_path_factory):
    from livesweep.convert import convert

    src = shared_data() / SID7
    out = tmp_path_factory.mktemp("sid") / "sid7.mcap"
    convert(src, out)
    return out


@pytest.fixture(scope="module")
def sid7_replay(sid7, tmp_path_factory):
    rec = tmp_path_factory.mktemp("sid_rec") / "replayed.mcap"
    return livesweep.replay(sid7, map=SYSID_MAP, record=rec)


@pytest.mark.slow
def test_library_replay_of_a_systemid_log_prints_what_the_command_prints(sid7, sid7_replay):
    """The same log, `livesweep replay --map ...` in a process of its own: the same frames,
    estimates, data time, test-point lines and verdict as the library's result."""
    from livesweep.cli import _monitor_settings, build_parser
    from livesweep.monitor.text import test_point_line

    r = sid7_replay
    cli = subprocess.run([sys.executable, "-m", "livesweep", "replay", str(sid7), "--map", SYSID_MAP],
                         capture_output=True, text=True, timeout=600)
    assert cli.returncode == 0, cli.stderr[-2000:]
    lines = cli.stdout.splitlines()
    s = r.summary
    assert lines[0].startswith(f"monitor: {s['frames']} frames, {s['estimates']} estimates over {s['data_s']:.1f} s "
                               "of data in ")
    n = int(next(ln for ln in lines if ln.startswith("  test points: ")).split()[2])
    printed = [ln.strip() for ln in lines if ln.startswith("    TP")]
    assert n == len(r.test_points) == len(printed) == 4
    assert printed == [test_point_line(k, tp) for k, tp in enumerate(r.test_points, 1)]
    assert f"  verdict: {r.verdict}" in lines and r.verdict == "NO-GO"
    # ArduCopter's SystemID run on axis 7 (rate roll) is the one the filtered log holds RATE for: GO
    tp = r.test_points[0]
    assert (tp["source"], tp["swept_input"], tp["verdict"]) == ("autopilot", "roll", "GO")
    assert all(t["verdict"] == "NO-GO" and t["pairs"] == [] for t in r.test_points[1:])
    # the library chose the settings the command chooses for --map
    assert r.settings_source == "map"
    assert r.settings == _monitor_settings(build_parser().parse_args(["replay", str(sid7), "--map", SYSID_MAP]))


@pytest.mark.slow
def test_the_results_are_what_the_replays_recording_carries(sid7_replay):
    """``record=``: the recording holds the same test points, verdicts and alerts, JSON-equal, and its
    settings; replayed again from its own settings it gives the same test points."""
    r = sid7_replay
    assert r.recording is not None and r.recording.is_file()
    recorded = read_channels(r.recording)
    assert recorded["test_point"] == list(r.test_points)
    assert recorded["verdict"] == list(r.verdicts)
    assert recorded["alert"] == list(r.alerts) and {a["kind"] for a in r.alerts} == {"map"}
    assert r.summary["recorded"] and r.counters["pipeline"]["unrecordable"] == 0
    again = livesweep.replay(r.recording)
    assert again.settings_source == "recording" and again.settings == r.settings
    assert_same(list(again.test_points), list(r.test_points), "test_points")


@pytest.mark.slow
def test_the_systemid_example_prints_each_test_points_verdict(sid7_replay, tmp_path):
    shared_data()
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "replay_systemid.py"), "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    got = [(ln.split()[1], ln.split(": ", 1)[1].split()[0]) for ln in lines if ln.startswith("TP")]
    assert got == [(tp["swept_input"], tp["verdict"]) for tp in sid7_replay.test_points]
    assert lines[-1] == f"verdict: {sid7_replay.verdict}" and out.stderr == ""


def test_the_systemid_example_says_when_the_shared_data_is_absent(monkeypatch, capsys):
    spec = importlib.util.spec_from_file_location("replay_systemid", ROOT / "examples" / "replay_systemid.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    monkeypatch.setattr(mod, "shared_log", lambda: None)
    assert mod.main([]) is None
    assert capsys.readouterr().out.startswith("skipped: the shared data is absent")


# --- refusals, before any work -----------------------------------------------------------------

class _View:
    closed = 0

    def close(self):
        self.closed += 1


def test_replay_refuses_bad_input_in_one_line_and_closes_a_view_it_was_given(tmp_path):
    log = ROOT / "replay_logs" / "xv15_cruise_verify.mcap"
    view = _View()
    with pytest.raises(ConfigError, match="does not exist"):
        livesweep.replay(tmp_path / "missing.mcap", rerun=view)
    assert view.closed == 1
    with pytest.raises(ConfigError, match="give --case or --map, not both"):
        livesweep.replay(log, case=ROOT / "config" / "xv15_channels.toml", map=SYSID_MAP)
    with pytest.raises(ConfigError, match="no such preset"):
        livesweep.replay(log, map="nope")
    with pytest.raises(ConfigError, match="is the log being replayed"):
        livesweep.replay(log, record=log, overwrite=True)
    (tmp_path / "taken.mcap").write_bytes(b"")
    with pytest.raises(LogFormatError):
        livesweep.replay(log, record=tmp_path / "taken.mcap")
    with pytest.raises(ConfigError, match="replay speed"):
        livesweep.replay(log, speed=-1.0)
    assert log.is_file()


def test_replay_result_is_frozen_and_the_default_settings_are_the_packaged_map():
    from dataclasses import FrozenInstanceError

    from livesweep.cli import _monitor_settings, build_parser
    from livesweep.monitor.session import replay_settings

    log = ROOT / "replay_logs" / "xv15_cruise_verify.mcap"      # a simulator's log: no settings attached
    settings, source = replay_settings(log)
    assert source == "default" and settings == _monitor_settings(build_parser().parse_args(["replay", str(log)]))
    r = livesweep.ReplayResult(path=log, settings=settings, settings_source=source, test_points=(), verdicts=(),
                               alerts=(), counters={}, link=None, summary={"verdict": "WAIT"})
    with pytest.raises(FrozenInstanceError):
        r.verdicts = ()
    assert r.verdict == "WAIT"
