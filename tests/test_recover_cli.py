"""`livesweep recover`: a recording whose process was killed with SIGKILL opens, after recovery, in
mcap's own reader, and holds every message up to the last flushed chunk."""

import subprocess
import sys
import textwrap

import pytest
from mcap.reader import make_reader

from livesweep import cli

CHILD = textwrap.dedent(
    """
    import os, signal, sys
    from livesweep.telemetry.mcap_log import McapLogWriter
    path, n = sys.argv[1], int(sys.argv[2])
    w = McapLogWriter(path, atomic=False, chunk_size=4096, flush_every=50, compression="zstd")
    w.add_channel("/mavlink/ATTITUDE", "mavlink.ATTITUDE", {"type": "object"})
    for k in range(n):
        w.write("/mavlink/ATTITUDE", {"time_boot_ms": 20 * k, "roll": 0.001 * k}, log_time_ns=1_000_000_000 + 20_000_000 * k)
    sys.stdout.write("written"); sys.stdout.flush()
    os.kill(os.getpid(), signal.SIGKILL)
    """
)


def test_a_killed_recording_after_recover_opens_in_the_mcap_reader(tmp_path, capsys):
    live = tmp_path / "live.mcap"
    n = 3000                                  # a multiple of flush_every: every closed chunk is on disk
    proc = subprocess.run([sys.executable, "-c", CHILD, str(live), str(n)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == -9 and proc.stdout == "written", proc.stderr
    with open(live, "rb") as f, pytest.raises(Exception):
        list(make_reader(f).iter_messages())          # unfinished: the standard reader refuses it
    assert cli.main(["recover", str(live)]) == 0
    said = capsys.readouterr().out
    out = tmp_path / "live.recovered.mcap"
    assert "was unfinished" in said and str(out) in said
    # the file ends at a flush, so at a record boundary: nothing in it was lost or is unverified
    assert "LOST" not in said and "UNVERIFIED" not in said and "nothing that was in the file was lost" in said
    with open(out, "rb") as f:
        reader = make_reader(f)
        msgs = [(m.log_time, m.data) for _, _, m in reader.iter_messages()]
        assert reader.get_summary().statistics.message_count == len(msgs)
    # every message up to the last flushed chunk: only the open chunk (at most 4096 bytes of
    # ~80-byte records) can be lost, and what is kept is the first messages, unchanged, in order
    assert n - 4096 // 70 - 1 <= len(msgs) < n
    assert [t for t, _ in msgs] == [1_000_000_000 + 20_000_000 * k for k in range(len(msgs))]
    assert msgs[-1][1].startswith(b'{"time_boot_ms":')
    # convert points at recover instead of refusing without a way out
    assert cli.main(["convert", str(live), "--out", str(tmp_path / "c.mcap")]) == 2
    assert "livesweep recover" in capsys.readouterr().err
    # a second recover refuses to overwrite unless forced
    assert cli.main(["recover", str(live)]) == 2
    assert "exists; it is not overwritten unless asked (--force)" in capsys.readouterr().err
    assert cli.main(["recover", str(live), "--force"]) == 0
