"""``report.html``: the report of one identification as an engineering document.

A first screen with the case, the date, the livesweep version, the input logs (SHA-256) and a
summary of every stage with its flags against the method's guidelines
(:func:`livesweep.report.summary.stage_summary`); then data quality, frequency responses,
transfer functions, the models the live monitor recorded in flight beside them ("In flight"),
state-space derivatives with units, the mode table, time-domain verification, the residual loop,
and a methods appendix so the document stands alone. Printable
(a print stylesheet). Rendered from the ``report.json`` dictionary only.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

from livesweep.report.summary import GUIDELINES, cr_text, guidelines, modes, report_criteria, stage_summary
from livesweep.spectral.criteria import DEFAULT_CRITERIA

__all__ = ["render"]

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;max-width:1200px;margin:0 auto;padding:0 16px;
color:#1a1a1a;line-height:1.4}
h1{margin-bottom:0}h2{border-bottom:2px solid #334;padding-bottom:2px;margin-top:32px}
.sub{color:#555;margin-top:2px}
table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #bbb;padding:3px 8px;vertical-align:top}
th{background:#eef0f4;text-align:left}td.num{text-align:right;font-variant-numeric:tabular-nums}
.pass{background:#e6f4ea}.flag{background:#fde2e1}.info{color:#555}
.badge{display:inline-block;padding:1px 8px;border-radius:10px;font-weight:600;font-size:90%}
.badge.pass{background:#2e7d32;color:#fff}.badge.flag{background:#c62828;color:#fff}
code{background:#f3f3f3;padding:0 3px}figure{display:inline-block;margin:6px;vertical-align:top}
figcaption{text-align:center;color:#444;font-size:90%}.hash{font-family:monospace;font-size:85%}
.appendix p,.appendix li{max-width:900px}
@media print{body{max-width:none;padding:0;font-size:10pt}h2{page-break-after:avoid}
table,figure,img{page-break-inside:avoid}img{max-width:100%;height:auto}a{color:inherit;text-decoration:none}
.noprint{display:none}}
"""

e = html.escape


def _num(x, spec: str = ".4g", none: str = "—") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return none
    text = format(x, spec)
    if text.lstrip("+-").strip("0.") == "" and text[0] in "+-":      # no "-0.000": a zero has no sign
        text = text[1:]
    return text


def _img(rel, width: int, alt: str) -> str:
    return f'<img src="{e(rel)}" width="{width}" alt="{e(alt)}">' if rel else ""


def _slice(r: dict) -> str:
    if r.get("start_s") is None and r.get("end_s") is None:
        return "whole log"
    return f"{_num(r.get('start_s'), '.1f', 'start')} to {_num(r.get('end_s'), '.1f', 'end')} s"


def _first_screen(report: dict, summary: list[dict]) -> str:
    c = report["case"]
    sp = report.get("spectral_settings") or {}
    logs = "".join(
        f"<tr><td>{e(r['role'])}</td><td>{e(r['label'])}</td><td>{e(r['name'])}</td>"
        f"<td class='hash' title='{e(r['sha256'] or '')}'>{e((r['sha256'] or 'missing')[:16])}</td>"
        f"<td class='num'>{_num(r['bytes'] / 1e6 if r['bytes'] else None, '.2f')}</td>"
        f"<td>{e(_slice(r))}</td></tr>"
        for r in report.get("inputs") or [])
    rows = []
    for s in summary:
        items = "".join(f"<li>{e(f)}</li>" for f in s["flags"]) + "".join(
            f"<li class='info'>{e(i)}</li>" for i in s["info"])
        rows.append(f"<tr class='{s['status']}'><td><b>{e(s['stage'])}</b></td>"
                    f"<td><span class='badge {s['status']}'>{'PASS' if s['status'] == 'pass' else 'FLAG'}</span></td>"
                    f"<td>{e(s['result'])}{'<ul>' + items + '</ul>' if items else ''}</td></tr>")
    n_flag = sum(s["status"] == "flag" for s in summary)
    verdict = ("every stage meets the guidelines" if not n_flag else
               f"{n_flag} of {len(summary)} stages flagged: read the flags before using the model")
    band = sp.get("band_rad_s") or []
    settings = (f"band {band[0]:g}-{band[1]:g} rad/s, " if len(band) == 2 else "") + (
        f"windows {', '.join(f'{w:g}' for w in sp.get('windows_s') or [])} s, {sp.get('sample_rate_hz', 0):g} Hz, "
        f"overlap {100 * sp.get('overlap', 0):.0f} %")
    return f"""<h1>{e(c['name'])}</h1>
<p class="sub">{e(c['aircraft'])} — {e(c['condition'])}</p>
<table><tr><th>case file</th><td><code>{e(c['path'])}</code></td></tr>
<tr><th>generated</th><td>{e(report.get('generated_utc', ''))} by livesweep {e(report['livesweep_version'])}</td></tr>
<tr><th>spectral settings</th><td>{e(settings)}</td></tr></table>
<h2 id="summary">Summary: {e(verdict)}</h2>
<table><tr><th>stage</th><th></th><th>result and flags (guidelines in <a href="#appendix">the appendix</a>)</th></tr>
{''.join(rows)}</table>
<h3>Input logs</h3><table><tr><th>role</th><th>label</th><th>file</th><th>SHA-256 (first 16)</th><th>MB</th>
<th>time slice</th></tr>{logs}</table>"""


