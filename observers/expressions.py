"""A small, safe expression language for the right-hand sides a user writes in a system file.

``dx/dt = f(x, u, t, p)``, ``y = h(x, u, t, p)``, ``x[k+1] = ...``: each component is one expression
over the time ``t``, the vectors ``x``, ``u``, ``p`` (indexed from 1, as the FMU's variables
``x[1]``, ``u[2]`` are), the named parameters of the file and the constants ``pi`` and ``e``::

    -c * x[2] - k * x[1] - alpha * x[1] ** 3 + u[1]
    where(x[1] > 0, sqrt(x[1]), 0)

Grammar: numbers; ``+ - * / ** %``, unary ``-`` and ``+``; ``^`` is a power too (``y^3``, with the
precedence of ``**``: ``-x^2 = -(x^2)``, ``2^3^2 = 2^9``); comparisons ``< <= > >= == !=`` (true is 1);
``and``, ``or``, ``not``; the functions ``sin cos tan asin acos atan atan2(y, x) sinh cosh tanh exp log
log10 sqrt abs sign floor min(a, b, ...) max(a, b, ...) clip(x, low, high) where(condition, a, b)``, and numpy's
seeded random stream ``randn(seed, k, j)`` (the ``j``-th standard normal of ``default_rng((seed, k))``) and
``rand(seed, k, j)`` (its ``j``-th uniform on ``[0, 1)``), :mod:`observers.random_stream`.
Anything else -- attributes, strings, other calls, slices, lambdas, ``a if c else b``, ``#`` comments --
is refused, naming the place (file, line, column) and the token.

The text is parsed with :mod:`ast` and checked node by node against that grammar; the checked tree
is turned into a tree of small Python closures over floats, once.  Nothing of the user's text is
ever given to ``eval``, ``exec`` or ``compile``.  Size is bounded before parsing
(:data:`MAX_LENGTH` characters, :data:`MAX_DEPTH` levels of nesting), so no text can make the parser
or the evaluator run long or recurse deeply.  Domain errors (``log(-1)``, ``sqrt(-1)``) give NaN
and overflows inf, as numpy does: the caller's finiteness checks name them.
"""

from __future__ import annotations

import ast
import math
import operator
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from .checks import ParameterError
from .random_stream import rand, randn

__all__ = ["ExpressionError", "Source", "Names", "compile_expression", "compile_vector", "VectorFunction", "FUNCTIONS",
           "MAX_LENGTH", "MAX_DEPTH", "check_text", "parse_text"]

MAX_LENGTH = 4000      #: characters in one expression
MAX_DEPTH = 60         #: nesting of brackets and of the expression tree
VECTORS = ("x", "u", "p")
CONSTANTS = {"pi": math.pi, "e": math.e}

Evaluator = Callable[[float, np.ndarray, np.ndarray, np.ndarray], float]


class ExpressionError(ParameterError):
    """An expression outside the grammar; the message names the field, the place and the token."""


@dataclass(frozen=True)
class Source:
    """Where an expression comes from: ``field`` (``plant.f[2]``), and optionally the file and the
    line and column of the expression's first character in it."""
    field: str
    file: str | None = None
    line: int | None = None
    column: int | None = None

    def at(self, node: ast.AST | None = None, line: int = 1, column: int = 0) -> str:
        if node is not None:           # parsed in brackets: line 1 is one column to the right
            line, column = getattr(node, "lineno", 1), getattr(node, "col_offset", 1)
            column -= line == 1
        if self.file is None:
            return f"{self.field} (line {line}, column {column + 1} of the expression)"
        first_line = self.line or 1
        column += (self.column or 1) if line == 1 else 1
        return f"{self.file}:{first_line + line - 1}:{column}: {self.field}"


@dataclass(frozen=True)
class Names:
    """What an expression may name: the sizes of ``x``, ``u``, ``p`` (0: absent) and the named
    parameters (name -> 1-based index into ``p``).

    ``labels`` renames a vector for the user (``{"x": "y"}``: the expressions of ``f(y, t)`` write
    ``y[1]`` for what the evaluator receives as ``x``); ``bare`` lists the labels of one-entry vectors
    that may also be written without an index (``sin(y)``).
    """
    x: int = 0
    u: int = 0
    p: int = 0
    parameters: Mapping[str, int] = field(default_factory=dict)
    time: bool = True
    labels: Mapping[str, str] = field(default_factory=dict)
    bare: frozenset = frozenset()

    def label(self, vector: str) -> str:
        """What the expressions call the vector ``vector`` (``x``, ``u`` or ``p``)."""
        return self.labels.get(vector, vector)

    def vector(self, label: str) -> str | None:
        """The vector (``x``, ``u``, ``p``) an expression names ``label``, if it is present."""
        return next((v for v in VECTORS if getattr(self, v) and self.label(v) == label), None)

    def allowed(self) -> list[str]:
        names = [self.label(v) for v in VECTORS if getattr(self, v)] + (["t"] if self.time else [])
        return names + sorted(self.parameters) + sorted(CONSTANTS)


