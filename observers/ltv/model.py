r"""The known parts of paper 001's plant class that may vary: ``C`` or ``C(t)``, and ``f_1 .. f_p``.

Plant (1), with ``p`` known nonlinearities (the paper's ``w(y, t) = m f(y)`` is ``p = 1``):

.. math:: \dot x = A(t) x + k C^T(t) x + b u + \sum_{i=1}^{p} m_i f_i(y, t), \qquad y = C^T(t) x .

* :class:`OutputVector` -- ``C`` constant (the paper's example) or a function of time ``C(t)``.
* :class:`Nonlinearities` -- ``f(y)`` or ``f(t, y)`` returning one number (``p = 1``) or ``p``.
* :func:`gain_matrix` -- ``m`` as the ``n x p`` matrix ``[m_1, ..., m_p]`` (a vector when ``p = 1``);
  in ``Theta`` its columns follow one another, ``[m_1; ...; m_p]``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..checks import ParameterError, as_vector
from .stepping import time_function

__all__ = ["OutputVector", "Nonlinearities", "gain_matrix"]


class OutputVector:
    """``C`` of ``y = C^T x``: a constant vector, or ``C(t)`` (a function of time returning ``n`` numbers)."""

    def __init__(self, C, n: int | None = None):
        if callable(C):
            if n is None:
                n = np.asarray(C(0.0)).size
            self.function, self.constant = time_function("C", C, (n,)), None
        else:
            self.function, self.constant = None, as_vector("C", C, n)
            if not np.any(self.constant):
                raise ParameterError("C: the output vector is zero; y = C^T x would measure nothing")
        self.n = n if n is not None else self.constant.size

    @property
    def varies(self) -> bool:
        """``C`` is a function of time."""
        return self.function is not None

    def at(self, t: float) -> np.ndarray:
        """``C(t)`` (the constant itself when ``C`` is constant)."""
        return self.constant if self.function is None else np.asarray(self.function(t), dtype=float)


class Nonlinearities:
    r"""The known ``f(y)`` (``timed``: ``f(t, y)``) returning ``f_1 .. f_p``: one number, or a vector of ``p``.

    ``values(t, y)`` is the tuple of the ``p`` values; :attr:`count` is ``p``.
    """

    def __init__(self, f: Callable, timed: bool = False):
        if not callable(f):
            raise ParameterError(f"f: expected a function of y, got {f!r}")
        self.f, self.timed = f, bool(timed)
        try:
            probes = [np.asarray(self._call(0.0, y), dtype=float) for y in (0.0, 1.0)]
        except Exception as exc:
            raise ParameterError(f"f: f(y) must return one number or a vector: {type(exc).__name__}: {exc}") from None
        if probes[0].ndim > 1 or probes[0].shape != probes[1].shape or probes[0].size == 0:
            raise ParameterError(f"f: f(y) must return one number or a vector of p numbers, got shape {probes[0].shape}")
        if not all(np.all(np.isfinite(v)) for v in probes):
            raise ParameterError(f"f: f(0) or f(1) is not finite: {[v.tolist() for v in probes]}")
        self.scalar = probes[0].ndim == 0
        self.count = 1 if self.scalar else probes[0].size

    def _call(self, t: float, y: float):
        return self.f(t, y) if self.timed else self.f(y)

    def values(self, t: float, y: float) -> tuple[float, ...]:
        """``(f_1(y, t), ..., f_p(y, t))``."""
        value = self._call(t, y)
        if self.scalar:
            return (float(value),)
        return tuple(np.asarray(value, dtype=float))


def gain_matrix(name: str, value, n: int, p: int) -> np.ndarray:
    """``value`` as the ``n x p`` matrix of the gains ``[m_1, ..., m_p]`` (a vector of ``n`` when ``p = 1``)."""
    matrix = np.asarray(value, dtype=float)
    if matrix.ndim == 1 and p == 1:
        matrix = as_vector(name, matrix, n)[:, None]
    if matrix.shape != (n, p):
        raise ParameterError(f"{name}: expected an n x p = {n} x {p} matrix (one column m_i per nonlinearity f_i"
                             f"{'' if p > 1 else ', or a vector of n'}), got shape {np.shape(value)}")
    if not np.all(np.isfinite(matrix)):
        raise ParameterError(f"{name}: not finite: {matrix.tolist()}")
    return matrix
