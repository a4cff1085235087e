"""One writer per output folder: a second identify or batch into a folder being written fails at once
with one line, and a lock left by a killed process blocks nothing."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from livesweep.batch import run_batch
from livesweep.errors import ConfigError
from livesweep.locks import LOCK_NAME, folder_lock

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "config" / "xv15_cruise_lateral.toml"


def test_a_second_identify_into_a_folder_being_written_is_refused(tmp_path):
    out = tmp_path / "report"
    out.mkdir()
    with folder_lock(out):                      # another identify is writing here
        r = subprocess.run([sys.executable, "-m", "livesweep", "identify", str(CASE), "--out", str(out),
                            "--stage", "frequency-response"], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and r.stderr.count("\n") == 1
        assert "another livesweep process is writing into it" in r.stderr and str(out) in r.stderr
        with pytest.raises(ConfigError, match="another livesweep process"):
            run_batch([CASE], out, stage="frequency-response", workers=1)
    assert not (out / "report.json").exists()


def test_a_lock_left_by_a_killed_process_blocks_nothing(tmp_path):
    out = tmp_path / "report"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time\nfrom livesweep.locks import folder_lock\n"
                               f"with folder_lock({str(out)!r}):\n    print('held', flush=True); time.sleep(60)"],
                              stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    with pytest.raises(ConfigError):
        with folder_lock(out):
            pass
    holder.kill()
    holder.wait(10)
    assert (out / LOCK_NAME).exists()
    with folder_lock(out):                      # the lock file is still there; the lock went with the process
        pass
    assert not (out / LOCK_NAME).exists()       # and the owner that finished removed it


def test_the_owner_removes_the_lock_file_when_it_is_done(tmp_path):
    with folder_lock(tmp_path):
        assert (tmp_path / LOCK_NAME).read_text() == f"{os.getpid()}\n"
    assert not (tmp_path / LOCK_NAME).exists()
    with pytest.raises(RuntimeError):           # also when the block fails
        with folder_lock(tmp_path):
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_finished_batch_leaves_no_lock_file(tmp_path):
    out = tmp_path / "batch"
    out.mkdir()
    run_batch([CASE], out, stage="frequency-response", workers=1, plots=False)
    assert (out / "summary.json").is_file()
    assert not any(p.name == LOCK_NAME for p in out.rglob("*")), sorted(out.rglob("*"))


def test_an_acquirer_holding_the_file_its_owner_deleted_starts_again(tmp_path, monkeypatch):
    """The race the deletion opens: B opens the lock file, its owner A deletes it and lets go, B locks
    the deleted file. B must notice (the file at the path is not the one it locked) and take the
    path's file, else a third process would make a new file, lock it too, and both would write."""
    import fcntl

    owner = folder_lock(tmp_path)
    owner.__enter__()
    real_flock, locked = fcntl.flock, []

    def flock(fd, op):
        if not locked:                          # B has opened A's file: A finishes now
            owner.__exit__(None, None, None)
            assert not (tmp_path / LOCK_NAME).exists()
        locked.append(fd)
        return real_flock(fd, op)

    monkeypatch.setattr(fcntl, "flock", flock)
    with folder_lock(tmp_path):                 # B
        assert len(locked) == 2                 # the deleted file, then the one at the path
        assert (tmp_path / LOCK_NAME).read_text() == f"{os.getpid()}\n"
        with pytest.raises(ConfigError, match="another livesweep process"):
            with folder_lock(tmp_path):         # C finds B's lock
                pass
    assert not (tmp_path / LOCK_NAME).exists()


_CONTENDER = """
import os, sys, time
from livesweep.errors import ConfigError
from livesweep.locks import folder_lock

folder, marker, start, until = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
while time.time() < start:
    time.sleep(0.001)
owned = together = 0
while time.time() < until:
    try:
        with folder_lock(folder):
            try:                                # only an owner may hold the marker
                fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                together += 1
                continue
            os.close(fd)
            owned += 1
            time.sleep(0.0002)
            os.unlink(marker)
    except ConfigError:
        pass
print(owned, together)
"""


@pytest.mark.slow
def test_processes_contending_for_a_folder_never_own_it_together(tmp_path):
    """Four processes take and release the folder's lock as fast as they can, the lock file deleted
    at every release: never two owners at once, and no lock file left at the end."""
    import time

    folder = tmp_path / "report"
    folder.mkdir()
    start = time.time() + 3.0                   # after every interpreter has imported livesweep
    procs = [subprocess.Popen([sys.executable, "-c", _CONTENDER, str(folder), str(tmp_path / "owner"), str(start),
                               str(start + 2.0)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(4)]
    results = []
    for p in procs:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        results.append(tuple(map(int, out.split())))
    assert sum(r[1] for r in results) == 0, results        # never two owners
    assert sum(r[0] for r in results) >= 100, results      # and they did contend, many times
    assert sum(r[0] > 0 for r in results) >= 2, results
    assert not (folder / LOCK_NAME).exists()
