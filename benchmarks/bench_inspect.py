#!/usr/bin/env python3
"""``livesweep inspect`` on every log in ``../shared/data``, against a bare read of the same file in the same run.

For each file (skipped when ``../shared/data`` is absent): the seconds ``inspect_log`` takes in this
process, the seconds the whole command takes (``python -m livesweep inspect FILE``: interpreter,
imports, report), and the seconds a competent bare read of the same file takes, measured in the
same run, with the ratio inspect / bare read. The bare reads, one per format, decode every message
and do nothing else:

* DataFlash ``.bin`` and PX4 ``.px4log``: pymavlink's ``DFReader_binary`` and ``recv_msg()`` until
  the end;
* MAVLink ``.tlog``: pymavlink's ``mavmmaplog`` and ``recv_msg()`` until the end;
* ULog: ``pyulog.ULog(path)``;
* MCAP: mcap's reader, ``iter_messages()`` over every message (the bytes, not decoded);
* tables: ``numpy.load``, ``numpy.loadtxt``, ``scipy.io.loadmat``, ``pyarrow.parquet.read_table``.

inspect does that pass and everything it reports (rates and units per topic, the SystemID runs
with their band, every preset's fit). ``--repeat N`` takes the best of N runs of each.

``--flight-tlog N`` adds a whole flight's tlog: the SystemID log's telemetry as a ground station
records it (``livesweep stream``'s messages at the logged rates, each frame behind its uint64
receive time), N flights one after the other (2: about 12 MB, 226 000 frames), against
``mavmmaplog``.

    python benchmarks/bench_inspect.py [--repeat 1] [--no-cli] [--flight-tlog 2]
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MAVLINK20", "1")          # before pymavlink loads: the flight tlog is MAVLink 2

import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

DATA = next((p for p in (Path(__file__).resolve().parents[2] / "shared" / "data", Path("/work/shared/data"))
             if p.is_dir()), None)


def _dataflash(path: Path) -> int:
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(path), zero_time_base=True)
    n = 0
    while r.recv_msg() is not None:
        n += 1
    return n


def _tlog(path: Path) -> int:
    from pymavlink import mavutil

    r = mavutil.mavmmaplog(str(path))          # the class directly: never mavlink_connection on a path
    n = 0
    while r.recv_msg() is not None:
        n += 1
    r.close()
    return n


def _ulog(path: Path) -> int:
    from pyulog import ULog

    u = ULog(str(path))
    return sum(len(d.data["timestamp"]) for d in u.data_list)


def _mcap(path: Path) -> int:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return sum(1 for _ in make_reader(f).iter_messages(log_time_order=False))


def _table(path: Path) -> int:
    import numpy as np

    fmt = _format(path)
    if fmt == "numpy":
        return len(np.load(path))
    if fmt == "matlab":
        from scipy.io import loadmat

        return sum(getattr(v, "size", 0) for k, v in loadmat(path).items() if not k.startswith("__"))
    if fmt == "parquet":
        import pyarrow.parquet as pq

        return pq.read_table(path).num_rows
    return len(np.loadtxt(path, skiprows=2))   # the X-Plane text table: a header line, the column names, data


BASELINES = {"dataflash": ("DFReader_binary", _dataflash), "tlog": ("mavmmaplog", _tlog), "ulog": ("pyulog", _ulog),
             "mcap": ("mcap reader", _mcap), "numpy": ("numpy.load", _table), "text": ("numpy.loadtxt", _table),
             "matlab": ("scipy loadmat", _table), "parquet": ("pyarrow", _table)}


def write_flight_tlog(path: Path, repeat: int) -> int:
    """The SystemID log's telemetry as a tlog, ``repeat`` flights one after the other; frames written."""
    import struct

    from pymavlink.dialects.v20 import ardupilotmega as mav2

    from livesweep.telemetry import mavlink_codec as codec
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


def _format(path: Path) -> str:
    from livesweep.convert.common import sniff_format

    return sniff_format(path)


def _best(f, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=1, help="runs of each measurement; the best is kept")
    ap.add_argument("--no-cli", action="store_true", help="leave out the whole command's time")
    ap.add_argument("--flight-tlog", type=int, default=0, metavar="N",
                    help="add the SystemID flight's telemetry as a tlog, N flights long (2: about 12 MB)")
    args = ap.parse_args()
    if DATA is None:
        print("skipped: ../shared/data is absent")
        return
    from livesweep.inspection import format_inspection, inspect_log

    logs = sorted(p for p in DATA.rglob("*") if p.is_file() and p.suffix.lower() != ".md" and p.name != "LICENSE")
    tmp = tempfile.TemporaryDirectory()
    if args.flight_tlog > 0 and (DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin").is_file():
        flight = Path(tmp.name) / "systemid_flight.tlog"
        write_flight_tlog(flight, args.flight_tlog)
        logs.append(flight)
    inspect_log(logs[0])                         # imports and the presets once, outside the measurements
    print(f"{'file':48s} {'MB':>6s} {'inspect s':>9s} {'command s':>9s} {'bare s':>7s}  {'inspect/bare':>12s}  bare read")
    worst = 0.0
    for p in logs:
        fmt = _format(p)
        what, bare = BASELINES[fmt]
        t_bare, _ = _best(lambda: bare(p), args.repeat)
        t_ins, ins = _best(lambda: format_inspection(inspect_log(p)), args.repeat)
        t_cli = float("nan")
        if not args.no_cli:
            t_cli, _ = _best(lambda: subprocess.run([sys.executable, "-m", "livesweep", "inspect", str(p)],
                                                    capture_output=True, check=False), args.repeat)
            worst = max(worst, t_cli)
        name = f"{p.parent.name}/{p.name}"
        print(f"{name[-48:]:48s} {p.stat().st_size / 1e6:6.1f} {t_ins:9.2f} {t_cli:9.2f} {t_bare:7.2f}  "
              f"{t_ins / max(t_bare, 1e-9):12.2f}  {what}")
    if not args.no_cli:
        print(f"slowest command: {worst:.2f} s")
    tmp.cleanup()


if __name__ == "__main__":
    main()
