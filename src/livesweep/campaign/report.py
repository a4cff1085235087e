"""One HTML page for a whole campaign: its test points, their responses overlaid, their parameters.

:func:`write_campaign_report` reads the ``/livesweep/model`` records of the campaign's recordings
(the monitor's fit of each closed test point, docs/outputs.md) and writes ``campaign.html``, self
contained (inline SVG drawn by :mod:`livesweep.report.svg`, the look of ``report.html``):

1. a table of the flights and their test points;
2. per pair (``output/input``), the recorded responses of its test points overlaid on one Bode
   plot (one colour per test point, "flight k TPn"; the fitted model dashed in the same colour);
   test points without a recorded model are listed as "no response recorded";
3. per pair, each parameter and figure with its +/- Cramer-Rao bound against a condition (or the
   test-point order), as small scatter plots, and a table of the values as recorded.

Examples
--------
>>> import livesweep.campaign                                                       # doctest: +SKIP
>>> from livesweep.campaign.report import write_campaign_report                     # doctest: +SKIP
>>> with livesweep.campaign.open("flights.db") as c:                                # doctest: +SKIP
...     write_campaign_report(c, "out", swept_input="roll")
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["write_campaign_report", "TestPointModel", "collect_models", "START_TOLERANCE_S"]

#: A ``/livesweep/model`` record belongs to a test point whose ``start_s`` is within this [s] of its own.
START_TOLERANCE_S = 0.05

e = html.escape


@dataclass
class TestPointModel:
    """A campaign test point and the model recorded for it (``pairs`` empty when none).

    Attributes
    ----------
    row : TestPointRow
    label : str
        ``"flight k TPn"``.
    pairs : list of dict
        The record's ``pairs`` (name, parameters, figures, curve, ...), as recorded.
    note : str
        Why there is no model ("no response recorded", the log not readable ...).
    """

    __test__ = False

    row: object
    label: str
    pairs: list = field(default_factory=list)
    note: str = ""


def _read_models(path: str) -> tuple[list, str]:
    """(model dicts with raw ``pairs``, note) of one recording; never raises for its content."""
    from livesweep.errors import LogFormatError
    from livesweep.stages.live_models import MODEL_TOPIC, parse_model
    from livesweep.telemetry.mcap_log import read_messages

    try:
        messages = list(read_messages(path, topics=MODEL_TOPIC))
    except (LogFormatError, OSError, ValueError) as exc:
        return [], f"models not read: {exc}"
    out = []
    for m in messages:
        try:
            parse_model(m.data)                          # checks the keys; the curve is taken as recorded
        except ValueError:
            continue
        out.append(m.data)
    return out, ""


def collect_models(campaign, *, swept_input=None) -> list[TestPointModel]:
    """Each test point of ``campaign`` (of ``swept_input`` if given) with its recorded model.

    Parameters
    ----------
    campaign : Campaign
    swept_input : str, optional

    Returns
    -------
    list of TestPointModel
        In flight then number order. A record matches the test point of the same flight whose
        ``start_s`` is within :data:`START_TOLERANCE_S`.
    """
    cache: dict[str, tuple] = {}
    out = []
    for row in campaign.test_points(swept_input=swept_input):
        label = f"flight {row.flight_id} TP{row.number}"
        if row.flight_path not in cache:
            cache[row.flight_path] = _read_models(row.flight_path)
        records, note = cache[row.flight_path]
        match = [d for d in records if row.start_s is not None
                 and abs(float(d["test_point"]["start_s"]) - row.start_s) <= START_TOLERANCE_S]
        pairs = [p for p in match[0]["pairs"] if isinstance(p.get("curve"), dict)] if match else []
        out.append(TestPointModel(row, label, pairs, "" if pairs else (note or "no response recorded")))
    return out


def _arr(curve: dict, key: str) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in curve.get(key) or []], float)


def _bode_svg(pair: str, items: list) -> str:
    """Magnitude, phase and coherence of one pair, each test point (label, curve) one colour."""
    from livesweep.report.chart import Chart, HLine, Line, Panel, color
    from livesweep.report.svg import to_svg

    mag, ph, coh = [], [], []
    ref = None                                  # (omega, phase) of the first curve: the phase branch
    for k, (label, c) in enumerate(items):
        w, m, p = _arr(c, "omega_rad_s"), _arr(c, "magnitude_db"), _arr(c, "phase_deg")
        mm, mp, g = _arr(c, "model_magnitude_db"), _arr(c, "model_phase_deg"), _arr(c, "coherence")
        ok = np.isfinite(w) & np.isfinite(p) & (w > 0)
        if ref is None and ok.any():
            ref = (w[ok], p[ok])
        elif ref is not None and ok.any():      # the same branch as the first curve: no 360 deg jumps
            at = np.interp(np.log(w[ok][0]), np.log(ref[0]), ref[1])
            shift = 360.0 * np.round((at - p[ok][0]) / 360.0)
            p, mp = p + shift, mp + shift
        col = color(k)
        mag.append(Line(w, m, col, 1.6, label=label))
        ph.append(Line(w, p, col, 1.6))
        if mm.size == w.size:
            mag.append(Line(w, mm, col, 1.0, dashed=True, alpha=0.8))
            ph.append(Line(w, mp, col, 1.0, dashed=True, alpha=0.8))
        if g.size == w.size:
            coh.append(Line(w, g, col, 1.2))
    p_mag = Panel(lines=tuple(mag), y_label=f"|{pair}| [dB]", legend="lower left", x_tick_labels=False,
                  note="solid: recorded response, dashed: fitted model")
    p_ph = Panel(lines=tuple(ph), y_label="phase [deg]", x_tick_labels=False, y_angle=True)
    p_coh = Panel(lines=tuple(coh), hlines=(HLine(0.6, dashed=True),), y_limits=(0.0, 1.05), y_label="γ²",
                  x_label="frequency [rad/s]")
    return to_svg(Chart(rows=((p_mag,), (p_ph,), (p_coh,)), title=f"{pair}: recorded responses",
                        size_in=(7.5, 7.0), height_ratios=(3.0, 3.0, 1.4)))


def _scatter_svg(name: str, units: str, xlabel: str, pts: list, order: bool) -> str:
    """One quantity against x: a square per value and its +/- Cramer-Rao bar (``pts``: (x, v, cr, k));
    ``order``: x is the test-point order (integer tick labels)."""
    from livesweep.report.chart import Chart, Line, Panel, color
    from livesweep.report.svg import PT_PER_IN, TICK_FONT, linear_ticks, to_svg

    xs = np.array([p[0] for p in pts], float)
    lo, hi = float(xs.min()), float(xs.max())
    pad = 0.5 if order else (0.1 * (hi - lo) if hi > lo else max(0.1 * abs(lo), 0.5))
    lo, hi = lo - pad, hi + pad
    d = 0.02 * (hi - lo)
    lines = []
    for x, v, cr, k in pts:
        c = color(k)
        if cr is not None and np.isfinite(cr):
            lines.append(Line(np.array([x, x, np.nan, x - d, x + d, np.nan, x - d, x + d]),
                              np.array([v - cr, v + cr, np.nan, v - cr, v - cr, np.nan, v + cr, v + cr]), c, 1.2))
        lines.append(Line(np.array([x - d, x + d]), np.array([v, v]), c, 7.0))
    lines.append(Line(np.array([lo, hi]), np.full(2, np.nan), "#000"))     # the x range
    panel = Panel(lines=tuple(lines), log_x=False, y_label=f"{name}{f' [{units}]' if units else ''}",
                  x_label=xlabel, label_size=9.0, x_tick_labels=False)
    size, margins = (3.6, 2.6), (0.24, 0.95, 0.87, 0.2)
    svg = to_svg(Chart(rows=((panel,),), title=name, size_in=size, margins=margins, title_size=10.0))
    W, H = size[0] * PT_PER_IN, size[1] * PT_PER_IN
    x0, x1, yb = margins[0] * W, margins[1] * W, (1 - margins[3]) * H
    ticks = np.arange(np.ceil(lo), np.floor(hi) + 1) if order else linear_ticks(lo, hi, target=4)
    labels = "".join(f'<text x="{x0 + (t - lo) / (hi - lo) * (x1 - x0):.1f}" y="{yb + TICK_FONT + 3:.1f}" '
                     f'font-size="{TICK_FONT}" text-anchor="middle">{t:g}</text>' for t in ticks if lo <= t <= hi)
    return svg.replace("</svg>", labels + "</svg>")


def _fmt(v, cr=None, units="") -> str:
    if v is None:
        return "–"
    text = f"{v:.4g}" + (f" ± {cr:.2g}" if cr is not None else "")
    return text + (f" {units}" if units else "")


def _conditions_text(row) -> str:
    return ", ".join(f"{k} {v:g}" if isinstance(v, (int, float)) else f"{k} {v}" for k, v in row.conditions
                     if v is not None)


def _table(tps: list, flights: dict) -> str:
    head = ("flight", "TP", "input", "axis", "source", "verdict", "start–end [s]", "conditions", "response")
    rows = []
    for t in tps:
        r = t.row
        verdict = r.verdict or "–"
        cls = "pass" if verdict == "GO" else "flag" if verdict == "NO-GO" else ""
        span = "–" if r.start_s is None else f"{r.start_s:.1f}–{r.end_s:.1f}"
        resp = ", ".join(p.get("name", "?") for p in t.pairs) or t.note
        cells = (f"{r.flight_id} <span class='hash'>{e(Path(r.flight_path).name)}</span>", str(r.number),
                 e(r.swept_input or "–"), "–" if r.axis is None else str(r.axis), e(r.source),
                 f"<span class='{cls}'>{e(verdict)}</span>", span, e(_conditions_text(r)), e(resp))
        rows.append(f"<tr data-tp='{e(t.label)}'>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    fl = "".join(f"<tr><td>{f.id}</td><td class='hash'>{e(f.sha256[:12])}</td><td>{e(f.format)}</td>"
                 f"<td>{e(f.vehicle or '–')}</td><td>{e(f.date or '–')}</td><td>{f.test_points}</td>"
                 f"<td>{e(f.path)}</td></tr>" for f in flights.values())
    return ("<h2>Flights</h2><table><tr><th>flight</th><th>sha256</th><th>format</th><th>vehicle</th><th>date</th>"
            f"<th>test points</th><th>path</th></tr>{fl}</table>"
            "<h2>Test points</h2><table><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>"
            + "".join(rows) + "</table>")


def _quantities(pair: str, items: list, condition: str | None) -> str:
    """The scatter plots and the table of one pair's parameters and figures (``items``: (k, tp, pair dict))."""
    use = condition is not None and any(t.row.condition(condition) is not None for _, t, _ in items)
    xlabel = condition if use else "test point (order)"
    xs, missing = {}, []
    for n, (k, t, _) in enumerate(items):
        x = t.row.condition(condition) if use else n + 1
        if x is None:
            missing.append(t.label)
        else:
            xs[k] = float(x)
    names = []
    for _, _, p in items:
        for kind in ("parameters", "figures"):
            for q in p.get(kind) or []:
                if (q.get("name"), q.get("units", "")) not in names:
                    names.append((q.get("name"), q.get("units", "")))
    figs, rows = [], []
    for name, units in names:
        pts, cells = [], []
        for n, (k, t, p) in enumerate(items):          # colour n: the test point's on the Bode plot
            q = next((q for kind in ("parameters", "figures") for q in p.get(kind) or [] if q.get("name") == name),
                     None)
            v, cr = (q or {}).get("value"), (q or {}).get("cramer_rao")
            cells.append(f"<td class='num'>{e(_fmt(v, cr))}</td>")
            if v is not None and k in xs:
                pts.append((xs[k], float(v), None if cr is None else float(cr), n))
        rows.append(f"<tr><td>{e(name)}</td><td>{e(units)}</td>" + "".join(cells) + "</tr>")
        if pts:
            figs.append(f"<figure data-quantity='{e(name)}'>{_scatter_svg(name, units, xlabel, pts, not use)}</figure>")
        else:
            figs.append(f"<p class='info'>{e(name)}: not determined in any test point.</p>")
    head = "".join(f"<th>{e(t.label)}{'' if use else f' ({n + 1})'}</th>" for n, (_, t, _) in enumerate(items))
    note = (f"<p class='info'>without {e(condition)}: {e(', '.join(missing))}</p>" if missing else "")
    if condition is not None and not use:
        note += f"<p class='info'>no test point of {e(pair)} has the condition {e(condition)}: test-point order.</p>"
    return (f"<h3>{e(pair)}: identified quantities against {e(xlabel)}</h3>{note}<div>{''.join(figs)}</div>"
            f"<table><tr><th>quantity</th><th>units</th>{head}</tr>{''.join(rows)}</table>")


