"""The model functions of paper 001's example (Kozachek, Bobtsov, Nikolaev 2023).

Referenced from FMU definitions as ``"plants.paper001:<name>"`` (see
:mod:`fmus.runtime.callables`); the ``plants`` package is bundled into every FMU, so
these need no ``extra_modules``.  Write your own functions with the same
signatures in a module of yours to observe another plant of the class

    x' = A(t) x + k C^T x + b u + m f(y),   y = C^T x.

* ``A(t) -> (n, n)`` and ``L(t) -> (n,)`` arrays, ``f(y) -> float``.
* ``L(t)`` must make ``A0(t) = A(t) - L(t) C^T`` uniformly stable
  (Assumptions 3-4); here ``A0 = [[0, 1], [-9, 0]]`` for ``C = [1; 0]``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["A_paper", "L_paper", "f_sin", "C_PAPER"]

#: output vector of the example, ``y = C^T x = x1``
C_PAPER = (1.0, 0.0)


def A_paper(t: float) -> np.ndarray:
    """``A(t) = [[2 - sin t, 1], [-8 + cos t, 0]]``."""
    return np.array([[2.0 - math.sin(t), 1.0], [-8.0 + math.cos(t), 0.0]])


def L_paper(t: float) -> np.ndarray:
    """``L(t) = [2 - sin t; 1 + cos t]``, so that ``A(t) - L(t) C^T = [[0, 1], [-9, 0]]``."""
    return np.array([2.0 - math.sin(t), 1.0 + math.cos(t)])


def f_sin(y: float) -> float:
    """``f(y) = sin y`` (the example's ``w = m sin y``)."""
    return math.sin(y)
