"""The MCAP read side is total: crafted JSON (huge numbers, deep nesting, arrays), damaged chunks
(CRC mismatches, decompression bombs) and unfinished or recovered logs give one-line errors naming
file, topic, message and field, counted skips in lenient mode, or notes in the identify report.

Files are real MCAP written here with mcap's own writer (raw message bytes) or McapLogWriter.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.records import Message
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

from livesweep.errors import LogFormatError
from livesweep.telemetry.mcap_log import (SKIP_REASONS, McapLogWriter, SkippedMessages, iter_file_order, read_fields,
                                          read_messages, read_topics_fields)
from livesweep.telemetry import mcap_columns
from livesweep.telemetry.mcap_recover import recover

T0 = 1_000_000_000
DT = 10_000_000


def _write_raw(path: Path, payloads: list[bytes]) -> Path:
    """One JSON channel ``/a`` whose message k carries ``payloads[k]`` verbatim at T0 + k DT."""
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=1024)
        w.start()
        sid = w.register_schema("A", "jsonschema", b'{"type":"object"}')
        cid = w.register_channel("/a", "json", sid)
        for k, p in enumerate(payloads):
            w.add_message(cid, T0 + k * DT, p, T0 + k * DT, k)
        w.finish()
    return path


def _good(n: int = 200) -> list[bytes]:
    return [json.dumps({"x": float(k % 7), "v": [1.0, 2.0]}).encode() for k in range(n)]


def _with(k: int, payload: bytes) -> list[bytes]:
    p = _good()
    p[k] = payload
    return p


def _one_line(exc) -> str:
    msg = str(exc.value)
    assert "\n" not in msg and len(msg) < 800, msg
    return msg


# --- numbers beyond float64 -------------------------------------------------------------------

@pytest.mark.parametrize("value", [b"9" * 400, b"-" + b"9" * 400, b"1e400", b"-1e999", b"Infinity"])
def test_a_number_beyond_float64_in_a_field_names_field_and_message(tmp_path, value):
    path = _write_raw(tmp_path / "big.mcap", _with(50, b'{"x": ' + value + b', "v": [1.0, 2.0]}'))
    with pytest.raises(LogFormatError) as e:
        read_fields(path, "/a", ["x"])
    msg = _one_line(e)
    for w in (str(path), "'/a'", "field 'x'", "message 50", f"log_time {T0 + 50 * DT} ns", "float64 range"):
        assert w in msg, (w, msg)
    # the other field of the same messages reads, and so does the message itself in a replay
    assert read_fields(path, "/a", ["v.0"])["v.0"].size == 200
    assert sum(1 for _ in iter_file_order(path)) == 200


def test_a_field_holding_arrays_is_an_error_not_a_2d_column(tmp_path):
    path = _write_raw(tmp_path / "v.mcap", _good())
    with pytest.raises(LogFormatError, match=r"field 'v' of message 0 .* is a JSON array, not a number: \[1.0, 2.0\]"):
        read_fields(path, "/a", ["v"])
    with pytest.raises(LogFormatError, match=r"field 'x' of message 3 .* is a JSON array, not a number"):
        read_fields(_write_raw(tmp_path / "m.mcap", _with(3, b'{"x": [1], "v": 0}')), "/a", ["x"])


# --- messages that are not JSON objects -------------------------------------------------------

BAD_MESSAGES = [
    (b'{"x": ' + b"[" * 100_000 + b"]" * 100_000 + b"}", "too_deep", "nested too deeply"),
    (b"[1, 2, 3]", "not_an_object", "is a JSON array, not an object"),
    (b"42", "not_an_object", "is a JSON number, not an object"),
    (b'{"x": 1', "not_json", "is not valid JSON"),
    (b'{"x": "\xff\xfe"}', "not_json", "is not valid JSON"),
    (b'{"x": ' + b"1" * 5000 + b"}", "not_json", "is not valid JSON"),      # over Python's 4300-digit limit
]


@pytest.mark.parametrize("payload, reason, words", BAD_MESSAGES)
def test_every_reader_names_a_message_that_is_not_a_json_object(tmp_path, payload, reason, words):
    path = _write_raw(tmp_path / "bad.mcap", _with(60, payload))
    where = f"message 60 (log_time {T0 + 60 * DT} ns)"
    for read in (lambda: read_fields(path, "/a", ["x"]), lambda: list(iter_file_order(path))):
        with pytest.raises(LogFormatError) as e:
            read()
        msg = _one_line(e)
        assert str(path) in msg and "'/a'" in msg and where in msg and words in msg, msg
    with pytest.raises(LogFormatError) as e:
        list(read_messages(path))
    msg = _one_line(e)
    assert f"log_time {T0 + 60 * DT} ns (sequence 60)" in msg and words in msg


@pytest.mark.parametrize("payload, reason, words", BAD_MESSAGES)
def test_lenient_file_order_skips_and_counts_bad_messages(tmp_path, payload, reason, words):
    path = _write_raw(tmp_path / "bad.mcap", _with(60, payload))
    skipped = SkippedMessages()
    got = list(iter_file_order(path, skipped=skipped))
    assert len(got) == 199 and all(isinstance(m.data, dict) for m in got)
    assert skipped.counts == {reason: 1} and skipped.total == 1 and reason in SKIP_REASONS
    assert "message 60" in skipped.examples[0] and words in skipped.examples[0]
    seq = [m.sequence for m in got]
    assert seq == [k for k in range(200) if k != 60]           # the skipped index shows as a gap


def test_lenient_file_order_skips_non_json_channels(tmp_path):
    path = tmp_path / "mixed.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("A", "jsonschema", b"{}")
        a = w.register_channel("/a", "json", sid)
        b = w.register_channel("/b", "cdr", sid)
        for k in range(10):
            w.add_message(a, T0 + k, b'{"x": 1}', T0 + k, k)
            w.add_message(b, T0 + k, b"\x00\x01", T0 + k, k)
        w.finish()
    skipped = SkippedMessages()
    assert [m.topic for m in iter_file_order(path, skipped=skipped)] == ["/a"] * 10
    assert skipped.counts == {"not_json_encoding": 10}
    with pytest.raises(LogFormatError, match=r"topic '/b': message 0 .*encoding 'cdr'"):
        list(iter_file_order(path))


# --- damaged chunks ---------------------------------------------------------------------------

def _crc_damaged(tmp_path: Path) -> tuple[Path, int]:
    """An uncompressed log with one digit changed inside a chunk (1250.0 -> 1290.0): still valid JSON,
    wrong value."""
    ok = tmp_path / "ok.mcap"
    with McapLogWriter(ok, compression="none", chunk_size=2048) as w:
        w.add_channel("/a", "A", {"type": "object"})
        for k in range(500):
            w.write("/a", {"x": 1000.0 + k}, log_time_ns=T0 + k * DT)
    buf = bytearray(ok.read_bytes())
    at = buf.find(b'"x":1250.0')
    buf[at + 6] = ord("9")                                      # 1250.0 -> 1290.0
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(buf))
    return bad, at


def test_a_chunk_crc_mismatch_is_an_error_naming_the_chunk(tmp_path):
    bad, _ = _crc_damaged(tmp_path)
    for read in (lambda: read_fields(bad, "/a", ["x"]), lambda: list(iter_file_order(bad)),
                 lambda: list(read_messages(bad))):
        with pytest.raises(LogFormatError) as e:
            read()
        msg = _one_line(e)
        assert str(bad) in msg and "fails its CRC check" in msg and "log times" in msg
        lo, hi = (int(x) for x in msg.split("log times ")[1].split(" ns")[0].split(" to "))
        assert lo <= T0 + 250 * DT <= hi                        # the damaged message is in that range


def test_lenient_file_order_skips_a_damaged_chunk_and_counts_it(tmp_path):
    bad, _ = _crc_damaged(tmp_path)
    skipped = SkippedMessages()
    xs = [m.data["x"] for m in iter_file_order(bad, skipped=skipped)]
    assert skipped.counts == {"bad_chunks": 1} and "CRC" in skipped.examples[0]
    assert 1950.0 not in xs and 1250.0 not in xs                 # neither the wrong nor the lost value
    assert 400 < len(xs) < 500 and xs == sorted(xs)


def test_an_unfinished_log_with_a_damaged_chunk_is_an_error_not_a_truncation(tmp_path):
    bad, at = _crc_damaged(tmp_path)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bad.read_bytes()[:at + 3000])               # torn after the damaged chunk
    with pytest.raises(LogFormatError, match="fails its CRC check"):
        read_fields(cut, "/a", ["x"])


def test_a_data_section_crc_mismatch_is_an_error(tmp_path):
    path = tmp_path / "d.mcap"
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=1024, enable_data_crcs=True)
        w.start()
        cid = w.register_channel("/a", "json", w.register_schema("A", "jsonschema", b"{}"))
        for k, p in enumerate(_good()):
            w.add_message(cid, T0 + k * DT, p, T0 + k * DT, k)
        w.add_metadata("test_point", {"pilot": "alice"})       # a record outside every chunk
        w.finish()
    buf = bytearray(path.read_bytes())
    buf[buf.find(b"alice")] = ord("A")
    path.write_bytes(bytes(buf))
    with pytest.raises(LogFormatError, match="the data section fails its CRC check"):
        read_fields(path, "/a", ["x"])
    skipped = SkippedMessages()
    assert len(list(iter_file_order(path, skipped=skipped))) == 200 and skipped.counts == {"data_section_crc": 1}


def test_a_decompression_bomb_is_refused_without_inflating_it():
    import resource

    import zstandard

    from livesweep.telemetry.mcap_log import _decompress

    bomb = zstandard.ZstdCompressor().compress(b"\0" * 400_000_000)          # 400 MB in ~13 kB
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(ValueError, match="declares 400000000 bytes"):
        _decompress("zstd", bomb, 1024)
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 100_000   # kB: nothing inflated


# --- unfinished and recovered logs: notes -------------------------------------------------------

def _sweep_log(path: Path, n: int = 6000) -> Path:
    """50 Hz, a frequency sweep u and y = u through a first-order lag (pole 5 rad/s)."""
    t = np.arange(n) / 50.0
    u = np.sin(0.5 * t + 0.02 * t**2)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = y[k - 1] + (5.0 * (u[k - 1] - y[k - 1])) / 50.0
    with McapLogWriter(path, chunk_size=4096) as w:
        w.add_channel("/s", "S", {"type": "object"})
        for k in range(n):
            w.write("/s", {"t": float(t[k]), "u": float(u[k]), "y": float(y[k])}, log_time_ns=T0 + k * 20_000_000)
    return path


def _count_messages(path: Path) -> int:
    """Messages mcap's streaming reader finds before the torn end (independent of livesweep)."""
    n = 0
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, skip_magic=False).records:
                n += isinstance(rec, Message)
        except Exception:  # noqa: BLE001 - the torn end
            pass
    return n


