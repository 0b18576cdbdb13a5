"""The expressions in C (observers/expressions_c.py): compiled, they give the Python closures' results to the bit.

One shared library holds every expression of this file (compiled once, module fixture); each C function is
called through ctypes and compared with ``compile_vector(...).of_lists`` bit for bit, every NaN counting as
one value (which of two NaN operands' signs a sum or a product keeps is the C compiler's choice of operand order,
in CPython as here): the operators and functions at edge-case inputs, the orders of -0.0, 0.0 and NaN in min, max and
clip, deep nesting, and a few hundred random expressions at random points.
"""

from __future__ import annotations

import ctypes
import math
import random
import shutil
import subprocess

import numpy as np
import pytest

from obsfmu.observers.expressions import FUNCTIONS, ExpressionError, Names, Source, compile_vector
from obsfmu.observers.expressions_c import c_source

CC = ["cc", "-shared", "-fPIC", "-O2", "-Wall", "-Werror", "-fvisibility=hidden", "-ffp-contract=off"]
MINGW = ["x86_64-w64-mingw32-gcc", "-shared", "-O2", "-Wall", "-Werror", "-ffp-contract=off"]

NAMES = Names(x=3, u=2, p=3, parameters={"k": 1, "c": 2, "alpha": 3})
# a parameter named t (time wins, except as a coefficient: _Compiler's p[i] * term) and one named pi (it wins)
BARE = Names(x=1, u=1, p=2, parameters={"t": 1, "pi": 2}, labels={"x": "y"}, bare=frozenset({"y", "u"}))

NAN = math.nan
EDGE = [0.0, -0.0, 1.0, -1.0, 0.5, -0.5, 2.0, -2.0, 3.0, -3.0, 7.0, -7.0, 2.5, -2.5, 0.1, math.pi, 1e10, 1e-300,
        1e308, -1e308, math.inf, -math.inf, NAN, -NAN, 5e-324, -5e-324, 1.0000000000000002, -1.0000000000000002,
        0.9999999999999999, -0.9999999999999999, 710.0, -710.0, 800.0, 64.0, 1e300, -1e300]
SIGNED = [0.0, -0.0, NAN, -NAN, 1.0, -1.0, math.inf, -math.inf]

