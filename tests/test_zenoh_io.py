"""Zenoh input/output on real loopback peer sessions (no mocks, no router).

The other end of each test is built with the plain zenoh API and its own loopback config, so
it does not depend on the code under test.
"""

from __future__ import annotations

import json
import math
import socket
import threading
import time

import pytest

from helpers import collect_frames as collect, tcp_listeners
import zenoh

from livesweep.errors import ConfigError, LivesweepError
from livesweep.telemetry.zenoh_io import ZenohPublisher, ZenohSource, zenoh_config


# ----------------------------------------------------------------------------- helpers


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def plain_config(*, listen: int | None = None, connect: int | None = None) -> zenoh.Config:
    """A loopback peer config written with the raw zenoh API (independent of zenoh_config)."""
    c = zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("listen/endpoints", json.dumps([] if listen is None else [f"tcp/127.0.0.1:{listen}"]))
    c.insert_json5("connect/endpoints", json.dumps([] if connect is None else [f"tcp/127.0.0.1:{connect}"]))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "false")
    return c


def with_free_port(make, tries: int = 5):
    """``make(port)`` on a free port, retrying when another process took it meanwhile."""
    last: Exception | None = None
    for _ in range(tries):
        port = free_port()
        try:
            return make(port), port
        except (LivesweepError, zenoh.ZError) as e:
            last = e
    raise AssertionError(f"no free port after {tries} tries: {last}")