def test_unfinished_and_recovered_logs_are_noted(tmp_path):
    full = _sweep_log(tmp_path / "full.mcap")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full.read_bytes()[: int(full.stat().st_size * 0.8)])
    n = _count_messages(cut)
    assert 1000 < n < 6000
    notes: list[str] = []
    cols = read_topics_fields(cut, {"/s": ["u"]}, notes=notes)
    assert cols["/s"]["u"].size == n
    assert len(notes) == 1 and str(cut) in notes[0] and "unfinished" in notes[0] and f"{n} messages read" in notes[0]
    rec = tmp_path / "rec.mcap"
    recover(cut, rec)
    notes = []
    read_topics_fields(rec, {"/s": ["u"]}, notes=notes)
    assert len(notes) == 1 and str(rec) in notes[0] and "recovered" in notes[0] and f"{n} messages kept" in notes[0]
    notes = []
    read_topics_fields(full, {"/s": ["u"]}, notes=notes)
    assert notes == []


CASE = """[case]
name = "lag"

[[identify]]
log = "{log}"

[signals.u]
topic = "/s"
field = "u"
stamp = "t"

[signals.y]
topic = "/s"
field = "y"
stamp = "t"

[spectral]
inputs = ["u"]
outputs = ["y"]
band_rad_s = [1.0, 10.0]
sample_rate_hz = 50.0
windows_s = [10.0, 20.0]
"""


