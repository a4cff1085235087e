#!/usr/bin/env python3
"""``livesweep inspect`` on a whole flight's tlog against a bare pymavlink read, in the same run.

The tlog is the shared ArduCopter SITL SystemID log (skipped when ``../shared/data`` is absent)
as a ground station records its telemetry (``livesweep stream``'s messages at the logged rates,
each frame behind its uint64 receive time), repeated ``--repeat`` times one after the other (2:
about 12 MB, 226 000 frames). The baseline is what any tool that reads a tlog must pay: pymavlink's
``mavutil.mavlink_connection(tlog)`` and ``recv_msg()`` until the end, decoding every frame. inspect
does that pass and everything it reports (rates and units per topic, the SystemID runs with their
band, every preset's fit).

    python benchmarks/bench_inspect.py [--repeat 2]
"""

from __future__ import annotations

import argparse
import os
import struct
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

from livesweep.telemetry import mavlink_codec as codec  # noqa: E402  (MAVLink 2 before pymavlink loads)

DATA = next((p for p in (Path(__file__).resolve().parents[2] / "shared" / "data", Path("/work/shared/data"))
             if p.is_dir()), None)


def write_tlog(path: Path, repeat: int) -> int:
    """The SystemID log's telemetry as a tlog, ``repeat`` flights one after the other; frames written."""
    from pymavlink.dialects.v20 import ardupilotmega as mav2

    from livesweep.telemetry.stream_log import dataflash_messages

    mav = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = []
    for t, name, rec in dataflash_messages(DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin",
                                           start_s=0.0, end_s=400.0, rate_hz=None):
        spec = codec._spec(name)
        fields = {fl.name: rec.get(fl.name, 0) for fl in spec.fields}
        for fl in spec.fields:
            if fl.kind == "char":
                fields[fl.name] = str(fields[fl.name] or "").encode()
            elif fl.length and not isinstance(fields[fl.name], list):
                fields[fl.name] = [0] * fl.length
        frames.append((t, bytes(getattr(mav, name.lower() + "_encode")(**fields).pack(mav))))
    with open(path, "wb") as f:
        for k in range(repeat):
            for t, frame in frames:
                f.write(struct.pack(">Q", 1_700_000_000_000_000 + round((t + 400.0 * k) * 1e6)) + frame)
    return len(frames) * repeat


def bare(path: Path) -> int:
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(str(path))
    n = 0
    while m.recv_msg() is not None:
        n += 1
    m.close()
    return n


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=2, help="flights in the tlog (2: about 12 MB)")
    args = ap.parse_args()
    if DATA is None or not (DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin").is_file():
        print("skipped: ../shared/data/ardupilot_sitl_systemid is absent")
        return
    from livesweep.inspect import inspect_log

    with tempfile.TemporaryDirectory() as tmp:
        tlog = Path(tmp) / "flight.tlog"
        n = write_tlog(tlog, args.repeat)
        size = tlog.stat().st_size / 1e6
        t = time.perf_counter()
        n_bare = bare(tlog)
        t_bare = time.perf_counter() - t
        t = time.perf_counter()
        ins = inspect_log(tlog)
        t_ins = time.perf_counter() - t
    print(f"tlog: {size:.1f} MB, {n} frames (pymavlink read {n_bare})")
    print(f"  bare pymavlink read     : {t_bare:6.2f} s")
    print(f"  livesweep inspect       : {t_ins:6.2f} s, {len(ins.systemid)} SystemID runs, "
          f"{sum(f.fits for f in ins.fits)} presets fit")
    print(f"  ratio inspect / bare read: {t_ins / t_bare:.2f}")


if __name__ == "__main__":
    main()
