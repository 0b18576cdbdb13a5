"""Argument checks shared by the estimators (thin layer over :mod:`observers.checks`).

Run-time checks happen before an estimator touches its state: shapes raise
:class:`~observers.checks.ParameterError`, NaN/inf signals raise
:class:`~observers.checks.SignalError`.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError, as_vector, finite_signal, require_positive


def dimension(name: str, value) -> int:
    """Return ``value`` as a positive integer (a number of parameters or rows)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ParameterError(f"{name}: expected a positive integer, got {value!r}")
    if value < 1:
        raise ParameterError(f"{name}: must be >= 1, got {value}")
    return int(value)


def positive_gains(name: str, value, size: int, allow_zero: bool = False) -> np.ndarray:
    """Return a scalar or ``size``-vector gain as a ``size``-vector of positive entries."""
    gains = as_vector(name, value)
    if gains.size == 1:
        gains = np.full(size, gains[0])
    elif gains.size != size:
        raise ParameterError(f"{name}: expected a scalar or {size} entries, got {gains.size}")
    bad = gains < 0 if allow_zero else gains <= 0
    if np.any(bad):
        index = int(np.argmax(bad))
        relation = ">= 0" if allow_zero else "> 0"
        raise ParameterError(f"{name}: entries must be {relation}, entry {index + 1} is {gains[index]:g}")
    return gains


def initial_estimate(theta0, p: int) -> np.ndarray:
    """``theta0`` as a ``p``-vector; ``None`` means zeros."""
    return np.zeros(p) if theta0 is None else as_vector("theta0", theta0, p)


def step_length(dt) -> float:
    """The step ``dt`` as a finite float > 0."""
    return require_positive("dt", dt)


def regression(y, phi, p: int, rows: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Check one sample of ``y = phi^T theta`` or ``Y = Phi theta``.

    Returns ``(Y, Phi)`` with ``Y`` of shape ``(m,)`` and ``Phi`` of shape
    ``(m, p)``; a 1-D ``phi`` is the scalar regression (``m = 1``).  ``rows``
    fixes ``m`` when the caller needs a particular number of rows.
    """
    try:
        Phi = np.asarray(phi, dtype=float)
        Y = np.asarray(y, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"y, phi: expected numbers, got {y!r}, {phi!r}") from exc
    if Phi.ndim == 1:
        Phi = Phi.reshape(1, -1)
    if Phi.ndim != 2 or Phi.shape[1] != p:
        raise ParameterError(
            f"phi: expected {p} entries (scalar regression) or a matrix with {p} columns, "
            f"got shape {np.shape(phi)}"
        )
    m = Phi.shape[0]
    if rows is not None and m != rows:
        raise ParameterError(f"phi: expected {rows} row(s), got shape {np.shape(phi)}")
    if Y.ndim == 2 and 1 in Y.shape:
        Y = Y.ravel()
    Y = Y.reshape(-1) if Y.ndim == 0 else Y
    if Y.ndim != 1 or Y.size != m:
        raise ParameterError(f"y: expected {m} entries (one per row of phi), got shape {np.shape(y)}")
    return finite_signal("y", Y), finite_signal("phi", Phi)
