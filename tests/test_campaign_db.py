"""The campaign database (livesweep.campaign): every flight and test point of real logs, added
once, atomically, by concurrent writers; damaged files skipped; the CLI."""

from __future__ import annotations

import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

import livesweep.campaign as campaign
from conftest import SITL_LOGS, _shared_data

DATA = _shared_data()
TLOGS = sorted((DATA / "mavlink_tlog").glob("*.tlog"))
BINS = [SITL_LOGS["roll"], SITL_LOGS["pitch"]]


def _need(*paths):
    missing = [str(p) for p in paths if not Path(p).is_file()]
    if missing or not TLOGS:
        pytest.skip(f"shared data not found: {', '.join(missing) or DATA / 'mavlink_tlog'}")


def _reference(log: Path) -> list[tuple[int, float, float]]:
    """pymavlink's reading of the SystemID texts: ``(axis, start [s, TimeUS], end [s, TimeUS])``."""
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(log), zero_time_base=True)
    out, open_ = [], None
    while (m := r.recv_match(type=["MSG"])) is not None:
        if m.Message.startswith("SystemID Starting: axis="):
            open_ = (int(m.Message.split("=")[1]), m.TimeUS * 1e-6)
        elif m.Message == "SystemID Finished" and open_ is not None:
            out.append((*open_, m.TimeUS * 1e-6))
            open_ = None
    return out


def _snapshot(db: Path) -> dict:
    con = sqlite3.connect(db)
    try:
        return {t: con.execute(f"SELECT * FROM {t} ORDER BY id").fetchall() for t in ("flights", "test_points")}
    finally:
        con.close()


def _consistent(db: Path) -> dict:
    """integrity_check ok, no orphan test points, every flight with all its test points (numbered 1..N)."""
    con = sqlite3.connect(db)
    try:
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert con.execute("PRAGMA foreign_key_check").fetchall() == []
        assert con.execute("SELECT COUNT(*) FROM test_points WHERE flight_id NOT IN (SELECT id FROM flights)"
                           ).fetchone()[0] == 0
        per = dict(con.execute("SELECT f.path, COUNT(t.id) FROM flights f LEFT JOIN test_points t "
                               "ON t.flight_id = f.id GROUP BY f.id"))
        for fid, n, top in con.execute("SELECT flight_id, COUNT(*), MAX(number) FROM test_points GROUP BY flight_id"):
            assert n == top, (fid, n, top)
        return per
    finally:
        con.close()


@pytest.fixture(scope="module")
def added(tmp_path_factory):
    _need(*BINS)
    db = tmp_path_factory.mktemp("campaign") / "c.db"
    with campaign.open(db) as c:
        report = c.add([*BINS, *TLOGS])
    return db, report


@pytest.mark.slow
def test_every_systemid_test_point_at_the_autopilots_own_times(added):
    db, report = added
    assert report.skipped == () and report.unchanged == ()
    got = dict(report.added)
    for tlog in TLOGS:
        assert got[str(tlog)] == 0                     # a tlog without SystemID: no test points
    with campaign.open(db) as c:
        assert c.schema_version == campaign.SCHEMA_VERSION
        flights = {Path(f.path).name: f for f in c.flights()}
        assert {f.format for f in flights.values()} == {"dataflash", "tlog"}
        for log in BINS:
            ref = _reference(log)
            assert ref, log
            fl = flights[log.name]
            assert fl.sha256 == campaign.sha256_of(log)
            tps = c.test_points(flight=fl.id)
            assert [tp.number for tp in tps] == list(range(1, len(ref) + 1))
            for tp, (axis, t0, t1) in zip(tps, ref):
                assert (tp.source, tp.verdict, tp.axis) == ("autopilot", None, axis)
                assert abs(tp.start_s - t0) < 0.01 and abs(tp.end_s - t1) < 0.01, (tp, t0, t1)
            # the run whose signals the filtered copy keeps is said to have data
            assert [tp.axis for tp in tps if tp.record_dict["data"]] == [7 if "roll" in log.name else 8]
        # queries: by axis, by flight SHA prefix, by condition range
        assert len(c.test_points(axis=7)) == 2
        assert len(c.test_points(flight=flights[BINS[0].name].sha256[:10])) == len(_reference(BINS[0]))
        assert {tp.axis for tp in c.test_points(conditions={"magnitude": (12, 20)})} == {7, 8}
        assert {tp.axis for tp in c.test_points(conditions={"magnitude": (None, 6)})} == {1}
        assert c.test_points(verdict="GO") == [] and len(c.test_points(verdict="none")) == 8


@pytest.mark.slow
def test_adding_again_changes_nothing_even_under_another_path(added, tmp_path):
    db, _ = added
    before = _snapshot(db)
    other = tmp_path / "renamed.bin"
    shutil.copy(BINS[0], other)
    with campaign.open(db) as c:
        report = c.add([*BINS, *TLOGS, other])
    assert report.added == () and report.skipped == ()
    assert sorted(report.unchanged) == sorted(map(str, [*BINS, *TLOGS, other]))
    assert _snapshot(db) == before


def test_damaged_files_are_reported_and_skipped_nothing_written(tmp_path):
    _need(*BINS)
    cut = tmp_path / "cut.bin"
    cut.write_bytes(BINS[0].read_bytes()[:400])
    noise = tmp_path / "noise.bin"
    noise.write_bytes(os.urandom(4000))
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    with campaign.open(tmp_path / "c.db") as c:
        report = c.add([cut, noise, empty, tmp_path / "missing.bin"])
        assert report.added == () and report.unchanged == ()
        assert [Path(p).name for p, _ in report.skipped] == ["cut.bin", "noise.bin", "empty.tlog", "missing.bin"]
        assert all(why and "\n" not in why for _, why in report.skipped)
        assert "damaged" in dict(report.skipped)[str(cut)]
        assert c.counts() == {"flights": 0, "test_points": 0, "results": 0}