# ---------------------------------------------------------------------------------------- functions
def _log(value: float) -> float:
    return math.log(value) if value > 0 else (-math.inf if value == 0 else math.nan)


def _sqrt(value: float) -> float:
    return math.sqrt(value) if value >= 0 else math.nan


def _exp(value: float) -> float:
    try:
        return math.exp(value)
    except OverflowError:
        return math.inf


def _sign(value: float) -> float:
    return 1.0 if value > 0 else -1.0 if value < 0 else 0.0 if value == 0 else math.nan


def _floor(value: float) -> float:
    """The largest whole number not above ``value``, as C's ``floor``: inf and NaN as they are, ``-0.0`` kept."""
    if not math.isfinite(value):
        return value
    whole = float(math.floor(value))
    return math.copysign(whole, value) if whole == 0.0 else whole


def _tan(value: float) -> float:
    return math.tan(value) if math.isfinite(value) else math.nan


def _periodic(function):
    return lambda value: function(value) if math.isfinite(value) else math.nan


def _unit_interval(function):
    """``asin``, ``acos``: NaN outside [-1, 1] (as numpy), not a ValueError."""
    return lambda value: function(value) if -1.0 <= value <= 1.0 else math.nan


def _growing(function):
    """``sinh``, ``cosh``: inf on overflow (as numpy), not an OverflowError."""
    def guarded(value):
        try:
            return function(value)
        except OverflowError:
            return math.copysign(math.inf, value) if function is math.sinh else math.inf
    return guarded


def _log10(value: float) -> float:
    return math.log10(value) if value > 0 else (-math.inf if value == 0 else math.nan)


def _clip(value: float, low: float, high: float) -> float:
    """``value`` limited to ``[low, high]`` (numpy's clip: ``min(max(value, low), high)``)."""
    return min(max(value, low), high)


def _extreme(function):
    """``min``, ``max`` of two or more numbers; NaN if any is NaN (as numpy's minimum, maximum)."""
    return lambda *values: math.nan if any(v != v for v in values) else function(values)


#: name -> (number of arguments, function of floats); a negative number -n: at least n;
#: ``where`` is handled apart (it is lazy)
FUNCTIONS: dict[str, tuple[int, Callable]] = {
    "sin": (1, _periodic(math.sin)), "cos": (1, _periodic(math.cos)), "tan": (1, _tan),
    "asin": (1, _unit_interval(math.asin)), "acos": (1, _unit_interval(math.acos)), "atan": (1, math.atan),
    "atan2": (2, math.atan2), "sinh": (1, _growing(math.sinh)), "cosh": (1, _growing(math.cosh)),
    "tanh": (1, math.tanh), "exp": (1, _exp), "log": (1, _log), "log10": (1, _log10), "sqrt": (1, _sqrt),
    "abs": (1, abs), "sign": (1, _sign), "floor": (1, _floor), "min": (-2, _extreme(min)), "max": (-2, _extreme(max)),
    "clip": (3, _clip), "where": (3, None), "randn": (3, randn), "rand": (3, rand),
}

_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.Pow: operator.pow, ast.Mod: operator.mod}
_COMPARE = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
            ast.Eq: operator.eq, ast.NotEq: operator.ne}
_HINTS = {ast.IfExp: "use where(condition, a, b)",
          ast.Attribute: "parameters are named plainly (k, not p.k)", ast.Constant: "only numbers are allowed"}


def _safe(function):
    """``function`` with Python's arithmetic exceptions turned into numpy's results."""
    def guarded(a, b):
        try:
            return function(a, b)
        except ZeroDivisionError:
            return math.nan if a == 0 or a != a else math.copysign(math.inf, a) * (1 if b >= 0 else -1)
        except OverflowError:
            return math.inf
    return guarded


