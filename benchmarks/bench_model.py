#!/usr/bin/env python3
"""How soon a closed test point's model is there: the fit's wall time against the monitor's
update period, and against a plain scipy fit of the same model, measured in this run.

Data: the shared ArduCopter SITL SystemID logs (roll-rate and pitch-rate chirps, 400 Hz),
converted and replayed through the monitor's pipeline with the ``ardupilot-sysid-dataflash``
preset. For each GO test point the pipeline fits the model right after judging it; the time from
judging to the ``/livesweep/model`` record is what the operator waits, printed as a ratio to the
update period (the live estimate's cadence, 0.2 s by default: the model must not hold the
analysis back by more than a few updates; the requirement is 1 s).

Baseline (like for like, same run, one core): the same low-order model ``K / (s + 1/T)
e^(-tau s)`` fitted with ``scipy.optimize.least_squares`` to the same 20 fitting points with the
same cost (magnitude and wrapped phase residuals, coherence weights), from one start at the
data's low-frequency gain and a mid-band pole, default 2-point finite differences, then the
Cramer-Rao bounds from its Jacobian. livesweep tries several starts (and a second-order model
when the first is not excellent), so it costs more than one plain fit; the ratio says how much.

    python benchmarks/bench_model.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from scipy.optimize import least_squares

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
DATA = ROOT.parent / "shared" / "data" / "ardupilot_sitl_systemid"
LOGS = ("sid_axis7_rate_roll.bin", "sid_axis8_rate_pitch.bin")


def plain_fit(pd):
    """The baseline: K / (s + a) e^(-tau s) on the fitting points ``pd`` (livesweep's PairData)."""
    from livesweep.ident.cost import residuals

    s = 1j * pd.omega

    def r(x):
        K, a, tau = x
        return residuals(pd, K / (s + a) * np.exp(-tau * s))

    dc = 10 ** (pd.magnitude_db[0] / 20)
    a0 = float(np.sqrt(pd.omega[0] * pd.omega[-1]))
    sol = least_squares(r, [dc * a0, a0, 0.0], bounds=([-np.inf, -np.inf, 0.0], [np.inf, np.inf, 1.0]),
                        x_scale="jac", method="trf")
    H = 2 * sol.jac.T @ sol.jac
    return sol, np.sqrt(np.diag(np.linalg.pinv(H)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    missing = [n for n in LOGS if not (DATA / n).is_file()]
    if missing:
        sys.exit(f"bench_model: shared logs not found in {DATA}: {', '.join(missing)}")
    import livesweep
    from livesweep.convert import convert
    from livesweep.ident.cost import fit_points
    from livesweep.ident.test_point_model import model_pair

    with tempfile.TemporaryDirectory() as tmp:
        for name in LOGS:
            mcap = Path(tmp) / (name + ".mcap")
            convert(DATA / name, mcap)
            r = livesweep.replay(mcap, map="ardupilot-sysid-dataflash")
            period = r.settings.update_period_s
            print(f"{name}: {len(r.models)} model(s); pipeline model time {r.summary['model_s']} s; "
                  f"ratio to the {period:g} s update period: "
                  f"{', '.join(f'{t / period:.2f}' for t in r.summary['model_s'])}")
            # the same fit again, on the judgement's response, timed against the plain scipy fit
            from livesweep.monitor.pipeline import MonitorPipeline
            from livesweep.telemetry.replay import McapReplaySource

            pipe = MonitorPipeline(r.settings, [McapReplaySource(mcap)], keep_estimates=False)
            pipe.run()
            [judgement] = [j for j in pipe.test_points.judgements.values() if j.final and j.verdict == "GO"]
            resp = judgement.pairs[0].response
            units = r.settings.signals[resp.output].units
            ours, base = [], []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                pm = model_pair(resp, output_units=units, criteria=r.settings.criteria)
                ours.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                pd = fit_points(resp, min_coherence=r.settings.criteria.min_coherence)
                sol, cr = plain_fit(pd)
                base.append(time.perf_counter() - t0)
            J_plain = float(np.dot(sol.fun, sol.fun))
            print(f"  {resp.output}/{resp.input}: livesweep {pm.structure}, J {pm.fit.cost:.3f}, "
                  f"{statistics.median(ours) * 1e3:.1f} ms (median of {args.repeats}); plain scipy first-order fit "
                  f"J {J_plain:.3f}, {statistics.median(base) * 1e3:.1f} ms; ratio {statistics.median(ours) / statistics.median(base):.2f}; "
                  f"livesweep / update period {statistics.median(ours) / period:.2f}")


if __name__ == "__main__":
    main()
