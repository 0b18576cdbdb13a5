"""The system file's expression language (observers/expressions.py): grammar, errors, limits, fuzz."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from obsfmu.observers import expressions
from obsfmu.observers.expressions import MAX_DEPTH, MAX_LENGTH, ExpressionError, Names, Source, compile_expression, \
    compile_vector

NAMES = Names(x=3, u=2, p=3, parameters={"k": 1, "c": 2, "alpha": 3})
X, U, P = np.array([0.7, -1.3, 2.2]), np.array([0.25, -4.0]), np.array([2.0, 0.5, -0.1])
T = 1.75
SOURCE = Source("plant.f[2]", "my.toml", 12, 9)

# each expression with the same formula written by hand in Python (1-based names, 0-based arrays)
CASES = [
    ("-c * x[2] - k * x[1] - alpha * x[1] ** 3 + u[1]",
     -P[1] * X[1] - P[0] * X[0] - P[2] * X[0] ** 3 + U[0]),
    ("sin(t) * cos(x[3]) + tan(0.3) - exp(-x[1]) + log(x[3]) + sqrt(abs(x[2]))",
     math.sin(T) * math.cos(X[2]) + math.tan(0.3) - math.exp(-X[0]) + math.log(X[2]) + math.sqrt(abs(X[1]))),
    ("sign(x[2]) * tanh(u[2]) + min(x[1], x[2]) - max(p[1], 3) % 2", np.sign(X[1]) * math.tanh(U[1])
     + min(X[0], X[1]) - max(P[0], 3) % 2),
    ("where(x[1] > 0, 1, -1) + where(x[2] >= 0, 10, 20) + (x[1] < x[2]) + (u[1] == 0.25) + (u[1] != 0.25)",
     1 + 20 + 0 + 1 + 0),
    ("x[1] > 0 and x[2] > 0 or not u[2] <= 0", float((X[0] > 0 and X[1] > 0) or not U[1] <= 0)),
    ("pi * e - +x[1] / 4 ** -0.5", math.pi * math.e - X[0] / 4 ** -0.5),
    ("2 ** 3 ** 2 - -x[1] ** 2", 2 ** 3 ** 2 - -X[0] ** 2),
    # issue 36: the functions an engineer expects, against numpy / math
    ("atan(x[1]) + atan2(x[2], x[1]) + atan2(-1, -1)", np.arctan(X[0]) + np.arctan2(X[1], X[0]) + np.arctan2(-1, -1)),
    ("asin(0.3) + acos(-0.2) + sinh(x[2]) + cosh(x[2]) + log10(x[3])",
     np.arcsin(0.3) + np.arccos(-0.2) + np.sinh(X[1]) + np.cosh(X[1]) + np.log10(X[2])),
    ("min(x[1], x[2], x[3]) + max(u[1], u[2], 0, p[1]) + clip(x[3], -1, 1) + clip(x[2], -1, 1) + clip(0.5, 0, 1)",
     min(X) + max(U[0], U[1], 0, P[0]) + np.clip(X[2], -1, 1) + np.clip(X[1], -1, 1) + 0.5),
    # ^ is a power with the precedence of ** (the field reference's own "y^3")
    ("x[1]^3 + 2^3^2 - -x[1]^2 + x[2]^2 * 2", X[0] ** 3 + 2 ** 9 + X[0] ** 2 + X[1] ** 2 * 2),
]


@pytest.mark.parametrize("text, expected", CASES)
def test_expressions_evaluate_as_python_would(text, expected):
    assert compile_expression(text, NAMES, SOURCE)(T, X, U, P) == pytest.approx(expected, rel=1e-15, abs=1e-15)


def test_a_vector_of_expressions():
    f = compile_vector(["x[2]", "-k * x[1] - c * x[2] + u[1]"], Names(x=2, u=1, p=2, parameters={"k": 1, "c": 2}),
                       Source("plant.f"), size=2)
    np.testing.assert_array_equal(f(0.0, np.array([1.0, 2.0]), np.array([3.0]), np.array([4.0, 5.0])),
                                  [2.0, -4.0 - 10.0 + 3.0])
    with pytest.raises(ExpressionError, match=r"plant.f: expected 3 expressions \(one per component\), got 2"):
        compile_vector(["x[2]", "x[1]"], Names(x=2), Source("plant.f"), size=3)
    with pytest.raises(ExpressionError, match=r"plant.f\[2\]"):
        compile_vector(["x[2]", "x[7]"], Names(x=2), Source("plant.f"))


def test_where_takes_only_the_branch_it_needs_and_domain_errors_give_nan():
    assert compile_expression("where(x[1] > 0, log(x[1]), -5)", NAMES, SOURCE)(T, -X, U, P) == -5
    for text in ("log(-1)", "sqrt(-2)", "0 / 0", "(-8) ** 0.5"):
        assert math.isnan(compile_expression(text, NAMES, SOURCE)(T, X, U, P)), text
    for text in ("1 / 0", "exp(1000)", "10.0 ** 400", "0 ** -1"):
        assert compile_expression(text, NAMES, SOURCE)(T, X, U, P) == math.inf, text


@pytest.mark.parametrize("text, message", [
    ("__import__('os').system('true')", "unknown function .*__import__"),
    ("x.__class__", "not allowed here .*'x.__class__'"),
    ("q * 2", r"unknown name \(allowed: x, u, p, t, alpha, c, k, e, pi\): 'q'"),
    ("x[0]", "indices start at 1"),
    ("x[4]", r"x has 3 entries, x\[1\] to x\[3\]"),
    ("x[k]", "an index must be a whole number"),
    ("x[1:2]", "an index must be a whole number"),
    ("x * 2", r"x is a vector: index it, x\[1\] to x\[3\]"),
    ("x[1] | 2", "operator not allowed"),
    ("1 if x[1] else 2", r"use where\(condition, a, b\)"),
    ("'text'", "only numbers are allowed"),
    ("True + 1", "only numbers are allowed"),
    ("lambda: 1", "not allowed here"),
    ("[x[1] for _ in t]", "not allowed here"),
    ("sin(x[1], 2)", "sin takes 1 argument"),
    ("where(x[1], 2)", "where takes 3 arguments"),
    ("max(*x)", "max takes at least 2 arguments"),
    ("sin(x=1)", "sin takes 1 argument"),
    ("1 < x[1] < 2", "one comparison at a time"),
    ("x[1] in x", "comparison not allowed"),
    ("x[1] +", "not a valid expression"),
    ("(x[1] := 3)", "not a valid expression"),
    ("(q := 3)", "not allowed here"),
    ("", "the expression is empty"),
    (")+(", "the bracket at character 1 closes nothing"),
    ("sin(x[1]", "1 bracket not closed"),
    ("x[1]\x00", "control character"),
    ("1e999", "the number is not finite"),
    ("1j", "only numbers are allowed"),
])
def test_anything_outside_the_grammar_is_refused_naming_place_and_token(text, message):
    with pytest.raises(ExpressionError, match=message) as refused:
        compile_expression(text, NAMES, SOURCE)
    assert str(refused.value).startswith(("my.toml:12:", "plant.f[2]")), str(refused.value)
    assert "plant.f[2]" in str(refused.value)


def test_the_place_is_the_line_and_column_in_the_file():
    with pytest.raises(ExpressionError) as refused:
        compile_expression("x[1] + bogus", NAMES, Source("plant.f[1]", "my.toml", 12, 9))
    assert str(refused.value).startswith("my.toml:12:16: plant.f[1]: unknown name"), str(refused.value)
    with pytest.raises(ExpressionError) as refused:
        compile_expression("x[1] +\n  bogus", NAMES, Source("plant.f[1]", "my.toml", 12, 9))
    assert str(refused.value).startswith("my.toml:13:3: plant.f[1]"), str(refused.value)


@pytest.mark.parametrize("text, limit", [
    ("x[1] + " * 200_000 + "1", f"more than the limit of {MAX_LENGTH}"),          # ~1.4 MB
    ("(" * 10_000 + "1" + ")" * 10_000, f"more than the limit of {MAX_LENGTH}"),
    ("(" * (MAX_DEPTH + 1) + "1" + ")" * (MAX_DEPTH + 1), f"more than the limit of {MAX_DEPTH}"),
    ("-" * (MAX_LENGTH - 10) + "x[1]", "cannot be parsed|nested more than"),
    ("+".join(["x[1]"] * 500), f"nested more than {MAX_DEPTH} deep"),
])
def test_huge_or_deep_expressions_are_refused_at_once_with_the_limit(text, limit):
    with pytest.raises(ExpressionError, match=limit):
        compile_expression(text, NAMES, SOURCE)


def test_the_module_never_evaluates_text():
    tree = ast.parse(Path(expressions.__file__).read_text())
    called = {node.func.id for node in ast.walk(tree) if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)}
    assert not called & {"eval", "exec", "compile", "__import__"}


_ALPHABET = st.sampled_from(["x[1]", "x[2]", "u[1]", "p[3]", "t", "k", "(", ")", "+", "-", "*", "/", "**", "<", "==",
                             " and ", " not ", "sin(", "where(", ",", "1", "0.5", "e", "[", "]", ".", "_", "'", "lambda",
                             "__class__", "import", ";", "=", "if", "\n", "%", "^", "@", "~", "|", "&"])


@settings(derandomize=True, max_examples=400, deadline=None)
@given(st.lists(_ALPHABET, max_size=30).map("".join))
def test_fuzz_token_soup_compiles_or_is_refused_cleanly(text):
    try:
        evaluate = compile_expression(text, NAMES, SOURCE)
    except ExpressionError as refused:
        assert "plant.f[2]" in str(refused)
        return
    value = evaluate(T, X, U, P)
    assert isinstance(value, float)


@settings(derandomize=True, max_examples=300, deadline=None)
@given(st.text(max_size=60))
def test_fuzz_any_text_compiles_or_is_refused_cleanly(text):
    try:
        compile_expression(text, NAMES, SOURCE)(T, X, U, P)
    except ExpressionError:
        pass


def test_the_functions_give_numpys_results_outside_their_domain():
    """NaN outside the domain, inf on overflow, NaN through min/max (numpy's minimum, maximum): never a
    Python exception inside an FMU, never a NaN silently dropped by Python's min."""
    for text, expected in (("asin(2)", np.nan), ("acos(-1.5)", np.nan), ("log10(-1)", np.nan), ("log10(0)", -np.inf),
                           ("sinh(1000)", np.inf), ("sinh(-1000)", -np.inf), ("cosh(-1000)", np.inf),
                           ("min(1, 0/0)", np.nan), ("max(0/0, 1)", np.nan)):
        value = compile_expression(text, NAMES, SOURCE)(T, X, U, P)
        assert (math.isnan(value) and math.isnan(expected)) or value == expected, text


@pytest.mark.parametrize("text, message", [
    ("x[1] + 1  # the spring", "'#' \\(character 11\\) is not part of an expression"),
    ("1" + "0" * 400 + " * x[1]", "the number is beyond the range of a float"),
    ("min(x[1])", "min takes at least 2 arguments"),
    ("clip(x[1], 0)", "clip takes 3 arguments"),
    ("atan2(x[1])", "atan2 takes 2 arguments"),
])
def test_what_issue_36_and_37_found_is_refused_in_one_line(text, message):
    with pytest.raises(ExpressionError, match=message):
        compile_expression(text, NAMES, SOURCE)