UNARY = [f"{name}(x[1])" for name, (count, _) in FUNCTIONS.items() if count == 1]
OPERATORS = ["+", "-", "*", "/", "%", "**", "^", "<", "<=", ">", ">=", "==", "!=", "and", "or"]
GRID = [
    *UNARY, "-x[1]", "+x[1]", "not x[1]", "not not x[1]",
    *(f"x[1] {op} x[2]" for op in OPERATORS), *(f"x[2] {op} x[1]" for op in OPERATORS),
    "atan2(x[1], x[2])", "atan2(x[2], x[1])", "min(x[1], x[2])", "max(x[1], x[2])", "min(x[1], x[2], x[3])",
    "max(x[1], x[2], x[3])", "clip(x[1], x[2], x[3])", "clip(x[1], -1, 1)", "where(x[1], x[2], x[3])",
    # powers: the whole exponents 1..64 of _plain and the others of _power; negative bases; 0 ** negative
    *(f"x[1] ** {n}" for n in (1, 2, 3, 4, 5, 17, 63, 64, 65, 0, -1, -2, -3)),
    "x[1] ** 2.0", "x[1] ** 0.5", "x[1] ** -0.5", "x[1] ** 1.5", "x[1] ** (1/3)", "x[1] ^ 3", "x[1] ^ -1",
    "2 ** x[1]", "(-2) ** x[1]", "0 ** x[1]", "(-0.0) ** x[1]", "1 ** x[1]", "(-1) ** x[1]", "0.5 ** x[1]",
    "(-0.5) ** x[1]", "1e300 ** x[1]", "(-1e300) ** x[1]", "x[1] ** x[2] ** x[3]", "-x[1] ** 2", "2 ** 3 ** 2",
    "0 ** -1", "0.0 ** -0.5", "(-0.0) ** -1", "(-8) ** (1/3)", "(-1e300) ** 1.5", "(-1e200) ** 3", "1e200 ** 2",
    "(-1e200) ** 2", "(-2) ** 0.5", "(-1e308 * 10) ** 0.5", "(-1e308 * 10) ** 3", "(1e308 * 10 - 1e308 * 10) ** 0",
    "1 ** (1e308 * 10 - 1e308 * 10)", "(-1) ** (1e308 * 10)", "0.5 ** (-1e308 * 10)", "1e308 ** 1.0000001",
    "(-1e308) ** 1.0000001", "(-1e-300) ** 1.5", "1e-300 ** 3",
    # %: the sign of the divisor; / and % by 0 and -0
    "x[1] % -3", "x[1] % 3", "-7 % 3", "7 % -3", "-7 % -3", "7 % 3", "x[1] % 0", "x[1] % -0.0", "x[1] / 0",
    "x[1] / -0.0", "x[1] / (-0.0)", "0 / x[1]", "-0.0 % x[1]", "x[1] % 1e-300", "1e300 % x[1]", "x[1] % 0.1",
    # the names: t, p by name and index, the constants, u
    "t", "t * x[1]", "k * x[1]", "c * x[2] - alpha * x[3]", "p[1] * x[2] + p[2] / p[3]", "u[1] + u[2] * t",
    "pi", "e", "pi * e - +x[1] / 4 ** -0.5", "-c * x[2] - k * x[1] - alpha * x[1] ** 3 + u[1]",
    # lazy: a branch or an operand that would be NaN or inf only when it is not taken
    "where(x[1] >= 0, sqrt(x[1]), -x[1])", "where(x[1] > 0, log(x[1]), where(x[1] < 0, sqrt(-x[1]), 0 / x[1]))",
    "where(x[1] != x[1], 0, x[1])", "x[1] > 0 and log(x[1]) > 1 or sqrt(x[1]) < 2", "x[1] and 1 / x[1]",
    "x[1] or 1 / x[1]", "x[1] and x[2] and x[3]", "x[1] or x[2] or x[3]", "not (x[1] and x[2])",
    # nested
    "sin(cos(tan(x[1]))) + exp(-x[1] ** 2 / 2) * log10(abs(x[2]) + 1)",
    "sqrt(x[1] ** 2 + x[2] ** 2) - abs(atan2(x[2], x[1]))", "sinh(x[1]) / cosh(x[1]) - tanh(x[1])",
    "clip(min(x[1], x[2]) * max(x[2], x[3]), -abs(x[3]), abs(x[3]))", "sign(x[1] - x[2]) * (x[1] % x[2])",
    "asin(clip(x[1], -1, 1)) + acos(clip(x[2] / 10, -1, 1))", "(x[1] < x[2]) + (x[2] <= x[3]) * 2 - (x[1] == x[3])",
    # numpy's random stream: NaN outside whole seeds, intervals and draws (observers/random_stream.py)
    "randn(x[1], x[2], x[3])", "rand(x[1], x[2], x[3])", "randn(abs(x[1]), 3, 0) + rand(7, abs(x[2]), 2)",
]
# 0.0 - x and 0.0 + -x, x never -0.0: GCC 12 folds them into -x (-0.0 for x = +0.0, IEEE's 0.0 - 0.0 is +0.0)
SIGNED_ZERO = ["0 - abs(x[1])", "0 + -abs(x[1])", "-abs(x[1]) + 0", "(not 1e-300) - (x[1] < 2)", "0 - (x[1] > 0)",
               "sign(0) - abs(x[1])", "min(0, 1) - abs(x[1])", "where(x[2], 0, 0) - (x[1] > 1)", "0 * 5 - abs(x[1])",
               "clip(0, -1, 1) - abs(x[1])", "(x[1] - x[1]) - abs(x[2])", "-(0 - abs(x[1]))", "x[1] - 0", "0 - x[1]"]
