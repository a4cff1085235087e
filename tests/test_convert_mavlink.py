"""MAVLink tlog and ArduPilot DataFlash / PX4 sdlog2 conversion to MCAP, on real third-party logs.

The logs are read in place from the shared data folder (README.md there says what each is) and
never copied into the repository; every test that needs one skips when it is absent. Every
reference number is computed here without livesweep's converters: pymavlink's own tlog reader
(``mavutil.mavmmaplog``, built directly: never ``mavlink_connection`` on a path), pymavlink's
``DFReader_binary`` iterating the log itself, CRC-checked frames found by a raw byte scan,
``hashlib`` and plain ``scipy.signal``.

The big jobs (pymavlink's pass over the 4 MB autotest tlog and the conversions of that tlog, of
the 8 MB SITL log and of the 3.7 MB px4log) run in subprocesses started with the module's first
test, so they overlap with each other and with the work done here; each file is converted once
per module.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps

from livesweep.convert import convert
from livesweep.convert.dataflash import convert_dataflash
from livesweep.convert.tlog import convert_tlog
from livesweep.errors import ConfigError, LogFormatError
from livesweep.telemetry import mavlink_codec as codec
from livesweep.telemetry.mcap_log import read_messages, read_metadata, read_summary, read_topics_fields
from pymavlink.dialects.v10 import ardupilotmega as mav1   # after the codec import (MAVLINK20=1)
from pymavlink.dialects.v20 import ardupilotmega as mav2


def _data_dir() -> Path:
    p = Path(__file__).resolve().parents[2] / "shared" / "data"
    return p if p.is_dir() else Path("/work/shared/data")


DATA = _data_dir()
AUTOTEST = DATA / "mavlink_tlog" / "uavlogviewer_autotest_flight_logs.tlog"
APE = DATA / "ardupilot_dataflash" / "ape_hexa_loiter_ac403.bin"
TRUNC = DATA / "ardupilot_dataflash" / "backend_log_80k_truncated_ac462.bin"
SITL = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
PX4 = DATA / "trex550_heli" / "2016-09-08_10_32_26.px4log"
SRC_DIR = Path(__file__).resolve().parents[1] / "src"


def need(*paths: Path) -> None:
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"third-party log(s) not found: {', '.join(missing)}")


# ----------------------------------------------------------------------------- background jobs

_PYMAVLINK_TLOG = r"""
import json, os, sys
os.environ["MAVLINK20"] = "1"
os.environ["MAVLINK_DIALECT"] = "ardupilotmega"
from pymavlink import mavutil
r = mavutil.mavmmaplog(sys.argv[1])      # pymavlink's own tlog reader, built directly
types, systems, bad, att = {}, {}, [], []
while True:
    m = r.recv_msg()
    if m is None:
        break
    t = m.get_type()
    types[t] = types.get(t, 0) + 1
    if t == "BAD_DATA":
        bad.append([str(m.reason).split(":")[0], bytes(m.data)[:1].hex()])
        continue
    key = "%d/%d" % (m.get_srcSystem(), m.get_srcComponent())
    systems.setdefault(key, {})
    systems[key][t] = systems[key].get(t, 0) + 1
    if t == "ATTITUDE":
        d = m.to_dict()
        d.update(t_us=round(m._timestamp * 1e6), sysid=m.get_srcSystem(), compid=m.get_srcComponent())
        att.append(d)