def _data_quality(report: dict) -> str:
    dq = report["data_quality"]
    g = guidelines(report)
    rows = []
    for ex in dq["excitation"]:
        band = ex["widest_band_rad_s"]
        ok = ex["fraction_of_band"] >= g["coverage"]
        rows.append(f"<tr class='{'pass' if ok else 'flag'}'><td>{e(ex['output'])}/{e(ex['input'])}</td>"
                    f"<td class='num'>{100 * ex['fraction_of_band']:.0f} %</td>"
                    f"<td>{'%.2f – %.2f' % tuple(band) if band else 'none'}</td>"
                    f"<td class='num'>{_num(ex['median_coherence'], '.2f')}</td></tr>")
    checks = []
    for c in dq["kinematic_checks"]:
        if "error" in c:
            checks.append(f"<tr class='flag'><td>{e(c.get('measured', ''))}</td><td colspan='4'>not run: "
                          f"{e(c['error'])}</td></tr>")
            continue
        checks.append(f"<tr class='{'pass' if c.get('passed') else 'flag'}'><td>{e(c['name'])}</td>"
                      f"<td class='num'>{_num(c.get('scale_factor_error'), '+.3f')}</td>"
                      f"<td class='num'>{_num(1000 * c['skew_s'] if c.get('skew_s') is not None else None, '+.0f')}</td>"
                      f"<td class='num'>{_num(c.get('rate_bias'), '+.3f')} {e(c.get('rate_bias_units', ''))}</td>"
                      f"<td>{'pass' if c.get('passed') else 'FAIL'}</td></tr>")
    repairs = []
    for name, r in (dq.get("repairs") or {}).items():
        done = {k: v for k, v in r.items() if v}
        if done:
            repairs.append(f"<li>{e(name)}: " + e(", ".join(f"{k.replace('_', ' ')} {v}" for k, v in done.items()))
                           + "</li>")
    for name, w in (dq.get("wild_points") or {}).items():
        if w.get("replaced"):
            repairs.append(f"<li>{e(name)}: {w['replaced']} wild point(s) replaced ({e(w.get('method', ''))})</li>")
    notes = "".join(f"<li>{e(n)}</li>" for n in dq.get("notes") or [])
    return (f"<h2 id='data'>Data quality</h2><p>{_num(dq.get('duration_s'), '.0f')} s of data at "
            f"{_num(dq.get('sample_rate_hz'), 'g')} Hz. A frequency point is adequate when γ² ≥ {g['coherence']} and "
            f"ε<sub>r</sub> ≤ {g['random_error']}; a pair is flagged below {100 * g['coverage']:.0f} % of the band.</p>"
            "<table><tr><th>pair</th><th>adequate</th><th>widest adequate band [rad/s]</th><th>median γ²</th></tr>"
            + "".join(rows) + "</table>"
            + ("<h3>Kinematic consistency</h3><table><tr><th>check</th><th>scale error</th><th>skew [ms]</th>"
               "<th>rate bias</th><th></th></tr>" + "".join(checks) + "</table>" if checks else "")
            + f"<h3>Repairs</h3><ul>{''.join(repairs) or '<li>none</li>'}</ul>"
            + (f"<h3>Notes</h3><ul>{notes}</ul>" if notes else ""))


def _responses(report: dict) -> str:
    figs = "".join(f"<figure>{_img(r['plot'], 560, r['output'] + '/' + r['input'])}<figcaption>{e(r['output'])}/"
                   f"{e(r['input'])} [{e(r.get('output_units', ''))}/{e(r.get('input_units', ''))}]</figcaption></figure>"
                   for r in report["frequency_responses"] if r.get("plot"))
    cond = any(r.get("conditioned") for r in report["frequency_responses"])
    return ("<h2 id='responses'>Frequency responses</h2><p>Composite of the windows in the summary"
            + ("; conditioned on the other inputs (MISO): partial coherence, the ordinary (SISO) estimate thin" if cond
               else "") + f". Points with γ² below {guidelines(report)['coherence']:g} are drawn faint and left out of the axis "
            "limits; the band shows ±1 random error. Data: <code>frequency_response_set.json</code>, "
            "<code>frequency_responses.csv</code>, <code>frequency_responses.mat</code>.</p>"
            + (figs or "<p>Plots were not written (<code>--no-plots</code>).</p>"))


def _factor_text(f: dict) -> str:
    if f.get("kind") == "second":
        return f"[ζ {_num(f.get('zeta'), '.3g')}, ω {_num(f.get('omega'), '.3g')} rad/s]"
    if f.get("kind") == "first":
        return f"(1/T {_num(f.get('inverse_time_constant'), '.3g')} rad/s)"
    if f.get("kind") == "s":
        return f"s^{f.get('power', 1)}" if f.get("power", 1) != 1 else "s"
    return str(f.get("kind", ""))


def _ms(seconds):
    return None if seconds is None else 1000.0 * seconds


