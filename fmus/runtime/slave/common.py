"""What the parts of the slave share: the refusal, the input modes, the faults of a step, words for a bad value."""

from __future__ import annotations

from enum import IntEnum

import numpy as np

__all__ = ["Refused", "InputMode", "EXTRAPOLATE", "INTERPOLATE", "NUMERICAL_FAULTS", "interpolation_parameter",
           "verdict", "slices"]


class Refused(Exception):
    """The slave refused an FMI call after checking it, and changed nothing (fmi2Error; the native
    binary keeps the instance in its FMI state: the next legal call works).  Any other exception
    of an FMI call is a failure (the binary's FMI error state)."""


class InputMode(IntEnum):
    """Value of the ``<port>_interpolation`` parameters."""

    HOLD = 0
    EXTRAPOLATE = 1
    INTERPOLATE = 2


EXTRAPOLATE, INTERPOLATE = int(InputMode.EXTRAPOLATE), int(InputMode.INTERPOLATE)

#: exceptions of a step that are faults of the data (fmi2Discard); anything else is a bug (fmi2Error)
NUMERICAL_FAULTS = (ValueError, ArithmeticError, np.linalg.LinAlgError)


def interpolation_parameter(port: str) -> str:
    return f"{port}_interpolation"


def verdict(value, bound: float) -> str:
    """``"nan is not finite"``, ``"1e+308 exceeds the bound 1e+100"`` (the worst entry of an array)."""
    where = ""
    if isinstance(value, np.ndarray):
        flat = value.ravel()
        if flat.size > 1:
            where = f" (entry {int(np.argmax(np.where(np.isfinite(flat), np.abs(flat), np.inf))) + 1} of {flat.size})"
            value = flat[int(np.argmax(np.where(np.isfinite(flat), np.abs(flat), np.inf)))]
        else:
            value = flat[0] if flat.size else 0.0
    value = complex(value) if np.iscomplexobj(value) else float(value)
    if not np.isfinite(value):
        return f"{value:g}{where} is not finite"
    return f"{value:g}{where} exceeds the bound {bound:g} in magnitude"


def slices(ports) -> dict[str, slice]:
    """Each port's elements in the vector of all ports' elements in declaration order."""
    where, offset = {}, 0
    for port in ports:
        where[port.name] = slice(offset, offset + port.size)
        offset += port.size
    return where
