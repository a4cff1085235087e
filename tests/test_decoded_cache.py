"""The decoded-column cache: a second read of a log gives exactly what decoding it gives, a log
changed in one byte is decoded again, a damaged entry or an unwritable folder costs only time,
and ``LIVESWEEP_CACHE=off`` writes nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from livesweep.config import RecordSpec, load_case
from livesweep.telemetry.mcap_log import read_topics_fields
from livesweep.telemetry.signals import read_signals

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "config" / "xv15_cruise_lateral.toml"


@pytest.fixture()
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("LIVESWEEP_CACHE_DIR", str(folder))
    monkeypatch.delenv("LIVESWEEP_CACHE", raising=False)
    return folder


def _read(log):
    case = load_case(CASE)
    notes: list[str] = []
    got = read_signals(RecordSpec(log=str(log)), case.signals, list(case.signals), notes=notes)
    return got, notes


def _same(a, b):
    assert list(a) == list(b)
    for k in a:
        np.testing.assert_array_equal(a[k].t_s, b[k].t_s)
        np.testing.assert_array_equal(a[k].values, b[k].values)
        assert a[k].source == b[k].source


def test_a_second_read_comes_from_the_cache_and_equals_a_decode(cache, tmp_path):
    log = tmp_path / "verify.mcap"
    log.write_bytes((ROOT / "replay_logs" / "xv15_cruise_verify.mcap").read_bytes())
    first, _ = _read(log)
    entries = list(cache.glob("*.npz"))
    assert len(entries) == 1
    second, _ = _read(log)
    _same(first, second)
    # and both equal the decoder itself, on a field the signals scale (p = xgyro in rad/s -> deg/s)
    cols = read_topics_fields(log, {"/mavlink/HIGHRES_IMU": ["xgyro"]})["/mavlink/HIGHRES_IMU"]
    np.testing.assert_allclose(second["p"].values, np.rad2deg(cols["xgyro"]), rtol=1e-12)
    # a copy under another name is the same content: no new entry
    other = tmp_path / "copy.mcap"
    other.write_bytes(log.read_bytes())
    _read(other)
    assert list(cache.glob("*.npz")) == entries


def test_a_changed_log_is_decoded_again(cache, tmp_path):
    log = tmp_path / "v.mcap"
    data = (ROOT / "replay_logs" / "xv15_cruise_verify.mcap").read_bytes()
    log.write_bytes(data)
    _read(log)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])          # torn: a different file, with a note
    got, notes = _read(cut)
    got2, notes2 = _read(cut)                            # the note comes back from the cache too
    assert len(list(cache.glob("*.npz"))) == 2
    assert any("unfinished" in n for n in notes) and notes2 == notes
    _same(got, got2)


def test_a_damaged_entry_or_no_cache_costs_only_time(cache, tmp_path, monkeypatch):
    log = tmp_path / "v.mcap"
    log.write_bytes((ROOT / "replay_logs" / "xv15_cruise_verify.mcap").read_bytes())
    want, _ = _read(log)
    (entry,) = cache.glob("*.npz")
    entry.write_bytes(b"PK\x03\x04 not a zip")
    got, _ = _read(log)
    _same(want, got)
    monkeypatch.setenv("LIVESWEEP_CACHE", "off")
    for e in cache.glob("*.npz"):
        e.unlink()
    got, _ = _read(log)
    _same(want, got)
    assert not list(cache.glob("*.npz"))
    monkeypatch.delenv("LIVESWEEP_CACHE")
    monkeypatch.setenv("LIVESWEEP_CACHE_DIR", str(tmp_path / "file"))
    (tmp_path / "file").write_text("a file, not a folder")          # cannot be created
    got, _ = _read(log)
    _same(want, got)


def test_the_cache_keeps_to_its_size_by_dropping_the_least_recently_used(cache, tmp_path, monkeypatch):
    import os

    data = (ROOT / "replay_logs" / "xv15_cruise_verify.mcap").read_bytes()
    logs = []
    for k in range(3):
        log = tmp_path / f"v{k}.mcap"
        log.write_bytes(data[: len(data) - 1000 * (k + 1)])        # three different (torn) logs
        logs.append(log)
    _read(logs[0])
    size = next(cache.glob("*.npz")).stat().st_size
    monkeypatch.setenv("LIVESWEEP_CACHE_MB", str(2.5 * size / 1e6))  # room for two entries
    first = next(cache.glob("*.npz"))
    os.utime(first, (1, 1))                                           # the oldest use
    _read(logs[1])
    _read(logs[2])
    left = list(cache.glob("*.npz"))
    assert len(left) == 2 and first not in left


@pytest.mark.parametrize("bad", ["lots", "-5", "nan"])
def test_a_bad_size_setting_is_named(cache, tmp_path, monkeypatch, bad):
    from livesweep.errors import ConfigError

    log = tmp_path / "v.mcap"
    log.write_bytes((ROOT / "replay_logs" / "xv15_cruise_verify.mcap").read_bytes())
    monkeypatch.setenv("LIVESWEEP_CACHE_MB", bad)
    with pytest.raises(ConfigError, match=f"LIVESWEEP_CACHE_MB = '{bad}': must be a number of megabytes"):
        _read(log)
