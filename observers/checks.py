"""Input validation shared by every algorithm of the project.

Every check raises early with a message that names the offending parameter
and says what is wrong with it, e.g. ``A: expected a square matrix, got
shape (2, 3)``.  Two exception types keep design-time and run-time problems
apart:

* :class:`ParameterError` -- a bad configuration (dimensions, non-finite
  entries, non-Hurwitz gains, singular or unobservable data).
* :class:`SignalError` -- a bad signal met while running (NaN/inf input).
  Whoever raises it must leave its state untouched.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "ParameterError",
    "SignalError",
    "as_vector",
    "as_matrix",
    "require_square",
    "require_hurwitz",
    "UnboundedMode",
    "unbounded_mode",
    "require_positive",
    "finite_signal",
]


class ParameterError(ValueError):
    """A configuration value is unusable; the message names the parameter."""


class SignalError(ValueError):
    """A run-time signal is unusable (NaN/inf); the state was not changed."""


def _as_float_array(name: str, value) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{name}: expected numbers, got {value!r}") from exc
    if not np.all(np.isfinite(array)):
        bad = np.argwhere(~np.isfinite(array))[0]
        raise ParameterError(f"{name}: entry {tuple(int(i) + 1 for i in bad)} is not finite")
    return array


def as_vector(name: str, value, size: int | None = None) -> np.ndarray:
    """Return ``value`` as a finite 1-D float array of length ``size``."""
    array = _as_float_array(name, value)
    if array.ndim == 0:
        array = array.reshape(1)
    if array.ndim == 2 and 1 in array.shape:
        array = array.ravel()
    if array.ndim != 1:
        raise ParameterError(f"{name}: expected a vector, got shape {array.shape}")
    if size is not None and array.size != size:
        raise ParameterError(f"{name}: expected {size} entries, got {array.size}")
    return array


def as_matrix(name: str, value, shape: tuple[int | None, int | None] | None = None) -> np.ndarray:
    """Return ``value`` as a finite 2-D float array; ``None`` in ``shape`` matches any size."""
    array = _as_float_array(name, value)
    if array.ndim == 0:
        array = array.reshape(1, 1)
    if array.ndim != 2:
        raise ParameterError(f"{name}: expected a matrix, got shape {array.shape}")
    if shape is not None:
        for axis, (want, got) in enumerate(zip(shape, array.shape)):
            if want is not None and want != got:
                what = "rows" if axis == 0 else "columns"
                raise ParameterError(
                    f"{name}: expected {want} {what}, got shape {array.shape} "
                    f"(expected {tuple('any' if s is None else s for s in shape)})"
                )
    return array


def require_square(name: str, value) -> np.ndarray:
    """Return ``value`` as a finite square matrix."""
    matrix = as_matrix(name, value)
    if matrix.shape[0] != matrix.shape[1]:
        raise ParameterError(f"{name}: expected a square matrix, got shape {matrix.shape}")
    return matrix


def require_hurwitz(name: str, matrix: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Raise unless every eigenvalue of ``matrix`` has real part < ``-margin``."""
    eigenvalues = np.linalg.eigvals(matrix)
    worst = eigenvalues[np.argmax(eigenvalues.real)]
    if worst.real >= -margin:
        raise ParameterError(
            f"{name}: not Hurwitz, eigenvalue {worst:.6g} has real part >= {-margin:g} "
            f"(eigenvalues {np.round(eigenvalues, 6).tolist()})"
        )
    return matrix


class UnboundedMode(NamedTuple):
    """An eigenvalue of ``M`` whose mode of ``x' = M x`` grows: ``Re > 0`` (``growing``), or on the imaginary
    axis with fewer eigenvectors (``geometric``) than its multiplicity (``algebraic``): ``t^k`` growth."""

    value: complex
    growing: bool
    algebraic: int = 1
    geometric: int = 1


def unbounded_mode(matrix: np.ndarray, tolerance: float = 1e-9) -> UnboundedMode | None:
    """The mode of ``x' = matrix x`` that is unbounded for ``t >= 0``, or None (every solution bounded).

    Bounded (marginally stable): every eigenvalue has ``Re < 0``, or ``Re = 0`` and is semisimple (no
    Jordan block).  ``Re`` is zero within ``tolerance * max(1, max |matrix|)``; eigenvalues within 1e3 times
    that are one, and the geometric multiplicity counts the singular values of ``matrix - lambda I``
    below it.  For a growing mode the eigenvalue of largest real part is returned.
    """
    eigenvalues = np.linalg.eigvals(matrix)
    scale = tolerance * max(1.0, float(np.abs(matrix).max(initial=0.0)))
    worst = eigenvalues[np.argmax(eigenvalues.real)]
    if worst.real > scale:
        return UnboundedMode(worst, True)
    n = matrix.shape[0]
    for value in eigenvalues[np.abs(eigenvalues.real) <= scale]:
        algebraic = int(np.sum(np.abs(eigenvalues - value) <= 1e3 * scale))
        singular = np.linalg.svd(matrix - value * np.eye(n), compute_uv=False)
        geometric = int(np.sum(singular <= 1e3 * scale))
        if geometric < algebraic:
            return UnboundedMode(value, False, algebraic, geometric)
    return None


def require_positive(name: str, value, allow_zero: bool = False) -> float:
    """Return ``value`` as a float that is > 0 (or >= 0)."""
    number = float(_as_float_array(name, value))
    if number < 0 or (number == 0 and not allow_zero):
        relation = ">= 0" if allow_zero else "> 0"
        raise ParameterError(f"{name}: must be {relation}, got {number:g}")
    return number


def finite_signal(name: str, value) -> np.ndarray:
    """Return ``value`` as a float array; raise :class:`SignalError` on NaN/inf."""
    array = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(array)):
        raise SignalError(f"{name}: non-finite value {array.tolist()} refused; state unchanged")
    return array
