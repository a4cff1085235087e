"""A message without a time field on the vehicle clock: MAVLink PID_TUNING takes ATTITUDE's stamp.

ArduCopter sends PID_TUNING in the same telemetry tick as ATTITUDE; the shared SITL SystemID log
is streamed as ArduCopter's telemetry (``dataflash_messages``, the records ``livesweep stream``
sends) with receive times ten times faster than the vehicle's (a log streamed at 10x). Reference:
the rate controller's own log, PIDR (``TimeUS``, ``Tar``), read with pymavlink: the demanded roll
rate the monitor aligns must be that record on the vehicle's clock, live and offline alike.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from livesweep.config import RecordSpec
from livesweep.maps import load_map
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.align import GridAligner
from livesweep.telemetry.frames import Frame
from livesweep.telemetry.recorder import McapRecorder
from livesweep.telemetry.signals import read_signals
from livesweep.telemetry.stream_log import dataflash_messages

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" if (ROOT.parent / "shared" / "data").is_dir() else Path("/work/shared/data")
SID7 = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
RX0 = 1_800_000_000 * 10**9


@pytest.fixture(scope="module")
def streamed():
    if not SID7.is_file():
        pytest.skip(f"third-party log not found: {SID7}")
    frames, first = [], None
    for t, name, rec in dataflash_messages(SID7, start_s=40.0, end_s=60.0, rate_hz=50.0):
        first = t if first is None else first
        r = codec.record_from_fields(name, {k: v for k, v in rec.items() if k not in ("sysid", "compid")},
                                     sysid=rec["sysid"], compid=rec["compid"])
        frames.append(Frame(f"/mavlink/{name}", RX0 + int((t - first) / 10 * 1e9), codec.vehicle_time_ns(r, name), r))
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import DFReader

    reader = DFReader.DFReader_binary(str(SID7), zero_time_base=False)
    pidr = []
    while (m := reader.recv_match(type="PIDR")) is not None:
        pidr.append((m.TimeUS * 1e-6, math.degrees(m.Tar)))
    return frames, np.array(pidr)


def _against_pidr(t: np.ndarray, v: np.ndarray, pidr: np.ndarray) -> tuple[int, float]:
    """The samples ``v`` at times ``t`` against the PIDR record at the same times: (valid samples,
    RMS error as a fraction of PIDR's RMS)."""
    ref = np.interp(t, pidr[:, 0], pidr[:, 1])
    ok = np.isfinite(v)
    return int(ok.sum()), float(np.sqrt(np.mean((v[ok] - ref[ok]) ** 2)) / np.sqrt(np.mean(ref[ok] ** 2)))


#: On the vehicle clock the PIDR record matches to this fraction of its RMS (measured 0.7 %; the
#: same comparison shifted by one 400 Hz loop, 2.5 ms, is off by 2-3 %).
PIDR_TOLERANCE = 0.02


@pytest.mark.slow
def test_the_live_aligner_puts_pid_tuning_on_the_vehicle_clock(streamed):
    frames, pidr = streamed
    pid = load_map("ardupilot-copter-pid")
    al = GridAligner(pid.signals, ["roll", "p", "phi"], 50.0)
    blocks = []
    for f in frames:
        al.push(f)
        while (b := al.pop_ready()) is not None:
            blocks.append(b)
    t = np.concatenate([b.t_s for b in blocks])
    roll = np.concatenate([b.values[0] for b in blocks])
    n, err = _against_pidr(t, roll, pidr)
    assert n > 900 and t[0] > 80.0 and err < PIDR_TOLERANCE, (n, t[0], err)    # boot seconds, not receive time
    assert al.counts["late_dropped"] == 0


@pytest.mark.slow
def test_the_offline_reader_borrows_the_same_stamps(streamed, tmp_path):
    frames, pidr = streamed
    log = tmp_path / "streamed.mcap"
    rec = McapRecorder(log)
    rec.record(frames)
    rec.close()
    pid = load_map("ardupilot-copter-pid")
    sig = read_signals(RecordSpec(log=log), pid.signals, ["roll"])["roll"]
    t = np.asarray(sig.t_s)
    n, err = _against_pidr(t, np.asarray(sig.values), pidr)
    assert n > 900 and t[0] > 80.0 and err < PIDR_TOLERANCE, (n, t[0], err)    # boot seconds, not receive time