def write_campaign_report(campaign, out_dir, *, swept_input=None, condition=None) -> Path:
    """Write ``campaign.html`` for the campaign's test points.

    Parameters
    ----------
    campaign : Campaign
        An open campaign (:func:`livesweep.campaign.open`).
    out_dir : str or Path
        Folder (created when missing).
    swept_input : str, optional
        Only the test points of this swept input.
    condition : str, optional
        The test-point condition (``test_point.conditions``) the identified quantities are plotted
        against; None, or a condition no test point of a pair has: their order in the campaign.

    Returns
    -------
    Path
        The page written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tps = collect_models(campaign, swept_input=swept_input)
    flights = {f.id: f for f in campaign.flights() if swept_input is None
               or any(t.row.flight_id == f.id for t in tps)}
    by_pair: dict[str, list] = {}
    for k, t in enumerate(tps):
        for p in t.pairs:
            by_pair.setdefault(p.get("name", "?"), []).append((k, t, p))
    body = [f"<h1>Campaign {e(Path(str(getattr(campaign, 'path', '') or '')).name or '')}</h1>",
            f"<p class='sub'>{len(flights)} flight(s), {len(tps)} test point(s)"
            + (f" of {e(swept_input)}" if swept_input else "") + f", {len(by_pair)} modelled pair(s)</p>",
            _table(tps, flights), "<h2>Responses</h2>"]
    if not by_pair:
        body.append("<p class='info'>No test point has a recorded response (/livesweep/model).</p>")
    for pair, items in by_pair.items():
        inputs = sorted({t.row.swept_input or "–" for _, t, _ in items})
        body.append(f"<h3>{e(pair)} <span class='info'>(swept input {e(', '.join(inputs))})</span></h3>")
        body.append(f"<figure data-pair='{e(pair)}'>{_bode_svg(pair, [(t.label, p['curve']) for _, t, p in items])}"
                    "</figure>")
        without = [t.label for t in tps if t.row.swept_input in inputs and not t.pairs]
        if without:
            body.append(f"<p class='info'>no response recorded: {e(', '.join(without))}</p>")
    if by_pair:
        body.append("<h2>Identified quantities</h2>")
        body += [_quantities(pair, items, condition) for pair, items in by_pair.items()]
    from livesweep.report.html import _CSS

    page = out / "campaign.html"
    page.write_text("<!DOCTYPE html><html><head><meta charset='utf-8'><title>livesweep campaign</title>"
                    f"<style>{_CSS}</style></head><body>{''.join(body)}</body></html>", encoding="utf-8")
    return page
