"""The recorder process: every datagram recorded as received, the analysis fed without holding it up.

References the code did not make: the bytes the sender put on the wire (a real UDP socket on
127.0.0.1) and pymavlink's own parser, for the message ids read from the frame headers.
"""

from __future__ import annotations

import base64
import socket
import time

import numpy as np
import pytest

from livesweep.telemetry import mavlink_codec as codec  # noqa: F401  (MAVLink 2 before pymavlink loads)
from livesweep.telemetry.capture import EVENT_MESSAGES, LiveCapture, frame_heads
from livesweep.telemetry.mcap_log import read_messages, read_summary
from livesweep.telemetry.recorder import RAW_TOPIC
from pymavlink.dialects.v20 import ardupilotmega as mav2

KEY = bytes(range(32))


def _frames(n: int, seed: int, signed: bool = False) -> list[bytes]:
    """Frames of assorted messages (MAVLink 2, optionally signed, and MAVLink 1)."""
    rng = np.random.default_rng(seed)
    m2 = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    if signed:
        m2.signing.secret_key, m2.signing.sign_outgoing, m2.signing.link_id = KEY, True, 0
        m2.signing.timestamp = 1
    out = []
    for k in range(n):
        choice = int(rng.integers(0, 5))
        if choice == 0:
            msg = mav2.MAVLink_attitude_message(k, *rng.standard_normal(6).tolist())
        elif choice == 1:
            msg = mav2.MAVLink_statustext_message(6, b"SystemID Starting: axis=7")
        elif choice == 2:
            msg = mav2.MAVLink_pid_tuning_message(1, *rng.standard_normal(6).tolist())
        elif choice == 3:
            msg = mav2.MAVLink_heartbeat_message(2, 3, 81, 25, 4, 3)
        else:
            msg = mav2.MAVLink_param_value_message(b"SID_F_STOP_HZ", 12.0, 9, 1300, k)
        out.append(bytes(msg.pack(m2)))
    return out


@pytest.mark.parametrize("signed", [False, True])
def test_message_and_system_ids_from_the_headers_are_pymavlinks(signed):
    """Datagrams of one to three frames: the ids read from the headers alone are the ones pymavlink
    decodes; bytes that do not frame as MAVLink say so (None)."""
    frames = _frames(300, 1, signed)
    parser = mav2.MAVLink(None)
    parser.robust_parsing = True
    if signed:
        parser.signing.secret_key = KEY
    k = 0
    while k < len(frames):
        group = frames[k:k + 1 + k % 3]
        k += len(group)
        data = b"".join(group)
        want = [(m.get_msgId(), m.get_srcSystem()) for m in parser.parse_buffer(data) or ()]
        assert frame_heads(data) == want
    assert frame_heads(b"\x00garbage") is None
    v1 = mav2.MAVLink_heartbeat_message(2, 3, 81, 25, 4, 3)
    m1 = mav2.MAVLink(None)
    m1.WIRE_PROTOCOL_VERSION = "1.0"
    assert frame_heads(bytes(v1.pack(m1, force_mavlink1=True))) == [(0, 0)]   # id 0 from system 0


@pytest.mark.slow
def test_every_datagram_is_recorded_as_received_and_test_point_evidence_is_never_shed(tmp_path):
    """An analysis that takes nothing for a while (a busy machine): the recorder records every
    datagram byte for byte and decoded, skips data for the analysis (counted), and holds back the
    test-point evidence until the analysis takes it: none of it is shed."""
    frames = _frames(20_000, 2)
    out = tmp_path / "cap.mcap"
    cap = LiveCapture(["udpin:127.0.0.1:0"], record_path=out, forward_buffer_bytes=32 * 1024)
    port = int(cap.urls[0].rsplit(":", 1)[1])
    try:
        cap.want(["/mavlink/ATTITUDE"])                         # the map's topic; PID_TUNING is not wanted
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            t0 = time.monotonic()
            for i, d in enumerate(frames):                      # ~10 000 datagrams/s, nobody polling
                s.sendto(d, ("127.0.0.1", port))
                if i % 500 == 499:
                    time.sleep(max(0.0, t0 + (i + 1) / 10_000 - time.monotonic()))
        time.sleep(1.0)
        got = []
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:                      # now the analysis catches up
            more = cap.poll(timeout_s=0.2)
            got += more
            if not more and cap.counts.get("datagrams") == len(frames):
                break
    finally:
        cap.close()
    events = [d for d in frames if frame_heads(d)[0][0] in EVENT_MESSAGES]
    got_events = [f for f in got if f.topic.rsplit("/", 1)[1] in EVENT_MESSAGES.values()]
    assert len(got_events) == len(events)                        # never shed
    assert sum(f.topic == "/mavlink/PID_TUNING" for f in got) == 1   # not wanted: its first frame only
    counts = cap.counts
    attitude_sent = sum(frame_heads(d)[0][0] == 30 for d in frames)
    attitude_got = sum(f.topic == "/mavlink/ATTITUDE" for f in got)
    assert counts["analysis_shed"] > 0                            # the analysis fell behind ...
    assert counts["analysis_shed"] == attitude_sent - attitude_got   # ... and every frame it missed is counted
    assert counts["datagrams"] == len(frames) and counts["kernel_drops"] == 0
    # the recording: every datagram as received, in order, and every message decoded
    raw = [base64.b64decode(m.data["b64"]) for m in read_messages(out, topics=RAW_TOPIC)]
    assert raw == frames
    s = read_summary(out)
    assert s.complete and sum(v for k, v in s.message_counts.items() if k.startswith("/mavlink/")) == len(frames)


