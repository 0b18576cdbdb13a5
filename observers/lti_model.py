"""Validation of the matrices of a linear state-space model ``(A, B, C, D)``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import as_matrix, require_square

__all__ = ["StateSpace"]


@dataclass(frozen=True)
class StateSpace:
    """``x' = A x + B u``, ``y = C x + D u`` with checked, consistent dimensions.

    ``prefix`` is put in front of every parameter name in error messages
    (e.g. ``plant.A``) so that a configuration error names its field.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray

    @classmethod
    def checked(cls, A, B=None, C=None, D=None, prefix: str = "") -> "StateSpace":
        A = require_square(prefix + "A", A)
        n = A.shape[0]
        B = np.zeros((n, 0)) if B is None else as_matrix(prefix + "B", B, shape=(n, None))
        C = np.eye(n) if C is None else as_matrix(prefix + "C", C, shape=(None, n))
        m, p = B.shape[1], C.shape[0]
        D = np.zeros((p, m)) if D is None else as_matrix(prefix + "D", D, shape=(p, m))
        return cls(A, B, C, D)

    @property
    def n(self) -> int:
        return self.A.shape[0]

    @property
    def m(self) -> int:
        return self.B.shape[1]

    @property
    def p(self) -> int:
        return self.C.shape[0]
