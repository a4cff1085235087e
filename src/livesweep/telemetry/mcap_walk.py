"""The message walk: (channel id, log time, publish time, bytes) of some channels in file order.

:func:`walk_messages` takes the hand-written chunk walk (:func:`_fast_message_walk`: struct over each
decompressed chunk, CRCs checked, a damaged chunk an error naming its byte offset and log-time range,
or skipped and counted) for a finished file, and falls back to :func:`_reference_walk` (the linear
scan of an unfinished file, or mcap's reader) when that walk declines a file.
Part of :mod:`livesweep.telemetry.mcap_log` (the facade: import from there).
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Channel
from mcap.stream_reader import CRCValidationError

from livesweep.errors import LogFormatError
from livesweep.telemetry.mcap_common import _MAGIC, _crc_error_text, _crc_text
from livesweep.telemetry.mcap_json import SkippedMessages
from livesweep.telemetry.mcap_source import _Source


def _reference_walk(src: _Source, chans: Mapping[int, Channel]) -> Iterator[tuple[int, int, int, bytes]]:
    """(channel_id, log_time, publish_time, data) of ``chans`` in file order, from the linear scan
    (unfinished files) or mcap's reader with CRC checks (when the fast walk declines a file)."""
    if src.scan is not None:
        for m in src.scan.messages:
            if m.channel_id in chans:
                yield m.channel_id, m.log_time, m.publish_time, m.data
        return
    topics = sorted({c.topic for c in chans.values()})
    try:
        with open(src.path, "rb") as f:
            for _s, ch, m in make_reader(f, validate_crcs=True).iter_messages(topics=topics, log_time_order=False):
                yield ch.id, m.log_time, m.publish_time, m.data
    except CRCValidationError as e:
        raise LogFormatError(_crc_error_text(src.path, e)) from None
    except Exception as e:  # noqa: BLE001 - McapError, OSError, zstd/lz4 errors on a damaged file
        raise LogFormatError(f"cannot read messages from MCAP log {src.path}: {type(e).__name__}: {e}") from e


def walk_messages(src: _Source, chans: Mapping[int, Channel],
                  skipped: SkippedMessages | None = None) -> Iterable[tuple[int, int, int, bytes]]:
    """(channel_id, log_time, publish_time, data) of ``chans`` in file order: the fast walk for a
    finished file, else (or when it declines the file) :func:`_reference_walk`."""
    if src.summary is not None:
        try:
            walked = _fast_message_walk(src.path, set(chans), skipped)
        except LogFormatError:
            raise
        except Exception:  # noqa: BLE001 - any surprise: the reference reader decides
            walked = None
        if walked is not None:
            return walked
    return _reference_walk(src, chans)


#: The name the MCAP modules use for :func:`walk_messages`.
_walk = walk_messages


# --- fast message walk ------------------------------------------------------------------------
# mcap's reader parses every record through Python objects (about 28 us a message here); for the
# common case of a finished, chunked file with zstd/lz4/no compression this walk does the same with
# struct over each decompressed chunk (a few us a message). Anything unexpected -> None, and the
# caller falls back to mcap's reader. CRCs are checked here as mcap's reader does with
# validate_crcs=True: each chunk's CRC of its uncompressed bytes, and the data section's CRC, when
# the writer stored them (non-zero).

_OP_MESSAGE, _OP_CHUNK, _OP_FOOTER, _OP_DATA_END = 0x05, 0x06, 0x02, 0x0F

_MESSAGE_HEAD = 22                  # channel id, sequence, log time, publish time

#: Largest uncompressed chunk read [bytes]; writers use 1 MiB or less (livesweep: 256 KiB).
_MAX_CHUNK_BYTES = 2**30


