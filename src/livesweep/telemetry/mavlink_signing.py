"""MAVLink 2 signing checks for :class:`~livesweep.telemetry.mavlink_decode.MavlinkDecoder`.

One job: decide whether a frame's signature is accepted, and count what is refused. The signature
is compared first (SHA-256 of key and frame, constant time) and only then is the stream's signing
time stamp checked and advanced, so a forged frame cannot move a stream's time stamp (pymavlink's
own ``check_signature`` stores the time stamp before it compares the signature). Unsigned frames
are counted here and accepted only with ``allow_unsigned``; a frame whose signature was refused is
never accepted. The counters are described in :mod:`livesweep.telemetry.mavlink_in`.
"""

from __future__ import annotations

import hashlib
import hmac
from typing import Any

from livesweep.errors import ConfigError

# signing time stamps count 10 µs units since 2015-01-01
_SIGNING_EPOCH_S = 1_420_070_400
# a new signing stream may be this much older than the newest time stamp seen (1 min in 10 µs units)
_SIGNING_NEW_STREAM_UNITS = 6_000_000


def _check_key(signing_key: Any) -> bytes | None:
    if signing_key is None:
        return None
    if not isinstance(signing_key, (bytes, bytearray)) or len(signing_key) != 32:
        n = len(signing_key) if hasattr(signing_key, "__len__") else "?"
        raise ConfigError(
            "MAVLink signing key must be 32 bytes (e.g. hashlib.sha256(passphrase).digest()), "
            f"got {type(signing_key).__name__} of length {n}"
        )
    return bytes(signing_key)


class _SigningChecks:
    """The signing callbacks a decoder installs in its pymavlink parsers.

    Used as a base class of :class:`~livesweep.telemetry.mavlink_decode.MavlinkDecoder`, which holds
    the state these methods read and advance: ``_key`` (the 32-byte key), ``_allow_unsigned``,
    ``_sign_streams`` (newest signing time stamp per (link id, sysid, compid)), ``_sign_time`` (the
    newest overall), ``_refused_signed`` (the last signed frame was refused), ``_refused_arrivals``
    (refused signed frames per (sysid, compid) since its last good one), ``counts`` and
    ``_warn_once``.
    """

    def _check_signature(self, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        """The signature first, then the stream's time stamp (MAVLink 2 signing, replay protection)."""
        key = self._key
        assert key is not None
        expected = hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6]
        arrived = self._refused_arrivals
        if not hmac.compare_digest(expected, bytes(msgbuf[-6:])):
            self._refuse_signed("bad_signature", "signed MAVLink frame with a wrong signature refused "
                                "(forged, or signed with another key)")
            arrived[(src_system, src_component)] = arrived.get((src_system, src_component), 0) + 1
            return False
        stamp = int.from_bytes(bytes(msgbuf[-12:-6]), "little")
        stream = (msgbuf[-13], src_system, src_component)
        last = self._sign_streams.get(stream)
        if (stamp <= last) if last is not None else (stamp + _SIGNING_NEW_STREAM_UNITS < self._sign_time):
            self.counts["replayed_signature"] += 1
            self._refuse_signed("bad_signature", "signed MAVLink frame refused: its signing time stamp is not newer "
                                "than its stream's (a replay)")
            arrived[(src_system, src_component)] = arrived.get((src_system, src_component), 0) + 1
            return False
        self._sign_streams[stream] = stamp
        self._sign_time = max(self._sign_time, stamp)
        return True

    def _refuse_signed(self, counter: str, text: str) -> None:
        self.counts[counter] += 1
        self._refused_signed = True
        self._warn_once(counter, text + "; further ones are only counted")

    # pymavlink calls this for unsigned frames AND for signed frames whose check failed
    def _unsigned_callback(self, mav: Any, msgid: int) -> bool:
        if self._refused_signed:
            self._refused_signed = False
            return False  # a bad signature is never accepted, not even with allow_unsigned
        if self._allow_unsigned:
            self.counts["unsigned_accepted"] += 1
            return True
        self.counts["rejected_unsigned"] += 1
        self._warn_once("unsigned", "unsigned MAVLink frame rejected (signing key set); further ones are only counted")
        return False
