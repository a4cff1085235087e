"""One compiled form of a channel-map signal, for the live aligner and the offline reader alike.

A signal of a channel map (:class:`~livesweep.config.SignalSpec`) says where a value lives: a
topic, a *field* and, optionally, which messages of that topic to take. This module turns it into
:class:`SignalExtractor`, the one object both paths use, so what the monitor shows live and what
``identify`` reads from the recording cannot disagree:

* **which raw fields it needs** (:attr:`SignalExtractor.read_fields`: the operands, the stamp and
  the selection fields, for :func:`~livesweep.telemetry.mcap_log.read_topics_fields`);
* **which messages it takes** (``sysid``, ``compid``, ``where``: :meth:`SignalExtractor.selects`
  on one message, :meth:`SignalExtractor.select_columns` on columns);
* **its value** in signal units, ``scale * expression + offset`` applied in one place
  (:meth:`SignalExtractor.value` on one message, :meth:`SignalExtractor.values` on numpy columns,
  vectorised; the same IEEE operations in the same order, so the two agree to the last bit).

**Fields and expressions.** A ``field`` that is one field name or path is read as it is (the fast
path): an exact key (``"servo1_raw"``, ``"control[0]"`` as pyulog flattens arrays), else a dotted
path into nested objects and lists (``"gyro.x"``, ``"controls.0"``). Anything else is an arithmetic
expression of such fields, ``+ - * /``, parentheses and numbers (``"servo2_raw - servo1_raw"``,
``"rollspeed * 57.29578"``, ``"0.5 * (servo1_raw + servo2_raw) - 1500"``), parsed by the project's
bounded, ``eval``-free parser (:mod:`livesweep.ident.expression`): the field paths are first
replaced by placeholder names of the same length, so every position in a parse error is a position
in the text as written. A key holding other characters (a space, ``-``) cannot be addressed.

**Missing samples.** Live, a message lacking an operand counts as ``missing_field``, an operand
that is not a finite number (null, text, a bool, NaN) or a result that is not finite (a division by
zero) as ``not_a_number``, and gives no sample; offline the same sample is NaN (the resampler
drops and counts it).

:func:`diagnose` says, one line per signal, why a signal found nothing in the first seconds of a
live run (no frames on its topic, a field that is not there, a selection nothing matches).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from livesweep.errors import ConfigError, quote
from livesweep.ident.expression import BinOp, Name, Neg, Node, Num, parse

if TYPE_CHECKING:  # pragma: no cover
    from livesweep.config import SignalSpec

__all__ = ["FieldExpression", "SignalExtractor", "parse_field", "compile_signal", "lookup", "found", "is_field_path",
           "as_number",
           "topics_seen_from", "diagnose", "SIGNAL_COUNT_KEYS"]

#: One field: a name, then ``.key`` / ``.index`` parts and ``[index]`` suffixes (ULog array fields).
#: Not preceded by a name character, a dot or ``]``, so the exponent of ``1.5e3`` is no field.
_FIELD = re.compile(r"(?<![A-Za-z0-9_.\]])[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z0-9_]+|\[[0-9]+\])*")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")          # a field path that is a name the parser reads as is
_PLACEHOLDER_FILL = "_QZXqzx"
_MISSING = object()

#: The per-signal counters the aligner keeps (:attr:`~livesweep.telemetry.align.GridAligner.signal_counts`).
SIGNAL_COUNT_KEYS = ("samples", "missing_field", "not_a_number", "filtered", "other_vehicle")


def is_field_path(text: str) -> bool:
    """True when ``text`` is one field name or path (``"servo1_raw"``, ``"gyro.x"``, ``"control[0]"``)."""
    return isinstance(text, str) and _FIELD.fullmatch(text) is not None


def lookup(data: Mapping[str, Any], path: str):
    """The value of field ``path`` in a message (an exact key first, else a dotted path into nested
    objects and lists, as :func:`~livesweep.telemetry.mcap_log.get_field`); a private sentinel when
    it is not there (test with :func:`found`)."""
    v = data.get(path, _MISSING)
    if v is _MISSING and "." in path:
        from livesweep.telemetry.mcap_log import get_field

        ok, v = get_field(data, path)
        if not ok:
            return _MISSING
    return v


def found(value) -> bool:
    """False for what :func:`lookup` returns when the field is not there."""
    return value is not _MISSING


def as_number(raw) -> float | None:
    """``raw`` as a finite float, or None (not a number, a bool, NaN, inf, or beyond float range)."""
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        return None
    try:
        v = float(raw)
    except OverflowError:          # an integer beyond float range (e.g. 400 digits)
        return None
    return v if math.isfinite(v) else None


# --------------------------------------------------------------------------------------------
# field expressions
# --------------------------------------------------------------------------------------------


def _evaluate(node: Node, env: Mapping[str, Any]):
    """Value of a field expression: Python floats (one message) or float64 arrays (columns)."""
    t = type(node)
    if t is Name:
        return env[node.name]
    if t is Num:
        return node.value
    if t is Neg:
        return -_evaluate(node.operand, env)
    a = _evaluate(node.left, env)
    b = _evaluate(node.right, env)
    op = node.op
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    return a / b


def _rename(node: Node, names: Mapping[str, str]) -> Node:
    """The tree with placeholder names replaced by the field paths they stand for."""
    if isinstance(node, Name):
        return Name(names.get(node.name, node.name))
    if isinstance(node, Neg):
        return Neg(_rename(node.operand, names))
    if isinstance(node, BinOp):
        return BinOp(node.op, _rename(node.left, names), _rename(node.right, names))
    return node


def _operands(node: Node, out: list[str]) -> None:
    """Field paths of the tree in first-appearance order."""
    if isinstance(node, Name):
        if node.name not in out:
            out.append(node.name)
    elif isinstance(node, Neg):
        _operands(node.operand, out)
    elif isinstance(node, BinOp):
        _operands(node.left, out)
        _operands(node.right, out)


@dataclass(frozen=True)
class FieldExpression:
    """A signal's ``field``: one field path, or arithmetic of field paths.

    Attributes
    ----------
    text : str
        As written in the map.
    operands : tuple of str
        The field paths it reads, in order of first appearance (one for a plain field).
    tree : Node or None
        The parsed expression (:mod:`livesweep.ident.expression` nodes, names = field paths);
        None for a plain field (read as it is).
    """

    text: str
    operands: tuple[str, ...]
    tree: Node | None

    @property
    def is_plain(self) -> bool:
        """True for a plain field (no arithmetic)."""
        return self.tree is None

    def evaluate(self, env: Mapping[str, Any]):
        """Value for ``env`` (operand path -> float, or -> float64 array for columns).

        Raises ZeroDivisionError for a division of Python floats by zero (arrays give inf/NaN).
        """
        if self.tree is None:
            return env[self.operands[0]]
        return _evaluate(self.tree, env)


def parse_field(text: str, where: str = "field") -> FieldExpression:
    """Parse a signal's ``field``.

    Parameters
    ----------
    text : str
        A field path (``"servo1_raw"``, ``"gyro.x"``, ``"controls.0"``, ``"control[0]"``) or an
        arithmetic expression of them (``"servo2_raw - servo1_raw"``).
    where : str
        How errors name the value, e.g. ``"map.toml: signals.roll.field"``.

    Returns
    -------
    FieldExpression

    Raises
    ------
    ConfigError
        ``"{where} = '<text>': <problem>"``: not a string, empty, a syntax error (with the
        position in ``text``), an expression that reads no field, or one beyond the parser's size
        limits.
    """
    if not isinstance(text, str):
        raise ConfigError(f"{where}: must be a string (a field or an expression of fields), got {quote(text)}")
    if not text.strip():
        raise ConfigError(f"{where}: must name a field, got {quote(text)}")
    if is_field_path(text):
        return FieldExpression(text, (text,), None)
    plain = {m.group(0) for m in _FIELD.finditer(text) if _NAME.fullmatch(m.group(0))}
    taken = set(plain)
    placeholder: dict[str, str] = {}              # field path -> a name of the same length
    for m in _FIELD.finditer(text):
        path = m.group(0)
        if path in plain or path in placeholder:
            continue
        for fill in _PLACEHOLDER_FILL:
            name = re.sub(r"[.\[\]]", fill, path)
            if name not in taken:
                break
        else:  # pragma: no cover - every fill character taken by another name of the same length
            raise ConfigError(f"{where} = {quote(text)}: cannot tell field {path!r} from the other names")
        taken.add(name)
        placeholder[path] = name
    substituted = _FIELD.sub(lambda m: placeholder.get(m.group(0), m.group(0)), text)
    back = {v: k for k, v in placeholder.items()}
    try:
        tree = parse(substituted)
    except ConfigError as e:
        msg = str(e)
        head = f"{quote(substituted)}: "
        detail = msg[len(head):] if msg.startswith(head) else msg
        for name, path in back.items():
            detail = detail.replace(repr(name), repr(path))
        raise ConfigError(f"{where} = {quote(text)}: {detail}") from None
    tree = _rename(tree, back)
    operands: list[str] = []
    _operands(tree, operands)
    if not operands:
        raise ConfigError(f"{where} = {quote(text)}: reads no field (a signal is a field or arithmetic of fields; "
                          "a constant goes into 'offset')")
    return FieldExpression(text, tuple(operands), tree)


# --------------------------------------------------------------------------------------------
# the compiled signal
# --------------------------------------------------------------------------------------------


class SignalExtractor:
    """A signal compiled once: the fields it reads, the messages it takes, its value.

    Parameters
    ----------
    spec : SignalSpec
        The signal (a map's ``[signals.NAME]``); its ``field`` is parsed here, so a spec built in
        code is checked as a map file's is.

    Attributes
    ----------
    spec : SignalSpec
    expression : FieldExpression
    conditions : tuple of (str, float)
        Every selection, ``sysid`` and ``compid`` first: a message is taken when each of these
        fields equals its value.
    read_fields : tuple of str
        Every field a message must carry for this signal: operands, the stamp field (when the
        signal has one on its own topic) and the selection fields, without repeats.
    follows_vehicle_lock : bool
        False when the signal names its own ``sysid`` or ``compid`` (it then overrides the
        aligner's lock on the first vehicle seen, for its own frames).
    """

    __slots__ = ("spec", "expression", "conditions", "read_fields", "follows_vehicle_lock", "_scale", "_offset",
                 "_plain", "_dotted")

    def __init__(self, spec: SignalSpec):
        self.spec = spec
        self.expression = parse_field(spec.field, f"signal {spec.name!r}: field")
        conds: list[tuple[str, float]] = []
        for key in ("sysid", "compid"):
            v = getattr(spec, key, None)
            if v is not None:
                conds.append((key, v))
        conds.extend(tuple(getattr(spec, "where", ()) or ()))
        self.conditions = tuple(conds)
        fields = list(self.expression.operands)
        own_stamp = spec.stamp if spec.stamp and not getattr(spec, "stamp_topic", None) else None
        for f in ([own_stamp] if own_stamp else []) + [k for k, _ in self.conditions]:
            if f not in fields:
                fields.append(f)
        self.read_fields = tuple(fields)
        self.follows_vehicle_lock = getattr(spec, "sysid", None) is None and getattr(spec, "compid", None) is None
        self._scale = spec.scale
        self._offset = spec.offset
        self._plain = self.expression.operands[0] if self.expression.is_plain else None
        self._dotted = self._plain is not None and "." in self._plain

    # -- selection ------------------------------------------------------------------------------
    def conditions_text(self) -> str:
        """The selection in words, ``"sysid = 1, axis = 2"`` ("" when every message is taken)."""
        return ", ".join(f"{k} = {_num_text(v)}" for k, v in self.conditions)

    def selects(self, data: Mapping[str, Any]) -> bool | None:
        """Whether the signal takes this message: True, False, or None when a selection field is
        missing from it (the caller counts ``missing_field``)."""
        for key, want in self.conditions:
            raw = data.get(key, _MISSING)
            if raw is _MISSING:
                raw = lookup(data, key)
                if raw is _MISSING:
                    return None
            if isinstance(raw, bool) or not isinstance(raw, (int, float)) or raw != want:
                return False
        return True

    def select_columns(self, cols: Mapping[str, np.ndarray]) -> np.ndarray | None:
        """Mask of the messages taken, from float64 columns holding at least :attr:`read_fields`;
        None when every message is taken (no selection)."""
        if not self.conditions:
            return None
        mask = None
        for key, want in self.conditions:
            m = cols[key] == float(want)
            mask = m if mask is None else mask & m
        return mask

    # -- value ----------------------------------------------------------------------------------
    def value(self, data: Mapping[str, Any]) -> tuple[float | None, str | None]:
        """``(value in signal units, None)`` of one message, or ``(None, problem)`` with problem
        ``"missing_field"`` or ``"not_a_number"``. Does not check the selection."""
        plain = self._plain
        if plain is not None:                                    # the fast path: one field
            raw = data.get(plain, _MISSING)
            if raw is _MISSING:
                if not self._dotted:
                    return None, "missing_field"
                raw = lookup(data, plain)
                if raw is _MISSING:
                    return None, "missing_field"
            v = as_number(raw)
            if v is None:
                return None, "not_a_number"
            return self._scale * v + self._offset, None
        env = {}
        for op in self.expression.operands:
            raw = data.get(op, _MISSING)
            if raw is _MISSING:
                raw = lookup(data, op)
                if raw is _MISSING:
                    return None, "missing_field"
            v = as_number(raw)
            if v is None:
                return None, "not_a_number"
            env[op] = v
        try:
            v = self._scale * _evaluate(self.expression.tree, env) + self._offset
        except ZeroDivisionError:
            return None, "not_a_number"
        return (v, None) if math.isfinite(v) else (None, "not_a_number")

    def values(self, cols: Mapping[str, np.ndarray]) -> np.ndarray:
        """Values in signal units from float64 columns (NaN where an operand is NaN or the result is
        not finite), the same operations as :meth:`value`, vectorised. A new array."""
        if self._plain is not None:
            out = self._scale * np.asarray(cols[self._plain], dtype=np.float64) + self._offset
        else:
            env = {op: np.asarray(cols[op], dtype=np.float64) for op in self.expression.operands}
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                out = self._scale * _evaluate(self.expression.tree, env) + self._offset
            out = np.array(out, dtype=np.float64, copy=True)
            if out.ndim == 0:                                     # pragma: no cover - operands are columns
                out = np.full(len(next(iter(env.values()))), float(out))
        out[~np.isfinite(out)] = np.nan
        return out


def _num_text(v) -> str:
    return str(int(v)) if isinstance(v, float) and v.is_integer() else str(v)


def compile_signal(spec: SignalSpec) -> SignalExtractor:
    """The compiled form of ``spec`` (:class:`SignalExtractor`); ConfigError naming the signal for a
    field that does not parse."""
    return SignalExtractor(spec)


# --------------------------------------------------------------------------------------------
# diagnosis
# --------------------------------------------------------------------------------------------


def topics_seen_from(frames: Iterable, into: dict | None = None) -> dict[str, tuple[int, Any]]:
    """What :func:`diagnose` needs to know about the frames received: ``{topic: (frames, sample)}``.

    ``frames`` counts every frame received on the topic (any system); ``sample`` is the ``data``
    dict of the first of them. Pass the previous result as ``into`` to add more frames.
    """
    seen = {} if into is None else into
    for f in frames:
        n, sample = seen.get(f.topic, (0, f.data))
        seen[f.topic] = (n + 1, sample)
    return seen


def _list(names: Iterable[str], limit: int) -> str:
    names = sorted(str(n) for n in names)
    more = f", ... ({len(names)} in all)" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


def _has(sample, path: str) -> bool:
    if isinstance(sample, Mapping):
        return lookup(sample, path) is not _MISSING
    keys = set(sample)
    return path in keys or path.split(".")[0] in keys


def _fields_of(sample) -> list[str]:
    return list(sample.keys() if isinstance(sample, Mapping) else sample)


def diagnose(signals: Mapping[str, SignalSpec], signal_counts: Mapping[str, Mapping[str, int]] | None,
             topics_seen: Mapping[str, tuple[int, Any]]) -> list[str]:
    """One line for each signal that found nothing, saying why.

    Parameters
    ----------
    signals : Mapping[str, SignalSpec]
        The signals to check (those the aligner aligns).
    signal_counts : Mapping[str, Mapping[str, int]] or None
        The aligner's :attr:`~livesweep.telemetry.align.GridAligner.signal_counts` (``samples``,
        ``missing_field``, ``not_a_number``, ``filtered``, ``other_vehicle`` per signal); a signal
        that has no entry, or None for all, counts as having found nothing.
    topics_seen : Mapping[str, (int, Mapping or Iterable of str)]
        For every topic received so far: ``(frames, fields)``, ``frames`` the number of frames
        received on it (any system), ``fields`` one frame's ``data`` dict (dotted paths such as
        ``gyro.x`` are then checked into it) or just the collection of its top-level field names.
        :func:`topics_seen_from` builds it from frames.

    Returns
    -------
    list of str
        In the order of ``signals``, e.g. ``"signal p: no frames on /mavlink/ATTITUDE (topics
        seen: /mavlink/HEARTBEAT, ...)"``, ``"signal da: field 'servo1_rawx' missing from
        /mavlink/SERVO_OUTPUT_RAW (fields there: ...)"``, ``"signal q: 500 frames of
        /mavlink/PID_TUNING, none with axis = 2"``. Empty when every signal has samples.
    """
    out = []
    for name, spec in signals.items():
        counts = (signal_counts or {}).get(name) or {}
        if counts.get("samples", 0) > 0:
            continue
        topic = spec.topic
        n, sample = topics_seen.get(topic, (0, ()))
        if not n:
            seen = [t for t, (k, _) in topics_seen.items() if k]
            where = f"topics seen: {_list(seen, 12)}" if seen else "no frames at all yet"
            out.append(f"signal {name}: no frames on {topic} ({where})")
            continue
        try:
            ex = compile_signal(spec)
        except ConfigError as e:
            out.append(f"signal {name}: {e}")
            continue
        missing = [f for f in ex.read_fields if not _has(sample, f)]
        stamp_topic = getattr(spec, "stamp_topic", None)
        if stamp_topic and not topics_seen.get(stamp_topic, (0, ()))[0]:
            out.append(f"signal {name}: timed by {stamp_topic}.{spec.stamp}, and no frames on {stamp_topic} yet")
        elif missing:
            what = "field" if len(missing) == 1 else "fields"
            out.append(f"signal {name}: {what} {', '.join(repr(f) for f in missing)} missing from {topic} "
                       f"(fields there: {_list(_fields_of(sample), 24)})")
        elif counts.get("filtered", 0):
            out.append(f"signal {name}: {n} frames of {topic}, none with {ex.conditions_text()}")
        elif counts.get("other_vehicle", 0):
            out.append(f"signal {name}: {n} frames of {topic}, none from the vehicle analysed (the first system "
                       "seen); give the signal a sysid (and compid) to follow another")
        elif counts.get("not_a_number", 0):
            out.append(f"signal {name}: {counts['not_a_number']} frames of {topic} gave no number (null, text, "
                       f"a non-finite value or a division by zero in {spec.field!r})")
        elif counts.get("missing_field", 0):
            out.append(f"signal {name}: {counts['missing_field']} frames of {topic} lack one of the fields "
                       f"{', '.join(repr(f) for f in ex.read_fields)}")
        else:
            out.append(f"signal {name}: {n} frames of {topic} seen, but no sample taken from them yet")
    return out
