"""Loss is a reason: a test point whose frames were lost on the way says so first, with the fraction
lost over its own span, and a NO-GO on a large loss reads "NO-GO (link)".

Real components: a simulated sweep streamed as MAVLink 2 datagrams over UDP on 127.0.0.1 through
a "radio" that loses frames after giving them their sequence numbers (so the monitor's MAVLink
sequence count sees the holes), and a recording written by ``livesweep sim`` replayed with frames
taken out by the standard mcap reader and writer. Reference: the frames the test itself lost,
counted by their own time stamps over the span the monitor reports for the test point; the same
data without losses gives no loss reason.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import copy_mcap_without
from livesweep.config import load_channel_map
from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
from livesweep.monitor.status_line import format_status
from livesweep.monitor.text import markdown_test_points
from livesweep.sim.scenario import simulate, sweep_scenario
from livesweep.spectral.verdict import frames_missing
from livesweep.telemetry.mavlink_in import MavlinkSource
from livesweep.telemetry.mavlink_out import MavlinkSender, stream_records
from livesweep.telemetry.replay import McapReplaySource
from livesweep.telemetry.sim_telemetry import mavlink_timeline

ROOT = Path(__file__).resolve().parents[1]
SIGNALS, _ = load_channel_map(ROOT / "config" / "xv15_channels.toml")
SETTINGS = MonitorSettings(signals=SIGNALS, inputs=("da", "dr"), outputs=("p", "r", "ay"), band_rad_s=(1.0, 20.0),
                           sample_rate_hz=50.0, window_s=60.0, segment_s=20.0, update_period_s=0.2,
                           required_pairs=(("p", "da"),))
#: The first reason of a test point that lost frames: "<p> % of the frames of <signal> lost during
#: this test point (<missing> of <expected>, ...".
LOSS_REASON = re.compile(r"^([\d.]+) % of the frames of (\w+) lost during this test point \((\d+) of (\d+),")


def _stamp_s(record: dict) -> float:
    """A record's vehicle time [s]: ``time_usec`` [us] or ``time_boot_ms`` [ms] (MAVLink's own fields)."""
    return record["time_usec"] * 1e-6 if "time_usec" in record else record["time_boot_ms"] * 1e-3


def _own_count(lost: list, topic: str, start_s: float, end_s: float) -> tuple[int, int]:
    """``(frames lost, frames sent or lost)`` of ``topic`` with a stamp in ``(start_s, end_s]``, from the
    test's own list of ``(topic, stamp [s], lost)``."""
    mine = [was_lost for t, s, was_lost in lost if t == topic and start_s < s <= end_s]
    return sum(mine), len(mine)


def _check_loss_reason(tp: dict, ledger: list, settings: MonitorSettings) -> tuple[str, float]:
    """The test point's first reason names the loss, with the fraction the test lost of the signal
    it names (within a point and 3 frames: the span's ends), and no other judged signal lost
    clearly more; returns (signal, the test's fraction)."""
    m = LOSS_REASON.match(tp["reasons"][0])
    assert m, tp["reasons"]
    pct, name, missing, expected = float(m.group(1)), m.group(2), int(m.group(3)), int(m.group(4))
    judged = {"da", "p"}                                  # the swept input and the required output
    assert name in judged, name
    own = {n: _own_count(ledger, settings.signals[n].topic, tp["start_s"], tp["end_s"]) for n in judged}
    lost, total = own[name]
    frac = lost / total
    assert abs(pct / 100 - frac) <= 0.01 and abs(missing - lost) <= 3 and abs(expected - total) <= 3, (tp["reasons"][0],
                                                                                                       own)
    assert all(pct / 100 >= a / b - 0.01 for a, b in own.values()), (tp["reasons"][0], own)
    assert tp["loss_fraction"] == pytest.approx(pct / 100, abs=0.0051)
    return name, frac


# ------------------------------------------------------------------------------------------------
# counting what a signal missed
# ------------------------------------------------------------------------------------------------

def test_frames_missing_counts_the_holes_by_the_signals_own_spacing():
    """A 50 Hz stream with millisecond time stamps (1 ms of jitter), 37 frames taken out singly and in
    runs: exactly those are missing; none is on the whole stream."""
    rng = np.random.default_rng(5)
    t = np.round(100.0 + np.arange(3000) * 0.02 + rng.uniform(-0.001, 0.001, 3000), 3)
    gone = np.r_[[10, 500, 501, 1200], np.arange(2000, 2033)]
    kept = np.delete(t, gone)
    lo, hi = t[0] - 0.01, t[-1] + 0.001
    assert frames_missing(t, lo, hi) == (3000, 0)
    assert frames_missing(kept, lo, hi) == (3000 - gone.size, gone.size)
    assert frames_missing(np.empty(0), lo, hi, spacing_s=0.02) == (0, round((hi - lo) / 0.02))


