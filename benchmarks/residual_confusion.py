#!/usr/bin/env python3
"""The residual loop on many simulated logs: the false-alarm calibration and the confusion matrix.

Every case is a simulated test point (both axes swept, turbulence) of one airframe with effects
injected that the airframe's shipped case does not declare; the loop runs on the case's
``[state_space]`` model (cruise: with time-domain verification on doublets and a 3-2-1-1).

    python benchmarks/residual_confusion.py --calibrate   # clean cruise seeds 30-43 -> POINTS_PER_INDEPENDENT
    python benchmarks/residual_confusion.py --development # the cases looked at while setting the gates
    python benchmarks/residual_confusion.py               # held-out: effect cases + clean cases
    python benchmarks/residual_confusion.py --held-out-2  # the second held-out set (see HELD_OUT_2)
    python benchmarks/residual_confusion.py --held-out-3  # the third (see HELD_OUT_3)
    python benchmarks/residual_confusion.py --held-out-4  # the fourth (see HELD_OUT_4)
    python benchmarks/residual_confusion.py --held-out-5  # the fifth (see HELD_OUT_5)
    python benchmarks/residual_confusion.py --held-out-6  # the sixth (see HELD_OUT_6), and so on to --held-out-15
    python benchmarks/residual_confusion.py -j 2 --only hover

The calibration set (clean XV-15 cruise, seeds 30-43 at full and half turbulence) is the only
data the selection criterion's constant was set on. The held-out set uses other seeds, other
effect magnitudes, the hover airframe (pilot loop closed) and the quadrotor, none of which were
looked at while tuning. Prints one line per case, the confusion matrix of kind and place (the
first added effect, or the set added for a pair), the false positives on clean cases, how many
recovered parameters lie within 3 Cramer-Rao bounds of their injection and how many costs halved.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tomllib  # noqa: E402
from collections import Counter  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from livesweep.errors import ConfigError  # noqa: E402
from livesweep.effects import make_effect  # noqa: E402
from livesweep.ident.residual import run_residual_loop  # noqa: E402
from livesweep.ident.state_space import StateSpaceModel, fit_state_space, select_pairs  # noqa: E402
from livesweep.ident.verify import verify  # noqa: E402
from livesweep.sim.scenario import simulate, sweep_scenario, verification_scenario  # noqa: E402
from livesweep.spectral.analysis import analyze  # noqa: E402
from livesweep.spectral.spectra import MIN_PERIODS_PER_WINDOW  # noqa: E402
from livesweep.spectral.windows import longest_window_samples  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Airframe:
    """How one airframe's test points are flown and analysed."""

    model: str
    case: str
    inputs: tuple
    band: tuple
    windows: tuple | None             # None: the method's defaults for the record (as the quad case file)
    amplitudes: dict
    rate_hz: float = 50.0
    verification: tuple = ()          # (input, kind, amplitude, pulse_s) manoeuvres; () = no time-domain test
    turbulence: float = 0.5
    references: bool = False          # analyse through the logged injections (<input>_ref), as the case does
    duration_s: float = 100.0
    edit: tuple = ()                  # edits of the case model every log of this airframe gets (see Case.edit)


AIRFRAMES = {
    "cruise": Airframe("xv15-cruise", "config/xv15_cruise_lateral.toml", ("da", "dr"), (0.3, 20.0),
                       (7.0, 12.0, 20.0, 40.0, 80.0), {"da": 3.0, "dr": 3.0},
                       verification=(("da", "doublet", 2.0, 1.0), ("dr", "doublet", 3.0, 1.5), ("da", "3211", 1.5, 0.7))),
    "hover": Airframe("xv15-hover", "config/xv15_hover_lateral.toml", ("da", "dr"), (0.2, 12.0),
                      (10.0, 20.0, 40.0, 80.0, 160.0), {"da": 1.5, "dr": 3.0}),
    # the quadrotor as config/quad_attitude.toml analyses it: 200 Hz, through the injections
    "quad": Airframe("quad-attitude", "config/quad_attitude.toml", ("roll_cmd", "pitch_cmd"), (1.0, 60.0),
                     None, {"roll_cmd": 0.1, "pitch_cmd": 0.1}, rate_hz=200.0,
                     references=True, duration_s=90.0,
                     # the command latency as a bench test measured it (the case leaves it free)
                     edit=(("fix", "tau_roll", 0.02), ("fix", "tau_pitch", 0.02))),
}


@dataclass(frozen=True)
class Case:
    """One log: airframe, seed, injected effects, an edit of the case model, what should be found."""

    name: str
    airframe: str
    seed: int
    effects: tuple = ()               # (kind, params) of make_effect
    expect: tuple = ()                # {(kind, where)} the loop should add (empty: nothing)
    truth: dict = field(default_factory=dict)   # parameter name -> injected value
    edit: tuple = ()                  # ("fix", name, value) / ("drop", "F", row, col, name)
    turbulence: float | None = None
    log_late: tuple = ()              # (input, seconds): that input is logged this much late (an input skew)
    conditions: tuple = ()            # (name, value) pairs flying it unlike the other sets (see _shifted)


#: What a case's ``conditions`` may change: how the test point is flown and logged, not the vehicle.
CONDITIONS = {
    "noise": "sensor noise times this",
    "gust_time_s": "turbulence correlation time [s] (the default's 2 s: gusts with more or less high-frequency content)",
    "amplitude": "sweep amplitudes times this (lower signal-to-noise)",
    "duration_s": "sweep length [s]",
    "repeats": "sweeps per axis",
    "rate_hz": "log rate [Hz]",
    "pilot_gain": "the stabilising pilot's gains times this (tighter or looser closed loop)",
}


def _shifted(sc, cond: dict):
    """The scenario ``sc`` with ``cond``'s sensor noise, gusts and pilot changed."""
    from dataclasses import replace
    if "noise" in cond:
        sc = replace(sc, sensors=tuple(replace(x, noise_std=x.noise_std * cond["noise"]) for x in sc.sensors))
    if "gust_time_s" in cond and sc.turbulence is not None:
        sc = replace(sc, turbulence=replace(sc.turbulence, correlation_time_s=cond["gust_time_s"]))
    if "pilot_gain" in cond and sc.pilot is not None:
        sc = replace(sc, pilot=replace(sc.pilot, gains=tuple((i, o, g * cond["pilot_gain"]) for i, o, g in sc.pilot.gains)))
    return sc


def _record(result, rate_hz, references=False):
    refs = [(n + "_ref", s) for n, s in result.injections.items()] if references else []
    rows = [(n, s.values[::int(round(s.rate_hz / rate_hz))])
            for n, s in [*result.inputs.items(), *refs, *result.outputs.items()]]
    n = min(r.size for _, r in rows)
    return np.array([r[:n] for _, r in rows]), [name for name, _ in rows]


def _log_late(x, names, case, rate_hz):
    """The record with ``case.log_late``'s input logged late (held at its first value meanwhile)."""
    if not case.log_late:
        return x
    x = x.copy()
    i, k = names.index(case.log_late[0]), int(round(case.log_late[1] * rate_hz))
    x[i] = np.concatenate([np.full(k, x[i, 0]), x[i, :-k]])
    return x


def _table(af: Airframe, case: Case) -> dict:
    with open(ROOT / af.case, "rb") as f:      # the model only: the case's logs need not exist
        table = tomllib.load(f)["state_space"]
    for e in (*af.edit, *case.edit):
        if e[0] == "fix":
            table["parameters"][e[1]] = {"value": e[2], "fixed": True}
        elif e[0] == "drop":
            _, key, row, col, name = e
            table[key][table["states"].index(row)][(table["states"] if key == "F" else table["inputs"]).index(col)] = "0"
            del table["parameters"][name]
    return table


def _windows_for(af: Airframe, n_samples: int, rate_hz: float):
    """The airframe's windows and band, or, for a record too short for its longest window (a
    ``duration_s`` condition), what the method sets for that record (docs/method.md §4.4): the
    default windows up to half the record, and the band from three periods of the longest."""
    half_s = longest_window_samples(n_samples) / rate_hz
    if af.windows is None or max(af.windows) <= half_s:
        return af.windows, af.band
    return None, (max(af.band[0], MIN_PERIODS_PER_WINDOW * 2 * np.pi / half_s), af.band[1])


def run_case(case: Case) -> dict:
    """Simulate, analyse, fit and run the loop on one case; a summary dict."""
    af = AIRFRAMES[case.airframe]
    effects = tuple(make_effect(k, **p) for k, p in case.effects)
    table = _table(af, case)
    outputs = list(table["outputs"])
    cond = dict(case.conditions)
    unknown = set(cond) - set(CONDITIONS)
    if unknown:
        raise ConfigError(f"case {case.name!r}: unknown condition(s) {sorted(unknown)}; known: {sorted(CONDITIONS)}")
    rate = cond.get("rate_hz", af.rate_hz)
    t0 = time.perf_counter()
    sc = sweep_scenario(af.model, axes=af.inputs, repeats=cond.get("repeats", 2), omega_min_rad_s=af.band[0],
                        omega_max_rad_s=af.band[1], duration_s=cond.get("duration_s", af.duration_s),
                        amplitudes={k: a * cond.get("amplitude", 1.0) for k, a in af.amplitudes.items()},
                        off_axis_rms=0.2, seed=case.seed, effects=effects,
                        turbulence_scale=af.turbulence if case.turbulence is None else case.turbulence)
    x, names = _record(simulate(_shifted(sc, cond)), rate, af.references)
    x = _log_late(x, names, case, rate)
    refs = [n + "_ref" for n in af.inputs] if af.references else None
    windows, band = _windows_for(af, x.shape[1], rate)
    frs = analyze(x - x.mean(axis=1, keepdims=True), names, rate, list(af.inputs), outputs, band,
                  windows_s=windows, references=refs).best
    check = None
    if af.verification:
        vs = verification_scenario(af.model, manoeuvres=af.verification, effects=effects, seed=case.seed + 100,
                                   turbulence_scale=0.3)
        v, vn = _record(simulate(_shifted(vs, cond)), rate)
        v = _log_late(v, vn, case, rate)
        t = np.arange(v.shape[1]) / rate
        u = v[[vn.index(n) for n in af.inputs]]
        y = v[[vn.index(o) for o in outputs]]

        def check(model, theta):
            M, F, G, H, J, tau = model.matrices(theta)
            return verify(M, F, G, H, J, tau, t, u, y, output_names=outputs, output_delays=model.output_delays_s(theta),
                          input_skews=model.input_skews_s(theta))
    model = StateSpaceModel.from_table(table)
    pairs, _ = select_pairs(frs, model)
    fit = fit_state_space(model, pairs)
    loop = run_residual_loop(table, fit, frs, verify=check)
    added = [(e["kind"], e["where"]) for e in loop.added]
    params = {p["name"]: p for e in loop.added for p in e["parameters"]}
    fixed = {f["name"]: f for s in loop.steps for t in s.tried if t.get("accepted") for f in t.get("fixed", ())}
    within = []
    for name, truth in case.truth.items():
        p = params.get(name)
        if p is None:
            continue
        q = fixed.get(name, p) if p.get("fixed") else p
        cr = q["cramer_rao_pct"]
        within.append((name, p["value"], truth, cr, cr is not None and abs(p["value"] - truth) <= 3 * cr / 100 * abs(p["value"])))
    tried = [(t["kind"], t["where"], t.get("significance", {}).get("F"), t.get("significance", {}).get("needed"),
              t.get("evidence_after"), t["reason"]) for t in loop.steps[0].tried]
    factor = next((p["factor"] for k, p in case.effects if k == "scale_factor"), 1.0)
    return {"name": case.name, "truth_factor": factor, "airframe": case.airframe, "expect": sorted(case.expect), "added": added,
            "conclusion": loop.conclusion, "within": within, "cost_before": loop.steps[0].cost_before,
            "cost_after": loop.fit.cost_average, "seconds": time.perf_counter() - t0, "tried": tried,
            "limits": {x["where"]: x["smallest_detectable_pct"] for x in loop.limits},
            "ambiguous": [(a["kind"], a["where"]) for e in loop.added for a in e.get("ambiguous_with", ())],
            "ambiguous_of": {(e["kind"], e["where"]): [(a["kind"], a["where"]) for a in e.get("ambiguous_with", ())]
                             for e in loop.added}}


def _e(kind, **p):
    return (kind, p)


TAU_A = 0.0892      # the cruise case's fixed aileron delay (the truth's)

CALIBRATION = [Case(f"clean cruise seed {s} turb {tb}", "cruise", s, turbulence=tb)
               for s in range(30, 44) for tb in (1.0, 0.5)]

