"""One writer per output folder: a second identify or batch into a folder being written fails at once
with one line, and a lock left by a killed process blocks nothing."""

from __future__ import annotations

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
