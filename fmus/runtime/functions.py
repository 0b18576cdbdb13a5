"""Functions of a user's model written as expressions (in a system file), carried by an FMU as text.

An adaptive observer needs functions of the user's model: ``A(t)``, ``L(t)``, ``f(y, t)``,
``Psi(y, u)``, ...  A kind takes each either as a ``"module:function"`` reference
(:mod:`fmus.runtime.callables`: the papers' own functions) or as an *expression function*: a JSON
option that holds the texts (one per entry of a scalar, vector or matrix), the function's arguments
and named constants.  :func:`expression_function` checks and writes the option at build time;
:func:`compiled` turns it back into a callable when the FMU is instantiated -- through the
whitelisted compiler of :mod:`observers.expressions`, never ``eval``.

Arguments bind to the compiler's slots: an argument named ``t`` of size 0 is the time; the first
other argument is the vector ``x`` and the second ``u``, each under its own name (``y[1]``,
``chi[2]``); a one-entry argument may be written bare (``sin(y)``); the constants are ``p``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.expressions import CONSTANTS, FUNCTIONS, Names, Source, compile_vector

__all__ = ["expression_function", "is_expression_function", "compiled", "expression_parts", "ExpressionFunction"]

_MARK = "expressions"          #: the key that tells an expression function from a reference
_SLOTS = ("x", "u")


def is_expression_function(option) -> bool:
    """``option`` is an expression function's option (a table with ``expressions``), not a reference."""
    return isinstance(option, Mapping) and _MARK in option


def _flat(texts, shape: tuple[int, ...], field: str) -> list[str]:
    """The texts of a scalar, vector or matrix, checked against ``shape``, row by row."""
    array = np.asarray(texts, dtype=object)
    if array.shape != shape:
        raise ParameterError(f"{field}: expected {_shape_text(shape)}, got {_shape_text(array.shape)}")
    return [_text(value, field) for value in array.reshape(-1)]


def _text(value, field: str) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value):
        return repr(float(value))
    raise ParameterError(f"{field}: expected expressions (texts) or numbers, got {value!r}")


def _shape_text(shape: tuple[int, ...]) -> str:
    if not shape:
        return "one expression"
    return f"{shape[0]} expressions" if len(shape) == 1 else " x ".join(map(str, shape)) + " expressions (rows)"


def _names(arguments: Sequence[tuple[str, int]], constants: Mapping[str, float], field: str) -> tuple[Names, bool]:
    """The :class:`~observers.expressions.Names` of ``arguments`` and whether the first is the time."""
    arguments = [(str(name), int(size)) for name, size in arguments]
    timed = bool(arguments) and arguments[0] == ("t", 0)
    vectors = arguments[1:] if timed else arguments
    if len(vectors) > len(_SLOTS) or any(name == "t" for name, _ in vectors):
        raise ParameterError(f"{field}: a function of the time t (first) and at most two vectors, got {arguments}")
    reserved = {"t", *CONSTANTS, *FUNCTIONS, *(name for name, _ in vectors)}
    for name in constants:
        if name in reserved:
            raise ParameterError(f"{field}: the constant {name!r} has the name of an argument, a constant or a "
                                 "function")
    sizes = {slot: max(size, 1) for slot, (_, size) in zip(_SLOTS, vectors)}
    names = Names(x=sizes.get("x", 0), u=sizes.get("u", 0), p=len(constants),
                  parameters={name: i for i, name in enumerate(constants, start=1)}, time=timed,
                  labels={slot: name for slot, (name, _) in zip(_SLOTS, vectors)},
                  bare=frozenset(name for name, size in vectors if size <= 1))
    return names, timed


def expression_function(texts, arguments: Sequence[tuple[str, int]], shape: Sequence[int] = (), *,
                        constants: Mapping[str, float] | None = None, field: str = "f") -> dict:
    """The option of an expression function, checked: every text compiles.

    Parameters
    ----------
    texts : str, list of str, or list of lists of str
        One expression per entry of the result (numbers are accepted as constant entries).
    arguments : sequence of (name, size)
        The function's positional arguments in order; ``("t", 0)`` first for a function of time, then
        at most two vectors (size 0: a scalar, passed as a float).
    shape : sequence of int
        ``()`` for a scalar result, ``(n,)`` a vector, ``(r, c)`` a matrix.
    constants : mapping, optional
        Named constants the expressions may use (``mu_max = 0.5``).
    field : str
        The field's name in messages (``components.observer.A``).

    Returns
    -------
    dict
        JSON-ready: ``{"expressions": [...], "shape": [...], "arguments": [[name, size], ...],
        "constants": {name: value}}``.

    Raises
    ------
    ParameterError
        A wrong shape, or :class:`~observers.expressions.ExpressionError` naming ``field[i]`` (row-major
        index from 1) and the token outside the grammar.
    """
    shape = tuple(int(s) for s in shape)
    constants = {str(k): float(v) for k, v in (constants or {}).items()}
    option = {_MARK: _flat(texts, shape, field), "shape": list(shape),
              "arguments": [[str(name), int(size)] for name, size in arguments], "constants": constants}
    compiled(option, field)
    return option


class ExpressionFunction:
    """The compiled expression function: ``function(*arguments)`` -> float or array of its shape."""

    def __init__(self, vector, shape: tuple[int, ...], timed: bool, constants: np.ndarray):
        self.vector, self.shape, self.timed = vector, shape, timed
        self.constants = constants.tolist()

    def __call__(self, *arguments):
        t = float(arguments[0]) if self.timed else 0.0
        vectors = [_floats(a) for a in arguments[self.timed:]]
        x, u = (vectors + [[], []])[:2]
        if not self.shape:            # one expression: its value, no array (called per RK4 stage: f(y) of paper 001)
            return float(self.vector.parts[0](t, x, u, self.constants))
        return self.vector.of_lists(t, x, u, self.constants).reshape(self.shape)


def _floats(argument) -> list:
    """An argument as a list of Python floats (a number without numpy: the common scalar case)."""
    if isinstance(argument, (float, int)) and not isinstance(argument, bool):
        return [float(argument)]
    return np.atleast_1d(np.asarray(argument, dtype=float)).tolist()


def expression_parts(option, what: str = "function") -> tuple[list[str], Names, tuple[int, ...], bool, np.ndarray]:
    """``(texts, names, shape, timed, constants)`` of an expression function's option, checked (the compiled C of a
    step kernel is written from the texts and names, :mod:`observers.expressions_c`)."""
    if not is_expression_function(option):
        raise ParameterError(f"{what}: expected an expression function (a table with 'expressions'), got {option!r}")
    try:
        shape = tuple(int(s) for s in option["shape"])
        constants = {str(k): float(v) for k, v in option.get("constants", {}).items()}
        names, timed = _names(option["arguments"], constants, what)
        texts = list(option[_MARK])
    except (KeyError, TypeError, ValueError) as exc:
        raise ParameterError(f"{what}: a malformed expression function ({exc})") from None
    if len(texts) != int(np.prod(shape, dtype=int)):
        raise ParameterError(f"{what}: {len(texts)} expressions for the shape {shape}")
    return texts, names, shape, timed, np.array(list(constants.values()), dtype=float)


def compiled(option, what: str = "function") -> ExpressionFunction:
    """The callable of an expression function's option (see :func:`expression_function`)."""
    texts, names, shape, timed, constants = expression_parts(option, what)
    vector = compile_vector(texts, names, Source(what))
    return ExpressionFunction(vector, shape, timed, constants)
