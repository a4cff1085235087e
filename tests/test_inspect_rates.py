"""`livesweep inspect` against references it did not compute: on every log in ../shared/data
(third-party; skipped when absent), no preset is suggested whose signals arrive slower than its
declared band needs, and the rates and needs a preset is refused with are the log's; the SystemID
test points listed are the ones the log has data for; the fields of ROS 2 MCAP channels are their
schemas' fields; progress goes to stderr, never into the report.

The references: the presets' TOML files read with ``tomllib`` (band, grid rate, signals); message
rates from each log's own reader (pymavlink's ``mavmmaplog`` for tlogs, ``DFReader_binary`` for
DataFlash, pyulog for ULog) as 1 / the median interval of the message's own time field; the
SystemID starts and the RATE records from ``DFReader_binary``; channels, counts and schemas from
mcap's reader.
"""

from __future__ import annotations

import io
import math
import os
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from livesweep import cli
from livesweep.inspection import format_inspection, inspect_log, stderr_progress

ROOT = Path(__file__).resolve().parents[1]
_DATA = ROOT.parent / "shared" / "data"
DATA = _DATA if _DATA.is_dir() else Path("/work/shared/data")
LOGS = sorted(p for p in DATA.rglob("*") if p.is_file() and p.suffix.lower() != ".md" and p.name != "LICENSE") \
    if DATA.is_dir() else []
PRESETS = ROOT / "src" / "livesweep" / "data" / "maps"
pytestmark = pytest.mark.skipif(not LOGS, reason="../shared/data is not here")
#: logs whose tests here take over 1 s on 2 cores (inspecting them, and reading their rates
#: independently): those parameters are marked slow, the others run in the quick run
SLOW_LOGS = {"sid_axis7_rate_roll.bin", "sid_axis8_rate_pitch.bin", "uavlogviewer_autotest_flight_logs.tlog",
             "2016-09-08_10_32_26.px4log"}


def _by_cost(logs):
    """``logs`` as test parameters named by file, the ones of :data:`SLOW_LOGS` marked slow."""
    return [pytest.param(p, id=p.name, marks=[pytest.mark.slow] if p.name in SLOW_LOGS else []) for p in logs]
os.environ.setdefault("MAVLINK20", "1")


@pytest.fixture(scope="module")
def inspections():
    return {}


def _inspect(cache: dict, log: Path):
    if log not in cache:
        cache[log] = inspect_log(log)
    return cache[log]


def _preset(name: str) -> dict:
    """A preset's TOML as written (a path for a map that is no preset)."""
    path = Path(name) if name.endswith(".toml") else PRESETS / f"{name}.toml"
    return tomllib.loads(path.read_text())


# ----------------------------------------------------------------------------- independent rates

def _median_rate(t_s) -> float:
    """1 / the median interval [Hz] of increasing times [s] (0 with fewer than two)."""
    t = np.asarray(t_s, float)
    if t.size < 2:
        return 0.0
    d = np.diff(t)
    d = d[d > 0]
    return float(1.0 / np.median(d)) if d.size else 0.0


def _tlog_rate(log: Path, msg: str, stamp: str | None, scale: float, where: dict) -> float:
    from pymavlink import mavutil

    r = mavutil.mavmmaplog(str(log))
    by_system: dict[int, list] = {}
    while (m := r.recv_match(type=msg)) is not None:
        if any(getattr(m, k, None) != v for k, v in where.items()):
            continue
        t = getattr(m, stamp) * scale if stamp and hasattr(m, stamp) else m._timestamp
        by_system.setdefault(m.get_srcSystem(), []).append(t)
    r.close()
    if not by_system:
        return 0.0
    return _median_rate(max(by_system.values(), key=len))


def _dataflash_times(log: Path, names) -> dict:
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(log), zero_time_base=False)
    out: dict[str, list] = {n: [] for n in names}
    while (m := r.recv_match(type=list(names))) is not None:
        out[m.get_type()].append(m.TimeUS * 1e-6)
    return out


