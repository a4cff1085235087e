"""``report.json``, ``report.html`` and plots for ``livesweep identify`` (DESIGN.md §4.3)."""

from __future__ import annotations

import html
import json
import os
import re
import tempfile
from pathlib import Path

from livesweep import __version__
from livesweep.errors import ConfigError
from livesweep.ident.residual import effect_text
from livesweep.numbers import finite_or_none
from livesweep.report.export import (RESPONSES_CSV, RESPONSES_MAT, polynomials, state_space_export,
                                     write_responses_csv, write_responses_mat)
from livesweep.report.plots import bode_plot

__all__ = ["write_report", "write_frequency_report", "prepare_out_dir", "save_response_set", "load_response_set",
           "RESPONSE_SET_FILE"]

#: the stage's full frequency-response set (complex H, settings), for the parametric stages
RESPONSE_SET_FILE = "frequency_response_set.json"


def prepare_out_dir(path) -> Path:
    """Create the output folder (and parents); ConfigError naming it when that is impossible."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {str(out)!r} exists and is not a directory")
    try:
        (out / "plots").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {str(out)!r} cannot be created: {exc.strerror}") from None
    if not os.access(out, os.W_OK):
        raise ConfigError(f"--out {str(out)!r} is not writable")
    return out


def save_response_set(response_set, path) -> Path:
    """Write a FrequencyResponseSet (and nothing else) as JSON, atomically."""
    path = Path(path)
    _atomic_write(path, json.dumps({"format": "livesweep.frequency_response_set/1", **response_set.to_dict()},
                                   allow_nan=False))
    return path


def load_response_set(path):
    """Read a FrequencyResponseSet written by :func:`save_response_set`; ConfigError naming the file."""
    from livesweep.spectral.response import FrequencyResponseSet

    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read a frequency-response set: {exc}") from None
    if d.get("format") != "livesweep.frequency_response_set/1":
        raise ConfigError(f"{path}: not a livesweep frequency-response set (format {d.get('format')!r})")
    return FrequencyResponseSet.from_dict(d)


_UNSAFE_FILE_CHARS = re.compile(r"[^A-Za-z0-9_.-]")


def _plot_rel(stem: str, taken: set[str]) -> str:
    """``plots/<stem>.png`` with ``stem`` made a plain file name (characters other than letters,
    digits, ``_ . -`` become ``_``; no leading dot; at most 100 characters) and unique among
    ``taken`` (``_2``, ``_3`` ... appended), whatever the signal names: a plot never lands
    outside ``plots/`` nor overwrites another plot."""
    safe = _UNSAFE_FILE_CHARS.sub("_", stem).lstrip(".")[:100] or "_"
    name, k = safe, 1
    while name in taken:
        k += 1
        name = f"{safe}_{k}"
    taken.add(name)
    return f"plots/{name}.png"


def _atomic_write(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".partial")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def write_report(identification, out_dir, *, plots: bool = True) -> Path:
    """Write an :class:`~livesweep.pipeline.identify.Identification` to a folder; nothing in it changes.

    Parameters
    ----------
    identification : Identification
        What :func:`livesweep.identify` returned.
    out_dir : str or Path
        Folder for ``report.json``, ``report.html``, ``frequency_response_set.json``, ``plots/`` and
        (when the residual loop added an effect) ``augmented_case.toml``; created if needed. Plots
        of an earlier run that this one did not write are removed.
    plots : bool
        False skips every plot (about half the time of a report); ``report.json`` is the same and
        its ``plot`` entries are null.

    Returns
    -------
    Path
        ``report.json``.
    """
    i = identification
    return write_frequency_report(i.frequency_response, out_dir, transfer_functions=i.transfer_functions,
                                  state_space=i.state_space, verification=i.verification, residual=i.residual,
                                  plots=plots)


def write_frequency_report(stage, out_dir, *, transfer_functions=None, state_space=None, verification=None,
                           residual=None, plots: bool = True) -> Path:
    """Write the report of the stages run; returns the path of ``report.json``.

    Parameters
    ----------
    stage : FrequencyResponseStage
    out_dir : str or Path
    transfer_functions : TransferFunctionStage, optional
    state_space : StateSpaceStage, optional
        Needs ``.fit`` (StateSpaceFit) and ``.pairs``.
    verification : VerificationStage, optional
        Needs ``.results``: list of (label, Verification).
    residual : ResidualStage, optional
        The residual loop (``.loop``): ``residual_loop`` in the JSON, residual plots per step and,
        when it added an effect, ``augmented_case.toml`` (the case with the augmented model).
    """
    out = prepare_out_dir(out_dir)
    case, an = stage.case, stage.analysis
    best = an.best
    units = {n: s.units for n, s in case.signals.items()}
    responses, taken = [], set()
    draw = plots
    tf_fits = list(transfer_functions.fits) if transfer_functions is not None else []
    ss_fit = state_space.fit if state_space is not None else None
    for pair in best.pairs():
        ordinary = an.siso.pair(pair.output, pair.input) if best.conditioned else None
        rel = _plot_rel(f"{pair.output}_{pair.input}", taken)
        models, band = [], None
        for f in tf_fits:
            if (f.output, f.input) == (pair.output, pair.input):
                models.append((f"TF {f.name} (J {f.cost:.0f})", pair.omega, f.response(pair.omega)))
                band = f.band_rad_s
        ssm = ss_fit.model if ss_fit is not None else None
        if ssm is not None and pair.output in ssm.outputs and pair.input in ssm.inputs:
            T = ss_fit.frequency_response(pair.omega)[list(ssm.outputs).index(pair.output), list(ssm.inputs).index(pair.input)]
            j = next((c for o, i, c in ss_fit.cost_pairs if (o, i) == (pair.output, pair.input)), None)
            models.append(("state space" + (f" (J {j:.0f})" if j is not None else ""), pair.omega, T))
        if draw:
            bode_plot(pair, out / rel, title=f"{case.name}: {pair.output} / {pair.input}",
                      units=(units.get(pair.output, ""), units.get(pair.input, "")), ordinary=ordinary,
                      models=models, fit_band_rad_s=band)
        responses.append({**pair.to_dict(), "output_units": units.get(pair.output, ""),
                          "input_units": units.get(pair.input, ""), "plot": rel if draw else None})
    report = {
        "livesweep_version": __version__,
        "case": {"name": case.name, "aircraft": case.aircraft, "condition": case.condition, "path": str(case.path)},
        "stages": ["frequency-response"],
        "frequency_responses": responses,
        "spectral_settings": best.settings,
        "data_quality": {**stage.data_quality, "notes": list(stage.data_quality["notes"])},   # a copy: stages stay as computed
    }
    stages = report["stages"]
    if transfer_functions is not None:
        stages.append("transfer-functions")
        report["transfer_functions"] = [{**f.to_dict(), "polynomials": polynomials(f),
                                         "handling_qualities": (transfer_functions.handling or {}).get(f.name)}
                                        for f in tf_fits]
        report["data_quality"]["notes"] += list(transfer_functions.notes)
    if ss_fit is not None:
        stages.append("state-space")
        report["state_space"] = {**ss_fit.to_dict(), "matrices": state_space_export(ss_fit, units)}
        report["data_quality"]["notes"] += list(state_space.notes)
    if verification is not None:
        stages.append("verification")
        from livesweep.report.plots import time_history_plot

        records = []
        for k, (label, v) in enumerate(verification.results):
            rel = _plot_rel(f"verification_{k}", taken) if draw else None
            if draw:
                time_history_plot(v.t_s, v.measured, v.predicted, v.inputs, [o.name for o in v.outputs],
                                  [o.units for o in v.outputs], list(verification.inputs), out / rel,
                                  title=f"{case.name}: verification, {label}", tic=[o.tic for o in v.outputs])
            records.append({"label": label, **v.to_dict(), "plot": rel})
        first = records[0] if records else {}
        report["verification"] = {**{k: first.get(k) for k in ("outputs", "j_rms", "passed", "guidelines")},
                                  "records": records}
        report["data_quality"]["notes"] += list(verification.notes)
    if residual is not None:
        stages.append("residual-loop")
        report["residual_loop"] = _residual_section(case, residual.loop, out, taken, draw)
        if residual.loop.added:      # the model with the effects the loop added
            report["residual_loop"]["matrices"] = state_space_export(residual.loop.fit, units)
        from livesweep.report.plots import time_history_plot

        after = []
        for k, (label, v) in enumerate(residual.verification_after):
            rel = _plot_rel(f"residual_verification_{k}", taken) if draw else None
            if draw:
                time_history_plot(v.t_s, v.measured, v.predicted, v.inputs, [o.name for o in v.outputs],
                                  [o.units for o in v.outputs], list(residual.loop.fit.model.inputs), out / rel,
                                  title=f"{case.name}: verification after the residual loop, {label}",
                                  tic=[o.tic for o in v.outputs])
            after.append({"label": label, "j_rms": finite_or_none(v.j_rms), "plot": rel,
                          "tic": {o.name: finite_or_none(o.tic) for o in v.outputs}})
        report["residual_loop"]["verification_final"] = after
    if best.conditioned:
        report["frequency_responses_ordinary"] = [p.to_dict() for p in an.siso.pairs()]
        report["multiple_coherence"] = {o: best.multiple_coherence[k].tolist() for k, o in enumerate(best.outputs)}
        report["ill_conditioned"] = best.ill_conditioned.astype(bool).tolist()
    save_response_set(best, out / RESPONSE_SET_FILE)
    report["frequency_response_set"] = RESPONSE_SET_FILE
    final = residual.loop.fit if residual is not None and residual.loop.added else ss_fit
    write_responses_csv(best, out / RESPONSES_CSV, units)
    write_responses_mat(best, out / RESPONSES_MAT, units, final)
    report["exports"] = {"csv": RESPONSES_CSV, "mat": RESPONSES_MAT}
    if best.conditioned:
        save_response_set(an.siso, out / ("ordinary_" + RESPONSE_SET_FILE))
    _remove_stale_plots(out, taken if draw else set())
    if residual is None or not residual.loop.added:
        (out / "augmented_case.toml").unlink(missing_ok=True)          # an earlier run's, not this one's
    path = out / "report.json"
    _atomic_write(path, json.dumps(report, indent=1, allow_nan=False))
    _atomic_write(out / "report.html", _embed_images(_html(report), out))
    return path


def _remove_stale_plots(out: Path, written: set[str]) -> None:
    """Delete ``plots/*.png`` this report did not write (left by an earlier run into the same folder)."""
    for f in (out / "plots").glob("*.png"):
        if f.stem not in written:
            f.unlink(missing_ok=True)


def _residual_section(case, loop, out: Path, taken: set[str], draw: bool = True) -> dict:
    from livesweep.report.case_file import write_augmented_case
    from livesweep.report.plots import residual_plot

    d = loop.to_dict()
    for k, (step, sd) in enumerate(zip(loop.steps, d["steps"])):
        rel = _plot_rel(f"residual_step_{k + 1}", taken) if draw else None
        what = (f"added {step.effect['kind']} at {step.effect['where']}" if step.effect else "nothing added")
        if draw:
            residual_plot(step.residuals_before, step.residuals_after, out / rel,
                          title=f"{case.name}: residual loop step {k + 1} ({what})")
        sd["plot"] = rel
        sd["residuals_before"] = [r.to_dict() for r in step.residuals_before]
        sd["residuals_after"] = [r.to_dict() for r in step.residuals_after]
    if loop.added:
        header = ("Written by livesweep's residual loop from " + str(case.path) + "\n" + "\n".join(
            f"added {e['kind']} at {e['where']}: " + ", ".join(f"{p['name']} = {p['value']:.6g}" for p in e["parameters"])
            for e in loop.added))
        write_augmented_case(case.path, loop.table, out / "augmented_case.toml", header=header)
        d["augmented_case"] = "augmented_case.toml"
    return d


def _html(report: dict) -> str:
    e = html.escape
    rows = []
    for ex in report["data_quality"]["excitation"]:
        band = ex["widest_band_rad_s"]
        rows.append(f"<tr><td>{e(ex['output'])}/{e(ex['input'])}</td><td>{100 * ex['fraction_of_band']:.0f} %</td>"
                    f"<td>{'%.2f - %.2f' % tuple(band) if band else '-'}</td><td>{ex['median_coherence']:.2f}</td></tr>")
    checks = "".join(
        f"<tr><td>{e(c.get('name', c['measured']))}</td><td>{c.get('scale_factor_error', '-')}</td><td>{c.get('skew_s', '-')}</td>"
        f"<td>{c.get('rate_bias', '-')}</td><td>{'pass' if c.get('passed') else 'FAIL'}</td></tr>"
        for c in report["data_quality"]["kinematic_checks"])
    notes = "".join(f"<li>{e(n)}</li>" for n in report["data_quality"]["notes"]) or "<li>none</li>"
    imgs = "".join(f'<figure>{_img(r["plot"], 600)}<figcaption>{e(r["output"])}/{e(r["input"])}'
                   f'</figcaption></figure>' for r in report["frequency_responses"] if r["plot"])
    extra = _html_parametric(report)
    c = report["case"]
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>livesweep: {e(c['name'])}</title>
<style>body{{font-family:sans-serif;max-width:1300px;margin:auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px}}figure{{display:inline-block;margin:4px}}</style></head><body>
<h1>{e(c['name'])}</h1><p>{e(c['aircraft'])} — {e(c['condition'])}; livesweep {e(report['livesweep_version'])}</p>
<h2>Excitation adequacy (γ² ≥ 0.6, ε ≤ 0.2)</h2><table><tr><th>pair</th><th>of band</th><th>widest band [rad/s]</th>
<th>median γ²</th></tr>{''.join(rows)}</table>
<h2>Kinematic consistency</h2><table><tr><th>check</th><th>scale error</th><th>skew [s]</th><th>rate bias</th><th></th></tr>
{checks}</table><h2>Notes</h2><ul>{notes}</ul>{extra}<h2>Frequency responses</h2>{imgs}</body></html>"""


def _img(rel, width: int) -> str:
    """An ``<img>`` of a plot written by this report; empty when plots were skipped."""
    return f'<img src="{html.escape(rel)}" width="{width}">' if rel else ""


def _embed_images(page: str, out: Path) -> str:
    """Make the page self-contained: every ``src="plots/..png"`` becomes a base64 data URI."""
    import base64
    import re

    def data_uri(m):
        path = out / html.unescape(m.group(1))
        if not path.is_file():
            return m.group(0)
        return 'src="data:image/png;base64,' + base64.b64encode(path.read_bytes()).decode() + '"'

    return re.sub(r'src="(plots/[^"]+\.png)"', data_uri, page)


def _flag(ok: bool) -> str:
    return "" if ok else ' style="background:#fdd"'


def _html_parametric(report: dict) -> str:
    """Transfer-function, derivative and verification tables, flagged against the guidelines."""
    e = html.escape
    parts = []
    tfs = report.get("transfer_functions") or []
    if tfs:
        rows = "".join(
            f"<tr><td>{e(t['name'])}</td><td>{e(t['output'])}/{e(t['input'])}</td><td>{t['gain']:.4g}</td>"
            f"<td>{e('; '.join(_factor_text(f) for f in t.get('factors', [])))}</td><td>{1000 * t['delay_s']:.1f}</td>"
            f"<td{_flag(t['cost'] <= 100)}>{t['cost']:.1f}</td>"
            f"<td>{e(', '.join(f'{k} {v:.0f}%' for k, v in (t.get('cramer_rao_pct') or {}).items() if v is not None))}</td></tr>"
            for t in tfs)
        hq = []
        for t in tfs:
            h = t.get("handling_qualities") or {}
            def fmt(d, k, scale=1.0, unit=""):
                v = (d or {}).get(k)
                return "-" if v is None else f"{scale * v:.3g}{unit}"
            hq.append(f"<tr><td>{e(t['name'])}</td>" + "".join(
                f"<td>{fmt(h.get(src), 'bandwidth_rad_s')}</td><td>{fmt(h.get(src), 'phase_delay_s', 1000)}</td>"
                for src in ("measured", "fitted")) + "</tr>")
        parts.append("<h3>Handling qualities (attitude response, method.md §10)</h3><table><tr><th>pair</th>"
                     "<th>&omega;<sub>BW</sub> measured [rad/s]</th><th>&tau;<sub>p</sub> measured [ms]</th>"
                     "<th>&omega;<sub>BW</sub> fitted</th><th>&tau;<sub>p</sub> fitted [ms]</th></tr>"
                     + "".join(hq) + "</table>")
        parts.append("<h2>Transfer functions</h2><p>J &le; 100 acceptable, &le; 50 excellent (method.md §7.2); "
                     "Cram&eacute;r&ndash;Rao bounds in % of the value.</p><table><tr><th>name</th><th>pair</th>"
                     f"<th>gain</th><th>factors</th><th>&tau; [ms]</th><th>J</th><th>CR %</th></tr>{rows}</table>")
    ss = report.get("state_space")
    if ss:
        rows = "".join(
            f"<tr><td>{e(p['name'])}</td><td>{p['value']:.5g}</td><td>{'fixed' if p['fixed'] else ''}</td>"
            f"<td{_flag(p.get('cramer_rao_pct') is None or p['cramer_rao_pct'] <= 20)}>"
            f"{'' if p.get('cramer_rao_pct') is None else '%.1f' % p['cramer_rao_pct']}</td>"
            f"<td{_flag(p.get('insensitivity_pct') is None or p['insensitivity_pct'] <= 10)}>"
            f"{'' if p.get('insensitivity_pct') is None else '%.1f' % p['insensitivity_pct']}</td></tr>"
            for p in ss["parameters"])
        cost = ss["cost"]
        pairs = ", ".join(f"{c['output']}/{c['input']} {c['cost']:.0f}" for c in cost["pairs"])
        parts.append(f"<h2>State-space derivatives</h2><p>J<sub>ave</sub> = {cost['average']:.1f} "
                     f"(&le; 100 guideline); per pair: {e(pairs)}. Flagged: CR % &gt; 20, insensitivity % &gt; 10 "
                     f"(method.md §8.4). Removed in structure reduction: {e(', '.join(ss.get('removed_parameters') or []) or 'none')}."
                     "</p><table><tr><th>parameter</th><th>value</th><th></th><th>CR %</th><th>I %</th></tr>"
                     f"{rows}</table>")
    ver = report.get("verification")
    if ver:
        blocks = []
        for r in ver["records"]:
            tics = ", ".join(f"{o['name']} {o['tic']:.3f}" for o in r["outputs"])
            blocks.append(f"<p{_flag(bool(r.get('passed')))}>{e(r['label'])}: J<sub>rms</sub> {r['j_rms']:.3f}, "
                          f"TIC {e(tics)} &mdash; {'passes' if r.get('passed') else 'FAILS'} the guidelines</p>"
                          + _img(r["plot"], 700))
        parts.append("<h2>Time-domain verification</h2><p>Dissimilar manoeuvres, no parameter changed; biases and "
                     "reference shifts by least squares (method.md §9). Guidelines: J<sub>rms</sub> &le; 2, TIC &le; 0.25."
                     "</p>" + "".join(blocks))
    rl = report.get("residual_loop")
    if rl:
        blocks = [f"<p><b>{e(rl['conclusion'])}</b> ({rl['re_identifications']} re-identifications)"
                  + (f"; augmented case: <code>{e(rl['augmented_case'])}</code>" if rl.get("augmented_case") else "")
                  + "</p>"]
        for k, st in enumerate(rl["steps"]):
            eff = st["effect"]
            cands = ", ".join(f"{c['kind']} at {c['where']} ({c['evidence']:.0f})" for c in st["candidates"][:4])
            vb, va = st.get("verification_before"), st.get("verification_after")
            ver = (f"; verification J<sub>rms</sub> {vb['j_rms']:.3f} &rarr; {va['j_rms']:.3f}" if vb and va else "")
            if eff:
                pars = effect_text(eff).split(": ", 1)[1]
                head = f"added <b>{e(eff['kind'])}</b> at <b>{e(eff['where'])}</b>: {e(pars)}"
            else:
                head = "nothing added"
            tried = "".join(f"<li>{e(t['kind'])} at {e(t['where'])}"
                            + "".join(f" with {e(w['kind'])} at {e(w['where'])}" for w in t.get("with", ()))
                            + f": J<sub>ave</sub> {t['cost_after']:.2f}, {e(t['reason'])}</li>"
                            for t in st["tried"])
            blocks.append(f"<h3>Step {k + 1}: {head}</h3><p>J<sub>ave</sub> {st['cost_before']:.2f} &rarr; "
                          f"{st['cost_after']:.2f}{ver}. Ranked evidence (noise units): {e(cands)}</p>"
                          f"<ul>{tried}</ul>" + _img(st["plot"], 900))
        for r in rl.get("verification_final", []):
            blocks.append(f"<p>Time domain after the loop, {e(r['label'])}: J<sub>rms</sub> {r['j_rms']:.3f} "
                          f"(before: see the verification section)</p>" + _img(r["plot"], 700))
        if rl["unexplained"]:
            blocks.append("<p>Unexplained: " + e("; ".join(str(u) for u in rl["unexplained"])) + "</p>")
        crit = rl.get("criterion") or {}
        test = (f" (an F-test counting its parameters and {crit['effective_points']:.0f} independent frequency "
                f"values, false-alarm probability {crit['false_alarm']:g} per step)") if crit else ""
        parts.append("<h2>Residual loop</h2><p>The identified model's residual against the data's random error, "
                     "matched to a catalogue of missing effects; the best-supported one is added and kept only when "
                     f"the drop of the residual is significant{e(test)}, J<sub>ave</sub> falls by 10 %, the "
                     "verification error does not get worse beyond noise, and its parameters meet CR &le; 20 %, "
                     "I &le; 10 % (one poorly determined shape parameter may be fixed at its fitted value).</p>"
                     + "".join(blocks))
    return "".join(parts)


def _factor_text(f: dict) -> str:
    if f.get("kind") == "second":
        return f"[{f.get('zeta', float('nan')):.3g}, {f.get('omega', float('nan')):.3g}]"
    if f.get("kind") == "first":
        return f"(1/T = {f.get('inverse_time_constant', float('nan')):.3g})"
    return str(f.get("kind", ""))
