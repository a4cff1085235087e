"""The same after landing: the live monitor's test-point models in ``identify``'s report.

A real ArduPilot SITL roll-rate sweep is converted, replayed through the monitor with a recording
(which then holds ``/livesweep/model`` beside the original dataflash topics), and identified over
its test point with the live model's structure as a ``[transfer_functions]`` table. The report
must carry the live model (``live_models``), its comparison with the offline fit (an independent
route: identify resamples the raw log itself) within one combined Cramer-Rao bound, and the
HTML section "In flight" with those numbers. Logs without the channel give no live models; a
malformed model message is skipped and counted, never an error.
"""

from __future__ import annotations

import copy
import json
import math
import types
from pathlib import Path

import pytest

from livesweep.settings import RecordSpec
from livesweep.stages.live_models import (MODEL_TOPIC, compare_pair, live_models_section, overlap_fraction,
                                          parameter_map, read_live_models)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def flight(sitl_mcaps, sitl_replays, tmp_path_factory):
    """The converted log, the replay's recording, its first model and that test point's judged band."""
    r = sitl_replays["roll"]
    assert r.models, "the replay recorded no model"
    model = r.models[0]
    tp = model["test_point"]
    point = next(t for t in r.test_points if t.get("judged_band_rad_s") and t["start_s"] == tp["start_s"])
    return types.SimpleNamespace(tmp=tmp_path_factory.mktemp("live_models"), log=sitl_mcaps["roll"], rec=r.recording,
                                 model=model, band=point["judged_band_rad_s"])


def _case(flight, path: Path, *, log=None, tf: bool = True) -> Path:
    tp, pair = flight.model["test_point"], flight.model["pairs"][0]
    lo, hi = flight.band
    text = f'''[case]
name = "sitl_roll_tp{tp["number"]}"
aircraft = "ArduCopter SITL"
condition = "roll-rate sweep, test point {tp["number"]}"

[[identify]]
log = "{log or flight.rec}"
start_s = {tp["start_s"]!r}
end_s = {tp["end_s"]!r}

[signals.roll]
topic = "/dataflash/RATE"
field = "RDes"
stamp = "TimeUS"
stamp_scale = 1e-6
units = "deg/s"

[signals.p]
topic = "/dataflash/RATE"
field = "R"
stamp = "TimeUS"
stamp_scale = 1e-6
units = "deg/s"

[spectral]
inputs = ["roll"]
outputs = ["p"]
band_rad_s = [{lo!r}, {hi!r}]
sample_rate_hz = 400.0
'''
    if tf:
        text += f'''
[transfer_functions.p_roll]
output = "p"
input = "roll"
numerator = "{pair["numerator"]}"
denominator = "{pair["denominator"]}"
'''
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def landed(flight):
    """``identify`` over the recording's test point and its report (JSON and HTML)."""
    import livesweep

    ident = livesweep.identify(_case(flight, flight.tmp / "tp1.toml"), until="transfer-functions")
    out = flight.tmp / "report"
    path = livesweep.write_report(ident, out, plots=False)
    return types.SimpleNamespace(ident=ident, report=json.loads(path.read_text()),
                                 html=(out / "report.html").read_text(encoding="utf-8"))