GRID += SIGNED_ZERO
# the orders of -0.0, 0.0, NaN: all triples of SIGNED
TRIPLES = ["min(x[1], x[2])", "max(x[1], x[2])", "min(x[1], x[2], x[3])", "max(x[1], x[2], x[3])",
           "clip(x[1], x[2], x[3])", "where(x[1], x[2], x[3])", "x[1] and x[2] or x[3]", "not x[1] or x[2]",
           "x[1] + x[2] * x[3]", "x[1] * x[2] - x[3]", "sign(x[1]) * abs(x[2])", "x[1] % x[2]", "x[1] / x[2]",
           "x[1] ** x[2]", "atan2(x[1], x[2])", "min(x[1], -0.0, 0.0, x[2])", "max(0.0, x[1], -0.0, x[2])"]
BARE_TEXTS = ["sin(y) + u", "t", "t * y", "y * t", "pi", "pi * y", "e", "p[2] - p[1]", "y ^ 2 - u % 2"]


def _deepest(template: str, closing: str = "") -> str:
    """``template`` repeated around ``x[1]`` as deeply as the Python compiler accepts (its depth limit)."""
    for n in range(80, 0, -1):
        text = template * n + "x[1]" + closing * n
        try:
            compile_vector([text], NAMES, Source("deep"))
        except ExpressionError:
            continue
        return text
    raise AssertionError(template)


NESTED = [_deepest("-"), _deepest("sin(", ")"), _deepest("1 + "), _deepest("x[2] * "), _deepest("x[2] ** "),
          _deepest("where(x[2], ", ", x[3])"), _deepest("min(x[2], ", ")"), _deepest("not "),
          "min(" + ", ".join(f"x[{i % 3 + 1}] * {i - 150}" for i in range(300)) + ")",
          "max(" + ", ".join(f"x[{i % 3 + 1}] / {i - 150}" for i in range(300)) + ")"]


# ------------------------------------------------------------------------------------------- random
_LEAVES = ["0", "0.0", "1", "2", "3", "0.5", "2.5", "7", "10", "64", "65", "1e300", "1e-300", "5e-324", "1e10",
           "123.456", "0.1", "t", "x[1]", "x[2]", "x[3]", "u[1]", "u[2]", "p[1]", "p[2]", "p[3]", "k", "c", "alpha",
           "pi", "e"]
_BINARY = ["+", "-", "*", "/", "%", "**", "^", "<", "<=", ">", ">=", "==", "!=", "and", "or"]
_ARITIES = {name: (2 if count < 0 else count) for name, (count, _) in FUNCTIONS.items()}


def _random_expression(rng: random.Random, depth: int) -> str:
    """A random text of the whole grammar, every part in brackets."""
    if depth == 0 or rng.random() < 0.2:
        return rng.choice(_LEAVES) if rng.random() < 0.8 else repr(round(rng.uniform(-10, 10), rng.randint(0, 3)))
    kind = rng.random()
    if kind < 0.15:
        return f"({rng.choice(['-', '+', 'not '])}{_random_expression(rng, depth - 1)})"
    if kind < 0.6:
        return f"({_random_expression(rng, depth - 1)} {rng.choice(_BINARY)} {_random_expression(rng, depth - 1)})"
    name = rng.choice(list(_ARITIES))
    count = _ARITIES[name] + (rng.randint(0, 2) if FUNCTIONS[name][0] < 0 else 0)
    return f"{name}({', '.join(_random_expression(rng, depth - 1) for _ in range(count))})"


def _random_value(rng: random.Random) -> float:
    choice = rng.random()
    if choice < 0.2:
        return rng.choice(EDGE)
    if choice < 0.5:
        return rng.uniform(-3, 3)
    if choice < 0.7:
        return float(rng.randint(-5, 5))
    if choice < 0.85:
        return rng.uniform(-1e3, 1e3)
    return rng.choice([-1, 1]) * 10.0 ** rng.uniform(-300, 300)


_RNG = random.Random(20261204)
RANDOM = [_random_expression(_RNG, _RNG.randint(1, 6)) for _ in range(400)]
RANDOM_POINTS = [(_random_value(_RNG), [_random_value(_RNG) for _ in range(3)], [_random_value(_RNG) for _ in range(2)],
                  [_random_value(_RNG) for _ in range(3)]) for _ in range(60)]
