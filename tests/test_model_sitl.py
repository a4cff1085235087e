"""Models of real ArduPilot SystemID test points, against offline identify and against predictions.

Data: the shared ArduCopter SITL DataFlash logs of a roll-rate and a pitch-rate chirp
(``ardupilot_sitl_systemid``, README: 0.5-12 Hz, 40 s), converted and replayed through the
monitor's pipeline with the ``ardupilot-sysid-dataflash`` preset (rate demands RDes/PDes ->
rates R/P at 400 Hz).

References the monitor did not make:

* offline ``identify`` on the same samples: a case over the test point's span, the same signals
  and structure, whose frequency-response stage resamples the raw log itself. The live values
  must equal it within their Cramer-Rao bounds.
* the autopilot's own start and end texts (MSG, read with pymavlink) for where each test point is.
* predictions written from the offline fits: the true one passes, the same with its delay
  doubled breaks the prediction limit (J > 100, the method's guideline) on that pair only.
"""

from __future__ import annotations

from pathlib import Path

import pytest

pytestmark = pytest.mark.slow      # four replays of 400 Hz logs and two identifications

from conftest import SITL_LOGS as LOGS

MAP = Path(__file__).resolve().parents[1] / "src" / "livesweep" / "data" / "maps" / "ardupilot-sysid-dataflash.toml"
FIELDS = {"roll": "RDes", "pitch": "PDes", "p": "R", "q": "P"}


def _autopilot_span(log: Path, axis: int) -> tuple[float, float]:
    """The vehicle times [s] of the autopilot's "SystemID Starting: axis=N" and the next "Finished"."""
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(str(log))
    start = end = None
    while (msg := m.recv_match(type="MSG")) is not None:
        if msg.Message.startswith(f"SystemID Starting: axis={axis}") and start is None:
            start = msg.TimeUS * 1e-6
        elif msg.Message.startswith("SystemID Finished") and start is not None and end is None:
            end = msg.TimeUS * 1e-6
    return start, end


@pytest.fixture(scope="module")
def logs(sitl_mcaps):
    return sitl_mcaps


@pytest.fixture(scope="module")
def live(sitl_replays):
    return sitl_replays


def _case(path: Path, log: Path, swept: str, out: str, tp: dict, pair: dict) -> Path:
    sig = "".join(f'[signals.{n}]\ntopic = "/dataflash/RATE"\nfield = "{FIELDS[n]}"\nstamp = "TimeUS"\n'
                  f'stamp_scale = 1e-6\nunits = "deg/s"\n\n' for n in (swept, out))
    lo, hi = tp["judged_band_rad_s"]
    path.write_text(f'[case]\nname = "tp"\n\n[[identify]]\nlog = "{log}"\nstart_s = {tp["start_s"]}\n'
                    f'end_s = {tp["end_s"]}\n\n{sig}[spectral]\ninputs = ["{swept}"]\noutputs = ["{out}"]\n'
                    f'band_rad_s = [{lo}, {hi}]\nsample_rate_hz = 400.0\n\n'
                    f'[transfer_functions.fit]\noutput = "{out}"\ninput = "{swept}"\n'
                    f'numerator = "{pair["numerator"]}"\ndenominator = "{pair["denominator"]}"\n')
    return path


@pytest.fixture(scope="module")
def offline(live, logs, tmp_path_factory):
    from livesweep.stages.identify import identify

    out = {}
    for axis, r in live.items():
        [model] = r.models
        [pair] = model["pairs"]
        [tp] = [t for t in r.test_points if t["start_s"] == model["test_point"]["start_s"]]
        case = _case(tmp_path_factory.mktemp("case") / "case.toml", logs[axis], pair["input"], pair["output"], tp, pair)
        res = identify(case, until="transfer-functions", parallel=False)
        out[axis] = res.transfer_functions.fits[0]
    return out


def test_each_go_test_point_gets_one_model_at_the_autopilots_times(live):
    for axis, r in live.items():
        go = [t for t in r.test_points if t["verdict"] == "GO"]
        assert len(go) == 1 and len(r.models) == 1
        start, end = _autopilot_span(LOGS[axis], {"roll": 7, "pitch": 8}[axis])
        tp = r.models[0]["test_point"]
        assert tp["start_s"] == pytest.approx(start, abs=0.01) and tp["end_s"] == pytest.approx(end, abs=0.01)
        assert tp["number"] == r.test_points.index(go[0]) + 1
        assert r.models[0]["pairs"][0]["name"] == {"roll": "p/roll", "pitch": "q/pitch"}[axis]


def test_live_values_equal_offline_identify_within_their_cramer_rao_bounds(live, offline):
    for axis, r in live.items():
        pair = r.models[0]["pairs"][0]
        fit = offline[axis]
        assert pair["band_rad_s"] == pytest.approx(list(fit.band_rad_s), rel=1e-3)
        for p in pair["parameters"]:
            assert p["cramer_rao"] is not None, p
            off = fit.parameters[p["name"]]
            assert abs(p["value"] - off) <= p["cramer_rao"], (axis, p, off)
            assert p["cramer_rao"] == pytest.approx(fit.cramer_rao[p["name"]], rel=0.1)
        assert pair["cost"] == pytest.approx(fit.cost, rel=0.1, abs=1.0)


