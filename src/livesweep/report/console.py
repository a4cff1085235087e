"""The console summary of an identification (``livesweep identify``, batch's ``identify.log``)."""

from __future__ import annotations

from livesweep.ident.residual import effect_text

__all__ = ["summary_lines"]


def summary_lines(ident) -> list[str]:
    """The console summary of an :class:`~livesweep.pipeline.identify.Identification`, one string per line."""
    out = []
    case, stage = ident.case, ident.frequency_response
    best = ident.responses
    tf, ss, ver, res = ident.transfer_functions, ident.state_space, ident.verification, ident.residual
    dq = stage.data_quality
    out.append(f"{case.name}: {len(best.outputs)} outputs x {len(best.inputs)} inputs, "
               f"{'MISO-conditioned' if best.conditioned else 'SISO'} composite of windows {best.settings['windows_s']} s "
               f"over {dq['duration_s']:.0f} s at {dq['sample_rate_hz']:g} Hz")
    out.append(f"  {'pair':12s} {'adequate':>9s}  widest band gamma^2>=0.6, eps<=0.2 [rad/s]")
    for a in stage.adequacy:
        band = "-" if a.widest_band_rad_s is None else "%.2f .. %.2f" % a.widest_band_rad_s
        out.append(f"  {a.output + '/' + a.input:12s} {100 * a.fraction:8.0f}%  {band}")
    for c in dq["kinematic_checks"]:
        if "error" in c:
            out.append(f"  kinematic check {c['measured']} vs {c['reconstructed_from']}: not run ({c['error']})")
        else:
            out.append(f"  kinematic check {c['name']}: scale {c['scale_factor_error']:+.3f}, skew {1000 * c['skew_s']:+.0f} ms, "
                       f"rate bias {c['rate_bias']:+.3f} {c['rate_bias_units']}: {'pass' if c['passed'] else 'FAIL'}")
    repaired = {n: r for n, r in dq["repairs"].items() if any(r.values())}
    wild = {n: w["replaced"] for n, w in dq["wild_points"].items() if w["replaced"]}
    if repaired or wild:
        out.append(f"  repairs: {repaired or 'none'}; wild points replaced: {wild or 'none'}")
    for f in (tf.fits if tf else ()):
        out.append(f"  transfer function {f.name}: gain {f.gain:.4g}, delay {1000 * f.delay_s:.1f} ms, J {f.cost:.1f}"
                   + ("" if f.converged else " (NOT CONVERGED)"))
    if ss is not None:
        fit = ss.fit
        worst = max((p.cramer_rao_pct for p in fit.parameters if not p.fixed and p.cramer_rao_pct is not None),
                    default=float("nan"))
        out.append(f"  state space: J_ave {fit.cost_average:.1f}, {sum(not p.fixed for p in fit.parameters)} free parameters "
                   f"(worst CR {worst:.0f}%), removed {', '.join(fit.removed_parameters) or 'none'}"
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
                out.append(f"    + {effect_text(st.effect)}; J_ave {st.cost_before:.2f} -> {st.cost_after:.2f}{ver_txt}")
    for note in ident.data_quality["notes"]:
        out.append(f"  note: {note}")
    return out