def _transfer_functions(report: dict) -> str:
    tfs = report.get("transfer_functions") or []
    if not tfs:
        return ""
    g = GUIDELINES
    rows = []
    for t in tfs:
        num = [_factor_text(f) for f in t.get("factors", []) if f.get("where") == "numerator"]
        den = [_factor_text(f) for f in t.get("factors", []) if f.get("where") == "denominator"]
        crs = ", ".join(f"{k} {cr_text(v)}" for k, v in (t.get("cramer_rao_pct") or {}).items())
        bad_cr = any(v is None or v > g["cramer_rao_pct"] for v in (t.get("cramer_rao_pct") or {}).values())
        band = t.get("band_rad_s") or []
        rows.append(f"<tr><td>{e(t['name'])}</td><td>{e(t['output'])}/{e(t['input'])}</td>"
                    f"<td class='num'>{_num(t['gain'])}</td><td>{e(t.get('gain_units') or '')}</td>"
                    f"<td>{e(' '.join(num) or '1')}</td><td>{e(' '.join(den) or '1')}"
                    f"</td><td class='num'>{_num(1000 * t['delay_s'] if t.get('delay_s') is not None else None, '.1f')}</td>"
                    f"<td>{'%.2f – %.2f' % tuple(band) if len(band) == 2 else ''}</td>"
                    f"<td class='num {'flag' if t['cost'] is None or t['cost'] > g['cost_tf'] else ''}'>"
                    f"{_num(t['cost'], '.1f')}</td>"
                    f"<td class='{'flag' if bad_cr else ''}'>{e(crs)}</td></tr>")
    hq = []
    sources = [("measured", "measured"), ("fitted", "TF fit"), ("model", "state-space model"),
               ("model_before_loop", "model before the residual loop")]
    if any((t.get("handling_qualities") or {}).get("model_before_loop") for t in tfs):
        sources[2] = ("model", "final model")
    shown = [(k, label) for k, label in sources if any((t.get("handling_qualities") or {}).get(k) for t in tfs)]
    for t in tfs:
        h = t.get("handling_qualities") or {}
        if not any(h.get(k) for k, _ in shown):
            continue
        resp = next((h[k].get("response") for k, _ in shown if h.get(k)), "")
        cells = "".join(f"<td class='num'>{_num((h.get(k) or {}).get('bandwidth_rad_s'), '.3g')}</td>"
                        f"<td class='num'>{_num(_ms((h.get(k) or {}).get('phase_delay_s')), '.0f')}</td>"
                        for k, _ in shown)
        hq.append(f"<tr><td>{e(t['name'])}</td><td>{e(resp or '')}</td>{cells}</tr>")
    hq_head = "".join(f"<th>ω<sub>BW</sub> {e(label)} [rad/s]</th><th>τ<sub>p</sub> {e(label)} [ms]</th>"
                      for _, label in shown)
    return ("<h2 id='tf'>Transfer functions</h2><p>T(s) = K · numerator / denominator · e<sup>−τs</sup>; "
            "first-order factors (s + 1/T), second-order [ζ, ω] = s² + 2ζωs + ω². Guidelines: J ≤ 100 "
            "(≤ 50 excellent), Cramér–Rao bounds ≤ 20 % of the value (<a href='#appendix'>appendix</a>). "
            "Polynomials: <code>report.json</code>.</p>"
            "<table><tr><th>name</th><th>pair</th><th>K</th><th>K units</th><th>numerator</th><th>denominator</th>"
            "<th>τ [ms]</th>"
            "<th>band [rad/s]</th><th>J</th><th>CR [%]</th></tr>" + "".join(rows) + "</table>"
            + ("<h3>Handling-qualities parameters</h3><table><tr><th>name</th><th>response</th>" + hq_head
               + "</tr>" + "".join(hq) + "</table>" if hq else ""))


def _pm_text(v: dict | None, spec: str = ".4g") -> str:
    """``value ± bound units`` of a recorded value (``n/a`` without a value)."""
    if not v or v.get("value") is None:
        return "n/a"
    bound = "" if v.get("cramer_rao") is None else f" ± {_num(v['cramer_rao'], '.2g')}"
    return f"{_num(v['value'], spec)}{bound} {v.get('units') or ''}".rstrip()


def _band_text(band) -> str:
    return "%.3g – %.3g" % tuple(band) if band and len(band) == 2 and None not in band else "—"


def _live_structure(p: dict) -> str:
    """K · numerator / denominator · e^(−τs) of a live pair, in the shorthand."""
    names = {v["name"] for v in p.get("parameters") or []}
    delay = " · e<sup>−τs</sup>" if "tau" in names else ""
    num = f" · {e(p['numerator'])}" if p.get("numerator") else ""
    return f"K{num} / {e(p.get('denominator') or '1')}{delay}"


def _live_comparison(p: dict, report: dict) -> str:
    """The parameters of one live pair: in flight, and beside the identification's when compared."""
    c = p.get("comparison")
    if c is None:
        rows = "".join(f"<tr><td>{e(v['name'])}</td><td class='num'>{_num(v['value'], '.4g')}</td>"
                       f"<td class='num'>{_num(v['cramer_rao'], '.2g')}</td><td>{e(v.get('units') or '')}</td>"
                       f"<td class='{'flag' if v.get('flags') else ''}'>{e('; '.join(v.get('flags') or ()))}</td></tr>"
                       for v in p.get("parameters") or [])
        return ("<table><tr><th>parameter</th><th>in flight</th><th>CR</th><th>units</th><th>flags</th></tr>"
                + rows + "</table>")
    tf = next((t for t in report.get("transfer_functions") or [] if t["name"] == c["transfer_function"]), {})
    rows = []
    for q in c["parameters"]:
        units = (tf.get("gain_units") or "") if q["name"] == "gain" else q.get("units") or ""
        name = q["name"] if q["offline_name"] == q["name"] else f"{q['name']} ({q['offline_name']})"
        bad = q.get("agrees") is False
        rows.append(f"<tr><td>{e(name)}</td><td>{e(units)}</td>"
                    f"<td class='num'>{_num(q['live_value'], '.4g')}</td>"
                    f"<td class='num'>{_num(q['live_cramer_rao'], '.2g')}</td>"
                    f"<td class='num'>{_num(q['offline_value'], '.4g')}</td>"
                    f"<td class='num'>{_num(q['offline_cramer_rao'], '.2g')}</td>"
                    f"<td class='num'>{_num(q['difference'], '+.3g')}</td>"
                    f"<td class='num {'flag' if bad else 'pass' if q.get('agrees') else ''}'>"
                    f"{_num(q['bounds'], '+.2g')}</td>"
                    "</tr>")
    rows.append(f"<tr class='info'><td>band [rad/s]</td><td></td>"
                f"<td colspan='2'>{_band_text(c['live_band_rad_s'])}</td>"
                f"<td colspan='2'>{_band_text(c['offline_band_rad_s'])}</td><td colspan='2'></td></tr>"
                f"<tr class='info'><td>J</td><td></td><td colspan='2' class='num'>{_num(c['live_cost'], '.1f')}</td>"
                f"<td colspan='2' class='num'>{_num(c['offline_cost'], '.1f')}</td><td colspan='2'></td></tr>")
    return ("<table><tr><th>parameter</th><th>units</th><th>in flight</th><th>CR</th>"
            f"<th>identify, TF {e(c['transfer_function'])}</th><th>CR</th><th>difference</th>"
            "<th>in combined bounds</th></tr>" + "".join(rows) + "</table>")


