"""``livesweep.monitor()``: the live monitor as a library call, with real components only.

A simulated aileron sweep goes out as real MAVLink 2 datagrams on 127.0.0.1 into
``livesweep.monitor("udp:127.0.0.1:0", case=...)``. Independent references: what the run recorded on
its MCAP's ``/livesweep/<name>`` channels (read with the ``mcap`` package's own reader and
``json``), the datagrams the sender counted, and ``livesweep.replay()`` of the recording.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import livesweep
from livesweep.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "config" / "xv15_channels.toml"
CHANNELS = ("test_point", "verdict", "alert")


def read_channels(path) -> dict[str, list[dict]]:
    """The ``/livesweep/<name>`` messages of ``path`` in the order written, decoded by the mcap
    package and json."""
    from mcap.reader import make_reader

    out = {name: [] for name in CHANNELS}
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(topics=[f"/livesweep/{n}" for n in CHANNELS],
                                                                    log_time_order=False):
            out[channel.topic.rsplit("/", 1)[1]].append((message.sequence, json.loads(message.data)))
    return {n: [d for _seq, d in sorted(v, key=lambda m: m[0])] for n, v in out.items()}


def assert_close(got, want, where="", rel=1e-6, abs_=1e-9):
    """Field by field: the same keys, strings, bools and None; numbers within ``rel`` or ``abs_``
    (NaN, written ``"NaN"``, equal to itself)."""
    if isinstance(want, dict):
        assert isinstance(got, dict) and set(got) == set(want), (where, sorted(set(got) ^ set(want)))
        for k in want:
            assert_close(got[k], want[k], f"{where}.{k}", rel, abs_)
    elif isinstance(want, list):
        assert isinstance(got, list) and len(got) == len(want), (where, got, want)
        for k, (g, w) in enumerate(zip(got, want)):
            assert_close(g, w, f"{where}[{k}]", rel, abs_)
    elif isinstance(want, (int, float)) and not isinstance(want, bool):
        assert isinstance(got, (int, float)) and not isinstance(got, bool), (where, got, want)
        assert math.isclose(got, want, rel_tol=rel, abs_tol=abs_), (where, got, want)
    else:
        assert got == want, (where, got, want)


def sweep_records(seed: int = 4, duration_s: float = 45.0) -> list[tuple]:
    """(vehicle time [s], message name, record) of a simulated XV-15 aileron sweep, in time order."""
    from livesweep.sim.scenario import simulate, sweep_scenario
    from livesweep.telemetry.sim_telemetry import mavlink_timeline

    res = simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=0.5, omega_max_rad_s=20.0,
                                  duration_s=duration_s, amplitudes={"da": 3.0}, off_axis_rms=0.3, seed=seed))
    recs, _ = mavlink_timeline(res)
    recs.sort(key=lambda r: (r.vehicle_time_ns, r.msgname))
    return [(r.vehicle_time_ns * 1e-9, r.msgname, r.record) for r in recs if r.msgname != "HEARTBEAT"]


@pytest.fixture(scope="module")
def live_run(tmp_path_factory):
    """The sweep streamed at 8x real time into the library's monitor, which records ``x.mcap``;
    returns (monitor, its summary, datagrams sent per message, what it showed while running, path)."""
    from livesweep.telemetry.mavlink_out import MavlinkSender, stream_records

    rec = tmp_path_factory.mktemp("live") / "x.mcap"
    live = livesweep.monitor("udp:127.0.0.1:0", case=CASE, record=rec)
    port = int(live.urls[0].rsplit(":", 1)[1])
    items = sweep_records()
    sent: dict = {}

    def send():
        tx = MavlinkSender(f"udpout:127.0.0.1:{port}")
        try:
            sent.update(stream_records(tx, items, speed=8.0)["counts"])
        finally:
            tx.close()

    with live:
        sender = threading.Thread(target=send)
        sender.start()
        sender.join(300)
        time.sleep(1.0)                          # what is still in flight
        while_running = {"running": live.running, "counters": live.counters, "verdict": live.verdict,
                         "test_points": live.test_points}
        summary = live.stop()
    return live, summary, sent, while_running, rec


@pytest.mark.slow
def test_the_monitors_results_are_what_its_recording_carries(live_run):
    live, summary, sent, _, rec = live_run
    assert summary["frames"] == sum(sent.values()) > 10_000          # every datagram the sender counted
    recorded = read_channels(rec)
    assert recorded["test_point"] == list(live.test_points)
    assert recorded["verdict"] == list(live.verdicts)
    assert recorded["alert"] == list(live.alerts)
    assert live.events and [p for n, p in live.events if n == "test_point"] == list(live.test_points)
    (tp,) = live.test_points                                        # the one sweep, closed and judged
    assert tp["swept_input"] == "da" and tp["state"] == "closed" and tp["verdict"] in ("GO", "NO-GO")
    assert live.verdict == summary["verdict"] == recorded["verdict"][-1]["verdict"] == tp["verdict"]
    assert live.counters == summary["counters"]
    assert live.recording == rec and live.layout == rec.with_suffix(".foxglove.json") and live.layout.is_file()


@pytest.mark.slow
def test_results_could_be_read_while_it_ran(live_run):
    _, summary, sent, while_running, _ = live_run
    assert while_running["running"] is True
    (src,) = while_running["counters"]["sources"]                  # the recorder process's UDP link
    assert 0 < sum(src["received"].values()) <= sum(sent.values())
    assert while_running["verdict"] in ("WAIT", "GO", "NO-GO")
    assert len(while_running["test_points"]) <= len(summary["test_points"])


@pytest.mark.slow
def test_a_replay_of_the_recording_gives_the_same_test_points(live_run):
    live, _, _, _, rec = live_run
    r = livesweep.replay(rec)
    assert r.settings_source == "recording" and r.settings == live.settings
    assert len(r.test_points) == len(live.test_points) == 1
    for got, want in zip(r.test_points, live.test_points):
        assert_close(got, want, "test_point")
    assert r.verdict == live.verdict


def test_stop_is_idempotent_and_a_with_block_stops(tmp_path):
    live = livesweep.monitor(["udpin:127.0.0.1:0"], case=CASE)
    assert live.running and live.summary is None
    first = live.stop()
    assert not live.running and live.stop() is first and live.summary is first
    assert first["frames"] == 0 and first["test_points"] == [] and live.verdict is None
    with livesweep.monitor("udpin:127.0.0.1:0", case=CASE, record=tmp_path / "quiet.mcap") as quiet:
        assert quiet.running
    assert not quiet.running and quiet.stop()["recorded"] is not None
    assert (tmp_path / "quiet.mcap").is_file()


@pytest.mark.parametrize("spec, words", [
    ("bogus", "source 'bogus' is neither a MAVLink input url"),
    ("flight.mcap", "source 'flight.mcap' is neither a MAVLink input url"),
    ("zenoh:", "source 'zenoh:': give the Zenoh key expression"),
    ("udpout:127.0.0.1:14550", "'udpout:127.0.0.1:14550': udpout sends; a monitor receives"),
    ("udp:127.0.0.1:99999", "'udp:127.0.0.1:99999': port 99999 is not in 1..65535"),
    (Path("flight.mcap"), "source 'flight.mcap' is a file, not a live link"),
])
def test_a_bad_source_spec_is_one_line_naming_it(spec, words):
    with pytest.raises(ConfigError) as e:
        livesweep.monitor(["udpin:127.0.0.1:0", spec], case=CASE)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_livesweep_monitor_is_callable_whatever_was_imported_first():
    """``livesweep.monitor`` is also the monitor's subpackage: it stays callable when the package
    was imported before, and the subpackage's modules stay reachable through it."""
    code = ("import livesweep.monitor.pipeline as p, livesweep\n"
            "assert callable(livesweep.monitor) and livesweep.monitor.pipeline is p\n"
            "from livesweep import monitor\n"
            "assert monitor is livesweep.monitor and livesweep.Monitor.__name__ == 'Monitor'\n"
            "try:\n    monitor('bogus')\nexcept livesweep.monitor.session.ConfigError as e:\n    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("source 'bogus' is neither")


@pytest.mark.slow
def test_the_example_runs_as_a_user_runs_it(tmp_path):
    """examples/monitor_live.py: the simulated sweep over UDP into livesweep.monitor(), one test
    point closed GO, and the verdict it prints is the one its recording carries."""
    rec = tmp_path / "live.mcap"
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "monitor_live.py"), "--record", str(rec)],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.strip().splitlines()
    assert lines[-1] == "verdict: GO" and any(ln.startswith("test point: da sweep") for ln in lines)
    assert read_channels(rec)["verdict"][-1]["verdict"] == "GO"