def test_the_status_line_and_the_test_point_table_say_the_loss():
    line = format_status({"frames_per_s": 41, "frames_lost": 14652, "test_point": "TP3 da",
                          "test_point_elapsed_s": 70, "test_point_loss": 0.27, "verdict": "NO-GO (link)"})
    assert line == "41 fr/s | lost 14652 | TP3 da 01:10 27 % lost | NO-GO (link)"
    assert " lost |" not in format_status({"test_point": "TP1 da", "test_point_loss": 0.0})
    md = markdown_test_points([(3, {"state": "closed", "start_s": 10.0, "end_s": 70.0, "source": "marker",
                                    "swept_input": "da", "verdict": "NO-GO", "label": "NO-GO (link)",
                                    "loss_fraction": 0.27, "pairs": [], "missing": []})], 80.0)
    assert md.startswith("**Test point 3 (closed): NO-GO (link)**, sweeping da, ")
    assert "; **27 % of its frames lost**" in md.splitlines()[0]


# ------------------------------------------------------------------------------------------------
# live: MAVLink over UDP through a radio that loses frames
# ------------------------------------------------------------------------------------------------

class LossyRadio(MavlinkSender):
    """A MAVLink sender whose frames get their sequence numbers and then, where ``lose(msgname,
    record)`` says so, never reach the socket (a radio that drops them on the way)."""

    def __init__(self, url: str, lose):
        super().__init__(url)
        self.lose, self._losing = lose, False

    def send_record(self, msgname, record):
        self._losing = self.lose(msgname, record)
        try:
            super().send_record(msgname, record)
        finally:
            self._losing = False

    def _write(self, buf: bytes) -> bool:
        return True if self._losing else super()._write(buf)


def _sweep_items(seed: int = 11, duration_s: float = 60.0):
    """A simulated da sweep as ``(vehicle time [s], message, record)`` and the sweep's (start, end) [s],
    with operator markers (NAMED_VALUE_INT LS_TP) 2 s before and after it."""
    res = simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=1, omega_min_rad_s=0.5, omega_max_rad_s=20.0,
                                  duration_s=duration_s, amplitudes={"da": 3.0}, off_axis_rms=0.3, seed=seed))
    recs, _ = mavlink_timeline(res)
    items = [(r.vehicle_time_ns * 1e-9, r.msgname, r.record) for r in recs if r.msgname != "HEARTBEAT"]
    seg = next(s for s in res.segments if s.kind == "sweep")
    a = seg.start_s + seg.parameters["trim_s"]             # the simulator's own schedule [s, vehicle time]
    b = a + seg.parameters["duration_s"]
    for t, value in ((a - 2.0, 1), (b + 2.0, 0)):          # LS_TP: 1 = start sweeping input 1 (da), 0 = end
        items.append((t, "NAMED_VALUE_INT", {"time_boot_ms": int(t * 1e3), "name": "LS_TP", "value": value}))
    items.sort(key=lambda x: x[0])
    return items, (a - 2.0, b + 2.0)


def _fly(items, lose, speed: float = 10.0):
    """Stream ``items`` over UDP on 127.0.0.1 into the monitor through a :class:`LossyRadio`; returns
    the monitor's summary and the test's ledger ``[(topic, stamp [s], lost)]`` of every data frame."""
    ledger = []

    def decide(msgname, record):
        if msgname in ("NAMED_VALUE_INT", "HEARTBEAT"):
            return False
        was_lost = bool(lose(msgname, record))
        ledger.append((f"/mavlink/{msgname}", _stamp_s(record), was_lost))
        return was_lost

    src = MavlinkSource("udpin:127.0.0.1:0")
    port = src.local_address[1]
    done = threading.Event()

    def send():
        radio = LossyRadio(f"udpout:127.0.0.1:{port}", decide)
        try:
            stream_records(radio, items, speed=speed)
        finally:
            radio.close()
            done.set()

    pipe = MonitorPipeline(SETTINGS, [src], keep_estimates=False)
    quiet = []

    def stop():
        if not done.is_set():
            return False
        quiet.append(time.monotonic())
        return time.monotonic() - quiet[0] > 1.0

    th = threading.Thread(target=send)
    th.start()
    summary = pipe.run(stop=stop, duration_s=120)
    th.join(10)
    return summary, ledger


