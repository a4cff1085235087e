"""Foxglove-ready recordings: every /livesweep channel has a full JSON schema, the recorded
estimate carries frequency, magnitude, phase and coherence per pair, and every path of the
layout written next to a recording resolves in that recording's messages."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from livesweep.config import read_channel_map
from livesweep.monitor.foxglove import foxglove_layout
from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
from livesweep.telemetry.recorder import McapRecorder
from livesweep.telemetry.replay import McapReplaySource

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT / "replay_logs" / "xv15_cruise_sweeps_da.mcap"
MAP = ROOT / "src" / "livesweep" / "data" / "xv15_channels.toml"


def _record(tmp_path):
    m = read_channel_map(MAP, one_clock=False)
    s = MonitorSettings(signals=m.signals, inputs=tuple(m.spectral.inputs), outputs=tuple(m.spectral.outputs),
                        band_rad_s=tuple(m.spectral.band_rad_s), sample_rate_hz=m.spectral.sample_rate_hz,
                        required_pairs=(("p", "da"),))
    out = tmp_path / "rec.mcap"
    rec = McapRecorder(out, settings=s.to_dict())
    pipe = MonitorPipeline(s, [McapReplaySource(LOG, speed=0.0)], recorder=rec, keep_estimates=1)
    pipe.run()
    return out, s, pipe


def _messages(path):
    with open(path, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        by_topic = {}
        for schema, channel, msg in r.iter_messages():
            by_topic.setdefault(channel.topic, []).append(json.loads(msg.data))
        schemas = {c.topic: json.loads(summary.schemas[c.schema_id].data) for c in summary.channels.values()}
    return by_topic, schemas


def _resolve(msg, path: str):
    """Values a Foxglove message path (after the topic) selects: fields, [:] slices, {k==v} filters."""
    items = [msg]
    for tok in re.findall(r'\.[A-Za-z0-9_]+|\[:\]|\{[^}]*\}', path):
        if tok == "[:]":
            items = [x for it in items for x in it]
        elif tok.startswith("{"):
            k, v = tok[1:-1].split("==")
            items = [it for it in items if it.get(k) == json.loads(v)]
        else:
            key = tok[1:]
            items = [it[int(key)] if isinstance(it, list) else it[key] for it in items
                     if (isinstance(it, dict) and key in it) or (isinstance(it, list) and key.isdigit())]
    return items


@pytest.mark.slow
def test_layout_paths_resolve_in_a_recording_and_estimates_carry_the_responses(tmp_path):
    out, s, pipe = _record(tmp_path)
    msgs, schemas = _messages(out)
    # every livesweep channel has a schema with its properties described
    for topic, sch in schemas.items():
        if topic.startswith("/livesweep/"):
            assert sch.get("type") == "object" and sch.get("properties"), topic
    est = msgs["/livesweep/estimate"][-1]
    pair = next(p for p in est["pairs"] if p["name"] == "p/da")
    n = len(est["omega_rad_s"])
    assert len(pair["magnitude_db"]) == len(pair["phase_deg"]) == len(pair["coherence"]) == n
    # the recorded numbers are the pipeline's estimate (the live path), to float precision
    last = pipe.estimates[-1]
    if abs(last.t_s - est["t_s"]) < 1e-9:
        np.testing.assert_allclose(pair["magnitude_db"], last.magnitude_db[0, 0], rtol=1e-12, equal_nan=True)
    assert set(pair) >= set(schemas["/livesweep/estimate"]["properties"]["pairs"]["items"]["required"])
    layout = foxglove_layout(s.signals, s.inputs, s.outputs)
    n_paths = 0
    for pid, cfg in layout["configById"].items():
        for p in cfg.get("paths", []):
            topic, rest = re.match(r"(/[A-Za-z0-9_/]+?)((?:\{.*?\})*\..*)$", p["value"]).groups()
            assert topic in msgs, p["value"]
            got = _resolve(msgs[topic][-1], rest)
            assert got and all(isinstance(x, (int, float, str)) for x in got), p["value"]
            n_paths += 1
    assert n_paths >= len(s.inputs) + len(s.outputs) + 2 * len(s.inputs) * len(s.outputs)


def test_the_shipped_layout_is_the_xv15_maps():
    from livesweep.config import load_channel_map

    sig, sp = load_channel_map(MAP)
    shipped = json.loads((ROOT / "src" / "livesweep" / "data" / "foxglove_xv15.json").read_text())
    assert shipped == json.loads(json.dumps(foxglove_layout(sig, sp.inputs, sp.outputs)))
