"""``report.json``, ``report.html`` and plots for ``livesweep identify`` (docs/outputs.md, report.json)."""

from __future__ import annotations

import datetime
import html
import json
import os
import re
import tempfile
from pathlib import Path

from livesweep import __version__
from livesweep.errors import ConfigError
from livesweep.numeric import finite_or_none
from livesweep.report.export import (RESPONSES_CSV, RESPONSES_MAT, gain_units, polynomials, state_space_export,
                                     write_responses_csv, write_responses_mat)
from livesweep.report.chart import bode_chart, residual_chart, time_history_chart
from livesweep.report.html import render as render_html
from livesweep.report.svg import to_svg
from livesweep.report.units import parameter_units
from livesweep.stages.live_models import live_models_section

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
    """``plots/<stem>.svg`` with ``stem`` made a plain file name (characters other than letters,
    digits, ``_ . -`` become ``_``; no leading dot; at most 100 characters) and unique among
    ``taken`` (``_2``, ``_3`` ... appended), whatever the signal names: a plot never lands
    outside ``plots/`` nor overwrites another plot."""
    safe = _UNSAFE_FILE_CHARS.sub("_", stem).lstrip(".")[:100] or "_"
    name, k = safe, 1
    while name in taken:
        k += 1
        name = f"{safe}_{k}"
    taken.add(name)
    return f"plots/{name}.svg"


def _write_svg(chart, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(to_svg(chart), encoding="utf-8")


def _atomic_write(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".partial")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)       # mkstemp makes 0600; a report is for others to read too
    os.replace(tmp, path)


