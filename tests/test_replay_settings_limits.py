"""The monitor settings a recording carries (``livesweep_settings.json``) pass the limits a channel
map and the command line get (livesweep.limits): a crafted recording asking for a gigahertz grid,
a nanosecond update period or a thousand outputs is refused by ``livesweep replay`` in one line
naming the recording, the key and the value, before anything is allocated; the command-line
options and a map meet the same limits."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from livesweep import limits
from livesweep.config import load_channel_map
from livesweep.errors import ConfigError
from livesweep.monitor.pipeline import MonitorSettings

ROOT = Path(__file__).resolve().parents[1]
SIGNALS, _ = load_channel_map(ROOT / "config" / "xv15_channels.toml")
GOOD = MonitorSettings(signals=SIGNALS, inputs=("da", "dr"), outputs=("p", "r", "ay"), band_rad_s=(1.0, 20.0),
                       sample_rate_hz=50.0, window_s=60.0, segment_s=20.0, update_period_s=0.2,
                       required_pairs=(("p", "da"),), saturation_limits={"da": (-20.0, 20.0)})
WHERE = "rec.mcap: livesweep_settings.json"


def _saved(**changes) -> dict:
    d = json.loads(json.dumps(GOOD.to_dict()))
    d.update(changes)
    return d


def _many_outputs(n: int) -> dict:
    d = _saved()
    for k in range(n):
        d["signals"][f"o{k}"] = dict(d["signals"]["p"], name=f"o{k}")
    d["outputs"] = [f"o{k}" for k in range(n)]
    return d


def test_the_saved_settings_of_a_real_monitor_come_back_unchanged():
    back = MonitorSettings.from_dict(_saved(), where=WHERE)
    assert back == GOOD


@pytest.mark.parametrize("d, words", [
    (_saved(sample_rate_hz=1e9), ["sample_rate_hz:", "1000000000.0", f"{limits.MAX_SAMPLE_RATE_HZ:g}"]),
    (_saved(sample_rate_hz=1e6), ["sample_rate_hz:", "1000000.0"]),
    (_saved(sample_rate_hz=1e5, band_rad_s=[1.0, 20.0]), ["sample_rate_hz:", "100000.0",
                                                          f"{limits.MAX_MONITOR_RATE_HZ:g} Hz"]),
    (_saved(sample_rate_hz=float("nan")), ["sample_rate_hz:", "nan"]),
    (_saved(update_period_s=1e-9), ["update_period_s:", "1e-09", f"{limits.MIN_UPDATE_PERIOD_S:g} s"]),
    (_saved(update_period_s="fast"), ["update_period_s", "'fast'"]),
    (_many_outputs(1000), ["outputs:", "1000 outputs x 2 inputs", str(limits.MAX_MONITOR_PAIRS)]),
    (_saved(window_s=1e7), ["window_s:", "10000000.0", f"{limits.MAX_WINDOW_S:g}"]),
    (_saved(window_s=-1.0), ["window_s:", "-1.0"]),
    (_saved(segment_s=500.0), ["segment_s:", "500.0"]),
    (_saved(band_rad_s=[1.0, 1e6]), ["band_rad_s", "Nyquist"]),
    (_saved(outputs=["p", "nope"]), ["outputs[1]", "'nope'"]),
    (_saved(required_pairs=[["nope", "da"]]), ["required_pairs[0]", "'nope'"]),
    (_saved(saturation_limits={"da": [5, -5]}), ["saturation_limits.'da'", "[5, -5]"]),
    (_saved(test_points={"sources": ["x"], "axes": {}, "required": {}, "min_duration_s": 1}),
     ["test_points.sources[0]", "'x'"]),
    (_saved(vehicle={"frame class": [1]}), ["vehicle.'frame class'"]),
    (_saved(map_name=["x"]), ["map_name", "['x']"]),
    ({k: v for k, v in _saved().items() if k != "signals"}, ["signals", "missing"]),
    ([1, 2], ["JSON object"]),
])
def test_saved_settings_beyond_the_limits_are_one_line_naming_file_key_and_value(d, words):
    with pytest.raises(ConfigError) as e:
        MonitorSettings.from_dict(d, where=WHERE)
    msg = str(e.value)
    assert msg.startswith(WHERE + ": ") and "\n" not in msg and len(msg) < 600, msg
    for w in words:
        assert w in msg, (w, msg)


def test_a_saved_signal_field_is_checked_as_a_map_file_is():
    d = _saved()
    d["signals"]["p"]["field"] = " + ".join(["a"] * 1000)
    with pytest.raises(ConfigError, match=r"^rec\.mcap: livesweep_settings\.json: signals\.p\.field = .*characters"):
        MonitorSettings.from_dict(d, where=WHERE)


def _recording(path: Path, settings: dict, n_messages: int = 0) -> Path:
    """An MCAP with ``settings`` as its livesweep_settings.json and the first messages of a log."""
    with open(ROOT / "replay_logs" / "xv15_cruise_sweeps_da.mcap", "rb") as f, open(path, "wb") as g:
        r, w = make_reader(f), Writer(g)
        w.start(profile=r.get_header().profile, library="test")
        schemas, channels = {}, {}
        for k, (schema, channel, msg) in enumerate(r.iter_messages()):
            if k >= n_messages:
                break
            if channel.id not in channels:
                if schema is not None and schema.id not in schemas:
                    schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding,
                                                          schemas.get(schema.id, 0) if schema else 0,
                                                          dict(channel.metadata))
            w.add_message(channels[channel.id], msg.log_time, msg.data, msg.publish_time, msg.sequence)
        w.add_attachment(0, 0, "livesweep_settings.json", "application/json", json.dumps(settings).encode())
        w.finish()
    return path


def _replay(*args):
    return subprocess.run([sys.executable, "-m", "livesweep", "replay", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("d, key, value", [
    (_saved(sample_rate_hz=1e9), "sample_rate_hz", "1000000000.0"),
    (_saved(update_period_s=1e-9), "update_period_s", "1e-09"),
    (_many_outputs(1000), "outputs", "1000 outputs"),
])
def test_replay_refuses_a_crafted_recording_in_one_line(tmp_path, d, key, value):
    rec = _recording(tmp_path / "rec.mcap", d)
    r = _replay(rec)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{rec}: livesweep_settings.json: {key}:" in lines[0] and value in lines[0], r.stderr


@pytest.mark.slow
def test_replay_runs_a_recording_inside_the_limits_and_checks_its_overrides(tmp_path):
    rec = _recording(tmp_path / "rec.mcap", _saved(), n_messages=3000)
    r = _replay(rec)
    assert r.returncode == 0 and "the settings recorded in" in r.stdout, r.stderr
    r = _replay(rec, "--update-period", "0.001")
    assert r.returncode == 2 and r.stderr.strip() == (f"livesweep: error: --update-period: must be at least "
                                                     f"{limits.MIN_UPDATE_PERIOD_S:g} s, got 0.001"), r.stderr
    r = _replay(rec, "--case", ROOT / "config" / "xv15_channels.toml", "--window", "1e9")
    assert r.returncode == 2 and "--window:" in r.stderr and "1000000000.0" in r.stderr, r.stderr


def test_a_map_with_more_pairs_than_the_monitor_analyses_is_refused(tmp_path):
    text = (ROOT / "config" / "xv15_channels.toml").read_text()
    extra = "".join(f'\n[signals.o{k}]\ntopic = "/mavlink/ATTITUDE"\nfield = "rollspeed"\nstamp = "time_boot_ms"\n'
                    f'stamp_scale = 0.001\n' for k in range(101))
    head, _, tail = text.partition("[spectral]")
    tail = tail.replace('outputs = ["p", "r", "ay", "phi"]',
                        "outputs = [" + ", ".join(f'"o{k}"' for k in range(101)) + "]")
    cmap = tmp_path / "big_map.toml"
    cmap.write_text(head + extra + "\n[spectral]" + tail)
    rec = _recording(tmp_path / "rec.mcap", _saved())
    r = _replay(rec, "--case", cmap)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().startswith(f"livesweep: error: {cmap}: spectral.outputs: 101 outputs x 2 inputs = "
                                       f"202 pairs"), r.stderr
