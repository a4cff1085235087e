"""The "Model" tab of the Rerun view: the model of the last closed test point and its trend.

:class:`ModelPanel` draws each ``/livesweep/model`` record (docs/outputs.md; entity paths:
:mod:`.blueprint`) in place of the one before:

* **Bode plots**, one column per pair: |H| [dB] and phase [deg] against ``log10 omega`` in a
  display box per plot (a ``rr.Transform3D`` maps the data onto it, as in :mod:`.rerun_plots`):
  the data as points (grey where gamma^2 is below the criteria's threshold), the fitted model as
  a red line, the prediction as a dashed purple line, and a legend of those colours.
* **Numbers** (``model/summary``, markdown): the breaches first, then per pair its structure,
  band, J, each parameter and figure as ``value ± Cramér-Rao bound units`` (:func:`value_text`)
  with its flags, each limit with OK or do not proceed, and the pairs not modelled.
* **Trend**: ``model/trend`` (markdown), per pair a row per test point (values ± bounds, J) and
  the trend notes; ``model/trend_plot``, gain, tau and bandwidth (:func:`trend_quantities`)
  against the test-point number, each with its bound as an error bar.

The entities of the model before that a new one does not draw (a pair or quantity it lacks) get
an ``rr.Clear``; a recursive clear of the whole tab at the same time would also hide the new
display transforms (the viewer resolves transforms by time alone).
"""

from __future__ import annotations

import math

import numpy as np
import rerun as rr

from livesweep.monitor.blueprint import (
    MODEL_LEGEND_PATH, MODEL_LEGEND_Y, MODEL_SUMMARY_PATH, MODEL_TITLE_Y, MODEL_TREND_PATH, PLOT_MARGINS,
    TREND_COLUMNS, model_box, model_pair_path, model_trend_plot_path, trend_box,
)
from livesweep.monitor.freq_plot import (
    MAG_STEPS_DB, PHASE_STEPS_DEG, frequency_extent, log_ticks, tick_label, value_extent,
)
from livesweep.monitor.models import MOVED_BOUNDS
from livesweep.monitor.text import band_text, md_table, time_text
from livesweep.spectral.criteria import DEFAULT_CRITERIA

__all__ = ["ModelPanel", "model_markdown", "trend_markdown", "value_text", "trend_quantities",
           "DATA_COLOR", "MODEL_COLOR", "PREDICTION_COLOR"]

DATA_COLOR = (66, 146, 230, 255)
MODEL_COLOR = (220, 60, 50, 255)
PREDICTION_COLOR = (140, 70, 200, 255)
_MASKED_COLOR = (125, 125, 125, 200)
_GRID_COLOR = (205, 205, 205, 255)            # opaque: overlapping translucent lines darken unevenly
_LABEL_COLOR = (150, 150, 150, 120)
#: The viewer draws a label below its point: half a label's height [display units, at the default
#: layout], by which a label is anchored above what it names to be centred on it.
_LABEL_HALF = 17.0
_TITLE_COLOR = (40, 40, 40, 255)
_STRUCTURES = {"first order": "K / (s + 1/T) e^(−τs)", "second order": "K / [ζ, ωn] e^(−τs)"}
#: What the trend plots show first, each ``(record list, name)``; a structure without them shows
#: its first parameters instead, up to :data:`~.blueprint.TREND_COLUMNS` in all.
MAIN_QUANTITIES = (("parameters", "gain"), ("parameters", "tau"), ("figures", "bandwidth"))
_DO_NOT_PROCEED = ": do not proceed"
#: Dashes of a prediction line per plot width (each dash two steps of a uniform log-frequency grid
#: of three times as many points, then one step of gap).
_DASHES = 45


def _num(x) -> float:
    """A record's number as a float; NaN for None, text or anything not finite."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def _arr(values, n: int | None = None) -> np.ndarray:
    """A record's list of numbers (None: NaN) as float64, NaN-padded or cut to ``n`` points."""
    v = np.array([_num(x) for x in (values if isinstance(values, (list, tuple)) else ())], float)
    if n is not None and v.size != n:
        v = np.concatenate([v[:n], np.full(max(0, n - v.size), math.nan)])
    return v