def _in_flight(report: dict) -> str:
    """Each test point's model as the live monitor recorded it, and beside it the transfer function
    of the same pair and structure this identification fitted."""
    from livesweep.stages.live_models import AGREE_BOUNDS, MIN_OVERLAP

    live = report.get("live_models") or []
    if not live:
        return ""
    blocks = []
    for m in live:
        tp = m["test_point"]
        what = (f"{e(str(tp.get('swept_input') or 'input'))} swept " if tp.get("swept_input") else "")
        head = (f"<h3>Test point {e(str(tp.get('number', '?')))}: {what}{_num(tp['start_s'], '.1f')} – "
                f"{_num(tp['end_s'], '.1f')} s" + (f" ({e(str(tp['source']))})" if tp.get("source") else "")
                + (f", verdict {e(str(tp['verdict']))}" if tp.get("verdict") else "") + "</h3>")
        name = Path(m["log"]).name
        where = (f"<p class='info'>Recorded in <code>{e(name)}</code>"
                 + (f" (record {e(m['record'])})" if m.get("record") and m["record"] != name else "")
                 + f"; {100 * m['overlap']:.0f} % of the test point inside the record's slice."
                 + (" Conditions: " + e(", ".join(f"{k} {_num(v, '.4g')}" for k, v in tp["conditions"].items()))
                    + "." if tp.get("conditions") else "") + "</p>")
        breaches = ("<ul>" + "".join(f"<li class='flag'>{e(b)}</li>" for b in m["breaches"]) + "</ul>"
                    if m.get("breaches") else "")
        rows = []
        for p in m["pairs"]:
            figs = ", ".join(f"{e(f['name'])} {e(_pm_text(f, '.3g'))}" for f in p.get("figures") or []
                             if f.get("value") is not None)
            flags = list(p.get("flags") or []) + [c["text"] for c in p.get("limits") or [] if not c.get("ok", True)]
            cmp = p.get("comparison")
            if cmp is not None:
                verdict = ("agrees" if cmp.get("agrees") else "differs" if cmp.get("agrees") is False else "no bounds")
                against = (f"TF {e(cmp['transfer_function'])}: {verdict}"
                           + (f" (largest difference {_num(cmp['max_bounds'], '.2g')} combined bounds)"
                              if cmp.get("max_bounds") is not None else ""))
                cls = "flag" if cmp.get("agrees") is False else "pass" if cmp.get("agrees") else ""
            else:
                against, cls = f"not compared: {e(p.get('not_compared') or '')}", "info"
            bad_cost = p.get("cost") is None or p["cost"] > GUIDELINES["cost_tf"]
            rows.append(f"<tr><td>{e(p['name'])}</td><td>{e(p.get('structure') or '')}</td>"
                        f"<td style='white-space:nowrap'>{_live_structure(p)}</td>"
                        f"<td>{_band_text(p.get('band_rad_s'))}</td>"
                        f"<td class='num {'flag' if bad_cost else ''}'>{_num(p.get('cost'), '.1f')}</td>"
                        f"<td>{figs or '—'}</td><td class='{'flag' if flags else ''}'>{e('; '.join(flags))}</td>"
                        f"<td class='{cls}'>{against}</td></tr>")
        table = ("<table><tr><th>pair</th><th>structure</th><th>model</th><th>band [rad/s]</th><th>J</th>"
                 "<th>figures</th><th>flags</th><th>the full identification</th></tr>" + "".join(rows) + "</table>")
        params = "".join(f"<h4>{e(p['name'])}: parameters"
                         + (f" in flight and in TF {e(p['comparison']['transfer_function'])}" if p.get("comparison")
                            else " in flight") + "</h4>" + _live_comparison(p, report) for p in m["pairs"])
        skipped = ("<p class='info'>Not modelled in flight: " + e("; ".join(m["skipped"])) + "</p>"
                   if m.get("skipped") else "")
        blocks.append(head + where + breaches + table + params + skipped)
    return ("<h2 id='inflight'>In flight: the models of the test points</h2><p>The live monitor fitted each closed "
            "test point on its own samples and recorded the model on <code>/livesweep/model</code>; those of the test "
            f"points lying for more than {100 * MIN_OVERLAP:.0f} % inside an identify record are shown here. "
            "Where this identification fits a transfer function of the same pair and structure, each parameter "
            "stands beside it: the difference (in flight − identify) and that difference in units of the combined "
            "Cramér–Rao bound "
            f"√(CR<sub>flight</sub>² + CR<sub>identify</sub>²); beyond {AGREE_BOUNDS:g} bounds it is flagged (the "
            "identification resamples the log itself, so the two are independent routes to the same numbers).</p>"
            + "".join(blocks))


