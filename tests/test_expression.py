"""Matrix-entry expressions: parsed without eval, checked against Python's own arithmetic."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from livesweep.errors import ConfigError
from livesweep.ident.expression import BinOp, Name, Neg, Num, compile_entry, evaluate, names_in, parse

VALUES = {"Yv": -0.2797, "Yr": 16.44, "U0": 286.93, "g": 32.174, "a": 2.5, "b_2": -3.0}


def test_numbers_names_and_precedence():
    assert parse("57.2958") == Num(57.2958)
    assert parse("1e-3") == Num(1e-3)
    assert parse(".5") == Num(0.5) and parse("5.") == Num(5.0) and parse("2.5E+2") == Num(250.0)
    assert parse("Yr - U0") == BinOp("-", Name("Yr"), Name("U0"))
    assert parse("-a*b_2") == BinOp("*", Neg(Name("a")), Name("b_2"))
    assert parse("57.2958/U0") == BinOp("/", Num(57.2958), Name("U0"))
    assert evaluate(parse("1 - 2 - 3"), {}) == -4.0                  # left associative
    assert evaluate(parse("8 / 4 / 2"), {}) == 1.0
    assert evaluate(parse("2 + 3 * 4"), {}) == 14.0
    assert evaluate(parse("(2 + 3) * 4"), {}) == 20.0
    assert evaluate(parse("2*-3"), {}) == -6.0 and evaluate(parse("a - -b_2"), VALUES) == -0.5
    assert evaluate(parse(3), {}) == 3.0                              # TOML numbers are accepted
    assert names_in(parse("(Yr - U0) * g / a")) == {"Yr", "U0", "g", "a"}


@pytest.mark.parametrize("text, msg", [
    ("", "empty expression"),
    ("   ", "empty expression"),
    ("Yr -", "unexpected end of expression"),
    ("Yr + * 2", "unexpected '\\*'"),
    ("(Yr - U0", "missing '\\)'"),
    ("Yr - U0)", "unexpected '\\)'"),
    ("Yr ** 2", "unexpected '\\*'"),
    ("Yr ^ 2", "unexpected character '\\^'"),
    ("sin(Yr)", "unexpected '\\('"),
    ("__import__('os')", "unexpected character"),
    ("2a", "malformed number"),
    ("1.2.3", "malformed number"),
    ("Yr U0", "unexpected 'U0'"),
    ("Yr; U0", "unexpected character ';'"),
])
def test_bad_text_is_a_config_error_naming_the_entry(text, msg):
    with pytest.raises(ConfigError, match=r"F\[0\]\[2\] = .*: " + msg):
        parse(text, where="F[0][2]")


def test_non_string_entries():
    with pytest.raises(ConfigError, match=r"G\[1\]\[0\] = True: must be a number"):
        parse(True, where="G[1][0]")
    with pytest.raises(ConfigError, match=r"G\[1\]\[0\] = \[1\]: must be a string or a number"):
        parse([1], where="G[1][0]")
    with pytest.raises(ConfigError, match="must be finite"):
        parse(float("nan"), where="G[1][0]")


def test_unknown_name_is_named():
    with pytest.raises(ConfigError, match=r"^F\[0\]\[2\] = 'Yr - U1': unknown name 'U1'"):
        compile_entry("Yr - U1", {"U0": 286.93}, ["Yr"], "F[0][2]")


def test_constant_division_by_zero_is_caught():
    with pytest.raises(ConfigError, match=r"H\[3\]\[0\] = '57.2958/U0': division by zero"):
        compile_entry("57.2958/U0", {"U0": 0.0}, [], "H[3][0]")


def test_compiled_entries_affine_forms_values_and_gradients():
    consts = {"U0": 286.93, "g": 32.174}
    params = ["Yv", "Yr", "Lp"]
    e = compile_entry("Yr - U0", consts, params, "F[0][2]")
    assert e.affine == (-286.93, ((1, 1.0),)) and e.parameters == ("Yr",)
    theta = np.array([-0.28, 16.44, -0.68])
    assert e.value(theta) == pytest.approx(16.44 - 286.93)
    c = compile_entry("57.2958/U0", consts, params)
    assert c.is_constant and c.value(theta) == pytest.approx(57.2958 / 286.93)
    a = compile_entry("2*(Yv - 3*Lp)/4 + g", consts, params)
    assert a.affine is not None
    v, grad = a.value_and_gradient(theta)
    assert v == pytest.approx(2 * (-0.28 - 3 * -0.68) / 4 + 32.174)
    np.testing.assert_allclose(grad, [0.5, 0.0, -1.5])
    # non-affine entries: exact forward-mode gradient, checked by central differences
    n = compile_entry("Yv*Yr/(Lp - 1) - Yr/Yv", consts, params)
    assert n.affine is None
    v, grad = n.value_and_gradient(theta)
    f = lambda t: t[0] * t[1] / (t[2] - 1) - t[1] / t[0]
    assert v == pytest.approx(f(theta))
    h = 1e-6
    num = [(f(theta + h * np.eye(3)[k]) - f(theta - h * np.eye(3)[k])) / (2 * h) for k in range(3)]
    np.testing.assert_allclose(grad, num, rtol=1e-6)


# --- random arithmetic against Python --------------------------------------------------------

_names = st.sampled_from(sorted(VALUES))
_numbers = st.one_of(
    st.integers(0, 999).map(str),
    st.floats(0, 1e4, allow_nan=False, allow_infinity=False).map(repr),
    st.tuples(st.integers(1, 9), st.integers(0, 99), st.integers(-5, 5)).map(lambda t: f"{t[0]}.{t[1]}e{t[2]}"),
)


def _expr():
    leaf = st.one_of(_names, _numbers)

    def extend(inner):
        return st.one_of(
            st.tuples(inner, st.sampled_from(["+", "-", "*", "/"]), inner).map(lambda t: f"{t[0]} {t[1]} {t[2]}"),
            st.tuples(inner, st.sampled_from(["+", "-", "*", "/"]), inner).map(lambda t: f"{t[0]}{t[1]}{t[2]}"),
            inner.map(lambda x: f"({x})"),
            inner.map(lambda x: f"-{x}"),
            inner.map(lambda x: f"+ {x}"),
        )

    return st.recursive(leaf, extend, max_leaves=12)


@settings(max_examples=400, deadline=None)
@given(_expr())
def test_random_arithmetic_agrees_with_python(text):
    try:
        expected = eval(text, {"__builtins__": {}}, dict(VALUES))   # test only: generated, safe text
    except (ZeroDivisionError, OverflowError):
        assume(False)
    expected = float(expected)
    assume(math.isfinite(expected))
    got = evaluate(parse(text, where="X[0][0]"), VALUES)
    assert got == pytest.approx(expected, rel=1e-12, abs=1e-300)
    # compiled (names as parameters and constants, constants folded) gives the same value
    params = ["Yv", "Yr", "a"]
    consts = {k: v for k, v in VALUES.items() if k not in params}
    try:
        e = compile_entry(text, consts, params, "X[0][0]")
    except ConfigError as exc:                      # a constant sub-expression divided by zero
        assert "division by zero" in str(exc)
        return
    theta = np.array([VALUES[p] for p in params])
    with np.errstate(all="ignore"):
        v = e.value(theta)
    if math.isfinite(v):
        # folding reorders operations: allow rounding relative to the largest intermediate size
        assert v == pytest.approx(expected, rel=1e-9, abs=1e-12 * _size(parse(text)))


def _size(node):
    """A bound on the magnitudes of intermediate results (for rounding tolerances)."""
    if isinstance(node, Num):
        return abs(node.value)
    if isinstance(node, Name):
        return abs(VALUES[node.name])
    if isinstance(node, Neg):
        return _size(node.operand)
    a, b = _size(node.left), _size(node.right)
    if node.op in "+-":
        return a + b
    if node.op == "*":
        return a * b
    r = abs(evaluate(node.right, VALUES))
    return max(a, a / r if r > 0 else math.inf, b)


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet="ab1.+-*/() e_^%$,;!", max_size=12))
def test_any_text_parses_or_fails_with_config_error(text):
    try:
        node = parse(text, where="M[1][1]")
    except ConfigError as exc:
        assert str(exc).startswith("M[1][1] = ")
        return
    assert isinstance(node, (Num, Name, Neg, BinOp))


# --- entries as long as a case may hold, against numpy -------------------------------------------

def _signed_sum(terms, signs) -> str:
    return " ".join(f"{'-' if s < 0 else '+'} {t}" for t, s in zip(terms, signs)).removeprefix("+ ")


def test_a_long_affine_entry_agrees_with_numpy():
    """100 terms (399 tokens, the limit is 400): the affine form holds every coefficient."""
    rng = np.random.default_rng(1)
    n = 100
    c = np.round(rng.uniform(0.1, 9.9, n), 4)
    signs = rng.choice([-1.0, 1.0], n)
    params = [f"p{k}" for k in range(n)]
    text = _signed_sum([f"{c[k]:.4f}*p{k}" for k in range(n)], signs)
    e = compile_entry(text, {}, params, "F[0][0]")
    assert e.affine is not None and e.parameters == tuple(params)
    np.testing.assert_allclose([w for _, w in e.affine[1]], signs * c, rtol=1e-15)
    theta = rng.uniform(-3.0, 3.0, n)
    v, g = e.value_and_gradient(theta)
    assert v == pytest.approx(float(np.dot(signs * c, theta)), rel=1e-12)
    np.testing.assert_allclose(g, signs * c, rtol=1e-15)


def test_a_long_sum_of_products_agrees_with_numpy():
    """60 products of two parameters and a constant (359 tokens): value and exact gradient."""
    rng = np.random.default_rng(2)
    n = 60
    c = np.round(rng.uniform(0.1, 9.9, n), 3)
    signs = rng.choice([-1.0, 1.0], n)
    params = [f"p{k}" for k in range(n)] + [f"q{k}" for k in range(n)]
    text = _signed_sum([f"{c[k]:.3f}*p{k}*q{k}" for k in range(n)], signs)
    e = compile_entry(text, {}, params, "F[0][0]")
    assert e.affine is None
    theta = rng.uniform(-2.0, 2.0, 2 * n)
    p, q = theta[:n], theta[n:]
    v, g = e.value_and_gradient(theta)
    assert v == pytest.approx(float(np.sum(signs * c * p * q)), rel=1e-12)
    assert e.value(theta) == v
    np.testing.assert_allclose(g, np.concatenate([signs * c * q, signs * c * p]), rtol=1e-12)


def test_a_long_polynomial_in_horner_form_agrees_with_numpy_polyval():
    """c0 + x*(c1 + x*(c2 + ... x*(c39))): 40 coefficients nested 39 deep (the limit is 50);
    value and d/dx against numpy's polynomial evaluation."""
    rng = np.random.default_rng(3)
    c = np.round(rng.uniform(-1.0, 1.0, 40), 5)
    text = f"{c[-1]:.5f}"
    for ck in c[-2::-1]:
        text = f"{ck:.5f} + x*({text})"
    e = compile_entry(text, {}, ["a", "x"], "F[0][0]")
    assert e.affine is None and e.parameters == ("x",)
    for x in (-1.3, -0.4, 0.0, 0.7, 1.1):
        v, g = e.value_and_gradient(np.array([5.0, x]))
        assert v == pytest.approx(np.polyval(c[::-1], x), rel=1e-12, abs=1e-12)
        assert g[0] == 0.0
        assert g[1] == pytest.approx(np.polyval(np.polyder(c[::-1]), x), rel=1e-11, abs=1e-11)
