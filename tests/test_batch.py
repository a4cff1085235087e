"""`livesweep batch`: many identifications in worker processes (a local process pool and a real
Dask LocalCluster), resumable by fingerprint. Small frequency-response-only cases on the shipped
replay logs; every report is compared number for number with a direct `livesweep identify` run."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from livesweep import cli
from livesweep.batch import add_batch_arguments, find_cases, fingerprint, run_batch
from livesweep.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
LOGS = ROOT / "replay_logs"
STAGE = "frequency-response"
FR_KEYS = ("omega_rad_s", "magnitude_db", "phase_deg", "coherence", "random_error")


def _signals_text() -> str:
    text = (ROOT / "config" / "xv15_channels.toml").read_text()
    return text[text.index("[signals.da]"):text.index("[spectral]")]


def _case_text(name: str, log: Path, band=(0.5, 15.0)) -> str:
    return (f'[case]\nname = "{name}"\naircraft = "XV-15"\n\n[[identify]]\nlog = "{log}"\nlabel = "aileron sweeps"\n\n'
            + _signals_text()
            + f'[spectral]\ninputs = ["da"]\noutputs = ["p", "phi"]\nband_rad_s = [{band[0]}, {band[1]}]\n'
              'windows_s = [10.0, 40.0]\nsample_rate_hz = 50.0\n')


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    d = tmp_path_factory.mktemp("cases")
    (d / "a_cruise.toml").write_text(_case_text("cruise da", LOGS / "xv15_cruise_sweeps_da.mcap"))
    (d / "b_hover.toml").write_text(_case_text("hover/da", LOGS / "xv15_hover_sweeps_da.mcap"))
    (d / "c_broken.toml").write_text(_case_text("broken", LOGS / "no_such_log.mcap"))
    shutil.copy(ROOT / "config" / "xv15_channels.toml", d / "channels.toml")    # a channel map, not a case
    (d / "notes.toml").write_text('title = "flight 12"\n')                      # some other TOML
    (d / "README.txt").write_text("[case]\n")
    return {"dir": d, "a": d / "a_cruise.toml", "b": d / "b_hover.toml", "c": d / "c_broken.toml"}


def _responses(report: dict) -> dict:
    return {(r["output"], r["input"]): r for r in report["frequency_responses"]}


def _assert_same_responses(got: dict, want: dict) -> None:
    # same code, same data, another process: only floating-point evaluation order may differ
    g, w = _responses(got), _responses(want)
    assert g.keys() == w.keys() and len(g) == 2
    for pair in w:
        for key in FR_KEYS:
            a, b = (np.array(x[pair][key], dtype=float) for x in (g, w))     # null (non-finite) -> nan
            assert a.size == 150
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=f"{pair} {key}")


@pytest.fixture(scope="module")
def local_run(cases, tmp_path_factory):
    out = tmp_path_factory.mktemp("batch")
    calls = []
    rows = run_batch([cases["a"], cases["b"], cases["c"]], out, stage=STAGE, workers=2,
                     progress=lambda done, total, row: calls.append((done, total, row["status"])))
    reports = {k: json.loads((Path(rows[i]["out"]) / "report.json").read_text()) for i, k in enumerate("ab")}
    return {"out": out, "rows": rows, "calls": calls, "reports": reports}


@pytest.mark.slow
def test_local_pool_runs_each_case_like_identify_and_reports_the_broken_one(cases, local_run, tmp_path):
    out, rows = local_run["out"], local_run["rows"]
    assert [r["status"] for r in rows] == ["ok", "ok", "failed"]
    assert [Path(r["out"]).name for r in rows] == ["cruise_da", "hover_da", "broken"]   # filesystem-safe names
    assert sorted(local_run["calls"]) == [(1, 3, "failed"), (2, 3, "ok"), (3, 3, "ok")]
    for key, row in zip("ab", rows):
        # a direct `livesweep identify` of the same case gives the same frequency responses
        direct = tmp_path / f"direct_{key}"
        assert cli.main(["identify", str(cases[key]), "--out", str(direct), "--stage", STAGE]) == 0
        want = json.loads((direct / "report.json").read_text())
        _assert_same_responses(local_run["reports"][key], want)
        # the summary row is read off the report: the adequate band of each pair, nothing parametric
        assert row["pairs"] == 2
        assert row["band_rad_s"] == {f"{e['output']}/{e['input']}": e["widest_band_rad_s"]
                                     for e in want["data_quality"]["excitation"]}
        assert row["band_rad_s"]["p/da"][0] >= 0.5 and row["band_rad_s"]["p/da"][1] <= 15.0
        assert row["J"] is None and row["TIC"] is None and row["residual"] is None and row["error"] is None
        log = (Path(row["out"]) / "identify.log").read_text()
        assert "frequency responses from 1 record(s)" in log and "wrote" in log
    summary = json.loads((out / "summary.json").read_text())
    assert [r["status"] for r in summary] == ["ok", "ok", "failed"]
    err = summary[2]["error"]
    assert "no_such_log.mcap" in err and "does not exist" in err and "\n" not in err
    lines = (out / "summary.txt").read_text().splitlines()
    body = [ln for ln in lines[2:] if not ln.lstrip().startswith("error:")]
    assert len(body) == 3
    assert body[0].split()[:4] == ["cruise", "da", "ok", "2/2"] and body[2].split()[:2] == ["broken", "failed"]


@pytest.mark.slow
def test_resume_skips_current_cases_and_reruns_changed_or_forced_ones(cases, local_run):
    out = local_run["out"]
    before = {p: p.stat().st_mtime_ns for p in out.rglob("report.json")}
    rows = run_batch([cases["a"], cases["b"], cases["c"]], out, stage=STAGE, workers=2)
    assert [r["status"] for r in rows] == ["skipped", "skipped", "failed"]
    # no case was run again: its report is the one written before, untouched
    assert {p: p.stat().st_mtime_ns for p in out.rglob("report.json")} == before
    assert [r["band_rad_s"] for r in rows[:2]] == [r["band_rad_s"] for r in local_run["rows"][:2]]

    text = cases["a"].read_text()
    try:
        cases["a"].write_text(text.replace("band_rad_s = [0.5, 15.0]", "band_rad_s = [0.8, 10.0]"))
        rows = run_batch([cases["a"], cases["b"]], out, stage=STAGE, workers=2)
        assert [r["status"] for r in rows] == ["ok", "skipped"]
        omega = _responses(json.loads((out / "cruise_da" / "report.json").read_text()))[("p", "da")]["omega_rad_s"]
        assert omega[0] == pytest.approx(0.8) and omega[-1] == pytest.approx(10.0)
    finally:
        cases["a"].write_text(text)
    rows = run_batch([cases["b"]], out, stage=STAGE, force=True)
    assert [r["status"] for r in rows] == ["ok"]
    _assert_same_responses(json.loads((out / "hover_da" / "report.json").read_text()), local_run["reports"]["b"])
    # a different last stage is a different result
    assert fingerprint(cases["b"], STAGE) != fingerprint(cases["b"], "transfer-functions")


@pytest.mark.slow
def test_dask_cluster_gives_the_local_numbers(cases, local_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        rows = run_batch([cases["a"], cases["b"], cases["c"]], tmp_path / "dask", stage=STAGE,
                         dask_address=cluster.scheduler_address)
    assert [r["status"] for r in rows] == ["ok", "ok", "failed"]
    for key, row in zip("ab", rows):
        _assert_same_responses(json.loads((Path(row["out"]) / "report.json").read_text()), local_run["reports"][key])
        assert row["band_rad_s"] == local_run["rows"]["ab".index(key)]["band_rad_s"]


def test_find_cases_takes_case_files_from_folders(cases):
    d = cases["dir"]
    assert find_cases([d]) == [cases["a"].resolve(), cases["b"].resolve(), cases["c"].resolve()]
    assert find_cases([cases["b"], d, str(cases["a"])]) == find_cases([d])        # de-duplicated, sorted
    assert find_cases([d / "channels.toml"]) == [(d / "channels.toml").resolve()]  # a file is taken as given
    with pytest.raises(ConfigError, match="nowhere.toml"):
        find_cases([d, d / "nowhere.toml"])


def test_fingerprint_follows_log_content_not_its_mtime(cases, tmp_path):
    log = tmp_path / "sweeps.mcap"
    shutil.copy(LOGS / "xv15_cruise_sweeps_da.mcap", log)
    case = tmp_path / "case.toml"
    case.write_text(_case_text("fp", log))
    fp = fingerprint(case, STAGE)
    log.touch()
    assert fingerprint(case, STAGE) == fp
    data = bytearray(log.read_bytes())
    data[len(data) // 2] ^= 0xFF
    log.write_bytes(bytes(data))
    assert fingerprint(case, STAGE) != fp


@pytest.mark.slow
def test_cli_progress_table_exit_code_and_clashing_names(cases, local_run, tmp_path, capsys):
    # two broken cases with the same name: their own folders; failures are rows, not exceptions
    twin = tmp_path / "twin.toml"
    twin.write_text(_case_text("broken", LOGS / "missing_too.mcap"))
    parser = add_batch_arguments(argparse.ArgumentParser())
    args = parser.parse_args([str(cases["c"]), str(twin), "--out", str(tmp_path / "out"), "--stage", STAGE])
    assert args.func(args) == 1
    text = capsys.readouterr().out
    assert "[1/2] broken failed" in text and "[2/2] broken failed" in text and "missing_too.mcap" in text
    rows = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert sorted(Path(r["out"]).name for r in rows) == ["broken", "broken-2"]
    again = json.loads(json.dumps(run_batch([twin, cases["c"]], tmp_path / "out", stage=STAGE)))
    assert {r["case"]: r["out"] for r in again} == {r["case"]: r["out"] for r in rows}   # folders stay put
    # every case current: exit 0
    args = parser.parse_args([str(cases["b"]), "--out", str(local_run["out"]), "--stage", STAGE])
    assert args.func(args) == 0
    assert "[1/1] hover/da skipped" in capsys.readouterr().out