def write_report(identification, out_dir, *, plots: bool = True) -> Path:
    """Write an :class:`~livesweep.stages.identify.Identification` to a folder; nothing in it changes.

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
                                  live_models=getattr(i, "live_models", None), plots=plots)


def write_frequency_report(stage, out_dir, *, transfer_functions=None, state_space=None, verification=None,
                           residual=None, live_models=None, plots: bool = True) -> Path:
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
    live_models : LiveModels, optional
        The models the live monitor recorded for the records' test points
        (:func:`livesweep.stages.live_models.read_live_models`): ``live_models`` in the JSON, each
        pair beside the transfer function of the same pair and structure; an empty list without.
    """
    out = prepare_out_dir(out_dir)
    case, an = stage.case, stage.analysis
    best = an.best
    units = {n: s.units for n, s in case.signals.items()}
    responses, taken = [], set()
    draw = plots
    tf_fits = list(transfer_functions.fits) if transfer_functions is not None else []
    ss_fit = state_space.fit if state_space is not None else None
    final_fit = residual.final if residual is not None and residual.final is not None else ss_fit
    changed = final_fit is not ss_fit
    for pair in best.pairs():
        ordinary = an.siso.pair(pair.output, pair.input) if best.conditioned else None
        rel = _plot_rel(f"{pair.output}_{pair.input}", taken)
        models, band = [], None
        for f in tf_fits:
            if (f.output, f.input) == (pair.output, pair.input):
                models.append((f"TF {f.name} (J {f.cost:.0f})", pair.omega, f.response(pair.omega), True, 3))
                band = f.band_rad_s, f"fit band of TF {f.name}"
        if changed:        # the model the report signs drawn solid, the one before the loop dashed beside it
            models += _ss_curves(final_fit, pair, "final model", dashed=False, colour=4)
            models += _ss_curves(ss_fit, pair, "before the residual loop", colour=5)
        elif ss_fit is not None:
            models += _ss_curves(ss_fit, pair, "state space", colour=4)
        if draw:
            _write_svg(bode_chart(pair, title=f"{case.name}: {pair.output} / {pair.input}",
                                  units=(units.get(pair.output, ""), units.get(pair.input, "")), ordinary=ordinary,
                                  models=models, fit_band_rad_s=band[0] if band else None,
                                  fit_band_label=band[1] if band else None,
                                  min_coherence=case.criteria.min_coherence), out / rel)
        responses.append({**pair.to_dict(), "output_units": units.get(pair.output, ""),
                          "input_units": units.get(pair.input, ""), "plot": rel if draw else None})
    report = {
        "livesweep_version": __version__,
        "generated_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC"),
        "case": {"name": case.name, "aircraft": case.aircraft, "condition": case.condition, "path": str(case.path)},
        "inputs": _inputs(case, stage),
        "stages": ["frequency-response"],
        "frequency_responses": responses,
        "spectral_settings": best.settings,
        "criteria": case.criteria.to_dict(),
        "data_quality": {**stage.data_quality, "notes": list(stage.data_quality["notes"])},   # a copy: stages stay as computed
    }
    stages = report["stages"]
    if transfer_functions is not None:
        stages.append("transfer-functions")
        report["transfer_functions"] = [{**f.to_dict(), "gain_units": gain_units(f, units),
                                         "polynomials": polynomials(f),
                                         "handling_qualities": _handling(transfer_functions, f, final_fit,
                                                                         ss_fit if changed else None, best, units)}
                                        for f in tf_fits]
        report["data_quality"]["notes"] += list(transfer_functions.notes)
    report["live_models"] = live_models_section(live_models, tf_fits)
    if live_models is not None:
        report["data_quality"]["notes"] += list(live_models.notes)
    if ss_fit is not None:
        stages.append("state-space")
        report["state_space"] = _model_dict(ss_fit, case.tables["state_space"], units)
        report["data_quality"]["notes"] += list(state_space.notes)
    if verification is not None:
        stages.append("verification")
        records = []
        for k, (label, v) in enumerate(verification.results):
            rel = _plot_rel(f"verification_{k}", taken) if draw else None
            if draw:
                _write_svg(time_history_chart(v.t_s, v.measured, v.predicted, v.inputs, [o.name for o in v.outputs],
                                              [o.units for o in v.outputs], list(verification.inputs),
                                              title=f"{case.name}: verification, {label}",
                                              tic=[o.tic for o in v.outputs]), out / rel)
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
            report["residual_loop"]["parameter_units"] = parameter_units(residual.loop.table, units)
        after = []
        for k, (label, v) in enumerate(residual.verification_after):
            rel = _plot_rel(f"residual_verification_{k}", taken) if draw else None
            if draw:
                _write_svg(time_history_chart(v.t_s, v.measured, v.predicted, v.inputs, [o.name for o in v.outputs],
                                              [o.units for o in v.outputs], list(residual.loop.fit.model.inputs),
                                              title=f"{case.name}: verification after the residual loop, {label}",
                                              tic=[o.tic for o in v.outputs]), out / rel)
            after.append({"label": label, "j_rms": finite_or_none(v.j_rms), "plot": rel,
                          "tic": {o.name: finite_or_none(o.tic) for o in v.outputs}})
        report["residual_loop"]["verification_final"] = after
    if best.conditioned:
        report["frequency_responses_ordinary"] = [p.to_dict() for p in an.siso.pairs()]
        report["multiple_coherence"] = {o: best.multiple_coherence[k].tolist() for k, o in enumerate(best.outputs)}
        report["ill_conditioned"] = best.ill_conditioned.astype(bool).tolist()
    save_response_set(best, out / RESPONSE_SET_FILE)
    report["frequency_response_set"] = RESPONSE_SET_FILE
    if ss_fit is not None:
        report["model"] = _final_model(report, residual if changed else None, final_fit, units)
    write_responses_csv(best, out / RESPONSES_CSV, units)
    write_responses_mat(best, out / RESPONSES_MAT, units, final_fit)
    report["exports"] = {"csv": RESPONSES_CSV, "mat": RESPONSES_MAT}
    if best.conditioned:
        save_response_set(an.siso, out / ("ordinary_" + RESPONSE_SET_FILE))
    _remove_stale_plots(out, taken if draw else set())
    if residual is None or not residual.loop.added:
        (out / "augmented_case.toml").unlink(missing_ok=True)          # an earlier run's, not this one's
    path = out / "report.json"
    _atomic_write(path, json.dumps(report, indent=1, allow_nan=False))
    _atomic_write(out / "report.html", _embed_images(render_html(report), out))
    return path


def _ss_curves(fit, pair, label: str, dashed: bool = True, colour: int = 4) -> list:
    """The Bode overlay of a state-space fit on ``pair`` (none when the model lacks the pair)."""
    m = fit.model
    if pair.output not in m.outputs or pair.input not in m.inputs:
        return []
    T = fit.frequency_response(pair.omega)[list(m.outputs).index(pair.output), list(m.inputs).index(pair.input)]
    j = next((c for o, i, c in fit.cost_pairs if (o, i) == (pair.output, pair.input)), None)
    return [(label + (f" (J {j:.0f})" if j is not None else ""), pair.omega, T, dashed, colour)]


def _handling(stage, tf, final_fit, before_fit, best, units) -> dict | None:
    """The handling-qualities figures of a transfer function's pair: measured and fitted (the
    stage's), and of the state-space model the report signs (``model``) and, when the residual
    loop changed it, of the model before the loop (``model_before_loop``)."""
    from livesweep.stages.parametric import handling_qualities

    h = (stage.handling or {}).get(tf.name)
    if h is None:
        return None
    h = dict(h)
    resp = best.pair(tf.output, tf.input)
    for key, fit in (("model", final_fit), ("model_before_loop", before_fit)):
        if fit is None or tf.output not in fit.model.outputs or tf.input not in fit.model.inputs:
            continue
        T = fit.frequency_response(resp.omega)[list(fit.model.outputs).index(tf.output),
                                               list(fit.model.inputs).index(tf.input)]
        h[key] = handling_qualities(resp.omega, T, output_units=units.get(tf.output, ""))
    return h