def _identify(tmp_path: Path, log: str):
    case = tmp_path / "case.toml"
    case.write_text(CASE.format(log=log))
    return subprocess.run([sys.executable, "-m", "livesweep", "identify", str(case), "--out", str(tmp_path / "rep"),
                           "--stage", "frequency-response"], capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_identify_reports_a_truncated_log_in_data_quality_notes_and_prints_it(tmp_path):
    full = _sweep_log(tmp_path / "full.mcap")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full.read_bytes()[: int(full.stat().st_size * 0.8)])
    n = _count_messages(cut)
    r = _identify(tmp_path, "cut.mcap")
    assert r.returncode == 0, r.stderr
    notes = json.loads((tmp_path / "rep" / "report.json").read_text())["data_quality"]["notes"]
    hits = [x for x in notes if "cut.mcap" in x and "unfinished" in x]
    assert len(hits) == 1 and f"{n} messages read" in hits[0]
    assert any("note: " in ln and "unfinished" in ln for ln in r.stdout.splitlines())


@pytest.mark.slow
def test_identify_on_a_crafted_number_is_one_line_exit_2(tmp_path):
    payloads = [json.dumps({"t": k / 50.0, "u": np.sin(k / 10.0), "y": 0.5}).encode() for k in range(500)]
    payloads[123] = b'{"t": 2.46, "u": ' + b"7" * 400 + b', "y": 0.5}'
    _write_raw(tmp_path / "big.mcap", payloads)
    text = CASE.replace('"/s"', '"/a"')
    (tmp_path / "case.toml").write_text(text.format(log="big.mcap"))
    r = subprocess.run([sys.executable, "-m", "livesweep", "identify", str(tmp_path / "case.toml"), "--out",
                        str(tmp_path / "rep"), "--stage", "frequency-response"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert "field 'u' of message 123" in r.stderr and "float64 range" in r.stderr and "big.mcap" in r.stderr


def test_columns_decoded_in_batches_equal_mcaps_reader_and_name_the_right_message(tmp_path, monkeypatch):
    from mcap.reader import make_reader

    monkeypatch.setattr(mcap_columns, "_DECODE_BATCH", 64)
    payloads = [json.dumps({"x": k * 0.25, "y": None if k % 9 == 0 else -k}).encode() for k in range(300)]
    path = _write_raw(tmp_path / "batches.mcap", payloads)
    got = read_fields(path, "/a", ["x", "y"])
    with open(path, "rb") as f:
        ref = [json.loads(m.data) for _s, _c, m in make_reader(f).iter_messages(log_time_order=True)]
    np.testing.assert_array_equal(got["x"], [r["x"] for r in ref])
    np.testing.assert_array_equal(got["y"], [np.nan if r["y"] is None else r["y"] for r in ref])
    payloads[250] = b'{"x": 1e999, "y": 0}'
    with pytest.raises(LogFormatError, match=f"field 'x' of message 250 \\(log_time {T0 + 250 * DT} ns\\)"):
        read_fields(_write_raw(tmp_path / "bad.mcap", payloads), "/a", ["x"])
    payloads[250] = b'{"y": 0}'
    with pytest.raises(LogFormatError, match=f"field 'x' is missing from message 250 \\(log_time {T0 + 250 * DT} ns\\)"):
        read_fields(_write_raw(tmp_path / "gap.mcap", payloads), "/a", ["x"])


def test_a_truncated_verification_log_is_noted_too(tmp_path):
    from livesweep.config import load_case
    from livesweep.stages.parametric import VerificationRunner

    full = _sweep_log(tmp_path / "full.mcap")
    (tmp_path / "cut.mcap").write_bytes(full.read_bytes()[: int(full.stat().st_size * 0.7)])
    n = _count_messages(tmp_path / "cut.mcap")
    case_path = tmp_path / "case.toml"
    case_path.write_text(CASE.format(log="full.mcap").replace('[signals.u]', '[[verify]]\nlog = "cut.mcap"\n\n[signals.u]'))
    runner = VerificationRunner(load_case(case_path), 50.0, ["u"], ["y"])
    assert len(runner.notes) == 1 and "cut.mcap" in runner.notes[0] and f"{n} messages read" in runner.notes[0]


def test_recover_keeps_a_damaged_chunk_only_flagged_as_unverified(tmp_path):
    """A chunk failing its CRC is what the mcap reader returns as it is: recover keeps its messages
    (so it never writes fewer than a reader reads) but counts them as unverified, in its result and
    in the copy's metadata, and every reader of the copy says so."""
    bad, at = _crc_damaged(tmp_path)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bad.read_bytes()[:at + 3000])                # unfinished, damaged chunk inside
    rec = tmp_path / "rec.mcap"
    r = recover(cut, rec)
    xs = read_fields(rec, "/a", ["x"])["x"]
    assert xs.size == r.messages_written and 250 < r.messages_written < 500
    assert r.messages_unverified > 0 and len(r.unverified_chunks) == 1
    assert 1250.0 not in xs and np.count_nonzero(xs == 1290.0) == 2   # the damaged value, kept and flagged
    notes: list[str] = []
    read_topics_fields(rec, {"/a": ["x"]}, notes=notes)
    assert f"{r.messages_written} messages kept" in notes[0]
    assert f"{r.messages_unverified} kept from chunks that failed their CRC check" in notes[0]
