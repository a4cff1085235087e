#!/usr/bin/env python3
"""``recover`` of an undamaged recording against a plain mcap-library copy, measured in the same
run (single core).

The recording is the one tests/test_recover_salvage.py damages: 30 000 messages on three MAVLink
channels (ATTITUDE, SERVO_OUTPUT_RAW, HEARTBEAT) in 16 KiB zstd chunks (about 200), a metadata
record and an attachment, written by ``McapLogWriter``. Timed:

* **livesweep**: ``recover(src, out)``: every record read in file order with its CRCs checked,
  damage looked for, everything copied to a finished log (written to ``.partial`` and renamed)
  with its ``livesweep.recover`` metadata;
* **baseline**: what a user of the ``mcap`` package writes to copy a file: ``make_reader`` with
  CRC validation, ``iter_messages`` in log-time order, every schema, channel, message, metadata
  record and attachment written again with ``mcap.writer.Writer`` (same chunk size and
  compression).

Both run in turn ``--repeats`` times, best kept. This replaces the test suite's former
``assert took < 15`` (tests/test_recover_salvage.py), whose budget is printed as a line of its own.

    python benchmarks/bench_recover.py [--repeats 5]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import random  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from mcap.reader import make_reader  # noqa: E402
from mcap.writer import CompressionType, Writer  # noqa: E402

from livesweep.telemetry.mcap_log import McapLogWriter  # noqa: E402
from livesweep.telemetry.mcap_recover import recover  # noqa: E402

TOPICS = ("/mavlink/ATTITUDE", "/mavlink/SERVO_OUTPUT_RAW", "/mavlink/HEARTBEAT")
N_MESSAGES = 30_000
CHUNK = 16 * 1024
BUDGET_S = 15.0            # the tests' former bound


def record(path: Path) -> None:
    """The recording of tests/test_recover_salvage.py (``_record``, finished)."""
    w = McapLogWriter(path, chunk_size=CHUNK, compression="zstd", atomic=True, flush_every=0)
    for topic in TOPICS:
        w.add_channel(topic, "mavlink." + topic.rsplit("/", 1)[1], {"type": "object"})
    w.add_metadata("test_point", {"aircraft": "XV-15", "manoeuvre": "roll sweep"})
    w.add_attachment("case.toml", b'[case]\nname = "roll"\n', "application/toml")
    rng = random.Random(7)
    t = 1_000_000_000
    for k in range(N_MESSAGES):
        t += 4_000_000
        if k % 50 == 0:
            w.write(TOPICS[2], {"type": 2, "custom_mode": k // 50}, log_time_ns=t)
        elif k % 2:
            w.write(TOPICS[0], {"time_boot_ms": 4 * k, "roll": rng.gauss(0, 0.1), "pitch": rng.gauss(0, 0.1),
                                "yaw": rng.random()}, log_time_ns=t, publish_time_ns=4_000_000 * k)
        else:
            w.write(TOPICS[1], {"time_usec": 4000 * k, "servo": [1500 + rng.randrange(-80, 80) for _ in range(4)]},
                    log_time_ns=t)
    w.close()


def mcap_copy(src: Path, out: Path) -> int:
    """Copy ``src`` to ``out`` with the mcap package alone; returns the messages written."""
    n = 0
    with open(src, "rb") as f, open(out, "wb") as g:
        reader = make_reader(f, validate_crcs=True)
        header = reader.get_header()
        w = Writer(g, chunk_size=CHUNK, compression=CompressionType.ZSTD)
        w.start(profile=header.profile, library=header.library)
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding,
                                                          schemas.get(channel.schema_id, 0), channel.metadata)
            w.add_message(channels[channel.id], message.log_time, message.data, message.publish_time,
                          message.sequence)
            n += 1
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        for a in reader.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        w.finish()
    return n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "flight.mcap"
        record(src)
        t_ls, t_ref = [], []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            r = recover(src, Path(tmp) / "recovered.mcap")
            t_ls.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            n = mcap_copy(src, Path(tmp) / "copied.mcap")
            t_ref.append(time.perf_counter() - t0)
        assert r.messages_written == n == N_MESSAGES and r.clean, (r.messages_written, n)
        ls, ref = min(t_ls), min(t_ref)
        size = src.stat().st_size / 1e6
        print(f"single core, {N_MESSAGES} messages, {size:.2f} MB, best of {args.repeats}")
        print(f"recover (livesweep):                  {ls:7.3f} s  ({N_MESSAGES / ls:,.0f} messages/s)")
        print(f"mcap reader + writer copy (baseline): {ref:7.3f} s  ({N_MESSAGES / ref:,.0f} messages/s)")
        print(f"ratio livesweep / baseline: {ls / ref:.2f}")
        print(f"budget: {ls:.2f} s for {N_MESSAGES} messages, under {BUDGET_S:g} s: {'OK' if ls < BUDGET_S else 'MISSED'}")


if __name__ == "__main__":
    main()