print(json.dumps({"types": types, "systems": systems, "bad": bad, "attitude": att}))
"""

_CONVERT = r"""
import json, sys, time
from livesweep.convert import convert
t0 = time.perf_counter()
res = convert(sys.argv[1], sys.argv[2])
print(json.dumps({"result": res.to_dict(), "seconds": time.perf_counter() - t0}))
"""


class _Job:
    """A Python subprocess printing one JSON object; started now, waited for on first use."""

    def __init__(self, script: str, *args: str):
        env = dict(os.environ, MAVLINK20="1", MAVLINK_DIALECT="ardupilotmega",
                   PYTHONPATH=os.pathsep.join(filter(None, [str(SRC_DIR), os.environ.get("PYTHONPATH")])))
        self.proc = subprocess.Popen([sys.executable, "-c", script, *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, env=env, text=True)
        self._out = None

    def result(self) -> dict:
        if self._out is None:
            out, err = self.proc.communicate(timeout=600)
            assert self.proc.returncode == 0, err[-3000:]
            self._out = json.loads(out)
        return self._out

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.communicate()


@pytest.fixture(scope="module", autouse=True)
def jobs(tmp_path_factory):
    out = tmp_path_factory.mktemp("bg")
    started = {}
    if AUTOTEST.is_file():
        started["pymavlink_autotest"] = _Job(_PYMAVLINK_TLOG, str(AUTOTEST))
    for key, src in (("autotest", AUTOTEST), ("sitl", SITL), ("px4", PX4)):
        if src.is_file():
            started[key] = (_Job(_CONVERT, str(src), str(out / f"{key}.mcap")), out / f"{key}.mcap")
    yield started
    for j in started.values():
        (j[0] if isinstance(j, tuple) else j).stop()


def _converted(jobs, key: str, src: Path) -> tuple[dict, Path]:
    need(src)
    job, path = jobs[key]
    return job.result(), path


# ----------------------------------------------------------------------------- helpers


def write_tlog(path: Path, records: list[tuple[int, bytes]], tail: bytes = b"") -> None:
    with open(path, "wb") as f:
        for ts_us, buf in records:
            f.write(ts_us.to_bytes(8, "big") + buf)
        f.write(tail)


def channel_info(path: Path) -> dict[str, tuple[str, dict, dict]]:
    """topic -> (schema name, schema, channel metadata), read with the mcap library itself."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        s = make_reader(f).get_summary()
    return {c.topic: (s.schemas[c.schema_id].name, json.loads(s.schemas[c.schema_id].data), dict(c.metadata))
            for c in s.channels.values()}


def heartbeats_by_crc(data: bytes) -> int:
    """HEARTBEAT frames in raw bytes, found by a byte scan and kept when pymavlink's CRC check passes."""
    a = np.frombuffer(data, np.uint8)
    mav = mav2.MAVLink(None)
    found = 0
    for magic, length, id_at in ((0xFD, 21, (7, 8, 9)), (0xFE, 17, (5,))):
        n = a.size - length
        if n <= 0:
            continue
        mask = (a[:n] == magic) & (a[1:1 + n] == 9)
        for k in id_at:
            mask &= a[k:k + n] == 0
        for i in np.flatnonzero(mask).tolist():
            try:
                m = mav.decode(bytearray(data[i:i + length]))
            except mav2.MAVError:
                continue
            found += m.get_type() == "HEARTBEAT"
    return found


def dfreader_pass(path: Path):
    """pymavlink's DFReader_binary iterating the log: counts per type, and raw elements of some types."""
    from pymavlink.DFReader import DFReader_binary

    r = DFReader_binary(str(path))
    counts, keep = {}, {"CTUN": [], "ATT": [], "FMTU": [], "MULT": [], "UNIT": [], "IMU": []}
    while True:
        m = r.recv_msg()
        if m is None:
            break
        t = m.get_type()
        counts[t] = counts.get(t, 0) + 1
        if t in keep:
            keep[t].append((m, list(m._elements), m._timestamp))
    return r, counts, keep


# ============================================================================= bad input


@pytest.mark.parametrize("kind", ["random.bin", "empty.bin", "text.bin", "corrupt_header.bin", "short.bin"])
def test_dataflash_bad_input_names_the_file_and_leaves_nothing(tmp_path, kind):
    rng = np.random.default_rng(7)
    content = {
        "random.bin": bytes(rng.integers(0, 256, 4096, dtype=np.uint8)),
        "empty.bin": b"",
        "text.bin": b"time,roll,pitch\n0.0,1.0,2.0\n0.1,1.1,2.1\n",
        "corrupt_header.bin": b"\xa3\x95\x80" + bytes(rng.integers(0, 256, 600, dtype=np.uint8)),
        "short.bin": b"\xa3\x95\x80\x80Y",
    }[kind]
    src = tmp_path / kind
    src.write_bytes(content)
    out = tmp_path / "out.mcap"
    with pytest.raises(LogFormatError) as e:
        convert_dataflash(src, out)
    assert str(src) in str(e.value)
    assert not out.exists() and not Path(str(out) + ".partial").exists()
    assert os.listdir(tmp_path) == [kind]


@pytest.mark.parametrize("kind", ["random.tlog", "empty.tlog", "text.tlog"])
def test_tlog_bad_input_names_the_file_and_leaves_nothing(tmp_path, kind):
    content = {"random.tlog": bytes(np.random.default_rng(3).integers(0, 256, 4096, dtype=np.uint8)),
               "empty.tlog": b"", "text.tlog": b"not a tlog at all\n" * 20}[kind]
    src = tmp_path / kind
    src.write_bytes(content)
    out = tmp_path / "out.mcap"
    with pytest.raises(LogFormatError) as e:
        convert_tlog(src, out)
    assert str(src) in str(e.value)
    assert os.listdir(tmp_path) == [kind]