# the functions of constants: the C compiler must not evaluate them itself (correctly rounded, not glibc's)
CONSTANT = [f"{name}({value!r})" for name in ("sin", "cos", "tan", "exp", "log", "log10", "sinh", "cosh", "tanh",
                                              "atan", "asin", "acos", "sqrt")
            for value in [round(_RNG.uniform(-1, 1) * 10 ** _RNG.randint(-3, 2), 6) for _ in range(25)]] + \
           [f"{_RNG.uniform(0, 20)!r} ** {_RNG.uniform(-5, 5)!r}" for _ in range(100)] + \
           [f"{_RNG.uniform(0, 20)!r} ** {_RNG.randint(2, 64)}" for _ in range(100)] + \
           [f"atan2({_RNG.uniform(-5, 5)!r}, {_RNG.uniform(-5, 5)!r})" for _ in range(50)]

SYMBOLS = {"grid": GRID + NESTED, "triples": TRIPLES, "random": RANDOM, "constant": CONSTANT, "empty": []}


# ----------------------------------------------------------------------------------------- harness
class _Kernel:
    """One exported C function and the Python closures of the same texts."""

    def __init__(self, library: ctypes.CDLL, symbol: str, texts: list[str], names: Names):
        self.texts, self.function = texts, getattr(library, symbol)
        self.function.restype = None
        self.function.argtypes = [ctypes.c_double] + [ctypes.POINTER(ctypes.c_double)] * 4
        self.python = compile_vector(texts, names, Source(symbol))

    def c(self, t: float, x: list, u: list, p: list) -> np.ndarray:
        out = (ctypes.c_double * max(len(self.texts), 1))()
        arrays = [(ctypes.c_double * len(v))(*v) for v in (x, u, p)]
        self.function(t, *arrays, out)
        return np.array(out[:len(self.texts)], dtype=float)

    def differences(self, t: float, x: list, u: list, p: list) -> list[str]:
        """The texts whose C value is not the Python one to the bit (NaNs all alike), with the values."""
        python, c = self.python.of_lists(t, x, u, p), self.c(t, x, u, p)
        same = (python.view(np.uint64) == c.view(np.uint64)) | (np.isnan(python) & np.isnan(c))
        return [f"{self.texts[i][:80]!r} at t={t!r} x={x!r} u={u!r} p={p!r}: Python {python[i]!r} "
                f"({python[i:i + 1].view(np.uint64)[0]:#018x}), C {c[i]!r} ({c[i:i + 1].view(np.uint64)[0]:#018x})"
                for i in np.flatnonzero(~same)]


def _assert_same(kernel: _Kernel, points) -> None:
    differences = [d for point in points for d in kernel.differences(*point)]
    assert not differences, f"{len(differences)} differences:\n" + "\n".join(differences[:20])


