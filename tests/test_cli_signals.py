"""SIGTERM and SIGHUP stop a command by unwinding it: `livesweep convert` killed while writing
leaves neither its output nor the ``.partial`` file, exits non-zero (128 + the signal) and says so
in one line; a signal ignored from the start (nohup) stays ignored (real subprocesses)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
ROWS = 400_000          # about 5 s of converting: time to see the .partial file and signal it


def _shared_data() -> Path | None:
    for base in (ROOT.parent / "shared" / "data", Path("/work/shared/data")):
        if base.is_dir():
            return base
    return None


@pytest.fixture(scope="module")
def big_csv(tmp_path_factory):
    """A delimited log of ROWS rows and its column map."""
    d = tmp_path_factory.mktemp("signals")
    t = np.arange(ROWS) * 0.001
    src = d / "big.csv"
    with open(src, "w") as f:
        f.write("time,a,b\n")
        np.savetxt(f, np.column_stack([t, np.sin(t), np.cos(t)]), fmt="%.6f", delimiter=",")
    cmap = d / "map.toml"
    cmap.write_text('name = "big"\ntime = "t"\n[columns.t]\nheader = "time"\nunits = "s"\n'
                    '[columns.a]\nheader = "a"\n[columns.b]\nheader = "b"\n')
    return src, cmap


def _convert(args, out: Path, *, ignore=()):
    def setup():                      # a plain start (whatever the test runner inherited), or as nohup leaves it
        for sig in (signal.SIGTERM, signal.SIGHUP):
            signal.signal(sig, signal.SIG_IGN if sig in ignore else signal.SIG_DFL)

    return subprocess.Popen([sys.executable, "-m", "livesweep", "convert", *map(str, args), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=setup)


#: Bytes in ``<out>.partial`` that show messages are being written (the header alone is 48).
WRITING = 32 * 1024


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except FileNotFoundError:
        return -1


def _signal_while_writing(proc, out: Path, sig) -> tuple[str, str]:
    """Send ``sig`` once ``<out>.partial`` holds messages (the converter is writing them); the
    process's (stdout, stderr)."""
    partial = out.with_name(out.name + ".partial")
    deadline = time.monotonic() + 60
    while _size(partial) < WRITING:
        if proc.poll() is not None:
            pytest.fail(f"convert ended (rc {proc.returncode}) before its .partial file held messages: "
                        f"{proc.stderr.read()}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail("no .partial file holding messages within 60 s")
        time.sleep(0.005)
    proc.send_signal(sig)
    try:
        return proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail(f"convert did not stop within 60 s of {sig.name}")


def _assert_stopped_clean(proc, out: Path, err: str, sig, *, warnings: bool = False) -> None:
    """Stopped by ``sig`` in one line (after the converter's own warnings, when it may give some),
    leaving nothing behind."""
    assert proc.returncode == 128 + sig, (proc.returncode, err)
    lines = err.strip().splitlines()
    assert lines and lines[-1] == f"livesweep: {sig.name}: stopped" and "Traceback" not in err, err
    assert len(lines) == 1 or warnings, err
    assert not out.exists()
    assert not out.with_name(out.name + ".partial").exists()
    assert sorted(p.name for p in out.parent.iterdir() if p.name.startswith(out.name)) == []


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_while_converting_leaves_no_partial_file(big_csv, tmp_path, sig):
    src, cmap = big_csv
    out = tmp_path / "out.mcap"
    proc = _convert([src, "--columns", cmap], out)
    _, err = _signal_while_writing(proc, out, sig)
    _assert_stopped_clean(proc, out, err, sig)


@pytest.mark.slow
def test_a_signal_ignored_from_the_start_stays_ignored(big_csv, tmp_path):
    src, cmap = big_csv
    out = tmp_path / "out.mcap"
    proc = _convert([src, "--columns", cmap], out, ignore=(signal.SIGHUP,))
    _, err = _signal_while_writing(proc, out, signal.SIGHUP)
    assert proc.returncode == 0, err
    assert out.is_file() and not out.with_name(out.name + ".partial").exists()


@pytest.mark.parametrize("rel", ["ardupilot_sitl_systemid/sid_axis7_rate_roll.bin",
                                 pytest.param("mavlink_tlog/uavlogviewer_autotest_flight_logs.tlog", marks=pytest.mark.slow),
                                 "px4_ulog/sample.ulg"])
def test_sigterm_while_converting_a_real_log(tmp_path, rel):
    base = _shared_data()
    if base is None or not (base / rel).is_file():
        pytest.skip(f"shared data {rel} is absent")
    out = tmp_path / "real.mcap"
    proc = _convert([base / rel], out)
    _, err = _signal_while_writing(proc, out, signal.SIGTERM)
    _assert_stopped_clean(proc, out, err, signal.SIGTERM, warnings=True)     # a tlog's skipped bytes are said


def test_the_handlers_are_put_back_when_main_returns(tmp_path):
    """main() called in-process (a notebook, a test) leaves the process's handlers as it found them."""
    from livesweep.cli import main

    before = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGHUP)}
    assert main(["convert", str(tmp_path / "missing.csv"), "--out", str(tmp_path / "o.mcap")]) == 2
    assert {s: signal.getsignal(s) for s in before} == before
    assert not os.listdir(tmp_path)
