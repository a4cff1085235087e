"""Transfer-function structures beyond livesweep.limits.MAX_TF_ORDER are refused when the case is
loaded, with one line naming the file, the key and the value; a report whose figures could not be
computed (None in report.json) is summarised with "n/a", never a crash."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from livesweep.config import load_case
from livesweep.errors import ConfigError
from livesweep.ident.transfer_function import parse_structure
from livesweep.limits import MAX_TF_ORDER
from livesweep.stages.identify import parse_case_specs
from livesweep.report.html import _transfer_functions
from livesweep.report.summary import stage_summary
from test_case_limits import CASE as BASE_CASE

CASE = BASE_CASE + """
[transfer_functions.y_u]
output = "y"
input = "u"
numerator = NUM
denominator = DEN
"""

FIRST_500 = " ".join(f"(1/T{k})" for k in range(500))


def _case(tmp_path: Path, num: str, den: str = '"[zeta, w]"') -> Path:
    (tmp_path / "a.mcap").write_bytes(b"x")
    p = tmp_path / "case.toml"
    p.write_text(CASE.replace("NUM", num).replace("DEN", den))
    return p


@pytest.mark.parametrize("num, den, key, words", [
    ('"s^500"', '"[zeta, w]"', "numerator", ["'s^500'", "order 500", str(MAX_TF_ORDER)]),
    (f'"{FIRST_500}"', '"[zeta, w]"', "numerator", ["(1/T0) (1/T1)", f"order {MAX_TF_ORDER + 1} or more"]),
    ('"s"', '"' + " ".join(f"[z{k}, w{k}]" for k in range(250)) + '"', "denominator", ["[z0, w0]", "or more"]),
    ('"21"', '"2"', "numerator", ["'21'", "order 21"]),
    ('"s^' + "9" * 5000 + '"', '"2"', "numerator", ["s^999", "or more"]),
    ('"' + "9" * 5000 + '"', '"2"', "numerator", ["999", str(MAX_TF_ORDER)]),
])
def test_orders_beyond_the_limit_are_refused_at_load(tmp_path, num, den, key, words):
    path = _case(tmp_path, num, den)
    with pytest.raises(ConfigError) as e:
        parse_case_specs(load_case(path))
    msg = str(e.value)
    assert str(path) in msg and f"transfer_functions.y_u.{key}:" in msg, msg
    assert "\n" not in msg and len(msg) < 600, msg
    for w in words:
        assert w in msg, (w, msg)


def test_the_limit_itself_is_accepted():
    assert parse_structure("s^2 " + " ".join(f"(1/T{k})" for k in range(MAX_TF_ORDER - 2))).order == MAX_TF_ORDER
    assert parse_structure(str(MAX_TF_ORDER)).order == MAX_TF_ORDER


@pytest.mark.slow
def test_cli_refuses_the_case_in_one_line(tmp_path):
    path = _case(tmp_path, f'"{FIRST_500}"')
    run = subprocess.run([sys.executable, "-m", "livesweep", "identify", str(path), "--out", str(tmp_path / "out")],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "transfer_functions.y_u.numerator" in lines[0] and str(path) in lines[0], run.stderr
    assert not (tmp_path / "out" / "report.json").exists()


def _report_with_undefined_figures() -> dict:
    tf = {"name": "p_da", "output": "p", "input": "da", "gain": None, "delay_s": None, "cost": None,
          "converged": False, "cramer_rao_pct": {"gain": None}, "factors": [], "band_rad_s": [1.0, 10.0]}
    ver = {"label": "doublet", "j_rms": None, "passed": False,
           "outputs": [{"name": "p", "tic": None, "units": "deg/s"}]}
    return {"stages": ["transfer-functions", "verification"], "transfer_functions": [tf],
            "verification": {"records": [ver], "outputs": ver["outputs"], "j_rms": None}}


def test_summary_prints_undefined_figures_as_n_a_and_flags_them():
    rows = {r["stage"]: r for r in stage_summary(_report_with_undefined_figures())}
    tf = rows["transfer-functions"]
    assert tf["result"] == "p_da J n/a" and tf["status"] == "flag"
    assert any("J not finite" in f for f in tf["flags"]), tf["flags"]
    ver = rows["verification"]
    assert ver["result"] == "doublet: J_rms n/a"
    assert any("J_rms = n/a" in f for f in ver["flags"]) and any("p n/a" in f for f in ver["flags"]), ver["flags"]


def test_html_transfer_function_table_shows_an_undefined_cost():
    html = _transfer_functions(_report_with_undefined_figures())
    row = html[html.index("<td>p_da</td>"):]
    assert "<td class='num flag'>—</td>" in row, row