def _parameter_table(params, units, removed=(), before=None) -> str:
    """Parameters with value, units, CR and I; with ``before`` (the parameters of the model before
    the residual loop) two more columns give their value and CR there."""
    g = GUIDELINES
    prior = {p["name"]: p for p in before or ()}
    rows = []
    for p in params:
        cr, ins = p.get("cramer_rao_pct"), p.get("insensitivity_pct")
        status = ("fixed (removed in structure reduction)" if p["name"] in removed else
                  "fixed" if p["fixed"] else "")
        bad_cr = not p["fixed"] and (cr is None or cr > g["cramer_rao_pct"])
        bad_i = not p["fixed"] and ins is not None and ins > g["insensitivity_pct"]
        unit = units.get(p["name"])
        extra = ""
        if before is not None:
            q = prior.get(p["name"])
            extra = ("<td class='num'>—</td><td>added by the loop</td>" if q is None else
                     f"<td class='num'>{_num(q['value'], '.5g')}</td>"
                     f"<td class='num'>{'fixed' if q['fixed'] else e(cr_text(q.get('cramer_rao_pct')))}</td>")
        rows.append(f"<tr><td>{e(p['name'])}</td><td class='num'>{_num(p['value'], '.5g')}</td>"
                    f"<td>{e(unit) if unit else '<i>see the model</i>'}</td><td>{e(status)}</td>"
                    f"<td class='num {'flag' if bad_cr else ''}'>{'' if p['fixed'] else e(cr_text(cr))}</td>"
                    f"<td class='num {'flag' if bad_i else ''}'>{'' if p['fixed'] else e(cr_text(ins))}</td>"
                    f"{extra}</tr>")
    head = "<th>before the loop</th><th>CR before [%]</th>" if before is not None else ""
    return ("<table><tr><th>parameter</th><th>value</th><th>units</th><th></th><th>CR [%]</th><th>I [%]</th>"
            + head + "</tr>" + "".join(rows) + "</table>")


def _mode_rows(section: dict) -> list[dict]:
    """The mode rows of a model section: named (``modes``) or, for a report without names, from
    the eigenvalues."""
    return section.get("modes") or modes(section.get("eigenvalues") or [])


def _mode_text(m: dict) -> str:
    if m["kind"] == "oscillatory":
        return f"ω<sub>n</sub> {_num(m['omega_n_rad_s'], '.3g')} rad/s, ζ {_num(m['zeta'], '.3f')}"
    if m.get("time_constant_s") is not None:
        return f"T {_num(m['time_constant_s'], '.3g')} s"
    if m.get("time_to_double_s") is not None:
        return f"doubles in {_num(m['time_to_double_s'], '.3g')} s"
    return _num(m["eigenvalue"][0], ".4g")


def _mode_table(rows, before=None) -> str:
    """The modes (named by their eigenvectors where the model's states allow); with ``before``
    (the modes of the model before the residual loop), each mode's nearest one there beside it."""
    out = []
    for m in rows:
        re_, im = m["eigenvalue"]
        lam = f"{re_:.4g} ± {im:.4g}j" if m["kind"] == "oscillatory" else f"{re_:.4g}"
        if m["kind"] == "oscillatory":
            what = (f"<td class='num'>{m['omega_n_rad_s']:.4g}</td><td class='num'>{m['zeta']:.3f}</td>"
                    f"<td class='num'>{m['period_s']:.3g}</td><td></td>")
        else:
            tc = m.get("time_constant_s")
            td = m.get("time_to_double_s")
            what = ("<td></td><td></td><td></td>"
                    f"<td class='num'>{_num(tc, '.3g') if tc is not None else ('doubles in ' + _num(td, '.3g') if td else '')}</td>")
        extra = ""
        if before is not None:      # the same name, else the nearest eigenvalue; added dynamics had none
            lam_c = complex(re_, im)
            same = [b for b in before if m.get("name") and b.get("name") == m["name"]]
            near = min(same or before, key=lambda b: abs(complex(*b["eigenvalue"]) - lam_c), default=None)
            extra = ("<td>— (added by the loop)</td>" if m.get("added_state") else "<td></td>" if near is None else
                     f"<td>{e(near.get('name') or near['kind'])}: {_mode_text(near)}</td>")
        out.append(f"<tr class='{'' if m['stable'] else 'flag'}'><td>{e(m.get('name') or m['kind'])}</td>"
                   f"<td class='num'>{e(lam)}</td>{what}<td>{'stable' if m['stable'] else 'unstable'}</td>{extra}</tr>")
    head = "<th>the mode before the loop</th>" if before is not None else ""
    return ("<table><tr><th>mode</th><th>eigenvalue [1/s]</th><th>ω<sub>n</sub> [rad/s]</th><th>ζ</th><th>period [s]</th>"
            "<th>time constant [s]</th><th></th>" + head + "</tr>" + "".join(out) + "</table>")


