"""Message bytes as JSON objects, how a message is named in an error, and what a lenient read skipped.

:func:`json_object` decodes one message or raises :class:`BadMessage` with a reason (a key of
:data:`SKIP_REASONS`); :class:`SkippedMessages` counts those a lenient read (``iter_file_order(...,
skipped=...)``) steps over. Part of :mod:`livesweep.telemetry.mcap_log` (the facade: import from there).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field


#: What :class:`SkippedMessages` counts, by reason.
SKIP_REASONS = {
    "not_json": "messages that are not valid JSON (also: not UTF-8, an integer of over 4300 digits)",
    "too_deep": "messages nested deeper than the JSON decoder's recursion limit",
    "not_an_object": "messages that are JSON but not an object (an array, number, string or null)",
    "not_json_encoding": "messages on a channel whose message encoding is not json",
    "bad_chunks": "chunks that fail their CRC check or do not decompress, skipped whole (their messages are not "
                  "counted one by one)",
    "data_section_crc": "1 when the data section's CRC does not match while every chunk's does (nothing dropped)",
}

_MAX_SKIP_EXAMPLES = 5


@dataclass
class SkippedMessages:
    """What a lenient read skipped; pass one to :func:`iter_file_order` (``skipped=``) to have bad
    messages skipped and counted instead of raising.

    Attributes
    ----------
    counts : dict[str, int]
        Reason (a key of :data:`SKIP_REASONS`) -> how many; reasons that never occurred are absent.
        The counts grow while the iteration runs.
    examples : list of str
        One-line descriptions of the first five skips: file, topic, message index in its topic
        and log time (or the chunk's byte offset and log-time range), and what was wrong.
    """

    counts: dict[str, int] = field(default_factory=dict)
    examples: list[str] = field(default_factory=list)

    @property
    def total(self) -> int:
        """Everything skipped, messages and chunks together."""
        return sum(self.counts.values())

    def add(self, reason: str, text: str) -> None:
        """Count one skip of ``reason`` (a key of :data:`SKIP_REASONS`) described by ``text``."""
        self.counts[reason] = self.counts.get(reason, 0) + 1
        if len(self.examples) < _MAX_SKIP_EXAMPLES:
            self.examples.append(text)


class BadMessage(Exception):
    """A message that is not a JSON object; ``reason`` is a key of SKIP_REASONS."""

    def __init__(self, reason: str, text: str) -> None:
        super().__init__(text)
        self.reason = reason


#: The name the MCAP modules use for :class:`BadMessage`.
_BadMessage = BadMessage


_JSON_KINDS = {list: "array", str: "string", int: "number", float: "number", bool: "boolean", type(None): "null"}


def json_object(data: bytes) -> dict:
    """One message's JSON object; BadMessage saying what it is instead."""
    try:
        obj = json.loads(data)
    except RecursionError:
        raise BadMessage("too_deep", "is nested too deeply to decode") from None
    except ValueError as e:        # JSONDecodeError, UnicodeDecodeError, an integer over 4300 digits
        raise BadMessage("not_json", f"is not valid JSON: {e}") from None
    if not isinstance(obj, dict):
        raise BadMessage("not_an_object", f"is a JSON {_JSON_KINDS.get(type(obj), 'value')}, not an object")
    return obj


#: The name the MCAP modules use for :func:`json_object`.
_json_object = json_object


def _at(path, topic: str, index: int, log_time: int) -> str:
    """How messages name a message: file, topic, index in its topic (file order), log time."""
    return f"{path}: topic {topic!r}: message {index} (log_time {log_time} ns)"
