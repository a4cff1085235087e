#!/usr/bin/env python3
"""Regenerate livesweep's sample logs bit-for-bit and check them against SHA256SUMS.

    python replay_logs/regenerate.py            # rewrite every log here, then print sizes and hashes
    python replay_logs/regenerate.py --check    # write to a temporary folder and compare with SHA256SUMS
    python replay_logs/regenerate.py --update-sums

The scenarios live in ``livesweep.sim.samples``; every log is deterministic (fixed seeds, fixed
simulated UTC start, no wall clock in the file) on one BLAS kernel and CPU. Another kernel or CPU
changes the last bits of the simulator's float64 signals, which can move a stored float32 value by
one ulp and so change the hash; tests/test_replay_logs.py compares decoded values within one
storage quantum instead.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import tempfile
from pathlib import Path

from livesweep.sim.samples import SAMPLE_LOGS, sample_scenario
from livesweep.sim.scenario import simulate
from livesweep.telemetry.sim_telemetry import write_sim_log

HERE = Path(__file__).resolve().parent
SUMS = HERE / "SHA256SUMS"


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write_log(name: str, folder: Path) -> Path:
    path = folder / name
    write_sim_log(simulate(sample_scenario(name)), path, notes=SAMPLE_LOGS[name][0])
    return path


def read_sums() -> dict[str, str]:
    if not SUMS.exists():
        return {}
    return {line.split()[1]: line.split()[0] for line in SUMS.read_text().splitlines() if line.strip()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="regenerate into a temporary folder and compare hashes")
    ap.add_argument("--update-sums", action="store_true", help="rewrite SHA256SUMS from the logs written")
    ap.add_argument("names", nargs="*", help="only these logs (default: all)")
    args = ap.parse_args(argv)
    names = args.names or list(SAMPLE_LOGS)
    expected = read_sums()
    bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) if args.check else HERE
        sums = {}
        for name in names:
            path = write_log(name, folder)
            digest = sha256(path)
            sums[name] = digest
            status = ""
            if args.check:
                status = "ok" if expected.get(name) == digest else "DIFFERS"
                bad += status != "ok"
            print(f"{name:32s} {path.stat().st_size / 1e6:6.2f} MB  {digest[:16]}  {status}")
        if args.update_sums:
            merged = {**expected, **sums}
            SUMS.write_text("".join(f"{merged[n]}  {n}\n" for n in sorted(merged)))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