def _state_space(report: dict) -> str:
    pre = report.get("state_space")
    if not pre:
        return ""
    final = report.get("model") or {}
    looped = final.get("source") == "residual-loop"
    ss = final if looped else pre
    cost = ss["cost"]
    pairs = ", ".join(f"{c['output']}/{c['input']} {_num(c['cost'], '.0f')}" for c in cost["pairs"])
    su = ss.get("state_units") or {}
    m = ss.get("matrices") or {}
    states = ", ".join(f"{s} [{su.get(s, '?')}]" for s in m.get("states", []))
    ins = ", ".join(f"{n} [{u}]" for n, u in zip(m.get("inputs", []), m.get("input_units", [])))
    outs = ", ".join(f"{n} [{u}]" for n, u in zip(m.get("outputs", []), m.get("output_units", [])))
    missing = "" if su else (" <b>The case gives no units for the states</b> (<code>[state_space.units]</code>), so "
                             "derivatives are shown without units.")
    story = ""
    if looped:
        story = (f"<p><b>This is the final model: {e(final['label'])}</b>, as the residual loop left it "
                 f"(<a href='#residual'>residual loop</a>; <code>augmented_case.toml</code>). J<sub>ave</sub> "
                 f"{_num(pre['cost']['average'], '.2f')} before the loop → {_num(cost['average'], '.2f')} after it, both "
                 f"on the state-space stage's {final['points_per_pair']} points per pair. The columns “before the "
                 "loop” give the model the state-space stage identified, for comparison.</p>")
    title = "State-space model" + (f": final, {e(final['label'])}" if looped else "")
    return (f"<h2 id='ss'>{title}</h2>{story}<p>States {e(states)}; inputs {e(ins)}; outputs {e(outs)}.{missing} "
            f"J<sub>ave</sub> = {_num(cost['average'], '.2f')} (guideline ≤ {GUIDELINES['cost_ss']:.0f}); per pair: "
            f"{e(pairs)}. A derivative's units are those of its state's rate per unit of the state or input it "
            "multiplies. Flagged: CR &gt; 20 %, insensitivity &gt; 10 %. Matrices A, B, C, D: <code>report.json</code> "
            "and <code>frequency_responses.mat</code>.</p>"
            + _parameter_table(ss["parameters"], ss.get("parameter_units") or {}, ss.get("removed_parameters") or (),
                               before=pre["parameters"] if looped else None)
            + "<h3>Modes</h3><p>Named by their eigenvectors (the states that dominate each mode).</p>"
            + _mode_table(_mode_rows(ss), before=_mode_rows(pre) if looped else None))


def _verification(report: dict) -> str:
    ver = report.get("verification")
    if not ver:
        return ""
    g = GUIDELINES
    final = report.get("model") or {}
    after = {r["label"]: r for r in (report.get("residual_loop") or {}).get("verification_final", [])}
    if final.get("source") == "residual-loop" and after:
        return _verification_final(ver, after, final)
    blocks = []
    for r in ver["records"]:
        ok = r.get("passed")
        tics = "".join(f"<td class='num {'' if o['tic'] is not None and o['tic'] <= g['tic'] else 'flag'}'>"
                       f"{_num(o['tic'], '.3f')}</td>" for o in r["outputs"])
        head = "".join(f"<th>TIC {e(o['name'])}</th>" for o in r["outputs"])
        blocks.append(f"<h3>{e(r['label'])}: {'passes' if ok else 'FAILS'} the guidelines</h3>"
                      f"<table><tr><th>J<sub>rms</sub></th>{head}</tr><tr><td class='num "
                      f"{'' if r['j_rms'] is not None and r['j_rms'] <= g['j_rms'] else 'flag'}'>{_num(r['j_rms'], '.3f')}"
                      f"</td>{tics}</tr></table>" + _img(r.get("plot"), 760, "verification " + r["label"]))
    return ("<h2 id='verification'>Time-domain verification</h2><p>The identified model, no parameter changed, "
            "driven with the measured inputs of dissimilar manoeuvres; biases and reference shifts by least squares. "
            f"Guidelines: J<sub>rms</sub> ≤ {g['j_rms']:g}, TIC ≤ {g['tic']:g}.</p>" + "".join(blocks))


def _verification_final(ver: dict, after: dict, final: dict) -> str:
    """Verification when the residual loop changed the model: the final model's J_rms and TIC,
    the model before the loop's beside them, and the final model's time histories."""
    g = GUIDELINES

    def cell(v, limit):
        return f"<td class='num {'' if v is not None and v <= limit else 'flag'}'>{_num(v, '.3f')}</td>"

    blocks = []
    for r in ver["records"]:
        a = after.get(r["label"])
        if a is None:
            continue
        names = [o["name"] for o in r["outputs"]]
        head = "".join(f"<th>TIC {e(n)}</th>" for n in names)
        ok = (a["j_rms"] is not None and a["j_rms"] <= g["j_rms"]
              and all(a["tic"].get(n) is not None and a["tic"][n] <= g["tic"] for n in names))
        rows = (f"<tr><td>final model</td>{cell(a['j_rms'], g['j_rms'])}"
                + "".join(cell(a["tic"].get(n), g["tic"]) for n in names) + "</tr>"
                + f"<tr><td>before the residual loop</td>{cell(r['j_rms'], g['j_rms'])}"
                + "".join(cell(o["tic"], g["tic"]) for o in r["outputs"]) + "</tr>")
        blocks.append(f"<h3>{e(r['label'])}: the final model {'passes' if ok else 'FAILS'} the guidelines</h3>"
                      f"<table><tr><th>model</th><th>J<sub>rms</sub></th>{head}</tr>{rows}</table>"
                      + _img(a.get("plot"), 760, "verification of the final model " + r["label"])
                      + (f"<p class='info'>The model before the loop on the same record: <code>{e(r['plot'])}</code>.</p>"
                         if r.get("plot") else ""))
    return ("<h2 id='verification'>Time-domain verification</h2><p>The final model "
            f"({e(final['label'])}), no parameter changed, driven with the measured inputs of dissimilar manoeuvres; "
            "biases and reference shifts by least squares; the model before the residual loop beside it. "
            f"Guidelines: J<sub>rms</sub> ≤ {g['j_rms']:g}, TIC ≤ {g['tic']:g}.</p>" + "".join(blocks))