def _ulog_rate(log: Path, topic: str) -> float:
    from pyulog import ULog

    u = ULog(str(log), [topic])
    return max((_median_rate(d.data["timestamp"] * 1e-6) for d in u.data_list if d.name == topic), default=0.0)


def _rate(log: Path, fmt: str, spec: dict) -> float:
    """The rate of a signal's messages in ``log`` [Hz], read with the log's own reader."""
    kind, _, name = spec["topic"].strip("/").partition("/")
    if fmt == "tlog" and kind == "mavlink":
        return _tlog_rate(log, name, spec.get("stamp"), spec.get("stamp_scale", 1.0), dict(spec.get("where", {})))
    if fmt == "dataflash" and kind == "dataflash":
        return _median_rate(_dataflash_times(log, [name])[name])
    if fmt == "ulog" and kind == "ulog":
        return _ulog_rate(log, name)
    pytest.fail(f"no reference reader for {spec['topic']} in a {fmt} log")


def _systemid_top_hz(log: Path, fmt: str) -> float | None:
    """The top of the SystemID band the log's SIDS records declare [Hz] (None without)."""
    if fmt != "dataflash":
        return None
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(log), zero_time_base=False)
    tops = []
    while (m := r.recv_match(type="SIDS")) is not None:
        tops.append(m.FSp)
    return max(tops) if tops else None


def _need_hz(preset: dict, sid_top_hz: float | None) -> float:
    """2.5 x the top of the band the preset's monitor judges [Hz]: the SystemID band when the log has
    one, else the preset's own, never above 0.8 of its grid's Nyquist frequency."""
    sp = preset["spectral"]
    top = sid_top_hz if sid_top_hz is not None else sp["band_rad_s"][1] / (2 * math.pi)
    top = min(top, 0.8 * sp["sample_rate_hz"] / 2)
    return 2.5 * top


@pytest.mark.parametrize("log", _by_cost(LOGS))
def test_no_preset_is_suggested_whose_signals_the_log_sends_too_slowly(inspections, log):
    ins = _inspect(inspections, log)
    sid_top = _systemid_top_hz(log, ins.format)
    for name, _pairs, _total in ins.maps:
        preset = _preset(name)
        need = _need_hz(preset, sid_top)
        sp = preset["spectral"]
        for sig in (*sp["inputs"], *sp["outputs"]):
            spec = preset["signals"][sig]
            rate = _rate(log, ins.format, spec)
            if rate == 0.0:
                continue                              # not in the log: that pair counts as without data
            assert rate >= 0.95 * need, (f"{name} suggested for {log.name} but {sig} ({spec['topic']}) arrives at "
                                         f"{rate:.3g} Hz, below the {need:.3g} Hz its band needs")


_SLOW = re.compile(r"(\w+) \((\w+)\) (?:arrives at|at) ([0-9.e+]+) Hz")
_NEEDS = re.compile(r"needs ([0-9.e+]+) Hz$")


@pytest.mark.parametrize("log", _by_cost(LOGS))
def test_a_preset_refused_as_too_slow_names_the_logs_rates_and_the_bands_need(inspections, log):
    """The rates a refusal quotes are the log's (its own reader, within 15 %), and the rate needed
    is 2.5 x the top of the band the preset declares (or the log's SystemID band)."""
    ins = _inspect(inspections, log)
    sid_top = _systemid_top_hz(log, ins.format)
    slow = [f for f in ins.fits if not f.live and "arrives at" in f.why]
    for f in slow:
        preset = _preset(f.name)
        assert len(format_inspection(ins).splitlines()) > 0
        need = float(_NEEDS.search(f.why).group(1))
        assert need == pytest.approx(_need_hz(preset, sid_top), rel=0.01), f.why
        named = _SLOW.findall(f.why)
        assert named and len({msg for _, msg, _ in named}) == len(named), f.why     # one entry per message
        for sig, msg, quoted in named:
            spec = preset["signals"][sig]
            assert spec["topic"].endswith("/" + msg)
            rate = _rate(log, ins.format, spec)
            assert float(quoted) == pytest.approx(rate, rel=0.15), (f.why, rate)
            assert float(quoted) < need


