"""The fast chunk walk behind read_fields/read_topics_fields equals mcap's own reader."""

import json
import subprocess
import sys

import numpy as np
import pytest
from mcap.reader import make_reader

from livesweep.telemetry.mcap_log import McapLogWriter, read_topics_fields


def reference(path, topic, fields):
    """Columns read with mcap's reader and json, written here independently."""
    rows = []
    with open(path, "rb") as f:
        for _s, ch, m in make_reader(f).iter_messages(topics=[topic], log_time_order=True):
            rows.append((m.log_time, json.loads(m.data)))
    out = {k: np.array([np.nan if r[1].get(k) is None else r[1][k] for r in rows], float) for k in fields}
    out["t_ns"] = np.array([r[0] for r in rows], np.int64)
    return out


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_fast_walk_equals_mcap_reader(tmp_path, compression):
    rng = np.random.default_rng(1)
    path = tmp_path / f"{compression}.mcap"
    with McapLogWriter(path, compression=compression, chunk_size=4096) as w:
        w.add_channel("/a", "A", {"type": "object"})
        w.add_channel("/b", "B", {"type": "object"})
        for k in range(3000):
            t = 1_000_000 + k * 10_000_000 + int(rng.integers(0, 5_000_000))   # not in time order
            if k % 3:
                w.write("/a", {"x": float(rng.standard_normal()), "n": k, "v": None if k % 97 == 0 else 1.5}, log_time_ns=t)
            else:
                w.write("/b", {"y": float(rng.standard_normal()), "s": "text"}, log_time_ns=t)
    got = read_topics_fields(path, {"/a": ["x", "n", "v"], "/b": ["y"]})
    for topic, fields in (("/a", ["x", "n", "v"]), ("/b", ["y"])):
        ref = reference(path, topic, fields)
        for f in [*fields, "t_ns"]:
            np.testing.assert_array_equal(got[topic][f], ref[f])


def test_unfinished_file_falls_back_to_the_streaming_reader(tmp_path):
    path = tmp_path / "killed.mcap"
    code = f"""
import os, signal
from livesweep.telemetry.mcap_log import McapLogWriter
w = McapLogWriter({str(path)!r}, atomic=False, chunk_size=2048, flush_every=10)
w.add_channel("/a", "A", {{"type": "object"}})
for k in range(2000):
    w.write("/a", {{"x": k * 0.5}}, log_time_ns=1000 + k)
os.kill(os.getpid(), signal.SIGKILL)
"""
    subprocess.run([sys.executable, "-c", code], timeout=60)
    got = read_topics_fields(path, {"/a": ["x"]})["/a"]
    assert 1800 < got["x"].size <= 2000
    np.testing.assert_array_equal(got["x"], 0.5 * np.arange(got["x"].size))
