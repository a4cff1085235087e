#!/usr/bin/env python3
"""Matrix-entry expressions: cost of parsing, compiling and evaluating one entry against its length.

An entry of ``N`` terms, a sum of products of parameters, constants and a constant ``s`` raised to
powers by repetition (``p3*q3*s*s/2.5 - p4*q4/s + ...``), goes through what a case does with it:
:func:`~livesweep.ident.expression.parse`, :func:`~livesweep.ident.expression.compile_entry`
(names resolved, constants folded, affine form tried) and one
:meth:`~livesweep.ident.expression.CompiledEntry.value_and_gradient` (the fit's Jacobian). Entries
of 150 and 500 terms are beyond the size limits of a case file
(:data:`~livesweep.limits.MAX_EXPRESSION_TOKENS`), which are lifted here so the cost can be seen
to grow with the length; the time is the best of ``--repeats`` runs [ms].

Printed: for 50, 150 and 500 terms, the characters, the time and its ratio to the 50-term time
(linear cost: about 3 and 10), and, measured in the same run, the baseline a competent engineer
would reach for first: CPython's own ``compile`` of the same text and one ``eval`` of it with the
parameter values (the value only: no gradient, no checks of names, size or nesting), with
livesweep's time as a ratio to it.

    python benchmarks/bench_expression.py [--terms 50,150,500] [--repeats 20]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from livesweep.ident import expression


def entry(n_terms: int) -> tuple[str, list[str]]:
    """An entry of ``n_terms`` products and the parameter names it uses."""
    terms, params = [], []
    for k in range(n_terms):
        power = "*s" * (k % 4)
        div = "/2.5" if k % 3 == 0 else ""
        terms.append(f"{'-' if k % 2 else '+'} p{k}*q{k}{power}{div}")
        params += [f"p{k}", f"q{k}"]
    return " ".join(terms).lstrip("+ "), params


def cost_ms(n_terms: int, repeats: int) -> tuple[int, float]:
    """(characters, best time of parse + compile + value_and_gradient [ms])."""
    text, params = entry(n_terms)
    theta = np.linspace(0.5, 1.5, len(params))
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        compiled = expression.compile_entry(text, {"s": 3.0}, params, "F[0][0]")
        compiled.value_and_gradient(theta)
        best = min(best, time.perf_counter() - t0)
    return len(text), 1e3 * best


def baseline_ms(n_terms: int, repeats: int) -> float:
    """Best time of CPython's ``compile`` + one ``eval`` of the same entry (its value only) [ms]."""
    text, params = entry(n_terms)
    values = {"s": 3.0, **dict(zip(params, np.linspace(0.5, 1.5, len(params)).tolist()))}
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        eval(compile(text, "<entry>", "eval"), {"__builtins__": {}}, values)   # noqa: S307 - the baseline
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--terms", default="50,150,500", help="entry lengths [terms], the first is the reference")
    ap.add_argument("--repeats", type=int, default=20, help="runs per length; the best is kept")
    args = ap.parse_args(argv)
    sizes = [int(t) for t in args.terms.split(",")]
    # lift the case-file limits so entries longer than a case may hold can be timed
    expression.MAX_EXPRESSION_CHARS = expression.MAX_EXPRESSION_TOKENS = sys.maxsize
    ref = None
    print(f"{'terms':>6} {'chars':>7} {'time [ms]':>10} {'vs 50':>7} {'CPython eval [ms]':>18} {'ratio':>7}")
    for n in sizes:
        chars, ms = cost_ms(n, args.repeats)
        base = baseline_ms(n, args.repeats)
        ref = ref or ms
        print(f"{n:>6} {chars:>7} {ms:>10.2f} {ms / ref:>7.2f} {base:>18.3f} {ms / base:>7.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