def wait_peer(session: zenoh.Session, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not list(session.info.peers_zid()):
        assert time.monotonic() < deadline, "zenoh peers did not connect"
        time.sleep(0.01)


def listeners_on(port: int) -> list[str] | None:
    return tcp_listeners(port)


def test_source_receives_objects_blocks_and_counts_malformed():
    src, port = with_free_port(lambda p: ZenohSource("vehicle/**", listen_port=p, stamp_field="t_s"))
    pub_session = None
    try:
        # the listener is on loopback only (and nothing else of ours listens on that port)
        addrs = listeners_on(port)
        if addrs is not None:
            assert addrs == ["127.0.0.1"], addrs
        assert json.loads(zenoh_config(listen=[port]).get_json("listen/endpoints")) == [f"tcp/127.0.0.1:{port}"]

        pub_session = zenoh.open(plain_config(connect=port))
        wait_peer(pub_session)
        imu = pub_session.declare_publisher("vehicle/imu", congestion_control=zenoh.CongestionControl.BLOCK)
        blk = pub_session.declare_publisher("vehicle/blk", congestion_control=zenoh.CongestionControl.BLOCK)
        bad = pub_session.declare_publisher("vehicle/bad", congestion_control=zenoh.CongestionControl.BLOCK)

        expected: dict[str, list[dict]] = {"vehicle/imu": [], "vehicle/blk": []}
        n_malformed = n_non_object = 0
        malformed = [b"{broken", b"\xff\xfe\x00 not utf-8", b"", b'{"a": 1,}', b"[1, 2"]
        non_object = [b"42", b'"text"', b"null", b"true"]
        n_samples = 500
        for i in range(n_samples):
            if i % 10 == 3:  # a block: JSON array of objects (with one non-object inside, every other block)
                items: list = [{"t_s": i * 0.001 + k * 1e-4, "k": k, "i": i} for k in range(3)]
                expected["vehicle/blk"] += items
                if i % 20 == 3:
                    items = items[:1] + [7] + items[1:]
                    n_non_object += 1
                blk.put(json.dumps(items))
            elif i % 25 == 7:
                bad.put(malformed[(i // 25) % len(malformed)])
                n_malformed += 1
            elif i % 25 == 8:
                bad.put(non_object[(i // 25) % len(non_object)])
                n_non_object += 1
            else:
                obj = {"t_s": i * 0.001, "p": math.sin(i), "name": f"s{i}", "nested": {"v": [i, i + 1]}}
                expected["vehicle/imu"].append(obj)
                imu.put(json.dumps(obj))
        n_good = sum(len(v) for v in expected.values())
        t_sent = time.time_ns()
        frames = collect(src, n_good)
        counts = src.counts
        for p in (imu, blk, bad):
            p.undeclare()
    finally:
        src.close()
        if pub_session is not None:
            pub_session.close()

    assert len(frames) == n_good
    for key, objs in expected.items():
        got = [f for f in frames if f.topic == f"/zenoh/{key}"]
        assert [f.data for f in got] == objs
        assert [f.vehicle_ns for f in got] == [int(round(o["t_s"] * 1e9)) for o in objs]
        assert all(0 < f.receive_ns <= t_sent + 10**10 for f in got)
    # the three objects of one block share one receive time
    blk_frames = [f for f in frames if f.topic == "/zenoh/vehicle/blk"]
    assert blk_frames[0].receive_ns == blk_frames[1].receive_ns == blk_frames[2].receive_ns
    assert counts["received"] == {k: len(v) for k, v in expected.items()}
    assert counts["malformed"] == n_malformed
    assert counts["non_object"] == n_non_object
    assert counts["samples"] == n_samples
    assert counts["dropped_queue_full"] == 0 and counts["bad_stamp"] == 0
    with pytest.raises(LivesweepError):
        src.poll()
    src.close()  # idempotent


def test_source_queue_limit_stamp_rules_and_poll_timing():
    src, port = with_free_port(lambda p: ZenohSource(
        "q/*", listen_port=p, stamp_field="t_us", stamp_scale_ns_per_unit=1000, max_queue=10))
    pub_session = zenoh.open(plain_config(connect=port))
    try:
        wait_peer(pub_session)
        t0 = time.monotonic()
        assert src.poll(0.2) == []
        assert 0.15 <= time.monotonic() - t0 < 2.0
        pub = pub_session.declare_publisher("q/a", congestion_control=zenoh.CongestionControl.BLOCK)
        pub.put(json.dumps({"t_us": 1_234_567_890_123_456}))  # integer stamp: exact
        pub.put(json.dumps({"t_us": "late"}))  # not a number -> vehicle_ns None, counted
        pub.put(json.dumps({"x": 1}))  # missing -> vehicle_ns None, counted
        for i in range(47):
            pub.put(json.dumps({"t_us": i}))
        pub_session.delete("q/a")  # a DELETE sample: counted, no frame
        deadline = time.monotonic() + 5
        while src.counts["dropped_queue_full"] + 10 < 51 and time.monotonic() < deadline:
            time.sleep(0.02)  # do not poll: let the queue fill
        frames = src.poll(0.5)
        c = src.counts
        pub.undeclare()
    finally:
        src.close()
        pub_session.close()
    assert len(frames) == 10 and c["dropped_queue_full"] == 41  # 51 samples, 10 queued
    assert frames[0].vehicle_ns == 1_234_567_890_123_456_000
    assert frames[1].vehicle_ns is None and frames[2].vehicle_ns is None
    # t_us 0.. after a stamp 39 years later does not follow the key's clock: no vehicle time (frames
    # still delivered) until five consecutive stamps agree on the new clock (a re-anchoring)
    assert [f.vehicle_ns for f in frames[3:7]] == [None] * 4
    assert [f.vehicle_ns for f in frames[7:]] == [4000, 5000, 6000]
    assert c["bad_stamp"] == 2 + 4
    assert [f.data["t_us"] for f in frames[3:]] == list(range(7))


# ----------------------------------------------------------------------------- ZenohPublisher


def test_publisher_puts_json_with_block():
    received: list[tuple[str, bytes, zenoh.Sample]] = []
    lock = threading.Lock()

    def on_sample(s: zenoh.Sample) -> None:
        with lock:
            received.append((str(s.key_expr), s.payload.to_bytes(), s))

    sub_session, port = with_free_port(lambda p: zenoh.open(plain_config(listen=p)))
    sub = sub_session.declare_subscriber("livesweep/**", on_sample)
    pub = ZenohPublisher(connect_port=port)
    try:
        wait_peer(pub.session)
        for i in range(50):
            pub.publish("coherence/roll", {"i": i, "f_hz": [0.5, 1.0], "coh": [0.9, 0.95]})
        pub.publish("events", {"msg": "sweep done", "bad": math.nan, "inf": [math.inf, 1.0]})
        pub.publish("block", [{"k": 0}, {"k": 1}])
        with pytest.raises(ConfigError):
            pub.publish("x/*", {"a": 1})
        with pytest.raises(ConfigError):
            pub.publish("events", {"a": object()})
        with pytest.raises(ConfigError):
            pub.publish("events", "not a dict")  # type: ignore[arg-type]
        deadline = time.monotonic() + 5
        while len(received) < 52 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert pub.published == {"coherence/roll": 50, "events": 1, "block": 1}
        assert pub.non_finite == 2
    finally:
        pub.close()
        pub.close()
        sub.undeclare()
        sub_session.close()
    with pytest.raises(LivesweepError):
        pub.publish("events", {})
    assert len(received) == 52
    roll = [json.loads(p) for k, p, _ in received if k == "livesweep/coherence/roll"]
    assert roll == [{"i": i, "f_hz": [0.5, 1.0], "coh": [0.9, 0.95]} for i in range(50)]
    ev = [(json.loads(p), s) for k, p, s in received if k == "livesweep/events"]
    assert ev[0][0] == {"msg": "sweep done", "bad": "NaN", "inf": ["Infinity", 1.0]}  # valid JSON, says which
    assert str(ev[0][1].encoding).startswith("application/json")
    assert ev[0][1].congestion_control == zenoh.CongestionControl.BLOCK
    assert [json.loads(p) for k, p, _ in received if k == "livesweep/block"] == [[{"k": 0}, {"k": 1}]]


def test_source_and_publisher_together():
    """ZenohPublisher -> ZenohSource, both from this module (the monitor's own round trip)."""
    src, port = with_free_port(lambda p: ZenohSource("livesweep/**", listen_port=p))
    pub = ZenohPublisher(connect_port=port)
    try:
        wait_peer(pub.session)
        for i in range(20):
            pub.publish("result", {"i": i})
        frames = collect(src, 20)
    finally:
        pub.close()
        src.close()
    assert [f.data for f in frames] == [{"i": i} for i in range(20)]
    assert {f.topic for f in frames} == {"/zenoh/livesweep/result"}
    assert all(f.vehicle_ns is None for f in frames)


# ----------------------------------------------------------------------------- configuration


def test_zenoh_config_defaults_and_files(tmp_path):
    c = zenoh_config()
    assert json.loads(c.get_json("listen/endpoints")) == []
    assert json.loads(c.get_json("connect/endpoints")) == []
    assert json.loads(c.get_json("mode")) == "peer"
    assert json.loads(c.get_json("scouting/multicast/enabled")) is False
    assert json.loads(c.get_json("scouting/gossip/enabled")) is False
    c = zenoh_config(listen=[7447], connect=["tcp/10.1.2.3:7447"], mode="client")
    assert json.loads(c.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(c.get_json("connect/endpoints")) == ["tcp/10.1.2.3:7447"]
    assert json.loads(c.get_json("mode")) == "client"

    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: ")
    missing = tmp_path / "missing.json5"
    wrong = tmp_path / "wrong.json5"
    wrong.write_text('{ mode: "nonsense" }')
    for p in (bad, missing, wrong):
        with pytest.raises(ConfigError) as e:
            zenoh_config(config_path=p)
        assert str(p) in str(e.value)

    # a deployment file without listen endpoints does not get the all-interfaces default
    nolisten = tmp_path / "router.json5"
    nolisten.write_text('{ mode: "router", connect: { endpoints: ["tcp/127.0.0.1:1"] } }')
    c = zenoh_config(config_path=nolisten)
    assert json.loads(c.get_json("listen/endpoints")) == []
    assert json.loads(c.get_json("mode")) == "router"
    explicit = tmp_path / "explicit.json5"
    explicit.write_text('{ mode: "peer", listen: { endpoints: ["tcp/127.0.0.1:0"] }, '
                        'scouting: { multicast: { enabled: false } } }')
    c = zenoh_config(config_path=explicit)
    assert json.loads(c.get_json("listen/endpoints")) == ["tcp/127.0.0.1:0"]
    assert json.loads(zenoh_config(config_path=explicit, listen=[9]).get_json("listen/endpoints")) == ["tcp/127.0.0.1:9"]

    # what a file does not set stays as safe as without a file: scouting off unless "enabled" is set
    for text, on in (('{ mode: "peer" }', False),
                     ('{ scouting: { multicast: { address: "224.0.0.224:7446" } } } // multicast: { enabled: true }',
                      False),
                     ('{ scouting: { multicast: { autoconnect: { router: ["peer"] }, enabled: true } } }', True),
                     ('{ "scouting": { "gossip": { "enabled": true } } }', False)):
        f = tmp_path / "scouting.json5"
        f.write_text(text)
        c = zenoh_config(config_path=f)
        assert json.loads(c.get_json("scouting/multicast/enabled")) is on, text
    assert json.loads(c.get_json("scouting/gossip/enabled")) is True          # the last file sets it

    for kw in ({"mode": "satellite"}, {"listen": ["no-slash"]}, {"listen": [70000]}, {"connect": [True]}):
        with pytest.raises(ConfigError):
            zenoh_config(**kw)
    with pytest.raises(ConfigError):
        ZenohSource("a/**", config=zenoh_config(), listen_port=1)
    for key in ("", "a//b", "/a"):
        with pytest.raises(ConfigError):
            ZenohSource(key)
    with pytest.raises(ConfigError):
        ZenohPublisher(prefix="live/*")
    with pytest.raises(ConfigError):
        ZenohSource("a/**", stamp_scale_ns_per_unit=0)


def test_sessions_close_cleanly():
    """Sessions with listeners close, free their port, and leave no Python threads behind."""
    before = {t.ident for t in threading.enumerate()}
    src, port = with_free_port(lambda p: ZenohSource("c/**", listen_port=p))
    pub = ZenohPublisher(connect_port=port, prefix="c")
    wait_peer(pub.session)
    pub.publish("x", {"a": 1})
    assert [f.data for f in collect(src, 1, settle=0.0)] == [{"a": 1}]
    pub.close()
    src.close()
    assert src.session.is_closed() and pub.session.is_closed()
    time.sleep(0.1)
    extra = [t for t in threading.enumerate() if t.ident not in before and not t.daemon]
    assert extra == []
    addrs = listeners_on(port)
    if addrs is not None:
        assert addrs == []
    # the port can be listened on again right away
    again = ZenohSource("c/**", listen_port=port)
    again.close()