def _power(base: float, exponent: float) -> float:
    if base == 0 and exponent < 0:
        return math.inf
    result = base ** exponent
    return math.nan if isinstance(result, complex) else result    # a negative base, a fractional exponent


_ARITHMETIC = {kind: _safe(_power if kind is ast.Pow else function) for kind, function in _BINARY.items()}


def _plain(kind, left: "Evaluator", right: "Evaluator", exponent: int | None = None) -> "Evaluator | None":
    """``left op right`` as one closure for the operators that never raise on floats (+, -, *: an
    overflow is inf) and for a power of a whole ``exponent`` from 1 to 64 (the same float as
    :func:`_power`); the per-step cost of an expression plant.  None for the others (guarded)."""
    if kind is ast.Pow and exponent is not None:
        def power(t, x, u, p):
            base = left(t, x, u, p)
            try:
                return base ** exponent
            except OverflowError:
                return math.inf
        return power
    if kind is ast.Add:
        return lambda t, x, u, p: left(t, x, u, p) + right(t, x, u, p)
    if kind is ast.Sub:
        return lambda t, x, u, p: left(t, x, u, p) - right(t, x, u, p)
    if kind is ast.Mult:
        return lambda t, x, u, p: left(t, x, u, p) * right(t, x, u, p)
    return None


# ------------------------------------------------------------------------------------------ checking
def check_text(text, source: Source) -> str:
    """``text`` checked against the limits (length, brackets, characters) and with ``^`` as a power: what
    :func:`parse_text` parses; :class:`ExpressionError` naming the field."""
    if not isinstance(text, str):
        raise ExpressionError(f"{source.field}: expected an expression as a string, got {text!r}")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"{source.field}: the expression has {len(text)} characters, more than the "
                              f"limit of {MAX_LENGTH}")
    depth = deepest = 0
    for column, character in enumerate(text):
        if character in "([":
            depth += 1
            deepest = max(deepest, depth)
        elif character in ")]":
            depth -= 1
            if depth < 0:
                raise ExpressionError(f"{source.field}: the bracket at character {column + 1} closes nothing")
    if depth:
        raise ExpressionError(f"{source.field}: {depth} bracket{'s' if depth > 1 else ''} not closed")
    if deepest > MAX_DEPTH:
        raise ExpressionError(f"{source.field}: brackets nested {deepest} deep, more than the limit of {MAX_DEPTH}")
    if any(ord(c) < 32 and c not in "\t\n\r" for c in text):
        raise ExpressionError(f"{source.field}: the expression holds a control character")
    if not text.strip():
        raise ExpressionError(f"{source.field}: the expression is empty")
    if "#" in text:
        raise ExpressionError(f"{source.field}: '#' (character {text.index('#') + 1}) is not part of an expression; "
                              f"a comment goes in the file, after the closing quote")
    return text.replace("^", "**")            # y^3: a power, with the precedence of ** (not Python's xor)


def parse_text(text: str, source: Source) -> ast.expr:
    """The Python syntax tree of a checked ``text`` (:func:`check_text`); :class:`ExpressionError` naming the place."""
    try:        # in brackets, so that an expression may span lines (the columns of line 1 shift by one)
        tree = ast.parse("(" + text + "\n)", mode="eval")
    except SyntaxError as exc:
        line, column = exc.lineno or 1, (exc.offset or 1) - 1 - ((exc.lineno or 1) == 1)
        lines = text.split("\n")
        if line > len(lines):                          # in the closing bracket: the text ended too early
            line, column = len(lines), len(lines[-1])
        where = source.at(line=line, column=column)
        raise ExpressionError(f"{where}: not a valid expression ({exc.msg})") from None
    except (RecursionError, MemoryError, ValueError) as exc:
        raise ExpressionError(f"{source.field}: the expression cannot be parsed ({type(exc).__name__})") from None
    return tree.body


def _token(node: ast.AST, text: str) -> str:
    segment = ast.get_source_segment(text, node) or type(node).__name__
    return segment if len(segment) <= 40 else segment[:37] + "..."


_GETTERS = {"x": lambda i: lambda t, x, u, p: x[i], "u": lambda i: lambda t, x, u, p: u[i],
            "p": lambda i: lambda t, x, u, p: p[i]}