def test_random_bytes_through_convert_are_refused(tmp_path):
    src = tmp_path / "flight.bin"
    src.write_bytes(bytes(np.random.default_rng(5).integers(0, 256, 2048, dtype=np.uint8)))
    with pytest.raises(LogFormatError) as e:
        convert(src, tmp_path / "o.mcap")
    assert str(src) in str(e.value) and not (tmp_path / "o.mcap").exists()


def test_options_that_do_not_apply_are_config_errors(tmp_path):
    need(TRUNC)
    with pytest.raises(ConfigError, match="column_map"):
        convert_dataflash(TRUNC, tmp_path / "o.mcap", column_map="x.toml")
    tl = tmp_path / "a.tlog"
    write_tlog(tl, [(1_732_000_000_000_000, att_frame(mav2, 1, 1, 0))])
    with pytest.raises(ConfigError, match="column_map"):
        convert_tlog(tl, tmp_path / "o.mcap", column_map="x.toml")
    assert not (tmp_path / "o.mcap").exists()


# ============================================================================= tlog: own files

T_US = 1_732_000_000_000_000


def att_frame(dialect, sysid: int, compid: int, k: int) -> bytes:
    m = dialect.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    m.seq = k % 256
    return m.attitude_encode(1000 + 20 * k, 0.01 * k, -0.02 * k, 0.5, 0.1, 0.2, 0.3).pack(m)


def test_tlog_v1_v2_mix_two_systems_damage_and_times(tmp_path):
    """Own file: MAVLink 1 and 2 frames from two systems, a bad CRC, a text record, a cut tail."""
    recs = []
    for k in range(10):
        recs.append((T_US + 20_000 * k, att_frame(mav1, 1, 1, k)))            # v1, system 1
        recs.append((T_US + 20_000 * k + 5, att_frame(mav2, 7, 42, k)))       # v2, system 7
    bad = bytearray(att_frame(mav2, 7, 42, 10))
    bad[-1] ^= 0xFF                                                           # CRC broken
    recs.append((T_US + 300_000, bytes(bad)))
    recs.append((T_US + 300_001, b"X"))                                       # a 1-byte text record
    recs.append((T_US + 400_000, att_frame(mav2, 7, 42, 11)))
    cut = (T_US + 500_000).to_bytes(8, "big") + att_frame(mav2, 7, 42, 12)[:9]
    src, out = tmp_path / "mix.tlog", tmp_path / "mix.mcap"
    write_tlog(src, recs, tail=cut)
    res = convert(src, out)                       # through the CONVERTERS table, by content
    assert res.format == "tlog" and res.format_version == "MAVLink 1/2 mix"
    assert res.messages_read == 22 and res.messages_written == 21             # 20 + 1 good v2, 1 bad CRC read
    assert res.skipped == {"bad_crc": 1, "bad_prefix_or_garbage": 1, "truncated_tail": 1}
    assert len(res.warnings) >= 3 and any("CRC" in w for w in res.warnings)
    assert res.topics == {"/mavlink/ATTITUDE": 21}
    msgs = list(read_messages(out, topics="/mavlink/ATTITUDE"))
    by_sys = {}
    for m in msgs:
        by_sys.setdefault((m.data["sysid"], m.data["compid"]), []).append(m)
    assert sorted(by_sys) == [(1, 1), (7, 42)] and len(by_sys[(1, 1)]) == 10 and len(by_sys[(7, 42)]) == 11
    first = by_sys[(7, 42)][0]
    assert first.log_time_ns == (T_US + 5) * 1000                 # tlog record time
    assert first.publish_time_ns == 1000 * 1_000_000              # time_boot_ms of the message
    assert first.data == codec.record_from_message(mav2.MAVLink(None).decode(bytearray(att_frame(mav2, 7, 42, 0))))


