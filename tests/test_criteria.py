"""One ``[criteria]`` line changes the GO coherence threshold everywhere it is used.

A case (or a map) sets ``[criteria] min_coherence = 0.8``; the adequacy of every pair, the
transfer-function fit band, the report's shading, text and appendix, the console's header, the
live verdict on a test point, its recorded record, the Rerun view's threshold line and legend, and
the status text all follow it. The expected values are computed here from the responses' own
coherence and random error with numpy (the definition of adequacy), not by the code under test.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from livesweep.config import load_case, read_channel_map
from livesweep.errors import ConfigError
from livesweep.spectral.criteria import DEFAULT_CRITERIA, Criteria

ROOT = Path(__file__).resolve().parents[1]
CRUISE = ROOT / "config" / "xv15_cruise_lateral.toml"


def _case_with(tmp_path, criteria_text: str) -> Path:
    """The shipped cruise case with absolute log paths and a [criteria] table, frequency responses
    and the transfer function only (the model tables are cut)."""
    text = CRUISE.read_text()
    text = text.replace('"../replay_logs/', f'"{ROOT / "replay_logs"}/')
    text = text[:text.index("[state_space]")]
    path = tmp_path / "case.toml"
    path.write_text(text + "\n" + criteria_text)
    return path


def test_criteria_table_is_read_from_a_case_and_a_map_and_bad_values_name_the_key(tmp_path):
    case = load_case(_case_with(tmp_path, "[criteria]\nmin_coherence = 0.8\n"))
    assert case.criteria == Criteria(min_coherence=0.8)
    assert load_case(_case_with(tmp_path, "")).criteria == DEFAULT_CRITERIA
    mp = tmp_path / "map.toml"
    base = (ROOT / "src" / "livesweep" / "data" / "xv15_channels.toml").read_text()
    mp.write_text(base + "\n[criteria]\nmin_coherence = 0.8\nrequired_fraction = 0.7\n")
    assert read_channel_map(mp, one_clock=False).criteria == Criteria(min_coherence=0.8, required_fraction=0.7)
    for bad, key in (("min_coherence = 1.2", "criteria.min_coherence"), ("max_random_error = -1", "criteria.max_random_error"),
                     ("min_coherence = \"high\"", "criteria.min_coherence"), ("min_coh = 0.7", "criteria.min_coh")):
        mp.write_text(base + f"\n[criteria]\n{bad}\n")
        with pytest.raises(ConfigError) as err:
            read_channel_map(mp, one_clock=False)
        msg = str(err.value)
        assert "\n" not in msg and str(mp) in msg and key in msg, msg


def test_loss_thresholds_follow_the_criteria():
    """The lost-frame thresholds are the adequacy rule's: 13.6 % and 22.5 % at the method's criteria."""
    assert DEFAULT_CRITERIA.loss_reason_fraction == pytest.approx(0.136, abs=5e-4)
    assert DEFAULT_CRITERIA.loss_link_fraction == pytest.approx(0.2254, abs=5e-4)
    strict = Criteria(min_coherence=0.8)
    assert strict.loss_link_fraction == pytest.approx(1 - np.sqrt(0.8))
    assert strict.loss_reason_fraction == pytest.approx(1 - np.sqrt(1 - 0.4 * np.sqrt(0.2)))


@pytest.fixture(scope="module")
def strict_and_default(tmp_path_factory):
    """The cruise case's frequency responses and transfer function, judged at 0.8 and at the default."""
    import livesweep

    tmp = tmp_path_factory.mktemp("criteria")
    out = {}
    for name, text in (("strict", "[criteria]\nmin_coherence = 0.8\n"), ("default", "")):
        d = tmp / name
        d.mkdir()
        ident = livesweep.identify(_case_with(d, text), until="transfer-functions", parallel=False)
        out[name] = ident
    return out


def _fraction(coherence, random_error, threshold):
    """The adequate fraction by the definition: gamma^2 >= threshold and eps_r <= 0.2, of the grid."""
    coh, eps = np.asarray(coherence, float), np.asarray(random_error, float)
    with np.errstate(invalid="ignore"):
        return float(np.mean((coh >= threshold) & (eps <= 0.2)))


