"""`livesweep convert` on damaged logs and dangerous outputs: DataFlash resynchronises past
corruption and counts it (checked against pymavlink's DFReader on the intact log), a log that is
mostly corruption is refused unless --partial, corrupt ULog blocks are counted skips, and a source
log or an existing output is never overwritten unless asked."""

from __future__ import annotations

import hashlib
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from livesweep.convert import convert
from livesweep.errors import LogFormatError
from livesweep.telemetry.mcap_log import read_summary

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
APE = DATA / "ardupilot_dataflash" / "ape_hexa_loiter_ac403.bin"
SMALL_ULOG = DATA / "px4_ulog" / "sample_log_small.ulg"


def _run(*args):
    return subprocess.run([sys.executable, "-m", "livesweep", "convert", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _one_line_exit_2(r) -> str:
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    return r.stderr


# --- outputs ----------------------------------------------------------------------------------

@pytest.fixture()
def csv(tmp_path):
    src = tmp_path / "flight.csv"
    src.write_text("time,x\n" + "".join(f"{k * 0.1:.1f},{k % 5}\n" for k in range(50)))
    return src


@pytest.mark.slow
def test_the_source_is_never_the_output_even_through_links_or_force(tmp_path, csv):
    before = _sha(csv)
    (tmp_path / "sym.csv").symlink_to(csv)
    os.link(csv, tmp_path / "hard.csv")
    for out in (csv, tmp_path / "sym.csv", tmp_path / "hard.csv"):
        for force in ((), ("--force",)):
            msg = _one_line_exit_2(_run(csv, "--out", out, *force))
            assert "is the input" in msg and str(csv) in msg
    assert _sha(csv) == before
    # the atomic writer's temporary name is checked too: x.mcap.partial must not be the source
    partial_src = tmp_path / "x.mcap.partial"
    partial_src.write_bytes(csv.read_bytes())
    assert "is the input" in _one_line_exit_2(_run(partial_src, "--out", tmp_path / "x.mcap"))
    assert _sha(partial_src) == before


def test_an_existing_output_is_replaced_only_with_force(tmp_path, csv):
    out = tmp_path / "out.mcap"
    out.write_bytes(b"precious")
    msg = _one_line_exit_2(_run(csv, "--out", out))
    assert "exists" in msg and "--force" in msg and out.read_bytes() == b"precious"
    r = _run(csv, "--out", out, "--force")
    assert r.returncode == 0, r.stderr
    assert read_summary(out).message_counts == {"/table/flight": 50}


def test_the_column_map_is_never_the_output(tmp_path, csv):
    cmap = tmp_path / "map.toml"
    cmap.write_text('time = "t"\n[columns.t]\nheader = "time"\n')
    before = _sha(cmap)
    assert "is the input" in _one_line_exit_2(_run(csv, "--out", cmap, "--columns", cmap, "--force"))
    assert _sha(cmap) == before


# --- DataFlash --------------------------------------------------------------------------------

needs_ape = pytest.mark.skipif(not APE.is_file(), reason=f"third-party log not found: {APE}")


@pytest.fixture(scope="module")
def ape_reference():
    """pymavlink's DFReader indexing the intact log: record offsets and lengths per type."""
    from pymavlink.DFReader import DFReader_binary

    r = DFReader_binary(str(APE))
    spans = [(o, r.formats[t].len) for t in range(256) for o in r.offsets[t]]
    return APE.read_bytes(), sorted(spans)


def _converted(tmp_path, data: bytes, name: str, **options):
    src = tmp_path / name
    src.write_bytes(data)
    return convert(src, tmp_path / (name + ".mcap"), **options)


@needs_ape
def test_an_unknown_type_early_no_longer_ends_the_conversion(tmp_path, ape_reference):
    """DFReader stops at the first record whose type has no FMT; that left 307 of 170 019 messages
    of a SITL log with exit 0. Now only the damaged record is lost."""
    data, spans = ape_reference
    k = next(i for i, (o, _) in enumerate(spans) if o > 20_000)
    at = spans[k][0]
    bad = bytearray(data)
    bad[at + 2] = 0xFE                                   # a type id no FMT defines
    res = _converted(tmp_path, bytes(bad), "unknown.bin")
    assert res.messages_read == res.messages_written == len(spans) - 1
    assert res.skipped == {"garbage": 1}
    assert f"first at offset {at}" in res.warnings[0] and f"({spans[k][1]} bytes" in res.warnings[0]


@needs_ape
def test_a_zeroed_block_loses_exactly_the_records_it_touches(tmp_path, ape_reference):
    data, spans = ape_reference
    a, b = len(data) // 3, len(data) // 3 + 5000
    bad = bytearray(data)
    bad[a:b] = bytes(b - a)
    # a record whose header survives is framed (DataFlash has no checksum); one whose header is
    # zeroed is lost, and framing resumes at the first header after the block
    lost = sum(1 for o, _ in spans if o + 3 > a and o < b)
    res = _converted(tmp_path, bytes(bad), "zeroed.bin")
    assert res.messages_read == len(spans) - lost
    assert res.skipped == {"garbage": 1} and "% of the file" in res.warnings[0]


@needs_ape
def test_a_cut_fmt_record_is_stepped_over(tmp_path, ape_reference):
    """DFReader stops with "Unsupported format char" (nothing converted); a broken FMT that would
    swallow the next record is garbage, so only it and its own type's records are lost."""
    data, spans = ape_reference
    fmts = [o for o, _ in spans if data[o + 2] == 0x80]
    at = fmts[10]
    bad = data[:at + 5] + data[at + 45:]                  # 40 bytes of an FMT record gone
    res = _converted(tmp_path, bad, "cutfmt.bin")
    its_type = sum(1 for o, _ in spans if data[o + 2] == data[at + 3])
    assert res.messages_read == len(spans) - 1 - its_type
    assert res.skipped["garbage"] == 1 + its_type and f"first at offset {at})" in res.warnings[0]


@needs_ape
def test_a_log_that_is_mostly_corruption_is_refused_unless_partial(tmp_path, ape_reference):
    data, spans = ape_reference
    a = spans[200][0] + 7                                 # mid-record, after the FMTs
    bad = bytearray(data)
    bad[a:a + int(0.7 * len(data))] = bytes(int(0.7 * len(data)))
    src = tmp_path / "wrecked.bin"
    src.write_bytes(bytes(bad))
    out = tmp_path / "wrecked.mcap"
    msg = _one_line_exit_2(_run(src, "--out", out))
    b = a + int(0.7 * len(data))
    zeroed = [o for o, _ in spans if o + 3 > a and o < b]
    # ArduPilot writes some FMT records late: types defined only inside the block are lost after it
    defined_before = {data[o + 3] for o, _ in spans if data[o + 2] == 0x80 and o + 3 <= a}
    undefined = {data[o + 3] for o in zeroed if data[o + 2] == 0x80} - defined_before
    lost = len(zeroed) + sum(1 for o, _ in spans if o >= b and data[o + 2] in undefined)
    assert str(src) in msg and "--partial" in msg and f"first at offset {spans[201][0]}" in msg
    assert not out.exists() and not out.with_name(out.name + ".partial").exists()
    r = _run(src, "--out", out, "--partial")
    assert r.returncode == 0, r.stderr
    assert "converted as asked, --partial" in r.stdout
    assert sum(read_summary(out).message_counts.values()) == len(spans) - lost


TRUNCATED = DATA / "ardupilot_dataflash" / "backend_log_80k_truncated_ac462.bin"


@pytest.mark.slow
@pytest.mark.skipif(not TRUNCATED.is_file(), reason=f"third-party log not found: {TRUNCATED}")
def test_damage_fuzz_never_gives_a_traceback(tmp_path):
    data = TRUNCATED.read_bytes()
    rng = np.random.default_rng(7)
    for k in range(30):
        bad = bytearray(data)
        at = int(rng.integers(100, len(bad) - 2000))
        if k % 3 == 0:
            bad[at:at + 64] = rng.integers(0, 256, 64, dtype=np.uint8).tobytes()
        elif k % 3 == 1:
            del bad[at:at + int(rng.integers(1, 300))]
        else:
            bad[at + 2:at + 3] = bytes([0x80])           # a byte that may become an FMT header
        try:
            res = _converted(tmp_path, bytes(bad), f"fuzz{k}.bin")
        except LogFormatError as e:
            assert "\n" not in str(e)
        else:
            assert res.messages_read == res.messages_written > 0


# --- ULog -------------------------------------------------------------------------------------

needs_ulog = pytest.mark.skipif(not SMALL_ULOG.is_file(), reason=f"third-party log not found: {SMALL_ULOG}")


def _ulog_messages(data: bytes):
    """(offset, size, type) of every message after the 16-byte header, by the ULog spec."""
    out, pos = [], 16
    while pos + 3 <= len(data):
        size, typ = struct.unpack_from("<HB", data, pos)
        out.append((pos, size, chr(typ)))
        pos += 3 + size
    return out


@needs_ulog
def test_a_corrupt_ulog_timestamp_is_a_counted_skip_not_a_traceback(tmp_path):
    pytest.importorskip("pyulog")
    data = bytearray(SMALL_ULOG.read_bytes())
    intact = convert(SMALL_ULOG, tmp_path / "intact.mcap")
    at = next(p for p, _, t in _ulog_messages(bytes(data)) if t == "L")
    data[at + 4:at + 12] = b"\xff" * 8                   # the logged string's timestamp: 2**64 - 1 us
    res = _converted(tmp_path, bytes(data), "ts.ulg")    # was: OverflowError traceback
    assert res.skipped["implausible_timestamp"] == 1
    assert res.messages_read == intact.messages_read - 1


@needs_ulog
def test_a_ulog_whose_definitions_are_lost_is_refused_unless_partial(tmp_path):
    pytest.importorskip("pyulog")
    data = bytearray(SMALL_ULOG.read_bytes())
    for pos, _, t in _ulog_messages(bytes(data)):
        if t == "A":                                      # every subscription record damaged
            data[pos + 2] = ord("Q")
    src = tmp_path / "nodefs.ulg"
    src.write_bytes(bytes(data))
    msg = _one_line_exit_2(_run(src, "--out", tmp_path / "o.mcap"))
    assert "0.0 % of the file" in msg and "--partial" in msg and not (tmp_path / "o.mcap").exists()
    r = _run(src, "--out", tmp_path / "o.mcap", "--partial")
    assert r.returncode == 0 and "corrupt" in r.stdout
