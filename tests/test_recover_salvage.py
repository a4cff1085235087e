"""`livesweep recover` on damaged recordings: it never writes fewer messages than mcap's reader or
livesweep's own (the replay's lenient reader) read from the same damaged file, counts what it lost
exactly when the file says how many messages it held, keeps messages of chunks that fail their CRC
check but says they are unverified, and exits 1 naming what was lost."""

from __future__ import annotations

import random
import re
import struct
from pathlib import Path

import pytest
from mcap.reader import make_reader

from livesweep import cli
from livesweep.telemetry.mcap_log import McapLogWriter, SkippedMessages, iter_file_order, read_metadata
from livesweep.telemetry.mcap_recover import RecoverResult, recover

TOPICS = ("/mavlink/ATTITUDE", "/mavlink/SERVO_OUTPUT_RAW", "/mavlink/HEARTBEAT")
N_MESSAGES = 30_000


def _record(path: Path, *, finish: bool = True) -> int:
    """A realistic recording: 30 000 messages on three channels in 16 KiB chunks (about 200 of them),
    a metadata record and an attachment. ``finish=False`` leaves it unfinished, as a killed
    recorder does. Returns the number of messages."""
    w = McapLogWriter(path, chunk_size=16 * 1024, compression="zstd", atomic=finish, flush_every=0 if finish else 500)
    for topic in TOPICS:
        w.add_channel(topic, "mavlink." + topic.rsplit("/", 1)[1], {"type": "object"})
    w.add_metadata("test_point", {"aircraft": "XV-15", "manoeuvre": "roll sweep"})
    w.add_attachment("case.toml", b'[case]\nname = "roll"\n', "application/toml")
    rng = random.Random(7)
    t = 1_000_000_000
    for k in range(N_MESSAGES):
        t += 4_000_000                                           # 250 messages a second
        if k % 50 == 0:
            w.write(TOPICS[2], {"type": 2, "custom_mode": k // 50}, log_time_ns=t)
        elif k % 2:
            w.write(TOPICS[0], {"time_boot_ms": 4 * k, "roll": rng.gauss(0, 0.1), "pitch": rng.gauss(0, 0.1),
                                "yaw": rng.random()}, log_time_ns=t, publish_time_ns=4_000_000 * k)
        else:
            w.write(TOPICS[1], {"time_usec": 4000 * k, "servo": [1500 + rng.randrange(-80, 80) for _ in range(4)]},
                    log_time_ns=t)
    if finish:
        w.close()
    else:
        w.abort()                                                # non-atomic: left unfinished on disk
    return N_MESSAGES


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("rec") / "flight.mcap"
    assert _record(path) == N_MESSAGES
    return path.read_bytes()


@pytest.fixture(scope="module")
def chunks(recording, tmp_path_factory):
    """The recording's chunk indexes in file order."""
    path = tmp_path_factory.mktemp("idx") / "flight.mcap"
    path.write_bytes(recording)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == N_MESSAGES
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def _flip(data: bytes, bits) -> bytes:
    b = bytearray(data)
    for bit in bits:
        b[bit // 8] ^= 1 << (bit % 8)
    return bytes(b)


def _mcap_reader_count(path: Path) -> int:
    """Messages mcap's reader yields with its default settings before it gives up (if it does)."""
    n = 0
    try:
        with open(path, "rb") as f:
            for _ in make_reader(f).iter_messages():
                n += 1
    except Exception:  # noqa: BLE001 - whatever it raises on damaged bytes
        pass
    return n


def _livesweep_reader_count(path: Path) -> int:
    """Messages livesweep's replay reader (lenient: skips damaged chunks) yields before it gives up."""
    n = 0
    try:
        for _ in iter_file_order(path, skipped=SkippedMessages()):
            n += 1
    except Exception:  # noqa: BLE001 - LogFormatError on what it cannot step over
        pass
    return n


def _check(src: Path, out: Path, r: RecoverResult, *, mcap_reads_output: bool = False) -> None:
    """The invariants of every recovery: at least what both readers read, the output finished and
    holding exactly what was reported (read by mcap's reader too when ``mcap_reads_output``: it
    takes a second), and the loss equal to expected - written when known."""
    assert r.messages_written >= _mcap_reader_count(src)
    assert r.messages_written >= _livesweep_reader_count(src)
    assert not out.with_name(out.name + ".partial").exists()
    with open(out, "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == r.messages_written
        if mcap_reads_output:
            assert sum(1 for _ in reader.iter_messages()) == r.messages_written
    bad = SkippedMessages()                # unverified messages may not be JSON; the output's CRCs all match
    assert sum(1 for _ in iter_file_order(out, skipped=bad)) + bad.total == r.messages_written
    assert "bad_chunks" not in bad.counts and "data_section_crc" not in bad.counts
    if r.messages_expected is not None:
        assert r.messages_lost == r.messages_expected - r.messages_written
    meta = read_metadata(out)["livesweep.recover"]
    assert meta["messages_recovered"] == str(r.messages_written)
    assert meta["messages_unverified"] == str(r.messages_unverified)
    assert meta["messages_lost"] == ("unknown" if r.messages_lost is None else str(r.messages_lost))
    assert meta["unverified_chunks"] == " ".join(map(str, r.unverified_chunks))
    assert meta["damaged_chunks"] == " ".join(map(str, r.damaged_chunks))


def _cli(capsys, src: Path, out: Path) -> tuple[int, str]:
    capsys.readouterr()
    rc = cli.main(["recover", str(src), "--out", str(out), "--force"])
    return rc, capsys.readouterr().out


@pytest.mark.slow
def test_an_undamaged_recording_copies_whole_and_exits_0(recording, tmp_path, capsys):
    src, out = tmp_path / "flight.mcap", tmp_path / "copy.mcap"
    src.write_bytes(recording)
    r = recover(src, out)                   # its speed: benchmarks/bench_recover.py (no timing here)
    assert (r.messages_written, r.messages_expected, r.messages_lost) == (N_MESSAGES, N_MESSAGES, 0)
    assert r.messages_unverified == 0
    assert r.clean and r.complete_source and not r.unreadable and not r.skipped_bytes
    _check(src, out, r, mcap_reads_output=True)
    rc, said = _cli(capsys, src, out)
    assert rc == 0 and "LOST" not in said and "UNVERIFIED" not in said and "nothing" in said


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(4))
def test_one_flipped_bit_in_a_chunk_in_the_middle(recording, chunks, tmp_path, capsys, seed):
    rng = random.Random(seed)
    c = chunks[len(chunks) // 2 + seed]
    first = c.chunk_start_offset + c.chunk_length - c.compressed_size      # its compressed records
    src, out = tmp_path / "flight.mcap", tmp_path / "out.mcap"
    src.write_bytes(_flip(recording, [8 * rng.randrange(first, first + c.compressed_size) + rng.randrange(8)]))
    r = recover(src, out)
    _check(src, out, r)
    assert r.messages_expected == N_MESSAGES
    # the chunk either does not decompress (skipped, its messages lost and counted) or fails its CRC
    # check (kept, unverified); either way it is named, and nothing else is touched
    assert (r.damaged_chunks, r.unverified_chunks) in (((c.chunk_start_offset,), ()), ((), (c.chunk_start_offset,)))
    assert not r.clean
    rc, said = _cli(capsys, src, out)
    assert rc == cli.EXIT_DATA_LOST == 1
    assert str(c.chunk_start_offset) in said
    if r.damaged_chunks:
        assert r.messages_lost > 0 and re.search(rf"LOST: {r.messages_lost} messages? of {N_MESSAGES}\b", said)
    else:
        assert r.messages_unverified > 0 and re.search(rf"UNVERIFIED: {r.messages_unverified} messages? kept", said)


@pytest.mark.parametrize("seed", range(4))
def test_one_flipped_bit_anywhere_in_the_middle_of_the_file(recording, tmp_path, seed):
    rng = random.Random(100 + seed)
    n = len(recording)
    src, out = tmp_path / "flight.mcap", tmp_path / "out.mcap"
    src.write_bytes(_flip(recording, [rng.randrange(8 * (n // 4), 8 * (3 * n // 4))]))
    r = recover(src, out)
    _check(src, out, r)
    assert r.messages_expected == N_MESSAGES


@pytest.mark.parametrize("seed", range(5))
def test_twenty_flipped_bits_in_the_first_kilobytes(recording, tmp_path, capsys, seed):
    """The header, the metadata, the attachment and the first chunks (which hold the only schema
    and channel records of the data section) are damaged: the channels come from the summary."""
    rng = random.Random(seed)
    src, out = tmp_path / "flight.mcap", tmp_path / "out.mcap"
    src.write_bytes(_flip(recording, [rng.randrange(8 * 12 * 1024) for _ in range(20)]))
    r = recover(src, out)
    _check(src, out, r)
    assert r.messages_expected == N_MESSAGES
    assert r.messages_written > N_MESSAGES - 1_000                  # only the first few chunks are hit
    rc, said = _cli(capsys, src, out)
    assert rc == 1 and not r.clean
    if r.messages_lost:
        assert re.search(rf"LOST: {r.messages_lost} messages? of {N_MESSAGES}\b", said)
        assert all(str(p) in said for p in r.damaged_chunks[:10])
    if r.messages_unverified:
        assert re.search(rf"UNVERIFIED: {r.messages_unverified} messages? kept", said)


@pytest.mark.slow
def test_a_chunk_that_fails_its_crc_is_kept_unverified(recording, chunks, tmp_path, capsys):
    c = chunks[10]
    src, out = tmp_path / "flight.mcap", tmp_path / "out.mcap"
    crc_at = c.chunk_start_offset + 9 + 24                    # the chunk's stored CRC of its records
    src.write_bytes(_flip(recording, [8 * crc_at]))
    r = recover(src, out)
    _check(src, out, r, mcap_reads_output=True)
    assert r.messages_written == N_MESSAGES and r.messages_lost == 0
    assert r.unverified_chunks == (c.chunk_start_offset,) and r.messages_unverified > 0
    meta = read_metadata(out)["livesweep.recover"]
    assert meta["unverified_chunks"] == str(c.chunk_start_offset)
    rc, said = _cli(capsys, src, out)
    assert rc == 1 and "UNVERIFIED" in said and str(c.chunk_start_offset) in said


@pytest.mark.slow
@pytest.mark.parametrize("damage", ["opcode", "length"])
def test_a_chunk_with_damaged_framing_is_found_again(recording, chunks, tmp_path, damage):
    """With the summary (its chunk index) and without it (an unfinished file: the chunk's own fields)."""
    c = chunks[len(chunks) // 3]
    at = c.chunk_start_offset if damage == "opcode" else c.chunk_start_offset + 1 + 5
    damaged = _flip(recording, [8 * at + 7])
    src, out = tmp_path / "flight.mcap", tmp_path / "out.mcap"
    src.write_bytes(damaged)
    r = recover(src, out)
    _check(src, out, r)
    assert r.messages_written == N_MESSAGES and r.clean
    # the same damage in a file without footer or summary
    cut = chunks[-3].chunk_start_offset                            # ends at a record boundary
    src.write_bytes(damaged[:cut])
    r = recover(src, out)
    src.write_bytes(recording[:cut])
    whole = recover(src, tmp_path / "whole.mcap")
    assert whole.messages_expected is None and whole.messages_lost == 0 and whole.clean
    assert r.messages_written == whole.messages_written > N_MESSAGES - 1000
    assert not r.complete_source and r.messages_lost == 0


def test_resynchronising_by_scanning_when_there_is_no_summary(recording, chunks, tmp_path, capsys):
    """An unfinished file whose chunk has its opcode, length and time range overwritten: reading
    resumes at the next chunk found by scanning; the loss is unknown (no statistics), and said so."""
    cut = chunks[-3].chunk_start_offset
    c = chunks[len(chunks) // 2]
    b = bytearray(recording[:cut])
    b[c.chunk_start_offset:c.chunk_start_offset + 40] = bytes(range(200, 240))
    src, out = tmp_path / "flight.mcap", tmp_path / "out.mcap"
    src.write_bytes(bytes(b))
    r = recover(src, out)
    _check(src, out, r)
    # the messages of the overwritten chunk, from its message index records (intact after it)
    in_chunk = sum(struct.unpack_from("<I", recording, off + 9 + 2)[0] // 16
                   for off in c.message_index_offsets.values())
    src_ok = tmp_path / "ok.mcap"
    src_ok.write_bytes(recording[:cut])
    ok = recover(src_ok, tmp_path / "ok_out.mcap")
    assert in_chunk > 0 and r.messages_written == ok.messages_written - in_chunk
    assert r.messages_lost is None and r.messages_expected is None
    assert any(a <= c.chunk_start_offset < z for a, z in r.skipped_bytes)
    rc, said = _cli(capsys, src, out)
    assert rc == 1 and "LOST: an unknown number of messages" in said and str(c.chunk_start_offset) in said


@pytest.mark.slow
def test_an_unfinished_recording_cut_mid_chunk(tmp_path, capsys):
    src = tmp_path / "live.mcap"
    n = _record(src, finish=False)
    with open(src, "rb") as f:
        with pytest.raises(Exception):
            list(make_reader(f).iter_messages())               # unfinished: mcap's reader refuses it
    full = src.read_bytes()
    # cut half way through the last chunk that is whole on disk
    pos, last = 8, None
    while pos + 9 <= len(full):
        op, length = struct.unpack_from("<BQ", full, pos)
        if pos + 9 + length > len(full):
            break
        if op == 0x06:
            last = (pos, length)
        pos += 9 + length
    assert last is not None
    cut = last[0] + 9 + last[1] // 2
    src.write_bytes(full[:cut])
    out = tmp_path / "live.recovered.mcap"
    r = recover(src, out)
    _check(src, out, r, mcap_reads_output=True)
    in_file = _livesweep_reader_count(src)                       # the complete chunks before the cut
    assert r.messages_written == in_file and 0 < in_file < n
    assert not r.complete_source and r.messages_expected is None and r.messages_lost is None
    assert r.skipped_bytes[-1] == (last[0], cut)
    rc, said = _cli(capsys, src, out)
    assert rc == 1 and "was unfinished" in said and "LOST: an unknown number of messages" in said
    assert f"{last[0]}-{cut}" in said