@pytest.mark.slow
def test_adequacy_and_fit_band_follow_min_coherence(strict_and_default):
    strict, default = strict_and_default["strict"], strict_and_default["default"]
    lower = 0
    for a_s, a_d in zip(strict.frequency_response.adequacy, default.frequency_response.adequacy):
        resp = strict.responses.pair(a_s.output, a_s.input)
        assert a_s.fraction == pytest.approx(_fraction(resp.coherence, resp.random_error, 0.8), abs=1e-12)
        assert a_d.fraction == pytest.approx(_fraction(resp.coherence, resp.random_error, 0.6), abs=1e-12)
        assert a_s.to_dict()["criteria"]["min_coherence"] == 0.8
        lower += a_s.fraction < a_d.fraction
    assert lower >= 1           # the stricter threshold takes points away somewhere
    tf_s, tf_d = strict.transfer_functions.fits[0], default.transfer_functions.fits[0]
    resp = strict.responses.pair(tf_s.output, tf_s.input)
    coh = resp.coherence
    lo, hi = tf_s.band_rad_s
    inside = (resp.omega >= lo) & (resp.omega <= hi)
    assert np.all(coh[inside] >= 0.8 - 1e-12)              # the fit band is coherent at 0.8
    assert np.log(tf_s.band_rad_s[1] / tf_s.band_rad_s[0]) <= np.log(tf_d.band_rad_s[1] / tf_d.band_rad_s[0]) + 1e-12


@pytest.mark.slow
def test_report_and_console_state_the_criteria(strict_and_default, tmp_path):
    from livesweep.report.chart import bode_chart
    from livesweep.report.console import summary_lines
    from livesweep.report.writer import write_report

    strict = strict_and_default["strict"]
    path = write_report(strict, tmp_path / "out", plots=False)
    rep = json.loads(Path(path).read_text())
    assert rep["criteria"] == {"min_coherence": 0.8, "max_random_error": 0.2, "required_fraction": 0.6}
    assert all(e["criteria"]["min_coherence"] == 0.8 for e in rep["data_quality"]["excitation"])
    html = (tmp_path / "out" / "report.html").read_text()
    assert "γ² below 0.8 are drawn faint" in html
    assert "A point is adequate when γ² ≥ 0.8" in html and "this case's [criteria]" in html
    assert any("gamma^2 >= 0.8, eps <= 0.2" in line for line in summary_lines(strict))
    # the Bode plot: the threshold line and the bold (coherent) points at 0.8
    pair = strict.responses.pair("p", "da")
    chart = bode_chart(pair, min_coherence=strict.case.criteria.min_coherence)
    coh_panel = chart.rows[2][0]
    assert [h.y for h in coh_panel.hlines] == [0.8]
    bold = chart.rows[0][0].lines[1]
    assert "γ² ≥ 0.8" in bold.label
    with np.errstate(invalid="ignore"):
        expected = np.isfinite(pair.magnitude_db) & np.isfinite(pair.phase_deg) & (pair.coherence >= 0.8)
    assert np.array_equal(np.isfinite(bold.y), expected)


def test_a_test_point_is_judged_by_its_criteria():
    """A first-order lag with output noise: at 0.8 the adequate fraction is what the definition
    gives on the judged response, lower than at 0.6, the record says which criteria, and the
    missing band's text names 0.8."""
    from scipy import signal

    from livesweep.spectral.verdict import judge_test_point

    rng = np.random.default_rng(7)
    fs, T = 50.0, 120.0
    t = np.arange(0, T, 1 / fs)
    u = signal.chirp(t, 0.05, T, 3.0, method="logarithmic")
    b, a = signal.bilinear([4.0], [1.0, 4.0], fs)
    y = signal.lfilter(b, a, u) + 0.35 * rng.standard_normal(t.size)
    values = np.vstack([u, y])
    j6 = judge_test_point(values, ["u", "y"], fs, "u", ["y"], (0.5, 15.0))
    j8 = judge_test_point(values, ["u", "y"], fs, "u", ["y"], (0.5, 15.0), criteria=Criteria(min_coherence=0.8))
    assert j8.pairs[0].adequate_fraction < j6.pairs[0].adequate_fraction
    r = j8.pairs[0].response
    assert r is not None
    assert j8.to_dict()["criteria"]["min_coherence"] == 0.8 and j6.to_dict()["criteria"]["min_coherence"] == 0.6
    if j8.missing:
        assert any("coherence below 0.8" in m or "rad/s" in m for m in j8.missing)


