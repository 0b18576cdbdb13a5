"""A linear state-space model ``(A, B, C, D)`` with checked dimensions, continuous or discrete.

Wherever the project takes a plant it also takes a ``control.StateSpace`` of python-control (or a
``scipy.signal`` state-space system, or any object with ``A``, ``B``, ``C``, ``D`` and ``dt``):
:meth:`StateSpace.of` reads it, ``dt`` included (0: continuous, ``x' = A x + B u``; ``T > 0``:
discrete, ``x[k+1] = A x[k] + B u[k]``).  python-control is not a dependency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import ParameterError, as_matrix, require_square

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
    dt: float = 0.0  #: 0: continuous; > 0: the sample time of a discrete model

    @classmethod
    def checked(cls, A, B=None, C=None, D=None, prefix: str = "", dt: float = 0.0) -> "StateSpace":
        A = require_square(prefix + "A", A)
        n = A.shape[0]
        B = np.zeros((n, 0)) if B is None else as_matrix(prefix + "B", B, shape=(n, None))
        C = np.eye(n) if C is None else as_matrix(prefix + "C", C, shape=(None, n))
        m, p = B.shape[1], C.shape[0]
        D = np.zeros((p, m)) if D is None else as_matrix(prefix + "D", D, shape=(p, m))
        return cls(A, B, C, D, _sample_time(prefix + "dt", dt))

    @classmethod
    def of(cls, system, prefix: str = "") -> "StateSpace":
        """``system`` -- a :class:`StateSpace`, a ``control.StateSpace``, a ``scipy.signal`` system or an
        ``(A, B, C, D)`` tuple -- as a checked :class:`StateSpace`."""
        if isinstance(system, cls):
            return system
        if isinstance(system, (tuple, list)):
            if len(system) != 4:
                raise ParameterError(f"{prefix or 'plant'}: expected (A, B, C, D), got {len(system)} matrices")
            return cls.checked(*system, prefix=prefix)
        if not all(hasattr(system, name) for name in "ABCD"):
            raise ParameterError(f"{prefix or 'plant'}: expected a state-space system (A, B, C, D), "
                                 f"got {type(system).__name__}")
        return cls.checked(system.A, system.B, system.C, system.D, prefix, getattr(system, "dt", 0.0))

    @property
    def discrete(self) -> bool:
        return self.dt > 0

    @property
    def n(self) -> int:
        return self.A.shape[0]

    @property
    def m(self) -> int:
        return self.B.shape[1]

    @property
    def p(self) -> int:
        return self.C.shape[0]


def _sample_time(name: str, dt) -> float:
    """python-control's ``dt`` (0 or None: continuous; a positive number: discrete) as a float."""
    if dt is None or dt is False or (not isinstance(dt, bool) and dt == 0):
        return 0.0
    if dt is True:
        raise ParameterError(f"{name}: a discrete system needs its sample time, got dt = True")
    try:
        value = float(dt)
    except (TypeError, ValueError):
        raise ParameterError(f"{name}: expected a sample time, got {dt!r}") from None
    if not (value > 0 and np.isfinite(value)):
        raise ParameterError(f"{name}: expected a positive finite sample time (or 0: continuous), got {dt!r}")
    return value