def _prediction(name: str, out: str, swept: str, fit, delay_factor: float) -> str:
    """A [predictions] table from a fit: its factors with their values."""
    parts = []
    for f in fit.factors:
        if f["where"] != "denominator":
            continue
        if f["kind"] == "first":
            parts.append(f"(1/{1.0 / f['inverse_time_constant']!r})")
        elif f["kind"] == "second":
            parts.append(f"[{f['zeta']!r}, {f['omega']!r}]")
        else:
            parts.append("s" if f["power"] == 1 else f"s^{f['power']}")
    assert not [f for f in fit.factors if f["where"] == "numerator"], "the default structures have no zeros"
    return (f'[predictions.{name}]\noutput = "{out}"\ninput = "{swept}"\ngain = {fit.gain!r}\n'
            f'denominator = "{" ".join(parts)}"\ndelay_s = {fit.delay_s * delay_factor!r}\n\n')


def test_a_prediction_with_its_delay_doubled_breaks_the_limit_on_its_pair_only(live, offline, logs, tmp_path):
    import livesweep

    m = tmp_path / "map.toml"
    text = MAP.read_text().replace("min_duration_s = 10.0", 'min_duration_s = 10.0\nconditions = ["alt"]')
    text = text.replace("[spectral]", '[signals.alt]\ntopic = "/dataflash/CTUN"\nfield = "Alt"\nstamp = "TimeUS"\n'
                        'stamp_scale = 1e-6\nunits = "m"\n\n[spectral]')
    m.write_text(text + "\n" + _prediction("roll_rate", "p", "roll", offline["roll"], 1.0)
                 + _prediction("pitch_rate", "q", "pitch", offline["pitch"], 2.0))
    runs = {axis: livesweep.replay(path, map=str(m)) for axis, path in logs.items()}
    roll, pitch = runs["roll"], runs["pitch"]
    [rp] = roll.models[0]["pairs"]
    [check] = [c for c in rp["limits"] if c["name"] == "prediction"]
    assert check["ok"] and check["value"] <= 100
    assert roll.models[0]["limits_ok"] and not [a for a in roll.alerts if a["kind"] == "limit"]
    [qp] = pitch.models[0]["pairs"]
    [check] = [c for c in qp["limits"] if c["name"] == "prediction"]
    assert not check["ok"] and check["value"] > 100
    alerts = [a for a in pitch.alerts if a["kind"] == "limit"]
    assert len(alerts) == 1 and alerts[0]["message"].startswith("q/pitch: prediction 'pitch_rate'")
    assert "do not proceed" in alerts[0]["message"] and "p/roll" not in alerts[0]["message"]
    # the operator's verdict says it right after the test point's label
    [tp] = [t for t in pitch.test_points if t["verdict"] == "GO"]
    assert tp["limits"] == [alerts[0]["message"]]
    [v] = [v for v in pitch.verdicts if v["test_point"] and v["test_point"]["start_s"] == tp["start_s"]]
    assert v["reasons"][1] == alerts[0]["message"]
    # the fit itself does not depend on the prediction
    assert qp["parameters"] == live["pitch"].models[0]["pairs"][0]["parameters"]
    # the map's condition, averaged over the test point, against pymavlink's reading of CTUN.Alt
    for axis, r in runs.items():
        tp = r.models[0]["test_point"]
        alt = _ctun_alt(LOGS[axis], tp["start_s"], tp["end_s"])
        assert tp["conditions"]["alt"] == pytest.approx(alt, rel=1e-6)      # CTUN.Alt is a float32
        assert r.models[0]["trend"][0]["rows"][-1]["conditions"] == tp["conditions"]


def _ctun_alt(log: Path, start_s: float, end_s: float) -> float:
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(str(log))
    vals = []
    while (msg := m.recv_match(type="CTUN")) is not None:
        if start_s <= msg.TimeUS * 1e-6 <= end_s:
            vals.append(msg.Alt)
    return sum(vals) / len(vals)


def test_the_model_is_published_on_zenoh_as_recorded(logs, live):
    """A real Zenoh session on loopback subscribes to ``livesweep/model`` while the pipeline runs
    the roll log with a publisher: it receives the model the replay recorded, as JSON."""
    import json
    import threading
    import time

    import zenoh

    from livesweep.monitor.pipeline import MonitorPipeline
    from livesweep.telemetry.replay import McapReplaySource
    from livesweep.telemetry.zenoh_io import ZenohPublisher
    from test_zenoh_io import plain_config, wait_peer, with_free_port

    got, lock = [], threading.Lock()

    def on_sample(s):
        with lock:
            got.append(json.loads(s.payload.to_bytes()))

    session, port = with_free_port(lambda p: zenoh.open(plain_config(listen=p)))
    sub = session.declare_subscriber("livesweep/model", on_sample)
    pub = ZenohPublisher(connect_port=port)
    try:
        wait_peer(pub.session)
        MonitorPipeline(live["roll"].settings, [McapReplaySource(logs["roll"])], publisher=pub,
                        keep_estimates=False).run()
        deadline = time.monotonic() + 5
        while not got and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:
        pub.close()
        sub.undeclare()
        session.close()
    assert pub.published.get("model") == 1
    assert got == [json.loads(json.dumps(live["roll"].models[0]))]
