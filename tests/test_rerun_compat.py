"""The adapter around rerun-sdk internals (livesweep.monitor.rerun_compat): the version check, the
public-API fallback, and that an .rrd written through the fallback holds the same data as one
written through the internal path (read back with RrdReader, as tests/test_rerun_view.py does)."""

from __future__ import annotations

import logging
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from livesweep.monitor import rerun_compat
from livesweep.monitor.rerun_view import RerunView

INPUTS = ["de", "da"]
OUTPUTS = ["q", "p"]
UNITS = ["deg", "deg", "deg/s", None]


@pytest.fixture
def fresh(monkeypatch):
    """The adapter as in a new process: nothing logged yet, the internal builder not yet checked."""
    monkeypatch.setattr(rerun_compat, "_said", set())
    rerun_compat._internal.cache_clear()
    yield rerun_compat
    rerun_compat._internal.cache_clear()


def _write(path, *, focus_omega):
    """One .rrd with every kind of data the view logs: time series, two estimates (a gap in one
    curve), waterfall rows, the focus plots, test points, a verdict and alerts."""
    view = RerunView(INPUTS, OUTPUTS, recording_id="compat", save_path=path, waterfall_rows=3)
    t = np.arange(600) / 100.0
    k = np.arange(4)[:, None]
    values = np.sin(2 * np.pi * (0.4 + 0.3 * k) * t) * (1.0 + k)
    view.log_alerts(None, [("link", "before any data")])
    view.log_timeseries(t[:250], INPUTS + OUTPUTS, values[:, :250], ["input"] * 2 + ["output"] * 2)
    view.log_timeseries(t[250:], INPUTS + OUTPUTS, values[:, 250:], ["input"] * 2 + ["output"] * 2, units=UNITS)
    omega = np.logspace(np.log10(0.5), np.log10(40.0), 50)
    x = np.log10(omega)[None, None, :]
    o = np.arange(len(OUTPUTS))[:, None, None]
    i = np.arange(len(INPUTS))[None, :, None]
    for n, te in enumerate((3.0, 5.0)):
        coh = np.clip(0.5 + 0.45 * np.sin(3.0 * x + o + 2.0 * i + n), 0.0, 1.0)
        mag = -20.0 * x * (1 + o) + 3.0 * i + 0.37 * n
        pha = -90.0 - 400.0 * x * (1 + i) - 5.0 * o
        if n:
            mag[1, 0, 10:13] = np.nan
            coh[0, 1, 5] = np.nan
        rows = [{"output": a, "input": b, "band": (1.0, 10.0), "fraction": 0.2 * (n + 1)}
                for a in OUTPUTS for b in INPUTS]
        view.log_estimate(te, omega, OUTPUTS, INPUTS, coh, mag, pha, rows, "WAIT", [f"reason {n}"],
                          coherence_kind=("ordinary", "partial")[n], sweep={"de": (2.0 + n, 30.0)},
                          band_rad_s=(0.5, 40.0))
    w = focus_omega
    response = SimpleNamespace(omega=w, coherence=np.clip(0.3 + 0.6 * np.cos(np.log10(w)), 0, 1),
                               H=10.0 / (1j * w * (1j * w / 5.0 + 1.0)), conditioned=True)
    tp = {"state": "open", "start_s": 1.0, "end_s": None, "source": "marker", "swept_input": "de",
          "verdict": "WAIT", "pairs": [], "missing": []}
    view.log_test_point(4.0, tp)
    view.log_focus(4.0, response, "TP 1 q/de: GO so far")
    view.log_test_point(5.5, {**tp, "state": "closed", "end_s": 5.5, "verdict": "GO"})
    view.log_verdict(5.5, "GO", ["last test point: GO"])
    view.log_alerts(5.5, [("coverage", "no energy below 0.8 rad/s")])
    path_used = view._plots.arrays.name
    view.close()
    return path_used


