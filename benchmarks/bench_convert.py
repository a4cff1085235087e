#!/usr/bin/env python3
"""Log conversion speed against the bare readers, measured in the same run on one core.

For the shared third-party logs (skipped when ``../shared/data`` is absent): the DataFlash
SystemID log (8 MB) against a plain pymavlink ``DFReader_binary`` pass that decodes every message
to a dict, and the autotest tlog against pymavlink's own ``mavmmaplog`` pass. The ratio says what
livesweep's conversion (decode, canonicalise, units, JSON, MCAP, provenance) costs on top of
merely reading the file.

    python benchmarks/bench_convert.py
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from livesweep.convert import convert  # noqa: E402

DATA = next((p for p in (Path(__file__).resolve().parents[2] / "shared" / "data", Path("/work/shared/data"))
             if p.is_dir()), None)


def _dataflash_baseline(path: Path) -> int:
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(path), zero_time_base=True)
    n = 0
    while (m := r.recv_msg()) is not None:
        m.to_dict()
        n += 1
    return n


def _tlog_baseline(path: Path) -> int:
    from pymavlink import mavutil

    r = mavutil.mavmmaplog(str(path))          # the class directly: never mavlink_connection on a path
    n = 0
    while (m := r.recv_msg()) is not None:
        m.to_dict()
        n += 1
    return n


def main() -> None:
    if DATA is None:
        print("shared data not found: nothing to measure")
        return
    cases = [("DataFlash SystemID (8 MB)", DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin", _dataflash_baseline),
             ("tlog autotest (4 MB)", DATA / "mavlink_tlog" / "uavlogviewer_autotest_flight_logs.tlog", _tlog_baseline)]
    with tempfile.TemporaryDirectory() as tmp:
        for label, src, baseline in cases:
            if not src.is_file():
                print(f"{label}: {src} missing")
                continue
            t0 = time.perf_counter()
            n_base = baseline(src)
            t_base = time.perf_counter() - t0
            t0 = time.perf_counter()
            res = convert(src, Path(tmp) / "out.mcap")
            t_conv = time.perf_counter() - t0
            print(f"{label}: convert {res.messages_written} messages in {t_conv:.2f} s "
                  f"({res.messages_written / t_conv:,.0f}/s); bare pymavlink read of {n_base} in {t_base:.2f} s "
                  f"({n_base / t_base:,.0f}/s); ratio convert/read {t_conv / t_base:.2f}x")


if __name__ == "__main__":
    main()