class _Compiler:
    """Checks one parsed expression against the grammar and builds its closure tree."""

    def __init__(self, text: str, names: Names, source: Source):
        self.text, self.names, self.source = "(" + text + "\n)", names, source
        self.uses: set[str] = set()           # the vectors and names the expression reads

    def refuse(self, node: ast.AST, what: str) -> ExpressionError:
        return ExpressionError(f"{self.source.at(node)}: {what}: {_token(node, self.text)!r}")

    def build(self, node: ast.AST, depth: int = 0) -> Evaluator:
        if depth > MAX_DEPTH:
            raise self.refuse(node, f"the expression is nested more than {MAX_DEPTH} deep")
        method = getattr(self, "_" + type(node).__name__, None)
        if method is None:
            hint = next((h for kind, h in _HINTS.items() if isinstance(node, kind)
                         or isinstance(getattr(node, "op", None), kind)), None)
            raise self.refuse(node, "not allowed here" + (f" ({hint})" if hint else ""))
        return method(node, depth + 1)

    def _Constant(self, node: ast.Constant, depth: int) -> Evaluator:
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.refuse(node, "only numbers are allowed")
        try:
            number = float(value)
        except OverflowError:                 # a whole number of 309 digits or more
            raise self.refuse(node, "the number is beyond the range of a float (about 1.8e308)") from None
        if not math.isfinite(number):
            raise self.refuse(node, "the number is not finite")
        return lambda t, x, u, p: number

    def _Name(self, node: ast.Name, depth: int) -> Evaluator:
        name, names = node.id, self.names
        self.uses.add(name)
        if name == "t" and names.time:
            return lambda t, x, u, p: t
        if name in names.parameters:
            index = names.parameters[name] - 1
            return lambda t, x, u, p: p[index]
        if name in CONSTANTS:
            value = CONSTANTS[name]
            return lambda t, x, u, p: value
        vector = names.vector(name)
        if vector is not None and name in names.bare:
            self.uses.add(vector)
            return _GETTERS[vector](0)
        if vector is not None:
            raise self.refuse(node, f"{name} is a vector: index it, {name}[1] to {name}[{getattr(names, vector)}]")
        raise self.refuse(node, f"unknown name (allowed: {', '.join(self.names.allowed())})")

    def _Subscript(self, node: ast.Subscript, depth: int) -> Evaluator:
        label = node.value.id if isinstance(node.value, ast.Name) else None
        vector = self.names.vector(label) if label is not None else None
        size = getattr(self.names, vector) if vector is not None else 0
        if not size:
            indexable = ", ".join(self.names.label(v) for v in VECTORS if getattr(self.names, v))
            raise self.refuse(node, f"only {indexable} can be indexed")
        index = node.slice
        if not (isinstance(index, ast.Constant) and type(index.value) is int):
            raise self.refuse(node, "an index must be a whole number")
        if not 1 <= index.value <= size:
            raise self.refuse(node, f"index out of range: {label} has {size} entries, {label}[1] to {label}[{size}]"
                              + (" (indices start at 1, as in the FMU's variable names)" if index.value == 0 else ""))
        self.uses.add(vector)
        return _GETTERS[vector](index.value - 1)

    def _UnaryOp(self, node: ast.UnaryOp, depth: int) -> Evaluator:
        operand = self.build(node.operand, depth)
        if isinstance(node.op, ast.USub):
            return lambda t, x, u, p: -operand(t, x, u, p)
        if isinstance(node.op, ast.UAdd):
            return operand
        if isinstance(node.op, ast.Not):
            return lambda t, x, u, p: float(not operand(t, x, u, p))
        raise self.refuse(node, "operator not allowed")

    def _BinOp(self, node: ast.BinOp, depth: int) -> Evaluator:
        function = _ARITHMETIC.get(type(node.op))
        if function is None:
            hint = _HINTS.get(type(node.op))
            raise self.refuse(node, "operator not allowed" + (f" ({hint})" if hint else ""))
        left, right = self.build(node.left, depth), self.build(node.right, depth)
        if isinstance(node.op, ast.Mult) and isinstance(node.left, ast.Name) and node.left.id in self.names.parameters:
            index = self.names.parameters[node.left.id] - 1      # a coefficient times a term: one call less
            return lambda t, x, u, p: p[index] * right(t, x, u, p)
        exponent = node.right.value if isinstance(node.right, ast.Constant) and type(node.right.value) is int \
            and 1 <= node.right.value <= 64 else None
        return _plain(type(node.op), left, right, exponent) or \
            (lambda t, x, u, p: function(left(t, x, u, p), right(t, x, u, p)))

    def _Compare(self, node: ast.Compare, depth: int) -> Evaluator:
        if len(node.ops) != 1:
            raise self.refuse(node, "one comparison at a time (write a < b and b < c)")
        function = _COMPARE[type(node.ops[0])] if type(node.ops[0]) in _COMPARE else None
        if function is None:
            raise self.refuse(node, "comparison not allowed")
        left, right = self.build(node.left, depth), self.build(node.comparators[0], depth)
        return lambda t, x, u, p: float(function(left(t, x, u, p), right(t, x, u, p)))

    def _BoolOp(self, node: ast.BoolOp, depth: int) -> Evaluator:
        parts = [self.build(value, depth) for value in node.values]
        if isinstance(node.op, ast.And):
            return lambda t, x, u, p: float(all(part(t, x, u, p) for part in parts))
        return lambda t, x, u, p: float(any(part(t, x, u, p) for part in parts))

    def _Call(self, node: ast.Call, depth: int) -> Evaluator:
        name = node.func.id if isinstance(node.func, ast.Name) else None
        if name not in FUNCTIONS:
            raise self.refuse(node.func, f"unknown function (allowed: {', '.join(FUNCTIONS)})")
        count, function = FUNCTIONS[name]
        wrong = len(node.args) < -count if count < 0 else len(node.args) != count
        if node.keywords or wrong or any(isinstance(a, ast.Starred) for a in node.args):
            takes = f"at least {-count} arguments" if count < 0 else f"{count} argument{'s' if count > 1 else ''}"
            raise self.refuse(node, f"{name} takes {takes}")
        args = [self.build(argument, depth) for argument in node.args]
        if name == "where":
            condition, if_true, if_false = args
            return lambda t, x, u, p: if_true(t, x, u, p) if condition(t, x, u, p) else if_false(t, x, u, p)
        if count == 1:
            (argument,) = args
            return lambda t, x, u, p: float(function(argument(t, x, u, p)))
        if len(args) == 2:
            first, second = args
            return lambda t, x, u, p: float(function(first(t, x, u, p), second(t, x, u, p)))
        return lambda t, x, u, p: float(function(*(argument(t, x, u, p) for argument in args)))