@pytest.mark.slow
def test_report_holds_the_live_model_beside_the_offline_fit(flight, landed):
    live = landed.report["live_models"]
    assert len(live) == 1
    m, rec = live[0], flight.model
    assert m["log"] == str(flight.rec)
    assert m["overlap"] == pytest.approx(1.0)
    for k in ("number", "start_s", "end_s", "swept_input", "verdict"):
        assert m["test_point"][k] == rec["test_point"][k]
    assert m["breaches"] == rec["breaches"]
    (pair,) = m["pairs"]
    want = rec["pairs"][0]
    for k in ("name", "structure", "numerator", "denominator", "band_rad_s", "cost", "parameters", "figures",
              "limits"):
        assert pair[k] == want[k], k
    c = pair["comparison"]
    assert pair["not_compared"] is None and c["transfer_function"] == "p_roll"
    fit = landed.ident.transfer_functions.fits[0]
    assert [q["name"] for q in c["parameters"]] == [p["name"] for p in want["parameters"]]
    for q in c["parameters"]:
        live_p = next(p for p in want["parameters"] if p["name"] == q["name"])
        assert q["live_value"] == live_p["value"] and q["live_cramer_rao"] == live_p["cramer_rao"]
        assert q["offline_value"] == pytest.approx(fit.parameters[q["offline_name"]], rel=1e-12)
        assert q["offline_cramer_rao"] == pytest.approx(fit.cramer_rao[q["offline_name"]], rel=1e-12)
        bound = math.hypot(q["live_cramer_rao"], q["offline_cramer_rao"])
        assert q["combined_bound"] == pytest.approx(bound)
        assert q["bounds"] == pytest.approx((q["live_value"] - q["offline_value"]) / bound)
        # two routes to the same samples: within one combined bound (they agree to ~0.001)
        assert abs(q["bounds"]) <= 1.0, q
        assert q["agrees"] is True
    assert c["agrees"] is True and c["max_bounds"] <= 1.0
    assert c["offline_cost"] == pytest.approx(fit.cost)
    assert any("in flight: 1 pair model(s) of 1 test point(s)" in i and "all within 2 combined bounds" in i
               for i in _summary_info(landed.report))
    from livesweep.report.console import summary_lines

    assert any(line.startswith("  in flight, test point 1: p/roll first order") and "TF p_roll: agrees" in line
               for line in summary_lines(landed.ident))


def _summary_info(report) -> list[str]:
    from livesweep.report.summary import stage_summary

    return [i for row in stage_summary(report) for i in row["info"]]


@pytest.mark.slow
def test_html_shows_the_in_flight_section_with_the_numbers(landed):
    html = landed.html
    assert "<h2 id='inflight'>In flight" in html and "href='#inflight'" in html
    section = html[html.index("<h2 id='inflight'>"):html.index("<h2 id=\"appendix\"")]
    assert "Test point 1" in section and "p/roll" in section and "TF p_roll" in section
    c = landed.report["live_models"][0]["pairs"][0]["comparison"]
    for q in c["parameters"]:
        assert f"{q['live_value']:.4g}" in section, q["name"]
        assert f"{q['offline_value']:.4g}" in section, q["name"]
    assert "in combined bounds" in section
    assert "class='num flag'" not in section          # nothing beyond the agreement threshold


@pytest.mark.slow
def test_live_model_keys_are_documented(landed):
    """docs/outputs.md's live_models sections against this real report (the cruise report of
    tests/test_docs.py has none)."""
    import test_docs as docs

    report = landed.report
    checked = set()
    for s in docs._sections(docs.DOCS / "outputs.md"):
        if s["h2"] != "`report.json`" or not s["keys"] or not s["text"].startswith("`live_models"):
            continue
        path = docs._TICKED.findall(s["text"])[0]
        keys = set(docs._one_keys_line(s, "outputs.md"))
        objs = docs._objects_at(report, path)
        if not objs:
            assert path == "live_models[].pairs[].limits[]", path       # no [limits] in this map
            continue
        actual = set().union(*(o.keys() for o in objs))
        assert actual == keys, f"{path}: report {sorted(actual)}, documented {sorted(keys)}"
        checked.add(path)
    assert checked == docs.LIVE_MODEL_OBJECTS - {"live_models[].pairs[].limits[]"}


@pytest.mark.slow
def test_a_log_without_models_gives_none(flight, landed):
    from livesweep.report.html import render

    live = read_live_models([RecordSpec(log=flight.log)])
    assert live.models == () and live.skipped == 0 and live.notes == ()
    assert live_models_section(live) == [] and live_models_section(None) == []
    page = render({**landed.report, "live_models": []})
    assert "inflight" not in page and "in flight:" not in page


