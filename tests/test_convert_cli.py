"""`livesweep convert` on the command line: a delimited table with a column map, counts printed
and stored, and bad input as one line with exit 2 (real subprocess, real MCAP read back)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from livesweep.telemetry.mcap_log import read_metadata, read_topics_fields


def _run(*args):
    return subprocess.run([sys.executable, "-m", "livesweep", "convert", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def test_csv_with_a_column_map_converts_and_reports_counts(tmp_path):
    t = np.arange(200) * 0.02
    rows = ["time,elev,q"] + [f"{a:.2f},{np.sin(a):.6f},{np.cos(a):.6f}" for a in t]
    rows[51] = f"{t[50]:.2f},nan,0.5"                      # one bad cell: written as null, counted
    src = tmp_path / "flight.csv"
    src.write_text("\n".join(rows) + "\n")
    cmap = tmp_path / "map.toml"
    cmap.write_text('name = "test"\ntime = "t"\n[columns.t]\nheader = "time"\nunits = "s"\n'
                    '[columns.de]\nheader = "elev"\nscale = 2.0\nunits = "deg"\n')
    r = _run(src, "--out", tmp_path / "out.mcap", "--columns", cmap)
    assert r.returncode == 0, r.stderr
    assert "messages read 200, written 200" in r.stdout and "skipped: 1 nonfinite cells; repaired: none" in r.stdout
    got = read_topics_fields(tmp_path / "out.mcap", {"/table/test": ["de", "time_s"]})["/table/test"]
    expected = 2.0 * np.sin(t)
    expected[50] = np.nan
    np.testing.assert_allclose(got["de"], expected, atol=1e-5)
    np.testing.assert_allclose(got["time_s"], t, atol=1e-9)
    meta = read_metadata(tmp_path / "out.mcap")
    assert meta["source"]["name"] == "flight.csv" and meta["source"]["format"] == "text"
    assert json.loads(meta["conversion"]["skipped"]) == {"nonfinite_cells": 1}


def test_unknown_format_and_missing_column_are_one_line_exit_2(tmp_path):
    junk = tmp_path / "junk.bin"
    junk.write_bytes(bytes(range(256)) * 4)
    r = _run(junk, "--out", tmp_path / "o.mcap")
    assert r.returncode == 2 and "unknown or unsupported format" in r.stderr and str(junk) in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "o.mcap").exists()
    src = tmp_path / "a.csv"
    src.write_text("time,x\n0,1\n0.1,2\n")
    cmap = tmp_path / "m.toml"
    cmap.write_text('time = "t"\n[columns.t]\nheader = "time"\n[columns.y]\nheader = "nope"\n')
    r = _run(src, "--out", tmp_path / "o.mcap", "--columns", cmap)
    assert r.returncode == 2 and "nope" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "o.mcap").exists()