def _compiled(text: str, names: Names, source: Source) -> tuple[Evaluator, set[str]]:
    text = check_text(text, source)
    compiler = _Compiler(text, names, source)
    return compiler.build(parse_text(text, source)), compiler.uses


def compile_expression(text: str, names: Names, source: Source) -> Evaluator:
    """Check ``text`` against the grammar and return ``evaluate(t, x, u, p) -> float``.

    :class:`ExpressionError` names the field, the place in the file and the token of the first
    thing outside the grammar.
    """
    return _compiled(text, names, source)[0]


class VectorFunction:
    """Expressions, one per component, as ``f(t, x, u, p) -> float vector``; ``uses``: the names read."""

    def __init__(self, parts: list[Evaluator], uses: set[str]):
        self.parts, self.uses, self.size = parts, frozenset(uses), len(parts)

    def __call__(self, t: float, x: np.ndarray, u: np.ndarray, p: np.ndarray) -> np.ndarray:
        t, x, u, p = float(t), x.tolist(), u.tolist(), p.tolist()     # Python floats: several times faster
        return np.array([part(t, x, u, p) for part in self.parts], dtype=float)

    def of_lists(self, t: float, x: list, u: list, p: list) -> np.ndarray:
        """As calling it, with ``t`` a float and ``x``, ``u``, ``p`` lists of floats (no conversion)."""
        return np.array([part(t, x, u, p) for part in self.parts], dtype=float)


def compile_vector(texts: Sequence[str], names: Names, source: Source, size: int | None = None) -> VectorFunction:
    """``texts`` (one expression per component) as one :class:`VectorFunction`.

    ``source.field`` names the whole vector (``plant.f``); each component is reported as
    ``plant.f[i]``.  ``size``: the number of components required.
    """
    if isinstance(texts, str) or not isinstance(texts, Sequence):
        raise ExpressionError(f"{source.field}: expected a list of expressions, one per component")
    if size is not None and len(texts) != size:
        raise ExpressionError(f"{source.field}: expected {size} expressions (one per component), got {len(texts)}")
    compiled = [_compiled(text, names, Source(f"{source.field}[{i}]", source.file, source.line, source.column))
                for i, text in enumerate(texts, start=1)]
    return VectorFunction([part for part, _ in compiled], set().union(*(uses for _, uses in compiled)))