@pytest.mark.slow
def test_a_test_point_outside_the_record_is_left_out(flight):
    tp = flight.model["test_point"]
    span = tp["end_s"] - tp["start_s"]
    before = RecordSpec(log=flight.rec, start_s=tp["start_s"] - 100.0, end_s=tp["start_s"] + 0.4 * span)
    assert read_live_models([before]).models == ()
    most = RecordSpec(log=flight.rec, start_s=tp["start_s"] + 0.3 * span, label="later part")
    (m,) = read_live_models([most, RecordSpec(log=flight.rec)]).models      # listed once
    assert m.record == "later part" and m.overlap == pytest.approx(0.7)


def _write_models(path: Path, messages: list) -> Path:
    from livesweep.telemetry.mcap_log import McapLogWriter
    from livesweep.telemetry.recorder import RESULT_SCHEMAS

    with McapLogWriter(path) as w:
        w.add_channel(MODEL_TOPIC, "livesweep.model", RESULT_SCHEMAS["model"])
        for k, m in enumerate(messages):
            if isinstance(m, bytes):
                w.write_encoded(MODEL_TOPIC, m, (k + 1) * 10**9)
            else:
                w.write(MODEL_TOPIC, m, log_time_ns=(k + 1) * 10**9)
    return path


@pytest.mark.slow
def test_a_malformed_model_message_is_skipped_and_counted(flight, landed, tmp_path):
    good = flight.model
    no_tp = {k: v for k, v in good.items() if k != "test_point"}
    bad_pairs = {**good, "pairs": "p/roll"}
    bad_value = copy.deepcopy(good)
    bad_value["pairs"][0]["parameters"][0]["value"] = "fast"
    log = _write_models(tmp_path / "models.mcap", [no_tp, good, bad_pairs, bad_value])
    live = read_live_models([RecordSpec(log=log)])
    assert len(live.models) == 1 and live.skipped == 3
    assert live.models[0].pairs[0].parameters == tuple(
        type(live.models[0].pairs[0].parameters[0])(p["name"], p["value"], p["cramer_rao"], p["units"],
                                                     tuple(p["flags"])) for p in good["pairs"][0]["parameters"])
    text = " ".join(live.skip_examples)
    assert "test_point is missing" in text and "pairs is missing or not a list" in text and "'fast'" in text
    assert any("3 /livesweep/model message(s) skipped" in n for n in live.notes)
    from livesweep.report.writer import write_frequency_report     # the report says so too

    i = landed.ident
    path = write_frequency_report(i.frequency_response, tmp_path / "report", transfer_functions=i.transfer_functions,
                                  live_models=live, plots=False)
    report = json.loads(path.read_text())
    assert len(report["live_models"]) == 1 and report["live_models"][0]["log"] == str(log)
    assert any("3 /livesweep/model message(s) skipped" in n for n in report["data_quality"]["notes"])
    # not JSON at all: the lenient reader steps over it
    log = _write_models(tmp_path / "junk.mcap", [good, b"{not json", good])
    live = read_live_models([RecordSpec(log=log)])
    assert len(live.models) == 1 and live.skipped == 1          # the same test point twice: listed once
    assert "not valid JSON" in live.skip_examples[0]


def _fit(numerator, denominator, parameters, cramer_rao, name="p_roll"):
    return types.SimpleNamespace(name=name, output="p", input="roll", numerator=numerator, denominator=denominator,
                                 parameters=parameters, cramer_rao=cramer_rao, cost=10.0, band_rad_s=(1.0, 10.0))


def _live_pair(numerator, denominator, values):
    from livesweep.stages.live_models import LivePair, LiveValue

    return LivePair("p/roll", "p", "roll", "case", numerator, denominator, (1.0, 10.0), 9.0, True,
                    tuple(LiveValue(k, v, cr) for k, (v, cr) in values.items()), (), (), ())