def test_a_port_already_taken_is_refused_with_one_line(tmp_path):
    """A second recorder on the same UDP port (a leftover monitor, a URL given twice) would take the
    datagrams from the first: it is refused, naming the input."""
    from livesweep.errors import LivesweepError

    first = LiveCapture(["udpin:127.0.0.1:0"], record_path=tmp_path / "a.mcap")
    try:
        with pytest.raises(LivesweepError, match=r"^MAVLink input udpin:127\.0\.0\.1:\d+ cannot be opened"):
            LiveCapture([first.urls[0]], record_path=tmp_path / "b.mcap")
    finally:
        first.close()
    assert not (tmp_path / "b.mcap").exists()


@pytest.mark.slow
def test_the_kernel_buffer_holds_about_a_second_of_the_measured_stream(tmp_path):
    """A kill loses what waits in the kernel's buffer: once the rate is known the recorder sizes it to
    ``KILL_LOSS_S`` of the stream, as the kernel charges datagrams (checked here by filling a socket
    of that size with the same datagrams, without reading it)."""
    from livesweep.telemetry.capture import KILL_LOSS_S, buffer_for

    cap = LiveCapture(["udpin:127.0.0.1:0"], record_path=tmp_path / "a.mcap")
    port = int(cap.urls[0].rsplit(":", 1)[1])
    frames = _frames(400, 3)
    rate = 2000.0
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            t0 = time.monotonic()
            for i in range(int(rate * 3.5)):
                s.sendto(frames[i % len(frames)], ("127.0.0.1", port))
                if i % 100 == 99:
                    time.sleep(max(0.0, t0 + (i + 1) / rate - time.monotonic()))
                    cap.source.poll(timeout_s=0)
        granted = cap.counts["rcvbuf_bytes"][0]          # while the stream runs (it follows the rate)
    finally:
        cap.close()
    mean_len = float(np.mean([len(f) for f in frames]))
    assert granted == pytest.approx(buffer_for(rate, mean_len), rel=0.3)
    # that buffer, filled and never read, holds about KILL_LOSS_S of this stream
    r = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    r.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, granted // 2)
    r.bind(("127.0.0.1", 0))
    with r, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for i in range(int(rate * KILL_LOSS_S * 3)):
            s.sendto(frames[i % len(frames)], r.getsockname())
        r.setblocking(False)
        held = 0
        while True:
            try:
                r.recv(4096)
            except BlockingIOError:
                break
            held += 1
    assert held / rate == pytest.approx(KILL_LOSS_S, rel=0.35)


@pytest.mark.slow
def test_a_kill_under_load_loses_at_most_the_promised_seconds(tmp_path):
    """SIGKILL to the monitor and its recorder while 3 000 datagrams/s arrive and every core is busy:
    what reached the file is a prefix of what was sent, and the rest is at most ``KILL_LOSS_S`` of
    the stream (the kernel buffer) plus the second the open chunk waits for its flush."""
    import os
    import signal
    import subprocess
    import sys

    from mcap.stream_reader import StreamReader
    from mcap.records import Channel, Message

    from helpers import CpuHog
    from livesweep.telemetry.capture import KILL_LOSS_S

    out = tmp_path / "killed.mcap"
    mon = subprocess.Popen([sys.executable, "-m", "livesweep", "monitor", "--mavlink", "udpin:127.0.0.1:0",
                            "--record", str(out), "--no-status", "--no-markers"], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, start_new_session=True)
    line = mon.stdout.readline().decode()
    port = int(line.split("udpin:127.0.0.1:")[1].split(";")[0].split()[0])
    frames = _frames(400, 5)
    rate, seconds = 3000.0, 8.0
    sent = []
    try:
        with CpuHog(), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            t0 = time.monotonic()
            for i in range(int(rate * seconds)):
                d = frames[i % len(frames)] + i.to_bytes(4, "little")     # a tail makes each datagram unique
                s.sendto(d, ("127.0.0.1", port))
                sent.append(d)
                if i % 100 == 99:
                    time.sleep(max(0.0, t0 + (i + 1) / rate - time.monotonic()))
            os.killpg(mon.pid, signal.SIGKILL)
    finally:
        if mon.poll() is None:
            os.killpg(mon.pid, signal.SIGKILL)
        mon.wait(30)
    raw_id, got = None, []
    with open(out, "rb") as f:
        try:
            for rec in StreamReader(f).records:
                if isinstance(rec, Channel) and rec.topic == RAW_TOPIC:
                    raw_id = rec.id
                elif isinstance(rec, Message) and rec.channel_id == raw_id:
                    got.append(base64.b64decode(__import__("json").loads(rec.data)["b64"]))
        except Exception:  # noqa: BLE001 - the torn tail of a killed recording
            pass
    assert got == sent[:len(got)]                       # a prefix, in order, nothing altered
    lost_s = (len(sent) - len(got)) / rate
    print(f"\nkill under load: {len(sent)} sent, {len(got)} in the file, {lost_s:.2f} s of stream lost")
    assert lost_s <= KILL_LOSS_S + 1.5, lost_s