def test_converted_tlog_equals_a_live_recording_of_it(tmp_path):
    """The same frames recorded live by McapRecorder and converted from the tlog give the same
    channels, schemas, times and records."""
    from livesweep.telemetry.mavlink_in import TlogSource
    from livesweep.telemetry.recorder import McapRecorder

    src = tmp_path / "two.tlog"
    m = mav2.MAVLink(None, srcSystem=9, srcComponent=1)
    recs = []
    for k in range(30):
        recs.append((T_US + 10_000 * k, att_frame(mav2, 1, 1, k)))
        recs.append((T_US + 10_000 * k + 1, m.heartbeat_encode(2, 3, 0, 0, 4).pack(m)))
        recs.append((T_US + 10_000 * k + 2, m.highres_imu_encode(5_000_000 + k, *([0.5 * k] * 13), 7).pack(m)))
    write_tlog(src, recs)
    live = McapRecorder(tmp_path / "live.mcap")
    with TlogSource(src) as s:
        while not s.finished:
            live.record(s.poll())
    live.close()
    convert_tlog(src, tmp_path / "conv.mcap")
    a, b = channel_info(tmp_path / "live.mcap"), channel_info(tmp_path / "conv.mcap")
    assert a == b and set(a) == {"/mavlink/ATTITUDE", "/mavlink/HEARTBEAT", "/mavlink/HIGHRES_IMU"}
    key = lambda x: (x.topic, x.log_time_ns, x.publish_time_ns, json.dumps(x.data))  # noqa: E731
    assert [key(x) for x in read_messages(tmp_path / "live.mcap")] == [key(x) for x in read_messages(tmp_path / "conv.mcap")]
    imu = [x for x in read_messages(tmp_path / "conv.mcap", topics="/mavlink/HIGHRES_IMU")]
    assert imu[3].publish_time_ns == (5_000_000 + 3) * 1000 and imu[3].data["sysid"] == 9   # time_usec


def test_tlog_mavlink1_only(tmp_path):
    src = tmp_path / "v1.tlog"
    write_tlog(src, [(T_US + 1000 * k, att_frame(mav1, 3, 1, k)) for k in range(5)])
    res = convert_tlog(src, tmp_path / "v1.mcap")
    assert res.format_version == "MAVLink 1" and res.skipped == {} and res.messages_written == 5


# ============================================================================= DataFlash: own damage


def test_dataflash_damage_mid_file_and_cut_body(tmp_path):
    """Garbage between records is skipped and counted; a cut record ends the log cleanly."""
    need(TRUNC)
    data = TRUNC.read_bytes()
    whole = convert_dataflash(TRUNC, tmp_path / "whole.mcap")
    # a record boundary in the data part: the first ATT record, where pymavlink's own index puts it
    r, _, _ = dfreader_pass(TRUNC)
    att_at = int(r.offsets[r.name_to_id["ATT"]][0])
    junk = bytes(np.random.default_rng(11).integers(0, 256, 37, dtype=np.uint8)).replace(b"\xa3", b"\x00")
    src = tmp_path / "junk.bin"
    src.write_bytes(data[:att_at] + junk + data[att_at:])
    res = convert_dataflash(src, tmp_path / "junk.mcap")
    assert res.skipped.get("garbage") == 1 and res.messages_read == whole.messages_read
    assert any("37 bytes" in w for w in res.warnings)
    src2 = tmp_path / "cut.bin"
    src2.write_bytes(data[:att_at + 10])                       # 10 bytes into the ATT record
    res2 = convert_dataflash(src2, tmp_path / "cut.mcap")
    assert res2.skipped == {"truncated_tail": 1} and any("mid-message" in w for w in res2.warnings)
    assert res2.messages_read < whole.messages_read and res2.topics.get("/dataflash/ATT", 0) == 0


# ============================================================================= DataFlash: real logs


@pytest.fixture(scope="module")
def ape(tmp_path_factory):
    need(APE)
    out = tmp_path_factory.mktemp("ape") / "ape.mcap"
    return convert(APE, out), out


@pytest.fixture(scope="module")
def ape_ref():
    need(APE)
    return dfreader_pass(APE)


@pytest.fixture(scope="module")
def trunc(tmp_path_factory):
    need(TRUNC)
    out = tmp_path_factory.mktemp("trunc") / "trunc.mcap"
    return convert(TRUNC, out), out


@pytest.mark.slow
def test_dataflash_counts_per_type_match_dfreader(ape, ape_ref, trunc):
    res, out = ape
    _, counts, _ = ape_ref
    assert res.format == "dataflash" and res.format_version == "ArduCopter V4.0.3"
    assert res.topics == {f"/dataflash/{t}": n for t, n in counts.items()}
    assert res.messages_read == res.messages_written == sum(counts.values()) == 32845
    assert res.skipped == {} and res.warnings == ()
    assert read_summary(out).message_counts == res.topics
    tres, _ = trunc
    _, tcounts, _ = dfreader_pass(TRUNC)
    assert tres.topics == {f"/dataflash/{t}": n for t, n in tcounts.items()}


