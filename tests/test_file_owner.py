"""One owner per file: no command replaces a recording in progress, ``--force`` or not.

A real ``livesweep monitor`` records real UDP frames on 127.0.0.1 while ``sim``, ``convert`` and
``recover`` aim at its file; the file is read back with the standard ``mcap`` reader.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from livesweep.errors import ConfigError, LogFormatError
from livesweep.locks import check_file_free, install_file
from livesweep.telemetry.mcap_log import McapLogWriter
from test_monitor_hardening import Vehicle, free_udp_port, sim_stream, start_monitor


def _livesweep(*args):
    return subprocess.run([sys.executable, "-m", "livesweep", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


def _mavlink_frames(path) -> int:
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return sum(summary.statistics.channel_message_counts[cid] for cid, ch in summary.channels.items()
               if ch.topic.startswith("/mavlink/"))


@pytest.mark.slow
def test_no_command_replaces_a_recording_in_progress(tmp_path):
    port = free_udp_port()
    out = tmp_path / "X.mcap"
    mon = start_monitor(["--mavlink", f"udpin:127.0.0.1:{port}", "--record", str(out)])
    v = Vehicle(1, None)
    frames = sim_stream(5, 30.0)[:600]
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for name, rec in frames[:300]:
                s.sendto(v.pack(name, rec), ("127.0.0.1", port))
            # the inputs the other commands would write from
            src_mcap = tmp_path / "other.mcap"
            r = _livesweep("sim", "--out", src_mcap, "--duration", "10", "--omega-min", "2", "--repeat", "1")
            assert r.returncode == 0, r.stderr
            csv = tmp_path / "flight.csv"
            t = np.arange(100) * 0.02
            csv.write_text("time,elev\n" + "".join(f"{a:.2f},{np.sin(a):.6f}\n" for a in t))
            cmap = tmp_path / "map.toml"
            cmap.write_text('time = "t"\n[columns.t]\nheader = "time"\n[columns.de]\nheader = "elev"\n')

            attempts = {
                "sim": ("sim", "--out", out, "--duration", "10", "--omega-min", "2", "--repeat", "1"),
                "sim --force": ("sim", "--out", out, "--duration", "10", "--omega-min", "2", "--repeat", "1", "--force"),
                "convert --force": ("convert", csv, "--out", out, "--columns", cmap, "--force"),
                "recover --force": ("recover", src_mcap, "--out", out, "--force"),
            }
            for what, args in attempts.items():
                r = _livesweep(*args)
                assert r.returncode == 2, (what, r.stdout, r.stderr)
                assert r.stderr.count("\n") == 1 and str(out) in r.stderr, (what, r.stderr)
                assert "another process is writing" in r.stderr, (what, r.stderr)
            assert not list(tmp_path.glob("X.mcap.*")), list(tmp_path.iterdir())   # no partial left behind
            for name, rec in frames[300:]:
                s.sendto(v.pack(name, rec), ("127.0.0.1", port))
        time.sleep(0.5)
    finally:
        mon.terminate()
        stdout, stderr = mon.communicate(timeout=60)
    assert mon.returncode == 0, stderr.decode()
    assert f"wrote {out}" in stdout.decode()
    assert _mavlink_frames(out) == len(frames)          # every frame sent, in the monitor's file


def test_a_recording_started_meanwhile_is_never_renamed_over(tmp_path):
    """The race the early check cannot see: the name is free when a writer starts and a recording
    takes it before the writer finishes."""
    target = tmp_path / "flight.mcap"
    writer = McapLogWriter(target, overwrite=True)          # atomic: writes flight.mcap.partial
    writer.add_channel("/x", "x", {"type": "object"})
    writer.write("/x", {"v": 1.0}, log_time_ns=1)
    recording = McapLogWriter(target, atomic=False, overwrite=False)   # a monitor takes the name, locked
    recording.add_channel("/y", "y", {"type": "object"})
    recording.write("/y", {"v": 2.0}, log_time_ns=1)
    with pytest.raises(LogFormatError, match="another process is writing"):
        writer.close()
    assert not (tmp_path / "flight.mcap.partial").exists()
    recording.close()
    with open(target, "rb") as f:
        assert [ch.topic for _, ch, _ in make_reader(f).iter_messages()] == ["/y"]


def test_install_refuses_an_existing_file_unless_forced_and_then_replaces_it(tmp_path):
    target, tmp = tmp_path / "a.mcap", tmp_path / "a.mcap.partial"
    target.write_bytes(b"old")
    tmp.write_bytes(b"new")
    with pytest.raises(ConfigError, match="exists"):
        check_file_free(target, overwrite=False)
    with pytest.raises(ConfigError, match="exists"):
        install_file(tmp, target, overwrite=False)
    assert target.read_bytes() == b"old" and tmp.exists()
    check_file_free(target, overwrite=True)
    install_file(tmp, target, overwrite=True)
    assert target.read_bytes() == b"new" and not tmp.exists()
    tmp.write_bytes(b"fresh")
    fresh = tmp_path / "b.mcap"
    install_file(tmp, fresh, overwrite=False)                 # a free name is taken without --force
    assert fresh.read_bytes() == b"fresh" and not tmp.exists()