def _dicts(items) -> list:
    return [x for x in (items if isinstance(items, (list, tuple)) else ()) if isinstance(x, dict)]


def value_text(value, cramer_rao=None, units: str = "") -> str:
    """``"75.63 ± 8.45 rad/s"``: a value (4 significant digits) with its Cramér-Rao bound (3
    digits, left out when None) and units; ``"n/a"`` for no value."""
    v, cr = _num(value), _num(cramer_rao)
    if math.isnan(v):
        return "n/a"
    text = f"{v:.4g}" + ("" if math.isnan(cr) else f" ± {cr:.3g}")
    return f"{text} {units}".rstrip() if units else text


def _values(row: dict, kind: str) -> dict:
    """name -> (value, bound) (NaN: none) of a trend row's ``parameters`` or ``figures``."""
    d = row.get(kind) if isinstance(row.get(kind), dict) else {}
    vbs = {str(k): list(vb) if isinstance(vb, (list, tuple)) else [vb] for k, vb in d.items()}
    return {k: (_num(vb[0] if vb else None), _num(vb[1] if len(vb) > 1 else None)) for k, vb in vbs.items()}


def _have(rows: list) -> list[tuple[str, str]]:
    """``(kind, name)`` of every parameter, then figure, with a value in some row, in first-seen order."""
    return [(kind, k) for kind in ("parameters", "figures")
            for k in dict.fromkeys(k for r in rows for k, (v, _) in _values(r, kind).items() if not math.isnan(v))]


def _io(pair: dict) -> tuple[str, str]:
    o, i = pair.get("output"), pair.get("input")
    if o is None or i is None:
        o, _, i = str(pair.get("name") or pair.get("pair") or "?").partition("/")
    return str(o), str(i)


# ------------------------------------------------------------------------------------------ text


def _tp_title(tp: dict) -> str:
    if not tp:
        return "Model"
    label = tp.get("label") or tp.get("verdict") or "?"
    what = f"{tp.get('swept_input') or 'an input'} swept {time_text(tp.get('start_s'))} – {time_text(tp.get('end_s'))}"
    return f"Test point {tp.get('number', '?')}: {label} ({what}, {tp.get('source') or 'unknown source'})"


def _values_table(head: str, items: list) -> list[str]:
    rows = [[f.get("name", "?"), value_text(f.get("value"), f.get("cramer_rao"), f.get("units") or ""),
             "; ".join(map(str, f.get("flags") or ())) or "—"] for f in items]
    return md_table([head, "value ± Cramér-Rao bound", "flags"], rows) + [""] if rows else []


def _pair_markdown(p: dict) -> list[str]:
    structure = p.get("structure") or "?"
    form = _STRUCTURES.get(structure) or f"K {p.get('numerator') or '1'} / {p.get('denominator') or '1'} e^(−τs)"
    fit = f"band {band_text(p.get('band_rad_s'))} rad/s, J {value_text(p.get('cost'))}"
    if p.get("converged") is False:
        fit += ", **not converged**"
    out = [f"#### {p.get('name') or '/'.join(_io(p))}: {structure}, {form}", "", fit, ""]
    out += [f"- ⚠ {f}" for f in p.get("flags") or ()] + ([""] if p.get("flags") else [])
    out += _values_table("parameter", _dicts(p.get("parameters")))
    out += _values_table("figure", _dicts(p.get("figures")))
    limits = _dicts(p.get("limits"))
    out += ["Limits:", ""] if limits else []
    for c in limits:
        text = str(c.get("text") or c.get("name") or "?")
        text = text[:-len(_DO_NOT_PROCEED)] if text.endswith(_DO_NOT_PROCEED) else text
        out.append(f"- {'OK' if c.get('ok') else '**do not proceed**'}: {text}")
    return out + [""]


def model_markdown(record: dict) -> str:
    """The numbers of a ``/livesweep/model`` record as markdown: its breaches in bold first, then
    per pair the structure, band, J, parameters and figures (value ± bound, flags) and limits, then
    the pairs not modelled. Any optional part may be missing."""
    out = []
    breaches = [str(b) for b in record.get("breaches") or ()]
    if breaches:
        out += ["## Do not proceed", ""] + [f"- **{b}**" for b in breaches] + [""]
    out += [f"### {_tp_title(record.get('test_point') or {})}", ""]
    pairs = _dicts(record.get("pairs"))
    for p in pairs:
        out += _pair_markdown(p)
    if not pairs:
        out += ["No pair of this test point was modelled.", ""]
    skipped = [str(s) for s in record.get("skipped") or ()]
    if skipped:
        out += ["**Not modelled:**", ""] + [f"- {s}" for s in skipped]
    return "\n".join(out).rstrip() + "\n"