def _decompress(kind: str, data: bytes, size: int) -> bytes | None:
    """A chunk's ``size`` uncompressed bytes; None for a compression this walk does not read.

    Never produces more than ``size + 1`` bytes (a crafted zstd frame may declare gigabytes); raises
    ValueError (or the codec's error) when the bytes do not decompress to exactly ``size``.
    """
    if kind == "":
        out = data
    elif kind == "zstd":
        import zstandard

        if zstandard.frame_content_size(data) > size:
            raise ValueError(f"its zstd frame declares {zstandard.frame_content_size(data)} bytes")
        out = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    elif kind == "lz4":
        import lz4.frame

        out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
    else:
        return None
    if len(out) != size:
        raise ValueError(f"it decompresses to {len(out)} bytes")
    return out


def _fast_message_walk(path: Path, channel_ids: set[int],
                       skipped: SkippedMessages | None = None) -> list[tuple[int, int, int, bytes]] | None:
    """(channel_id, log_time, publish_time, data) of the wanted channels in file order, or None.

    A damaged chunk (its CRC does not match, it does not decompress to its declared size, or it
    declares more than ``_MAX_CHUNK_BYTES``) raises LogFormatError naming the file, the chunk's
    byte offset and its log-time range; with ``skipped`` it is left out and counted instead (so is
    a data-section CRC mismatch).
    """
    import struct

    buf = path.read_bytes()
    if not buf.startswith(_MAGIC):
        return None
    out: list[tuple[int, int, int, bytes]] = []
    unpack_hdr = struct.Struct("<BQ").unpack_from
    unpack_msg = struct.Struct("<HIQQ").unpack_from
    pos, end = len(_MAGIC), len(buf) - len(_MAGIC)

    def walk(data: bytes, p: int, stop: int) -> bool:
        while p < stop:
            if p + 9 > stop:
                return False
            op, length = unpack_hdr(data, p)
            body = p + 9
            if body + length > stop:
                return False
            if op == _OP_MESSAGE:
                if length < _MESSAGE_HEAD:
                    return False
                cid, _seq, log_t, pub_t = unpack_msg(data, body)
                if cid in channel_ids:
                    out.append((cid, log_t, pub_t, data[body + _MESSAGE_HEAD:body + length]))
            p = body + length
        return True

    def damaged(text: str, reason: str) -> None:
        if skipped is None:
            raise LogFormatError(text)
        skipped.add(reason, text)

    while pos < end:
        op, length = unpack_hdr(buf, pos)
        body = pos + 9
        if op == _OP_CHUNK:
            t0, t1, size, crc = struct.unpack_from("<QQQI", buf, body)
            q = body + 28
            (clen,) = struct.unpack_from("<I", buf, q)
            kind = buf[q + 4:q + 4 + clen].decode()
            q += 4 + clen
            (rlen,) = struct.unpack_from("<Q", buf, q)
            q += 8
            what = f"the chunk at byte {pos} (log times {t0} to {t1} ns)"
            if size > _MAX_CHUNK_BYTES:
                damaged(f"{path}: {what} declares {size} bytes uncompressed; livesweep reads chunks of at most "
                        f"{_MAX_CHUNK_BYTES} bytes", "bad_chunks")
            else:
                try:
                    data = _decompress(kind, buf[q:q + rlen], size)
                except Exception as e:  # noqa: BLE001 - ValueError, zstd/lz4 errors: damaged bytes
                    damaged(f"{path}: {what} does not decompress ({kind}) to the {size} bytes it declares: "
                            f"{e}; the log is damaged", "bad_chunks")
                else:
                    if data is None:
                        return None
                    actual = zlib.crc32(data)
                    if crc and actual != crc:
                        damaged(_crc_text(path, what, crc, actual), "bad_chunks")
                    elif not walk(data, 0, size):
                        return None
        elif op == _OP_MESSAGE:
            if not walk(buf, pos, body + length):
                return None
        elif op == _OP_DATA_END:
            (crc,) = struct.unpack_from("<I", buf, body)
            actual = zlib.crc32(memoryview(buf)[:pos])
            if crc and actual != crc:
                damaged(_crc_text(path, "the data section", crc, actual), "data_section_crc")
        elif op == _OP_FOOTER:
            break
        pos = body + length
    return out