@pytest.mark.slow
def test_a_live_test_point_that_lost_frames_on_the_link_says_so_first():
    """30 % of the vehicle's frames lost at random by the radio from 8 s after the operator's start
    marker to 8 s before the end marker; the same flight without losses as the reference."""
    items, (start, end) = _sweep_items()
    clean, _ = _fly(items, lambda m, r: False)
    (tp,) = clean["test_points"]
    assert (tp["source"], tp["swept_input"], tp["verdict"]) == ("marker", "da", "GO"), tp
    assert tp["loss_fraction"] == 0.0 and not any("lost" in r for r in tp["reasons"]), tp["reasons"]

    rng = np.random.default_rng(7)
    lossy, ledger = _fly(items, lambda m, r: start + 8.0 < _stamp_s(r) < end - 8.0 and rng.random() < 0.3)
    (tp,) = lossy["test_points"]
    assert (tp["source"], tp["swept_input"]) == ("marker", "da"), tp
    _check_loss_reason(tp, ledger, SETTINGS)
    # what the link counted while the test point was open: every frame the radio lost (the monitor
    # saw them all as MAVLink sequence gaps; the kernel's own drops, if this machine made any, too)
    n_lost = sum(was_lost for _, _, was_lost in ledger)
    drops = sum(int(s.get("kernel_drops", 0)) for s in lossy["counters"]["sources"])
    m = re.search(r"(\d+) frames missing by MAVLink sequence number", tp["reasons"][1])
    assert tp["reasons"][1].startswith("on the link while this test point was open: ") and m, tp["reasons"][:2]
    assert n_lost <= int(m.group(1)) <= n_lost + drops, (tp["reasons"][1], n_lost, drops)
    if tp["verdict"] == "NO-GO":               # the operator is told the link first, not to fly the sweep again
        assert lossy["reasons"][1].startswith("a link that keeps the frames"), lossy["reasons"][:3]


# ------------------------------------------------------------------------------------------------
# replay: a `livesweep sim` recording with frames taken out
# ------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def sim_recording(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("link_loss")
    out = tmp / "sweep.mcap"
    subprocess.run([sys.executable, "-m", "livesweep", "sim", "--axis", "da", "--repeat", "1", "--duration", "60",
                    "--amplitude", "3", "--off-axis-rms", "0.2", "--seed", "3", "--out", str(out)],
                   check=True, capture_output=True, text=True, timeout=300)
    return tmp, out


def _replay_settings():
    from livesweep.cli import _monitor_settings, build_parser

    return _monitor_settings(build_parser().parse_args(["replay", "x.mcap", "--require", "p/da"]))


@pytest.mark.slow
def test_a_replayed_test_point_that_lost_frames_says_so_first_and_a_no_go_is_the_links(sim_recording):
    """The recording replayed whole is GO with no loss reason; with 27 % of its data frames taken out
    at random over a block of its time that holds the sweep, the first reason is that loss (the
    fraction the test took out), and the NO-GO reads "NO-GO (link)" on the record, in the operator's
    verdict and in the replay command's summary."""
    tmp, log = sim_recording
    settings = _replay_settings()
    whole = MonitorPipeline(settings, [McapReplaySource(log)], keep_estimates=False).run()
    (tp,) = whole["test_points"]
    assert tp["verdict"] == "GO" and tp["loss_fraction"] == 0.0, tp
    assert not any("lost" in r for r in tp["reasons"]), tp["reasons"]
    block = (tp["start_s"] - 20.0, tp["end_s"] + 5.0)

    rng = np.random.default_rng(3)
    ledger = []

    def leave_out(topic, data):
        if not topic.startswith("/mavlink/") or topic == "/mavlink/HEARTBEAT":
            return False
        s = _stamp_s(json.loads(data))
        out = bool(block[0] <= s <= block[1] and rng.random() < 0.27)
        ledger.append((topic, s, out))
        return out

    lossy_log = tmp / "lossy.mcap"
    copy_mcap_without(log, lossy_log, leave_out)
    lossy = MonitorPipeline(settings, [McapReplaySource(lossy_log)], keep_estimates=False).run()
    (tp,) = lossy["test_points"]
    _, frac = _check_loss_reason(tp, ledger, settings)
    assert tp["reasons"][0].endswith(": the verdict reflects the link, not the sweep"), tp["reasons"][0]
    assert (tp["verdict"], tp["label"]) == ("NO-GO", "NO-GO (link)"), tp
    assert lossy["reasons"][0].endswith(": NO-GO (link)") and lossy["reasons"][1].startswith(
        "a link that keeps the frames"), lossy["reasons"][:3]
    assert not any(r.startswith("on the link") for r in tp["reasons"])     # a file has no link counters

    printed = subprocess.run([sys.executable, "-m", "livesweep", "replay", str(lossy_log), "--require", "p/da"],
                             check=True, capture_output=True, text=True, timeout=300).stdout
    line = next(ln for ln in printed.splitlines() if ln.strip().startswith("TP1 "))
    assert ": NO-GO (link);" in line and f"; {100 * tp['loss_fraction']:.0f} % of its frames lost" in line, line
