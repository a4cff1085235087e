"""Tests for livesweep.telemetry.mcap_log: real files in tmp_path, checked against mcap's own reader."""

from __future__ import annotations

import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from livesweep.errors import LogFormatError
from livesweep.telemetry.mcap_log import (
    WRITER_METADATA_NAME,
    LogMessage,
    McapLogWriter,
    read_attachments,
    read_fields,
    read_messages,
    read_metadata,
    read_summary,
)
from livesweep.telemetry.mcap_recover import recover

ATT_SCHEMA = {
    "type": "object",
    "properties": {
        "roll": {"type": "number"},
        "pitch": {"type": "number"},
        "q": {"type": "array", "items": {"type": "number"}},
        "mode": {"type": "string"},
        "count": {"type": "integer"},
    },
}
SERVO_SCHEMA = {"type": "object", "properties": {"servo": {"type": "array"}, "time_usec": {"type": "integer"}}}


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _write_sample(path: Path, compression: str = "zstd", chunk_size: int = 1024) -> dict:
    """Two topics, interleaved and partly out of order in log time, plus metadata and an attachment.

    Returns what was written, for comparison.
    """
    expected: list[tuple[str, int, int, int, dict]] = []
    with McapLogWriter(path, compression=compression, chunk_size=chunk_size) as w:
        w.add_channel("/mavlink/ATTITUDE", "mavlink.ATTITUDE", ATT_SCHEMA, metadata={"sysid": 1})
        w.add_channel("/mavlink/SERVO_OUTPUT_RAW", "mavlink.SERVO_OUTPUT_RAW", SERVO_SCHEMA)
        w.add_metadata("test_point", {"aircraft": "XV-15", "airspeed_kt": 170, "notes": "lateral sweep #2"})
        for k in range(60):
            t = 5_000_000_000 + k * 20_000_000  # 50 Hz, ns
            att = {"roll": 0.001 * k - 0.02, "pitch": -1.5e-3, "q": [1.0, 0.0, k / 7, -k / 3],
                   "mode": f"SWEEP{k % 3}", "count": 2**40 + k, "ok": k % 2 == 0, "none": None,
                   "nested": {"a": [[k, k + 1], [0.1, "x"]], "b": {}}}
            pub = 123_456_000 + k * 20_000_000  # vehicle clock, different epoch
            w.write("/mavlink/ATTITUDE", att, log_time_ns=t, publish_time_ns=pub)
            expected.append(("/mavlink/ATTITUDE", t, pub, k, att))
            if k % 2 == 0:
                # servo messages arrive 5 ms *before* the attitude message in log time
                ts = t - 5_000_000
                servo = {"servo": [1500 + k, 1400 - k, 0], "time_usec": ts // 1000}
                w.write("/mavlink/SERVO_OUTPUT_RAW", servo, log_time_ns=ts)
                expected.append(("/mavlink/SERVO_OUTPUT_RAW", ts, ts, k // 2, servo))
        w.add_attachment("case.toml", b'[case]\nname = "x"\n', "application/toml", log_time_ns=42)
        counts = w.message_counts
    expected.sort(key=lambda e: e[1])
    return {"messages": expected, "counts": counts}


# ------------------------------------------------------------------------------------------------
# writer -> reader round trip
# ------------------------------------------------------------------------------------------------


def test_round_trip_values_times_sequences_and_order(tmp_path):
    path = tmp_path / "run.mcap"
    sample = _write_sample(path)
    got = list(read_messages(path))
    assert len(got) == 90
    want = [LogMessage(topic, t, pub, seq, data) for topic, t, pub, seq, data in sample["messages"]]
    assert got == want  # exact values, nested lists/dicts, big ints, bools, None, strings, times
    assert [m.log_time_ns for m in got] == sorted(m.log_time_ns for m in got)
    att = [m for m in got if m.topic == "/mavlink/ATTITUDE"]
    assert [m.sequence for m in att] == list(range(60))
    assert att[7].data["q"][2] == 7 / 7 and att[9].data["q"][3] == -9 / 3
    assert att[59].data["count"] == 2**40 + 59 and isinstance(att[59].data["count"], int)
    assert att[3].publish_time_ns == 123_456_000 + 3 * 20_000_000
    assert att[3].log_time_ns == 5_060_000_000
    servo = [m for m in got if m.topic == "/mavlink/SERVO_OUTPUT_RAW"]
    assert servo[1].publish_time_ns == servo[1].log_time_ns == 5_035_000_000  # publish defaults to log


def test_topic_and_time_filters(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path)
    t0 = 5_000_000_000
    got = list(read_messages(path, topics="/mavlink/ATTITUDE", start_ns=t0 + 100_000_000, end_ns=t0 + 200_000_000))
    assert [m.log_time_ns - t0 for m in got] == [100_000_000, 120_000_000, 140_000_000, 160_000_000, 180_000_000]
    got = list(read_messages(path, topics=["/mavlink/SERVO_OUTPUT_RAW"], end_ns=t0))
    assert [m.log_time_ns for m in got] == [t0 - 5_000_000]  # end is exclusive
    both = list(read_messages(path, topics=["/mavlink/SERVO_OUTPUT_RAW", "/mavlink/ATTITUDE"]))
    assert len(both) == 90
    assert list(read_messages(path, topics="/nope")) == []


def test_counts_and_encodings_match_mcaps_own_reader(tmp_path):
    path = tmp_path / "run.mcap"
    sample = _write_sample(path)
    assert sample["counts"] == {"/mavlink/ATTITUDE": 60, "/mavlink/SERVO_OUTPUT_RAW": 30}
    summ = read_summary(path)
    assert summ.complete is True
    assert summ.message_counts == sample["counts"]
    assert summ.start_ns == 4_995_000_000
    assert summ.end_ns == 5_000_000_000 + 59 * 20_000_000
    assert summ.duration_s == pytest.approx(1.185, abs=1e-12)
    assert summ.schemas == {"/mavlink/ATTITUDE": "mavlink.ATTITUDE",
                            "/mavlink/SERVO_OUTPUT_RAW": "mavlink.SERVO_OUTPUT_RAW"}
    assert summ.attachments == ("case.toml",)
    assert summ.library == "livesweep"

    with open(path, "rb") as f:  # independent reader
        r = make_reader(f)
        s = r.get_summary()
        by_topic = {s.channels[cid].topic: n for cid, n in s.statistics.channel_message_counts.items()}
        assert by_topic == summ.message_counts
        assert s.statistics.message_count == 90
        assert s.statistics.message_start_time == summ.start_ns
        assert s.statistics.message_end_time == summ.end_ns
        for ch in s.channels.values():
            assert ch.message_encoding == "json"
            schema = s.schemas[ch.schema_id]
            assert schema.encoding == "jsonschema"
        att = next(c for c in s.channels.values() if c.topic == "/mavlink/ATTITUDE")
        assert json.loads(s.schemas[att.schema_id].data) == ATT_SCHEMA
        assert att.metadata == {"sysid": "1"}
        assert r.get_header().library == "livesweep"
        raw = [m for _, c, m in r.iter_messages(topics="/mavlink/SERVO_OUTPUT_RAW")]
        assert raw[0].data == b'{"servo":[1500,1400,0],"time_usec":4995000}'  # compact JSON
        assert [m.sequence for m in raw] == list(range(30))


def test_metadata_and_attachments_round_trip(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path)
    md = read_metadata(path)
    assert md["test_point"] == {"aircraft": "XV-15", "airspeed_kt": "170", "notes": "lateral sweep #2"}
    assert md[WRITER_METADATA_NAME] == {
        "library": "livesweep", "nonfinite_total": "0",
        "nonfinite:/mavlink/ATTITUDE": "0", "nonfinite:/mavlink/SERVO_OUTPUT_RAW": "0",
    }
    assert read_attachments(path) == {"case.toml": b'[case]\nname = "x"\n'}
    assert read_summary(path).metadata == md
    with open(path, "rb") as f:
        (a,) = list(make_reader(f).iter_attachments())
        assert (a.name, a.media_type, a.log_time, a.create_time) == ("case.toml", "application/toml", 42, 42)
    with open(path, "rb") as f:
        names = [m.name for m in make_reader(f).iter_metadata()]
    assert names == ["test_point", WRITER_METADATA_NAME]


def test_nonfinite_written_as_strings_that_say_which_and_counted(tmp_path):
    """NaN, +inf and -inf stay distinguishable in the log (JSON has no such numbers; null would lose
    which): the strings of the protobuf JSON mapping, read back as NaN samples by the column readers."""
    path = tmp_path / "nan.mcap"
    w = McapLogWriter(path)
    w.add_channel("/sim/a", "A", {"type": "object"})
    w.add_channel("/sim/b", "B", {"type": "object"})
    w.write("/sim/a", {"x": math.nan, "v": [1.0, math.inf, [-math.inf, 2.5]], "d": {"y": math.nan}},
            log_time_ns=10)
    w.write("/sim/a", {"x": np.float32("nan"), "arr": np.array([0.5, np.nan]), "n": np.int64(7)}, log_time_ns=20)
    w.write("/sim/b", {"x": 1.25}, log_time_ns=30)
    assert w.nonfinite_counts == {"/sim/a": 6, "/sim/b": 0}
    w.close()
    with open(path, "rb") as f:
        raw = [m.data for _, _, m in make_reader(f).iter_messages()]
    assert raw[0] == b'{"x":"NaN","v":[1.0,"Infinity",["-Infinity",2.5]],"d":{"y":"NaN"}}'
    assert raw[1] == b'{"x":"NaN","arr":[0.5,"NaN"],"n":7}'
    msgs = list(read_messages(path))
    assert msgs[0].data == {"x": "NaN", "v": [1.0, "Infinity", ["-Infinity", 2.5]], "d": {"y": "NaN"}}
    info = read_metadata(path)[WRITER_METADATA_NAME]
    assert info["nonfinite_total"] == "6"
    assert info["nonfinite:/sim/a"] == "6" and info["nonfinite:/sim/b"] == "0"
    cols = read_fields(path, "/sim/a", ["x"])
    assert np.isnan(cols["x"]).all() and cols["t_ns"].tolist() == [10, 20]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_deterministic_bytes(tmp_path, compression):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    _write_sample(a, compression=compression)
    _write_sample(b, compression=compression)
    assert a.read_bytes() == b.read_bytes()
    assert _sha256(a) == _sha256(b)
    assert len(list(read_messages(a))) == 90
    with open(a, "rb") as f:
        assert make_reader(f).get_summary().statistics.message_count == 90


def test_compressions_differ_but_decode_the_same(tmp_path):
    paths = {c: tmp_path / f"{c}.mcap" for c in ("zstd", "lz4", "none")}
    for c, p in paths.items():
        _write_sample(p, compression=c)
    assert len({_sha256(p) for p in paths.values()}) == 3
    decoded = [list(read_messages(p)) for p in paths.values()]
    assert decoded[0] == decoded[1] == decoded[2]
    assert paths["none"].stat().st_size > paths["zstd"].stat().st_size


def test_empty_log_summary(tmp_path):
    path = tmp_path / "empty.mcap"
    with McapLogWriter(path) as w:
        w.add_channel("/x", "X", {"type": "object"})
    s = read_summary(path)
    assert (s.start_ns, s.end_ns, s.duration_s) == (0, 0, 0.0)
    assert s.message_counts == {"/x": 0}
    assert s.complete is True
    cols = read_fields(path, "/x", ["a"])
    assert cols["a"].shape == (0,) and cols["t_ns"].dtype == np.int64


# ------------------------------------------------------------------------------------------------
# atomic writing, abort, bad paths, validation
# ------------------------------------------------------------------------------------------------


def test_atomic_close_renames_partial(tmp_path):
    path = tmp_path / "run.mcap"
    w = McapLogWriter(path)
    w.add_channel("/x", "X", {"type": "object"})
    w.write("/x", {"a": 1}, log_time_ns=1)
    assert sorted(os.listdir(tmp_path)) == ["run.mcap.partial"]
    assert w.close() == path
    assert sorted(os.listdir(tmp_path)) == ["run.mcap"]
    assert w.close() == path  # idempotent
    with pytest.raises(LogFormatError, match="closed"):
        w.write("/x", {"a": 2}, log_time_ns=2)


def test_atomic_with_block_exception_leaves_nothing(tmp_path):
    path = tmp_path / "run.mcap"
    with pytest.raises(RuntimeError, match="boom"):
        with McapLogWriter(path, flush_every=1) as w:
            w.add_channel("/x", "X", {"type": "object"})
            for k in range(100):
                w.write("/x", {"a": k}, log_time_ns=k)
            assert (tmp_path / "run.mcap.partial").stat().st_size > 0
            raise RuntimeError("boom")
    assert os.listdir(tmp_path) == []
    with pytest.raises(LogFormatError, match="aborted"):
        w.close()


def test_abort_non_atomic_keeps_what_was_recorded(tmp_path):
    """A live recording is never deleted: an abort (an exception, a failure while finishing)
    leaves it unfinished, as a kill would, and it reads back."""
    path = tmp_path / "live.mcap"
    w = McapLogWriter(path, atomic=False, flush_every=1)
    w.add_channel("/x", "X", {"type": "object"})
    for k in range(500):
        w.write("/x", {"a": k}, log_time_ns=k)
    w.flush()
    w.abort()
    w.abort()
    assert os.listdir(tmp_path) == ["live.mcap"]
    s = read_summary(path)
    assert not s.complete and s.message_counts["/x"] == 500


@pytest.mark.parametrize("atomic", [True, False])
def test_unwritable_path_raises_and_leaves_nothing(tmp_path, atomic):
    missing = tmp_path / "no_such_dir" / "run.mcap"
    with pytest.raises(LogFormatError, match="no_such_dir"):
        McapLogWriter(missing, atomic=atomic)
    a_file = tmp_path / "plain.txt"
    a_file.write_text("x")
    with pytest.raises(LogFormatError, match="plain.txt"):
        McapLogWriter(a_file / "run.mcap", atomic=atomic)  # parent is a regular file
    a_dir = tmp_path / "adir"
    a_dir.mkdir()
    with pytest.raises(LogFormatError, match="adir.*directory"):
        McapLogWriter(a_dir, atomic=atomic)
    assert sorted(os.listdir(tmp_path)) == ["adir", "plain.txt"]
    assert os.listdir(a_dir) == []


def test_add_channel_idempotent_and_conflicts(tmp_path):
    w = McapLogWriter(tmp_path / "c.mcap")
    cid = w.add_channel("/x", "X", {"type": "object"})
    assert w.add_channel("/x", "X", {"type": "object"}) == cid
    cid2 = w.add_channel("/y", "X", {"type": "object"})  # same schema, another topic
    assert cid2 != cid
    with pytest.raises(LogFormatError, match="'/x'.*different schema"):
        w.add_channel("/x", "X", {"type": "object", "properties": {"a": {"type": "number"}}})
    with pytest.raises(LogFormatError, match="'/x'"):
        w.add_channel("/x", "Other", {"type": "object"})
    w.close()
    with open(tmp_path / "c.mcap", "rb") as f:
        s = make_reader(f).get_summary()
    assert len(s.channels) == 2 and len(s.schemas) == 1  # identical schema stored once


def test_write_validation_errors_name_topic_and_value(tmp_path):
    w = McapLogWriter(tmp_path / "v.mcap")
    w.add_channel("/x", "X", {"type": "object"})
    with pytest.raises(LogFormatError, match=r"'/nope'.*add_channel"):
        w.write("/nope", {}, log_time_ns=0)
    with pytest.raises(LogFormatError, match=r"'/x'.*log_time_ns.*-5"):
        w.write("/x", {}, log_time_ns=-5)
    with pytest.raises(LogFormatError, match=r"'/x'.*log_time_ns.*1.5"):
        w.write("/x", {}, log_time_ns=1.5)
    with pytest.raises(LogFormatError, match=r"'/x'.*publish_time_ns.*True"):
        w.write("/x", {}, log_time_ns=1, publish_time_ns=True)
    with pytest.raises(LogFormatError, match=r"'/x'.*dict"):
        w.write("/x", [1, 2], log_time_ns=1)
    with pytest.raises(LogFormatError, match=r"'/x'.*JSON"):
        w.write("/x", {"o": object()}, log_time_ns=1)
    with pytest.raises(LogFormatError, match="reserved"):
        w.add_metadata(WRITER_METADATA_NAME, {})
    w.add_metadata("m", {"a": 1})
    with pytest.raises(LogFormatError, match="'m'.*already"):
        w.add_metadata("m", {"a": 2})
    w.write("/x", {"k": 1}, log_time_ns=np.int64(3))  # numpy ints are accepted
    assert w.message_counts == {"/x": 1}
    w.close()
    assert [m.log_time_ns for m in read_messages(tmp_path / "v.mcap")] == [3]


def test_bad_writer_options(tmp_path):
    with pytest.raises(LogFormatError, match="compression"):
        McapLogWriter(tmp_path / "a.mcap", compression="gzip")
    with pytest.raises(LogFormatError, match="chunk_size"):
        McapLogWriter(tmp_path / "a.mcap", chunk_size=0)
    assert os.listdir(tmp_path) == []


# ------------------------------------------------------------------------------------------------
# read_fields, bad inputs
# ------------------------------------------------------------------------------------------------


def test_read_fields_columns(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path)
    cols = read_fields(path, "/mavlink/ATTITUDE", ["roll", "count", "ok", "none", "q.3", "nested.a.0.1"])
    assert cols["roll"].dtype == np.float64 and cols["t_ns"].dtype == np.int64
    assert cols["roll"].tolist() == [0.001 * k - 0.02 for k in range(60)]
    assert cols["count"][5] == float(2**40 + 5)
    assert cols["ok"][:4].tolist() == [1.0, 0.0, 1.0, 0.0]
    assert np.isnan(cols["none"]).all()
    assert cols["q.3"][9] == -3.0
    assert cols["nested.a.0.1"][10] == 11.0
    assert cols["t_ns"].tolist() == [5_000_000_000 + k * 20_000_000 for k in range(60)]
    pub = read_fields(path, "/mavlink/ATTITUDE", ["roll"], time="publish")
    assert pub["t_ns"].tolist() == [123_456_000 + k * 20_000_000 for k in range(60)]
    servo = read_fields(path, "/mavlink/SERVO_OUTPUT_RAW", ["servo.0", "time_usec"])
    assert servo["servo.0"].tolist() == [1500.0 + k for k in range(0, 60, 2)]
    assert (servo["time_usec"] * 1000 == servo["t_ns"]).all()


def test_read_fields_errors(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path)
    with pytest.raises(LogFormatError) as e:
        read_fields(path, "/mavlink/ATTITUDE", ["roll", "yaw"])
    msg = str(e.value)
    assert "run.mcap" in msg and "/mavlink/ATTITUDE" in msg and "'yaw'" in msg
    with pytest.raises(LogFormatError) as e:
        read_fields(path, "/mavlink/GPS", ["lat"])
    msg = str(e.value)
    assert "'/mavlink/GPS'" in msg and "/mavlink/ATTITUDE" in msg and "/mavlink/SERVO_OUTPUT_RAW" in msg
    with pytest.raises(LogFormatError, match="'mode'.*not a number"):
        read_fields(path, "/mavlink/ATTITUDE", ["mode"])
    cols = read_fields(path, "/mavlink/ATTITUDE", ["yaw"], missing="nan")
    assert cols["yaw"].shape == (60,) and np.isnan(cols["yaw"]).all()


def test_foreign_file_without_summary_and_non_json_channel(tmp_path):
    """A finished MCAP from another writer, with no summary section and a non-JSON channel."""
    from mcap.writer import IndexType, Writer

    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as f:
        w = Writer(f, repeat_channels=False, repeat_schemas=False, use_statistics=False,
                   index_types=IndexType.NONE, use_summary_offsets=False)
        w.start(library="other")
        sid = w.register_schema("S", "jsonschema", b"{}")
        cid = w.register_channel("/t", "json", sid)
        raw = w.register_channel("/raw", "application/octet-stream", 0)
        for i in range(5):
            w.add_message(cid, 10 - i, json.dumps({"i": i}).encode(), 100 + i, i)
        w.add_message(raw, 3, b"\x01", 3, 0)
        w.finish()
    with open(path, "rb") as f:
        assert make_reader(f).get_summary() is None
    s = read_summary(path)
    assert s.complete is True and s.library == "other"
    assert s.message_counts == {"/t": 5, "/raw": 1}
    assert (s.start_ns, s.end_ns) == (3, 10)
    assert s.schemas == {"/t": "S", "/raw": ""}
    assert [(m.log_time_ns, m.data["i"]) for m in read_messages(path, topics="/t")] == [
        (6, 4), (7, 3), (8, 2), (9, 1), (10, 0)]
    with pytest.raises(LogFormatError, match="'/raw'.*application/octet-stream"):
        list(read_messages(path))


def test_not_mcap_empty_or_missing_file(tmp_path):
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    text = tmp_path / "notes.mcap"
    text.write_text("this is not an MCAP file\n" * 10)
    for p, what in [(empty, "empty"), (text, "not an MCAP file")]:
        for fn in (read_summary, read_metadata, read_attachments, lambda q: list(read_messages(q))):
            with pytest.raises(LogFormatError, match=what) as e:
                fn(p)
            assert p.name in str(e.value)
    with pytest.raises(LogFormatError, match="missing.mcap.*does not exist"):
        read_summary(tmp_path / "missing.mcap")


# ------------------------------------------------------------------------------------------------
# crash safety: SIGKILL before close, non-atomic
# ------------------------------------------------------------------------------------------------

CRASH_CHILD = textwrap.dedent(
    """
    import os, signal, sys
    from livesweep.telemetry.mcap_log import McapLogWriter
    path, n = sys.argv[1], int(sys.argv[2])
    w = McapLogWriter(path, atomic=False, chunk_size=2048, flush_every=10, compression="zstd")
    w.add_channel("/sim/truth", "sim.Truth", {"type": "object"})
    w.add_metadata("test_point", {"aircraft": "XV-15"})
    w.add_attachment("case.toml", b"[case]", "application/toml")
    for k in range(n):
        w.write("/sim/truth", {"k": k, "p": k * 0.25, "v": [k, -k]},
                log_time_ns=1_000_000_000 + k * 20_000_000, publish_time_ns=k * 20_000_000 + 5)
    sys.stdout.write(str(n)); sys.stdout.flush()
    os.kill(os.getpid(), signal.SIGKILL)
    """
)


@pytest.mark.parametrize("n_written", [1000, 1005])
def test_crash_sigkill_then_read_and_recover(tmp_path, n_written):
    # 1000 is a multiple of flush_every (10), so every finished chunk reached the file and only
    # the open chunk is lost; at 1005 up to 5 more messages may sit in Python's file buffer.
    path = tmp_path / "live.mcap"
    proc = subprocess.run([sys.executable, "-c", CRASH_CHILD, str(path), str(n_written)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == -9, proc.stderr
    assert proc.stdout == str(n_written)
    with open(path, "rb") as f:  # mcap's seeking reader cannot read it: it really is unfinished
        with pytest.raises(Exception):
            list(make_reader(f).iter_messages())

    # bound on the loss: the open chunk. A message record is 31 bytes + JSON; the shortest JSON
    # here is {"k":0,"p":0.0,"v":[0,0]} (24 bytes); a chunk is written once it exceeds 2048 bytes.
    max_in_open_chunk = 2048 // (31 + 24) + 1
    unflushed = n_written % 10
    msgs = list(read_messages(path))
    n = len(msgs)
    assert n_written - max_in_open_chunk - unflushed <= n < n_written
    assert [m.data for m in msgs] == [{"k": k, "p": k * 0.25, "v": [k, -k]} for k in range(n)]
    assert [m.log_time_ns for m in msgs] == [1_000_000_000 + k * 20_000_000 for k in range(n)]
    assert [m.publish_time_ns for m in msgs] == [k * 20_000_000 + 5 for k in range(n)]
    assert [m.sequence for m in msgs] == list(range(n))

    s = read_summary(path)
    assert s.complete is False and s.tail_error
    assert s.message_counts == {"/sim/truth": n}
    assert (s.start_ns, s.end_ns) == (1_000_000_000, 1_000_000_000 + (n - 1) * 20_000_000)
    assert s.metadata == {"test_point": {"aircraft": "XV-15"}}  # the writer's own record is never written
    assert read_attachments(path) == {"case.toml": b"[case]"}
    cols = read_fields(path, "/sim/truth", ["p"])
    assert cols["p"].tolist() == [k * 0.25 for k in range(n)]

    out = tmp_path / "recovered.mcap"
    r = recover(path, out)
    assert r.messages_written == n and r.messages_unverified == 0 and not r.damaged_chunks
    assert r.complete_source is False and r.messages_expected is None   # no statistics to count against
    # the file ends where the last flush left it: at a record boundary (nothing in it lost), or inside
    # a record cut off by the kill (the messages in it are lost, how many is unknown)
    assert (r.messages_lost, r.clean) == ((0, True) if not r.skipped_bytes else (None, False))
    assert not (tmp_path / "recovered.mcap.partial").exists()
    with open(out, "rb") as f:
        r = make_reader(f)
        st_ = r.get_summary().statistics
        assert st_.message_count == n
        assert sum(1 for _ in r.iter_messages()) == n
        (ch,) = r.get_summary().channels.values()
        assert (ch.topic, ch.message_encoding) == ("/sim/truth", "json")
        assert r.get_summary().schemas[ch.schema_id].encoding == "jsonschema"
    rs = read_summary(out)
    assert rs.complete is True and rs.message_counts == {"/sim/truth": n}
    assert rs.metadata["test_point"] == {"aircraft": "XV-15"}
    assert rs.metadata["livesweep.recover"]["messages_recovered"] == str(n)
    assert rs.attachments == ("case.toml",)
    assert list(read_messages(out)) == msgs


def test_truncated_at_any_byte_reads_a_prefix(tmp_path):
    """Cut a finished file at many offsets (inside chunks, indexes, summary, footer): the readers
    never crash, report complete=False, and return exactly the messages of the chunks that are whole."""
    full = tmp_path / "full.mcap"
    _write_sample(full, chunk_size=512)
    data = full.read_bytes()
    want = list(read_messages(full))
    cut = tmp_path / "cut.mcap"
    seen_counts = set()
    for size in list(range(9, len(data), 61)) + [len(data) - 1]:
        cut.write_bytes(data[:size])
        s = read_summary(cut)
        assert s.complete is False
        got = list(read_messages(cut))
        assert sum(s.message_counts.values()) == len(got)
        want_set = {(m.topic, m.sequence): m for m in want}
        assert all(want_set[(m.topic, m.sequence)] == m for m in got)
        seen_counts.add(len(got))
    assert min(seen_counts) == 0 and max(seen_counts) == 90 and len(seen_counts) > 5
    cut.write_bytes(data[:5])
    with pytest.raises(LogFormatError, match="not an MCAP file"):
        read_summary(cut)


def test_recover_refuses_same_path_and_bad_input(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path)
    with pytest.raises(LogFormatError, match="input file"):
        recover(path, path)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"\x00" * 100)
    with pytest.raises(LogFormatError, match="junk.mcap.*not an MCAP"):
        recover(junk, tmp_path / "out.mcap")
    r = recover(path, tmp_path / "copy.mcap")  # a finished file copies whole
    assert (r.messages_written, r.messages_expected, r.messages_lost, r.clean) == (90, 90, 0, True)
    assert list(read_messages(tmp_path / "copy.mcap")) == list(read_messages(path))


# ------------------------------------------------------------------------------------------------
# property test: JSON round trip
# ------------------------------------------------------------------------------------------------

_scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**64)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=8)
)
_values = st.recursive(
    _scalars,
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=5), kids, max_size=4),
    max_leaves=12,
)
_messages = st.dictionaries(st.text(max_size=6), _values, max_size=5)


