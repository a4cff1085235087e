"""``report.json``, ``report.html`` and plots for ``livesweep identify`` (DESIGN.md §4.3)."""

from __future__ import annotations

import html
import json
import os
import tempfile
from pathlib import Path

from livesweep import __version__
from livesweep.errors import ConfigError
from livesweep.report.plots import bode_plot

__all__ = ["write_frequency_report", "prepare_out_dir", "save_response_set", "load_response_set",
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


def _atomic_write(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".partial")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def write_frequency_report(stage, out_dir) -> Path:
    """Write the frequency-response stage's report; returns the path of ``report.json``."""
    out = prepare_out_dir(out_dir)
    case, an = stage.case, stage.analysis
    best = an.best
    units = {n: s.units for n, s in case.signals.items()}
    responses, plots = [], []
    for pair in best.pairs():
        ordinary = an.siso.pair(pair.output, pair.input) if best.conditioned else None
        rel = f"plots/{pair.output}_{pair.input}.png"
        bode_plot(pair, out / rel, title=f"{case.name}: {pair.output} / {pair.input}",
                  units=(units.get(pair.output, ""), units.get(pair.input, "")), ordinary=ordinary)
        responses.append({**pair.to_dict(), "output_units": units.get(pair.output, ""),
                          "input_units": units.get(pair.input, ""), "plot": rel})
        plots.append(rel)
    report = {
        "livesweep_version": __version__,
        "case": {"name": case.name, "aircraft": case.aircraft, "condition": case.condition, "path": str(case.path)},
        "stages": ["frequency-response"],
        "frequency_responses": responses,
        "spectral_settings": best.settings,
        "data_quality": stage.data_quality,
    }
    if best.conditioned:
        report["frequency_responses_ordinary"] = [p.to_dict() for p in an.siso.pairs()]
        report["multiple_coherence"] = {o: best.multiple_coherence[k].tolist() for k, o in enumerate(best.outputs)}
        report["ill_conditioned"] = best.ill_conditioned.astype(bool).tolist()
    save_response_set(best, out / RESPONSE_SET_FILE)
    report["frequency_response_set"] = RESPONSE_SET_FILE
    if best.conditioned:
        save_response_set(an.siso, out / ("ordinary_" + RESPONSE_SET_FILE))
    path = out / "report.json"
    _atomic_write(path, json.dumps(report, indent=1, allow_nan=False))
    _atomic_write(out / "report.html", _html(report))
    return path


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
    imgs = "".join(f'<figure><img src="{e(r["plot"])}" width="600"><figcaption>{e(r["output"])}/{e(r["input"])}'
                   f'</figcaption></figure>' for r in report["frequency_responses"])
    c = report["case"]
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>livesweep: {e(c['name'])}</title>
<style>body{{font-family:sans-serif;max-width:1300px;margin:auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px}}figure{{display:inline-block;margin:4px}}</style></head><body>
<h1>{e(c['name'])}</h1><p>{e(c['aircraft'])} — {e(c['condition'])}; livesweep {e(report['livesweep_version'])}</p>
<h2>Excitation adequacy (γ² ≥ 0.6, ε ≤ 0.2)</h2><table><tr><th>pair</th><th>of band</th><th>widest band [rad/s]</th>
<th>median γ²</th></tr>{''.join(rows)}</table>
<h2>Kinematic consistency</h2><table><tr><th>check</th><th>scale error</th><th>skew [s]</th><th>rate bias</th><th></th></tr>
{checks}</table><h2>Notes</h2><ul>{notes}</ul><h2>Frequency responses</h2>{imgs}</body></html>"""