@pytest.mark.slow
def test_a_killed_add_leaves_the_db_consistent_and_adding_again_completes_it(tmp_path):
    _need(*BINS)
    db = tmp_path / "c.db"
    files = [BINS[0], *TLOGS, BINS[1]]
    code = ("import sys, livesweep.campaign as c\n"
            "c.open(sys.argv[1]).add(sys.argv[2:])\n")
    p = subprocess.Popen([sys.executable, "-c", code, str(db), *map(str, files)])
    deadline = time.monotonic() + 60
    n = 0
    while time.monotonic() < deadline and p.poll() is None:
        if db.is_file():
            try:
                con = sqlite3.connect(db, timeout=5)
                n = con.execute("SELECT COUNT(*) FROM flights").fetchone()[0]
                con.close()
            except sqlite3.OperationalError:     # the schema is not there yet
                n = 0
            if n >= 1:
                break
        time.sleep(0.01)
    p.send_signal(signal.SIGKILL)
    p.wait()
    assert n >= 1
    per = _consistent(db)
    assert 1 <= len(per) < len(files), per           # killed mid-way: some files, not all
    assert per[str(BINS[0])] == len(_reference(BINS[0]))
    with campaign.open(db) as c:
        report = c.add(files)
        assert len(report.added) + len(report.unchanged) == len(files) and report.skipped == ()
        assert len(report.unchanged) == len(per)
    per = _consistent(db)
    assert per == {str(BINS[0]): 4, **{str(t): 0 for t in TLOGS}, str(BINS[1]): 4}


@pytest.mark.slow
def test_two_writers_at_once_both_succeed(tmp_path):
    _need(*BINS)
    db = tmp_path / "c.db"
    cmd = [sys.executable, "-m", "livesweep", "campaign", "add", str(db)]
    a = subprocess.Popen([*cmd, str(BINS[0]), str(TLOGS[0])], stdout=subprocess.PIPE, text=True)
    b = subprocess.Popen([*cmd, str(BINS[1]), str(TLOGS[-1])], stdout=subprocess.PIPE, text=True)
    out_a, _ = a.communicate(timeout=120)
    out_b, _ = b.communicate(timeout=120)
    assert a.returncode == 0 and b.returncode == 0, (out_a, out_b)
    assert "added 4 test points" in out_a and "added 4 test points" in out_b
    per = _consistent(db)
    assert per == {str(BINS[0]): 4, str(BINS[1]): 4, **{str(t): 0 for t in {TLOGS[0], TLOGS[-1]}}}


@pytest.mark.slow
def test_a_monitor_recording_gives_its_recorded_test_points_with_verdicts(sitl_replays, tmp_path):
    from livesweep.telemetry.mcap_read import read_messages

    rec = Path(sitl_replays["roll"].recording)
    want = [m.data for m in read_messages(rec, topics="/livesweep/test_point") if m.data.get("state") == "closed"]
    assert want
    want.sort(key=lambda w: w["start_s"])            # numbered in start order (the file is in log-time order)
    with campaign.open(tmp_path / "c.db") as c:
        report = c.add([rec])
        assert report.added == ((str(rec), len(want)),)
        tps = c.test_points()
        assert [(tp.source, tp.verdict, tp.swept_input, tp.axis, tp.start_s, tp.end_s) for tp in tps] == \
            [("recorded", w["verdict"], w["swept_input"], w["axis"], w["start_s"], w["end_s"]) for w in want]
        assert [tp.number for tp in tps] == list(range(1, len(want) + 1))
        assert tps[0].verdict == "GO" and tps[0].axis == 7
        (axis7,) = [tp for tp in c.test_points(axis=7)]    # at the autopilot's own times, as recorded
        _, t0, t1 = next(r for r in _reference(SITL_LOGS["roll"]) if r[0] == 7)
        assert abs(axis7.start_s - t0) < 0.01 and abs(axis7.end_s - t1) < 0.01
        assert json.loads(tps[0].record)["source"] == "autopilot"       # how the monitor found it
        assert c.test_points(verdict="GO", axis=7) == tps[:1]


def test_cli_add_and_list(tmp_path, capsys):
    from livesweep.cli import main

    db = tmp_path / "c.db"
    noise = tmp_path / "noise.bin"
    noise.write_bytes(os.urandom(2000))
    assert main(["campaign", "add", str(db), str(noise)]) == 0
    out = capsys.readouterr().out
    assert f"{noise}: skipped: " in out and "0 added, 0 unchanged, 1 skipped" in out
    assert main(["campaign", "list", str(db), "--axis", "7", "--verdict", "GO"]) == 0
    assert "0 test points" in capsys.readouterr().out
    assert main(["campaign", "list", str(tmp_path / "nope.db")]) == 2
    with pytest.raises(SystemExit) as e:
        main(["campaign", "--help"])
    assert e.value.code == 0
    assert "campaign add" in capsys.readouterr().out


def test_schema_is_versioned_and_wal(tmp_path):
    db = tmp_path / "c.db"
    campaign.open(db).close()
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA user_version").fetchone()[0] == len(campaign.MIGRATIONS) == campaign.SCHEMA_VERSION
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    assert {"flights", "test_points", "results"} <= tables
    con.close()
    with campaign.open(db) as c:                               # reopening migrates nothing
        assert c.schema_version == campaign.SCHEMA_VERSION
        rid = c.add_result([], "frequency-response", {"note": "x"}, selection={"axis": 7})
        assert rid == 1 and c.counts()["results"] == 1