def _units(record: dict) -> dict:
    """pair name -> value name -> units, from the record's pairs."""
    return {p.get("name"): {f.get("name"): f.get("units") or "" for f in
                            _dicts(p.get("parameters")) + _dicts(p.get("figures"))} for p in _dicts(record.get("pairs"))}


def trend_markdown(record: dict) -> str:
    """The trend of a ``/livesweep/model`` record as markdown: per pair one row per test point
    (the map's conditions averaged over it, value ± bound of each parameter and figure that has a
    value, J), then the trend notes."""
    units, out = _units(record), []
    trend = [t for t in _dicts(record.get("trend")) if _dicts(t.get("rows"))]
    for t in trend:
        rows, name = _dicts(t.get("rows")), t.get("pair") or "?"
        cols, u = _have(rows), units.get(name, {})
        conds = list(dict.fromkeys(k for r in rows if isinstance(r.get("conditions"), dict) for k in r["conditions"]))
        head = ["TP", "start", "verdict"] + conds + [f"{k} [{u[k]}]" if u.get(k) else k for _, k in cols] + ["J"]
        body = [[r.get("test_point", "?"), time_text(r.get("start_s")), r.get("verdict") or "?"]
                + [value_text((r.get("conditions") or {}).get(c)) for c in conds]
                + [value_text(*_values(r, kind).get(k, (None, None))) for kind, k in cols]
                + [value_text(r.get("cost"))] for r in rows]
        out += [f"#### {name}", ""] + md_table(head, body) + [""]
    if not trend:
        out += ["No model yet.", ""]
    notes = [str(n) for n in record.get("trend_notes") or ()]
    if notes:
        out += ["**Moved:**", ""] + [f"- {n}" for n in notes]
    elif any(len(_dicts(t.get("rows"))) > 1 for t in trend):
        out.append(f"No parameter moved by more than {MOVED_BOUNDS:g} times its combined bound since the test "
                   "point before.")
    return "\n".join(out).rstrip() + "\n"


def trend_quantities(rows: list) -> list[tuple[str, str]]:
    """``(record list, name)`` of the values the trend plots show for a pair's trend ``rows``:
    those of :data:`MAIN_QUANTITIES` present, then the other parameters, at most
    :data:`~.blueprint.TREND_COLUMNS`."""
    have = _have(rows)
    main = [q for q in MAIN_QUANTITIES if q in have]
    rest = [q for q in have if q[0] == "parameters" and q not in main]
    return (main + rest)[:TREND_COLUMNS]


# ------------------------------------------------------------------------------------------ plots


def _frame(log, path: str, box: tuple, xr: tuple, yr: tuple, xticks: list, yticks: list, label: str) -> None:
    """With ``log(path, *archetypes)``: the transform of ``path`` mapping the data box ``xr`` x
    ``yr`` onto the display box ``box`` (x, y, width, height; y down), and at ``path/grid`` the
    box's edges, the grid lines and tick labels (``(value, text)`` each) and ``label`` above it."""
    (x0, x1), (y0, y1) = xr, yr
    bx, by, w, h = box
    sx, sy = w / (x1 - x0), h / (y1 - y0)
    log(path, rr.Transform3D(translation=[bx - x0 * sx, by + y1 * sy, 0.0], scale=[sx, -sy, 1.0]))
    left, _, top, bottom = PLOT_MARGINS
    xs, ys = {x0, x1} | {x for x, _ in xticks}, {y0, y1} | {y for y, _ in yticks}
    lines = [[[x, y0], [x, y1]] for x in sorted(xs)] + [[[x0, y], [x1, y]] for y in sorted(ys)]
    pts = [[x, y0 - 0.4 * bottom / sy] for x, _ in xticks]
    pts += [[x0 - 0.5 * left / sx, y + _LABEL_HALF / sy] for y, _ in yticks]
    pts.append([0.5 * (x0 + x1), y1 + 0.5 * top / sy])
    labels = [t for _, t in xticks] + [t for _, t in yticks] + [label]
    log(f"{path}/grid", rr.LineStrips2D(lines, colors=[_GRID_COLOR], radii=rr.Radius.ui_points(0.5), draw_order=5.0),
        rr.Points2D(pts, labels=labels, show_labels=True, radii=0.0,
                    colors=[_LABEL_COLOR] * (len(pts) - 1) + [_TITLE_COLOR], draw_order=6.0))


