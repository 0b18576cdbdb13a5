"""Laurent polynomials in the generator coefficients, for building the full-gamma regression.

A polynomial is a dict ``exponent tuple -> coefficient`` (exponents may be negative: the backward
recurrence of a generator divides by its last coefficient).  Only used when a regression is built
(:mod:`observers.gpebo.companion`); a regression row at run time is a matrix product.
"""

from __future__ import annotations

from collections import defaultdict

__all__ = ["constant", "variable", "add", "multiply", "evaluate"]

Polynomial = dict


def constant(value: float, variables: int) -> Polynomial:
    """The constant ``value`` in ``variables`` unknowns (empty dict for 0)."""
    return {(0,) * variables: float(value)} if value else {}


def variable(index: int, variables: int, power: int = 1) -> Polynomial:
    """The monomial ``x_index^power``."""
    exponent = [0] * variables
    exponent[index] = power
    return {tuple(exponent): 1.0}


def _clean(terms) -> Polynomial:
    return {e: c for e, c in terms.items() if c != 0}


def add(a: Polynomial, b: Polynomial, scale: float = 1.0) -> Polynomial:
    """``a + scale b``."""
    terms = defaultdict(float, a)
    for e, c in b.items():
        terms[e] += scale * c
    return _clean(terms)


def multiply(a: Polynomial, b: Polynomial) -> Polynomial:
    """``a b``."""
    terms = defaultdict(float)
    for ea, ca in a.items():
        for eb, cb in b.items():
            terms[tuple(x + y for x, y in zip(ea, eb))] += ca * cb
    return _clean(terms)


def evaluate(a: Polynomial, x) -> float:
    """``a(x)``; a negative power of a zero entry raises ZeroDivisionError."""
    total = 0.0
    for e, c in a.items():
        term = c
        for value, power in zip(x, e):
            term *= float(value) ** power if power >= 0 else 1.0 / float(value) ** -power
        total += term
    return total
