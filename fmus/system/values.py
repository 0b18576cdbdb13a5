"""Checking one value of a system file against its field's type; every mistake names the field.

Limits are checked from the sizes alone, before any work: a matrix or vector longer than
:data:`MAX_DIMENSION` (design size) or :data:`MAX_ENTRIES` (tables of break points) is refused with the
limit in the message.  Texts hold no control characters (they go into the FMUs' XML and logs).
"""

from __future__ import annotations

import math
import unicodedata

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.expressions import MAX_LENGTH, Names, Source, compile_expression

from ..config import MAX_DIMENSION as CONFIG_MAX_DIMENSION
from .schema import Field

__all__ = ["check_value", "check_text", "MAX_DIMENSION", "MAX_ENTRIES"]

MAX_DIMENSION = CONFIG_MAX_DIMENSION     #: rows and columns of a matrix (as for the design file: fmus/config.py)
MAX_ENTRIES = 100_000     #: entries of a vector (a table source's break points)
MAX_TEXT = 1000           #: characters of a text field (names, units, descriptions, paths)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number(where: str, value) -> float:
    if not _is_number(value):
        raise ParameterError(f"{where}: expected a number, got {_shown(value)}")
    try:
        number = float(value)
    except OverflowError:                     # a whole number of 309 digits or more (TOML integers are unbounded)
        raise ParameterError(f"{where}: {_shown(value)} is beyond the range of a float (about 1.8e308)") from None
    if not math.isfinite(number):
        raise ParameterError(f"{where}: expected a finite number, got {value}")
    return number


def _shown(value) -> str:
    text = "true" if value is True else "false" if value is False else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _escaped(text: str) -> str:
    """``text`` with its control and format characters as ``\\uXXXX`` (a message must read as it is)."""
    return "".join(f"\\u{ord(c):04X}" if unicodedata.category(c) in ("Cc", "Cf") else c for c in text)


def check_text(where: str, value, *, lines: bool = False, limit: int = MAX_TEXT) -> str:
    """A string without control characters (``lines``: tabs and newlines allowed) of at most ``limit``."""
    where = _escaped(where)       # a key (a name) is part of where: it must not reorder the message
    if not isinstance(value, str):
        raise ParameterError(f"{where}: expected a text, got {_shown(value)}")
    if len(value) > limit:
        raise ParameterError(f"{where}: {len(value)} characters, more than the limit of {limit}")
    for character in value:
        category = unicodedata.category(character)
        if category == "Cc" and not (lines and character in "\t\n\r"):
            raise ParameterError(f"{where}: holds the control character U+{ord(character):04X}")
        if category == "Cf":         # U+202E and the other bidi overrides, zero-width characters: text that reads
            raise ParameterError(f"{where}: holds the invisible format character U+{ord(character):04X} (a "
                                 f"bidirectional override or zero-width character: the text would read otherwise "
                                 f"than it is)")
    return value


def _vector(where: str, value, limit: int) -> np.ndarray:
    if not isinstance(value, list):
        raise ParameterError(f"{where}: expected a list of numbers, got {_shown(value)}")
    if len(value) > limit:
        raise ParameterError(f"{where}: {len(value)} entries, more than the limit of {limit}")
    return np.array([_number(f"{where}[{i}]", v) for i, v in enumerate(value, start=1)], dtype=float)


def _rows(where: str, value, entries: str = "numbers") -> None:
    """``value`` is a non-empty list of rows of one length, within the limits."""
    if not isinstance(value, list) or not value:
        raise ParameterError(f"{where}: expected a list of rows (lists of {entries}), got {_shown(value)}")
    if len(value) > MAX_DIMENSION:
        raise ParameterError(f"{where}: {len(value)} rows, more than the limit of {MAX_DIMENSION}")
    for i, row in enumerate(value, start=1):
        if not isinstance(row, list):
            raise ParameterError(f"{where}: row {i} is {_shown(row)}, expected a list of {entries}")
        if len(row) > MAX_DIMENSION:
            raise ParameterError(f"{where}: row {i} has {len(row)} entries, more than the limit of {MAX_DIMENSION}")
        if len(row) != len(value[0]):
            raise ParameterError(f"{where}: row {i} has {_entries(len(row))}, row 1 has {len(value[0])}")
    if not value[0]:
        raise ParameterError(f"{where}: the rows are empty")


def _constant(where: str, value) -> float:
    """A number, or a text that is a constant expression (``"-16000/250"``, ``"2*pi"``): compiled by the
    whitelisted expression grammar of :mod:`observers.expressions` (never ``eval``) with no variables."""
    if not isinstance(value, str):
        return _number(where, value)
    evaluate = compile_expression(check_text(where, value), Names(time=False), Source(where))
    result = evaluate(0.0, np.zeros(0), np.zeros(0), np.zeros(0))
    if not math.isfinite(result):
        raise ParameterError(f"{where}: {value!r} is {result}, expected a finite number")
    return float(result)


def _matrix(where: str, value) -> np.ndarray:
    _rows(where, value, "numbers or constant expressions")
    return np.array([[_constant(f"{where}[{i}][{j}]", v) for j, v in enumerate(row, start=1)]
                     for i, row in enumerate(value, start=1)], dtype=float)


def _entries(count: int) -> str:
    return f"{count} entr{'y' if count == 1 else 'ies'}"


def _poles(where: str, value) -> list:
    if not isinstance(value, list) or not value:
        raise ParameterError(f"{where}: expected a list of poles (numbers, or [re, im] pairs), got {_shown(value)}")
    if len(value) > MAX_DIMENSION:
        raise ParameterError(f"{where}: {len(value)} poles, more than the limit of {MAX_DIMENSION}")
    for i, pole in enumerate(value, start=1):
        if isinstance(pole, list):
            if len(pole) != 2:
                raise ParameterError(f"{where}[{i}]: expected a number or an [re, im] pair, got {_shown(pole)}")
            _vector(f"{where}[{i}]", pole, 2)
        else:
            _number(f"{where}[{i}]", pole)
    return value


