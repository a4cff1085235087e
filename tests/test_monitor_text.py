"""Operator-facing text: percentages never on the wrong side of a threshold, sweep and duration lines."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from livesweep.monitor.text import (
    adequacy_markdown, band_text, coherence_kind_text, duration_text, markdown_test_points, md_cell, percent,
    sweep_text,
)


def _shown(text: str) -> float:
    """The fraction a reader takes from ``percent``'s text."""
    assert text.endswith(" %"), text
    return float(text[:-2]) / 100.0


@pytest.mark.parametrize("fraction, threshold, text", [
    (0.5999, 0.6, "59.9 %"),            # the bug: printed "60 % ... NOT adequate (need 60 %)"
    (0.5995, 0.6, "59.9 %"),
    (0.5999999999999999, 0.6, "59.9 %"),
    (0.6, 0.6, "60 %"),
    (0.6000001, 0.6, "60 %"),
    (0.59, 0.6, "59 %"),
    (0.605, 0.605, "60.5 %"),            # whole-percent rounding (60) would fall below a 60.5 % threshold
    (0.6049, 0.605, "60 %"),             # below and shown below: whole percent is fine
    (0.75, 0.6, "75 %"),
    (0.0, 0.6, "0 %"),
    (1.0, 0.6, "100 %"),
    (0.9996, None, "99.9 %"),            # "100 %" means all of the band
    (0.0004, None, "0.1 %"),             # "0 %" means none of it
    (0.25, None, "25 %"),
])
def test_percent_examples(fraction, threshold, text):
    assert percent(fraction, threshold) == text


@pytest.mark.parametrize("bad", [None, float("nan"), float("inf"), "x"])
def test_percent_of_nothing(bad):
    assert percent(bad, 0.6) == "—"
    assert percent(bad, missing="n/a") == "n/a"


@pytest.mark.slow
@settings(max_examples=2000, deadline=None)
@given(st.floats(0.0, 1.0), st.floats(0.01, 0.99))
def test_percent_never_crosses_its_threshold(fraction, threshold):
    text = percent(fraction, threshold)
    assert (_shown(text) < threshold) == (fraction < threshold), (fraction, threshold, text)
    assert abs(_shown(text) - fraction) <= 0.005 + 1e-12                # and stays close to the value
    assert (text == "100 %") == (fraction == 1.0)                        # all means all
    assert (text == "0 %") == (fraction == 0.0)                          # none means none


@pytest.mark.slow
@settings(max_examples=2000, deadline=None)
@given(st.floats(0.0, 1.0), st.floats(0.01, 0.99))
def test_points_say_the_side_of_the_threshold_and_the_distance(fraction, threshold):
    """The distance in percentage points has the sign of the side it is on, never "+0" or "-0"."""
    from livesweep.numeric import points

    text = points(fraction, threshold)
    d = float(text.split()[0])
    assert abs(d - 100 * (fraction - threshold)) <= 0.5 + 1e-9
    if abs(fraction - threshold) >= 0.0005:           # a tenth of a point away: its side, signed
        assert text.startswith("-" if fraction < threshold else "+"), text
    assert text not in ("+0 points", "-0 points", "-0.0 points", "+0.0 points")


def test_band_duration_cell():
    assert band_text((0.3, 18.93)) == "0.3 – 18.9"
    assert band_text(None) == band_text([]) == "—"
    assert band_text([(0.3, 1.0), (2.0, 5.0)]) == "0.3 – 1, 2 – 5"
    assert [duration_text(s) for s in (0.4, 45, 89.6, 125, 3 * 3600 + 61)] == \
        ["0 s", "45 s", "90 s", "2 min 05 s", "3 h 01 min"]
    assert duration_text(None) == duration_text(math.nan) == "unknown"
    assert md_cell("a|b\nc") == "a\\|b c"


def test_sweep_lines():
    assert sweep_text("da", 3.2, 45.0) == "da: sweeping 3.2 rad/s, 45 s to the band top"
    assert sweep_text("da", 0.437, 130.0) == "da: sweeping 0.44 rad/s, 2 min 10 s to the band top"
    assert sweep_text("dr", 18.4, 0.0) == "dr: sweeping 18 rad/s, band top reached"
    assert sweep_text("dr", 5.0, None) == "dr: sweeping 5 rad/s, time to the band top unknown"
    assert sweep_text("de", None, 30.0) == "de: not sweeping"
    assert coherence_kind_text("partial") == "partial γ² (MISO-conditioned)"
    with pytest.raises(ValueError, match="coherence_kind"):
        coherence_kind_text("multiple")


def test_adequacy_markdown_rows():
    md = adequacy_markdown(12.0, [{"output": "p", "input": "da", "band": (0.3, 2.5), "fraction": 0.5999},
                                  {"output": "r", "input": "da", "band": None, "fraction": 0.0},
                                  {"output": "ay", "input": "da", "band": (0.3, 20.0), "fraction": 1.0,
                                   "verdict": "required | GO"}],
                           "NO-GO", [], coherence_kind="partial", sweep={"da": (3.2, 45.0)})
    lines = md.splitlines()
    assert lines[0] == "## NO-GO"                        # the verdict first, as a heading
    assert "Flight time 12.0 s. Coherence judged: **partial γ² (MISO-conditioned)**, threshold γ² ≥ 0.6" in lines
    assert "- da: sweeping 3.2 rad/s, 45 s to the band top" in lines
    assert "| p/da | 0.3 – 2.5 | 59.9 % | partly adequate |" in lines
    assert "| r/da | — | 0 % | not adequate |" in lines
    assert "| ay/da | 0.3 – 20 | 100 % | required \\| GO |" in lines


def test_test_points_markdown_mixed_kinds_and_empty():
    assert markdown_test_points([], 0.0) == "*No test point yet.*\n"
    tp = {"state": "closed", "start_s": 10.0, "end_s": 250.0, "source": "autopilot", "swept_input": "da",
          "verdict": "NO-GO",
          "pairs": [{"output": "p", "input": "da", "adequate_fraction": 0.61, "band_rad_s": [0.3, 20.0],
                     "coherence": "partial"},
                    {"output": "r", "input": "da", "adequate_fraction": 0.2, "band_rad_s": None,
                     "coherence": "ordinary"}],
          "missing": ["r/da needs 0.3-20 rad/s: coherence below 0.6 there"]}
    md = markdown_test_points([(4, tp)], 300.0)
    assert md.startswith("**Test point 4 (closed): NO-GO**, sweeping da, 10.0 – 250.0 s (4 min 00 s), "
                         "found by autopilot\n")
    assert "| p/da (partial γ²) | 0.3 – 20 | 61 % | adequate | — |" in md
    assert "| r/da (ordinary γ²) | — | 20 % | NOT adequate | 1 below |" in md
    assert "- r/da needs 0.3-20 rad/s: coherence below 0.6 there" in md