@pytest.mark.slow
def test_dataflash_multiplier_and_units_from_fmtu(ape, ape_ref):
    """CTUN.CRt is int16 with FMTU unit 'n' (m/s) and multiplier 'B': stored value = raw * MULT['B']."""
    res, out = ape
    _, _, keep = ape_ref
    ctun_fmt = keep["CTUN"][0][0].fmt
    unit_of = {chr(el[1]): el[2].rstrip(b"\0").decode() for _, el, _ in keep["UNIT"]}
    mult_of = {chr(el[1]): el[2] for _, el, _ in keep["MULT"]}
    fmtu = {el[1]: (el[2].rstrip(b"\0").decode(), el[3].rstrip(b"\0").decode()) for _, el, _ in keep["FMTU"]}
    units, mults = fmtu[ctun_fmt.type]
    k = ctun_fmt.columns.index("CRt")
    assert ctun_fmt.format[k] == "h" and unit_of[units[k]] == "m/s"
    mult = mult_of[mults[k]]          # logged as a float32 cast to double: 0.009999999776...
    assert np.float32(mult) == np.float32(0.01)
    raw = np.array([el[k] for _, el, _ in keep["CTUN"]], dtype=float)
    assert np.count_nonzero(raw) > 100
    got = read_topics_fields(out, {"/dataflash/CTUN": ["CRt", "TimeUS"], "/dataflash/ATT": ["Roll", "TimeUS"]},
                             missing="error")
    crt = got["/dataflash/CTUN"]
    order = np.argsort([el[0] for _, el, _ in keep["CTUN"]], kind="stable")
    np.testing.assert_allclose(crt["CRt"], (raw * mult)[order], rtol=1e-7, atol=0)      # float32 multiplier
    # format 'c' (int16 centi-degrees): DFReader applies the multiplier the format implies
    att_ref = np.array([m.Roll for m, _, _ in keep["ATT"]])
    np.testing.assert_allclose(got["/dataflash/ATT"]["Roll"],
                               att_ref[np.argsort([el[0] for _, el, _ in keep["ATT"]], kind="stable")], atol=1e-12)
    # units and multipliers in the channel metadata
    _, schema, meta = channel_info(out)["/dataflash/CTUN"]
    assert json.loads(meta["units"])["CRt"] == "m/s" and json.loads(meta["units"])["TimeUS"] == "us"
    assert json.loads(meta["multipliers"])["CRt"] == pytest.approx(0.01)
    assert "m/s" in schema["properties"]["CRt"]["description"]
    assert json.loads(channel_info(out)["/dataflash/ATT"][2]["units"])["Roll"] == "deg"


@pytest.mark.slow
def test_dataflash_gps_time_base_matches_dfreader_clock(ape, ape_ref):
    """log_time is UNIX time from the GPS week/ms (as DFReader's own clock), publish_time is TimeUS."""
    res, out = ape
    _, _, keep = ape_ref
    ref_t = np.array(sorted(ts for _, _, ts in keep["ATT"]))           # DFReader _timestamp, UNIX s
    att = read_topics_fields(out, {"/dataflash/ATT": ["TimeUS"]})["/dataflash/ATT"]
    np.testing.assert_allclose(att["t_ns"] / 1e9, ref_t, rtol=0, atol=2e-6)
    pub = read_topics_fields(out, {"/dataflash/ATT": ["TimeUS"]}, time="publish")["/dataflash/ATT"]
    np.testing.assert_array_equal(pub["t_ns"], att["TimeUS"].astype(np.int64) * 1000)
    assert read_metadata(out)["dataflash"]["time_base"] == "gps"
    assert 1_588_000_000 < att["t_ns"][0] / 1e9 < 1_589_000_000         # 2020-05, the log's date


@pytest.mark.slow
def test_dataflash_provenance_metadata(ape):
    res, out = ape
    meta = read_metadata(out)
    digest = hashlib.sha256(APE.read_bytes()).hexdigest()
    assert res.sha256 == digest
    assert meta["source"] == {"name": APE.name, "sha256": digest, "format": "dataflash",
                              "format_version": "ArduCopter V4.0.3", "size_bytes": str(APE.stat().st_size),
                              "converter": meta["source"]["converter"]}
    conv = meta["conversion"]
    assert int(conv["messages_read"]) == int(conv["messages_written"]) == res.messages_written
    assert json.loads(conv["skipped"]) == {} and json.loads(conv["warnings"]) == []