DEVELOPMENT = [
    # cruise, seeds 70+ (looked at while the criterion's gates were set)
    Case("cruise delay 20 ms da", "cruise", 70, (_e("time_delay", input="da", delay_s=0.02),), {("time_delay", "da")},
         {"tau_a": TAU_A + 0.02}, (("fix", "tau_a", TAU_A),)),
    Case("cruise delay 80 ms da", "cruise", 71, (_e("time_delay", input="da", delay_s=0.08),), {("time_delay", "da")},
         {"tau_a": TAU_A + 0.08}, (("fix", "tau_a", TAU_A),)),
    Case("cruise lag 0.05 s dr", "cruise", 72, (_e("actuator_lag", input="dr", time_constant_s=0.05),),
         {("actuator_lag", "dr")}, {"w_act_dr": 20.0}),
    Case("cruise lag 0.2 s da", "cruise", 73, (_e("actuator_lag", input="da", time_constant_s=0.2),),
         {("actuator_lag", "da")}, {"w_act_da": 5.0}),
    Case("cruise 2nd-order 8 rad/s zeta 0.6 dr", "cruise", 74,
         (_e("actuator_second_order", input="dr", omega_rad_s=8.0, zeta=0.6),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 8.0, "zeta_act_dr": 0.6}),
    Case("cruise notch 4 rad/s depth 0.8 dr", "cruise", 75,
         (_e("notch_filter", input="dr", omega_rad_s=4.0, zeta=0.25, depth=0.8),), {("notch_filter", "dr")},
         {"w_notch_dr": 4.0, "zeta_notch_dr": 0.25, "depth_notch_dr": 0.8}),
    Case("cruise notch 10 rad/s depth 0.6 da", "cruise", 76,
         (_e("notch_filter", input="da", omega_rad_s=10.0, zeta=0.3, depth=0.6),), {("notch_filter", "da")},
         {"w_notch_da": 10.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.6}),
    Case("cruise mode p 12 rad/s zeta 0.05/0.15", "cruise", 77,
         (_e("structural_mode", output="p", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 12.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("cruise mode r 9 rad/s zeta 0.08/0.2", "cruise", 78,
         (_e("structural_mode", output="r", omega_rad_s=9.0, zeta_pole=0.08, zeta_zero=0.2),),
         {("structural_mode", "r")}, {"w_mode_r": 9.0, "zeta_mode_r": 0.08, "zeta_zero_mode_r": 0.2}),
    Case("cruise mode ay 15 rad/s zeta 0.05/0.12", "cruise", 79,
         (_e("structural_mode", output="ay", omega_rad_s=15.0, zeta_pole=0.05, zeta_zero=0.12),),
         {("structural_mode", "ay")}, {"w_mode_ay": 15.0, "zeta_mode_ay": 0.05, "zeta_zero_mode_ay": 0.12}),
    Case("cruise skew 40 ms r", "cruise", 80, (_e("sensor_skew", output="r", delay_s=0.04),), {("sensor_skew", "r")},
         {"skew_r": 0.04}),
    Case("cruise skew 25 ms ay", "cruise", 81, (_e("sensor_skew", output="ay", delay_s=0.025),), {("sensor_skew", "ay")},
         {"skew_ay": 0.025}),
    Case("cruise scale 0.85 p", "cruise", 82, (_e("scale_factor", output="p", factor=0.85),), {("scale_factor", "p")},
         {"k_p": 0.85}),
    Case("cruise missing Lv", "cruise", 83, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -8.119e-3},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("cruise mode p + lag dr", "cruise", 84,
         (_e("structural_mode", output="p", omega_rad_s=11.0, zeta_pole=0.06, zeta_zero=0.18),
          _e("actuator_lag", input="dr", time_constant_s=0.1)),
         {("structural_mode", "p"), ("actuator_lag", "dr")},
         {"w_mode_p": 11.0, "zeta_mode_p": 0.06, "zeta_zero_mode_p": 0.18, "w_act_dr": 10.0}),
    Case("cruise skew p + delay dr", "cruise", 85,
         (_e("sensor_skew", output="p", delay_s=0.05), _e("time_delay", input="dr", delay_s=0.06)),
         {("sensor_skew", "p"), ("time_delay", "dr")}, {"skew_p": 0.05, "tau_r": 0.03276 + 0.06},
         (("fix", "tau_r", 0.03276),)),
    Case("cruise mode p 12 + lag da 0.1 s", "cruise", 86,
         (_e("structural_mode", output="p", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15),
          _e("actuator_lag", input="da", time_constant_s=0.1)),
         {("structural_mode", "p"), ("actuator_lag", "da")}, {"w_mode_p": 12.0, "zeta_zero_mode_p": 0.15,
                                                             "w_act_da": 10.0}),
    # hover (pilot loop closed; no time-domain verification)
    Case("hover delay 0.1 s da", "hover", 70, (_e("time_delay", input="da", delay_s=0.1),), {("time_delay", "da")},
         {"tau_da": 0.1}),
    Case("hover delay 40 ms dr", "hover", 71, (_e("time_delay", input="dr", delay_s=0.04),), {("time_delay", "dr")},
         {"tau_dr": 0.04}),
    Case("hover lag 0.15 s da", "hover", 72, (_e("actuator_lag", input="da", time_constant_s=0.15),),
         {("actuator_lag", "da")}, {"w_act_da": 1 / 0.15}),
    Case("hover 2nd-order 6 rad/s zeta 0.5 dr", "hover", 73,
         (_e("actuator_second_order", input="dr", omega_rad_s=6.0, zeta=0.5),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 6.0, "zeta_act_dr": 0.5}),
    Case("hover notch 3 rad/s depth 0.7 da", "hover", 74,
         (_e("notch_filter", input="da", omega_rad_s=3.0, zeta=0.3, depth=0.7),), {("notch_filter", "da")},
         {"w_notch_da": 3.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.7}),
    Case("hover mode p 8 rad/s zeta 0.05/0.15", "hover", 75,
         (_e("structural_mode", output="p", omega_rad_s=8.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 8.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("hover skew 50 ms r", "hover", 76, (_e("sensor_skew", output="r", delay_s=0.05),), {("sensor_skew", "r")},
         {"skew_r": 0.05}),
    Case("hover mode p + delay dr", "hover", 77,
         (_e("structural_mode", output="p", omega_rad_s=7.0, zeta_pole=0.06, zeta_zero=0.2),
          _e("time_delay", input="dr", delay_s=0.08)), {("structural_mode", "p"), ("time_delay", "dr")},
         {"w_mode_p": 7.0, "tau_dr": 0.08}),
]

DEVELOPMENT_CLEAN = ([Case(f"clean cruise seed {s}", "cruise", s) for s in range(90, 98)]
                     + [Case(f"clean hover seed {s}", "hover", s) for s in range(90, 97)])

TAU_R = 0.03276     # the cruise case's rudder delay (the truth's)
HELD_OUT = [
    # not run until the gates were frozen: other seeds (200+), other magnitudes and places
    Case("cruise delay 30 ms dr", "cruise", 201, (_e("time_delay", input="dr", delay_s=0.03),), {("time_delay", "dr")},
         {"tau_r": TAU_R + 0.03}, (("fix", "tau_r", TAU_R),)),
    Case("cruise delay 0.12 s da", "cruise", 202, (_e("time_delay", input="da", delay_s=0.12),), {("time_delay", "da")},
         {"tau_a": TAU_A + 0.12}, (("fix", "tau_a", TAU_A),)),
    Case("cruise lag 0.08 s da", "cruise", 203, (_e("actuator_lag", input="da", time_constant_s=0.08),),
         {("actuator_lag", "da")}, {"w_act_da": 12.5}),
    Case("cruise 2nd-order 12 rad/s zeta 0.7 da", "cruise", 204,
         (_e("actuator_second_order", input="da", omega_rad_s=12.0, zeta=0.7),), {("actuator_second_order", "da")},
         {"wn_act_da": 12.0, "zeta_act_da": 0.7}),
    Case("cruise notch 7 rad/s depth 0.9 da", "cruise", 205,
         (_e("notch_filter", input="da", omega_rad_s=7.0, zeta=0.2, depth=0.9),), {("notch_filter", "da")},
         {"w_notch_da": 7.0, "zeta_notch_da": 0.2, "depth_notch_da": 0.9}),
    Case("cruise mode p 14 rad/s zeta 0.05/0.2", "cruise", 206,
         (_e("structural_mode", output="p", omega_rad_s=14.0, zeta_pole=0.05, zeta_zero=0.2),),
         {("structural_mode", "p")}, {"w_mode_p": 14.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.2}),
    Case("cruise mode beta 6 rad/s zeta 0.07/0.2", "cruise", 207,
         (_e("structural_mode", output="beta", omega_rad_s=6.0, zeta_pole=0.07, zeta_zero=0.2),),
         {("structural_mode", "beta")}, {"w_mode_beta": 6.0, "zeta_mode_beta": 0.07, "zeta_zero_mode_beta": 0.2}),
    Case("cruise skew 50 ms beta", "cruise", 208, (_e("sensor_skew", output="beta", delay_s=0.05),),
         {("sensor_skew", "beta")}, {"skew_beta": 0.05}),
    Case("cruise skew 30 ms p", "cruise", 209, (_e("sensor_skew", output="p", delay_s=0.03),), {("sensor_skew", "p")},
         {"skew_p": 0.03}),
    Case("cruise scale 1.25 beta", "cruise", 210, (_e("scale_factor", output="beta", factor=1.25),),
         {("scale_factor", "beta")}, {"k_beta": 1.25}),
    Case("cruise missing Np", "cruise", 211, (), {("missing_derivative", "F[r][p]")}, {"F_r_p": -0.2308},
         (("drop", "F", "r", "p", "Np"),)),
    Case("cruise notch da + skew r", "cruise", 212,
         (_e("notch_filter", input="da", omega_rad_s=8.0, zeta=0.3, depth=0.7), _e("sensor_skew", output="r", delay_s=0.05)),
         {("notch_filter", "da"), ("sensor_skew", "r")}, {"w_notch_da": 8.0, "skew_r": 0.05}),
    Case("cruise mode r + 2nd-order da", "cruise", 213,
         (_e("structural_mode", output="r", omega_rad_s=10.0, zeta_pole=0.05, zeta_zero=0.15),
          _e("actuator_second_order", input="da", omega_rad_s=9.0, zeta=0.6)),
         {("structural_mode", "r"), ("actuator_second_order", "da")}, {"w_mode_r": 10.0, "wn_act_da": 9.0}),
    Case("hover delay 60 ms da", "hover", 201, (_e("time_delay", input="da", delay_s=0.06),), {("time_delay", "da")},
         {"tau_da": 0.06}),
    Case("hover delay 20 ms da", "hover", 202, (_e("time_delay", input="da", delay_s=0.02),), {("time_delay", "da")},
         {"tau_da": 0.02}),
    Case("hover lag 0.1 s dr", "hover", 203, (_e("actuator_lag", input="dr", time_constant_s=0.1),),
         {("actuator_lag", "dr")}, {"w_act_dr": 10.0}),
    Case("hover 2nd-order 5 rad/s zeta 0.6 da", "hover", 204,
         (_e("actuator_second_order", input="da", omega_rad_s=5.0, zeta=0.6),), {("actuator_second_order", "da")},
         {"wn_act_da": 5.0, "zeta_act_da": 0.6}),
    Case("hover notch 5 rad/s depth 0.8 dr", "hover", 205,
         (_e("notch_filter", input="dr", omega_rad_s=5.0, zeta=0.25, depth=0.8),), {("notch_filter", "dr")},
         {"w_notch_dr": 5.0, "zeta_notch_dr": 0.25, "depth_notch_dr": 0.8}),
    Case("hover mode r 6 rad/s zeta 0.05/0.15", "hover", 206,
         (_e("structural_mode", output="r", omega_rad_s=6.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "r")}, {"w_mode_r": 6.0, "zeta_mode_r": 0.05, "zeta_zero_mode_r": 0.15}),
    Case("hover skew 40 ms p", "hover", 207, (_e("sensor_skew", output="p", delay_s=0.04),), {("sensor_skew", "p")},
         {"skew_p": 0.04}),
    Case("hover missing Np", "hover", 208, (), {("missing_derivative", "F[r][p]")}, {"F_r_p": 0.03862},
         (("drop", "F", "r", "p", "Np"),)),
    Case("hover lag da + skew r", "hover", 209,
         (_e("actuator_lag", input="da", time_constant_s=0.12), _e("sensor_skew", output="r", delay_s=0.05)),
         {("actuator_lag", "da"), ("sensor_skew", "r")}, {"w_act_da": 1 / 0.12, "skew_r": 0.05}),
]
TAU_Q = 0.02        # the quadrotor's command latency (the truth's)
HELD_OUT += [
    # added when the gates were already frozen: a second input-side place (cruise), and the quadrotor,
    # an airframe the loop had never run on (attitude loop closed, 200 Hz, through the injections)
    Case("cruise input skew 40 ms dr", "cruise", 214, (), {("sensor_skew", "dr")}, {"skew_dr": 0.04},
         (("fix", "tau_r", TAU_R),), log_late=("dr", 0.04)),
    Case("quad delay 25 ms roll", "quad", 201, (_e("time_delay", input="roll_cmd", delay_s=0.025),),
         {("time_delay", "roll_cmd")}, {"tau_roll": TAU_Q + 0.025}),
    Case("quad lag 30 ms pitch", "quad", 202, (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.03),),
         {("actuator_lag", "pitch_cmd")}, {"w_act_pitch_cmd": 1 / 0.03}),
    Case("quad 2nd-order 25 rad/s zeta 0.5 roll", "quad", 203,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=25.0, zeta=0.5),),
         {("actuator_second_order", "roll_cmd")}, {"wn_act_roll_cmd": 25.0, "zeta_act_roll_cmd": 0.5}),
    Case("quad notch 15 rad/s depth 0.8 pitch", "quad", 204,
         (_e("notch_filter", input="pitch_cmd", omega_rad_s=15.0, zeta=0.2, depth=0.8),), {("notch_filter", "pitch_cmd")},
         {"w_notch_pitch_cmd": 15.0, "zeta_notch_pitch_cmd": 0.2, "depth_notch_pitch_cmd": 0.8}),
    Case("quad mode q 30 rad/s zeta 0.05/0.15", "quad", 205,
         (_e("structural_mode", output="q", omega_rad_s=30.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "q")}, {"w_mode_q": 30.0, "zeta_mode_q": 0.05, "zeta_zero_mode_q": 0.15}),
    Case("quad skew 30 ms phi", "quad", 206, (_e("sensor_skew", output="phi", delay_s=0.03),), {("sensor_skew", "phi")},
         {"skew_phi": 0.03}),
    Case("quad missing Mu", "quad", 207, (), {("missing_derivative", "F[q][u]")}, {"F_q_u": 0.65},
         (("drop", "F", "q", "u", "Mu"),)),
    Case("quad mode p + lag pitch", "quad", 208,
         (_e("structural_mode", output="p", omega_rad_s=25.0, zeta_pole=0.06, zeta_zero=0.2),
          _e("actuator_lag", input="pitch_cmd", time_constant_s=0.04)),
         {("structural_mode", "p"), ("actuator_lag", "pitch_cmd")}, {"w_mode_p": 25.0, "w_act_pitch_cmd": 25.0}),
]
HELD_OUT_CLEAN = ([Case(f"clean cruise seed {s}", "cruise", s) for s in range(220, 228)]
                  + [Case(f"clean hover seed {s}", "hover", s) for s in range(220, 227)]
                  + [Case(f"clean quad seed {s}", "quad", s) for s in range(220, 225)]
                  + [Case("clean cruise calm air", "cruise", 228, turbulence=0.0),
                     Case("clean cruise full turbulence", "cruise", 229, turbulence=1.0)])


# Second held-out set: written after the second start of the refit (the case's own starting values
# when the refit from the current fit does not converge) was added, on a miss of the first held-out
# set, which from then on counts as development data. Not run before that change was frozen.
HELD_OUT_2 = [
    Case("cruise delay 50 ms da", "cruise", 301, (_e("time_delay", input="da", delay_s=0.05),), {("time_delay", "da")},
         {"tau_a": TAU_A + 0.05}, (("fix", "tau_a", TAU_A),)),
    Case("cruise delay 80 ms dr", "cruise", 302, (_e("time_delay", input="dr", delay_s=0.08),), {("time_delay", "dr")},
         {"tau_r": TAU_R + 0.08}, (("fix", "tau_r", TAU_R),)),
    Case("cruise lag 60 ms dr", "cruise", 303, (_e("actuator_lag", input="dr", time_constant_s=0.06),),
         {("actuator_lag", "dr")}, {"w_act_dr": 1 / 0.06}),
    Case("cruise lag 0.15 s da", "cruise", 304, (_e("actuator_lag", input="da", time_constant_s=0.15),),
         {("actuator_lag", "da")}, {"w_act_da": 1 / 0.15}),
    Case("cruise 2nd-order 10 rad/s zeta 0.5 dr", "cruise", 305,
         (_e("actuator_second_order", input="dr", omega_rad_s=10.0, zeta=0.5),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 10.0, "zeta_act_dr": 0.5}),
    Case("cruise notch 5 rad/s depth 0.8 dr", "cruise", 306,
         (_e("notch_filter", input="dr", omega_rad_s=5.0, zeta=0.25, depth=0.8),), {("notch_filter", "dr")},
         {"w_notch_dr": 5.0, "zeta_notch_dr": 0.25, "depth_notch_dr": 0.8}),
    Case("cruise mode r 8 rad/s zeta 0.06/0.2", "cruise", 307,
         (_e("structural_mode", output="r", omega_rad_s=8.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "r")}, {"w_mode_r": 8.0, "zeta_mode_r": 0.06, "zeta_zero_mode_r": 0.2}),
    Case("cruise mode p 18 rad/s zeta 0.05/0.15", "cruise", 308,
         (_e("structural_mode", output="p", omega_rad_s=18.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 18.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("cruise skew 40 ms r", "cruise", 309, (_e("sensor_skew", output="r", delay_s=0.04),), {("sensor_skew", "r")},
         {"skew_r": 0.04}),
    Case("cruise skew 60 ms ay", "cruise", 310, (_e("sensor_skew", output="ay", delay_s=0.06),), {("sensor_skew", "ay")},
         {"skew_ay": 0.06}),
    Case("cruise scale 0.8 p", "cruise", 311, (_e("scale_factor", output="p", factor=0.8),),
         {("scale_factor", "p")}, {"k_p": 0.8}),
    Case("cruise missing Lv", "cruise", 312, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -8.119e-3},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("cruise lag dr + mode p", "cruise", 313,
         (_e("actuator_lag", input="dr", time_constant_s=0.08),
          _e("structural_mode", output="p", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_lag", "dr"), ("structural_mode", "p")}, {"w_act_dr": 12.5, "w_mode_p": 12.0}),
    # (written as 30 ms at first: at 50 Hz the log is two samples late, 40 ms, which the loop found)
    Case("cruise input skew 40 ms da", "cruise", 314, (), {("sensor_skew", "da")}, {"skew_da": 0.04},
         (("fix", "tau_a", TAU_A),), log_late=("da", 0.04)),
    Case("hover delay 80 ms dr", "hover", 301, (_e("time_delay", input="dr", delay_s=0.08),), {("time_delay", "dr")},
         {"tau_dr": 0.08}),
    Case("hover lag 0.2 s dr", "hover", 302, (_e("actuator_lag", input="dr", time_constant_s=0.2),),
         {("actuator_lag", "dr")}, {"w_act_dr": 5.0}),
    Case("hover 2nd-order 8 rad/s zeta 0.5 da", "hover", 303,
         (_e("actuator_second_order", input="da", omega_rad_s=8.0, zeta=0.5),), {("actuator_second_order", "da")},
         {"wn_act_da": 8.0, "zeta_act_da": 0.5}),
    Case("hover notch 4 rad/s depth 0.7 da", "hover", 304,
         (_e("notch_filter", input="da", omega_rad_s=4.0, zeta=0.3, depth=0.7),), {("notch_filter", "da")},
         {"w_notch_da": 4.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.7}),
    Case("hover mode p 6 rad/s zeta 0.06/0.2", "hover", 305,
         (_e("structural_mode", output="p", omega_rad_s=6.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "p")}, {"w_mode_p": 6.0, "zeta_mode_p": 0.06, "zeta_zero_mode_p": 0.2}),
    Case("hover skew 40 ms phi", "hover", 306, (_e("sensor_skew", output="phi", delay_s=0.04),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.04}),
    Case("hover missing Lp", "hover", 307, (), {("missing_derivative", "F[p][p]")}, {"F_p_p": -0.2365},
         (("drop", "F", "p", "p", "Lp"),)),
    Case("hover scale 1.3 v", "hover", 308, (_e("scale_factor", output="v", factor=1.3),),
         {("scale_factor", "v")}, {"k_v": 1.3}),
    Case("hover delay da + mode r", "hover", 309,
         (_e("time_delay", input="da", delay_s=0.06),
          _e("structural_mode", output="r", omega_rad_s=7.0, zeta_pole=0.05, zeta_zero=0.2)),
         {("time_delay", "da"), ("structural_mode", "r")}, {"tau_da": 0.06, "w_mode_r": 7.0}),
    Case("quad delay 15 ms pitch", "quad", 301, (_e("time_delay", input="pitch_cmd", delay_s=0.015),),
         {("time_delay", "pitch_cmd")}, {"tau_pitch": TAU_Q + 0.015}),
    Case("quad lag 20 ms roll", "quad", 302, (_e("actuator_lag", input="roll_cmd", time_constant_s=0.02),),
         {("actuator_lag", "roll_cmd")}, {"w_act_roll_cmd": 50.0}),
    Case("quad 2nd-order 30 rad/s zeta 0.6 pitch", "quad", 303,
         (_e("actuator_second_order", input="pitch_cmd", omega_rad_s=30.0, zeta=0.6),),
         {("actuator_second_order", "pitch_cmd")}, {"wn_act_pitch_cmd": 30.0, "zeta_act_pitch_cmd": 0.6}),
    Case("quad notch 20 rad/s depth 0.7 roll", "quad", 304,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=20.0, zeta=0.2, depth=0.7),), {("notch_filter", "roll_cmd")},
         {"w_notch_roll_cmd": 20.0, "zeta_notch_roll_cmd": 0.2, "depth_notch_roll_cmd": 0.7}),
    Case("quad mode p 35 rad/s zeta 0.05/0.15", "quad", 305,
         (_e("structural_mode", output="p", omega_rad_s=35.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 35.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("quad skew 20 ms theta", "quad", 306, (_e("sensor_skew", output="theta", delay_s=0.02),),
         {("sensor_skew", "theta")}, {"skew_theta": 0.02}),
    Case("quad missing Lv", "quad", 307, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -0.80},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("quad scale 1.2 q", "quad", 308, (_e("scale_factor", output="q", factor=1.2),),
         {("scale_factor", "q")}, {"k_q": 1.2}),
    Case("quad mode q + delay roll", "quad", 309,
         (_e("structural_mode", output="q", omega_rad_s=20.0, zeta_pole=0.06, zeta_zero=0.2),
          _e("time_delay", input="roll_cmd", delay_s=0.02)),
         {("structural_mode", "q"), ("time_delay", "roll_cmd")}, {"w_mode_q": 20.0, "tau_roll": TAU_Q + 0.02}),
]
HELD_OUT_2_CLEAN = ([Case(f"clean cruise seed {s}", "cruise", s) for s in range(330, 338)]
                    + [Case(f"clean hover seed {s}", "hover", s) for s in range(330, 337)]
                    + [Case(f"clean quad seed {s}", "quad", s) for s in range(330, 336)]
                    + [Case("clean cruise calm air", "cruise", 338, turbulence=0.0),
                       Case("clean cruise full turbulence", "cruise", 339, turbulence=1.0)])

#: A third held-out set, written after the last change to the loop (stop 22) and run once on it:
#: new seeds (401-449), magnitudes and places, every kind on every airframe, three pairs.
HELD_OUT_3 = [
    Case("cruise delay 25 ms da", "cruise", 401, (_e("time_delay", input="da", delay_s=0.025),), {("time_delay", "da")},
         {"tau_a": TAU_A + 0.025}, (("fix", "tau_a", TAU_A),)),
    Case("cruise lag 0.1 s da", "cruise", 402, (_e("actuator_lag", input="da", time_constant_s=0.1),),
         {("actuator_lag", "da")}, {"w_act_da": 10.0}),
    Case("cruise lag 50 ms dr", "cruise", 403, (_e("actuator_lag", input="dr", time_constant_s=0.05),),
         {("actuator_lag", "dr")}, {"w_act_dr": 20.0}),
    Case("cruise 2nd-order 14 rad/s zeta 0.6 da", "cruise", 404,
         (_e("actuator_second_order", input="da", omega_rad_s=14.0, zeta=0.6),), {("actuator_second_order", "da")},
         {"wn_act_da": 14.0, "zeta_act_da": 0.6}),
    Case("cruise notch 7 rad/s depth 0.6 da", "cruise", 405,
         (_e("notch_filter", input="da", omega_rad_s=7.0, zeta=0.2, depth=0.6),), {("notch_filter", "da")},
         {"w_notch_da": 7.0, "zeta_notch_da": 0.2, "depth_notch_da": 0.6}),
    Case("cruise mode r 14 rad/s zeta 0.05/0.2", "cruise", 406,
         (_e("structural_mode", output="r", omega_rad_s=14.0, zeta_pole=0.05, zeta_zero=0.2),),
         {("structural_mode", "r")}, {"w_mode_r": 14.0, "zeta_mode_r": 0.05, "zeta_zero_mode_r": 0.2}),
    Case("cruise mode p 6 rad/s zeta 0.08/0.25", "cruise", 407,
         (_e("structural_mode", output="p", omega_rad_s=6.0, zeta_pole=0.08, zeta_zero=0.25),),
         {("structural_mode", "p")}, {"w_mode_p": 6.0, "zeta_mode_p": 0.08, "zeta_zero_mode_p": 0.25}),
    Case("cruise skew 30 ms p", "cruise", 408, (_e("sensor_skew", output="p", delay_s=0.03),), {("sensor_skew", "p")},
         {"skew_p": 0.03}),
    Case("cruise scale 1.25 r", "cruise", 409, (_e("scale_factor", output="r", factor=1.25),),
         {("scale_factor", "r")}, {"k_r": 1.25}),
    Case("cruise missing Np", "cruise", 410, (), {("missing_derivative", "F[r][p]")}, {"F_r_p": -0.2308},
         (("drop", "F", "r", "p", "Np"),)),
    Case("cruise delay da + skew ay", "cruise", 411,
         (_e("time_delay", input="da", delay_s=0.04), _e("sensor_skew", output="ay", delay_s=0.04)),
         {("time_delay", "da"), ("sensor_skew", "ay")}, {"tau_a": TAU_A + 0.04, "skew_ay": 0.04},
         (("fix", "tau_a", TAU_A),)),
    Case("cruise input skew 40 ms dr", "cruise", 412, (), {("sensor_skew", "dr")}, {"skew_dr": 0.04},
         (("fix", "tau_r", TAU_R),), log_late=("dr", 0.04)),
    Case("hover delay 40 ms da", "hover", 401, (_e("time_delay", input="da", delay_s=0.04),), {("time_delay", "da")},
         {"tau_da": 0.04}),
    Case("hover delay 0.12 s dr", "hover", 402, (_e("time_delay", input="dr", delay_s=0.12),), {("time_delay", "dr")},
         {"tau_dr": 0.12}),
    Case("hover lag 0.12 s da", "hover", 403, (_e("actuator_lag", input="da", time_constant_s=0.12),),
         {("actuator_lag", "da")}, {"w_act_da": 1 / 0.12}),
    Case("hover 2nd-order 6 rad/s zeta 0.7 dr", "hover", 404,
         (_e("actuator_second_order", input="dr", omega_rad_s=6.0, zeta=0.7),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 6.0, "zeta_act_dr": 0.7}),
    Case("hover notch 3 rad/s depth 0.6 dr", "hover", 405,
         (_e("notch_filter", input="dr", omega_rad_s=3.0, zeta=0.3, depth=0.6),), {("notch_filter", "dr")},
         {"w_notch_dr": 3.0, "zeta_notch_dr": 0.3, "depth_notch_dr": 0.6}),
    Case("hover mode r 5 rad/s zeta 0.05/0.15", "hover", 406,
         (_e("structural_mode", output="r", omega_rad_s=5.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "r")}, {"w_mode_r": 5.0, "zeta_mode_r": 0.05, "zeta_zero_mode_r": 0.15}),
    Case("hover skew 60 ms p", "hover", 407, (_e("sensor_skew", output="p", delay_s=0.06),), {("sensor_skew", "p")},
         {"skew_p": 0.06}),
    Case("hover missing Nr", "hover", 408, (), {("missing_derivative", "F[r][r]")}, {"F_r_r": -0.1416},
         (("drop", "F", "r", "r", "Nr"),)),
    Case("hover lag dr + skew phi", "hover", 409,
         (_e("actuator_lag", input="dr", time_constant_s=0.15), _e("sensor_skew", output="phi", delay_s=0.03)),
         {("actuator_lag", "dr"), ("sensor_skew", "phi")}, {"w_act_dr": 1 / 0.15, "skew_phi": 0.03}),
    Case("quad delay 10 ms roll", "quad", 401, (_e("time_delay", input="roll_cmd", delay_s=0.01),),
         {("time_delay", "roll_cmd")}, {"tau_roll": TAU_Q + 0.01}),
    Case("quad delay 30 ms pitch", "quad", 402, (_e("time_delay", input="pitch_cmd", delay_s=0.03),),
         {("time_delay", "pitch_cmd")}, {"tau_pitch": TAU_Q + 0.03}),
    Case("quad lag 15 ms pitch", "quad", 403, (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.015),),
         {("actuator_lag", "pitch_cmd")}, {"w_act_pitch_cmd": 1 / 0.015}),
    Case("quad 2nd-order 40 rad/s zeta 0.5 roll", "quad", 404,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=40.0, zeta=0.5),), {("actuator_second_order", "roll_cmd")},
         {"wn_act_roll_cmd": 40.0, "zeta_act_roll_cmd": 0.5}),
    Case("quad notch 25 rad/s depth 0.6 pitch", "quad", 405,
         (_e("notch_filter", input="pitch_cmd", omega_rad_s=25.0, zeta=0.2, depth=0.6),), {("notch_filter", "pitch_cmd")},
         {"w_notch_pitch_cmd": 25.0, "zeta_notch_pitch_cmd": 0.2, "depth_notch_pitch_cmd": 0.6}),
    Case("quad mode q 25 rad/s zeta 0.05/0.15", "quad", 406,
         (_e("structural_mode", output="q", omega_rad_s=25.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "q")}, {"w_mode_q": 25.0, "zeta_mode_q": 0.05, "zeta_zero_mode_q": 0.15}),
    Case("quad mode p 15 rad/s zeta 0.06/0.2", "quad", 407,
         (_e("structural_mode", output="p", omega_rad_s=15.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "p")}, {"w_mode_p": 15.0, "zeta_mode_p": 0.06, "zeta_zero_mode_p": 0.2}),
    Case("quad skew 15 ms phi", "quad", 408, (_e("sensor_skew", output="phi", delay_s=0.015),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.015}),
    Case("quad scale 0.8 p", "quad", 409, (_e("scale_factor", output="p", factor=0.8),),
         {("scale_factor", "p")}, {"k_p": 0.8}),
    Case("quad missing Mq", "quad", 410, (), {("missing_derivative", "F[q][q]")}, {"F_q_q": -3.4},
         (("drop", "F", "q", "q", "Mq"),)),
    Case("quad notch roll + skew theta", "quad", 411,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=15.0, zeta=0.2, depth=0.7),
          _e("sensor_skew", output="theta", delay_s=0.02)),
         {("notch_filter", "roll_cmd"), ("sensor_skew", "theta")}, {"w_notch_roll_cmd": 15.0, "skew_theta": 0.02}),
]
HELD_OUT_3_CLEAN = ([Case(f"clean cruise seed {s}", "cruise", s) for s in range(440, 448)]
                    + [Case(f"clean hover seed {s}", "hover", s) for s in range(440, 447)]
                    + [Case(f"clean quad seed {s}", "quad", s) for s in range(440, 446)]
                    + [Case("clean cruise calm air", "cruise", 448, turbulence=0.0),
                       Case("clean cruise full turbulence", "cruise", 449, turbulence=1.0)])


#: A fourth held-out set, written after the last change to the loop (stop 23: partners of a pair
#: both needed, the verification gate at the false-alarm level, rivals named) and run once on it:
#: seeds 501-549, new magnitudes and places, missing control derivatives, an input skew on da.
HELD_OUT_4 = [
    Case("cruise delay 50 ms dr", "cruise", 501, (_e("time_delay", input="dr", delay_s=0.05),), {("time_delay", "dr")},
         {"tau_r": TAU_R + 0.05}, (("fix", "tau_r", TAU_R),)),
    Case("cruise lag 0.15 s da", "cruise", 502, (_e("actuator_lag", input="da", time_constant_s=0.15),),
         {("actuator_lag", "da")}, {"w_act_da": 1 / 0.15}),
    Case("cruise 2nd-order 10 rad/s zeta 0.5 dr", "cruise", 503,
         (_e("actuator_second_order", input="dr", omega_rad_s=10.0, zeta=0.5),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 10.0, "zeta_act_dr": 0.5}),
    Case("cruise notch 5 rad/s depth 0.7 dr", "cruise", 504,
         (_e("notch_filter", input="dr", omega_rad_s=5.0, zeta=0.25, depth=0.7),), {("notch_filter", "dr")},
         {"w_notch_dr": 5.0, "zeta_notch_dr": 0.25, "depth_notch_dr": 0.7}),
    Case("cruise mode p 16 rad/s zeta 0.05/0.15", "cruise", 505,
         (_e("structural_mode", output="p", omega_rad_s=16.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 16.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("cruise mode r 8 rad/s zeta 0.06/0.2", "cruise", 506,
         (_e("structural_mode", output="r", omega_rad_s=8.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "r")}, {"w_mode_r": 8.0, "zeta_mode_r": 0.06, "zeta_zero_mode_r": 0.2}),
    Case("cruise skew 35 ms ay", "cruise", 507, (_e("sensor_skew", output="ay", delay_s=0.035),),
         {("sensor_skew", "ay")}, {"skew_ay": 0.035}),
    Case("cruise scale 0.8 r", "cruise", 508, (_e("scale_factor", output="r", factor=0.8),),
         {("scale_factor", "r")}, {"k_r": 0.8}),
    Case("cruise missing Ndr", "cruise", 509, (), {("missing_derivative", "G[r][dr]")}, {"G_r_dr": 0.02213},
         (("drop", "G", "r", "dr", "Ndr"),)),
    Case("cruise mode r + lag dr", "cruise", 510,
         (_e("structural_mode", output="r", omega_rad_s=11.0, zeta_pole=0.05, zeta_zero=0.15),
          _e("actuator_lag", input="dr", time_constant_s=0.1)),
         {("structural_mode", "r"), ("actuator_lag", "dr")}, {"w_mode_r": 11.0, "w_act_dr": 10.0}),
    Case("cruise input skew 30 ms da", "cruise", 511, (), {("sensor_skew", "da")}, {"skew_da": 0.03},
         (("fix", "tau_a", TAU_A),), log_late=("da", 0.03)),
    Case("hover delay 80 ms dr", "hover", 501, (_e("time_delay", input="dr", delay_s=0.08),), {("time_delay", "dr")},
         {"tau_dr": 0.08}),
    Case("hover delay 20 ms da", "hover", 502, (_e("time_delay", input="da", delay_s=0.02),), {("time_delay", "da")},
         {"tau_da": 0.02}),
    Case("hover lag 80 ms da", "hover", 503, (_e("actuator_lag", input="da", time_constant_s=0.08),),
         {("actuator_lag", "da")}, {"w_act_da": 12.5}),
    Case("hover 2nd-order 7 rad/s zeta 0.6 da", "hover", 504,
         (_e("actuator_second_order", input="da", omega_rad_s=7.0, zeta=0.6),), {("actuator_second_order", "da")},
         {"wn_act_da": 7.0, "zeta_act_da": 0.6}),
    Case("hover notch 4 rad/s depth 0.8 dr", "hover", 505,
         (_e("notch_filter", input="dr", omega_rad_s=4.0, zeta=0.25, depth=0.8),), {("notch_filter", "dr")},
         {"w_notch_dr": 4.0, "zeta_notch_dr": 0.25, "depth_notch_dr": 0.8}),
    Case("hover mode p 9 rad/s zeta 0.05/0.15", "hover", 506,
         (_e("structural_mode", output="p", omega_rad_s=9.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 9.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("hover skew 50 ms phi", "hover", 507, (_e("sensor_skew", output="phi", delay_s=0.05),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.05}),
    Case("hover missing Nda", "hover", 508, (), {("missing_derivative", "G[r][da]")}, {"G_r_da": 0.00591},
         (("drop", "G", "r", "da", "Nda"),)),
    Case("hover delay dr + mode p", "hover", 509,
         (_e("time_delay", input="dr", delay_s=0.06),
          _e("structural_mode", output="p", omega_rad_s=7.0, zeta_pole=0.05, zeta_zero=0.2)),
         {("time_delay", "dr"), ("structural_mode", "p")}, {"tau_dr": 0.06, "w_mode_p": 7.0}),
    Case("quad delay 20 ms roll", "quad", 501, (_e("time_delay", input="roll_cmd", delay_s=0.02),),
         {("time_delay", "roll_cmd")}, {"tau_roll": TAU_Q + 0.02}),
    Case("quad lag 25 ms roll", "quad", 502, (_e("actuator_lag", input="roll_cmd", time_constant_s=0.025),),
         {("actuator_lag", "roll_cmd")}, {"w_act_roll_cmd": 40.0}),
    Case("quad 2nd-order 35 rad/s zeta 0.5 pitch", "quad", 503,
         (_e("actuator_second_order", input="pitch_cmd", omega_rad_s=35.0, zeta=0.5),),
         {("actuator_second_order", "pitch_cmd")}, {"wn_act_pitch_cmd": 35.0, "zeta_act_pitch_cmd": 0.5}),
    Case("quad notch 30 rad/s depth 0.7 roll", "quad", 504,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=30.0, zeta=0.2, depth=0.7),), {("notch_filter", "roll_cmd")},
         {"w_notch_roll_cmd": 30.0, "zeta_notch_roll_cmd": 0.2, "depth_notch_roll_cmd": 0.7}),
    Case("quad notch 10 rad/s depth 0.6 pitch", "quad", 505,
         (_e("notch_filter", input="pitch_cmd", omega_rad_s=10.0, zeta=0.25, depth=0.6),), {("notch_filter", "pitch_cmd")},
         {"w_notch_pitch_cmd": 10.0, "zeta_notch_pitch_cmd": 0.25, "depth_notch_pitch_cmd": 0.6}),
    Case("quad mode q 20 rad/s zeta 0.05/0.15", "quad", 506,
         (_e("structural_mode", output="q", omega_rad_s=20.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "q")}, {"w_mode_q": 20.0, "zeta_mode_q": 0.05, "zeta_zero_mode_q": 0.15}),
    Case("quad mode p 25 rad/s zeta 0.06/0.2", "quad", 507,
         (_e("structural_mode", output="p", omega_rad_s=25.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "p")}, {"w_mode_p": 25.0, "zeta_mode_p": 0.06, "zeta_zero_mode_p": 0.2}),
    Case("quad skew 25 ms p", "quad", 508, (_e("sensor_skew", output="p", delay_s=0.025),),
         {("sensor_skew", "p")}, {"skew_p": 0.025}),
    Case("quad skew 30 ms q", "quad", 509, (_e("sensor_skew", output="q", delay_s=0.03),),
         {("sensor_skew", "q")}, {"skew_q": 0.03}),
    Case("quad scale 1.25 theta", "quad", 510, (_e("scale_factor", output="theta", factor=1.25),),
         {("scale_factor", "theta")}, {"k_theta": 1.25}),
    Case("quad missing Mu", "quad", 511, (), {("missing_derivative", "F[q][u]")}, {"F_q_u": 0.65},
         (("drop", "F", "q", "u", "Mu"),)),
    Case("quad lag pitch + skew phi", "quad", 512,
         (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.03), _e("sensor_skew", output="phi", delay_s=0.02)),
         {("actuator_lag", "pitch_cmd"), ("sensor_skew", "phi")}, {"w_act_pitch_cmd": 1 / 0.03, "skew_phi": 0.02}),
]
HELD_OUT_4_CLEAN = ([Case(f"clean cruise seed {s}", "cruise", s) for s in range(540, 548)]
                    + [Case(f"clean hover seed {s}", "hover", s) for s in range(540, 547)]
                    + [Case(f"clean quad seed {s}", "quad", s) for s in range(540, 546)]
                    + [Case("clean cruise calm air", "cruise", 548, turbulence=0.0),
                       Case("clean cruise full turbulence", "cruise", 549, turbulence=1.0)])

#: A fifth held-out set, written after the last change to the loop (stop 24: a missing derivative
#: screened along the exact response, a resonance's gain with the exact factor) and run once on it:
#: seeds 601-649, effects inside the coherent band, new magnitudes and places.
HELD_OUT_5 = [
    Case("cruise delay 30 ms dr", "cruise", 601, (_e("time_delay", input="dr", delay_s=0.03),), {("time_delay", "dr")},
         {"tau_r": TAU_R + 0.03}, (("fix", "tau_r", TAU_R),)),
    Case("cruise lag 80 ms dr", "cruise", 602, (_e("actuator_lag", input="dr", time_constant_s=0.08),),
         {("actuator_lag", "dr")}, {"w_act_dr": 12.5}),
    Case("cruise 2nd-order 8 rad/s zeta 0.6 da", "cruise", 603,
         (_e("actuator_second_order", input="da", omega_rad_s=8.0, zeta=0.6),), {("actuator_second_order", "da")},
         {"wn_act_da": 8.0, "zeta_act_da": 0.6}),
    Case("cruise notch 9 rad/s depth 0.8 da", "cruise", 604,
         (_e("notch_filter", input="da", omega_rad_s=9.0, zeta=0.3, depth=0.8),), {("notch_filter", "da")},
         {"w_notch_da": 9.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.8}),
    Case("cruise mode p 14 rad/s zeta 0.08/0.25", "cruise", 605,
         (_e("structural_mode", output="p", omega_rad_s=14.0, zeta_pole=0.08, zeta_zero=0.25),),
         {("structural_mode", "p")}, {"w_mode_p": 14.0, "zeta_mode_p": 0.08, "zeta_zero_mode_p": 0.25}),
    Case("cruise mode beta 10 rad/s zeta 0.05/0.15", "cruise", 606,
         (_e("structural_mode", output="beta", omega_rad_s=10.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "beta")}, {"w_mode_beta": 10.0, "zeta_mode_beta": 0.05, "zeta_zero_mode_beta": 0.15}),
    Case("cruise skew 40 ms r", "cruise", 607, (_e("sensor_skew", output="r", delay_s=0.04),),
         {("sensor_skew", "r")}, {"skew_r": 0.04}),
    Case("cruise scale 1.2 p", "cruise", 608, (_e("scale_factor", output="p", factor=1.2),),
         {("scale_factor", "p")}, {"k_p": 1.2}),
    Case("cruise missing Nv", "cruise", 609, (), {("missing_derivative", "F[r][v]")}, {"F_r_v": 0.00724},
         (("drop", "F", "r", "v", "Nv"),)),
    Case("cruise notch da + skew r", "cruise", 610,
         (_e("notch_filter", input="da", omega_rad_s=7.0, zeta=0.3, depth=0.7), _e("sensor_skew", output="r", delay_s=0.03)),
         {("notch_filter", "da"), ("sensor_skew", "r")}, {"w_notch_da": 7.0, "skew_r": 0.03}),
    Case("cruise input skew 40 ms dr", "cruise", 611, (), {("sensor_skew", "dr")}, {"skew_dr": 0.04},
         (("fix", "tau_r", TAU_R),), log_late=("dr", 0.04)),
    Case("hover delay 50 ms da", "hover", 601, (_e("time_delay", input="da", delay_s=0.05),), {("time_delay", "da")},
         {"tau_da": 0.05}),
    Case("hover lag 0.12 s dr", "hover", 602, (_e("actuator_lag", input="dr", time_constant_s=0.12),),
         {("actuator_lag", "dr")}, {"w_act_dr": 1 / 0.12}),
    Case("hover 2nd-order 8 rad/s zeta 0.7 dr", "hover", 603,
         (_e("actuator_second_order", input="dr", omega_rad_s=8.0, zeta=0.7),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 8.0, "zeta_act_dr": 0.7}),
    Case("hover notch 3 rad/s depth 0.7 da", "hover", 604,
         (_e("notch_filter", input="da", omega_rad_s=3.0, zeta=0.3, depth=0.7),), {("notch_filter", "da")},
         {"w_notch_da": 3.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.7}),
    Case("hover mode r 6 rad/s zeta 0.05/0.15", "hover", 605,
         (_e("structural_mode", output="r", omega_rad_s=6.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "r")}, {"w_mode_r": 6.0, "zeta_mode_r": 0.05, "zeta_zero_mode_r": 0.15}),
    Case("hover skew 40 ms p", "hover", 606, (_e("sensor_skew", output="p", delay_s=0.04),),
         {("sensor_skew", "p")}, {"skew_p": 0.04}),
    Case("hover scale 0.8 phi", "hover", 607, (_e("scale_factor", output="phi", factor=0.8),),
         {("scale_factor", "phi")}, {"k_phi": 0.8}),
    Case("hover missing Lv", "hover", 608, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -0.004374},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("hover lag da + mode r", "hover", 609,
         (_e("actuator_lag", input="da", time_constant_s=0.1),
          _e("structural_mode", output="r", omega_rad_s=8.0, zeta_pole=0.05, zeta_zero=0.2)),
         {("actuator_lag", "da"), ("structural_mode", "r")}, {"w_act_da": 10.0, "w_mode_r": 8.0}),
    Case("hover delay 0.1 s dr", "hover", 610, (_e("time_delay", input="dr", delay_s=0.1),), {("time_delay", "dr")},
         {"tau_dr": 0.1}),
    Case("quad delay 25 ms pitch", "quad", 601, (_e("time_delay", input="pitch_cmd", delay_s=0.025),),
         {("time_delay", "pitch_cmd")}, {"tau_pitch": TAU_Q + 0.025}),
    Case("quad lag 20 ms pitch", "quad", 602, (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.02),),
         {("actuator_lag", "pitch_cmd")}, {"w_act_pitch_cmd": 50.0}),
    Case("quad 2nd-order 25 rad/s zeta 0.6 roll", "quad", 603,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=25.0, zeta=0.6),),
         {("actuator_second_order", "roll_cmd")}, {"wn_act_roll_cmd": 25.0, "zeta_act_roll_cmd": 0.6}),
    Case("quad notch 12 rad/s depth 0.7 roll", "quad", 604,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=12.0, zeta=0.25, depth=0.7),), {("notch_filter", "roll_cmd")},
         {"w_notch_roll_cmd": 12.0, "zeta_notch_roll_cmd": 0.25, "depth_notch_roll_cmd": 0.7}),
    Case("quad mode p 15 rad/s zeta 0.05/0.15", "quad", 605,
         (_e("structural_mode", output="p", omega_rad_s=15.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 15.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("quad mode q 9 rad/s zeta 0.06/0.2", "quad", 606,
         (_e("structural_mode", output="q", omega_rad_s=9.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "q")}, {"w_mode_q": 9.0, "zeta_mode_q": 0.06, "zeta_zero_mode_q": 0.2}),
    Case("quad skew 20 ms phi", "quad", 607, (_e("sensor_skew", output="phi", delay_s=0.02),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.02}),
    Case("quad skew 35 ms theta", "quad", 608, (_e("sensor_skew", output="theta", delay_s=0.035),),
         {("sensor_skew", "theta")}, {"skew_theta": 0.035}),
    Case("quad scale 0.8 q", "quad", 609, (_e("scale_factor", output="q", factor=0.8),),
         {("scale_factor", "q")}, {"k_q": 0.8}),
    Case("quad missing Lpitch", "quad", 610, (), {("missing_derivative", "G[p][pitch_cmd]")}, {"G_p_pitch_cmd": 4.0},
         (("drop", "G", "p", "pitch_cmd", "Lpitch"),)),
    Case("quad delay roll + mode q", "quad", 611,
         (_e("time_delay", input="roll_cmd", delay_s=0.02),
          _e("structural_mode", output="q", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("time_delay", "roll_cmd"), ("structural_mode", "q")}, {"tau_roll": TAU_Q + 0.02, "w_mode_q": 12.0}),
]
HELD_OUT_5_CLEAN = ([Case(f"clean cruise seed {s}", "cruise", s) for s in range(640, 648)]
                    + [Case(f"clean hover seed {s}", "hover", s) for s in range(640, 647)]
                    + [Case(f"clean quad seed {s}", "quad", s) for s in range(640, 646)]
                    + [Case("clean cruise calm air", "cruise", 648, turbulence=0.0),
                       Case("clean cruise full turbulence", "cruise", 649, turbulence=1.0)])

#: A sixth held-out set, written before the stop-25 change to the loop was final (a lack-of-fit
#: test on the baseline, refits of every missing derivative when it fails) and run once after it:
#: seeds 701-749, new magnitudes and places, effects inside the coherent band.
HELD_OUT_6 = [
    Case("cruise delay 45 ms dr", "cruise", 701, (_e("time_delay", input="dr", delay_s=0.045),), {("time_delay", "dr")},
         {"tau_r": TAU_R + 0.045}, (("fix", "tau_r", TAU_R),)),
    Case("cruise lag 60 ms da", "cruise", 702, (_e("actuator_lag", input="da", time_constant_s=0.06),),
         {("actuator_lag", "da")}, {"w_act_da": 1 / 0.06}),
    Case("cruise 2nd-order 10 rad/s zeta 0.5 dr", "cruise", 703,
         (_e("actuator_second_order", input="dr", omega_rad_s=10.0, zeta=0.5),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 10.0, "zeta_act_dr": 0.5}),
    Case("cruise notch 5 rad/s depth 0.6 dr", "cruise", 704,
         (_e("notch_filter", input="dr", omega_rad_s=5.0, zeta=0.3, depth=0.6),), {("notch_filter", "dr")},
         {"w_notch_dr": 5.0, "zeta_notch_dr": 0.3, "depth_notch_dr": 0.6}),
    Case("cruise mode r 11 rad/s zeta 0.06/0.2", "cruise", 705,
         (_e("structural_mode", output="r", omega_rad_s=11.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "r")}, {"w_mode_r": 11.0, "zeta_mode_r": 0.06, "zeta_zero_mode_r": 0.2}),
    Case("cruise skew 30 ms p", "cruise", 706, (_e("sensor_skew", output="p", delay_s=0.03),),
         {("sensor_skew", "p")}, {"skew_p": 0.03}),
    Case("cruise scale 0.85 r", "cruise", 707, (_e("scale_factor", output="r", factor=0.85),),
         {("scale_factor", "r")}, {"k_r": 0.85}),
    Case("cruise missing Lv", "cruise", 708, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -0.008119},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("cruise lag dr + mode p", "cruise", 709,
         (_e("actuator_lag", input="dr", time_constant_s=0.1),
          _e("structural_mode", output="p", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_lag", "dr"), ("structural_mode", "p")}, {"w_act_dr": 10.0, "w_mode_p": 12.0}),
    Case("cruise missing Np", "cruise", 710, (), {("missing_derivative", "F[r][p]")}, {"F_r_p": -0.2308},
         (("drop", "F", "r", "p", "Np"),)),
    Case("cruise input skew 30 ms da", "cruise", 711, (), {("sensor_skew", "da")}, {"skew_da": 0.03},
         (("fix", "tau_a", TAU_A),), log_late=("da", 0.03)),
    Case("hover delay 70 ms dr", "hover", 701, (_e("time_delay", input="dr", delay_s=0.07),), {("time_delay", "dr")},
         {"tau_dr": 0.07}),
    Case("hover lag 0.08 s da", "hover", 702, (_e("actuator_lag", input="da", time_constant_s=0.08),),
         {("actuator_lag", "da")}, {"w_act_da": 12.5}),
    Case("hover 2nd-order 10 rad/s zeta 0.5 da", "hover", 703,
         (_e("actuator_second_order", input="da", omega_rad_s=10.0, zeta=0.5),), {("actuator_second_order", "da")},
         {"wn_act_da": 10.0, "zeta_act_da": 0.5}),
    Case("hover notch 4 rad/s depth 0.6 dr", "hover", 704,
         (_e("notch_filter", input="dr", omega_rad_s=4.0, zeta=0.3, depth=0.6),), {("notch_filter", "dr")},
         {"w_notch_dr": 4.0, "zeta_notch_dr": 0.3, "depth_notch_dr": 0.6}),
    Case("hover mode p 7 rad/s zeta 0.06/0.2", "hover", 705,
         (_e("structural_mode", output="p", omega_rad_s=7.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "p")}, {"w_mode_p": 7.0, "zeta_mode_p": 0.06, "zeta_zero_mode_p": 0.2}),
    Case("hover skew 30 ms r", "hover", 706, (_e("sensor_skew", output="r", delay_s=0.03),),
         {("sensor_skew", "r")}, {"skew_r": 0.03}),
    Case("hover scale 1.25 p", "hover", 707, (_e("scale_factor", output="p", factor=1.25),),
         {("scale_factor", "p")}, {"k_p": 1.25}),
    Case("hover missing Np", "hover", 708, (), {("missing_derivative", "F[r][p]")}, {"F_r_p": 0.03862},
         (("drop", "F", "r", "p", "Np"),)),
    Case("hover missing Nda", "hover", 709, (), {("missing_derivative", "G[r][da]")}, {"G_r_da": 0.00591},
         (("drop", "G", "r", "da", "Nda"),)),
    Case("hover delay dr + skew p", "hover", 710,
         (_e("time_delay", input="dr", delay_s=0.06), _e("sensor_skew", output="p", delay_s=0.03)),
         {("time_delay", "dr"), ("sensor_skew", "p")}, {"tau_dr": 0.06, "skew_p": 0.03}),
    Case("quad delay 30 ms roll", "quad", 701, (_e("time_delay", input="roll_cmd", delay_s=0.03),),
         {("time_delay", "roll_cmd")}, {"tau_roll": TAU_Q + 0.03}),
    Case("quad lag 30 ms roll", "quad", 702, (_e("actuator_lag", input="roll_cmd", time_constant_s=0.03),),
         {("actuator_lag", "roll_cmd")}, {"w_act_roll_cmd": 1 / 0.03}),
    Case("quad 2nd-order 20 rad/s zeta 0.5 pitch", "quad", 703,
         (_e("actuator_second_order", input="pitch_cmd", omega_rad_s=20.0, zeta=0.5),),
         {("actuator_second_order", "pitch_cmd")}, {"wn_act_pitch_cmd": 20.0, "zeta_act_pitch_cmd": 0.5}),
    Case("quad notch 10 rad/s depth 0.6 pitch", "quad", 704,
         (_e("notch_filter", input="pitch_cmd", omega_rad_s=10.0, zeta=0.3, depth=0.6),),
         {("notch_filter", "pitch_cmd")},
         {"w_notch_pitch_cmd": 10.0, "zeta_notch_pitch_cmd": 0.3, "depth_notch_pitch_cmd": 0.6}),
    Case("quad mode p 11 rad/s zeta 0.05/0.2", "quad", 705,
         (_e("structural_mode", output="p", omega_rad_s=11.0, zeta_pole=0.05, zeta_zero=0.2),),
         {("structural_mode", "p")}, {"w_mode_p": 11.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.2}),
    Case("quad mode q 14 rad/s zeta 0.07/0.2", "quad", 706,
         (_e("structural_mode", output="q", omega_rad_s=14.0, zeta_pole=0.07, zeta_zero=0.2),),
         {("structural_mode", "q")}, {"w_mode_q": 14.0, "zeta_mode_q": 0.07, "zeta_zero_mode_q": 0.2}),
    Case("quad skew 25 ms q", "quad", 707, (_e("sensor_skew", output="q", delay_s=0.025),),
         {("sensor_skew", "q")}, {"skew_q": 0.025}),
    Case("quad skew 20 ms p", "quad", 708, (_e("sensor_skew", output="p", delay_s=0.02),),
         {("sensor_skew", "p")}, {"skew_p": 0.02}),
    Case("quad missing Mq", "quad", 709, (), {("missing_derivative", "F[q][q]")}, {"F_q_q": -3.4},
         (("drop", "F", "q", "q", "Mq"),)),
    Case("quad scale 1.2 theta", "quad", 710, (_e("scale_factor", output="theta", factor=1.2),),
         {("scale_factor", "theta")}, {"k_theta": 1.2}),
    Case("quad lag pitch + mode p", "quad", 711,
         (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.025),
          _e("structural_mode", output="p", omega_rad_s=13.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_lag", "pitch_cmd"), ("structural_mode", "p")}, {"w_act_pitch_cmd": 40.0, "w_mode_p": 13.0}),
]
HELD_OUT_6_CLEAN = ([Case(f"clean cruise seed {s}", "cruise", s) for s in range(740, 748)]
                    + [Case(f"clean hover seed {s}", "hover", s) for s in range(740, 747)]
                    + [Case(f"clean quad seed {s}", "quad", s) for s in range(740, 746)]
                    + [Case("clean cruise calm air", "cruise", 748, turbulence=0.0),
                       Case("clean cruise full turbulence", "cruise", 749, turbulence=1.0)])


# Written at stop 26, after the quadrotor's analysis took the method's default windows (up to half
# the record) instead of 2-20 s, and before anything was run on it. Run once.
HELD_OUT_7 = [
    Case("quad delay 20 ms pitch", "quad", 801, (_e("time_delay", input="pitch_cmd", delay_s=0.02),),
         {("time_delay", "pitch_cmd")}, {"tau_pitch": TAU_Q + 0.02}),
    Case("quad lag 25 ms pitch", "quad", 802, (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.025),),
         {("actuator_lag", "pitch_cmd")}, {"w_act_pitch_cmd": 40.0}),
    Case("quad 2nd-order 25 rad/s zeta 0.6 roll", "quad", 803,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=25.0, zeta=0.6),),
         {("actuator_second_order", "roll_cmd")}, {"wn_act_roll_cmd": 25.0, "zeta_act_roll_cmd": 0.6}),
    Case("quad notch 12 rad/s depth 0.7 roll", "quad", 804,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=12.0, zeta=0.3, depth=0.7),),
         {("notch_filter", "roll_cmd")},
         {"w_notch_roll_cmd": 12.0, "zeta_notch_roll_cmd": 0.3, "depth_notch_roll_cmd": 0.7}),
    Case("quad mode p 16 rad/s zeta 0.05/0.15", "quad", 805,
         (_e("structural_mode", output="p", omega_rad_s=16.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 16.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("quad mode q 10 rad/s zeta 0.06/0.2", "quad", 806,
         (_e("structural_mode", output="q", omega_rad_s=10.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "q")}, {"w_mode_q": 10.0, "zeta_mode_q": 0.06, "zeta_zero_mode_q": 0.2}),
    Case("quad skew 30 ms theta", "quad", 807, (_e("sensor_skew", output="theta", delay_s=0.03),),
         {("sensor_skew", "theta")}, {"skew_theta": 0.03}),
    Case("quad skew 25 ms phi", "quad", 808, (_e("sensor_skew", output="phi", delay_s=0.025),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.025}),
    Case("quad missing Lv", "quad", 809, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -0.80},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("quad missing Mu", "quad", 810, (), {("missing_derivative", "F[q][u]")}, {"F_q_u": 0.65},
         (("drop", "F", "q", "u", "Mu"),)),
    Case("quad scale 0.8 q", "quad", 811, (_e("scale_factor", output="q", factor=0.8),),
         {("scale_factor", "q")}, {"k_q": 0.8}),
    Case("quad scale 1.25 p", "quad", 812, (_e("scale_factor", output="p", factor=1.25),),
         {("scale_factor", "p")}, {"k_p": 1.25}),
    Case("quad delay roll + mode q", "quad", 813,
         (_e("time_delay", input="roll_cmd", delay_s=0.025),
          _e("structural_mode", output="q", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("time_delay", "roll_cmd"), ("structural_mode", "q")}, {"tau_roll": TAU_Q + 0.025, "w_mode_q": 12.0}),
    Case("quad missing Mroll", "quad", 814, (), {("missing_derivative", "G[q][roll_cmd]")},
         {"G_q_roll_cmd": -3.3}, (("drop", "G", "q", "roll_cmd", "Mroll"),)),
    Case("cruise delay 30 ms dr", "cruise", 801, (_e("time_delay", input="dr", delay_s=0.03),), {("time_delay", "dr")},
         {"tau_r": TAU_R + 0.03}, (("fix", "tau_r", TAU_R),)),
    Case("cruise lag 80 ms dr", "cruise", 802, (_e("actuator_lag", input="dr", time_constant_s=0.08),),
         {("actuator_lag", "dr")}, {"w_act_dr": 12.5}),
    Case("cruise notch 6 rad/s depth 0.7 da", "cruise", 803,
         (_e("notch_filter", input="da", omega_rad_s=6.0, zeta=0.3, depth=0.7),), {("notch_filter", "da")},
         {"w_notch_da": 6.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.7}),
    Case("cruise mode p 9 rad/s zeta 0.05/0.15", "cruise", 804,
         (_e("structural_mode", output="p", omega_rad_s=9.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 9.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("cruise skew 40 ms r", "cruise", 805, (_e("sensor_skew", output="r", delay_s=0.04),),
         {("sensor_skew", "r")}, {"skew_r": 0.04}),
    Case("cruise scale 1.2 p", "cruise", 806, (_e("scale_factor", output="p", factor=1.2),),
         {("scale_factor", "p")}, {"k_p": 1.2}),
    Case("hover delay 50 ms dr", "hover", 801, (_e("time_delay", input="dr", delay_s=0.05),), {("time_delay", "dr")},
         {"tau_dr": 0.05}),
    Case("hover lag 0.06 s dr", "hover", 802, (_e("actuator_lag", input="dr", time_constant_s=0.06),),
         {("actuator_lag", "dr")}, {"w_act_dr": 1 / 0.06}),
    Case("hover mode r 6 rad/s zeta 0.06/0.2", "hover", 803,
         (_e("structural_mode", output="r", omega_rad_s=6.0, zeta_pole=0.06, zeta_zero=0.2),),
         {("structural_mode", "r")}, {"w_mode_r": 6.0, "zeta_mode_r": 0.06, "zeta_zero_mode_r": 0.2}),
    Case("hover skew 40 ms p", "hover", 804, (_e("sensor_skew", output="p", delay_s=0.04),),
         {("sensor_skew", "p")}, {"skew_p": 0.04}),
    Case("hover scale 0.8 r", "hover", 805, (_e("scale_factor", output="r", factor=0.8),),
         {("scale_factor", "r")}, {"k_r": 0.8}),
    Case("hover missing Lp", "hover", 806, (), {("missing_derivative", "F[p][p]")}, {"F_p_p": -0.2365},
         (("drop", "F", "p", "p", "Lp"),)),
]
HELD_OUT_7_CLEAN = ([Case(f"clean quad seed {s}", "quad", s) for s in range(820, 834)]
                    + [Case(f"clean cruise seed {s}", "cruise", s) for s in range(820, 825)]
                    + [Case(f"clean hover seed {s}", "hover", s) for s in range(820, 825)])

# Written at stop 26, after the missing-derivative catalogue stopped offering entries in the
# columns of kinematic states (attitude), and before anything was run on it. Run once.
HELD_OUT_8 = [
    Case("hover delay 30 ms da", "hover", 901, (_e("time_delay", input="da", delay_s=0.03),), {("time_delay", "da")},
         {"tau_da": 0.03}),
    Case("hover lag 0.1 s dr", "hover", 902, (_e("actuator_lag", input="dr", time_constant_s=0.1),),
         {("actuator_lag", "dr")}, {"w_act_dr": 10.0}),
    Case("hover 2nd-order 8 rad/s zeta 0.6 dr", "hover", 903,
         (_e("actuator_second_order", input="dr", omega_rad_s=8.0, zeta=0.6),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 8.0, "zeta_act_dr": 0.6}),
    Case("hover notch 3 rad/s depth 0.7 da", "hover", 904,
         (_e("notch_filter", input="da", omega_rad_s=3.0, zeta=0.3, depth=0.7),), {("notch_filter", "da")},
         {"w_notch_da": 3.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.7}),
    Case("hover mode p 8 rad/s zeta 0.05/0.15", "hover", 905,
         (_e("structural_mode", output="p", omega_rad_s=8.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 8.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("hover skew 30 ms phi", "hover", 906, (_e("sensor_skew", output="phi", delay_s=0.03),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.03}),
    Case("hover scale 1.25 phi", "hover", 907, (_e("scale_factor", output="phi", factor=1.25),),
         {("scale_factor", "phi")}, {"k_phi": 1.25}),
    Case("hover missing Lv", "hover", 908, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -0.004374},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("hover delay dr + mode p", "hover", 909,
         (_e("time_delay", input="dr", delay_s=0.06),
          _e("structural_mode", output="p", omega_rad_s=7.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("time_delay", "dr"), ("structural_mode", "p")}, {"tau_dr": 0.06, "w_mode_p": 7.0}),
    Case("cruise input skew 60 ms da", "cruise", 901, (), {("sensor_skew", "da")}, {"skew_da": 0.06},
         (("fix", "tau_a", TAU_A),), log_late=("da", 0.06)),
    Case("cruise lag 50 ms da", "cruise", 902, (_e("actuator_lag", input="da", time_constant_s=0.05),),
         {("actuator_lag", "da")}, {"w_act_da": 20.0}),
    Case("cruise mode r 14 rad/s zeta 0.05/0.15", "cruise", 903,
         (_e("structural_mode", output="r", omega_rad_s=14.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "r")}, {"w_mode_r": 14.0, "zeta_mode_r": 0.05, "zeta_zero_mode_r": 0.15}),
    Case("cruise skew 25 ms p", "cruise", 904, (_e("sensor_skew", output="p", delay_s=0.025),),
         {("sensor_skew", "p")}, {"skew_p": 0.025}),
    Case("cruise missing Np", "cruise", 905, (), {("missing_derivative", "F[r][p]")}, {"F_r_p": -0.2308},
         (("drop", "F", "r", "p", "Np"),)),
    Case("quad lag 20 ms pitch", "quad", 901, (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.02),),
         {("actuator_lag", "pitch_cmd")}, {"w_act_pitch_cmd": 50.0}),
    Case("quad mode q 18 rad/s zeta 0.05/0.15", "quad", 902,
         (_e("structural_mode", output="q", omega_rad_s=18.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "q")}, {"w_mode_q": 18.0, "zeta_mode_q": 0.05, "zeta_zero_mode_q": 0.15}),
    Case("quad skew 20 ms q", "quad", 903, (_e("sensor_skew", output="q", delay_s=0.02),),
         {("sensor_skew", "q")}, {"skew_q": 0.02}),
    Case("quad missing Lpitch", "quad", 904, (), {("missing_derivative", "G[p][pitch_cmd]")},
         {"G_p_pitch_cmd": 4.0}, (("drop", "G", "p", "pitch_cmd", "Lpitch"),)),
]
HELD_OUT_8_CLEAN = ([Case(f"clean hover seed {s}", "hover", s) for s in range(920, 935)]
                    + [Case(f"clean cruise seed {s}", "cruise", s) for s in range(920, 925)]
                    + [Case(f"clean quad seed {s}", "quad", s) for s in range(920, 925)])

# Written at stop 27, before the change that re-identifies every control-path effect once when
# the fit is inadequate was final, and before anything was run on it. Run once.
HELD_OUT_9 = [
    # first written at 5 rad/s: the simulated pilot's roll loop diverged with it (found before any
    # result was printed, by simulating the set's cases alone)
    Case("hover 2nd-order 8 rad/s zeta 0.7 da", "hover", 1001,
         (_e("actuator_second_order", input="da", omega_rad_s=8.0, zeta=0.7),), {("actuator_second_order", "da")},
         {"wn_act_da": 8.0, "zeta_act_da": 0.7}),
    Case("hover 2nd-order 10 rad/s zeta 0.4 dr", "hover", 1002,
         (_e("actuator_second_order", input="dr", omega_rad_s=10.0, zeta=0.4),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 10.0, "zeta_act_dr": 0.4}),
    Case("hover delay 20 ms dr", "hover", 1003, (_e("time_delay", input="dr", delay_s=0.02),), {("time_delay", "dr")},
         {"tau_dr": 0.02}),
    Case("hover lag 0.08 s da", "hover", 1004, (_e("actuator_lag", input="da", time_constant_s=0.08),),
         {("actuator_lag", "da")}, {"w_act_da": 12.5}),
    Case("hover notch 5 rad/s depth 0.6 dr", "hover", 1005,
         (_e("notch_filter", input="dr", omega_rad_s=5.0, zeta=0.3, depth=0.6),), {("notch_filter", "dr")},
         {"w_notch_dr": 5.0, "zeta_notch_dr": 0.3, "depth_notch_dr": 0.6}),
    Case("hover mode r 9 rad/s zeta 0.05/0.15", "hover", 1006,
         (_e("structural_mode", output="r", omega_rad_s=9.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "r")}, {"w_mode_r": 9.0, "zeta_mode_r": 0.05, "zeta_zero_mode_r": 0.15}),
    Case("hover skew 40 ms phi", "hover", 1007, (_e("sensor_skew", output="phi", delay_s=0.04),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.04}),
    Case("hover skew 30 ms r", "hover", 1008, (_e("sensor_skew", output="r", delay_s=0.03),),
         {("sensor_skew", "r")}, {"skew_r": 0.03}),
    Case("hover scale 1.3 p", "hover", 1009, (_e("scale_factor", output="p", factor=1.3),),
         {("scale_factor", "p")}, {"k_p": 1.3}),
    Case("hover missing Nda", "hover", 1010, (), {("missing_derivative", "G[r][da]")}, {"G_r_da": 0.00591},
         (("drop", "G", "r", "da", "Nda"),)),
    Case("hover lag dr + mode p", "hover", 1011,
         (_e("actuator_lag", input="dr", time_constant_s=0.1),
          _e("structural_mode", output="p", omega_rad_s=10.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_lag", "dr"), ("structural_mode", "p")}, {"w_act_dr": 10.0, "w_mode_p": 10.0}),
    Case("cruise 2nd-order 7 rad/s zeta 0.6 dr", "cruise", 1001,
         (_e("actuator_second_order", input="dr", omega_rad_s=7.0, zeta=0.6),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 7.0, "zeta_act_dr": 0.6}),
    Case("cruise delay 25 ms da", "cruise", 1002, (_e("time_delay", input="da", delay_s=0.025),),
         {("time_delay", "da")}, {"tau_a": TAU_A + 0.025}, (("fix", "tau_a", TAU_A),)),
    Case("cruise lag 0.12 s da", "cruise", 1003, (_e("actuator_lag", input="da", time_constant_s=0.12),),
         {("actuator_lag", "da")}, {"w_act_da": 1 / 0.12}),
    Case("cruise notch 4 rad/s depth 0.8 dr", "cruise", 1004,
         (_e("notch_filter", input="dr", omega_rad_s=4.0, zeta=0.3, depth=0.8),), {("notch_filter", "dr")},
         {"w_notch_dr": 4.0, "zeta_notch_dr": 0.3, "depth_notch_dr": 0.8}),
    Case("cruise mode p 15 rad/s zeta 0.05/0.15", "cruise", 1005,
         (_e("structural_mode", output="p", omega_rad_s=15.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 15.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("cruise skew 30 ms beta", "cruise", 1006, (_e("sensor_skew", output="beta", delay_s=0.03),),
         {("sensor_skew", "beta")}, {"skew_beta": 0.03}),
    Case("cruise scale 0.8 r", "cruise", 1007, (_e("scale_factor", output="r", factor=0.8),),
         {("scale_factor", "r")}, {"k_r": 0.8}),
    Case("cruise missing Nv", "cruise", 1008, (), {("missing_derivative", "F[r][v]")}, {"F_r_v": 0.00724},
         (("drop", "F", "r", "v", "Nv"),)),
    Case("cruise input skew 40 ms da", "cruise", 1009, (), {("sensor_skew", "da")}, {"skew_da": 0.04},
         (("fix", "tau_a", TAU_A),), log_late=("da", 0.04)),
    Case("cruise mode r 10 + delay da", "cruise", 1010,
         (_e("structural_mode", output="r", omega_rad_s=10.0, zeta_pole=0.05, zeta_zero=0.15),
          _e("time_delay", input="da", delay_s=0.05)),
         {("structural_mode", "r"), ("time_delay", "da")}, {"w_mode_r": 10.0, "tau_a": TAU_A + 0.05},
         (("fix", "tau_a", TAU_A),)),
    Case("quad delay 30 ms roll", "quad", 1001, (_e("time_delay", input="roll_cmd", delay_s=0.03),),
         {("time_delay", "roll_cmd")}, {"tau_roll": TAU_Q + 0.03}),
    Case("quad lag 30 ms roll", "quad", 1002, (_e("actuator_lag", input="roll_cmd", time_constant_s=0.03),),
         {("actuator_lag", "roll_cmd")}, {"w_act_roll_cmd": 1 / 0.03}),
    Case("quad 2nd-order 15 rad/s zeta 0.5 pitch", "quad", 1003,
         (_e("actuator_second_order", input="pitch_cmd", omega_rad_s=15.0, zeta=0.5),),
         {("actuator_second_order", "pitch_cmd")}, {"wn_act_pitch_cmd": 15.0, "zeta_act_pitch_cmd": 0.5}),
    Case("quad notch 8 rad/s depth 0.7 pitch", "quad", 1004,
         (_e("notch_filter", input="pitch_cmd", omega_rad_s=8.0, zeta=0.3, depth=0.7),), {("notch_filter", "pitch_cmd")},
         {"w_notch_pitch_cmd": 8.0, "zeta_notch_pitch_cmd": 0.3, "depth_notch_pitch_cmd": 0.7}),
    Case("quad mode p 12 rad/s zeta 0.05/0.15", "quad", 1005,
         (_e("structural_mode", output="p", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 12.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("quad skew 25 ms p", "quad", 1006, (_e("sensor_skew", output="p", delay_s=0.025),),
         {("sensor_skew", "p")}, {"skew_p": 0.025}),
    Case("quad scale 1.2 theta", "quad", 1007, (_e("scale_factor", output="theta", factor=1.2),),
         {("scale_factor", "theta")}, {"k_theta": 1.2}),
    Case("quad missing Mq", "quad", 1008, (), {("missing_derivative", "F[q][q]")}, {"F_q_q": -3.4},
         (("drop", "F", "q", "q", "Mq"),)),
    Case("quad lag pitch + mode p", "quad", 1009,
         (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.03),
          _e("structural_mode", output="p", omega_rad_s=14.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_lag", "pitch_cmd"), ("structural_mode", "p")}, {"w_act_pitch_cmd": 1 / 0.03, "w_mode_p": 14.0}),
]
HELD_OUT_9_CLEAN = ([Case(f"clean hover seed {s}", "hover", s) for s in range(1020, 1030)]
                    + [Case(f"clean cruise seed {s}", "cruise", s) for s in range(1020, 1028)]
                    + [Case(f"clean quad seed {s}", "quad", s) for s in range(1020, 1028)])

# Written at stop 27 after held-out-9 was run, with no change to the loop to follow: a second
# judgement of the same code. Run once.
HELD_OUT_10 = [
    Case("hover 2nd-order 9 rad/s zeta 0.5 da", "hover", 1101,
         (_e("actuator_second_order", input="da", omega_rad_s=9.0, zeta=0.5),), {("actuator_second_order", "da")},
         {"wn_act_da": 9.0, "zeta_act_da": 0.5}),
    Case("hover 2nd-order 7 rad/s zeta 0.7 dr", "hover", 1102,
         (_e("actuator_second_order", input="dr", omega_rad_s=7.0, zeta=0.7),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 7.0, "zeta_act_dr": 0.7}),
    Case("hover delay 60 ms da", "hover", 1103, (_e("time_delay", input="da", delay_s=0.06),), {("time_delay", "da")},
         {"tau_da": 0.06}),
    Case("hover lag 0.12 s dr", "hover", 1104, (_e("actuator_lag", input="dr", time_constant_s=0.12),),
         {("actuator_lag", "dr")}, {"w_act_dr": 1 / 0.12}),
    Case("hover notch 4 rad/s depth 0.8 da", "hover", 1105,
         (_e("notch_filter", input="da", omega_rad_s=4.0, zeta=0.3, depth=0.8),), {("notch_filter", "da")},
         {"w_notch_da": 4.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.8}),
    Case("hover mode p 11 rad/s zeta 0.05/0.15", "hover", 1106,
         (_e("structural_mode", output="p", omega_rad_s=11.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 11.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("hover skew 50 ms phi", "hover", 1107, (_e("sensor_skew", output="phi", delay_s=0.05),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.05}),
    Case("hover scale 1.25 r", "hover", 1108, (_e("scale_factor", output="r", factor=1.25),),
         {("scale_factor", "r")}, {"k_r": 1.25}),
    Case("hover missing Np", "hover", 1109, (), {("missing_derivative", "F[r][p]")}, {"F_r_p": 0.03862},
         (("drop", "F", "r", "p", "Np"),)),
    Case("hover 2nd-order dr + skew p", "hover", 1110,
         (_e("actuator_second_order", input="dr", omega_rad_s=8.0, zeta=0.5),
          _e("sensor_skew", output="p", delay_s=0.05)),
         {("actuator_second_order", "dr"), ("sensor_skew", "p")}, {"wn_act_dr": 8.0, "skew_p": 0.05}),
    Case("cruise 2nd-order 12 rad/s zeta 0.5 da", "cruise", 1101,
         (_e("actuator_second_order", input="da", omega_rad_s=12.0, zeta=0.5),), {("actuator_second_order", "da")},
         {"wn_act_da": 12.0, "zeta_act_da": 0.5}),
    Case("cruise delay 40 ms dr", "cruise", 1102, (_e("time_delay", input="dr", delay_s=0.04),), {("time_delay", "dr")},
         {"tau_r": TAU_R + 0.04}, (("fix", "tau_r", TAU_R),)),
    Case("cruise lag 0.1 s dr", "cruise", 1103, (_e("actuator_lag", input="dr", time_constant_s=0.1),),
         {("actuator_lag", "dr")}, {"w_act_dr": 10.0}),
    Case("cruise notch 8 rad/s depth 0.6 da", "cruise", 1104,
         (_e("notch_filter", input="da", omega_rad_s=8.0, zeta=0.3, depth=0.6),), {("notch_filter", "da")},
         {"w_notch_da": 8.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.6}),
    Case("cruise mode p 7 rad/s zeta 0.05/0.15", "cruise", 1105,
         (_e("structural_mode", output="p", omega_rad_s=7.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 7.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("cruise skew 50 ms r", "cruise", 1106, (_e("sensor_skew", output="r", delay_s=0.05),),
         {("sensor_skew", "r")}, {"skew_r": 0.05}),
    Case("cruise scale 1.2 beta", "cruise", 1107, (_e("scale_factor", output="beta", factor=1.2),),
         {("scale_factor", "beta")}, {"k_beta": 1.2}),
    Case("cruise missing Lv", "cruise", 1108, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -0.008119},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("cruise input skew 50 ms dr", "cruise", 1109, (), {("sensor_skew", "dr")}, {"skew_dr": 0.05},
         (("fix", "tau_r", TAU_R),), log_late=("dr", 0.05)),
    Case("cruise notch da + mode r", "cruise", 1110,
         (_e("notch_filter", input="da", omega_rad_s=5.0, zeta=0.3, depth=0.7),
          _e("structural_mode", output="r", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("notch_filter", "da"), ("structural_mode", "r")}, {"w_notch_da": 5.0, "w_mode_r": 12.0}),
    Case("quad delay 40 ms pitch", "quad", 1101, (_e("time_delay", input="pitch_cmd", delay_s=0.04),),
         {("time_delay", "pitch_cmd")}, {"tau_pitch": TAU_Q + 0.04}),
    Case("quad lag 40 ms pitch", "quad", 1102, (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.04),),
         {("actuator_lag", "pitch_cmd")}, {"w_act_pitch_cmd": 25.0}),
    Case("quad 2nd-order 20 rad/s zeta 0.6 roll", "quad", 1103,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=20.0, zeta=0.6),),
         {("actuator_second_order", "roll_cmd")}, {"wn_act_roll_cmd": 20.0, "zeta_act_roll_cmd": 0.6}),
    Case("quad notch 15 rad/s depth 0.7 roll", "quad", 1104,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=15.0, zeta=0.3, depth=0.7),), {("notch_filter", "roll_cmd")},
         {"w_notch_roll_cmd": 15.0, "zeta_notch_roll_cmd": 0.3, "depth_notch_roll_cmd": 0.7}),
    Case("quad mode q 14 rad/s zeta 0.05/0.15", "quad", 1105,
         (_e("structural_mode", output="q", omega_rad_s=14.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "q")}, {"w_mode_q": 14.0, "zeta_mode_q": 0.05, "zeta_zero_mode_q": 0.15}),
    Case("quad skew 30 ms q", "quad", 1106, (_e("sensor_skew", output="q", delay_s=0.03),),
         {("sensor_skew", "q")}, {"skew_q": 0.03}),
    Case("quad scale 0.8 p", "quad", 1107, (_e("scale_factor", output="p", factor=0.8),),
         {("scale_factor", "p")}, {"k_p": 0.8}),
    Case("quad missing Mu", "quad", 1108, (), {("missing_derivative", "F[q][u]")}, {"F_q_u": 0.65},
         (("drop", "F", "q", "u", "Mu"),)),
    Case("quad delay roll + mode q", "quad", 1109,
         (_e("time_delay", input="roll_cmd", delay_s=0.03),
          _e("structural_mode", output="q", omega_rad_s=16.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("time_delay", "roll_cmd"), ("structural_mode", "q")}, {"tau_roll": TAU_Q + 0.03, "w_mode_q": 16.0}),
    Case("quad skew 20 ms phi", "quad", 1110, (_e("sensor_skew", output="phi", delay_s=0.02),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.02}),
]
HELD_OUT_10_CLEAN = ([Case(f"clean hover seed {s}", "hover", s) for s in range(1120, 1130)]
                     + [Case(f"clean cruise seed {s}", "cruise", s) for s in range(1120, 1128)]
                     + [Case(f"clean quad seed {s}", "quad", s) for s in range(1120, 1128)])

# Written at stop 27 after held-out-10 was run, before the backward step (an effect added earlier
# is re-tested once a later one is in) was written. Run once.
HELD_OUT_11 = [
    Case("hover 2nd-order 6 rad/s zeta 0.6 dr", "hover", 1201,
         (_e("actuator_second_order", input="dr", omega_rad_s=6.0, zeta=0.6),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 6.0, "zeta_act_dr": 0.6}),
    Case("hover delay 80 ms dr", "hover", 1202, (_e("time_delay", input="dr", delay_s=0.08),), {("time_delay", "dr")},
         {"tau_dr": 0.08}),
    Case("hover lag 0.05 s da", "hover", 1203, (_e("actuator_lag", input="da", time_constant_s=0.05),),
         {("actuator_lag", "da")}, {"w_act_da": 20.0}),
    Case("hover notch 2.5 rad/s depth 0.7 dr", "hover", 1204,
         (_e("notch_filter", input="dr", omega_rad_s=2.5, zeta=0.3, depth=0.7),), {("notch_filter", "dr")},
         {"w_notch_dr": 2.5, "zeta_notch_dr": 0.3, "depth_notch_dr": 0.7}),
    Case("hover mode phi 9 rad/s zeta 0.05/0.15", "hover", 1205,
         (_e("structural_mode", output="phi", omega_rad_s=9.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "phi")}, {"w_mode_phi": 9.0, "zeta_mode_phi": 0.05, "zeta_zero_mode_phi": 0.15}),
    Case("hover skew 60 ms r", "hover", 1206, (_e("sensor_skew", output="r", delay_s=0.06),),
         {("sensor_skew", "r")}, {"skew_r": 0.06}),
    Case("hover scale 0.75 phi", "hover", 1207, (_e("scale_factor", output="phi", factor=0.75),),
         {("scale_factor", "phi")}, {"k_phi": 0.75}),
    Case("hover missing Lv", "hover", 1208, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -0.004374},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("hover 2nd-order da + mode r", "hover", 1209,
         (_e("actuator_second_order", input="da", omega_rad_s=9.0, zeta=0.6),
          _e("structural_mode", output="r", omega_rad_s=8.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_second_order", "da"), ("structural_mode", "r")}, {"wn_act_da": 9.0, "w_mode_r": 8.0}),
    Case("hover 2nd-order dr + skew phi", "hover", 1210,
         (_e("actuator_second_order", input="dr", omega_rad_s=7.0, zeta=0.5),
          _e("sensor_skew", output="phi", delay_s=0.05)),
         {("actuator_second_order", "dr"), ("sensor_skew", "phi")}, {"wn_act_dr": 7.0, "skew_phi": 0.05}),
    Case("cruise 2nd-order 9 rad/s zeta 0.5 dr", "cruise", 1201,
         (_e("actuator_second_order", input="dr", omega_rad_s=9.0, zeta=0.5),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 9.0, "zeta_act_dr": 0.5}),
    Case("cruise delay 60 ms da", "cruise", 1202, (_e("time_delay", input="da", delay_s=0.06),),
         {("time_delay", "da")}, {"tau_a": TAU_A + 0.06}, (("fix", "tau_a", TAU_A),)),
    Case("cruise lag 0.06 s dr", "cruise", 1203, (_e("actuator_lag", input="dr", time_constant_s=0.06),),
         {("actuator_lag", "dr")}, {"w_act_dr": 1 / 0.06}),
    Case("cruise notch 10 rad/s depth 0.7 dr", "cruise", 1204,
         (_e("notch_filter", input="dr", omega_rad_s=10.0, zeta=0.3, depth=0.7),), {("notch_filter", "dr")},
         {"w_notch_dr": 10.0, "zeta_notch_dr": 0.3, "depth_notch_dr": 0.7}),
    Case("cruise mode r 8 rad/s zeta 0.05/0.15", "cruise", 1205,
         (_e("structural_mode", output="r", omega_rad_s=8.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "r")}, {"w_mode_r": 8.0, "zeta_mode_r": 0.05, "zeta_zero_mode_r": 0.15}),
    Case("cruise skew 40 ms p", "cruise", 1206, (_e("sensor_skew", output="p", delay_s=0.04),),
         {("sensor_skew", "p")}, {"skew_p": 0.04}),
    Case("cruise scale 1.25 p", "cruise", 1207, (_e("scale_factor", output="p", factor=1.25),),
         {("scale_factor", "p")}, {"k_p": 1.25}),
    Case("cruise missing Np", "cruise", 1208, (), {("missing_derivative", "F[r][p]")}, {"F_r_p": -0.2308},
         (("drop", "F", "r", "p", "Np"),)),
    Case("cruise 2nd-order da + skew r", "cruise", 1209,
         (_e("actuator_second_order", input="da", omega_rad_s=10.0, zeta=0.5),
          _e("sensor_skew", output="r", delay_s=0.04)),
         {("actuator_second_order", "da"), ("sensor_skew", "r")}, {"wn_act_da": 10.0, "skew_r": 0.04}),
    Case("cruise lag da + mode p", "cruise", 1210,
         (_e("actuator_lag", input="da", time_constant_s=0.08),
          _e("structural_mode", output="p", omega_rad_s=13.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_lag", "da"), ("structural_mode", "p")}, {"w_act_da": 12.5, "w_mode_p": 13.0}),
    Case("quad delay 15 ms roll", "quad", 1201, (_e("time_delay", input="roll_cmd", delay_s=0.015),),
         {("time_delay", "roll_cmd")}, {"tau_roll": TAU_Q + 0.015}),
    Case("quad lag 50 ms roll", "quad", 1202, (_e("actuator_lag", input="roll_cmd", time_constant_s=0.05),),
         {("actuator_lag", "roll_cmd")}, {"w_act_roll_cmd": 20.0}),
    Case("quad 2nd-order 30 rad/s zeta 0.5 pitch", "quad", 1203,
         (_e("actuator_second_order", input="pitch_cmd", omega_rad_s=30.0, zeta=0.5),),
         {("actuator_second_order", "pitch_cmd")}, {"wn_act_pitch_cmd": 30.0, "zeta_act_pitch_cmd": 0.5}),
    Case("quad notch 10 rad/s depth 0.6 roll", "quad", 1204,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=10.0, zeta=0.3, depth=0.6),), {("notch_filter", "roll_cmd")},
         {"w_notch_roll_cmd": 10.0, "zeta_notch_roll_cmd": 0.3, "depth_notch_roll_cmd": 0.6}),
    Case("quad mode p 20 rad/s zeta 0.05/0.15", "quad", 1205,
         (_e("structural_mode", output="p", omega_rad_s=20.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 20.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("quad skew 40 ms theta", "quad", 1206, (_e("sensor_skew", output="theta", delay_s=0.04),),
         {("sensor_skew", "theta")}, {"skew_theta": 0.04}),
    Case("quad scale 1.2 q", "quad", 1207, (_e("scale_factor", output="q", factor=1.2),),
         {("scale_factor", "q")}, {"k_q": 1.2}),
    Case("quad missing Lv", "quad", 1208, (), {("missing_derivative", "F[p][v]")}, {"F_p_v": -0.80},
         (("drop", "F", "p", "v", "Lv"),)),
    Case("quad 2nd-order pitch + skew p", "quad", 1209,
         (_e("actuator_second_order", input="pitch_cmd", omega_rad_s=20.0, zeta=0.5),
          _e("sensor_skew", output="p", delay_s=0.03)),
         {("actuator_second_order", "pitch_cmd"), ("sensor_skew", "p")}, {"wn_act_pitch_cmd": 20.0, "skew_p": 0.03}),
    Case("quad notch roll + mode q", "quad", 1210,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=8.0, zeta=0.3, depth=0.7),
          _e("structural_mode", output="q", omega_rad_s=15.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("notch_filter", "roll_cmd"), ("structural_mode", "q")}, {"w_notch_roll_cmd": 8.0, "w_mode_q": 15.0}),
]
HELD_OUT_11_CLEAN = ([Case(f"clean hover seed {s}", "hover", s) for s in range(1220, 1230)]
                     + [Case(f"clean cruise seed {s}", "cruise", s) for s in range(1220, 1228)]
                     + [Case(f"clean quad seed {s}", "quad", s) for s in range(1220, 1228)])

# Held-out-12 (written and committed before any of it was run; run once): every case flown
# unlike all the sets above (the conditions of CONDITIONS: sensor noise x2-x3, gusts with a
# 0.7 s or 5 s correlation time instead of 2 s, stronger turbulence, smaller or shorter sweeps,
# one sweep per axis, a tighter or looser pilot, the quadrotor logged at 100 Hz), so that what the
# loop's criterion assumes about noise and turbulence is tested off the simulator settings it was
# developed on. Effect parameters differ from every earlier set.
_NOISY, _NOISY2 = (("noise", 3.0),), (("noise", 2.0),)
_FAST_GUSTS, _SLOW_GUSTS = (("gust_time_s", 0.7),), (("gust_time_s", 5.0),)
_SMALL, _SHORT = (("amplitude", 0.6),), (("duration_s", 70.0), ("repeats", 1))
_TIGHT, _LOOSE = (("pilot_gain", 1.4),), (("pilot_gain", 0.7),)
_LOG100 = (("rate_hz", 100.0),)

HELD_OUT_12 = [
    Case("hover 2nd-order 7 rad/s zeta 0.7 da, noise x3", "hover", 1301,
         (_e("actuator_second_order", input="da", omega_rad_s=7.0, zeta=0.7),), {("actuator_second_order", "da")},
         {"wn_act_da": 7.0, "zeta_act_da": 0.7}, conditions=_NOISY),
    Case("hover delay 50 ms da, fast gusts", "hover", 1302, (_e("time_delay", input="da", delay_s=0.05),),
         {("time_delay", "da")}, {"tau_da": 0.05}, conditions=_FAST_GUSTS),
    Case("hover lag 0.08 s dr, small sweeps", "hover", 1303, (_e("actuator_lag", input="dr", time_constant_s=0.08),),
         {("actuator_lag", "dr")}, {"w_act_dr": 12.5}, conditions=_SMALL),
    Case("hover notch 3 rad/s depth 0.6 da, tight pilot", "hover", 1304,
         (_e("notch_filter", input="da", omega_rad_s=3.0, zeta=0.25, depth=0.6),), {("notch_filter", "da")},
         {"w_notch_da": 3.0, "zeta_notch_da": 0.25, "depth_notch_da": 0.6}, conditions=_TIGHT),
    Case("hover mode p 8 rad/s zeta 0.05/0.2, turbulence 0.8", "hover", 1305,
         (_e("structural_mode", output="p", omega_rad_s=8.0, zeta_pole=0.05, zeta_zero=0.2),),
         {("structural_mode", "p")}, {"w_mode_p": 8.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.2}, turbulence=0.8),
    Case("hover skew 40 ms phi, noise x3", "hover", 1306, (_e("sensor_skew", output="phi", delay_s=0.04),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.04}, conditions=_NOISY),
    Case("hover scale 1.3 p, slow gusts", "hover", 1307, (_e("scale_factor", output="p", factor=1.3),),
         {("scale_factor", "p")}, {"k_p": 1.3}, conditions=_SLOW_GUSTS),
    Case("hover missing Nda, loose pilot", "hover", 1308, (), {("missing_derivative", "G[r][da]")}, {"G_r_da": 0.00591},
         (("drop", "G", "r", "da", "Nda"),), conditions=_LOOSE),
    Case("hover lag da + skew r, noise x2", "hover", 1309,
         (_e("actuator_lag", input="da", time_constant_s=0.1), _e("sensor_skew", output="r", delay_s=0.05)),
         {("actuator_lag", "da"), ("sensor_skew", "r")}, {"w_act_da": 10.0, "skew_r": 0.05}, conditions=_NOISY2),
    Case("hover delay dr + mode phi, one short sweep", "hover", 1310,
         (_e("time_delay", input="dr", delay_s=0.08),
          _e("structural_mode", output="phi", omega_rad_s=7.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("time_delay", "dr"), ("structural_mode", "phi")}, {"tau_dr": 0.08, "w_mode_phi": 7.0}, conditions=_SHORT),
    Case("cruise 2nd-order 11 rad/s zeta 0.4 da, noise x3", "cruise", 1301,
         (_e("actuator_second_order", input="da", omega_rad_s=11.0, zeta=0.4),), {("actuator_second_order", "da")},
         {"wn_act_da": 11.0, "zeta_act_da": 0.4}, conditions=_NOISY),
    Case("cruise delay 40 ms dr, turbulence 1.0", "cruise", 1302, (_e("time_delay", input="dr", delay_s=0.04),),
         {("time_delay", "dr")}, {"tau_r": TAU_R + 0.04}, (("fix", "tau_r", TAU_R),), turbulence=1.0),
    Case("cruise lag 0.1 s da, fast gusts", "cruise", 1303, (_e("actuator_lag", input="da", time_constant_s=0.1),),
         {("actuator_lag", "da")}, {"w_act_da": 10.0}, conditions=_FAST_GUSTS),
    Case("cruise notch 7 rad/s depth 0.6 da, small sweeps", "cruise", 1304,
         (_e("notch_filter", input="da", omega_rad_s=7.0, zeta=0.3, depth=0.6),), {("notch_filter", "da")},
         {"w_notch_da": 7.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.6}, conditions=_SMALL),
    Case("cruise mode p 13 rad/s zeta 0.05/0.15, noise x2", "cruise", 1305,
         (_e("structural_mode", output="p", omega_rad_s=13.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 13.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15},
         conditions=_NOISY2),
    Case("cruise skew 50 ms r, slow gusts", "cruise", 1306, (_e("sensor_skew", output="r", delay_s=0.05),),
         {("sensor_skew", "r")}, {"skew_r": 0.05}, conditions=_SLOW_GUSTS),
    Case("cruise scale 0.8 r, turbulence 1.0", "cruise", 1307, (_e("scale_factor", output="r", factor=0.8),),
         {("scale_factor", "r")}, {"k_r": 0.8}, turbulence=1.0),
    Case("cruise missing Nv, noise x2", "cruise", 1308, (), {("missing_derivative", "F[r][v]")}, {"F_r_v": 7.240e-3},
         (("drop", "F", "r", "v", "Nv"),), conditions=_NOISY2),
    Case("cruise lag dr + mode p, noise x2", "cruise", 1309,
         (_e("actuator_lag", input="dr", time_constant_s=0.1),
          _e("structural_mode", output="p", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_lag", "dr"), ("structural_mode", "p")}, {"w_act_dr": 10.0, "w_mode_p": 12.0}, conditions=_NOISY2),
    Case("cruise 2nd-order da + skew r, fast gusts", "cruise", 1310,
         (_e("actuator_second_order", input="da", omega_rad_s=10.0, zeta=0.6),
          _e("sensor_skew", output="r", delay_s=0.06)),
         {("actuator_second_order", "da"), ("sensor_skew", "r")}, {"wn_act_da": 10.0, "skew_r": 0.06},
         conditions=_FAST_GUSTS),
    Case("quad lag 30 ms pitch, noise x3", "quad", 1301, (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.03),),
         {("actuator_lag", "pitch_cmd")}, {"w_act_pitch_cmd": 1 / 0.03}, conditions=_NOISY),
    Case("quad delay 15 ms roll, logged at 100 Hz", "quad", 1302, (_e("time_delay", input="roll_cmd", delay_s=0.015),),
         {("time_delay", "roll_cmd")}, {"tau_roll": TAU_Q + 0.015}, conditions=_LOG100),
    Case("quad 2nd-order 35 rad/s zeta 0.6 roll, tight pilot", "quad", 1303,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=35.0, zeta=0.6),),
         {("actuator_second_order", "roll_cmd")}, {"wn_act_roll_cmd": 35.0, "zeta_act_roll_cmd": 0.6},
         conditions=_TIGHT),
    Case("quad notch 20 rad/s depth 0.6 pitch, small sweeps", "quad", 1304,
         (_e("notch_filter", input="pitch_cmd", omega_rad_s=20.0, zeta=0.3, depth=0.6),), {("notch_filter", "pitch_cmd")},
         {"w_notch_pitch_cmd": 20.0, "zeta_notch_pitch_cmd": 0.3, "depth_notch_pitch_cmd": 0.6}, conditions=_SMALL),
    Case("quad mode p 30 rad/s zeta 0.05/0.15, fast gusts", "quad", 1305,
         (_e("structural_mode", output="p", omega_rad_s=30.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 30.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15},
         conditions=_FAST_GUSTS),
    Case("quad skew 15 ms q, noise x2", "quad", 1306, (_e("sensor_skew", output="q", delay_s=0.015),),
         {("sensor_skew", "q")}, {"skew_q": 0.015}, conditions=_NOISY2),
    Case("quad scale 1.25 p, logged at 100 Hz", "quad", 1307, (_e("scale_factor", output="p", factor=1.25),),
         {("scale_factor", "p")}, {"k_p": 1.25}, conditions=_LOG100),
    Case("quad missing Mu, slow gusts", "quad", 1308, (), {("missing_derivative", "F[q][u]")}, {"F_q_u": 0.65},
         (("drop", "F", "q", "u", "Mu"),), conditions=_SLOW_GUSTS),
    Case("quad lag roll + skew theta, turbulence 1.0", "quad", 1309,
         (_e("actuator_lag", input="roll_cmd", time_constant_s=0.04), _e("sensor_skew", output="theta", delay_s=0.03)),
         {("actuator_lag", "roll_cmd"), ("sensor_skew", "theta")}, {"w_act_roll_cmd": 25.0, "skew_theta": 0.03},
         turbulence=1.0),
    Case("quad notch pitch + mode p, noise x2", "quad", 1310,
         (_e("notch_filter", input="pitch_cmd", omega_rad_s=12.0, zeta=0.3, depth=0.7),
          _e("structural_mode", output="p", omega_rad_s=25.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("notch_filter", "pitch_cmd"), ("structural_mode", "p")}, {"w_notch_pitch_cmd": 12.0, "w_mode_p": 25.0},
         conditions=_NOISY2),
]
_SHIFTS = (_NOISY, _FAST_GUSTS, _SLOW_GUSTS, _SMALL, _SHORT, _TIGHT, _LOOSE, _NOISY2)
HELD_OUT_12_CLEAN = ([Case(f"clean hover seed {s} {dict(c)}", "hover", s, conditions=c)
                      for s, c in zip(range(1320, 1328), _SHIFTS)]
                     + [Case(f"clean cruise seed {s} {dict(c)}", "cruise", s, conditions=c)
                        for s, c in zip(range(1320, 1328), (*_SHIFTS[:5], _NOISY2, _NOISY, _FAST_GUSTS))]
                     + [Case(f"clean quad seed {s} {dict(c)}", "quad", s, conditions=c)
                        for s, c in zip(range(1320, 1328), (*_SHIFTS, _LOG100)[1:])])

# Held-out-13 (written and committed before any of it was run; run once): the code after
# held-out-12's three changes (a refit stopped by its budget continued, each leading place's best
# refitted, a richer rival named by the test that chose the simpler) and the referenced-response
# fix. Seeds 1401-1427, magnitudes and places unlike the earlier sets where the catalogue allows,
# 7 pairs, a third of the cases flown under held-out-12's shifted conditions.
HELD_OUT_13 = [
    Case("hover 2nd-order 10 rad/s zeta 0.45 dr", "hover", 1401,
         (_e("actuator_second_order", input="dr", omega_rad_s=10.0, zeta=0.45),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 10.0, "zeta_act_dr": 0.45}),
    Case("hover delay 30 ms da", "hover", 1402, (_e("time_delay", input="da", delay_s=0.03),), {("time_delay", "da")},
         {"tau_da": 0.03}),
    Case("hover lag 0.12 s dr, noise x2", "hover", 1403, (_e("actuator_lag", input="dr", time_constant_s=0.12),),
         {("actuator_lag", "dr")}, {"w_act_dr": 1 / 0.12}, conditions=_NOISY2),
    Case("hover notch 4 rad/s depth 0.65 dr, tight pilot", "hover", 1404,
         (_e("notch_filter", input="dr", omega_rad_s=4.0, zeta=0.2, depth=0.65),), {("notch_filter", "dr")},
         {"w_notch_dr": 4.0, "zeta_notch_dr": 0.2, "depth_notch_dr": 0.65}, conditions=_TIGHT),
    Case("hover mode r 6 rad/s zeta 0.05/0.18", "hover", 1405,
         (_e("structural_mode", output="r", omega_rad_s=6.0, zeta_pole=0.05, zeta_zero=0.18),),
         {("structural_mode", "r")}, {"w_mode_r": 6.0, "zeta_mode_r": 0.05, "zeta_zero_mode_r": 0.18}),
    Case("hover skew 70 ms p", "hover", 1406, (_e("sensor_skew", output="p", delay_s=0.07),),
         {("sensor_skew", "p")}, {"skew_p": 0.07}),
    Case("hover scale 1.3 phi, slow gusts", "hover", 1407, (_e("scale_factor", output="phi", factor=1.3),),
         {("scale_factor", "phi")}, {"k_phi": 1.3}, conditions=_SLOW_GUSTS),
    Case("hover missing Yp", "hover", 1408, (), {("missing_derivative", "F[v][p]")}, {"F_v_p": -1.489},
         (("drop", "F", "v", "p", "Yp"),)),
    Case("hover delay da + mode p", "hover", 1409,
         (_e("time_delay", input="da", delay_s=0.06),
          _e("structural_mode", output="p", omega_rad_s=10.0, zeta_pole=0.06, zeta_zero=0.2)),
         {("time_delay", "da"), ("structural_mode", "p")}, {"tau_da": 0.06, "w_mode_p": 10.0}),
    Case("hover notch da + skew r, fast gusts", "hover", 1410,
         (_e("notch_filter", input="da", omega_rad_s=5.0, zeta=0.3, depth=0.7),
          _e("sensor_skew", output="r", delay_s=0.04)),
         {("notch_filter", "da"), ("sensor_skew", "r")}, {"w_notch_da": 5.0, "skew_r": 0.04}, conditions=_FAST_GUSTS),
    Case("cruise 2nd-order 14 rad/s zeta 0.55 dr", "cruise", 1401,
         (_e("actuator_second_order", input="dr", omega_rad_s=14.0, zeta=0.55),), {("actuator_second_order", "dr")},
         {"wn_act_dr": 14.0, "zeta_act_dr": 0.55}),
    Case("cruise delay 20 ms dr", "cruise", 1402, (_e("time_delay", input="dr", delay_s=0.02),),
         {("time_delay", "dr")}, {"tau_r": TAU_R + 0.02}, (("fix", "tau_r", TAU_R),)),
    Case("cruise lag 0.07 s da, small sweeps", "cruise", 1403, (_e("actuator_lag", input="da", time_constant_s=0.07),),
         {("actuator_lag", "da")}, {"w_act_da": 1 / 0.07}, conditions=_SMALL),
    Case("cruise notch 5 rad/s depth 0.75 da", "cruise", 1404,
         (_e("notch_filter", input="da", omega_rad_s=5.0, zeta=0.3, depth=0.75),), {("notch_filter", "da")},
         {"w_notch_da": 5.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.75}),
    Case("cruise mode beta 11 rad/s zeta 0.05/0.15", "cruise", 1405,
         (_e("structural_mode", output="beta", omega_rad_s=11.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "beta")}, {"w_mode_beta": 11.0, "zeta_mode_beta": 0.05, "zeta_zero_mode_beta": 0.15}),
    Case("cruise skew 45 ms beta, noise x2", "cruise", 1406, (_e("sensor_skew", output="beta", delay_s=0.045),),
         {("sensor_skew", "beta")}, {"skew_beta": 0.045}, conditions=_NOISY2),
    Case("cruise scale 1.15 r", "cruise", 1407, (_e("scale_factor", output="r", factor=1.15),),
         {("scale_factor", "r")}, {"k_r": 1.15}),
    Case("cruise missing Nr", "cruise", 1408, (), {("missing_derivative", "F[r][r]")}, {"F_r_r": -0.9759},
         (("drop", "F", "r", "r", "Nr"),)),
    Case("cruise 2nd-order dr + mode p", "cruise", 1409,
         (_e("actuator_second_order", input="dr", omega_rad_s=8.0, zeta=0.7),
          _e("structural_mode", output="p", omega_rad_s=15.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_second_order", "dr"), ("structural_mode", "p")}, {"wn_act_dr": 8.0, "w_mode_p": 15.0}),
    Case("cruise delay da + skew p", "cruise", 1410,
         (_e("time_delay", input="da", delay_s=0.04), _e("sensor_skew", output="p", delay_s=0.03)),
         {("time_delay", "da"), ("sensor_skew", "p")}, {"tau_a": TAU_A + 0.04, "skew_p": 0.03},
         (("fix", "tau_a", TAU_A),)),
    Case("quad 2nd-order 25 rad/s zeta 0.7 roll", "quad", 1401,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=25.0, zeta=0.7),),
         {("actuator_second_order", "roll_cmd")}, {"wn_act_roll_cmd": 25.0, "zeta_act_roll_cmd": 0.7}),
    Case("quad delay 25 ms pitch, logged at 100 Hz", "quad", 1402,
         (_e("time_delay", input="pitch_cmd", delay_s=0.025),), {("time_delay", "pitch_cmd")},
         {"tau_pitch": TAU_Q + 0.025}, conditions=_LOG100),
    Case("quad lag 20 ms roll", "quad", 1403, (_e("actuator_lag", input="roll_cmd", time_constant_s=0.02),),
         {("actuator_lag", "roll_cmd")}, {"w_act_roll_cmd": 50.0}),
    Case("quad notch 15 rad/s depth 0.7 roll", "quad", 1404,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=15.0, zeta=0.25, depth=0.7),), {("notch_filter", "roll_cmd")},
         {"w_notch_roll_cmd": 15.0, "zeta_notch_roll_cmd": 0.25, "depth_notch_roll_cmd": 0.7}),
    Case("quad mode q 35 rad/s zeta 0.05/0.15", "quad", 1405,
         (_e("structural_mode", output="q", omega_rad_s=35.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "q")}, {"w_mode_q": 35.0, "zeta_mode_q": 0.05, "zeta_zero_mode_q": 0.15}),
    Case("quad skew 25 ms phi, noise x3", "quad", 1406, (_e("sensor_skew", output="phi", delay_s=0.025),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.025}, conditions=_NOISY),
    Case("quad scale 0.85 theta", "quad", 1407, (_e("scale_factor", output="theta", factor=0.85),),
         {("scale_factor", "theta")}, {"k_theta": 0.85}),
    Case("quad missing Mroll", "quad", 1408, (), {("missing_derivative", "G[q][roll_cmd]")}, {"G_q_roll_cmd": -3.3},
         (("drop", "G", "q", "roll_cmd", "Mroll"),)),
    Case("quad lag pitch + mode p", "quad", 1409,
         (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.04),
          _e("structural_mode", output="p", omega_rad_s=18.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_lag", "pitch_cmd"), ("structural_mode", "p")}, {"w_act_pitch_cmd": 25.0, "w_mode_p": 18.0}),
    Case("quad 2nd-order roll + skew q, slow gusts", "quad", 1410,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=30.0, zeta=0.6),
          _e("sensor_skew", output="q", delay_s=0.02)),
         {("actuator_second_order", "roll_cmd"), ("sensor_skew", "q")}, {"wn_act_roll_cmd": 30.0, "skew_q": 0.02},
         conditions=_SLOW_GUSTS),
]
HELD_OUT_13_CLEAN = ([Case(f"clean hover seed {s}", "hover", s) for s in range(1420, 1424)]
                     + [Case(f"clean hover seed {s} {dict(c)}", "hover", s, conditions=c)
                        for s, c in zip(range(1424, 1428), (_NOISY2, _LOOSE, _FAST_GUSTS, _SHORT))]
                     + [Case(f"clean cruise seed {s}", "cruise", s) for s in range(1420, 1424)]
                     + [Case(f"clean cruise seed {s} {dict(c)}", "cruise", s, conditions=c)
                        for s, c in zip(range(1424, 1428), (_SMALL, _SLOW_GUSTS, _NOISY, _SHORT))]
                     + [Case(f"clean quad seed {s}", "quad", s) for s in range(1420, 1424)]
                     + [Case(f"clean quad seed {s} {dict(c)}", "quad", s, conditions=c)
                        for s, c in zip(range(1424, 1428), (_LOG100, _TIGHT, _NOISY2, _FAST_GUSTS))])


# Held-out-14 (written and committed before any of it was run; run once): the code after
# held-out-13's change (an earlier effect replaced by its simpler rival once a later one is in).
# Seeds 1501-1527, 6 pairs, magnitudes unlike held-out-13's, some cases under shifted conditions.
HELD_OUT_14 = [
    Case("hover 2nd-order 8.5 rad/s zeta 0.55 da", "hover", 1501,
         (_e("actuator_second_order", input="da", omega_rad_s=8.5, zeta=0.55),), {("actuator_second_order", "da")},
         {"wn_act_da": 8.5, "zeta_act_da": 0.55}),
    Case("hover delay 45 ms dr", "hover", 1502, (_e("time_delay", input="dr", delay_s=0.045),), {("time_delay", "dr")},
         {"tau_dr": 0.045}),
    Case("hover lag 0.07 s da, loose pilot", "hover", 1503, (_e("actuator_lag", input="da", time_constant_s=0.07),),
         {("actuator_lag", "da")}, {"w_act_da": 1 / 0.07}, conditions=_LOOSE),
    Case("hover notch 6 rad/s depth 0.75 da", "hover", 1504,
         (_e("notch_filter", input="da", omega_rad_s=6.0, zeta=0.25, depth=0.75),), {("notch_filter", "da")},
         {"w_notch_da": 6.0, "zeta_notch_da": 0.25, "depth_notch_da": 0.75}),
    Case("hover mode p 11 rad/s zeta 0.05/0.15", "hover", 1505,
         (_e("structural_mode", output="p", omega_rad_s=11.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 11.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("hover skew 45 ms r, slow gusts", "hover", 1506, (_e("sensor_skew", output="r", delay_s=0.045),),
         {("sensor_skew", "r")}, {"skew_r": 0.045}, conditions=_SLOW_GUSTS),
    Case("hover scale 0.8 p", "hover", 1507, (_e("scale_factor", output="p", factor=0.8),),
         {("scale_factor", "p")}, {"k_p": 0.8}),
    Case("hover missing Lp", "hover", 1508, (), {("missing_derivative", "F[p][p]")}, {"F_p_p": -0.2365},
         (("drop", "F", "p", "p", "Lp"),)),
    Case("hover lag dr + mode phi", "hover", 1509,
         (_e("actuator_lag", input="dr", time_constant_s=0.1),
          _e("structural_mode", output="phi", omega_rad_s=8.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_lag", "dr"), ("structural_mode", "phi")}, {"w_act_dr": 10.0, "w_mode_phi": 8.0}),
    Case("hover 2nd-order da + skew p, noise x2", "hover", 1510,
         (_e("actuator_second_order", input="da", omega_rad_s=9.0, zeta=0.6),
          _e("sensor_skew", output="p", delay_s=0.04)),
         {("actuator_second_order", "da"), ("sensor_skew", "p")}, {"wn_act_da": 9.0, "skew_p": 0.04},
         conditions=_NOISY2),
    Case("cruise 2nd-order 12 rad/s zeta 0.6 da", "cruise", 1501,
         (_e("actuator_second_order", input="da", omega_rad_s=12.0, zeta=0.6),), {("actuator_second_order", "da")},
         {"wn_act_da": 12.0, "zeta_act_da": 0.6}),
    Case("cruise delay 50 ms da, noise x2", "cruise", 1502, (_e("time_delay", input="da", delay_s=0.05),),
         {("time_delay", "da")}, {"tau_a": TAU_A + 0.05}, (("fix", "tau_a", TAU_A),), conditions=_NOISY2),
    Case("cruise lag 0.09 s dr", "cruise", 1503, (_e("actuator_lag", input="dr", time_constant_s=0.09),),
         {("actuator_lag", "dr")}, {"w_act_dr": 1 / 0.09}),
    Case("cruise notch 8 rad/s depth 0.7 dr", "cruise", 1504,
         (_e("notch_filter", input="dr", omega_rad_s=8.0, zeta=0.3, depth=0.7),), {("notch_filter", "dr")},
         {"w_notch_dr": 8.0, "zeta_notch_dr": 0.3, "depth_notch_dr": 0.7}),
    Case("cruise mode r 10 rad/s zeta 0.05/0.15, turbulence 1.0", "cruise", 1505,
         (_e("structural_mode", output="r", omega_rad_s=10.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "r")}, {"w_mode_r": 10.0, "zeta_mode_r": 0.05, "zeta_zero_mode_r": 0.15}, turbulence=1.0),
    Case("cruise skew 35 ms p", "cruise", 1506, (_e("sensor_skew", output="p", delay_s=0.035),),
         {("sensor_skew", "p")}, {"skew_p": 0.035}),
    Case("cruise scale 0.85 p", "cruise", 1507, (_e("scale_factor", output="p", factor=0.85),),
         {("scale_factor", "p")}, {"k_p": 0.85}),
    Case("cruise missing Lp", "cruise", 1508, (), {("missing_derivative", "F[p][p]")}, {"F_p_p": -0.678},
         (("drop", "F", "p", "p", "Lp"),)),
    Case("cruise notch da + mode r", "cruise", 1509,
         (_e("notch_filter", input="da", omega_rad_s=6.0, zeta=0.3, depth=0.7),
          _e("structural_mode", output="r", omega_rad_s=12.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("notch_filter", "da"), ("structural_mode", "r")}, {"w_notch_da": 6.0, "w_mode_r": 12.0}),
    Case("cruise lag da + skew r, fast gusts", "cruise", 1510,
         (_e("actuator_lag", input="da", time_constant_s=0.08), _e("sensor_skew", output="r", delay_s=0.05)),
         {("actuator_lag", "da"), ("sensor_skew", "r")}, {"w_act_da": 12.5, "skew_r": 0.05}, conditions=_FAST_GUSTS),
    Case("quad 2nd-order 20 rad/s zeta 0.5 roll", "quad", 1501,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=20.0, zeta=0.5),),
         {("actuator_second_order", "roll_cmd")}, {"wn_act_roll_cmd": 20.0, "zeta_act_roll_cmd": 0.5}),
    Case("quad delay 20 ms roll", "quad", 1502, (_e("time_delay", input="roll_cmd", delay_s=0.02),),
         {("time_delay", "roll_cmd")}, {"tau_roll": TAU_Q + 0.02}),
    Case("quad lag 25 ms pitch, small sweeps", "quad", 1503,
         (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.025),), {("actuator_lag", "pitch_cmd")},
         {"w_act_pitch_cmd": 40.0}, conditions=_SMALL),
    Case("quad notch 25 rad/s depth 0.6 roll", "quad", 1504,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=25.0, zeta=0.3, depth=0.6),), {("notch_filter", "roll_cmd")},
         {"w_notch_roll_cmd": 25.0, "zeta_notch_roll_cmd": 0.3, "depth_notch_roll_cmd": 0.6}),
    Case("quad mode p 22 rad/s zeta 0.05/0.15", "quad", 1505,
         (_e("structural_mode", output="p", omega_rad_s=22.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 22.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("quad skew 20 ms theta, logged at 100 Hz", "quad", 1506, (_e("sensor_skew", output="theta", delay_s=0.02),),
         {("sensor_skew", "theta")}, {"skew_theta": 0.02}, conditions=_LOG100),
    Case("quad scale 1.2 phi", "quad", 1507, (_e("scale_factor", output="phi", factor=1.2),),
         {("scale_factor", "phi")}, {"k_phi": 1.2}),
    Case("quad missing Mq", "quad", 1508, (), {("missing_derivative", "F[q][q]")}, {"F_q_q": -3.4},
         (("drop", "F", "q", "q", "Mq"),)),
    Case("quad delay pitch + mode q", "quad", 1509,
         (_e("time_delay", input="pitch_cmd", delay_s=0.02),
          _e("structural_mode", output="q", omega_rad_s=28.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("time_delay", "pitch_cmd"), ("structural_mode", "q")}, {"tau_pitch": TAU_Q + 0.02, "w_mode_q": 28.0}),
    Case("quad notch roll + skew p, noise x2", "quad", 1510,
         (_e("notch_filter", input="roll_cmd", omega_rad_s=12.0, zeta=0.3, depth=0.7),
          _e("sensor_skew", output="p", delay_s=0.015)),
         {("notch_filter", "roll_cmd"), ("sensor_skew", "p")}, {"w_notch_roll_cmd": 12.0, "skew_p": 0.015},
         conditions=_NOISY2),
]
HELD_OUT_14_CLEAN = ([Case(f"clean hover seed {s}", "hover", s) for s in range(1520, 1524)]
                     + [Case(f"clean hover seed {s} {dict(c)}", "hover", s, conditions=c)
                        for s, c in zip(range(1524, 1528), (_NOISY, _TIGHT, _SLOW_GUSTS, _SMALL))]
                     + [Case(f"clean cruise seed {s}", "cruise", s) for s in range(1520, 1524)]
                     + [Case(f"clean cruise seed {s} {dict(c)}", "cruise", s, conditions=c)
                        for s, c in zip(range(1524, 1528), (_NOISY2, _FAST_GUSTS, _SHORT, _SMALL))]
                     + [Case(f"clean quad seed {s}", "quad", s) for s in range(1520, 1524)]
                     + [Case(f"clean quad seed {s} {dict(c)}", "quad", s, conditions=c)
                        for s, c in zip(range(1524, 1528), (_NOISY, _LOOSE, _SHORT, _LOG100))])


# Held-out-15 (written and committed before any of it was run; run once): the code after the
# replacement step was widened (the simpler kinds at an accepted effect's place refitted whatever
# their screen said, and any of them a replacement candidate). Seeds 1601-1627, 6 pairs.
HELD_OUT_15 = [
    Case("hover 2nd-order 6.5 rad/s zeta 0.65 da", "hover", 1601,
         (_e("actuator_second_order", input="da", omega_rad_s=6.5, zeta=0.65),), {("actuator_second_order", "da")},
         {"wn_act_da": 6.5, "zeta_act_da": 0.65}),
    Case("hover delay 70 ms dr", "hover", 1602, (_e("time_delay", input="dr", delay_s=0.07),), {("time_delay", "dr")},
         {"tau_dr": 0.07}),
    Case("hover lag 0.09 s da", "hover", 1603, (_e("actuator_lag", input="da", time_constant_s=0.09),),
         {("actuator_lag", "da")}, {"w_act_da": 1 / 0.09}),
    Case("hover notch 3.5 rad/s depth 0.6 dr, tight pilot", "hover", 1604,
         (_e("notch_filter", input="dr", omega_rad_s=3.5, zeta=0.3, depth=0.6),), {("notch_filter", "dr")},
         {"w_notch_dr": 3.5, "zeta_notch_dr": 0.3, "depth_notch_dr": 0.6}, conditions=_TIGHT),
    Case("hover mode phi 10 rad/s zeta 0.05/0.2, noise x2", "hover", 1605,
         (_e("structural_mode", output="phi", omega_rad_s=10.0, zeta_pole=0.05, zeta_zero=0.2),),
         {("structural_mode", "phi")}, {"w_mode_phi": 10.0, "zeta_mode_phi": 0.05, "zeta_zero_mode_phi": 0.2},
         conditions=_NOISY2),
    Case("hover skew 55 ms phi", "hover", 1606, (_e("sensor_skew", output="phi", delay_s=0.055),),
         {("sensor_skew", "phi")}, {"skew_phi": 0.055}),
    Case("hover scale 1.35 v", "hover", 1607, (_e("scale_factor", output="v", factor=1.35),),
         {("scale_factor", "v")}, {"k_v": 1.35}),
    Case("hover missing Ndr", "hover", 1608, (), {("missing_derivative", "G[r][dr]")}, {"G_r_dr": 0.01187},
         (("drop", "G", "r", "dr", "Ndr"),)),
    Case("hover 2nd-order dr + mode p", "hover", 1609,
         (_e("actuator_second_order", input="dr", omega_rad_s=7.0, zeta=0.5),
          _e("structural_mode", output="p", omega_rad_s=9.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_second_order", "dr"), ("structural_mode", "p")}, {"wn_act_dr": 7.0, "w_mode_p": 9.0}),
    Case("hover delay da + skew r, slow gusts", "hover", 1610,
         (_e("time_delay", input="da", delay_s=0.04), _e("sensor_skew", output="r", delay_s=0.06)),
         {("time_delay", "da"), ("sensor_skew", "r")}, {"tau_da": 0.04, "skew_r": 0.06}, conditions=_SLOW_GUSTS),
    Case("cruise 2nd-order 9 rad/s zeta 0.45 da", "cruise", 1601,
         (_e("actuator_second_order", input="da", omega_rad_s=9.0, zeta=0.45),), {("actuator_second_order", "da")},
         {"wn_act_da": 9.0, "zeta_act_da": 0.45}),
    Case("cruise delay 30 ms da", "cruise", 1602, (_e("time_delay", input="da", delay_s=0.03),),
         {("time_delay", "da")}, {"tau_a": TAU_A + 0.03}, (("fix", "tau_a", TAU_A),)),
    Case("cruise lag 0.11 s dr", "cruise", 1603, (_e("actuator_lag", input="dr", time_constant_s=0.11),),
         {("actuator_lag", "dr")}, {"w_act_dr": 1 / 0.11}),
    Case("cruise notch 12 rad/s depth 0.65 da, noise x2", "cruise", 1604,
         (_e("notch_filter", input="da", omega_rad_s=12.0, zeta=0.3, depth=0.65),), {("notch_filter", "da")},
         {"w_notch_da": 12.0, "zeta_notch_da": 0.3, "depth_notch_da": 0.65}, conditions=_NOISY2),
    Case("cruise mode p 9 rad/s zeta 0.05/0.15", "cruise", 1605,
         (_e("structural_mode", output="p", omega_rad_s=9.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "p")}, {"w_mode_p": 9.0, "zeta_mode_p": 0.05, "zeta_zero_mode_p": 0.15}),
    Case("cruise skew 55 ms r", "cruise", 1606, (_e("sensor_skew", output="r", delay_s=0.055),),
         {("sensor_skew", "r")}, {"skew_r": 0.055}),
    Case("cruise scale 1.3 p, turbulence 1.0", "cruise", 1607, (_e("scale_factor", output="p", factor=1.3),),
         {("scale_factor", "p")}, {"k_p": 1.3}, turbulence=1.0),
    Case("cruise missing Nda", "cruise", 1608, (), {("missing_derivative", "G[r][da]")}, {"G_r_da": -0.02166},
         (("drop", "G", "r", "da", "Nda"),)),
    Case("cruise delay dr + mode r", "cruise", 1609,
         (_e("time_delay", input="dr", delay_s=0.05),
          _e("structural_mode", output="r", omega_rad_s=14.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("time_delay", "dr"), ("structural_mode", "r")}, {"tau_r": TAU_R + 0.05, "w_mode_r": 14.0},
         (("fix", "tau_r", TAU_R),)),
    Case("cruise notch dr + skew p", "cruise", 1610,
         (_e("notch_filter", input="dr", omega_rad_s=6.0, zeta=0.3, depth=0.7), _e("sensor_skew", output="p", delay_s=0.04)),
         {("notch_filter", "dr"), ("sensor_skew", "p")}, {"w_notch_dr": 6.0, "skew_p": 0.04}),
    Case("quad 2nd-order 40 rad/s zeta 0.6 pitch", "quad", 1601,
         (_e("actuator_second_order", input="pitch_cmd", omega_rad_s=40.0, zeta=0.6),),
         {("actuator_second_order", "pitch_cmd")}, {"wn_act_pitch_cmd": 40.0, "zeta_act_pitch_cmd": 0.6}),
    Case("quad delay 30 ms roll", "quad", 1602, (_e("time_delay", input="roll_cmd", delay_s=0.03),),
         {("time_delay", "roll_cmd")}, {"tau_roll": TAU_Q + 0.03}),
    Case("quad lag 35 ms roll, noise x2", "quad", 1603, (_e("actuator_lag", input="roll_cmd", time_constant_s=0.035),),
         {("actuator_lag", "roll_cmd")}, {"w_act_roll_cmd": 1 / 0.035}, conditions=_NOISY2),
    Case("quad notch 18 rad/s depth 0.7 pitch", "quad", 1604,
         (_e("notch_filter", input="pitch_cmd", omega_rad_s=18.0, zeta=0.25, depth=0.7),), {("notch_filter", "pitch_cmd")},
         {"w_notch_pitch_cmd": 18.0, "zeta_notch_pitch_cmd": 0.25, "depth_notch_pitch_cmd": 0.7}),
    Case("quad mode q 24 rad/s zeta 0.05/0.15, fast gusts", "quad", 1605,
         (_e("structural_mode", output="q", omega_rad_s=24.0, zeta_pole=0.05, zeta_zero=0.15),),
         {("structural_mode", "q")}, {"w_mode_q": 24.0, "zeta_mode_q": 0.05, "zeta_zero_mode_q": 0.15},
         conditions=_FAST_GUSTS),
    Case("quad skew 30 ms q", "quad", 1606, (_e("sensor_skew", output="q", delay_s=0.03),),
         {("sensor_skew", "q")}, {"skew_q": 0.03}),
    Case("quad scale 0.8 p", "quad", 1607, (_e("scale_factor", output="p", factor=0.8),),
         {("scale_factor", "p")}, {"k_p": 0.8}),
    Case("quad missing Lroll", "quad", 1608, (), {("missing_derivative", "G[p][roll_cmd]")}, {"G_p_roll_cmd": 40.0},
         (("drop", "G", "p", "roll_cmd", "Lroll"),)),
    Case("quad 2nd-order roll + mode p", "quad", 1609,
         (_e("actuator_second_order", input="roll_cmd", omega_rad_s=25.0, zeta=0.5),
          _e("structural_mode", output="p", omega_rad_s=30.0, zeta_pole=0.05, zeta_zero=0.15)),
         {("actuator_second_order", "roll_cmd"), ("structural_mode", "p")},
         {"wn_act_roll_cmd": 25.0, "w_mode_p": 30.0}),
    Case("quad lag pitch + skew phi, logged at 100 Hz", "quad", 1610,
         (_e("actuator_lag", input="pitch_cmd", time_constant_s=0.03), _e("sensor_skew", output="phi", delay_s=0.02)),
         {("actuator_lag", "pitch_cmd"), ("sensor_skew", "phi")}, {"w_act_pitch_cmd": 1 / 0.03, "skew_phi": 0.02},
         conditions=_LOG100),
]
HELD_OUT_15_CLEAN = ([Case(f"clean hover seed {s}", "hover", s) for s in range(1620, 1624)]
                     + [Case(f"clean hover seed {s} {dict(c)}", "hover", s, conditions=c)
                        for s, c in zip(range(1624, 1628), (_FAST_GUSTS, _NOISY2, _SHORT, _LOOSE))]
                     + [Case(f"clean cruise seed {s}", "cruise", s) for s in range(1620, 1624)]
                     + [Case(f"clean cruise seed {s} {dict(c)}", "cruise", s, conditions=c)
                        for s, c in zip(range(1624, 1628), (_NOISY, _SLOW_GUSTS, _SMALL, _FAST_GUSTS))]
                     + [Case(f"clean quad seed {s}", "quad", s) for s in range(1620, 1624)]
                     + [Case(f"clean quad seed {s} {dict(c)}", "quad", s, conditions=c)
                        for s, c in zip(range(1624, 1628), (_SLOW_GUSTS, _SMALL, _TIGHT, _NOISY))])


def _summary(results, clean):
    """(right, named, confusion): ``right`` counts the cases whose added effects are exactly the
    injected ones (or a scale error reported as one the data cannot show); ``named`` also counts
    those where a wrong first choice was reported as hard to tell from the injected one (method
    §13.6), with nothing else wrong."""
    ok = named = 0
    conf = Counter()
    for r in results:
        exp = {tuple(x) for x in r["expect"]}
        got = set(map(tuple, r["added"][:len(exp)])) if exp else set(map(tuple, r["added"]))
        right = got == exp and (len(r["added"]) == len(exp))
        alternative = len(r["added"]) == len(exp) and all(
            tuple(a) in exp or any(tuple(b) in exp - got for b in r["ambiguous_of"].get(tuple(a), ()))
            for a in r["added"])
        if not r["added"] and len(exp) == 1 and next(iter(exp))[0] == "scale_factor":
            # a scale error the model absorbs: right when the loop says it could not show one this size
            (kind, where), = exp
            right = r["limits"].get(where, 0.0) >= 100 * abs(r["truth_factor"] - 1.0)
            got = exp if right else got
        ok += right
        named += right or alternative
        truth_label = " + ".join(f"{k}@{w}" for k, w in sorted(exp)) or "nothing"
        got_label = " + ".join(f"{k}@{w}" for k, w in (sorted(got) if right else r["added"])) or "nothing"
        if right and not r["added"]:
            got_label += " (reported not identifiable)"
        conf[(truth_label, got_label, bool(right))] += 1
    return ok, named, conf


def _run_or_say_why(case: Case) -> dict:
    """:func:`run_case`, or ``{"name", "error"}`` when the case cannot be run (a simulation that
    diverges: an effect that destabilises the simulated pilot's loop), so one bad case does not
    stop the set; such cases are listed and left out of the counts."""
    try:
        return run_case(case)
    except ConfigError as exc:
        return {"name": case.name, "error": str(exc)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--calibrate", action="store_true", help="run the clean calibration set")
    ap.add_argument("--development", action="store_true", help="run the development set (looked at while tuning)")
    ap.add_argument("--held-out-2", action="store_true",
                    help="run the second held-out set (written after the last change to the loop)")
    ap.add_argument("--held-out-3", action="store_true",
                    help="run the third held-out set (written after the last change to the loop, stop 22)")
    ap.add_argument("--held-out-4", action="store_true",
                    help="run the fourth held-out set (written after the last change to the loop, stop 23)")
    ap.add_argument("--held-out-5", action="store_true",
                    help="run the fifth held-out set (written after the last change to the loop, stop 24)")
    ap.add_argument("--held-out-6", action="store_true",
                    help="run the sixth held-out set (written before the last change to the loop was final, stop 25)")
    ap.add_argument("--held-out-7", action="store_true",
                    help="run the seventh held-out set (written after the quadrotor took the method's windows, stop 26)")
    ap.add_argument("--held-out-8", action="store_true",
                    help="run the eighth held-out set (written after kinematic columns left the catalogue, stop 26)")
    ap.add_argument("--held-out-9", action="store_true",
                    help="run the ninth held-out set (written before control-path refits on inadequate fits, stop 27)")
    ap.add_argument("--held-out-10", action="store_true",
                    help="run the tenth held-out set (written after held-out-9 was run, no change to follow, stop 27)")
    ap.add_argument("--held-out-12", action="store_true",
                    help="the twelfth held-out set: every case flown under conditions unlike the others "
                         "(noise, gusts, sweep size and length, pilot, log rate)")
    ap.add_argument("--held-out-13", action="store_true",
                    help="the thirteenth held-out set (written after held-out-12's changes, before running them on it)")
    ap.add_argument("--held-out-14", action="store_true",
                    help="the fourteenth held-out set (written after held-out-13's change, before running it on it)")
    ap.add_argument("--held-out-15", action="store_true",
                    help="the fifteenth held-out set (written after the replacement step was widened, before running it)")
    ap.add_argument("--held-out-11", action="store_true",
                    help="run the eleventh held-out set (written before the backward step, stop 27)")
    ap.add_argument("-j", type=int, default=1, help="processes")
    ap.add_argument("--only", default=None, help="airframe name or a substring of case names")
    a = ap.parse_args(argv)
    cases = (CALIBRATION if a.calibrate else DEVELOPMENT + DEVELOPMENT_CLEAN if a.development
             else HELD_OUT_2 + HELD_OUT_2_CLEAN if a.held_out_2 else HELD_OUT_3 + HELD_OUT_3_CLEAN if a.held_out_3
             else HELD_OUT_4 + HELD_OUT_4_CLEAN if a.held_out_4
             else HELD_OUT_5 + HELD_OUT_5_CLEAN if a.held_out_5
             else HELD_OUT_6 + HELD_OUT_6_CLEAN if a.held_out_6
             else HELD_OUT_7 + HELD_OUT_7_CLEAN if a.held_out_7
             else HELD_OUT_8 + HELD_OUT_8_CLEAN if a.held_out_8
             else HELD_OUT_9 + HELD_OUT_9_CLEAN if a.held_out_9
             else HELD_OUT_10 + HELD_OUT_10_CLEAN if a.held_out_10
             else HELD_OUT_11 + HELD_OUT_11_CLEAN if a.held_out_11
             else HELD_OUT_12 + HELD_OUT_12_CLEAN if a.held_out_12
             else HELD_OUT_13 + HELD_OUT_13_CLEAN if a.held_out_13
             else HELD_OUT_14 + HELD_OUT_14_CLEAN if a.held_out_14
             else HELD_OUT_15 + HELD_OUT_15_CLEAN if a.held_out_15 else HELD_OUT + HELD_OUT_CLEAN)
    if a.only:
        cases = [c for c in cases if a.only == c.airframe or a.only in c.name]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(a.j) as ex:
        results = list(ex.map(_run_or_say_why, cases))
    failed = [r for r in results if "error" in r]
    results = [r for r in results if "error" not in r]
    for r in failed:
        print(f"{r['name']:42s} NOT RUN: {r['error']}")
    for r in results:
        within = ", ".join(f"{n} {v:.4g} (truth {t:.4g}, CR {cr}%){'' if w else ' OUTSIDE 3 CR'}"
                           for n, v, t, cr, w in r["within"])
        print(f"{r['name']:42s} {r['seconds']:5.1f}s  J {r['cost_before']:7.2f} -> {r['cost_after']:6.2f}  "
              f"{r['conclusion']}" + (f"  [{within}]" if within else ""))
        if a.calibrate or not r["added"] or set(map(tuple, r["added"])) != {tuple(x) for x in r["expect"]}:
            for t in r["tried"]:
                print(f"{'':46s}tried {t[0]}@{t[1]}: F {t[2]}, needed {t[3]}, got {t[4]}: {t[5][:300]}")
    effect = [r for r in results if r["expect"]]
    clean = [r for r in results if not r["expect"]]
    ok, named, conf = _summary(effect, clean)
    print(f"\n{len(results)} cases in {time.perf_counter() - t0:.0f} s"
          + (f" ({len(failed)} not run, listed above)" if failed else ""))
    if effect:
        n_par = sum(len(r["within"]) for r in effect)
        n_in = sum(w for r in effect for *_, w in r["within"])
        halved = sum(r["cost_after"] <= 0.5 * r["cost_before"] for r in effect if r["added"])
        print(f"effect cases: right kind and place {ok}/{len(effect)} ({100 * ok / len(effect):.0f} %); "
              f"parameters within 3 CR {n_in}/{n_par}; cost halved {halved}/{sum(bool(r['added']) for r in effect)}")
        print(f"  right, or the injected effect named as hard to tell from the one added: {named}/{len(effect)} "
              f"({100 * named / len(effect):.0f} %)")
        print("confusion (truth -> added):")
        for (t, g, right), n in sorted(conf.items()):
            print(f"  {n:2d}  {t:45s} -> {g}{'' if right else '   <-- miss'}")
    if clean:
        fp = [r for r in clean if r["added"]]
        print(f"clean cases: false positives {len(fp)}/{len(clean)}"
              + "".join(f"\n  {r['name']}: {r['conclusion']}" for r in fp))


if __name__ == "__main__":
    main(sys.argv[1:])
