#!/usr/bin/env python3
"""A full residual loop on the XV-15 cruise case with injected effects, on one core.

Data: cruise sweeps of both axes (half turbulence) and verification doublets simulated with the
effects; the model: the shipped case's ``[state_space]``, which lacks them. Prints the loop's wall
time, the number of re-identifications, and the ratio to one plain state-space fit of the same
model on the same data measured in this run (target: a loop with two effects under 10 s).

Also the import floor measured in the same run: the wall time of a fresh ``python -c "import
numpy, scipy"`` (best of 3). The fit and loop times are measured inside this process after its
imports, so the floor is not in them; it is in this whole benchmark process's wall time (from
interpreter start: imports, simulation, spectral analysis, fit, loop), which is printed with the
floor subtracted.

    python benchmarks/bench_residual.py     # 60 ms skew on the roll gyro + 0.125 s rudder lag
    python benchmarks/bench_residual.py actuator_lag:input=dr,time_constant_s=0.125   # one effect
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import copy  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from livesweep.config import load_case  # noqa: E402
from livesweep.ident.residual import effect_text, run_residual_loop  # noqa: E402
from livesweep.ident.state_space import StateSpaceModel, fit_state_space, select_pairs  # noqa: E402
from livesweep.ident.verify import verify  # noqa: E402
from livesweep.sim.effects import parse_effect  # noqa: E402
from livesweep.sim.scenario import simulate, sweep_scenario, verification_scenario  # noqa: E402
from livesweep.spectral.analysis import analyze  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUTPUTS = ["p", "r", "ay", "beta"]


def import_floor_s(repeats: int = 3) -> float:
    """Best wall time of ``repeats`` fresh ``python -c "import numpy, scipy"`` processes [s]."""
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import numpy, scipy"], check=True)
        best = min(best, time.perf_counter() - t)
    return best


def process_wall_s() -> float | None:
    """Wall time since this process started [s] (Linux /proc; None elsewhere), to 1 clock tick."""
    try:
        with open("/proc/self/stat") as f:
            start_ticks = int(f.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None
    return uptime - start_ticks / os.sysconf("SC_CLK_TCK")


def _at_50hz(result):
    rows = [(n, s.values[::int(round(s.rate_hz / 50.0))]) for n, s in [*result.inputs.items(), *result.outputs.items()]]
    n = min(r.size for _, r in rows)
    return np.array([r[:n] for _, r in rows]), [name for name, _ in rows]


def main(argv) -> None:
    effects = tuple(parse_effect(a) for a in (argv or ["sensor_skew:output=p,delay_s=0.06",
                                                        "actuator_lag:input=dr,time_constant_s=0.125"]))
    sc = sweep_scenario("xv15-cruise", axes=("da", "dr"), repeats=2, omega_min_rad_s=0.3, omega_max_rad_s=20.0,
                        duration_s=100.0, amplitudes={"da": 3.0, "dr": 3.0}, off_axis_rms=0.2, seed=11,
                        effects=effects, turbulence_scale=0.5)
    x, names = _at_50hz(simulate(sc))
    frs = analyze(x - x.mean(axis=1, keepdims=True), names, 50.0, ["da", "dr"], OUTPUTS, (0.3, 20.0),
                  windows_s=(7.0, 12.0, 20.0, 40.0, 80.0)).best
    vs = verification_scenario("xv15-cruise", manoeuvres=(("da", "doublet", 2.0, 1.0), ("dr", "doublet", 3.0, 1.5)),
                               effects=effects, seed=111, turbulence_scale=0.3)
    v, vn = _at_50hz(simulate(vs))
    t = np.arange(v.shape[1]) / 50.0
    u = v[[vn.index("da"), vn.index("dr")]]
    y = v[[vn.index(o) for o in OUTPUTS]]

    def check(model, theta):
        M, F, G, H, J, tau = model.matrices(theta)
        return verify(M, F, G, H, J, tau, t, u, y, output_names=OUTPUTS, output_delays=model.output_delays_s(theta))

    table = copy.deepcopy(load_case(ROOT / "config" / "xv15_cruise_lateral.toml").tables["state_space"])
    model = StateSpaceModel.from_table(table, where="bench")
    pairs, _ = select_pairs(frs, model)
    t0 = time.perf_counter()
    fit = fit_state_space(model, pairs)
    t_fit = time.perf_counter() - t0
    t0 = time.perf_counter()
    loop = run_residual_loop(table, fit, frs, verify=check)
    t_loop = time.perf_counter() - t0
    print(f"injected: {[e.as_dict() for e in effects]}")
    print(f"one state-space fit (baseline):  {t_fit:6.2f} s, J_ave {fit.cost_average:.2f}")
    print(f"residual loop:                   {t_loop:6.2f} s, {loop.n_fits} re-identifications, "
          f"{len(loop.steps)} steps: {loop.conclusion}")
    for st in loop.steps:
        if st.effect:
            print(f"  + {effect_text(st.effect)}; J_ave {st.cost_before:.2f} -> {st.cost_after:.2f}")
    print(f"ratio loop / one fit: {t_loop / t_fit:.0f}x (target: a loop with two effects under 10 s on one core)")
    whole = process_wall_s()
    floor = import_floor_s()
    print(f"import floor: {floor:.2f} s (fresh python -c \"import numpy, scipy\", best of 3, this run); not in the "
          f"fit ({t_fit:.2f} s) and loop ({t_loop:.2f} s) times, which are measured after this process's imports")
    if whole is not None:
        print(f"this whole process (imports, simulation, analysis, fit, loop): {whole:6.2f} s, minus the floor "
              f"{whole - floor:6.2f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
