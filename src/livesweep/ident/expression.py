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
exact gradient, from a post-order instruction list compiled once per entry (one pass for the
value, one reverse pass for the gradient).

Cost: tokenizing, parsing, resolving, the affine form, the names an entry uses and every value or
gradient are linear in the entry's length (each character, token and node handled a bounded
number of times; ``benchmarks/bench_expression.py`` times them).

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
from dataclasses import dataclass, field

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
_SPACE = re.compile(r"\s*")


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
        col = _SPACE.match(text, pos).end()          # the next non-space character (no copy of the rest)
        if col == n:
            break
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise ConfigError(f"{where}{quote(text)}: unexpected character {text[col]!r} at position {col}")
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
    out: set[str] = set()
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, (Name, _Param)):
            out.add(n.name)
        elif isinstance(n, Neg):
            stack.append(n.operand)
        elif isinstance(n, BinOp):
            stack += (n.right, n.left)
    return out


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
    """Names -> numbers (constants) or _Param (parameters); constant subtrees folded (one
    post-order walk, left operands first)."""
    done: list = []
    stack = [(node, False)]
    while stack:
        n, ready = stack.pop()
        if isinstance(n, Num):
            done.append(n)
        elif isinstance(n, Name):
            if n.name in constants:
                done.append(Num(float(constants[n.name])))
            elif n.name in index:
                done.append(_Param(index[n.name], n.name))
            else:
                raise ConfigError(f"{_where(where)}{quote(text)}: unknown name {n.name!r} (not a parameter or constant)")
        elif not ready:
            stack.append((n, True))
            stack += [(n.operand, False)] if isinstance(n, Neg) else [(n.right, False), (n.left, False)]
        elif isinstance(n, Neg):
            inner = done.pop()
            done.append(Num(-inner.value) if isinstance(inner, Num) else Neg(inner))
        else:
            right = done.pop()
            left = done.pop()
            if isinstance(left, Num) and isinstance(right, Num):
                if n.op == "/" and right.value == 0.0:
                    raise ConfigError(f"{_where(where)}{quote(text)}: division by zero")
                value = float(_apply(n.op, left.value, right.value))
                if not math.isfinite(value):
                    raise ConfigError(f"{_where(where)}{quote(text)}: the constant part {left.value!r} {n.op} "
                                      f"{right.value!r} overflows the float range")
                done.append(Num(value))
            else:
                done.append(BinOp(n.op, left, right))
    return done[0]


def _affine(node: Node):
    """(c0, {index: c}) when the resolved tree is affine in the parameters, else None.

    One walk: each node passes the factor it is multiplied by down to its operands, which add
    their terms into one dictionary (a constant subtree is a :class:`Num` after
    :func:`_resolve`).
    """
    coef: dict = {}
    c0 = 0.0
    stack = [(node, 1.0)]
    while stack:
        n, scale = stack.pop()
        if isinstance(n, Num):
            c0 += scale * n.value
        elif isinstance(n, _Param):
            coef[n.index] = coef.get(n.index, 0.0) + scale
        elif isinstance(n, Neg):
            stack.append((n.operand, -scale))
        elif n.op in "+-":
            stack.append((n.right, scale if n.op == "+" else -scale))
            stack.append((n.left, scale))
        elif n.op == "*" and isinstance(n.left, Num):
            stack.append((n.right, scale * n.left.value))
        elif n.op == "*" and isinstance(n.right, Num):
            stack.append((n.left, scale * n.right.value))
        elif n.op == "/" and isinstance(n.right, Num):     # non-zero: a zero divisor is refused when folded
            stack.append((n.left, scale / n.right.value))
        else:                                              # a product or quotient of parameters
            return None
    return c0, coef


def _program(node: Node) -> tuple:
    """The resolved tree as post-order instructions ``(op, a, b)``: ``("num", value, 0)``,
    ``("par", index, 0)``, ``("neg", slot, 0)`` or ``(operator, left slot, right slot)``; the
    last instruction computes the entry."""
    code: list = []
    slots: list = []
    stack = [(node, False)]
    while stack:
        n, ready = stack.pop()
        if isinstance(n, Num):
            code.append(("num", float(n.value), 0))
        elif isinstance(n, _Param):
            code.append(("par", n.index, 0))
        elif not ready:
            stack.append((n, True))
            stack += [(n.operand, False)] if isinstance(n, Neg) else [(n.right, False), (n.left, False)]
            continue
        elif isinstance(n, Neg):
            code.append(("neg", slots.pop(), 0))
        else:
            b = slots.pop()
            code.append((n.op, slots.pop(), b))
        slots.append(len(code) - 1)
    return tuple(code)


def _run(code: tuple, theta: np.ndarray) -> list:
    """The value of every instruction of :func:`_program` for ``theta`` (float64; division by
    zero gives inf/nan)."""
    v: list = [None] * len(code)
    with np.errstate(all="ignore"):
        for k, (op, a, b) in enumerate(code):
            if op == "num":
                v[k] = np.float64(a)
            elif op == "par":
                v[k] = theta[a]
            elif op == "neg":
                v[k] = -v[a]
            elif op == "+":
                v[k] = v[a] + v[b]
            elif op == "-":
                v[k] = v[a] - v[b]
            elif op == "*":
                v[k] = v[a] * v[b]
            else:
                v[k] = v[a] / v[b]
    return v


def _gradient(code: tuple, v: list, size: int) -> np.ndarray:
    """d(entry)/d(theta) by one reverse pass over :func:`_program`'s instructions and their values."""
    g = np.zeros(size)
    adj = [0.0] * len(code)
    adj[-1] = 1.0
    with np.errstate(all="ignore"):
        for k in range(len(code) - 1, -1, -1):
            op, a, b = code[k]
            d = adj[k]
            if op == "par":
                g[a] += d
            elif op == "neg":
                adj[a] -= d
            elif op == "+":
                adj[a] += d
                adj[b] += d
            elif op == "-":
                adj[a] += d
                adj[b] -= d
            elif op == "*":
                adj[a] += d * v[b]
                adj[b] += d * v[a]
            elif op == "/":
                adj[a] += d / v[b]
                adj[b] -= d * v[a] / (v[b] * v[b])
    return g


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
    program : tuple
        The tree as post-order instructions (how a non-affine entry is evaluated).
    """

    text: str
    where: str
    tree: Node
    parameters: tuple
    affine: tuple | None
    program: tuple = field(default=(), compare=False, repr=False)

    def __post_init__(self):
        if not self.program:
            object.__setattr__(self, "program", _program(self.tree))

    @property
    def is_constant(self) -> bool:
        """True when the entry depends on no parameter."""
        return not self.parameters

    def value(self, theta) -> float:
        """Entry value for the full parameter vector ``theta``."""
        if self.affine is not None:
            c0, terms = self.affine
            return c0 + sum(c * theta[k] for k, c in terms)
        return float(_run(self.program, np.asarray(theta, float))[-1])

    def value_and_gradient(self, theta):
        """``(value, d value / d theta)`` for the full parameter vector ``theta`` (exact)."""
        theta = np.asarray(theta, float)
        if self.affine is not None:
            c0, terms = self.affine
            g = np.zeros(theta.size)
            for k, c in terms:
                g[k] += c
            return c0 + float(g @ theta), g
        v = _run(self.program, theta)
        return float(v[-1]), _gradient(self.program, v, theta.size)


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