def _ticks(y0: float, y1: float, step: float) -> list[tuple[float, str]]:
    """``(value, label)`` of every multiple of ``step`` from ``y0`` to ``y1``."""
    return [(y0 + k * step, tick_label(round(y0 + k * step, 12))) for k in range(int(round((y1 - y0) / step)) + 1)]


def _runs(ok: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in ``ok``."""
    d = np.diff(np.concatenate(([0], ok.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _strips(x: np.ndarray, y: np.ndarray) -> list:
    """The finite stretches of a curve (at least two points each) as line strips."""
    return [np.column_stack([x[a:b], y[a:b]]) for a, b in _runs(np.isfinite(x) & np.isfinite(y)) if b - a > 1]


def _dashes(x: np.ndarray, y: np.ndarray, dx: float) -> list:
    """A curve as dashes on a uniform grid of step ``dx`` in x: two steps drawn, one left out."""
    out = []
    for s in _strips(x, y):
        xs = np.linspace(s[0, 0], s[-1, 0], max(3, int(math.ceil((s[-1, 0] - s[0, 0]) / dx)) + 1))
        ys = np.interp(xs, s[:, 0], s[:, 1])
        out += [np.column_stack([xs[k:k + 3], ys[k:k + 3]]) for k in range(0, xs.size - 1, 3)]
    return [d for d in out if len(d) > 1]


def _nearest_turn(y: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``y`` [deg] moved by whole turns to lie on the branch of ``ref`` (by their median difference)."""
    d = y - ref
    if not np.isfinite(d).any():
        return y
    return y + 360.0 * round(float(np.nanmedian(d)) / -360.0)


def _draw_pair(log, p: dict, column: int, n: int, min_coherence: float) -> set[str]:
    """One pair's Bode column; which of ``"data"``, ``"masked"`` (data below the threshold),
    ``"model"`` and ``"prediction"`` it drew."""
    c = p.get("curve") if isinstance(p.get("curve"), dict) else {}
    w = _arr(c.get("omega_rad_s"))
    ok = np.isfinite(w) & (w > 0)
    if ok.sum() < 2:
        return set()
    x = np.where(ok, np.log10(np.where(ok, w, 1.0)), math.nan)
    xr = frequency_extent(w[ok])
    ticks = log_ticks(*xr)
    unit = " rad/s" if n == 1 else ""              # narrower columns: the view's title gives the unit
    xticks = [(t, tick_label(10.0 ** t) + (unit if k == len(ticks) - 1 else "")) for k, (t, _) in enumerate(ticks)]
    coh = _arr(c.get("coherence"), w.size)
    good = np.isnan(coh) | (coh >= min_coherence)          # a point without a coherence is drawn as data
    path = model_pair_path(*_io(p))
    drawn = set()
    for kind, key, steps, label in (("magnitude", "magnitude_db", MAG_STEPS_DB, "|H| [dB]"),
                                    ("phase", "phase_deg", PHASE_STEPS_DEG, "phase [deg]")):
        data, model, pred = (_arr(c.get(k), w.size) for k in (key, f"model_{key}", f"predicted_{key}"))
        if kind == "phase":
            model, pred = _nearest_turn(model, data), _nearest_turn(pred, data)
        need = np.concatenate([data[good & ok], model[ok], pred[ok]])
        need = need[np.isfinite(need)]
        if need.size == 0:
            continue
        y0, y1, step = value_extent(None, float(need.min()), float(need.max()), steps)
        sub = f"{path}/{key}"
        _frame(log, sub, model_box(kind, column, n), xr, (y0, y1), xticks, _ticks(y0, y1, step), label)
        shown = ok & np.isfinite(data) & (data >= y0) & (data <= y1)
        if shown.any():
            drawn |= {"data" if g else "masked" for g in good[shown]}
            log(f"{sub}/data", rr.Points2D(np.column_stack([x[shown], data[shown]]), radii=rr.Radius.ui_points(2.5),
                                           colors=[DATA_COLOR if g else _MASKED_COLOR for g in good[shown]],
                                           draw_order=20.0))
        if strips := _strips(x, model):
            drawn.add("model")
            log(f"{sub}/model", rr.LineStrips2D(strips, colors=[MODEL_COLOR], radii=rr.Radius.ui_points(1.75),
                                                draw_order=22.0))
        if dashes := _dashes(x, pred, (xr[1] - xr[0]) / (3 * _DASHES)):
            drawn.add("prediction")
            log(f"{sub}/prediction", rr.LineStrips2D(dashes, colors=[PREDICTION_COLOR], radii=rr.Radius.ui_points(1.5),
                                                     draw_order=21.0))
    bx, _, bw, _ = model_box("magnitude", column, n)
    title = f"{p.get('name') or '/'.join(_io(p))}: {p.get('structure') or '?'}, J {value_text(p.get('cost'))}"
    log(f"{path}/title", rr.Points2D([[bx + 0.5 * bw, MODEL_TITLE_Y]], labels=[title], show_labels=True,
                                     radii=0.0, colors=[_TITLE_COLOR]))
    return drawn


def _legend(log, min_coherence: float, drawn: set[str]) -> None:
    """What the colours of the Bode plots are: a sample of each (a dot for the data, a line for
    the model and prediction) with its name beside it."""
    entries = [(text, color) for role, text, color in (
        ("data", "data", DATA_COLOR), ("masked", f"data, γ² < {min_coherence:g}", _MASKED_COLOR),
        ("model", "model (fit)", MODEL_COLOR), ("prediction", "prediction", PREDICTION_COLOR)) if role in drawn]
    if not entries:
        return
    y, x, dots, lines, pts = MODEL_LEGEND_Y, 0.0, [], [], []
    for text, color in entries:
        if color in (DATA_COLOR, _MASKED_COLOR):
            dots.append(([x + 18.0, y + _LABEL_HALF], color))
        else:
            lines.append(([[x, y + _LABEL_HALF], [x + 36.0, y + _LABEL_HALF]], color))
        pts.append([x + 50.0 + 4.5 * len(text), y])           # a character is about 9 display units wide
        x += 100.0 + 9.0 * len(text)
    log(MODEL_LEGEND_PATH, rr.Points2D(pts, labels=[t for t, _ in entries], show_labels=True,
                                       radii=0.0, colors=[_TITLE_COLOR]))
    if dots:
        log(f"{MODEL_LEGEND_PATH}/dots", rr.Points2D([d for d, _ in dots], colors=[c for _, c in dots],
                                                     radii=rr.Radius.ui_points(3.0), draw_order=22.0))
    if lines:
        log(f"{MODEL_LEGEND_PATH}/lines", rr.LineStrips2D([s for s, _ in lines], colors=[c for _, c in lines],
                                                          radii=rr.Radius.ui_points(1.75), draw_order=22.0))


def _nice_range(lo: float, hi: float, divisions: int) -> tuple[float, float, float]:
    """``(y0, y1, step)``: [lo, hi] padded, on multiples of a 1-2-5 step (:func:`value_extent`)."""
    span = hi - lo if hi - lo > 1e-9 * max(abs(lo), abs(hi)) else 0.2 * abs(hi) or 1.0
    m = 10.0 ** math.floor(math.log10(span / divisions))
    return value_extent(None, lo, hi, (m, 2 * m, 5 * m, 10 * m), max_divisions=divisions, min_span=span)


def _draw_trend(log, entry: dict, row: int, n_rows: int, io: tuple[str, str], units: dict) -> None:
    """One pair's row of trend plots: each quantity against the test-point number."""
    rows, name = _dicts(entry.get("rows")), entry.get("pair") or "/".join(io)
    for col, (kind, q) in enumerate(trend_quantities(rows)):
        vbs = [(_num(r.get("test_point")), *_values(r, kind).get(q, (math.nan, math.nan))) for r in rows]
        pts = [(tp, v, 0.0 if math.isnan(cr) else abs(cr)) for tp, v, cr in vbs if not math.isnan(tp + v)]
        if not pts:
            continue
        a = np.array(pts)
        xr = (float(a[:, 0].min()) - 0.5, float(a[:, 0].max()) + 0.5)
        every = max(1, math.ceil((xr[1] - xr[0]) / 8))
        xticks = [(float(t), f"TP{t}") for t in range(math.ceil(xr[0]), math.floor(xr[1]) + 1, every)]
        box = trend_box(row, col, n_rows)
        y0, y1, step = _nice_range(float((a[:, 1] - a[:, 2]).min()), float((a[:, 1] + a[:, 2]).max()),
                                   max(2, min(4, int(box[3] // 50))))      # a tick label every 50 display units at most
        path, u = model_trend_plot_path(*io, q), units.get(q) or ""
        _frame(log, path, box, xr, (y0, y1), xticks, _ticks(y0, y1, step), f"{name}: {q}" + (f" [{u}]" if u else ""))
        cap = 0.06 * (xr[1] - xr[0]) / max(1, len(pts)) ** 0.5
        bars = [[[t, v - e], [t, v + e]] for t, v, e in pts if e > 0]
        bars += [[[t - cap, v + s * e], [t + cap, v + s * e]] for t, v, e in pts if e > 0 for s in (-1.0, 1.0)]
        if bars:
            log(f"{path}/bounds", rr.LineStrips2D(bars, colors=[MODEL_COLOR], radii=rr.Radius.ui_points(1.0),
                                                  draw_order=21.0))
        if len(pts) > 1:
            log(f"{path}/line", rr.LineStrips2D([a[:, :2]], colors=[_MASKED_COLOR], radii=rr.Radius.ui_points(0.75),
                                                draw_order=20.0))
        log(f"{path}/points", rr.Points2D(a[:, :2], colors=[MODEL_COLOR], radii=rr.Radius.ui_points(3.5),
                                          draw_order=22.0))


class ModelPanel:
    """The "Model" tab of one recording stream: :meth:`log` draws a ``/livesweep/model`` record
    at the stream's current time (the caller sets it) in place of the model before.

    Parameters
    ----------
    rec : rerun.RecordingStream
    """

    def __init__(self, rec: rr.RecordingStream) -> None:
        self.rec = rec
        self._paths: set[str] = set()        # the entities the last model drew

    def log(self, record: dict) -> None:
        """Draw ``record`` (read only): Bode plots of data, model and prediction per pair, the
        trend plots, the numbers and the trend as markdown; clear what the model before drew and
        this one does not. Optional parts may be missing (no prediction, no figures, no pairs,
        skipped pairs): what is there is drawn."""
        drawn: set[str] = set()

        def log(path: str, *archetypes) -> None:
            self.rec.log(path, *archetypes)
            drawn.add(path)

        pairs = _dicts(record.get("pairs"))
        crit = record.get("criteria") if isinstance(record.get("criteria"), dict) else {}
        min_coh = _num(crit.get("min_coherence"))
        min_coh = DEFAULT_CRITERIA.min_coherence if math.isnan(min_coh) else min_coh
        drawn_roles = set().union(*(_draw_pair(log, p, k, len(pairs), min_coh) for k, p in enumerate(pairs)))
        _legend(log, min_coh, drawn_roles)
        ios, units = {p.get("name"): _io(p) for p in pairs}, _units(record)
        trend = [t for t in _dicts(record.get("trend")) if _dicts(t.get("rows"))]
        for k, t in enumerate(trend):
            _draw_trend(log, t, k, len(trend), ios.get(t.get("pair")) or _io(t), units.get(t.get("pair"), {}))
        for path in sorted(self._paths - drawn):
            self.rec.log(path, rr.Clear(recursive=False))
        self._paths = drawn
        self.rec.log(MODEL_SUMMARY_PATH, rr.TextDocument(model_markdown(record), media_type=rr.MediaType.MARKDOWN))
        self.rec.log(MODEL_TREND_PATH, rr.TextDocument(trend_markdown(record), media_type=rr.MediaType.MARKDOWN))