def _residual(report: dict) -> str:
    rl = report.get("residual_loop")
    if not rl:
        return ""
    from livesweep.ident.residual import effect_text, model_effects

    blocks = [f"<p><b>{e(rl['conclusion'])}</b> ({rl['re_identifications']} re-identifications)"
              + (f"; augmented case: <code>{e(rl['augmented_case'])}</code>" if rl.get("augmented_case") else "")
              + "</p>"]
    n_loop, ss, final = rl.get("points_per_pair"), report.get("state_space") or {}, report.get("model") or {}
    if n_loop and ss and final:
        blocks.append(
            f"<p>The loop refits the model on {n_loop} points per pair (the state-space stage fits "
            f"{final['points_per_pair']}: a lightly damped mode is narrower than their spacing), so the J<sub>ave</sub> "
            "of its steps are on those points. On the stage's points: "
            + (f"J<sub>ave</sub> {_num(ss['cost']['average'], '.2f')} before the loop, "
               f"{_num(final['cost']['average'], '.2f')} for the final model ({e(final['label'])}; "
               "<a href='#ss'>state-space model</a>).</p>" if final.get("source") == "residual-loop" else
               f"J<sub>ave</sub> {_num(ss['cost']['average'], '.2f')}, the model unchanged.</p>"))
    for k, st in enumerate(rl["steps"]):
        eff = st["effect"]
        cands = ", ".join(f"{c['kind']} at {c['where']} ({c['evidence']:.0f})" for c in st["candidates"][:4])
        vb, va = st.get("verification_before"), st.get("verification_after")
        ver = (f"; verification J<sub>rms</sub> {vb['j_rms']:.3f} → {va['j_rms']:.3f}" if vb and va else "")
        head = (f"added <b>{e(eff['kind'])}</b> at <b>{e(eff['where'])}</b>: {e(effect_text(eff).split(': ', 1)[1])}"
                if eff else "nothing added")
        tried = "".join(f"<li>{e(t['kind'])} at {e(t['where'])}"
                        + "".join(f" with {e(w['kind'])} at {e(w['where'])}" for w in t.get("with", ()))
                        + f": J<sub>ave</sub> {_num(t.get('cost_after'), '.2f')}; {e(t['reason'])}</li>"
                        for t in st["tried"])
        why = (f"The model had no path to the coherent pair(s) {e(', '.join(eff['gives_a_path_for']))} (skipped: no "
               f"residual to screen); each absent entry that gives one was refitted on every pair, the new one "
               f"included, and the lowest J<sub>ave</sub> within the guidelines kept."
               if eff and eff.get("gives_a_path_for") else f"Strongest candidates (evidence, noise units): {e(cands)}")
        on = f" (on {n_loop} points per pair)" if n_loop else ""
        blocks.append(f"<h3>Step {k + 1}: {head}</h3><p>J<sub>ave</sub> {st['cost_before']:.2f} → "
                      f"{st['cost_after']:.2f}{on}{ver}. {why}</p>"
                      + (f"<ul>{tried}</ul>" if tried else "") + _img(st.get("plot"), 1100, f"residual step {k + 1}"))
    if rl.get("parameter_units") and rl.get("augmented_case"):
        final = {p["name"]: p for e_ in model_effects(st["effect"] for st in rl["steps"]) for p in e_["parameters"]}
        if final:
            blocks.append("<h3>Parameters of the added effects</h3>" + _parameter_table(
                [{"name": n, "value": p["value"], "fixed": bool(p.get("fixed")), "cramer_rao_pct": p.get("cramer_rao_pct"),
                  "insensitivity_pct": p.get("insensitivity_pct")} for n, p in final.items()], rl["parameter_units"]))
    for r in rl.get("verification_final", []):
        blocks.append(f"<p>Time domain after the loop, {e(r['label'])}: J<sub>rms</sub> {_num(r['j_rms'], '.3f')} "
                      "(<a href='#verification'>time-domain verification</a>)</p>")
    unexplained = [u for u in rl.get("unexplained") or [] if "pair" in u]
    if unexplained:
        blocks.append("<p>Still above noise after the loop: " + e(", ".join(
            f"{u['pair']} ({u['rms_noise_units']} noise units rms)" for u in unexplained)) + "</p>")
    crit = rl.get("criterion") or {}
    test = (f" (an F-test counting its parameters and {crit['effective_points']:.0f} independent frequency values, "
            f"false-alarm probability {crit['false_alarm']:g} per step)") if crit else ""
    return ("<h2 id='residual'>Residual loop</h2><p>The model's residual against the data's random error, matched to a "
            "catalogue of effects the model may lack; the best-supported one is added and kept only when the drop of "
            f"the residual is significant{e(test)}, J<sub>ave</sub> falls by 10 %, the verification error does not get "
            "worse beyond noise, and its parameters meet the CR and insensitivity guidelines (one poorly determined "
            "shape parameter, or an effect's only parameter at least three Cramér–Rao bounds from zero, may be "
            "fixed at its fitted value and is marked so).</p>" + "".join(blocks))


