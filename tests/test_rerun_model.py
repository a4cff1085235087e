"""The Rerun view's "Model" tab: a real replay's ``/livesweep/model`` record drawn into an .rrd and
read back (curves, numbers, breaches, trend, blueprint), and the markdown and drawing of hand-made
records with parts missing."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import RrdReader

from livesweep.monitor.blueprint import (
    MODEL_BODE_PATH, MODEL_SUMMARY_PATH, MODEL_TREND_PATH, MODEL_TREND_PLOT_PATH, default_blueprint, model_box,
    model_pair_path, model_trend_plot_path,
)
from livesweep.monitor.rerun_model import ModelPanel, model_markdown, trend_markdown, trend_quantities, value_text
from test_rerun_view import _rows

ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "src" / "livesweep" / "data" / "maps" / "ardupilot-sysid-dataflash.toml"
#: A limit the log's roll-rate model breaks (its delay is about 0.010 s) and a prediction of it.
EXTRA = """
[limits]
max_delay_s = 0.005

[predictions.roll_rate]
output = "p"
input = "roll"
gain = 70.0
denominator = "(1/0.0125)"
delay_s = 0.012
"""


# ------------------------------------------------------------------------------------ helpers


def _last(chunks, entity: str, column: str):
    rows = _rows(chunks, entity, column)
    assert rows, f"nothing in {column} at {entity}"
    return rows[-1][1]


@pytest.fixture(scope="module")
def replayed(sitl_mcaps, tmp_path_factory):
    """One replay of the SITL roll-rate sweep, with a broken delay limit and a prediction, into an .rrd."""
    import livesweep

    tmp = tmp_path_factory.mktemp("rerun_model")
    log = sitl_mcaps["roll"]
    map_path = tmp / "map.toml"
    map_path.write_text(MAP.read_text() + EXTRA)
    r = livesweep.replay(log, map=str(map_path), rerun=tmp / "model.rrd")
    assert r.models, "the replay made no model"
    return {"record": r.models[-1], "chunks": RrdReader(tmp / "model.rrd").stream().to_chunks(),
            "path": tmp / "model.rrd"}


# ------------------------------------------------------------------------------------ the replay


@pytest.mark.slow
def test_bode_curves_hold_the_records_numbers_inside_their_boxes(replayed):
    record, chunks = replayed["record"], replayed["chunks"]
    pairs = record["pairs"]
    assert pairs and record["pairs"][0]["name"] == "p/roll"
    for column, p in enumerate(pairs):
        c = p["curve"]
        x = np.log10(np.asarray(c["omega_rad_s"], float))
        root = model_pair_path(p["output"], p["input"])
        for kind, key in (("magnitude", "magnitude_db"), ("phase", "phase_deg")):
            (model,) = _last(chunks, f"{root}/{key}/model", "LineStrips2D:strips")     # one unbroken line
            np.testing.assert_allclose(np.asarray(model), np.column_stack([x, c[f"model_{key}"]]), rtol=1e-6, atol=1e-5)
            data = np.asarray(_last(chunks, f"{root}/{key}/data", "Points2D:positions"))
            np.testing.assert_allclose(data, np.column_stack([x, c[key]]), rtol=1e-6, atol=1e-5)
            # the prediction is dashed: every dash lies on the predicted curve, and they span the band
            dashes = _last(chunks, f"{root}/{key}/prediction", "LineStrips2D:strips")
            pts = np.concatenate([np.asarray(d) for d in dashes])
            np.testing.assert_allclose(pts[:, 1], np.interp(pts[:, 0], x, c[f"predicted_{key}"]), atol=1e-3)
            assert len(dashes) > 20 and pts[:, 0].min() == pytest.approx(x[0]) and pts[:, 0].max() == pytest.approx(x[-1])
            # the display transform puts every point inside the pair's box
            t = np.asarray(_last(chunks, f"{root}/{key}", "Transform3D:translation")).ravel()
            s = np.asarray(_last(chunks, f"{root}/{key}", "Transform3D:scale")).ravel()
            shown = np.asarray(model) * s[:2] + t[:2]
            bx, by, bw, bh = model_box(kind, column, len(pairs))
            assert np.all(shown[:, 0] >= bx - 1e-3) and np.all(shown[:, 0] <= bx + bw + 1e-3)
            assert np.all(shown[:, 1] >= by - 1e-3) and np.all(shown[:, 1] <= by + bh + 1e-3)
        (title,) = _last(chunks, f"{root}/title", "Points2D:labels")
        assert title.startswith(f"{p['name']}: {p['structure']}, J {value_text(p['cost'])}")
    legend = _last(chunks, f"{MODEL_BODE_PATH}/legend", "Points2D:labels")
    assert "model (fit)" in legend and "prediction" in legend and "data" in legend


@pytest.mark.slow
def test_table_holds_each_value_with_its_bound_and_the_breach_first(replayed):
    record, chunks = replayed["record"], replayed["chunks"]
    (text,) = _last(chunks, MODEL_SUMMARY_PATH, "TextDocument:text")
    assert record["breaches"] and all("delay" in b for b in record["breaches"])
    breach = record["breaches"][0]
    assert breach.endswith("limit 0.005 s: do not proceed")
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert lines[0] == "## Do not proceed" and lines[1] == f"- **{breach}**"
    assert text.index(breach) < text.index("Test point 1")
    for p in record["pairs"]:
        assert f"{p['name']}: {p['structure']}" in text and "band 3.14 – 75.4 rad/s" in text
        assert f"J {value_text(p['cost'])}" in text
        for f in p["parameters"] + p["figures"]:
            shown = value_text(f["value"], f["cramer_rao"], f["units"])
            assert f"| {f['name']} | {shown} |" in text
            if f["value"] is not None:
                assert f"{f['value']:.4g} ± {f['cramer_rao']:.3g}" in shown
        for c in p["limits"]:
            assert ("- OK: " if c["ok"] else "- **do not proceed**: ") + c["text"].removesuffix(": do not proceed") in text
    tau = next(f for f in record["pairs"][0]["parameters"] if f["name"] == "tau")
    assert f"{tau['value']:.4g} ± {tau['cramer_rao']:.3g} s" in text


@pytest.mark.slow
def test_trend_table_and_plot_hold_each_test_points_values(replayed):
    record, chunks = replayed["record"], replayed["chunks"]
    (text,) = _last(chunks, MODEL_TREND_PATH, "TextDocument:text")
    pairs = {p["name"]: p for p in record["pairs"]}
    for entry in record["trend"]:
        p = pairs[entry["pair"]]
        assert f"#### {entry['pair']}" in text
        for row in entry["rows"]:
            for name, (v, cr) in row["parameters"].items():
                assert value_text(v, cr) in text
        quantities = trend_quantities(entry["rows"])
        assert [q for _, q in quantities] == ["gain", "tau", "bandwidth"]
        for kind, q in quantities:
            path = model_trend_plot_path(p["output"], p["input"], q)
            pts = np.asarray(_last(chunks, f"{path}/points", "Points2D:positions"))
            want = [[r["test_point"], r[kind][q][0]] for r in entry["rows"]]
            np.testing.assert_allclose(pts, want, rtol=1e-6)
            bars = _last(chunks, f"{path}/bounds", "LineStrips2D:strips")
            for tp, (v, cr) in ((r["test_point"], r[kind][q]) for r in entry["rows"]):
                assert any(np.allclose(b, [[tp, v - cr], [tp, v + cr]], rtol=1e-6) for b in bars)


def _views(node):
    if isinstance(node, rrb.Blueprint):
        return _views(node.root_container)
    if isinstance(node, rrb.View):
        return [node]
    return [v for child in node.contents for v in _views(child)]


@pytest.mark.slow
def test_the_model_tab_shows_every_model_entity(replayed):
    bp = default_blueprint(["roll", "pitch", "yaw"], ["p", "q", "r"])
    (tabs,) = [bp.root_container]
    assert [str(t.name) for t in tabs.contents][:2] == ["Test point", "Model"]
    views = _views(tabs.contents[1])
    kinds = {str(v.origin): type(v).__name__ for v in views}
    assert kinds == {"/" + MODEL_BODE_PATH: "Spatial2DView", "/" + MODEL_TREND_PLOT_PATH: "Spatial2DView",
                     "/" + MODEL_SUMMARY_PATH: "TextDocumentView", "/" + MODEL_TREND_PATH: "TextDocumentView"}
    entities = {c.entity_path for c in replayed["chunks"] if c.entity_path.startswith("/model/")}
    assert len(entities) > 20
    for e in entities:
        assert [o for o in kinds if e == o or e.startswith(o + "/")], f"{e} is in no view of the Model tab"
    assert default_blueprint(["roll"], ["p"], active_tab="Model").root_container.active_tab == 1
    with pytest.raises(ValueError, match="active_tab"):
        default_blueprint(["roll"], ["p"], active_tab="Nope")


# ------------------------------------------------------------------------------------ hand-made records


def _pair(name="q/de", *, prediction=False, curve=True):
    o, i = name.split("/")
    w = [1.0, 2.0, 5.0, 10.0]
    p = {"name": name, "output": o, "input": i, "structure": "second order", "band_rad_s": [1.0, 10.0],
         "cost": 42.25, "converged": True, "flags": ["wn: CR 31 % > 20 %"],
         "parameters": [{"name": "gain", "value": 3.14159, "cramer_rao": 0.0123, "units": "", "flags": []},
                        {"name": "wn", "value": 6.2, "cramer_rao": None, "units": "rad/s",
                         "flags": ["not determined by the data"]}],
         "curve": {"omega_rad_s": w, "magnitude_db": [1.0, None, -3.0, -9.0], "phase_deg": [-10.0, -20.0, -60.0, -150.0],
                   "coherence": [0.9, 0.95, 0.4, 0.8], "model_magnitude_db": [0.5, 0.0, -3.5, -9.5],
                   "model_phase_deg": [-370.0, -380.0, -420.0, -510.0]} if curve else {}}
    if prediction:
        p["curve"].update(predicted_magnitude_db=[0.0, -1.0, -4.0, -10.0], predicted_phase_deg=[-5, -25, -65, -155])
    return p


def test_markdown_of_a_minimal_record():
    record = {"test_point": {"number": 3, "start_s": 10.0, "end_s": 40.5, "swept_input": "de", "source": "marker",
                             "label": "NO-GO"},
              "pairs": [_pair()], "skipped": ["p/de: no coherent band"], "breaches": ["q/de: zeta 0.1, limit 0.3"],
              "trend": [{"pair": "q/de", "rows": [
                  {"test_point": 2, "start_s": 1.0, "verdict": "GO", "parameters": {"gain": [3.0, 0.1], "wn": [6.0, None]},
                   "figures": {"bandwidth": [None, None]}, "cost": 40.0},
                  {"test_point": 3, "start_s": 10.0, "verdict": "NO-GO", "parameters": {"gain": [3.14159, 0.0123]},
                   "figures": {}, "cost": 42.25}]}],
              "trend_notes": ["q/de: gain moved from 3 (TP2) to 3.142 (TP3), 2.4 times their combined bound"]}
    text = model_markdown(record)
    lines = text.splitlines()
    assert lines[:3] == ["## Do not proceed", "", "- **q/de: zeta 0.1, limit 0.3**"]
    assert "### Test point 3: NO-GO (de swept 10.0 s – 40.5 s, marker)" in text
    assert "#### q/de: second order, K / [ζ, ωn] e^(−τs)" in text
    assert "band 1 – 10 rad/s, J 42.25" in text
    assert "| gain | 3.142 ± 0.0123 | — |" in text
    assert "| wn | 6.2 rad/s | not determined by the data |" in text            # no bound: the value alone
    assert "- ⚠ wn: CR 31 % > 20 %" in text
    assert "figure" not in text and "Limits:" not in text                       # none given: no table
    assert text.rstrip().endswith("- p/de: no coherent band")
    trend = trend_markdown(record)
    assert "| TP | start | verdict | gain | wn [rad/s] | J |" in trend          # bandwidth never had a value
    assert "| 2 | 1.0 s | GO | 3 ± 0.1 | 6 | 40 |" in trend
    assert "| 3 | 10.0 s | NO-GO | 3.142 ± 0.0123 | n/a | 42.25 |" in trend
    assert trend.rstrip().endswith(record["trend_notes"][0])
    assert value_text(None, 1.0, "s") == "n/a" and value_text(0.0103212, 0.00125179, "s") == "0.01032 ± 0.00125 s"
    assert trend_quantities(record["trend"][0]["rows"]) == [("parameters", "gain"), ("parameters", "wn")]
    # nothing at all: still a document
    assert "No pair of this test point was modelled." in model_markdown({})
    assert "No model yet." in trend_markdown({})


def _drawn(records, tmp_path) -> list:
    rec = rr.RecordingStream("livesweep-test", recording_id="model-panel")
    mem = rec.memory_recording()
    panel = ModelPanel(rec)
    for k, r in enumerate(records):
        rec.set_time("flight_time", duration=float(k + 1))
        panel.log(r)
    rec.flush()
    path = tmp_path / "panel.rrd"
    path.write_bytes(mem.drain_as_bytes())
    return RrdReader(path).stream().to_chunks()


def test_records_missing_parts_draw_what_they_have_and_a_later_model_clears_the_rest(tmp_path):
    two = {"pairs": [_pair("q/de", prediction=True), _pair("p/da")],
           "trend": [{"pair": "q/de", "rows": [{"test_point": 1, "parameters": {"gain": [3.0, 0.1]}}]}]}
    broken = {"pairs": [_pair("q/de", curve=False), {"name": "r/dr"}, "junk"], "trend": [{"pair": "x"}, None],
              "breaches": None, "criteria": {"min_coherence": "?"}, "test_point": None}
    chunks = _drawn([two, {}, broken, {"pairs": [_pair("q/de")]}], tmp_path)
    q = model_pair_path("q", "de")
    # 1 s: two pairs side by side; the missing magnitude point is left out, grey below gamma^2 0.6
    pos = _rows(chunks, f"{q}/magnitude_db/data", "Points2D:positions")
    assert pos[0][0] == 1_000_000_000 and np.allclose(pos[0][1], [[0.0, 1.0], [math.log10(5.0), -3.0], [1.0, -9.0]])
    colors = _rows(chunks, f"{q}/magnitude_db/data", "Points2D:colors")[0][1]
    assert colors[1] != colors[0] == colors[2]
    # the model's phase is put on the data's turn (-370 deg is drawn at -10)
    (strip,) = _rows(chunks, f"{q}/phase_deg/model", "LineStrips2D:strips")[0][1]
    assert np.allclose(np.asarray(strip)[:, 1], [-10.0, -20.0, -60.0, -150.0])
    assert _rows(chunks, f"{model_pair_path('p', 'da')}/magnitude_db/model", "LineStrips2D:strips")
    # 2 s: an empty record clears every plot of the one before; the documents say so
    cleared = {c.entity_path for c in chunks if "Clear:is_recursive" in c.to_record_batch().schema.names}
    assert f"/{q}/magnitude_db/prediction" in cleared and f"/{model_pair_path('p', 'da')}/title" in cleared
    docs = [(t, text) for t, (text,) in _rows(chunks, MODEL_SUMMARY_PATH, "TextDocument:text")]
    assert [t for t, _ in docs] == [k * 1_000_000_000 for k in (1, 2, 3, 4)]
    assert docs[1][1].startswith("### Model\n") and "No pair of this test point was modelled." in docs[1][1]
    # 3 s: a pair without a curve, one with nothing but a name, and junk: the text, no plot, no error
    assert "#### q/de: second order" in docs[2][1] and "#### r/dr: ?" in docs[2][1]
    assert _rows(chunks, f"{model_pair_path('r', 'dr')}/magnitude_db", "Transform3D:scale") == []
    # 4 s: one pair again, drawn after the clears
    assert [t for t, _ in _rows(chunks, f"{q}/magnitude_db/model", "LineStrips2D:strips")] == [1_000_000_000,
                                                                                              4_000_000_000]
    assert [t for t, _ in _rows(chunks, MODEL_TREND_PLOT_PATH + "/q_de/gain/points", "Points2D:positions")] == [
        1_000_000_000]


def test_the_trend_table_has_a_column_per_condition():
    from livesweep.monitor.rerun_model import trend_markdown

    rows = [{"test_point": k, "start_s": 10.0 * k, "verdict": "GO", "conditions": {"airspeed": v},
             "parameters": {"gain": [2.0 + k, 0.1]}, "figures": {}, "cost": 5.0} for k, v in ((1, 30.0), (2, 41.5))]
    text = trend_markdown({"trend": [{"pair": "p/roll", "rows": rows}], "pairs": []})
    header = next(line for line in text.splitlines() if line.startswith("| TP"))
    assert [c.strip() for c in header.strip("|").split("|")][:5] == ["TP", "start", "verdict", "airspeed", "gain"]
    assert "| 41.5 |" in text and "| 4 ± 0.1 |" in text