def test_status_text_and_layout_name_the_threshold():
    from livesweep.monitor.blueprint import default_blueprint
    from livesweep.monitor.text import adequacy_markdown, test_point_line

    md = adequacy_markdown(10.0, [], "GO", [], min_coherence=0.8)
    assert re.search(r"threshold γ² ≥ 0\.8\b", md)
    names = []

    def walk(node):
        if getattr(node, "name", None):
            names.append(str(node.name))
        for child in getattr(node, "contents", None) or []:
            if not isinstance(child, str):
                walk(child)

    walk(default_blueprint(["da"], ["p"], min_coherence=0.8).root_container)
    assert any(n.endswith("grey: γ² < 0.8") for n in names), names
    # a recorded test point judged at required_fraction 0.7 is read with that fraction
    tp = {"swept_input": "da", "start_s": 1.0, "end_s": 40.0, "source": "sweep", "verdict": "NO-GO",
          "pairs": [{"output": "p", "input": "da", "adequate_fraction": 0.65}],
          "criteria": {"min_coherence": 0.8, "max_random_error": 0.2, "required_fraction": 0.7}}
    assert "-5 points" in test_point_line(1, tp)


@pytest.fixture(scope="module")
def replays(tmp_path_factory):
    """The shipped cruise aileron sweeps replayed with the packaged XV-15 map, once as it is and
    once with ``[criteria] min_coherence = 0.8`` (one line), the strict one into an .rrd."""
    import livesweep

    tmp = tmp_path_factory.mktemp("criteria_live")
    base = (ROOT / "src" / "livesweep" / "data" / "xv15_channels.toml").read_text()
    strict_map = tmp / "strict.toml"
    strict_map.write_text(base + "\n[criteria]\nmin_coherence = 0.8\n")
    log = ROOT / "replay_logs" / "xv15_cruise_sweeps_da.mcap"
    default = livesweep.replay(log, map=str(ROOT / "src" / "livesweep" / "data" / "xv15_channels.toml"))
    strict = livesweep.replay(log, map=str(strict_map), rerun=tmp / "strict.rrd", record=tmp / "strict.mcap")
    return default, strict, tmp


@pytest.mark.slow
def test_the_live_verdict_the_recording_and_the_rerun_legend_follow_one_criteria_line(replays):
    from rerun.chunk import RrdReader

    from livesweep.monitor.blueprint import coherence_path
    from livesweep.monitor.session import recorded_settings

    default, strict, tmp = replays
    assert strict.settings.criteria == Criteria(min_coherence=0.8)
    assert len(strict.test_points) == len(default.test_points) >= 1
    lower = 0
    for tp_s, tp_d in zip(strict.test_points, default.test_points):
        assert tp_s["criteria"]["min_coherence"] == 0.8 and tp_d["criteria"]["min_coherence"] == 0.6
        for p_s, p_d in zip(tp_s["pairs"], tp_d["pairs"]):
            assert p_s["adequate_fraction"] <= p_d["adequate_fraction"] + 1e-12
            lower += p_s["adequate_fraction"] < p_d["adequate_fraction"] - 1e-9
    assert lower >= 1
    # the recording keeps the criteria, so its replay judges the same way
    assert recorded_settings(tmp / "strict.mcap").criteria == Criteria(min_coherence=0.8)
    # Rerun: the threshold line sits at 0.8 and its legend says so
    chunks = RrdReader(tmp / "strict.rrd").stream().to_chunks()
    entity = "/" + coherence_path("p", "da") + "/threshold"
    labels, strips = [], []
    for c in chunks:
        if c.entity_path != entity:
            continue
        rb = c.to_record_batch()
        for name in rb.schema.names:
            if name.endswith("LineStrips2D:labels"):
                labels += rb.column(name).to_pylist()
            if name.endswith("LineStrips2D:strips"):
                strips += rb.column(name).to_pylist()
    assert labels and all(v == ["γ² = 0.8"] for v in labels), labels
    assert strips and all(abs(pt[1] - 0.8) < 1e-6 for s in strips for line in s for pt in line), strips[:1]