def _model_dict(fit, table: dict, units: dict) -> dict:
    """A state-space fit as ``report.json`` carries it: parameters, cost, matrices, units, named modes."""
    from livesweep.ident.modes import name_modes

    m = fit.matrices()
    try:
        named = [mode.to_dict() for mode in name_modes(m["A"], m["states"], units=dict(table.get("units") or {}))]
    except ValueError:        # a matrix with non-finite entries: the eigenvalues say it (n/a modes)
        named = []
    return {**fit.to_dict(), "matrices": state_space_export(fit, units),
            "parameter_units": parameter_units(table, units),
            "state_units": dict(table.get("units") or {}), "modes": named}


def _final_model(report: dict, residual, final_fit, units: dict) -> dict:
    """``report.json``'s ``model``: the model the report signs. It is the residual loop's when the
    loop added effects (judged on the state-space stage's points), else the state-space stage's.
    ``before_loop`` names the section holding the model before the loop, with its J_ave and
    verification, so the two compare on the same frequency points."""
    from livesweep.ident.cost import N_OMEGA

    ss = report["state_space"]
    ver = [{"label": r["label"], "j_rms": r["j_rms"], "tic": {o["name"]: o["tic"] for o in r["outputs"]}}
           for r in (report.get("verification") or {}).get("records", [])]
    if residual is None:
        return {"source": "state-space", "label": "state space", "effects_added": [], "points_per_pair": N_OMEGA,
                **ss, "verification": ver, "before_loop": None}
    added = [{"kind": e["kind"], "where": e["where"]} for e in residual.loop.added]
    rl = report["residual_loop"]
    return {"source": "residual-loop",
            "label": "state space + " + ", ".join(f"{a['kind']} at {a['where']}" for a in added),
            "effects_added": added, "points_per_pair": N_OMEGA,
            **_model_dict(final_fit, residual.loop.table, units),
            "verification": [{k: r[k] for k in ("label", "j_rms", "tic")} for r in rl.get("verification_final", [])],
            "before_loop": {"section": "state_space", "cost_average": ss["cost"]["average"], "verification": ver}}


def _inputs(case, stage) -> list[dict]:
    """The logs the report rests on: role, label, file, SHA-256, size and the slice used."""
    from livesweep.convert.common import sha256_of

    rows = []
    for role, records in (("identify", case.identify), ("verify", case.verify)):
        for rec in records:
            path = Path(rec.log)
            ok = path.is_file()
            rows.append({"role": role, "label": rec.label or path.name, "log": str(path), "name": path.name,
                         "sha256": sha256_of(path) if ok else None, "bytes": path.stat().st_size if ok else None,
                         "start_s": rec.start_s, "end_s": rec.end_s})
    return rows


def _remove_stale_plots(out: Path, written: set[str]) -> None:
    """Delete plots this report did not write: an earlier run's into the same folder, and any PNG
    (earlier livesweep versions drew the report's plots as PNGs)."""
    for f in (out / "plots").iterdir() if (out / "plots").is_dir() else ():
        if f.suffix in (".svg", ".png") and (f.suffix == ".png" or f.stem not in written):
            f.unlink(missing_ok=True)


def _residual_section(case, loop, out: Path, taken: set[str], draw: bool = True) -> dict:
    from livesweep.report.case_file import write_augmented_case

    from livesweep.ident.residual import N_OMEGA_LOOP

    d = {**loop.to_dict(), "points_per_pair": N_OMEGA_LOOP}
    for k, (step, sd) in enumerate(zip(loop.steps, d["steps"])):
        rel = _plot_rel(f"residual_step_{k + 1}", taken) if draw else None
        what = (f"added {step.effect['kind']} at {step.effect['where']}" if step.effect else "nothing added")
        if draw:
            _write_svg(residual_chart(step.residuals_before, step.residuals_after,
                                      title=f"{case.name}: residual loop step {k + 1} ({what})"), out / rel)
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


def _embed_images(page: str, out: Path) -> str:
    """Make the page self-contained: every ``src="plots/...svg"`` becomes a base64 data URI."""
    import base64

    def data_uri(m):
        path = out / html.unescape(m.group(1))
        if not path.is_file():
            return m.group(0)
        return 'src="data:image/svg+xml;base64,' + base64.b64encode(path.read_bytes()).decode() + '"'

    return re.sub(r'src="(plots/[^"]+\.svg)"', data_uri, page)