@settings(max_examples=40, deadline=None)
@given(msgs=st.lists(_messages, min_size=1, max_size=4),
       t0=st.integers(min_value=0, max_value=2**63))
def test_property_json_round_trip(msgs, t0):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "p.mcap"
        with McapLogWriter(path) as w:
            w.add_channel("/p", "P", {"type": "object"})
            for i, m in enumerate(msgs):
                w.write("/p", m, log_time_ns=t0 + i, publish_time_ns=2**64 - 1 - i)
        assert w.nonfinite_counts == {"/p": 0}
        got = list(read_messages(path))
    assert [g.data for g in got] == msgs
    assert [g.log_time_ns for g in got] == [t0 + i for i in range(len(msgs))]
    assert [g.publish_time_ns for g in got] == [2**64 - 1 - i for i in range(len(msgs))]


def test_the_fast_message_path_writes_the_files_mcap_s_own_add_message_writes(tmp_path):
    """Messages out of time order on two channels, JSON and pre-encoded, across many chunks: the file
    is byte for byte the one the mcap library's Writer.add_message makes."""
    def make(path, fast):
        w = McapLogWriter(path, atomic=False, flush_every=0, chunk_size=4096)
        if not fast:
            w._fast = None
        else:
            assert w._fast is not None                  # the pinned mcap has the internals it needs
        w.add_channel("/a", "a", {"type": "object"})
        w.add_channel("/b", "b", {"type": "object"})
        for i in range(3000):
            w.write("/a" if i % 3 else "/b", {"i": i, "x": 0.5 * i},
                    log_time_ns=10**9 + (i * 7919) % 5000 * 10**6, publish_time_ns=5 * i)
            if i % 7 == 0:
                w.write_encoded("/b", b'{"raw":1}', 10**9 + i)
        w.close()
        return path.read_bytes()

    assert make(tmp_path / "fast.mcap", True) == make(tmp_path / "library.mcap", False)
