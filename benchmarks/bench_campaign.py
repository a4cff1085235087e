#!/usr/bin/env python3
"""A synthetic campaign: how fast flights go in and test points come out of the SQLite database.

``--flights`` flights of ``--points`` test points each (fake SHA-256s, random axes, swept inputs,
verdicts and conditions) are inserted through :meth:`livesweep.campaign.Campaign.insert` (the
function ``Campaign.add`` writes each file with: one transaction per flight). Printed:

* insert time per flight (one transaction each: flight row + its test points);
* query times of :meth:`Campaign.test_points` by axis, by verdict, by a condition range, and all
  three at once, each the median of ``--repeat`` runs;
* the baseline, measured in the same run: the same selections done in plain Python over a list
  of dicts loaded once from the database (loading not counted), and the ratio database / Python.

    python benchmarks/bench_campaign.py [--flights 200] [--points 20] [--repeat 20]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import random
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

import livesweep.campaign as campaign  # noqa: E402
from livesweep.campaign.scan import ScannedFile  # noqa: E402

INPUTS = ("roll", "pitch", "yaw", "collective")
VERDICTS = ("GO", "NO-GO", None)


def _flight(k: int, n: int, rng: random.Random) -> ScannedFile:
    tps = []
    for j in range(n):
        t0 = 60.0 + 70.0 * j
        tps.append({"number": j + 1, "start_s": t0, "end_s": t0 + 45.0, "swept_input": rng.choice(INPUTS),
                    "axis": rng.randint(1, 13), "source": "autopilot", "verdict": rng.choice(VERDICTS),
                    "label": None,
                    "conditions": {"airspeed_m_s": rng.uniform(0, 60), "altitude_m": rng.uniform(0, 3000),
                                   "magnitude": rng.choice((5.0, 10.0, 15.0))},
                    "record": {"what": f"synthetic {k}/{j}"}})
    return ScannedFile(f"/flights/{k:04d}.bin", hashlib.sha256(f"flight {k}".encode()).hexdigest(), "dataflash",
                       str(rng.randint(1, 4)), None, tuple(tps))


def _median_s(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--flights", type=int, default=200)
    ap.add_argument("--points", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=20)
    a = ap.parse_args(argv)
    rng = random.Random(1)
    with tempfile.TemporaryDirectory(prefix="bench-campaign-") as tmp:
        db = Path(tmp) / "c.db"
        with campaign.open(db) as c:
            flights = [_flight(k, a.points, rng) for k in range(a.flights)]
            t = time.perf_counter()
            for f in flights:
                c.insert(f)
            add_s = time.perf_counter() - t
            n = c.counts()["test_points"]
            print(f"inserted {a.flights} flights x {a.points} test points = {n} test points in {add_s:.3f} s: "
                  f"{1e3 * add_s / a.flights:.2f} ms per flight (one transaction each)")
            print(f"re-insert of a flight already in (same SHA-256): "
                  f"{1e3 * _median_s(lambda: c.insert(flights[0]), a.repeat)[0]:.3f} ms")

            # the baseline: every test point as a dict, loaded once (not timed in the queries)
            t = time.perf_counter()
            rows = [dict(id=r[0], flight_id=r[1], axis=r[2], swept_input=r[3], verdict=r[4],
                         conditions=json.loads(r[5]))
                    for r in c.connection.execute("SELECT id, flight_id, axis, swept_input, verdict, conditions "
                                                  "FROM test_points ORDER BY flight_id, number")]
            load_s = time.perf_counter() - t
            print(f"baseline load: {n} test points as dicts in {1e3 * load_s:.1f} ms (not counted below)")

            def in_range(d, name, lo, hi):
                v = d["conditions"].get(name)
                return v is not None and lo <= v <= hi

            queries = {
                "axis = 7": (lambda: c.test_points(axis=7), lambda: [d for d in rows if d["axis"] == 7]),
                "verdict = GO": (lambda: c.test_points(verdict="GO"),
                                 lambda: [d for d in rows if d["verdict"] == "GO"]),
                "airspeed 20-30 m/s": (
                    lambda: c.test_points(conditions={"airspeed_m_s": (20, 30)}),
                    lambda: [d for d in rows if in_range(d, "airspeed_m_s", 20, 30)]),
                "axis 7 + GO + airspeed 20-30": (
                    lambda: c.test_points(axis=7, verdict="GO", conditions={"airspeed_m_s": (20, 30)}),
                    lambda: [d for d in rows if d["axis"] == 7 and d["verdict"] == "GO"
                             and in_range(d, "airspeed_m_s", 20, 30)]),
            }
            print(f"{'query':32s} {'rows':>6s} {'database ms':>12s} {'python ms':>10s} {'ratio':>7s}")
            for name, (dbq, pyq) in queries.items():
                t_db, got = _median_s(dbq, a.repeat)
                t_py, want = _median_s(pyq, a.repeat)
                assert [r.id for r in got] == [d["id"] for d in want], name
                print(f"{name:32s} {len(got):6d} {1e3 * t_db:12.3f} {1e3 * t_py:10.3f} {t_db / t_py:7.1f}")
            print("(ratio = database / plain Python over the loaded dicts; the database query also builds "
                  "a TestPointRow per row, with its conditions and record)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
