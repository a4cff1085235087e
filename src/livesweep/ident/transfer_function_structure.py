"""Transfer-function structures in Tischler & Remple's factored shorthand (Eq. 2.8; docs/method.md §7.3).

``(1/T)`` is ``(s + 1/T)``, ``[zeta, w]`` is ``(s^2 + 2 zeta w s + w^2)``, ``s`` / ``s^n`` a free
differentiator; each value is a parameter name or a number that fixes it. :func:`parse_structure`
reads the shorthand into a :class:`Structure`, a product of :class:`Factor` objects; a
:class:`TransferFunctionModel` is a numerator, a denominator and an optional delay to fit to one
pair. Parameters: ``1/T`` [rad/s], ``zeta`` [-], ``w`` [rad/s].
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from livesweep.errors import ConfigError, quote
from livesweep.limits import MAX_TF_ORDER

__all__ = ["Factor", "Structure", "parse_structure", "TransferFunctionModel", "RESERVED_NAMES",
           "STRUCTURE_PREFIXES"]

RESERVED_NAMES = frozenset({"gain", "tau"})
#: The prefix :func:`parse_structure` gives the generated parameter names of a plain-order
#: numerator and denominator (so a numerator ``"2"`` and a denominator ``"2"`` do not share names).
STRUCTURE_PREFIXES = {"numerator": "n", "denominator": "d"}

_NAME = r"[A-Za-z_][A-Za-z0-9_]*"
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_ARG = rf"(?:{_NAME}|{_NUM})"
_RE_S = re.compile(r"s(?:\^(\d+))?")
_RE_FIRST = re.compile(rf"\(\s*1\s*/\s*({_ARG})\s*\)")
_RE_SECOND = re.compile(rf"\[\s*({_ARG})\s*,\s*({_ARG})\s*\]")
_RE_TOKEN = re.compile(r"\[[^\[\]]*\]|\([^()]*\)|[^\s\[\]()]+|\S+")
_RE_NAME = re.compile(_NAME)


@dataclass(frozen=True)
class Factor:
    """One factor of the shorthand.

    Attributes
    ----------
    kind : str
        ``"s"`` (root(s) at the origin), ``"first"`` ``(s + 1/T)`` or ``"second"``
        ``(s^2 + 2 zeta w s + w^2)``.
    names : tuple
        Parameter names as written (``None`` where a value is fixed): ``(T,)`` for a first-order
        factor, ``(zeta, w)`` for a quadratic, ``()`` for ``s``.
    fixed : tuple
        Fixed values (``None`` where free): ``(1/T [rad/s],)`` or ``(zeta [-], w [rad/s])``.
    power : int
        Power of ``s`` (kind ``"s"`` only).
    """

    kind: str
    names: tuple = ()
    fixed: tuple = ()
    power: int = 1

    @property
    def n_roots(self) -> int:
        return self.power if self.kind == "s" else (1 if self.kind == "first" else 2)

    @property
    def keys(self) -> tuple:
        """Parameter keys (``"1/T"`` for first-order factors, the names for quadratics; None if fixed)."""
        if self.kind == "first":
            return (None if self.names[0] is None else f"1/{self.names[0]}",)
        return tuple(self.names)

    @property
    def is_free(self) -> bool:
        return any(k is not None for k in self.keys)

    def text(self) -> str:
        if self.kind == "s":
            return "s" if self.power == 1 else f"s^{self.power}"
        if self.kind == "first":
            return f"(1/{self.names[0] if self.names[0] is not None else _g(1.0 / self.fixed[0])})"
        a = [n if n is not None else _g(v) for n, v in zip(self.names, self.fixed)]
        return f"[{a[0]}, {a[1]}]"


def _g(v: float) -> str:
    return f"{v:.6g}"


@dataclass(frozen=True)
class Structure:
    """A product of shorthand factors (numerator or denominator of a transfer function).

    Attributes
    ----------
    factors : tuple of Factor
        In the written order.
    text : str
        The text it was parsed from (not compared).
    """

    factors: tuple = ()
    text: str = field(default="", compare=False)

    @property
    def order(self) -> int:
        """Degree of the polynomial in s."""
        return sum(f.n_roots for f in self.factors)

    @property
    def parameter_keys(self) -> tuple:
        """Keys of the free parameters, in the written order."""
        return tuple(k for f in self.factors for k in f.keys if k is not None)

    def __str__(self) -> str:
        return " ".join(f.text() for f in self.factors) or "1"


def _arg(tok: str, text: str, what: str):
    """(name, None) for a parameter name, (None, value) for a number."""
    if _RE_NAME.fullmatch(tok):
        if tok in RESERVED_NAMES:
            raise ConfigError(f"transfer-function structure {quote(text)}: parameter name {quote(tok)} is reserved "
                              f"({', '.join(sorted(RESERVED_NAMES))} name the gain and the delay)")
        return tok, None
    v = float(tok)
    if not math.isfinite(v):
        raise ConfigError(f"transfer-function structure {quote(text)}: {what} {quote(tok)} is not finite")
    return None, v


def parse_structure(text, *, prefix: str = "") -> Structure:
    """Parse the factored shorthand of Tischler & Remple's Eq. 2.8.

    Parameters
    ----------
    text : str or int
        Factors separated by spaces: ``s``, ``s^n`` (roots at the origin), ``(1/T)`` for
        ``(s + 1/T)`` and ``[zeta, w]`` for ``(s^2 + 2 zeta w s + w^2)``. ``T``, ``zeta`` and ``w``
        are parameter names (identifiers) or numbers, which fix that value (``(1/0.05)`` is
        ``(s + 20)``; ``(1/-5)`` an unstable ``(s - 0.2)``). A plain order ``"n"`` (or int) is a
        generic n-th order polynomial in factored form: ``n // 2`` quadratics
        ``[zeta_<prefix>i, w_<prefix>i]`` and, for odd n, one ``(1/T_<prefix>1)`` first.
        ``""`` or ``"0"`` is the constant 1.
    prefix : str
        Inserted in the generated names of a plain order (the model uses ``"n"``/``"d"`` so a
        numerator ``"2"`` and a denominator ``"2"`` do not share names).

    Returns
    -------
    Structure

    Raises
    ------
    ConfigError
        Naming the token that is not a factor, a repeated or reserved parameter name, a zero
        time constant, a non-positive fixed natural frequency or an order (degree in s) above
        :data:`livesweep.limits.MAX_TF_ORDER`.
    """
    if isinstance(text, bool) or not isinstance(text, (str, int)):
        raise ConfigError(f"transfer-function structure must be text or an order, got {quote(text)}")
    src = str(text)
    t = src.strip()
    factors: list[Factor] = []

    def too_high(order) -> ConfigError:
        return ConfigError(f"transfer-function structure {quote(src)}: order {order} is above the limit of "
                           f"{MAX_TF_ORDER}")

    if re.fullmatch(r"\d+", t or "0"):
        if len(t) > 6:                                  # no int() of thousands of digits
            raise too_high(quote(t))
        n = int(t or "0")
        if n > MAX_TF_ORDER:
            raise too_high(n)
        if n % 2:
            factors.append(Factor("first", (f"T_{prefix}1",), (None,)))
        for i in range(n // 2):
            factors.append(Factor("second", (f"zeta_{prefix}{i + 1}", f"w_{prefix}{i + 1}"), (None, None)))
        return Structure(tuple(factors), src)
    order = 0
    for match in _RE_TOKEN.finditer(t):
        tok = match.group()
        if m := _RE_S.fullmatch(tok):
            if len(m.group(1) or "") > 6:
                raise too_high(f"{m.group(1)[:7]}... or more")
            p = int(m.group(1) or 1)
            if p < 1:
                raise ConfigError(f"transfer-function structure {quote(src)}: bad factor {quote(tok)} "
                                  "(power of s must be >= 1)")
            factors.append(Factor("s", (), (), p))
        elif m := _RE_FIRST.fullmatch(tok):
            name, val = _arg(m.group(1), src, "time constant")
            if name is None:
                if val == 0:
                    raise ConfigError(f"transfer-function structure {quote(src)}: factor {quote(tok)} has a zero "
                                      "time constant")
                factors.append(Factor("first", (None,), (1.0 / val,)))
            else:
                factors.append(Factor("first", (name,), (None,)))
        elif m := _RE_SECOND.fullmatch(tok):
            zn, zv = _arg(m.group(1), src, "damping")
            wn, wv = _arg(m.group(2), src, "natural frequency")
            if wn is None and not wv > 0:
                raise ConfigError(f"transfer-function structure {quote(src)}: factor {quote(tok)} needs a natural "
                                  "frequency > 0")
            factors.append(Factor("second", (zn, wn), (zv, wv)))
        else:
            raise ConfigError(f"transfer-function structure {quote(src)}: bad factor {quote(tok)} (expected s, s^n, "
                              "(1/T), [zeta, w] with names or numbers, or a plain order such as 2)")
        order += factors[-1].n_roots
        if order > MAX_TF_ORDER:          # stop at the limit, not after a crafted text's millions of factors
            raise too_high(order if match.end() == len(t) else f"{order} or more")
    seen: set = set()
    for f in factors:
        for n in f.names:
            if n is None:
                continue
            if n in seen:
                raise ConfigError(f"transfer-function structure {quote(src)}: parameter name {quote(n)} is used twice")
            seen.add(n)
    return Structure(tuple(factors), src)


@dataclass(frozen=True)
class TransferFunctionModel:
    """A transfer-function structure to fit to one pair.

    Attributes
    ----------
    name : str
    numerator, denominator : Structure or str
        Text (or an order) is parsed with :func:`parse_structure` (plain-order names get the
        prefixes ``n``/``d``).
    delay : bool
        Fit a delay ``e^(-tau s)``, ``tau >= 0`` [s].
    output, input : str, optional
        When given, the pair fitted with this model must have these names.
    """

    name: str
    numerator: Structure | str = ""
    denominator: Structure | str = ""
    delay: bool = True
    output: str | None = None
    input: str | None = None

    def __post_init__(self):
        for key, prefix in STRUCTURE_PREFIXES.items():
            if not isinstance(getattr(self, key), Structure):
                object.__setattr__(self, key, parse_structure(getattr(self, key), prefix=prefix))
        common = set(self.numerator.parameter_keys) & set(self.denominator.parameter_keys)
        if common:
            raise ConfigError(f"transfer function {self.name!r}: parameter {sorted(common)[0]!r} appears in both "
                              "numerator and denominator (use distinct names)")