@pytest.mark.slow
def test_truncated_log_ends_cleanly(trunc):
    """The 80 kB log cut mid-message: a truncated_tail skip and a warning, no exception."""
    res, out = trunc
    assert res.skipped == {"truncated_tail": 1}
    assert len(res.warnings) == 1 and "mid-message" in res.warnings[0]
    assert res.format_version == "ArduCopter V4.6.2"
    assert res.topics["/dataflash/PARM"] == 1077                      # README: 1077 PARM
    assert json.loads(read_metadata(out)["conversion"]["skipped"]) == {"truncated_tail": 1}
    # multi-instance IMU: one channel, the instance field kept and named in the metadata
    _, _, meta = channel_info(out)["/dataflash/IMU"]
    assert meta["instance_field"] == "I" and json.loads(meta["units"])["I"] == "instance"
    inst = read_topics_fields(out, {"/dataflash/IMU": ["I"]})["/dataflash/IMU"]["I"]
    assert set(np.unique(inst)) >= {0.0}


# ============================================================================= tlog: the autotest log


@pytest.fixture(scope="module")
def autotest(jobs):
    out, path = _converted(jobs, "autotest", AUTOTEST)
    return out["result"], path


@pytest.fixture(scope="module")
def autotest_ref(jobs):
    need(AUTOTEST)
    return jobs["pymavlink_autotest"].result()


@pytest.mark.slow
def test_autotest_tlog_systems_and_bad_data_vs_pymavlink(autotest, autotest_ref):
    """pymavlink finds three sources, (1,1), (250,250) and (0,0), and 140 BAD_DATA.

    The (0,0) "system" is 3 UNKNOWN_* messages (ids far outside any dialect) that pymavlink decodes
    from misaligned bytes after a BAD_DATA (an unknown id has no CRC extra, so nothing rejects
    them); the converter keeps the record alignment and has no such messages. Its 140 BAD_DATA
    are console text logged one byte per record ("Bad prefix" runs that begin with a text byte);
    the converter skips those text records one by one (285) and pymavlink swallows 5 real
    HEARTBEATs while resynchronising, which the converter keeps: a CRC-checked byte scan of the
    raw file finds exactly the converter's HEARTBEAT count.
    """
    res, out = autotest
    ref = autotest_ref
    assert set(ref["systems"]) == {"1/1", "250/250", "0/0"}
    assert all(t.startswith("UNKNOWN_") for t in ref["systems"]["0/0"]) and sum(ref["systems"]["0/0"].values()) == 3
    assert len(ref["bad"]) == ref["types"]["BAD_DATA"] == 140
    assert {r for r, _ in ref["bad"]} == {"Bad prefix"}
    assert all(chr(int(b, 16)).isprintable() or chr(int(b, 16)) in "\r\n\t" for _, b in ref["bad"])
    # the converter: the two real systems, in the same numbers except the 5 HEARTBEATs
    mine: dict[str, dict[str, int]] = {}
    ids = read_topics_fields(out, {topic: ["sysid", "compid"] for topic in res["topics"]})
    for topic, cols in ids.items():
        for (sysid, compid), n in zip(*np.unique(np.stack([cols["sysid"], cols["compid"]], 1), axis=0,
                                                  return_counts=True)):
            mine.setdefault(f"{int(sysid)}/{int(compid)}", {})[topic.split("/")[-1]] = int(n)
    assert set(mine) == {"1/1", "250/250"}
    for k in mine:
        diff = {t: mine[k].get(t, 0) - ref["systems"][k].get(t, 0) for t in set(mine[k]) | set(ref["systems"][k])}
        assert {t: d for t, d in diff.items() if d} in ({}, {"HEARTBEAT": diff.get("HEARTBEAT", 0)})
    hb_extra = sum(mine[k].get("HEARTBEAT", 0) - ref["systems"][k].get("HEARTBEAT", 0) for k in mine)
    assert hb_extra == 5
    assert res["topics"]["/mavlink/HEARTBEAT"] == heartbeats_by_crc(AUTOTEST.read_bytes())
    assert res["skipped"] == {"bad_prefix_or_garbage": 285}
    assert any("285" in w and "not MAVLink" in w for w in res["warnings"])
    assert res["format"] == "tlog" and res["format_version"] == "MAVLink 2"