def test_the_quadplane_tlog_at_4_hz_is_not_given_the_plane_preset(inspections):
    """ATTITUDE and SERVO_OUTPUT_RAW arrive at about 4 Hz in the QuadPlane SITL tlog; the plane
    preset's band (0.5-40 rad/s) needs 2.5 x 6.4 Hz: it is not suggested, and its one line names
    both messages."""
    log = DATA / "mavlink_tlog" / "uavlogviewer_vtol_sitl.tlog"
    if not log.is_file():
        pytest.skip("no QuadPlane tlog")
    ins = _inspect(inspections, log)
    assert "ardupilot-plane" not in [m[0] for m in ins.maps]
    plane = _preset("ardupilot-plane")
    fit = next(f for f in ins.fits if f.name == "ardupilot-plane")
    for msg, sig in (("SERVO_OUTPUT_RAW", "da"), ("ATTITUDE", "p")):
        rate = _rate(log, "tlog", plane["signals"][sig])
        assert 3.5 < rate < 4.5
        assert f"({msg})" in fit.why
    line = next(ln for ln in format_inspection(ins).splitlines() if ln.strip().startswith("ardupilot-plane:"))
    assert "SERVO_OUTPUT_RAW" in line and "ATTITUDE" in line and f"needs {_need_hz(plane, None):.3g} Hz" in line


# ----------------------------------------------------------------------------- SystemID test points

@pytest.mark.slow
@pytest.mark.parametrize("name", ["sid_axis7_rate_roll.bin", "sid_axis8_rate_pitch.bin"])
def test_systemid_test_points_are_listed_only_where_the_log_has_their_data(inspections, name):
    """The filtered SystemID logs announce four runs (SIDS) but keep RATE only around one: that one
    is a test point, the other three are named in one line as announced without data."""
    log = DATA / "ardupilot_sitl_systemid" / name
    if not log.is_file():
        pytest.skip(f"no {name}")
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(log), zero_time_base=False)
    sids, rate_t = [], []
    while (m := r.recv_match(type=["SIDS", "RATE"])) is not None:
        if m.get_type() == "SIDS":
            sids.append((m.TimeUS * 1e-6, int(m.Ax), m.TR + m.TFin + m.TFout))
        else:
            rate_t.append(m.TimeUS * 1e-6)
    covered = [ax for t, ax, dur in sids if min(rate_t) <= t and t + dur <= max(rate_t)]
    assert len(sids) == 4 and len(covered) == 1
    ins = _inspect(inspections, log)
    assert [run.axis for run in ins.systemid] == [ax for _, ax, _ in sids]          # every run announced
    assert [run.axis for run in ins.systemid if run.data] == covered
    assert len(ins.test_points) == 1 and f"axis {covered[0]} " in ins.test_points[0][2]
    starts = [run.start_s for run in ins.systemid]                                  # on the log's own clock
    assert np.diff(starts) == pytest.approx(np.diff([t for t, _, _ in sids]), abs=0.01)
    text = format_inspection(ins)
    lines = [ln for ln in text.splitlines() if "announced but without data" in ln]
    assert len(lines) == 1
    for _, ax, _ in sids:
        assert (f"axis {ax} (" in lines[0]) == (ax not in covered)
    assert sum(1 for ln in text.splitlines() if ln.startswith("  ") and ": SystemID axis" in ln) == 1


# ----------------------------------------------------------------------------- MCAP fields

def _schema_top_fields(text: str) -> list[str]:
    """The top-level field names of a ROS message definition: the lines of its own section that
    are ``type name`` (comments and constants left out)."""
    own = re.split(r"^={20,}\s*$", text, flags=re.M)[0]
    names = []
    for line in own.splitlines():
        parts = line.split("#", 1)[0].split()
        if len(parts) >= 2 and "=" not in parts[1] and "=" not in parts[0]:
            names.append(parts[1])
    return names