def _rows(path):
    """Every row of the recording as (entity, column, its field metadata, its Arrow type, time)
    -> the values in the order they were logged (the properties entity, which holds the
    recording's start time, left out)."""
    out: dict = {}
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.entity_path == "/__properties":
            continue
        rb = chunk.to_record_batch()
        names = rb.schema.names
        row_ids = rb.column("rerun.controls.RowId").to_pylist()
        times = rb.column("flight_time").cast("int64").to_pylist() if "flight_time" in names else [None] * rb.num_rows
        for name in names:
            if name in ("rerun.controls.RowId", "flight_time"):
                continue
            field = rb.schema.field(name)
            meta = tuple(sorted((field.metadata or {}).items()))
            for row_id, t, v in zip(row_ids, times, rb.column(name).to_pylist()):
                if v is None:
                    continue          # a column of another archetype logged in the same chunk
                out.setdefault((chunk.entity_path, name, meta, str(field.type), t), []).append((row_id, repr(v)))
    return {k: [v for _, v in sorted(rows)] for k, rows in out.items()}


def test_the_version_check_knows_the_releases_it_was_written_for():
    assert rerun_compat.known_version("0.41.0") and rerun_compat.known_version("0.41.7")
    assert not rerun_compat.known_version("0.42.0")
    assert not rerun_compat.known_version("1.0")
    assert not rerun_compat.known_version("")
    assert rerun_compat.known_version() == rerun_compat.known_version(rr.__version__)


def test_an_unknown_version_uses_the_public_api_and_says_so_once(fresh, caplog):
    with caplog.at_level(logging.INFO, logger=rerun_compat.__name__):
        assert fresh.arrays("9.9.0").name == "public"
        assert fresh.arrays("9.9.0").name == "public"
    said = [r.getMessage() for r in caplog.records if r.name == rerun_compat.__name__]
    assert len(said) == 1 and "public" in said[0] and "9.9.0" in said[0], said


def test_missing_internals_fall_back_to_the_public_api(fresh, monkeypatch, caplog):
    monkeypatch.setitem(sys.modules, "rerun.encodings.tensor_data_ext", None)     # the import fails
    with caplog.at_level(logging.INFO, logger=rerun_compat.__name__):
        chosen = fresh.arrays(f"{rerun_compat.KNOWN_VERSIONS[0]}.0")
    assert chosen.name == "public"
    said = [r.getMessage() for r in caplog.records if r.name == rerun_compat.__name__]
    assert len(said) == 1 and "tensor_data_ext" in said[0], said


def test_both_paths_build_identical_arrays():
    fast, public = rerun_compat.InternalArrays(), rerun_compat.PublicArrays()
    rng = np.random.default_rng(3)
    img = rng.integers(0, 101, (4, 15)).astype(np.uint8)
    v = rng.random(9)
    strips = [rng.random((5, 2), dtype=np.float32), rng.random((1, 2), dtype=np.float32)]
    xy = rng.random((7, 2), dtype=np.float32)
    pairs = [(fast.tensor(img, ("a", "b")), public.tensor(img, ("a", "b"))), (fast.tensor(v), public.tensor(v)),
             (fast.strips(strips), public.strips(strips)), (fast.strips([]), public.strips([])),
             (fast.points(xy), public.points(xy)), (fast.points(xy[:0]), public.points(xy[:0]))]
    for a, b in pairs:
        assert a.type == b.type and a.equals(b)


def test_the_fallback_writes_the_same_rrd_as_the_internal_path(fresh, monkeypatch, tmp_path):
    focus_omega = np.logspace(np.log10(0.3), np.log10(30.0), 40)
    if fresh.arrays().name != "internal":
        pytest.skip(f"rerun-sdk {rr.__version__}: the internal path is not available to compare with")
    assert _write(tmp_path / "internal.rrd", focus_omega=focus_omega) == "internal"
    monkeypatch.setattr(rerun_compat, "known_version", lambda version=None: False)
    assert _write(tmp_path / "public.rrd", focus_omega=focus_omega) == "public"

    internal, public = _rows(tmp_path / "internal.rrd"), _rows(tmp_path / "public.rrd")
    entities = {k[0] for k in internal}
    for e in ("/spectra/q_de/coherence", "/spectra/q_de/waterfall", "/focus/coherence", "/telemetry/inputs/de"):
        assert e in entities, sorted(entities)
    columns = {k[1] for k in internal}
    assert {"Tensor:data", "LineStrips2D:strips", "Points2D:positions", "Scalars:scalars"} <= columns, columns
    assert internal.keys() == public.keys()
    for key in internal:
        assert internal[key] == public[key], key