@pytest.mark.slow
def test_autotest_tlog_counts_per_type_vs_pymavlink(autotest, autotest_ref):
    res, out = autotest
    ref = {t: n for t, n in autotest_ref["types"].items() if t != "BAD_DATA" and not t.startswith("UNKNOWN_")}
    mine = {topic.split("/")[-1]: n for topic, n in res["topics"].items()}
    assert set(mine) == set(ref)
    assert {t: mine[t] - ref[t] for t in mine if mine[t] != ref[t]} == {"HEARTBEAT": 5}
    assert res["messages_read"] == res["messages_written"] == sum(ref.values()) + 5 == 96646
    assert read_summary(out).message_counts == res["topics"]


@pytest.mark.slow
def test_autotest_attitude_equals_pymavlink(autotest, autotest_ref):
    """Every converted ATTITUDE equals pymavlink's (float32-exact), with the tlog time and the
    vehicle time as log_time and publish_time, also across the SITL's reboot (time_boot_ms steps
    back 6 s): a clock that restarts is the vehicle's own time, not an implausible stamp."""
    _, out = autotest
    ref = autotest_ref["attitude"]
    msgs = list(read_messages(out, topics="/mavlink/ATTITUDE"))
    assert len(msgs) == len(ref) > 3000
    fallback = []
    for k, (m, d) in enumerate(zip(msgs, ref)):
        assert (m.data["sysid"], m.data["compid"]) == (d["sysid"], d["compid"])
        assert m.data["time_boot_ms"] == d["time_boot_ms"]
        assert m.log_time_ns == d["t_us"] * 1000
        if m.publish_time_ns != d["time_boot_ms"] * 1_000_000:
            assert m.publish_time_ns == m.log_time_ns
            fallback.append(k)
        for f in ("roll", "pitch", "yaw", "rollspeed", "pitchspeed", "yawspeed"):
            assert np.float32(m.data[f]) == np.float32(d[f])
    steps_back = [k for k in range(1, len(ref)) if ref[k]["sysid"] == ref[k - 1]["sysid"]
                  and ref[k]["time_boot_ms"] < ref[k - 1]["time_boot_ms"] - 1000]
    assert fallback == [] and len(steps_back) == 1


@pytest.mark.slow
def test_tlog_channels_are_what_the_live_recorder_writes(autotest):
    """Same topics, schema names and schemas as McapRecorder (mavlink_codec.json_schema)."""
    res, out = autotest
    info = channel_info(out)
    for topic, (name, schema, meta) in info.items():
        msg = topic.split("/")[-1]
        assert topic == f"/mavlink/{msg}" and name == f"mavlink.{msg}"
        assert schema == codec.json_schema(msg)
        assert meta == {}
    meta = read_metadata(out)
    assert meta["source"]["format"] == "tlog" and meta["source"]["format_version"] == "MAVLink 2"
    assert meta["source"]["sha256"] == hashlib.sha256(AUTOTEST.read_bytes()).hexdigest()
    assert json.loads(meta["conversion"]["skipped"]) == {"bad_prefix_or_garbage": 285}
    assert int(meta["conversion"]["messages_read"]) == res["messages_read"]


# ============================================================================= SITL SystemID log

# README (ardupilot_sitl_systemid), axis 7, Welch nperseg 4096 at 400 Hz over the SIDD span:
# frequency [Hz], |H|, phase [deg] for Targ -> Gx and for RATE.RDes -> RATE.R
README_TARG_GX = ((0.5, 0.61, 53.0), (2.0, 0.95, 6.0), (8.0, 0.82, -26.0))
README_RDES_R = ((0.5, 0.99, -6.0), (2.0, 0.93, -21.0), (8.0, 0.78, -60.0))
# The README prints |H| to 2 decimals and phase to whole degrees, so the exact reference lies within
# 0.005 / 0.5 deg of each printed value. The converted samples are the logged float32 values
# exactly (shortest round-trip decimals), so the same Welch estimate reproduces the reference up to
# that rounding: measured worst cases 0.005 (0.995 printed as 0.99) and 0.4 deg. Tolerances: 0.006, 0.6 deg.
TOL_MAG, TOL_DEG = 0.006, 0.6


def h1(x, y, fs, nperseg):
    f, pxy = sps.csd(x, y, fs=fs, nperseg=nperseg)
    _, pxx = sps.welch(x, fs=fs, nperseg=nperseg)
    _, pyy = sps.welch(y, fs=fs, nperseg=nperseg)
    return f, pxy / pxx, np.abs(pxy) ** 2 / (pxx * pyy)