@pytest.mark.parametrize("log", [p for p in LOGS if p.suffix == ".mcap"], ids=lambda p: p.name)
def test_ros2_mcap_topics_are_counted_and_their_schema_fields_listed(inspections, log):
    from mcap.reader import make_reader

    with open(log, "rb") as f:
        summary = make_reader(f).get_summary()
    counts: dict[str, int] = {}
    for cid, n in summary.statistics.channel_message_counts.items():
        counts[summary.channels[cid].topic] = counts.get(summary.channels[cid].topic, 0) + n
    ins = _inspect(inspections, log)
    topics = {t.topic: t for t in ins.topics}
    assert {t: n for t, n in counts.items() if n} == {t: ti.messages for t, ti in topics.items()}
    text = format_inspection(ins)
    assert "from the fields above" not in text                   # no map can be written on undecoded topics
    for ch in summary.channels.values():
        if not counts.get(ch.topic):
            continue
        t = topics[ch.topic]
        schema = summary.schemas[ch.schema_id]
        assert t.encoding == ch.message_encoding == "cdr" and not t.decoded
        body = schema.data.decode()
        if re.search(r"^---\s*$", body, flags=re.M):              # a service definition: said in one line
            assert not t.fields
            line = next(ln for ln in text.splitlines() if ln.strip().startswith(f"{ch.topic}:") and "cannot" in ln)
            assert "cdr" in line
            continue
        listed = [f for f, _ in t.fields]
        assert list(dict.fromkeys(f.split(".")[0] for f in listed)) == _schema_top_fields(body)
        assert ", ".join(f"{f} (" for f in listed[:1]) in text


def test_an_mcap_channel_in_an_encoding_livesweep_cannot_read_is_named_in_one_line(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / "mixed.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        pb = w.register_schema(name="demo.Pose", encoding="protobuf", data=b"\x0a\x04demo")
        js = w.register_schema(name="rates", encoding="jsonschema", data=b'{"type": "object"}')
        c_pb = w.register_channel(topic="/pose", message_encoding="protobuf", schema_id=pb)
        c_js = w.register_channel(topic="/rates", message_encoding="json", schema_id=js)
        for k in range(20):
            t = 1_000_000_000 + k * 50_000_000
            w.add_message(channel_id=c_pb, log_time=t, publish_time=t, data=b"\x08\x01")
            w.add_message(channel_id=c_js, log_time=t, publish_time=t, data=b'{"p": 0.5, "q": -0.25, "name": "a"}')
        w.finish()
    ins = inspect_log(path)
    text = format_inspection(ins)
    pose = next(t for t in ins.topics if t.topic == "/pose")
    assert pose.messages == 20 and not pose.decoded and pose.encoding == "protobuf" and not pose.fields
    lines = [ln for ln in text.splitlines() if "/pose" in ln and "protobuf" in ln and "cannot" in ln]
    assert len(lines) == 1
    rates = next(t for t in ins.topics if t.topic == "/rates")
    assert rates.decoded and [f for f, _ in rates.fields] == ["p", "q"]


# ----------------------------------------------------------------------------- progress

def test_progress_goes_to_stderr_and_never_into_the_report(capsys):
    log = DATA / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin"
    if not log.is_file():
        pytest.skip("no SystemID log")
    size_mb = log.stat().st_size / 1e6
    buf = io.StringIO()
    ins = inspect_log(log, progress=stderr_progress(log, stream=buf, after_s=0.0))
    said = buf.getvalue().splitlines()
    assert said and all(ln.startswith(f"reading {log.name}: ") for ln in said)
    assert said[0].endswith(f" of {size_mb:.1f} MB)")      # the file framed first
    assert len(said) <= 3                                  # a line every 5 s at most when not a terminal
    assert "reading" not in format_inspection(ins)
    assert cli.main(["inspect", str(log)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{log}: dataflash") and "reading " not in out