def _table(where: str, value, entry) -> dict:
    if not isinstance(value, dict):
        raise ParameterError(f"{where}: expected a table of name = value, got {_shown(value)}")
    if len(value) > MAX_DIMENSION:
        raise ParameterError(f"{where}: {len(value)} entries, more than the limit of {MAX_DIMENSION}")
    return {check_text(f"{where}.{name}", name): entry(f"{where}.{name}", v) for name, v in value.items()}


def _units(where: str, value):
    if isinstance(value, list):
        if len(value) > MAX_DIMENSION:
            raise ParameterError(f"{where}: {len(value)} units, more than the limit of {MAX_DIMENSION}")
        return [check_text(f"{where}[{i}]", v, limit=100) for i, v in enumerate(value, start=1)]
    return check_text(where, value, limit=100)


def _names(where: str, value) -> list[str]:
    """Names of the entries of a port (``state_names``): distinct non-empty texts."""
    if not isinstance(value, list) or not value:
        raise ParameterError(f"{where}: expected a list of names (texts), one per entry, got {_shown(value)}")
    if len(value) > MAX_DIMENSION:
        raise ParameterError(f"{where}: {len(value)} names, more than the limit of {MAX_DIMENSION}")
    names = [check_text(f"{where}[{i}]", v, limit=60) for i, v in enumerate(value, start=1)]
    for i, name in enumerate(names, start=1):
        if not name.strip():
            raise ParameterError(f"{where}[{i}]: a name must not be empty")
        if name in names[:i - 1]:
            raise ParameterError(f"{where}[{i}]: {name!r} is named twice")
    return names


def _expressions(where: str, value) -> list[str]:
    if not isinstance(value, list) or not value:
        raise ParameterError(f"{where}: expected a list of expressions (texts), got {_shown(value)}")
    if len(value) > MAX_DIMENSION:
        raise ParameterError(f"{where}: {len(value)} expressions, more than the limit of {MAX_DIMENSION}")
    return [check_text(f"{where}[{i}]", v, lines=True, limit=MAX_LENGTH) for i, v in enumerate(value, start=1)]


def _expression(where: str, value):
    """One expression: a text (checked as text; the kind compiles it) or a finite number."""
    if _is_number(value):
        return _number(where, value)
    return check_text(where, value, lines=True, limit=MAX_LENGTH)


def _expression_vector(where: str, value) -> list:
    if not isinstance(value, list) or not value:
        raise ParameterError(f"{where}: expected a list of expressions (texts) or numbers, got {_shown(value)}")
    if len(value) > MAX_DIMENSION:
        raise ParameterError(f"{where}: {len(value)} entries, more than the limit of {MAX_DIMENSION}")
    return [_expression(f"{where}[{i}]", v) for i, v in enumerate(value, start=1)]


def _expression_matrix(where: str, value) -> list:
    _rows(where, value, "expressions or numbers")
    return [[_expression(f"{where}[{i}][{j}]", v) for j, v in enumerate(row, start=1)]
            for i, row in enumerate(value, start=1)]


def _expression_or_vector(where: str, value):
    return _expression_vector(where, value) if isinstance(value, list) else _expression(where, value)


def _vector_or_matrix(where: str, value) -> np.ndarray:
    if isinstance(value, list) and value and isinstance(value[0], list):
        return _matrix(where, value)
    return _vector(where, value, MAX_ENTRIES)


def _integer(where: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParameterError(f"{where}: expected a whole number, got {_shown(value)}")
    if abs(value) > 2 ** 53:
        raise ParameterError(f"{where}: {value} is beyond the limit of 2^53")
    return value


def _boolean(where: str, value) -> bool:
    if not isinstance(value, bool):
        raise ParameterError(f"{where}: expected true or false, got {_shown(value)}")
    return value


def _choice(where: str, value, choices) -> str:
    check_text(where, value)
    if value not in choices:
        raise ParameterError(f"{where}: {value!r} is not one of {', '.join(choices)}")
    return value


_CHECKS = {
    "number": _number,
    "integer": _integer,
    "boolean": _boolean,
    "string": check_text,
    "component": check_text,
    "vector": lambda where, value: _vector(where, value, MAX_ENTRIES),
    "matrix": _matrix,
    "poles": _poles,
    "units": _units,
    "names": _names,
    "expressions": _expressions,
    "expression": _expression,
    "expression-vector": _expression_vector,
    "expression-matrix": _expression_matrix,
    "expression-or-vector": _expression_or_vector,
    "vector-or-matrix": _vector_or_matrix,
    "table": lambda where, value: _table(where, value, _number),
    "unit-table": lambda where, value: _table(where, value, lambda w, v: check_text(w, v, limit=100)),
}


def check_value(field: Field, where: str, value):
    """``value`` checked against ``field``: its type, shape and limits.

    Parameters
    ----------
    field : Field
        What the value must be.
    where : str
        The field's full name in messages (``components.plant.A``).
    value
        The value as :mod:`tomllib` read it.

    Returns
    -------
    object
        Numbers as floats, vectors and matrices as numpy arrays, the rest as read.

    Raises
    ------
    ParameterError
        Naming ``where`` (and the row of a matrix, the entry of a vector) and the limit exceeded.
    """
    if field.type == "choice":
        return _choice(where, value, field.choices)
    checked = _CHECKS[field.type](where, value)
    if field.maximum is not None and checked > field.maximum:
        raise ParameterError(f"{where}: {checked} is more than the limit of {field.maximum}")
    return checked