_APPENDIX = """
<h2 id="appendix" class="appendix">Appendix: method and guidelines</h2><div class="appendix">
<p>livesweep follows the frequency-response method of Tischler &amp; Remple (<i>Aircraft and Rotorcraft System
Identification</i>, AIAA, 2006). The steps and the numbers this report tests:</p>
<ol>
<li><b>Data consistency.</b> Signals are resampled onto one uniform grid; gaps are excluded (not interpolated) from
spectral windows; wild points are replaced by a Hampel filter and counted; trims are removed. Where an attitude and
its rate are both logged, the attitude is compared with the integral of the rate for scale factor, time skew and
rate bias.</li>
<li><b>Frequency responses.</b> Each window length gives Hann-tapered, 80 % overlapped segments; auto- and
cross-spectra are averaged; the windows are combined into one composite estimate weighted by their random error.
With several inputs the responses are conditioned on the other inputs (MISO), with partial coherence. The random
error of a point is ε<sub>r</sub> = √(1 − γ²) / (|γ| √(2 n<sub>d</sub>)) with n<sub>d</sub> the effective number of
averages. A point is adequate when γ² ≥ {min_coherence:g} and ε<sub>r</sub> ≤ {max_random_error:g}{criteria_source}.</li>
<li><b>Transfer functions.</b> Gain, poles, zeros and delay minimise
J = (20/n<sub>ω</sub>) Σ W<sub>γ</sub> [(|T̂| − |T|)² + 0.01745 (∠T̂ − ∠T)²] (magnitude in dB, phase in deg,
W<sub>γ</sub> = [1.58 (1 − e<sup>−γ²</sup>)]², 20 points over the pair's coherent band). J ≤ 100 is acceptable,
J ≤ 50 excellent.</li>
<li><b>State-space derivatives.</b> The model's M, F, G, H, J and delays are fitted to every pair at once with the
same J (J<sub>ave</sub> over the pairs). Each parameter's Cramér–Rao bound (from the Hessian of J, as a % of its
value) should be ≤ 20 % and its insensitivity ≤ 10 %. Structure reduction removes, one at a time, the most
insensitive parameter (I &gt; 10 %), else the one with the largest bound (CR &gt; 20 %), and keeps a removal when
J<sub>ave</sub> rises by at most 2.</li>
<li><b>Time-domain verification.</b> The model, unchanged, is driven with the inputs of manoeuvres not used to
identify it. J<sub>rms</sub> (rms output error weighted as the fit weights the outputs) ≤ 2 and Theil's inequality
coefficient TIC ≤ 0.25 per output.</li>
<li><b>Residual loop.</b> The residual (data − model) of every pair, divided by the data's random error, is
matched to the signatures of missing effects (delays, actuators, notch filters, structural modes, sensor skews and
scale factors, missing derivatives). An effect is added only when an F-test on the whitened sums of squares,
counting its parameters and the independent frequency values, finds the drop significant.</li>
</ol>
<p>Flags in the summary: pairs adequate over less than half their band, failed kinematic checks, J above the
guideline, Cramér–Rao bounds above 20 % (beyond 1000 %: not identifiable, e.g. at a bound), insensitivity above
10 %, a second-order factor with ζ &gt; 2 (two real roots fitted as one pair) or a root a decade outside the fitted
band (degenerate fits), verification above its guidelines, and residual the catalogue cannot explain. Unstable
modes are shown, not flagged: many airframes are unstable without their flight control system.</p></div>
"""


def _appendix(report: dict) -> str:
    """The method appendix, stating the criteria that judged this report."""
    c = report_criteria(report)
    m = DEFAULT_CRITERIA
    source = "" if c == m else (f" (this case's [criteria]; the method's are γ² ≥ {m.min_coherence:g} and "
                                f"ε<sub>r</sub> ≤ {m.max_random_error:g})")
    return (_APPENDIX.replace("{min_coherence:g}", f"{c.min_coherence:g}")
            .replace("{max_random_error:g}", f"{c.max_random_error:g}").replace("{criteria_source}", source))


def render(report: dict) -> str:
    """The HTML of a ``report.json`` dictionary (plots referenced as ``plots/*.svg``)."""
    summary = stage_summary(report)
    toc = ("<p class='noprint'><a href='#summary'>summary</a> · <a href='#data'>data quality</a> · "
           "<a href='#responses'>frequency responses</a>" + (" · <a href='#tf'>transfer functions</a>"
                                                           if report.get("transfer_functions") else "")
           + (" · <a href='#inflight'>in flight</a>" if report.get("live_models") else "")
           + (" · <a href='#ss'>state space</a>" if report.get("state_space") else "")
           + (" · <a href='#verification'>verification</a>" if report.get("verification") else "")
           + (" · <a href='#residual'>residual loop</a>" if report.get("residual_loop") else "")
           + " · <a href='#appendix'>method</a></p>")
    body = (_first_screen(report, summary) + toc + _data_quality(report) + _responses(report)
            + _transfer_functions(report) + _in_flight(report) + _state_space(report) + _verification(report)
            + _residual(report)
            + _appendix(report))
    return (f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>livesweep: {e(report['case']['name'])}"
            f"</title><style>{_CSS}</style></head><body>{body}</body></html>")
