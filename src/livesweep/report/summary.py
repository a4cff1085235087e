"""The report's first screen: every stage that ran, its result in one line and its flags against
the method's guidelines (the appendix of ``report.html`` states them).

Works on the ``report.json`` dictionary, so the same summary is computed for a report read back
from disk. Pure: no I/O.
"""

from __future__ import annotations

import math

from livesweep.ident.accuracy import (MAX_COST, MAX_COST_AVERAGE, MAX_CRAMER_RAO_PCT, MAX_INSENSITIVITY_PCT,
                                      MAX_QUADRATIC_ZETA, NOT_DETERMINED_PCT, pct_text)
from livesweep.ident.verify import J_RMS_MAX, TIC_MAX
from livesweep.spectral.criteria import DEFAULT_CRITERIA, Criteria

__all__ = ["GUIDELINES", "guidelines", "report_criteria", "stage_summary", "modes", "cr_text", "figure",
           "live_models_info"]

#: The guidelines the flags test (method: Tischler & Remple; the report's appendix), with the
#: method's criteria; a report judged by other criteria reads them through :func:`guidelines`.
GUIDELINES = {
    "coherence": DEFAULT_CRITERIA.min_coherence,          # gamma^2 at least this, with
    "random_error": DEFAULT_CRITERIA.max_random_error,    # eps_r at most this, counts as an adequate frequency point
    "coverage": 0.5,             # a pair is flagged when adequate over less than this fraction of its band
    "cost_tf": MAX_COST,                 # J of a transfer-function fit (<= 50 excellent)
    "cost_ss": MAX_COST_AVERAGE,         # J_ave of the state-space fit
    "cramer_rao_pct": MAX_CRAMER_RAO_PCT,          # CR bound of a parameter, % of its value
    "insensitivity_pct": MAX_INSENSITIVITY_PCT,    # insensitivity, % of its value
    "j_rms": J_RMS_MAX,                            # time-domain verification
    "tic": TIC_MAX,                                # Theil inequality coefficient
    "zeta_max": MAX_QUADRATIC_ZETA,    # a second-order factor more damped than this is two first-order ones
    "not_identifiable_pct": NOT_DETERMINED_PCT,   # CR beyond this: the data say nothing about the parameter
}


def report_criteria(report: dict) -> Criteria:
    """The criteria that judged a ``report.json`` (its ``criteria``; the method's when absent)."""
    return Criteria.from_dict(report.get("criteria"))


def guidelines(report: dict) -> dict:
    """:data:`GUIDELINES` with the coherence and random-error thresholds of the report's criteria."""
    c = report_criteria(report)
    return {**GUIDELINES, "coherence": c.min_coherence, "random_error": c.max_random_error}


def cr_text(pct) -> str:
    """A Cramer-Rao bound [% of value] for display: ``12.3``, or ``not determined`` (not finite, or
    beyond :data:`~livesweep.ident.accuracy.NOT_DETERMINED_PCT`)."""
    return pct_text(pct, ".1f")


def figure(value, spec: str) -> str:
    """A figure of the report (``None`` where it could not be computed, e.g. a cost that is not
    finite) formatted with ``spec``, or ``"n/a"``."""
    return "n/a" if value is None else format(value, spec)


def modes(eigenvalues) -> list[dict]:
    """One row per mode of the eigenvalues ``[[re, im], ...]``: complex pairs once (positive
    imaginary part) with natural frequency [rad/s], damping ratio and period [s]; real roots with
    time constant [s] (or, unstable, time to double [s])."""
    rows = []
    for re, im in eigenvalues:
        if im < 0:
            continue
        lam = complex(re, im)
        if im > 0:
            wn = abs(lam)
            rows.append({"kind": "oscillatory", "eigenvalue": [re, im], "omega_n_rad_s": wn, "zeta": -re / wn,
                         "period_s": 2 * math.pi / im, "stable": re < 0})
        else:
            row = {"kind": "real", "eigenvalue": [re, 0.0], "stable": re < 0}
            if re < 0:
                row["time_constant_s"] = -1.0 / re
            elif re > 0:
                row["time_to_double_s"] = math.log(2.0) / re
            rows.append(row)
    rows.sort(key=lambda r: -abs(complex(*r["eigenvalue"])))
    return rows


