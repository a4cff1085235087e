"""Matrix-entry expressions of a state-space case (docs/case-file.md), parsed without ``eval``.

An entry is a number, a parameter or constant name, or arithmetic of them::

    entry   := sum
    sum     := product (("+" | "-") product)*
    product := unary (("*" | "/") unary)*
    unary   := ("-" | "+") unary | atom
    atom    := NUMBER | NAME | "(" sum ")"

    NUMBER  := digits ["." digits] [("e" | "E") ["+" | "-"] digits]   (also ".5", "5.")
    NAME    := [A-Za-z_][A-Za-z0-9_]*

Operators associate left to right with the usual precedence, so an entry means what the same
text means in Python (``2*-3``, ``a - -b``, ``-a/b*c``). A small tokenizer and a recursive-descent
parser build an AST; :func:`compile_entry` resolves names (constants become numbers, parameters
become indices into the parameter vector ``theta``), folds constants and keeps an *affine* form
``c0 + sum_k c_k theta_k`` whenever the entry is affine in the parameters (nearly every entry of a
stability-derivative model), so matrices and their parameter derivatives are assembled without
walking trees. Non-affine entries (products or quotients of parameters) are evaluated, with their
exact gradient, by forward-mode differentiation of the tree.

Every error is a :class:`~livesweep.errors.ConfigError` naming the entry, e.g.
``F[0][2] = 'Yr - U1': unknown name 'U1'``.

Size: an entry holds at most :data:`~livesweep.limits.MAX_EXPRESSION_CHARS` characters,
:data:`~livesweep.limits.MAX_EXPRESSION_TOKENS` tokens and
:data:`~livesweep.limits.MAX_EXPRESSION_DEPTH` levels of parentheses and unary signs, so every
tree walked here (recursively) stays far inside Python's recursion limit.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError, quote
from livesweep.limits import MAX_EXPRESSION_CHARS, MAX_EXPRESSION_DEPTH, MAX_EXPRESSION_TOKENS

__all__ = ["Node", "Num", "Name", "Neg", "BinOp", "parse", "names_in", "evaluate", "CompiledEntry",
           "compile_entry"]

_TOKEN = re.compile(r"""
    \s*(?:
      (?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
    | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
    | (?P<op>[-+*/()])
    )""", re.VERBOSE)


# --- AST ---------------------------------------------------------------------------------------

class Node:
    """Base class of expression-tree nodes (immutable)."""

    __slots__ = ()


@dataclass(frozen=True)
class Num(Node):
    """A number literal."""

    value: float


@dataclass(frozen=True)
class Name(Node):
    """A parameter or constant name (resolved by :func:`compile_entry`)."""

    name: str


@dataclass(frozen=True)
class Neg(Node):
    """Unary minus."""

    operand: Node


@dataclass(frozen=True)
class BinOp(Node):
    """``left op right`` with ``op`` one of ``+ - * /``."""

    op: str
    left: Node
    right: Node


@dataclass(frozen=True)
class _Param(Node):
    """A parameter, resolved to its index in the parameter vector."""

    index: int
    name: str


# --- tokenizer and parser ----------------------------------------------------------------------

def _tokenize(text: str, where: str):
    tokens = []
    pos, n = 0, len(text)
    while pos < n:
        if text[pos:].strip() == "":
            break
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            bad = text[pos:].lstrip()[:1]
            col = len(text) - len(text[pos:].lstrip())
            raise ConfigError(f"{where}{quote(text)}: unexpected character {bad!r} at position {col}")
        kind = m.lastgroup
        tokens.append((kind, m.group(kind), m.start(kind)))
        if len(tokens) > MAX_EXPRESSION_TOKENS:
            raise ConfigError(f"{where}{quote(text)}: more than {MAX_EXPRESSION_TOKENS} numbers, names and operators; "
                              "split the model (an entry is a few terms)")
        pos = m.end()
        # a number glued to a name ("2a", "1e3x") is not arithmetic
        if kind == "num" and pos < n and (text[pos].isalnum() or text[pos] in "_."):
            raise ConfigError(f"{where}{quote(text)}: malformed number at position {m.start(kind)}")
    return tokens


class _Parser:
    def __init__(self, text: str, where: str):
        self.text, self.where = text, where
        self.tokens = _tokenize(text, where)
        self.i = 0
        self.depth = 0

    def _enter(self, pos: int) -> None:
        """One more level of parentheses or unary sign; bounded so the parser's recursion is."""
        self.depth += 1
        if self.depth > MAX_EXPRESSION_DEPTH:
            raise self._error(f"nested more than {MAX_EXPRESSION_DEPTH} levels of parentheses and signs "
                              f"(at position {pos})")

    def _error(self, msg: str):
        return ConfigError(f"{self.where}{quote(self.text)}: {msg}")

    def _peek(self):
        return self.tokens[self.i] if self.i < len(self.tokens) else (None, None, len(self.text))

    def parse(self) -> Node:
        if not self.tokens:
            raise self._error("empty expression")
        node = self._sum()
        kind, val, pos = self._peek()
        if kind is not None:
            raise self._error(f"unexpected {val!r} at position {pos}")
        return node

    def _sum(self) -> Node:
        node = self._product()
        while True:
            kind, val, _ = self._peek()
            if kind == "op" and val in "+-":
                self.i += 1
                node = BinOp(val, node, self._product())
            else:
                return node

    def _product(self) -> Node:
        node = self._unary()
        while True:
            kind, val, _ = self._peek()
            if kind == "op" and val in "*/":
                self.i += 1
                node = BinOp(val, node, self._unary())
            else:
                return node

    def _unary(self) -> Node:
        kind, val, pos = self._peek()
        if kind == "op" and val in "+-":
            self.i += 1
            self._enter(pos)
            operand = self._unary()
            self.depth -= 1
            return Neg(operand) if val == "-" else operand
        return self._atom()

    def _atom(self) -> Node:
        kind, val, pos = self._peek()
        if kind is None:
            raise self._error("unexpected end of expression")
        self.i += 1
        if kind == "num":
            value = float(val)
            if not math.isfinite(value):
                raise self._error(f"number {val} at position {pos} is beyond the float range")
            return Num(value)
        if kind == "name":
            return Name(val)
        if val == "(":
            self._enter(pos)
            node = self._sum()
            k2, v2, p2 = self._peek()
            if k2 != "op" or v2 != ")":
                raise self._error(f"missing ')' for '(' at position {pos}")
            self.i += 1
            self.depth -= 1
            return node
        raise self._error(f"unexpected {val!r} at position {pos}")


def _where(where: str) -> str:
    return f"{where} = " if where else ""


def parse(text, where: str = "") -> Node:
    """Parse an entry into an AST.

    Parameters
    ----------
    text : str or int or float
        The entry. TOML numbers are accepted as well as strings.
    where : str
        How errors name the entry, e.g. ``"F[0][2]"``.

    Raises
    ------
    ConfigError
        Empty text, a character that is not arithmetic, a syntax error, a number beyond the
        float range, or an entry beyond the size limits of the module notes (naming the entry).
    """
    if isinstance(text, bool):
        raise ConfigError(f"{_where(where)}{text!r}: must be a number or an arithmetic expression, not a boolean")
    if isinstance(text, (int, float)):
        if not math.isfinite(text):
            raise ConfigError(f"{_where(where)}{text!r}: must be finite")
        return Num(float(text))
    if not isinstance(text, str):
        raise ConfigError(f"{_where(where)}{quote(text)}: must be a string or a number, not {type(text).__name__}")
    if len(text) > MAX_EXPRESSION_CHARS:
        raise ConfigError(f"{_where(where)}{quote(text)}: {len(text)} characters; an entry holds at most "
                          f"{MAX_EXPRESSION_CHARS}")
    return _Parser(text, _where(where)).parse()


def names_in(node: Node) -> set[str]:
    """Every name the tree refers to."""
    if isinstance(node, Name):
        return {node.name}
    if isinstance(node, _Param):
        return {node.name}
    if isinstance(node, Neg):
        return names_in(node.operand)
    if isinstance(node, BinOp):
        return names_in(node.left) | names_in(node.right)
    return set()


def _apply(op: str, a, b):
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    return a / b


def evaluate(node: Node, values: dict) -> float:
    """Value of an unresolved tree for ``values`` (name -> number); division by zero gives inf/nan."""
    if isinstance(node, Num):
        return node.value
    if isinstance(node, Name):
        return float(values[node.name])
    if isinstance(node, Neg):
        return -evaluate(node.operand, values)
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(_apply(node.op, np.float64(evaluate(node.left, values)), np.float64(evaluate(node.right, values))))


# --- compiled entries --------------------------------------------------------------------------

def _resolve(node: Node, constants: dict, index: dict, text, where: str) -> Node:
    """Names -> numbers (constants) or _Param (parameters); constant subtrees folded."""
    if isinstance(node, Num):
        return node
    if isinstance(node, Name):
        if node.name in constants:
            return Num(float(constants[node.name]))
        if node.name in index:
            return _Param(index[node.name], node.name)
        raise ConfigError(f"{_where(where)}{quote(text)}: unknown name {node.name!r} (not a parameter or constant)")
    if isinstance(node, Neg):
        inner = _resolve(node.operand, constants, index, text, where)
        return Num(-inner.value) if isinstance(inner, Num) else Neg(inner)
    left = _resolve(node.left, constants, index, text, where)
    right = _resolve(node.right, constants, index, text, where)
    if isinstance(left, Num) and isinstance(right, Num):
        if node.op == "/" and right.value == 0.0:
            raise ConfigError(f"{_where(where)}{quote(text)}: division by zero")
        value = float(_apply(node.op, left.value, right.value))
        if not math.isfinite(value):
            raise ConfigError(f"{_where(where)}{quote(text)}: the constant part {left.value!r} {node.op} "
                              f"{right.value!r} overflows the float range")
        return Num(value)
    return BinOp(node.op, left, right)


def _affine(node: Node):
    """(c0, {index: c}) when the resolved tree is affine in the parameters, else None."""
    if isinstance(node, Num):
        return node.value, {}
    if isinstance(node, _Param):
        return 0.0, {node.index: 1.0}
    if isinstance(node, Neg):
        a = _affine(node.operand)
        return None if a is None else (-a[0], {k: -v for k, v in a[1].items()})
    a, b = _affine(node.left), _affine(node.right)
    if a is None or b is None:
        return None
    if node.op in "+-":
        sign = 1.0 if node.op == "+" else -1.0
        coef = dict(a[1])
        for k, v in b[1].items():
            coef[k] = coef.get(k, 0.0) + sign * v
        return a[0] + sign * b[0], coef
    if node.op == "*":
        if not a[1]:
            return a[0] * b[0], {k: a[0] * v for k, v in b[1].items()}
        if not b[1]:
            return a[0] * b[0], {k: b[0] * v for k, v in a[1].items()}
        return None
    if not b[1]:                                   # division by a constant (non-zero: folded check)
        return a[0] / b[0], {k: v / b[0] for k, v in a[1].items()}
    return None


def _forward(node: Node, theta: np.ndarray):
    """(value, gradient) of a resolved tree by forward-mode differentiation."""
    if isinstance(node, Num):
        return np.float64(node.value), np.zeros(theta.size)
    if isinstance(node, _Param):
        g = np.zeros(theta.size)
        g[node.index] = 1.0
        return np.float64(theta[node.index]), g
    if isinstance(node, Neg):
        v, g = _forward(node.operand, theta)
        return -v, -g
    a, ga = _forward(node.left, theta)
    b, gb = _forward(node.right, theta)
    if node.op == "+":
        return a + b, ga + gb
    if node.op == "-":
        return a - b, ga - gb
    if node.op == "*":
        return a * b, ga * b + a * gb
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return a / b, (ga * b - a * gb) / (b * b)


@dataclass(frozen=True)
class CompiledEntry:
    """One matrix entry, resolved against the constants and the parameter order.

    Attributes
    ----------
    text : str
        The entry as written.
    where : str
        Its name in messages, e.g. ``"F[0][2]"``.
    tree : Node
        Resolved tree (constants folded; parameters as indices).
    parameters : tuple of str
        Parameters the entry depends on.
    affine : tuple or None
        ``(c0, ((index, c), ...))`` when the entry is ``c0 + sum c theta[index]``, else None.
    """

    text: str
    where: str
    tree: Node
    parameters: tuple
    affine: tuple | None

    @property
    def is_constant(self) -> bool:
        """True when the entry depends on no parameter."""
        return not self.parameters

    def value(self, theta) -> float:
        """Entry value for the full parameter vector ``theta``."""
        if self.affine is not None:
            c0, terms = self.affine
            return c0 + sum(c * theta[k] for k, c in terms)
        with np.errstate(all="ignore"):
            return float(_forward(self.tree, np.asarray(theta, float))[0])

    def value_and_gradient(self, theta):
        """``(value, d value / d theta)`` for the full parameter vector ``theta`` (exact)."""
        theta = np.asarray(theta, float)
        if self.affine is not None:
            c0, terms = self.affine
            g = np.zeros(theta.size)
            for k, c in terms:
                g[k] += c
            return c0 + float(g @ theta), g
        with np.errstate(all="ignore"):
            v, g = _forward(self.tree, theta)
        return float(v), g


def compile_entry(text, constants: dict, parameters, where: str = "") -> CompiledEntry:
    """Parse and resolve one entry.

    Parameters
    ----------
    text : str or number
        The entry.
    constants : dict of str -> float
        Constant values (their units are the case file's).
    parameters : sequence of str
        Parameter names, in the order of the parameter vector.
    where : str
        Name of the entry for messages, e.g. ``"F[0][2]"``.

    Raises
    ------
    ConfigError
        Syntax errors, unknown names, division of constants by zero (naming the entry).
    """
    index = {name: k for k, name in enumerate(parameters)}
    tree = _resolve(parse(text, where), constants, index, text, where)
    used = sorted(names_in(tree), key=lambda n: index[n])
    aff = _affine(tree)
    if aff is not None:
        aff = (float(aff[0]), tuple((int(k), float(c)) for k, c in sorted(aff[1].items()) if c != 0.0))
    return CompiledEntry(str(text), where, tree, tuple(used), aff)
