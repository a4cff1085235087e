#!/usr/bin/env python3
"""livesweep's hand-written MCAP message walk against the ``mcap`` package's own reader, on a shipped log.

Reads the same file (default: the largest ``replay_logs/*.mcap``; ``--all`` for every one) both ways,
best of ``--repeat`` runs each, checks both give the same messages, and prints seconds, microseconds a
message and the ratio mcap / hand (above 1: mcap's reader is slower).

Raw messages, ``(channel id, log time, publish time, bytes)`` of every channel in file order, what
``read_topics_fields`` and ``iter_file_order`` consume:

* ``hand walk``: ``mcap_walk._walk`` on a finished file, i.e. the hand chunk walk (``_fast_message_walk``:
  chunks decompressed and CRC-checked, records unpacked with ``struct``), after ``_open`` (summary read);
* ``mcap reader, CRCs``: ``mcap_walk._reference_walk``, i.e. ``make_reader(f, validate_crcs=True)
  .iter_messages(log_time_order=False)`` after the same ``_open``: the drop-in replacement;
* ``mcap reader, no CRCs``: the same without CRC checks (not a replacement: damage would go unseen);
* ``mcap stream reader``: ``StreamReader(f, validate_crcs=True).records``, the linear pass the readers
  use for an unfinished file.

Decoded JSON objects in file order:

* ``hand: iter_file_order``: the hand walk and ``json.loads`` per message;
* ``mcap: iter_decoded_messages``: mcap's reader with a JSON ``DecoderFactory`` (``json.loads``).

    python benchmarks/bench_mcap_read.py [--repeat 5] [--all] [FILE ...]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from mcap.decoder import DecoderFactory
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader

from livesweep.telemetry.mcap_log import _open, _reference_walk, _walk, iter_file_order

LOGS = Path(__file__).resolve().parents[1] / "replay_logs"


class _JsonDecoders(DecoderFactory):
    def decoder_for(self, message_encoding, schema):
        return json.loads if message_encoding == "json" else None


def hand_walk(path: Path) -> list:
    src = _open(path)
    return list(_walk(src, src.channels))


def mcap_reader_crc(path: Path) -> list:
    src = _open(path)
    return list(_reference_walk(src, src.channels))


def mcap_reader_no_crc(path: Path) -> list:
    with open(path, "rb") as f:
        return [(ch.id, m.log_time, m.publish_time, m.data)
                for _s, ch, m in make_reader(f).iter_messages(log_time_order=False)]


def mcap_stream(path: Path) -> list:
    with open(path, "rb") as f:
        return [(r.channel_id, r.log_time, r.publish_time, r.data)
                for r in StreamReader(f, skip_magic=False, validate_crcs=True).records if isinstance(r, Message)]


def hand_decoded(path: Path) -> list:
    return [(m.topic, m.log_time_ns, m.data) for m in iter_file_order(path)]


def mcap_decoded(path: Path) -> list:
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[_JsonDecoders()])
        return [(ch.topic, m.log_time, obj) for _s, ch, m, obj in reader.iter_decoded_messages(log_time_order=False)]


RAW = [("hand walk", hand_walk), ("mcap reader, CRCs", mcap_reader_crc),
       ("mcap reader, no CRCs", mcap_reader_no_crc), ("mcap stream reader", mcap_stream)]
DECODED = [("hand: iter_file_order", hand_decoded), ("mcap: iter_decoded_messages", mcap_decoded)]


def best(fn, path: Path, repeat: int) -> tuple[float, list]:
    out, times = None, []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn(path)
        times.append(time.perf_counter() - t0)
    return min(times), out


def bench(path: Path, repeat: int) -> None:
    print(f"\n{path.name}: {path.stat().st_size / 1e6:.2f} MB, best of {repeat}")
    for title, group in (("raw messages, file order", RAW), ("decoded JSON, file order", DECODED)):
        print(f"  {title}")
        base_t, base = None, None
        for name, fn in group:
            t, out = best(fn, path, repeat)
            if base is None:
                base_t, base = t, out
                same = ""
            else:
                same = "" if out == base else "  (DIFFERENT MESSAGES)"
            n = len(out)
            print(f"    {name:<28} {t:8.3f} s  {1e6 * t / max(n, 1):6.2f} us/msg  {n:7d} msgs  "
                  f"ratio {t / base_t:5.2f}{same}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--all", action="store_true", help="every replay_logs/*.mcap")
    a = ap.parse_args()
    files = a.files or sorted(LOGS.glob("*.mcap"), key=lambda p: p.stat().st_size, reverse=True)
    if not a.files and not a.all:
        files = files[:1]
    for path in files:
        bench(path, a.repeat)


if __name__ == "__main__":
    main()
