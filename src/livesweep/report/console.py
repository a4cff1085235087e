"""The console summary of an identification (``livesweep identify``, batch's ``identify.log``)."""

from __future__ import annotations

import math

from livesweep.ident.accuracy import pct_text
from livesweep.ident.cost import N_OMEGA
from livesweep.ident.residual import N_OMEGA_LOOP, effect_text

__all__ = ["summary_lines", "repair_lines", "live_model_lines"]


def _worst_cr(fit) -> str:
    worst = max((p.cramer_rao_pct for p in fit.parameters if not p.fixed), default=float("nan"),
                key=lambda v: v if math.isfinite(v) else math.inf)
    text = pct_text(worst, ".0f")
    return text if text == "not determined" else text + "%"


def summary_lines(ident) -> list[str]:
    """The console summary of an :class:`~livesweep.stages.identify.Identification`, one string per line."""
    out = []
    case, stage = ident.case, ident.frequency_response
    best = ident.responses
    tf, ss, ver, res = ident.transfer_functions, ident.state_space, ident.verification, ident.residual
    dq = stage.data_quality
    out.append(f"{case.name}: {len(best.outputs)} outputs x {len(best.inputs)} inputs, "
               f"{'MISO-conditioned' if best.conditioned else 'SISO'} composite of windows {best.settings['windows_s']} s "
               f"over {dq['duration_s']:.0f} s at {dq['sample_rate_hz']:g} Hz")
    out.append(f"  {'pair':12s} {'adequate':>9s}  widest band {case.criteria.ascii()} [rad/s]")
    for a in stage.adequacy:
        band = "-" if a.widest_band_rad_s is None else "%.2f .. %.2f" % a.widest_band_rad_s
        out.append(f"  {a.output + '/' + a.input:12s} {100 * a.fraction:8.0f}%  {band}")
    for c in dq["kinematic_checks"]:
        if "error" in c:
            out.append(f"  kinematic check {c['measured']} vs {c['reconstructed_from']}: not run ({c['error']})")
        else:
            out.append(f"  kinematic check {c['name']}: scale {c['scale_factor_error']:+.3f}, skew {1000 * c['skew_s']:+.0f} ms, "
                       f"rate bias {c['rate_bias']:+.3f} {c['rate_bias_units']}: {'pass' if c['passed'] else 'FAIL'}")
    out += repair_lines(dq)
    for f in (tf.fits if tf else ()):
        out.append(f"  transfer function {f.name}: gain {f.gain:.4g}, delay {1000 * f.delay_s:.1f} ms, J {f.cost:.1f}"
                   + ("" if f.converged else " (NOT CONVERGED)"))
    if ss is not None:
        fit = ss.fit
        out.append(f"  state space: J_ave {fit.cost_average:.1f}, {sum(not p.fixed for p in fit.parameters)} free parameters "
                   f"(worst CR {_worst_cr(fit)}), removed {', '.join(fit.removed_parameters) or 'none'}"
                   + ("" if fit.converged else " (NOT CONVERGED)"))
    for label, v in (ver.results if ver else ()):
        out.append(f"  verification {label}: J_rms {v.j_rms:.3f}, TIC "
                   + ", ".join(f"{o.name} {o.tic:.3f}" for o in v.outputs) + (": pass" if v.passed else ": FAIL"))
    if res is not None:
        loop = res.loop
        out.append(f"  residual loop: {loop.conclusion} ({loop.n_fits} re-identifications)")
        for st in loop.steps:
            if st.effect is not None:
                ver_txt = (f", verification J_rms {st.verification_before['j_rms']:.3f} -> {st.verification_after['j_rms']:.3f}"
                           if st.verification_before and st.verification_after else "")
                out.append(f"    + {effect_text(st.effect)}; J_ave {st.cost_before:.2f} -> {st.cost_after:.2f} "
                           f"on the loop's {N_OMEGA_LOOP} points per pair{ver_txt}")
        if res.final is not None and ss is not None:
            fit = res.final
            added = ", ".join(f"{e['kind']} at {e['where']}" for e in loop.added)
            out.append(f"  final model (state space + {added}): J_ave {fit.cost_average:.1f} "
                       f"({ss.fit.cost_average:.1f} before the residual loop, both on {N_OMEGA} points per pair), "
                       f"{sum(not p.fixed for p in fit.parameters)} free parameters (worst CR {_worst_cr(fit)})")
    out += live_model_lines(ident)
    for note in ident.data_quality["notes"]:
        out.append(f"  note: {note}")
    return out