def live_models_info(report: dict) -> list[str]:
    """Lines on the models the live monitor recorded for the report's test points
    (``live_models``): how many, how the compared pairs stand against the transfer functions (in
    combined Cramer-Rao bounds), the limits broken in flight. Empty without live models."""
    from livesweep.stages.live_models import AGREE_BOUNDS

    live = report.get("live_models") or []
    if not live:
        return []
    pairs = [(m, p) for m in live for p in m["pairs"]]
    compared = [(m, p["comparison"]) for m, p in pairs if p.get("comparison")]
    text = (f"in flight: {len(pairs)} pair model(s) of {len(live)} test point(s) recorded in the logs "
            "(see In flight)")
    if compared:
        differ = [f"{c['pair']} of TP{m['test_point'].get('number', '?')} ({c['max_bounds']:.2g})"
                  for m, c in compared if c.get("agrees") is False]
        worst = max((c["max_bounds"] for _, c in compared if c.get("max_bounds") is not None), default=None)
        text += (f"; {len(compared)} compared with the transfer functions: "
                 + (f"{len(differ)} differ by more than {AGREE_BOUNDS:g} combined bounds: " + ", ".join(differ)
                    if differ else f"all within {AGREE_BOUNDS:g} combined bounds"
                    + (f" (largest {worst:.2g})" if worst is not None else "")))
    out = [text]
    breaches = [b for m in live for b in m.get("breaches") or []]
    if breaches:
        out.append(f"{len(breaches)} limit(s) broken in flight: " + "; ".join(breaches))
    return out


def _row(stage, result, flags, info=()):
    return {"stage": stage, "result": result, "flags": list(flags), "info": list(info),
            "status": "flag" if flags else "pass"}