def test_parameters_are_matched_by_their_place_in_the_structure():
    live = _live_pair("(1/Tz)", "[zeta, wn] (1/T)", {"gain": (2.0, 0.1), "1/Tz": (1.0, 0.1), "zeta": (0.5, 0.05),
                                                      "wn": (8.0, 0.4), "1/T": (20.0, 3.0), "tau": (0.02, 0.002)})
    fit = _fit("(1/Ta)", "[z_d, w_d] (1/Tb)",
               {"z_d": 0.48, "w_d": 8.3, "1/Tb": 20.0, "gain": 2.0, "1/Ta": 1.0, "tau": 0.021},
               {"z_d": 0.05, "w_d": 0.3, "1/Tb": 4.0, "gain": 0.1, "1/Ta": 0.1, "tau": 0.002})
    mapping, why = parameter_map(live, fit)
    assert why == "" and mapping == {"gain": "gain", "1/Tz": "1/Ta", "zeta": "z_d", "wn": "w_d", "1/T": "1/Tb",
                                     "tau": "tau"}
    cmp, _ = compare_pair(live, fit)
    wn = next(q for q in cmp.parameters if q.name == "wn")
    assert wn.difference == pytest.approx(-0.3) and wn.combined_bound == pytest.approx(0.5)
    assert wn.bounds == pytest.approx(-0.6) and wn.agrees
    assert cmp.max_bounds == pytest.approx(0.6) and cmp.agrees
    # the display form "1" of no factor is no factor, not a first-order one
    assert parameter_map(_live_pair("", "(1/T)", {"gain": (1, 1), "1/T": (1, 1), "tau": (1, 1)}),
                         _fit("1", "(1/Tr)", {"gain": 1, "1/Tr": 1, "tau": 1}, {}))[0] is not None


@pytest.mark.parametrize("numerator, denominator, parameters, why", [
    ("", "[zeta, wn]", {"gain": 1.0, "zeta": 0.5, "wn": 5.0, "tau": 0.01}, "another structure"),
    ("", "(1/0.5)", {"gain": 1.0, "tau": 0.01}, "another structure"),             # a fixed value for a free one
    ("", "(1/T)", {"gain": 1.0, "1/T": 5.0}, "a delay in flight only"),
])
def test_another_structure_is_not_compared(numerator, denominator, parameters, why):
    live = _live_pair("", "(1/T)", {"gain": (1.0, 0.1), "1/T": (5.0, 0.5), "tau": (0.01, 0.001)})
    cmp, reason = compare_pair(live, _fit(numerator, denominator, parameters, {k: 0.1 for k in parameters}))
    assert cmp is None and why in reason


def test_a_bound_that_is_not_determined_gives_no_difference_in_bounds():
    live = _live_pair("", "(1/T)", {"gain": (1.0, None), "1/T": (5.0, 0.5), "tau": (0.01, 0.001)})
    cmp, _ = compare_pair(live, _fit("", "(1/T)", {"gain": 1.2, "1/T": 9.0, "tau": 0.01},
                                     {"gain": 0.1, "1/T": math.inf, "tau": 0.001}))
    gain, inv_t, tau = cmp.parameters
    assert gain.difference == pytest.approx(-0.2) and gain.bounds is None and gain.agrees is None
    assert inv_t.offline_cramer_rao is None and inv_t.bounds is None
    assert tau.bounds == pytest.approx(0.0) and cmp.agrees is True and cmp.max_bounds == pytest.approx(0.0)


def test_overlap_fraction():
    assert overlap_fraction(10.0, 20.0, None, None) == 1.0
    assert overlap_fraction(10.0, 20.0, 15.0, None) == pytest.approx(0.5)
    assert overlap_fraction(10.0, 20.0, 0.0, 12.0) == pytest.approx(0.2)
    assert overlap_fraction(10.0, 20.0, 30.0, 40.0) == 0.0