def live_model_lines(ident) -> list[str]:
    """One line per pair of each model the live monitor recorded for the case's test points, with
    how it stands against the transfer function of the same structure; then the reader's notes."""
    from livesweep.stages.live_models import AGREE_BOUNDS, compare_live_models

    live = getattr(ident, "live_models", None)
    if live is None:
        return []
    fits = ident.transfer_functions.fits if ident.transfer_functions is not None else ()
    out = []
    for m, compared in zip(live.models, compare_live_models(live, fits)):
        for p, (cmp, why) in zip(m.pairs, compared):
            cost = "n/a" if p.cost is None else f"{p.cost:.1f}"
            text = f"  in flight, test point {m.test_point.get('number', '?')}: {p.name} {p.structure}, J {cost}"
            if cmp is None:
                text += f"; not compared ({why})"
            elif cmp.max_bounds is None:
                text += f"; TF {cmp.transfer_function}: no parameter with both bounds"
            else:
                text += (f"; TF {cmp.transfer_function}: {'agrees' if cmp.agrees else 'DIFFERS'}, largest difference "
                         f"{cmp.max_bounds:.2g} combined bounds (limit {AGREE_BOUNDS:g})")
            out.append(text)
    out += [f"  note: {n}" for n in live.notes]
    return out


def _n(count: int, one: str, many: str | None = None) -> str:
    return f"{count} {one if count == 1 else (many or one + 's')}"


def repair_lines(data_quality: dict) -> list[str]:
    """What the data-consistency step repaired or left out, one line per signal that needed it
    (none when nothing was touched): ``p: 2 gaps interpolated across (14 grid samples); 1 wild
    point replaced (Hampel, ...)``. ``data_quality`` is the stage's ``data_quality`` dict
    (``repairs`` holds :class:`~livesweep.consistency.resample.RepairCounts` as dicts, ``wild_points``
    the wild-point replacements)."""
    repairs = data_quality.get("repairs") or {}
    wild = data_quality.get("wild_points") or {}
    lines = []
    for name in list(repairs) + [n for n in wild if n not in repairs]:
        r = repairs.get(name) or {}
        parts = []
        if r.get("nan_samples"):
            parts.append(_n(r["nan_samples"], "sample") + " dropped (value or time stamp not a number)")
        if r.get("duplicate_stamps"):
            parts.append(_n(r["duplicate_stamps"], "sample") + " dropped (time stamp repeated)")
        if r.get("backward_stamps"):
            parts.append(_n(r["backward_stamps"], "time stamp") + " out of order, put back in order")
        if r.get("gaps_interpolated"):
            parts.append(_n(r["gaps_interpolated"], "short gap") + " interpolated across ("
                         + _n(r.get("samples_interpolated", 0), "grid sample") + ")")
        if r.get("gaps_excluded"):
            parts.append(_n(r["gaps_excluded"], "long gap") + " left out, not interpolated ("
                         + _n(r.get("samples_excluded", 0), "grid sample") + "; no spectral window spans them)")
        w = wild.get(name) or {}
        if w.get("replaced"):
            parts.append(_n(w["replaced"], "wild point") + " replaced"
                         + (f" ({w['method']})" if w.get("method") else ""))
        if parts:
            lines.append(f"    {name}: " + "; ".join(parts))
    return ["  repairs to the data:"] + lines if lines else []
