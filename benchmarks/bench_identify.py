#!/usr/bin/env python3
"""A whole ``livesweep identify`` of the shipped XV-15 cruise case (every stage, report with
plots), against the same command of the version this work started from, both measured in this
run on this machine.

The baseline is commit ``67c61f1`` (the code when issue 14 asked for a 3x faster identify),
checked out into a temporary git worktree and run on its own copy of the case and logs. Each
run is a fresh ``python -m livesweep identify`` process, so interpreter start-up and imports are
counted as a user meets them. Rounds alternate baseline and current so machine load hits both.

Current is timed three ways:

* cold: an empty decoded-log cache (``LIVESWEEP_CACHE_DIR`` set to a new folder), as on the
  first run of a case;
* warm: the logs decoded before, as when a case file is edited and run again;
* warm, ``--no-plots``: what ``batch`` and CI pay.

Beside every time, the import floor measured in the same run: the wall time of a fresh
``python -c "import numpy, scipy"`` (interpreter start-up and the two imports every run pays
before livesweep does anything; best of 3), and each time minus that floor -- the part livesweep's
own code can change.

    python benchmarks/bench_identify.py [--rounds 5] [--base 67c61f1]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE = Path("config") / "xv15_cruise_lateral.toml"
BASE_COMMIT = "67c61f1"


def _run(src: Path, cwd: Path, out: Path, env: dict, *extra: str) -> float:
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "livesweep", "identify", str(CASE), "--out", str(out), *extra],
                       cwd=cwd, env={**env, "PYTHONPATH": str(src)}, capture_output=True, text=True)
    elapsed = time.perf_counter() - t
    if r.returncode != 0:
        raise SystemExit(f"identify failed in {cwd}:\n{r.stderr[-2000:]}")
    return elapsed


def import_floor_s(env: dict, repeats: int = 3) -> float:
    """Best wall time of ``repeats`` fresh ``python -c "import numpy, scipy"`` processes [s]."""
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import numpy, scipy"], env=env, check=True)
        best = min(best, time.perf_counter() - t)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--base", default=BASE_COMMIT, help="git commit of the baseline (default %(default)s)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_identify_"))
    base = tmp / "base"
    # bytecode is written and used by both, as on a user's machine (the priming runs compile it)
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "LIVESWEEP_CACHE", "LIVESWEEP_CACHE_DIR", "PYTHONDONTWRITEBYTECODE")}
    try:
        made = subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base), args.base],
                              capture_output=True, text=True)
        if made.returncode != 0:
            print(f"baseline {args.base} cannot be checked out ({made.stderr.strip()}); timing current only")
            base = None
        warm_cache = tmp / "cache_warm"
        times: dict[str, list[float]] = {"baseline": [], "cold": [], "warm": [], "warm, --no-plots": []}
        _run(ROOT / "src", ROOT, tmp / "prime", {**env, "LIVESWEEP_CACHE_DIR": str(warm_cache)})   # also compiles .pyc
        if base is not None:
            _run(base / "src", base, tmp / "prime_base", env)
        floor = import_floor_s(env)
        for k in range(args.rounds):
            if base is not None:
                times["baseline"].append(_run(base / "src", base, tmp / "out_base", env))
            times["cold"].append(_run(ROOT / "src", ROOT, tmp / "out_cold",
                                      {**env, "LIVESWEEP_CACHE_DIR": str(tmp / f"cache_cold_{k}")}))
            warm = {**env, "LIVESWEEP_CACHE_DIR": str(warm_cache)}
            times["warm"].append(_run(ROOT / "src", ROOT, tmp / "out_warm", warm))
            times["warm, --no-plots"].append(_run(ROOT / "src", ROOT, tmp / "out_np", warm, "--no-plots"))
        print(f"livesweep identify {CASE} (every stage, report), {args.rounds} rounds, {os.cpu_count()} CPUs; "
              "median [min-max] wall time of a fresh process")
        print(f"  import floor: {floor:.2f} s (fresh python -c \"import numpy, scipy\", best of 3, this run); "
              "'above floor' = median - floor")
        ref = statistics.median(times["baseline"]) if times["baseline"] else None
        for name, ts in times.items():
            if not ts:
                continue
            med = statistics.median(ts)
            ratio = (f"   {ref / med:4.2f}x faster than the baseline ({(ref - floor) / (med - floor):4.2f}x above the "
                     "floor)") if ref and name != "baseline" else ""
            label = f"baseline ({args.base})" if name == "baseline" else f"current, {name}"
            print(f"  {label:28s} {med:5.2f} s [{min(ts):.2f}-{max(ts):.2f}], floor {floor:.2f} s, above floor "
                  f"{med - floor:5.2f} s{ratio}")
    finally:
        if base is not None and base.exists():
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)], capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
