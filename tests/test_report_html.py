"""report.html of the shipped cruise case, parsed: the first screen summarises every stage with its
flags, every derivative has units, the mode table is the model's eigenvalues (numpy on the
exported A matrix), and no Python repr, NaN text or missing image reaches the page."""

import base64
import json
import re
from html.parser import HTMLParser

import numpy as np
import pytest

from livesweep.report.summary import stage_summary


class _Page(HTMLParser):
    """Tables (by the heading before them) as lists of rows of cell texts, images, visible text."""

    def __init__(self):
        super().__init__()
        self.tables, self.images, self.text = [], [], []
        self._heading, self._in_heading, self._row, self._cell, self._skip = "", False, None, None, 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag in ("style", "script"):
            self._skip += 1
        if tag in ("h1", "h2", "h3"):
            self._in_heading, self._heading = True, ""
        elif tag == "table":
            self.tables.append((self._heading, []))
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "img":
            self.images.append(a.get("src", ""))

    def handle_endtag(self, tag):
        if tag in ("style", "script"):
            self._skip -= 1
        if tag in ("h1", "h2", "h3"):
            self._in_heading = False
        elif tag in ("td", "th") and self._cell is not None and self._row is not None:
            self._row.append(" ".join("".join(self._cell).split()))
            self._cell = None
        elif tag == "tr" and self._row is not None and self.tables:
            self.tables[-1][1].append(self._row)
            self._row = None

    def handle_data(self, data):
        if self._skip:
            return
        self.text.append(data)
        if self._in_heading:
            self._heading += data
        if self._cell is not None:
            self._cell.append(data)

    def table(self, heading_start):
        return next(rows for h, rows in self.tables if h.strip().startswith(heading_start))


@pytest.fixture(scope="module")
def page(cruise_report_dir):
    out, report, _ = cruise_report_dir
    p = _Page()
    p.feed((out / "report.html").read_text())
    return p, report, out


def test_the_first_screen_summarises_every_stage_with_its_flags(page):
    p, report, _ = page
    rows = p.table("Summary")[1:]
    assert [r[0] for r in rows] == report["stages"] == ["frequency-response", "transfer-functions", "state-space",
                                                        "verification", "residual-loop"]
    want = {s["stage"]: s for s in stage_summary(report)}
    for stage, badge, text in rows:
        s = want[stage]
        assert badge == ("PASS" if s["status"] == "pass" else "FLAG")
        for flag in s["flags"]:
            assert " ".join(flag.split()) in text
    # the shipped logs sweep each axis on its own: beta/da and ay/da are poorly excited, and the
    # report says so on its first screen (their adequate fraction is under half the band)
    fr = dict((r[0], r[2]) for r in rows)["frequency-response"]
    assert "beta/da" in fr and "ay/da" in fr
    logs = p.table("Input logs")[1:]
    assert [r[2] for r in logs] == [r["name"] for r in report["inputs"]] and all(len(r[3]) == 16 for r in logs)
    assert report["generated_utc"].endswith("UTC") and report["livesweep_version"] in "".join(p.text)


def test_every_derivative_has_units(page):
    p, report, _ = page
    rows = p.table("State-space model")
    head, body = rows[0], rows[1:]
    assert head[:3] == ["parameter", "value", "units"]
    assert {r[0] for r in body} == {q["name"] for q in report["state_space"]["parameters"]}
    units = {r[0]: r[2] for r in body}
    assert all(u and u != "see the model" for u in units.values()), units
    # independent of the code's unit algebra: L derivatives are (rad/s^2) per unit, rates cancel to 1/s
    assert units["Lp"] == units["Nr"] == "1/s"
    assert units["Lda"] == "(rad/s²)/deg" and units["Lv"] == "(rad/s²)/(ft/s)" and units["tau_a"] == "s"


def test_the_mode_table_is_the_models_eigenvalues(page):
    p, report, _ = page
    A = np.array(report["state_space"]["matrices"]["A"], float)
    eig = np.linalg.eigvals(A)
    rows = p.table("Modes")[1:]
    got = []
    for name, lam, wn, zeta, *_ in rows:
        nums = [float(x) for x in re.findall(r"[-+]?\d+\.?\d*(?:e[-+]?\d+)?", lam)]
        if "±" in lam:
            re_, im = nums[0], nums[1]
            got += [complex(re_, im), complex(re_, -im)]
            assert float(wn) == pytest.approx(abs(complex(re_, im)), rel=2e-3)
            assert float(zeta) == pytest.approx(-re_ / abs(complex(re_, im)), abs=2e-3)
        else:
            got.append(complex(nums[0], 0.0))
    assert len(got) == len(eig)
    assert sorted(r[0] for r in rows) == ["Dutch roll", "roll subsidence", "spiral"]
    for e in eig:                                          # nearest neighbour, to the 4 digits shown
        assert min(abs(e - g) for g in got) <= 1e-3 * max(1.0, abs(e))


def test_no_python_repr_nan_or_missing_image(page):
    p, report, out = page
    text = " ".join(p.text)
    for bad in ("None", "nan", "NaN", "inf", "{'", "[{", "'kind'", "e+2", "e+1"):
        assert not re.search(rf"(?<![A-Za-z]){re.escape(bad)}(?![A-Za-z])", text), bad
    assert len(p.images) == len(report["frequency_responses"]) + 1 + 1          # Bode per pair, verification, loop step
    for src in p.images:
        assert src.startswith("data:image/svg+xml;base64,")
        assert base64.b64decode(src.split(",", 1)[1]).startswith(b"<svg ")
    for r in report["frequency_responses"]:
        assert (out / r["plot"]).is_file()
    assert json.loads((out / "report.json").read_text())["stages"] == report["stages"]