def _compile(command: list[str], sources: list[str], directory, name: str):
    files = []
    for i, source in enumerate(sources):
        files.append(directory / f"{name}_{i}.c")
        files[-1].write_text(source)
    target = directory / name
    result = subprocess.run([*command, "-o", str(target), *map(str, files), *(["-lm"] if command[0] == "cc" else [])],
                            check=False, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return target


@pytest.fixture(scope="module")
def sources() -> list[str]:
    return [c_source(SYMBOLS, NAMES), c_source({"bare": BARE_TEXTS}, BARE, Source("plant.f", "my.toml", 3, 5))]


@pytest.fixture(scope="module")
def library(sources, tmp_path_factory) -> ctypes.CDLL:
    if shutil.which("cc") is None:
        pytest.skip("no C compiler (cc)")
    return ctypes.CDLL(str(_compile(CC, sources, tmp_path_factory.mktemp("expressions_c"), "expressions.so")))


def _grid_points():
    for i, a in enumerate(EDGE):
        for j, b in enumerate(EDGE):
            c = EDGE[(i * 7 + j * 3) % len(EDGE)]
            yield b, [a, b, c], [a, b], [a, b, c]


# -------------------------------------------------------------------------------------------- tests
def test_every_function_and_operator_of_the_grammar_is_tested():
    text = " ".join(GRID)
    assert all(f"{name}(" in text for name in FUNCTIONS)
    assert all(f" {op} " in text for op in OPERATORS)


def test_the_operators_and_functions_at_edge_cases_are_the_python_ones_to_the_bit(library):
    _assert_same(_Kernel(library, "grid", GRID + NESTED, NAMES), _grid_points())


def test_min_max_clip_and_the_logic_keep_the_python_order_of_signed_zeros_and_nans(library):
    points = [(0.0, [a, b, c], [0.0, 0.0], [0.0, 0.0, 0.0]) for a in SIGNED for b in SIGNED for c in SIGNED]
    _assert_same(_Kernel(library, "triples", TRIPLES, NAMES), points)


def test_random_expressions_at_random_points_are_the_python_ones_to_the_bit(library):
    _assert_same(_Kernel(library, "random", RANDOM, NAMES), RANDOM_POINTS)


def test_functions_of_constants_are_computed_by_the_c_library_as_in_python(library):
    _assert_same(_Kernel(library, "constant", CONSTANT, NAMES), [(0.0, [0.0] * 3, [0.0] * 2, [0.0] * 3)])


def test_bare_vectors_renamed_vectors_and_parameters_named_like_t_and_pi(library):
    kernel = _Kernel(library, "bare", BARE_TEXTS, BARE)
    _assert_same(kernel, [(b, [a], [b], [a, b]) for a in EDGE[::3] for b in EDGE[1::3]])
    assert kernel.c(2.0, [3.0], [0.0], [5.0, 7.0])[1:5].tolist() == [2.0, 15.0, 6.0, 7.0]


def test_a_function_without_expressions_writes_nothing(library):
    assert _Kernel(library, "empty", [], NAMES).c(0.0, [0.0], [0.0], [0.0]).size == 0


def test_the_source_includes_math_h_and_stdint_h_only_and_exports_only_the_symbols(sources, library):
    includes = [line for source in sources for line in source.splitlines() if line.startswith("#include")]
    assert set(includes) == {"#include <math.h>", "#include <stdint.h>"}
    if shutil.which("nm") is None:
        pytest.skip("no nm")
    listing = subprocess.run(["nm", "-D", "--defined-only", library._name], check=True, capture_output=True,
                             text=True).stdout
    assert sorted(line.split()[-1] for line in listing.splitlines()) == sorted([*SYMBOLS, "bare"])


def test_without_sse2_math_the_left_operand_is_hidden_through_a_volatile(tmp_path):
    if shutil.which("cc") is None:
        pytest.skip("no C compiler (cc)")
    source = c_source({"signed_zero": SIGNED_ZERO}, NAMES)
    library = ctypes.CDLL(str(_compile([*CC, "-U__SSE2_MATH__"], [source], tmp_path, "fallback.so")))
    _assert_same(_Kernel(library, "signed_zero", SIGNED_ZERO, NAMES), [(0.0, [a, b, 0.0], [0.0] * 2, [0.0] * 3)
                                                                       for a in SIGNED for b in SIGNED])


def test_mingw_compiles_the_source(sources, tmp_path):
    if shutil.which(MINGW[0]) is None:
        pytest.skip(f"{MINGW[0]} is not installed")
    assert _compile(MINGW, sources, tmp_path, "expressions.dll").stat().st_size > 0


@pytest.mark.parametrize("text", ["x[1] + foo(2)", "x[4]", "x[1] if t else 0", "min(x[1])", "'a'", "x[1]  # c"])
def test_a_refused_text_is_refused_with_the_python_compilers_message(text):
    with pytest.raises(ExpressionError) as python:
        compile_vector(["t", text], NAMES, Source("plant.f.f", "my.toml", 3, 5))
    with pytest.raises(ExpressionError) as c:
        c_source({"f": ["t", text]}, NAMES, Source("plant.f", "my.toml", 3, 5))
    assert str(c.value) == str(python.value)
    with pytest.raises(ExpressionError, match=r"^f\[2\]"):
        c_source({"f": ["t", text]}, NAMES)


@pytest.mark.parametrize("symbol", ["1f", "f-g", "", "int", "ex_sin", "EX_EXPORT", "x", "out", "__f", None])
def test_a_symbol_that_is_not_a_free_c_identifier_is_refused(symbol):
    with pytest.raises(ValueError):
        c_source({symbol: ["t"]}, NAMES)