def stage_summary(report: dict) -> list[dict]:
    """``[{stage, result, flags, info, status}]`` for every stage in ``report["stages"]``.

    ``flags`` are departures from :data:`GUIDELINES` an engineer must look at before signing;
    ``info`` are facts worth knowing that are not failures (an unstable mode of an unstable
    airframe, repairs made to the data).
    """
    g = guidelines(report)
    out = []
    dq = report.get("data_quality") or {}
    ran = report.get("stages") or []
    if "frequency-response" in ran:
        ex = dq.get("excitation") or []
        poor = [f"{e['output']}/{e['input']} ({100 * e['fraction_of_band']:.0f} %)" for e in ex
                if e["fraction_of_band"] < g["coverage"]]
        flags = []
        if poor:
            flags.append(f"{len(poor)} of {len(ex)} pairs adequate over less than {100 * g['coverage']:.0f} % of the band: "
                         + ", ".join(poor))
        for c in dq.get("kinematic_checks") or []:
            if "error" in c:
                flags.append(f"kinematic check {c.get('measured')} not run: {c['error']}")
            elif not c.get("passed"):
                flags.append(f"kinematic check {c['name']} fails (scale {c['scale_factor_error']:+.3f}, "
                             f"skew {1000 * c['skew_s']:+.0f} ms)")
        info = []
        wild = sum(w.get("replaced", 0) for w in (dq.get("wild_points") or {}).values())
        if wild:
            info.append(f"{wild} wild point(s) replaced")
        rep = sum(v for r in (dq.get("repairs") or {}).values() for v in r.values() if isinstance(v, (int, float)))
        if rep:
            info.append(f"{rep:.0f} sample repair(s) (see data quality)")
        info += list(dq.get("notes") or [])
        good = len(ex) - len(poor)
        if "transfer-functions" not in ran:
            info += live_models_info(report)
        out.append(_row("frequency-response", f"{len(report.get('frequency_responses') or [])} pairs; {good} of {len(ex)} "
                        f"adequate (γ² ≥ {g['coherence']}, ε ≤ {g['random_error']}) over at least "
                        f"{100 * g['coverage']:.0f} % of the band", flags, info))
    if "transfer-functions" in ran:
        flags, parts = [], []
        for t in report.get("transfer_functions") or []:
            parts.append(f"{t['name']} J {figure(t['cost'], '.1f')}")
            if not t.get("converged", True):
                flags.append(f"{t['name']}: the fit did not converge")
            if t["cost"] is None:
                flags.append(f"{t['name']}: J not finite")
            elif t["cost"] > g["cost_tf"]:
                flags.append(f"{t['name']}: J = {t['cost']:.0f} > {g['cost_tf']:.0f}")
            bad = [k for k, v in (t.get("cramer_rao_pct") or {}).items() if v is None or v > g["cramer_rao_pct"]]
            if bad:
                flags.append(f"{t['name']}: CR > {g['cramer_rao_pct']:.0f} % on " + ", ".join(bad))
            for f in t.get("factors") or []:
                if f.get("kind") == "second" and f.get("zeta") is not None and f["zeta"] > g["zeta_max"]:
                    flags.append(f"{t['name']}: degenerate fit, ζ = {f['zeta']:.3g} (> {g['zeta_max']:g}: two real "
                                 "roots fitted as one oscillatory pair; try first-order factors or another band)")
            band = t.get("band_rad_s") or []
            for f in t.get("factors") or []:
                w = f.get("omega") or f.get("inverse_time_constant")
                if w is not None and len(band) == 2 and band[0] and (abs(w) < band[0] / 10 or abs(w) > band[1] * 10):
                    flags.append(f"{t['name']}: a root at {abs(w):.3g} rad/s, a decade outside the fitted band "
                                 f"{band[0]:.3g}-{band[1]:.3g} rad/s (not determined by the data)")
        out.append(_row("transfer-functions", "; ".join(parts), flags, live_models_info(report)))
    final = report.get("model") or {}
    looped = final.get("source") == "residual-loop"
    if "state-space" in ran:
        ss = final if looped else report["state_space"]       # the row signs the model the report gives
        free = [p for p in ss["parameters"] if not p["fixed"]]
        flags, info = [], []
        J = ss["cost"]["average"]
        if J is None or J > g["cost_ss"]:
            flags.append(f"J_ave = {J} > {g['cost_ss']:.0f}" if J is not None else "J_ave not finite")
        if not ss.get("converged", True):
            flags.append(f"the fit did not converge: {ss.get('message', '')}")
        lost = [p["name"] for p in free if p.get("cramer_rao_pct") is None
                or p["cramer_rao_pct"] > g["not_identifiable_pct"]]
        if lost:
            flags.append("not identifiable (at a bound, or the data do not determine them): " + ", ".join(lost))
        cr = [p["name"] for p in free if p["name"] not in lost and p["cramer_rao_pct"] > g["cramer_rao_pct"]]
        if cr:
            flags.append(f"CR > {g['cramer_rao_pct']:.0f} %: " + ", ".join(cr))
        ins = [p["name"] for p in free if p.get("insensitivity_pct") is not None
               and p["insensitivity_pct"] > g["insensitivity_pct"]]
        if ins:
            flags.append(f"insensitivity > {g['insensitivity_pct']:.0f} %: " + ", ".join(ins))
        unstable = [m for m in modes(ss.get("eigenvalues") or []) if not m["stable"]]
        if unstable:
            info.append(f"{len(unstable)} unstable mode(s) (see the mode table)")
        removed = ss.get("removed_parameters") or []
        if removed:
            info.append("removed in structure reduction: " + ", ".join(removed))
        result = f"J_ave {J:.1f}, {len(free)} free parameters" if J is not None else f"{len(free)} free parameters"
        if looped:
            before = final["before_loop"]["cost_average"]
            result = (f"final model, {final['label']}: {result} (before the residual loop: J_ave "
                      f"{figure(before, '.1f')}, {sum(not p['fixed'] for p in report['state_space']['parameters'])} "
                      f"free parameters; both on {final['points_per_pair']} points per pair)")
        out.append(_row("state-space", result, flags, info))
    if "verification" in ran:
        ver = report["verification"]
        flags, parts = [], []
        for r in ver["records"]:
            parts.append(f"{r['label']}: J_rms {figure(r['j_rms'], '.3f')}")
            if r["j_rms"] is None or r["j_rms"] > g["j_rms"]:
                flags.append(f"{r['label']}: J_rms = {figure(r['j_rms'], '.3f')} > {g['j_rms']:g}")
            high = [f"{o['name']} {figure(o['tic'], '.3f')}" for o in r["outputs"]
                    if o["tic"] is None or o["tic"] > g["tic"]]
            if high:
                flags.append(f"{r['label']}: TIC > {g['tic']:g} on " + ", ".join(high))
        if looped and final.get("verification"):      # the model the report signs, the one before it beside it
            flags = []
            parts = [f"{r['label']}: J_rms {figure(r['j_rms'], '.3f')} (before the residual loop "
                     f"{figure(b['j_rms'], '.3f')})" for r, b in zip(final["verification"], ver["records"])]
            for r in final["verification"]:
                if r["j_rms"] is None or r["j_rms"] > g["j_rms"]:
                    flags.append(f"{r['label']}: J_rms = {figure(r['j_rms'], '.3f')} > {g['j_rms']:g}")
                high = [f"{n} {figure(t, '.3f')}" for n, t in r["tic"].items() if t is None or t > g["tic"]]
                if high:
                    flags.append(f"{r['label']}: TIC > {g['tic']:g} on " + ", ".join(high))
        out.append(_row("verification", "; ".join(parts), flags))
    if "residual-loop" in ran:
        rl = report["residual_loop"]
        flags, info = [], []
        if rl["conclusion"].startswith("residual above noise"):
            flags.append("residual above noise that no catalogued effect explains")
        if rl.get("augmented_case"):
            info.append(f"model augmented: see {rl['augmented_case']}")
        out.append(_row("residual-loop", rl["conclusion"], flags, info))
    return out