@pytest.mark.slow
def test_sitl_systemid_log_has_sidd_at_400_hz(jobs):
    out, path = _converted(jobs, "sitl", SITL)
    res = out["result"]
    print(f"\nSITL {SITL.name}: {res['messages_read']} messages in {out['seconds']:.2f} s "
          f"({res['messages_read'] / out['seconds']:.0f} messages/s)")
    assert res["format"] == "dataflash" and res["format_version"] == "ArduCopter V4.4.0-dev"
    assert res["skipped"] == {} and res["messages_read"] == res["messages_written"]
    assert {"/dataflash/SIDD", "/dataflash/SIDS", "/dataflash/RATE", "/dataflash/ATT"} <= set(res["topics"])
    got = read_topics_fields(path, {"/dataflash/SIDD": ["TimeUS", "Targ", "F"], "/dataflash/SIDS": ["Ax", "FSt", "FSp"]})
    sidd = got["/dataflash/SIDD"]
    t = sidd["TimeUS"] * 1e-6
    rate = (t.size - 1) / (t[-1] - t[0])
    assert t.size > 20_000 and abs(rate - 400.0) < 1.0 and abs(np.median(np.diff(t)) - 0.0025) < 1e-5
    assert sidd["F"].min() == pytest.approx(0.5, abs=0.01) and 11.0 < sidd["F"].max() <= 12.0
    sids = got["/dataflash/SIDS"]
    assert 7.0 in sids["Ax"] and set(sids["FSt"]) == {0.5} and set(sids["FSp"]) == {12.0}
    # no GPS in this filtered log: boot-relative times, log_time == publish_time == TimeUS
    assert read_metadata(path)["dataflash"]["time_base"] == "boot"
    np.testing.assert_array_equal(sidd["t_ns"], sidd["TimeUS"].astype(np.int64) * 1000)


@pytest.mark.slow
def test_sitl_frequency_response_matches_readme(jobs):
    _, path = _converted(jobs, "sitl", SITL)
    got = read_topics_fields(path, {"/dataflash/SIDD": ["TimeUS", "Targ", "Gx"],
                                    "/dataflash/RATE": ["TimeUS", "RDes", "R"]})
    sidd, rate = got["/dataflash/SIDD"], got["/dataflash/RATE"]
    span = (rate["TimeUS"] >= sidd["TimeUS"][0]) & (rate["TimeUS"] <= sidd["TimeUS"][-1])
    for (x, y), ref in (((sidd["Targ"], sidd["Gx"]), README_TARG_GX),
                        ((rate["RDes"][span], rate["R"][span]), README_RDES_R)):
        f, h, coh = h1(x, y, 400.0, 4096)
        for f0, mag, deg in ref:
            i = int(np.argmin(np.abs(f - f0)))
            assert abs(abs(h[i]) - mag) <= TOL_MAG, (f0, abs(h[i]), mag)
            assert abs(np.degrees(np.angle(h[i])) - deg) <= TOL_DEG, (f0, np.degrees(np.angle(h[i])), deg)
            assert coh[i] > 0.99


# ============================================================================= PX4 sdlog2


@pytest.mark.slow
def test_trex_px4log_converts(jobs):
    out, path = _converted(jobs, "px4", PX4)
    res = out["result"]
    assert res["format"] == "dataflash" and res["format_version"].startswith("PX4 sdlog2 (PX4FMU_V2")
    assert res["skipped"] == {} and res["messages_read"] == res["messages_written"] == 114465
    for topic in ("ATT", "IMU", "ATSP", "RC", "OUT0", "OUT1", "LPOS", "TIME"):
        assert res["topics"].get(f"/dataflash/{topic}", 0) > 1000, topic
    got = read_topics_fields(path, {"/dataflash/ATT": ["Roll", "Pitch", "RollRate"], "/dataflash/IMU": ["AccZ"],
                                    "/dataflash/TIME": ["StartTime"]})
    att = got["/dataflash/ATT"]
    assert np.all(np.abs(att["Roll"]) < np.pi) and np.all(np.abs(att["Pitch"]) < np.pi)   # radians
    assert abs(np.median(got["/dataflash/IMU"]["AccZ"]) + 9.8) < 1.5                     # m/s^2, z down
    # sdlog2 records carry no time: each takes the last TIME.StartTime (µs since boot)
    st = got["/dataflash/TIME"]["StartTime"]
    assert att["t_ns"][0] >= st[0] * 1000 and att["t_ns"][-1] <= st[-1] * 1000
    assert np.all(np.diff(got["/dataflash/TIME"]["t_ns"]) > 0)
